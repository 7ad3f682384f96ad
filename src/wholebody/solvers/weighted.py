"""The ``weighted`` method of :func:`~wholebody.solvers.hierarchy.solve_hierarchy`.

The single weighted QP (Fahmi et al. 2019, eq. 7): ``levels = [hard, objective]`` as one QP with the
hard level's rows as constraints, its independent equality rows eliminated first
(:func:`~.common.regular_nullspace`: the QP over their nullspace, Herzog et al. 2016 eq. 17,
smaller for the backend; dependent rows, or as many as the variables, stay rows). Equal to the
two-level cascade whenever the hard level is feasible, up to the ε effect of the cascade's soft
first level (it trades an O(ε) violation for norm; the hard rows do not), i.e. exactly equal as
ε → 0. If the hard level
is infeasible (or the backend fails on the single QP, e.g. quadprog on inconsistent equality
rows), :func:`_solve_weighted` returns the reason and ``solve_hierarchy`` returns the cascade's
result instead, recorded in ``method`` and ``warnings``, or with
``SolverSettings(weighted_fallback=False)`` the failure (:func:`_without_weighted_solution`).

:func:`_solve_weighted` is the reference; :mod:`.compiled_cascade` assembles the same QP in C++
(``wholebody._cascade.WeightedRun``) and solves DAQP's there, the default when built.
"""

from __future__ import annotations

import numpy as np

from .backends import solve_qp
from .cascade import _solve_cascade
from .common import _finish, _rows, log, regular_nullspace

FALLBACK_WARNING = "weighted: hard level infeasible or the single QP failed; result of the cascade"
#: the status of a weighted QP without a solution where the cascade is not asked for (the
#: reason follows in parentheses)
FAILED_STATUS = "weighted: hard level infeasible or the single QP failed"
#: the reason where the QP's solution breaks the hard level beyond the feasibility tolerance
HARD_NOT_HELD = "hard level not satisfied"


def _solve_weighted(levels, n, settings, feas_tol, t0):
    """One QP: rows of levels[0] as hard constraints, levels[-1] as weighted objective (Fahmi et
    al. 2019, eq. 7), over x = x1 + Z u where the hard equalities are eliminated
    (:func:`~.common.regular_nullspace`), solved by ``settings.backend`` with ε =
    ``settings.regularization`` (ε‖x‖²: ε I on u, ε Zᵀx1 in the linear term) → a
    HierarchySolution, or the reason (a str) where the QP failed or the hard level does not
    hold at its solution."""
    eps = settings.regularization
    obj = levels[-1]
    hard = levels[0] if len(levels) == 2 else None
    Bo, Co = _rows(obj, n)
    wB = obj.w[:, None] * Bo
    rhs = obj.w * obj.b
    elimination = None
    if hard is not None:
        Bh, Ch = _rows(hard, n)
        keep = hard.w > 0  # a zero-weight row is not part of the hard level's cost
        if 0 < keep.sum() < n:  # (as many rows as variables: x fixed, left to the backend)
            elimination = regular_nullspace(Bh[keep], hard.b[keep])
    Z, M = None, wB
    if elimination is not None:
        x1, Z = elimination
        M, rhs = wB @ Z, rhs - wB @ x1
    nu = M.shape[1]
    m = Co.shape[0]
    nv = nu + m
    H = np.zeros((nv, nv))
    H[:nu, :nu] = M.T @ M
    H.flat[: nu * nv : nv + 1] += eps
    H.flat[nu * nv + nu :: nv + 1] = 1.0
    g = np.zeros(nv)
    g[:nu] = -(M.T @ rhs)
    if Z is not None:
        g[:nu] += eps * (Z.T @ x1)

    blocks, lows, ups = [], [], []
    if hard is not None:
        if Z is None:
            blocks, lows, ups = [Bh[keep]], [hard.b[keep]], [hard.b[keep]]
        blocks.append(Ch)
        lows.append(hard.lower)
        ups.append(hard.upper)
    rows = np.concatenate(blocks) if blocks else np.zeros((0, n))
    lower = np.concatenate(lows) if lows else np.zeros(0)
    upper = np.concatenate(ups) if ups else np.zeros(0)
    if m:  # soft rows of the objective level, one slack each (as in the cascade)
        VC = obj.v[:, None] * Co
        il, iu = np.flatnonzero(np.isfinite(obj.lower)), np.flatnonzero(np.isfinite(obj.upper))
        rows = np.concatenate((rows, VC[il], VC[iu]))
        lower = np.concatenate((lower, obj.v[il] * obj.lower[il], np.full(iu.size, -np.inf)))
        upper = np.concatenate((upper, np.full(il.size, np.inf), obj.v[iu] * obj.upper[iu]))
    A = np.zeros((rows.shape[0], nv))
    if Z is not None:  # the rows over u, their bounds less their values at x1
        A[:, :nu] = rows @ Z
        shift = rows @ x1
        lower, upper = lower - shift, upper - shift
    else:
        A[:, :nu] = rows
    if m:
        first = A.shape[0] - il.size - iu.size
        A[first + np.arange(il.size), nu + il] = 1.0
        A[first + il.size + np.arange(iu.size), nu + iu] = -1.0
    y, status, ok = solve_qp(H, g, A, lower, upper, backend=settings.backend, **settings.options)
    if not ok:
        log.debug("weighted QP failed: %s", status)
        return status
    x = x1 + Z @ y[:nu] if Z is not None else y[:n]
    if hard is not None:
        r = np.abs(Bh[keep] @ x - hard.b[keep])
        cx = Ch @ x
        viol = np.maximum(np.maximum(hard.lower - cx, cx - hard.upper), 0.0)
        if np.any(r > feas_tol * (1.0 + np.abs(hard.b[keep]))) or np.any(viol > feas_tol * (1.0 + np.abs(cx))):
            log.debug("weighted QP: hard level not satisfied")
            return HARD_NOT_HELD
    times = np.full(len(levels), np.nan)
    return _finish(levels, x, "optimal", True, t0, times, "weighted", len(levels), np.zeros(0), [])


def _without_weighted_solution(levels, n, settings, tols, t0, reason: str = ""):
    """What the method returns where the weighted QP gave no solution (``reason``: why): the
    cascade's result, with :data:`FALLBACK_WARNING` first among its warnings (``method``
    "cascade"), or with ``settings.weighted_fallback`` False a failed solution (ok False,
    :data:`FAILED_STATUS` and the reason, x zero)."""
    if not settings.weighted_fallback:
        status = f"{FAILED_STATUS} ({reason})" if reason else FAILED_STATUS
        log.debug(status)
        return _finish(levels, np.zeros(n), status, False, t0,
                       np.full(len(levels), np.nan), "weighted", 0, np.zeros(0), [])
    log.debug(FALLBACK_WARNING)
    sol = _solve_cascade(levels, n, settings, None, tols, t0)
    sol.warnings = (FALLBACK_WARNING,) + sol.warnings
    return sol
