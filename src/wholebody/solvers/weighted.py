"""The ``weighted`` method of :func:`~wholebody.solvers.hierarchy.solve_hierarchy`.

The single weighted QP (Fahmi et al. 2019, eq. 7): ``levels = [hard, objective]`` as one QP with the
hard level's rows as constraints — no nullspace. Equal to the two-level cascade whenever the
hard level is feasible, up to the ε effect of the cascade's soft first level (it trades an
O(ε) violation for norm; the hard rows do not), i.e. exactly equal as ε → 0. If the hard level
is infeasible (or the backend fails on the single QP, e.g. quadprog on inconsistent equality
rows), :func:`_solve_weighted` returns None and ``solve_hierarchy`` returns the cascade's
result instead (:func:`_cascade_instead`), recorded in ``method`` and ``warnings``.

:func:`_solve_weighted` is the reference; :mod:`.compiled_cascade` assembles the same QP in C++
(``wholebody._cascade.WeightedRun``) and solves DAQP's there, the default when built.
"""

from __future__ import annotations

import numpy as np

from .backends import solve_qp
from .cascade import _solve_cascade
from .common import _finish, _rows, log

FALLBACK_WARNING = "weighted: hard level infeasible or the single QP failed; result of the cascade"


def _solve_weighted(levels, n, settings, feas_tol, t0):
    """One QP: rows of levels[0] as hard constraints, levels[-1] as weighted objective (Fahmi et al. 2019, eq. 7),
    solved by ``settings.backend`` with ε = ``settings.regularization``."""
    eps = settings.regularization
    obj = levels[-1]
    hard = levels[0] if len(levels) == 2 else None
    Bo, Co = _rows(obj, n)
    wB = obj.w[:, None] * Bo
    m = Co.shape[0]
    nv = n + m
    H = np.zeros((nv, nv))
    H[:n, :n] = wB.T @ wB
    H.flat[: n * nv : nv + 1] += eps
    H.flat[n * nv + n :: nv + 1] = 1.0
    g = np.zeros(nv)
    g[:n] = -(wB.T @ (obj.w * obj.b))

    blocks, lows, ups = [], [], []
    if hard is not None:
        Bh, Ch = _rows(hard, n)
        keep = hard.w > 0  # a zero-weight row is not part of the hard level's cost
        blocks += [Bh[keep], Ch]
        lows += [hard.b[keep], hard.lower]
        ups += [hard.b[keep], hard.upper]
    A = np.zeros((sum(b.shape[0] for b in blocks), nv))
    if blocks:
        A[:, :n] = np.concatenate(blocks)
    lower = np.concatenate(lows) if lows else np.zeros(0)
    upper = np.concatenate(ups) if ups else np.zeros(0)
    if m:  # soft rows of the objective level, one slack each (as in the cascade)
        VC = obj.v[:, None] * Co
        il, iu = np.flatnonzero(np.isfinite(obj.lower)), np.flatnonzero(np.isfinite(obj.upper))
        S = np.zeros((il.size + iu.size, nv))
        S[: il.size, :n] = VC[il]
        S[np.arange(il.size), n + il] = 1.0
        S[il.size :, :n] = VC[iu]
        S[il.size + np.arange(iu.size), n + iu] = -1.0
        A = np.concatenate((A, S))
        lower = np.concatenate((lower, obj.v[il] * obj.lower[il], np.full(iu.size, -np.inf)))
        upper = np.concatenate((upper, np.full(il.size, np.inf), obj.v[iu] * obj.upper[iu]))
    y, status, ok = solve_qp(H, g, A, lower, upper, backend=settings.backend, **settings.options)
    if not ok:
        log.debug("weighted QP failed: %s", status)
        return None
    x = y[:n]
    if hard is not None:
        Bh, Ch = _rows(hard, n)
        keep = hard.w > 0
        r = np.abs(Bh[keep] @ x - hard.b[keep])
        cx = Ch @ x
        viol = np.maximum(np.maximum(hard.lower - cx, cx - hard.upper), 0.0)
        if np.any(r > feas_tol * (1.0 + np.abs(hard.b[keep]))) or np.any(viol > feas_tol * (1.0 + np.abs(cx))):
            log.debug("weighted QP: hard level not satisfied")
            return None
    times = np.full(len(levels), np.nan)
    return _finish(levels, x, "optimal", True, t0, times, "weighted", len(levels), np.zeros(0), [])


def _cascade_instead(levels, n, settings, tols, t0):
    """The cascade's result where the weighted QP gave none, with :data:`FALLBACK_WARNING` first
    among its warnings (``method`` "cascade")."""
    log.debug(FALLBACK_WARNING)
    sol = _solve_cascade(levels, n, settings, None, tols, t0)
    sol.warnings = (FALLBACK_WARNING,) + sol.warnings
    return sol
