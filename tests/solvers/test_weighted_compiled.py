"""The weighted method compiled (``wholebody._cascade.WeightedRun`` through
solvers/compiled_cascade.py) against its Python reference (``weighted._solve_weighted``,
``compiled=False``): the same QP (Fahmi et al. 2019, eq. 7) assembled in C++, DAQP's solved there.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import native_cycle_or_skip
from test_hierarchy import cfg, random_hierarchy

from wholebody.solvers import Level, solve_hierarchy
from wholebody.solvers.weighted import FAILED_STATUS, FALLBACK_WARNING


def feasible_pair(rng, n):
    """[hard, objective]: a hard level feasible at a random point (equalities, some of zero
    weight, one-sided inequalities through it with a margin) and a random objective level
    (conflicting equalities, two- and one-sided inequalities, unreachable bounds)."""
    x_feas = rng.standard_normal(n)
    Bh = rng.standard_normal((int(rng.integers(1, n // 2 + 1)), n))
    w = rng.uniform(0.5, 2.0, Bh.shape[0])
    w[rng.random(w.size) < 0.2] = 0.0  # not part of the hard level's cost: no row
    Ch = rng.standard_normal((int(rng.integers(1, n)), n))
    cx = Ch @ x_feas
    upper = np.where(rng.random(cx.size) < 0.5, np.inf, cx + rng.uniform(0, 1, cx.size))
    hard = Level(eq=(Bh, Bh @ x_feas), ineq=(Ch, cx - rng.uniform(0, 1, cx.size), upper),
                 weights=w, name="hard")
    return [hard, random_hierarchy(rng, n=n, n_levels=1)[0]]


def problems(seed, count):
    """Feasible pairs, random pairs (the hard level often infeasible: the cascade's result) and
    single objective levels."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        n = int(rng.integers(4, 16))
        kind = i % 3
        out.append(feasible_pair(rng, n) if kind == 0 else
                   random_hierarchy(rng, n=n, n_levels=2) if kind == 1 else
                   random_hierarchy(rng, n=n, n_levels=1))
    return out


@pytest.mark.parametrize("backend", ["quadprog", "daqp"])
def test_compiled_weighted_matches_python(backend):
    """The same outcome as the Python reference (ok, status, method, warnings), x and the level
    costs to 1e-7 on 240 random problems; both branches — the weighted QP's solution and the
    cascade's result where it gives none — taken often."""
    native_cycle_or_skip("_cascade")
    settings = cfg(method="weighted", backend=backend, regularization=1e-6)
    methods = []
    for i, levels in enumerate(problems(11, 240)):
        compiled = solve_hierarchy(levels, settings=settings)
        python = solve_hierarchy(levels, settings=settings, compiled=False)
        where = f"problem {i}"
        assert (compiled.ok, compiled.status, compiled.method, compiled.warnings) == \
            (python.ok, python.status, python.method, python.warnings), where
        scale = 1.0 + np.abs(python.x).max()
        np.testing.assert_allclose(compiled.x, python.x, atol=1e-7 * scale, rtol=0, err_msg=where)
        np.testing.assert_allclose(compiled.costs, python.costs,
                                   atol=1e-7 * (1.0 + python.costs.max()), rtol=0, err_msg=where)
        methods.append(compiled.method)
        if compiled.method == "weighted":
            assert compiled.timings["qps"] == 1 and compiled.timings["qp"] >= 0.0
    assert methods.count("weighted") > 100 and methods.count("cascade") > 20


@pytest.mark.parametrize("options", [{}, {"iter_limit": 2}, {"raw_tol": -1.0}],
                         ids=["default", "daqp-fails", "verdict-refuses"])
def test_daqp_in_the_run_gives_what_python_gives(monkeypatch, options):
    """DAQP called by the compiled weighted run itself (``WeightedRun.solve_daqp``) and called
    from Python (``solve_qp(..., "daqp")``) on the run's assembled QP: bitwise the same x and the
    same outcome — also when DAQP fails (iteration limit 2) or its verdict on the unscaled rows
    refuses every solution (raw_tol −1): then both return the cascade's result."""
    import wholebody.solvers.compiled_cascade as cc
    native_cycle_or_skip("_cascade")
    if cc._daqp_in_cascade("daqp", options) is None:
        pytest.skip("DAQP's C interface is not usable with the installed daqp")
    settings = cfg(method="weighted", backend="daqp", backend_options=options,
                   regularization=1e-6)
    cases = problems(12, 120)
    in_run = [solve_hierarchy(levels, settings=settings) for levels in cases]
    monkeypatch.setattr(cc, "_daqp_in_cascade", lambda backend, opts: None)
    from_python = [solve_hierarchy(levels, settings=settings) for levels in cases]
    for i, (a, b) in enumerate(zip(in_run, from_python)):
        np.testing.assert_array_equal(a.x, b.x, err_msg=str(i))
        assert (a.ok, a.status, a.method, a.warnings) == (b.ok, b.status, b.method, b.warnings), i
    weighted = sum(s.method == "weighted" for s in in_run)
    if not options:  # the weighted solution mostly, the cascade's where the hard level fails
        assert 80 < weighted < len(cases)
    else:  # DAQP (or its verdict) failed on most QPs: the cascade's results
        assert weighted < 20
        assert sum(s.warnings[:1] == (FALLBACK_WARNING,) for s in in_run) == len(cases) - weighted


def test_hard_infeasible_falls_back_to_the_cascade():
    """x0 ≥ 1 and x0 ≤ 0 in the hard level: no weighted solution; the compiled method returns
    the cascade's result with the fallback warning first, as the Python method does, and the
    bound run does the same."""
    native_cycle_or_skip("_cascade")
    from wholebody.solvers.hierarchy import BoundWeighted
    n = 4
    hard = Level(ineq=(np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0]]), np.array([1.0, -np.inf]),
                       np.array([np.inf, 0.0])), name="hard")
    obj = Level(eq=(np.eye(n), np.arange(n, dtype=float)), name="obj")
    settings = cfg(method="weighted", backend="daqp")
    python = solve_hierarchy([hard, obj], settings=settings, compiled=False)
    for sol in (solve_hierarchy([hard, obj], settings=settings),
                BoundWeighted([hard, obj], settings).solve()):
        assert sol.ok and sol.method == "cascade" and sol.warnings[0] == FALLBACK_WARNING
        assert sol.warnings == python.warnings
        np.testing.assert_allclose(sol.x, python.x, atol=1e-9)
        assert sol.costs[0] == pytest.approx(0.5, rel=1e-3)  # the hard level's compromise x0 = 0.5
    assert BoundWeighted([hard, obj], settings).solve_quick() is None  # no weighted optimum
    failing = cfg(method="weighted", backend="daqp", weighted_fallback=False)
    for sol in (solve_hierarchy([hard, obj], settings=failing, compiled=False),
                solve_hierarchy([hard, obj], settings=failing),
                BoundWeighted([hard, obj], failing).solve()):
        assert not sol.ok and sol.method == "weighted"
        assert sol.status.startswith(FAILED_STATUS + " (") and "daqp" in sol.status
        assert sol.warnings == () and np.all(sol.x == 0.0)


