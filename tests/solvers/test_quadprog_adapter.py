"""The quadprog adapter on a level QP where Goldfarb–Idnani on the raw rows never returns.

``data/degenerate_apex_qp.npz`` is the last-level QP of Table 1 (talos, double support) on a
state of ``robot.smooth_motion`` where one sole's wrench sits at the apex of its contact wrench
cone: all 16 of the cone's rows are active, with row norms from 1e2 to 1e6 (the cascade's rows
in w = R u). quadprog given those rows loops forever (it has no iteration limit and no
anti-cycling rule); the adapter passes the rows as given (see ``solve_quadprog``), so this is a
known defect, kept as a strict xfail. The solve runs in a child process with a time limit (the
QP takes milliseconds when it returns), so the test ends instead of hanging the suite; a
solution is checked against DAQP's (a different algorithm) and the rows."""

from __future__ import annotations

import multiprocessing
from pathlib import Path

import numpy as np
import pytest

from wholebody.solvers import backends

DATA = Path(__file__).parent / "data" / "degenerate_apex_qp.npz"


def _solve(queue) -> None:
    d = np.load(DATA)
    queue.put(backends.solve_quadprog(np.eye(d["g"].size), d["g"], d["A"], d["lower"], d["upper"]))


@pytest.mark.xfail(strict=True, reason="quadprog loops forever on this degenerate vertex")
def test_quadprog_returns_on_a_degenerate_apex():
    queue = multiprocessing.get_context("spawn").Queue()
    child = multiprocessing.get_context("spawn").Process(target=_solve, args=(queue,))
    child.start()
    child.join(10.0)
    if child.is_alive():
        child.kill()
        raise AssertionError("quadprog did not return within 10 s")
    x, status, ok = queue.get(timeout=5.0)
    assert ok, status
    d = np.load(DATA)
    g, A, lower, upper = d["g"], d["A"], d["lower"], d["upper"]
    y, daqp_status, daqp_ok = backends.solve_daqp(np.eye(g.size), g, A, lower, upper)
    assert daqp_ok, daqp_status
    np.testing.assert_allclose(x, y, atol=1e-8 * max(1.0, np.abs(y).max()), rtol=0)
    ax = A @ x
    scale = np.linalg.norm(A, axis=1) * np.linalg.norm(x)
    assert np.all(ax >= lower - 1e-12 * scale) and np.all(ax <= upper + 1e-12 * scale)