def test_bound_weighted_follows_its_arrays():
    """BoundWeighted holds the level arrays: after their contents change in place, solve() (and
    its quick path) gives what solve_hierarchy gives on copies of the new contents; it refuses another method,
    more than two levels and arrays it cannot hold."""
    native_cycle_or_skip("_cascade")
    from wholebody.solvers.hierarchy import BoundWeighted
    rng = np.random.default_rng(13)
    levels = feasible_pair(rng, 8)
    settings = cfg(method="weighted", backend="daqp", regularization=1e-6)
    bound = BoundWeighted(levels, settings)
    for _ in range(5):
        for L in levels:
            L.b[:] += 0.1 * rng.standard_normal(L.b.size)
            L.B[:] += 0.05 * rng.standard_normal(L.B.shape)
        copies = [Level.trusted(L.B.copy(), L.b.copy(), L.w.copy(), L.C.copy(), L.lower.copy(),
                                L.upper.copy(), L.v.copy(), name=L.name) for L in levels]
        a, b = bound.solve(), solve_hierarchy(copies, settings=settings)
        assert (a.ok, a.method, a.status) == (b.ok, b.method, b.status)
        np.testing.assert_array_equal(a.x, b.x)
        x, costs, _, qps = bound.solve_quick()  # the quick path: the same optimum
        np.testing.assert_array_equal(x, b.x)
        np.testing.assert_array_equal(costs, b.costs)
        assert qps == 1
    with pytest.raises(ValueError, match="BoundWeighted runs method 'weighted'"):
        BoundWeighted(levels, cfg(method="cascade"))
    with pytest.raises(ValueError, match="'weighted' takes"):
        BoundWeighted(levels + levels[-1:], settings)
    levels[0].b = np.repeat(levels[0].b, 2)[::2]  # a strided view: not held as it is
    with pytest.raises(ValueError, match="level 'hard' b: needs a C-contiguous"):
        BoundWeighted(levels, settings)


def full_weighted_qp(levels, n, eps):
    """The weighted QP with the hard equality rows kept as rows (no elimination), assembled here
    on its own: min ½‖W(B x − b)‖² + ½ε‖x‖² + ½‖s‖² over [x; s], s ≥ 0 implied by the rows —
    solved by quadprog, the oracle."""
    from wholebody.solvers.backends import solve_qp
    hard, obj = levels
    keep = hard.w > 0
    wB, wb = obj.w[:, None] * obj.B, obj.w * obj.b
    m = obj.C.shape[0]
    H = np.zeros((n + m, n + m))
    H[:n, :n] = wB.T @ wB + eps * np.eye(n)
    H[n:, n:] = np.eye(m)
    g = np.concatenate((-(wB.T @ wb), np.zeros(m)))
    rows = [np.hstack((hard.B[keep], np.zeros((keep.sum(), m)))),
            np.hstack((hard.C, np.zeros((hard.C.shape[0], m))))]
    lower, upper = [hard.b[keep], hard.lower], [hard.b[keep], hard.upper]
    for i in range(m):  # v C x + s ≥ v lower, v C x − s ≤ v upper
        for sign, lo, up in ((1.0, obj.v[i] * obj.lower[i], np.inf),
                             (-1.0, -np.inf, obj.v[i] * obj.upper[i])):
            if np.isfinite(lo) or np.isfinite(up):
                row = np.zeros(n + m)
                row[:n], row[n + i] = obj.v[i] * obj.C[i], sign
                rows.append(row[None])
                lower.append([lo])
                upper.append([up])
    y, status, ok = solve_qp(H, g, np.vstack(rows), np.concatenate(lower), np.concatenate(upper),
                             backend="quadprog")
    return y[:n] if ok else None


@pytest.mark.parametrize("equalities", ["independent", "dependent", "as many as variables"])
def test_weighted_over_the_nullspace_equals_the_qp_with_equality_rows(equalities):
    """The weighted QP posed over the nullspace of the hard equalities (x = x1 + Z u) has the
    optimum of the same QP with the equality rows kept, solved by quadprog on an assembly of
    its own — compiled and Python, on feasible pairs; with dependent equality rows (one row
    repeated; the oracle is given it once) or as many as the variables they stay rows, with the
    same optimum."""
    native_cycle_or_skip("_cascade")
    rng = np.random.default_rng(17)
    eps = 1e-6
    settings = cfg(method="weighted", backend="daqp", regularization=eps)
    compared = 0
    for i in range(60):
        n = int(rng.integers(4, 12))
        hard, obj = feasible_pair(rng, n)
        oracle = full_weighted_qp([hard, obj], n, eps)  # (quadprog takes independent rows only)
        if equalities == "dependent":
            keep = hard.w > 0
            if not keep.any():
                continue
            B, b = hard.B[keep], hard.b[keep]
            hard = Level(eq=(np.vstack((B, B[:1])), np.concatenate((b, b[:1]))),
                         ineq=(hard.C, hard.lower, hard.upper), name="hard")
        elif equalities == "as many as variables":
            x = np.linalg.solve(hard.B[:1] @ hard.B[:1].T, hard.b[:1]) @ hard.B[:1]
            B = np.vstack((hard.B[:1], rng.standard_normal((n - 1, n))))
            hard = Level(eq=(B, B @ x), ineq=(hard.C, hard.C @ x - 1.0,
                                               np.full(hard.C.shape[0], np.inf)), name="hard")
            oracle = full_weighted_qp([hard, obj], n, eps)
        if oracle is None:
            continue
        for compiled in (True, False):
            sol = solve_hierarchy([hard, obj], settings=settings, compiled=compiled)
            assert sol.ok and sol.method == "weighted", (i, compiled, sol.status)
            scale = 1.0 + np.abs(oracle).max()
            np.testing.assert_allclose(sol.x, oracle, atol=1e-6 * scale, rtol=0,
                                       err_msg=f"problem {i} compiled={compiled}")
        compared += 1
    assert compared > 40
