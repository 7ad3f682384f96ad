"""Hierarchical (lexicographic) least squares with inequalities — Herzog et al. 2016, §2.2.

Semantics (eqs. 5-11)
---------------------
Level r minimises ``‖W_r(B_r x − b_r)‖² + ‖v_r‖² + ε‖x‖²`` with ``v_r = V_r · violation`` of
``lower_r ≤ C_r x ≤ upper_r``, over the optimal set of levels 1..r−1. That set is exactly

    { x : W_k B_k x = W_k B_k x*_k  and  lower_k − v*_k/V_k ≤ C_k x ≤ upper_k + v*_k/V_k,  k < r }

because the weighted residual vector and the slack vector of a convex least-squares level are
unique over its optimal set (strict convexity in the residual; the squared distance to an
interval is strictly convex outside it). So fixing residuals through ``x = x*_r + Z_r u``
(eq. 8) and relaxing bounds by the optimal slacks (eq. 9) is exact. Reported costs are
evaluated at the returned x and exclude the ε term.

Methods
-------
``cascade`` (the reference)
    One QP per level over the nullspace coordinates u, plus one slack per inequality row of the
    level that still has freedom (eqs. 10-11). ``Z`` is updated recursively, ``Z_{r+1} = Z_r N_r``
    with ``N_r`` an orthonormal kernel basis of ``W_r B_r Z_r``: Z keeps orthonormal columns and
    the variable count shrinks level by level. Equality rows lock their directions even when
    they cannot be satisfied (their residual is what is kept). Inequality rows with
    ``‖C_i Z‖ ≤ drop_tol ‖C_i‖`` have no freedom left: they are dropped from the QP (their value
    can no longer change) and checked to still hold within ``feas_tol``; a level with
    ``Z`` empty is only evaluated.

    Closed form first. Every level's QP is first solved without its rows: the minimiser of
    ``½‖M u + e‖² + ε/2‖x* + Z u‖²`` by Householder QR of the stacked ``[M; √ε I]`` (a
    regularised least-squares problem; not the normal equations ``MᵀM + εI``, whose condition
    number is squared). The level QP reuses that factor R: it is posed in w = R u, so the
    backend sees an identity Hessian (see :func:`_level_qp`). If it satisfies the level's own inequality rows and the relaxed higher rows, it
    is the QP's solution (the minimiser of a relaxation that is feasible, with zero slacks) and
    the backend is not called; otherwise the QP of eqs. 10-11 is solved. A level of equalities
    only, below no inequality, is thus exactly the least-squares problem its QP is. On the
    Table 2 stack (talos14) no QP is needed in ~98 % of the cycles; on Table 1 (talos) levels
    3-5 still need ~1.7 QPs per cycle. Seed 000 solves a QP per level; the optimum is the same.
    (Solving the QP on a growing working set of its rows — exact as well — was measured slower
    on Table 1: the set grew from 4 to ~20 rows over 2-3 QPs.) The implicit equalities below
    are looked for only when a QP is needed.

    Two numerical devices keep the QPs well posed without changing the optimal set by more
    than round-off:

    * implicit equalities. When a level pushes against higher-priority inequalities (or leaves
      own rows violated), those rows are, once its equalities are locked, pinned: their
      projected normals are positively dependent, the feasible cone of the next QP has an
      empty interior, and the backends report "inconsistent"/"infeasible" on rounding noise
      (plain eqs. 8-11: quadprog failed on 10 and DAQP on 12 of 20 random conflicting
      hierarchies). Such rows are detected geometrically — tight rows whose normalised
      normals admit a nonnegative null combination (NNLS, after two cheap certificates of
      independence) — and locked like equality rows. This is exact: the set is the same.
      Deciding it from multipliers or from the size of a violation was tried and rejected:
      rows active or violated only because of the ε term (O(ε‖x‖)) are then locked too, which
      is wrong by O(1) for the lower levels.
    * margin. Rows still tight at x* (or violated within ``feas_tol``, what a backend's
      tolerance leaves) are loosened to include x* with a margin ``relax_tol (1 + |C x*|)``
      (1e-9), so the next QP has an interior; costs move by O(relax_tol × multiplier). With
      the margin alone quadprog stopped failing, but ProxQP still failed on 91 of 300
      hierarchies; with both devices all three backends solve all test hierarchies.

    Compiled. ``wholebody._cascade.CascadeRun`` (src/wholebody/native/cascade.cpp) is this
    algorithm line for line in C++ (Eigen: Householder QR, QR with column pivoting, the same
    tolerances); it hands each level QP back to Python, where :func:`_backend_solve` calls the
    backend (and the fallback) exactly as the Python cascade does — except DAQP's, which it
    solves itself through DAQP's C interface with the adapter's rows, settings and verdict
    (:func:`_daqp_in_cascade`; bitwise the same results) — and calls scipy's NNLS for the
    implicit-equality search. It is the default when built (``compiled=True``); the Python
    cascade is the reference the tests compare it with (x to 1e-7 on the random hierarchies,
    torques to 1e-6 Nm on Tables 1/2). Results differ only by rounding: Eigen's and LAPACK's
    factorisations pivot alike but round differently.

    Nullspace by QR with column pivoting, not SVD: the kernel basis comes from LAPACK
    ``dgeqp3``/``dorgqr`` on ``(W_r B_r Z_r)ᵀ``; a direction is locked when ``|R_ii|`` exceeds
    ``rank_tol · max_i ‖W_i B_i‖`` (relative to the UNPROJECTED rows, so a row that is
    numerically a combination of already locked rows locks nothing). At these sizes QRCP is
    2-5× faster than a full SVD (e.g. 45 µs vs 230 µs for a 38×32 block, measured), which
    matters at 1 kHz. Its rank decision is reliable except on adversarial (Kahan-like)
    matrices; as a guard, whenever some ``|R_ii|`` falls within three decades of the threshold
    the kernel is recomputed with an SVD (the paper's choice), whose singular values are the
    exact measure.

    ε (``regularization``). The ε‖x‖² of eq. 5 makes every QP strictly convex (Goldfarb–Idnani
    needs a positive definite Hessian); reported costs exclude it, but x is the solution of the
    regularised cascade. Relative to the exact lexicographic optimum each level's cost is off
    by about ε‖x‖² plus what the ε-perturbed residuals/slacks of the higher levels cost it —
    O(ε ‖x‖ × multipliers), which can be large: with the paper's ε = 1e-4 and ‖x‖ ~ 10-100 a
    higher level's cost can even DROP below the value it had when that level was solved,
    because lower levels can move within its relaxed bound (measured on the test hierarchies:
    95 % of them within 1e-2 relative of the exact optimum). For control this is harmless.
    The tests therefore check two different things: (1) the cascade reproduces an
    independently formulated regularised cascade at the same ε (1e-4) to 1e-6; (2) with a
    small ε (1e-10) it reproduces the unregularised lexicographic optimum (oracle at ε = 1e-11,
    itself good to a few 1e-6): all within 1e-5, ≥ 98 % within 1e-6.

``daqp``
    DAQP's native hierarchical mode: all levels stacked in one constraint matrix with
    ``break_points``, equality rows with ``sense = 5``. Findings (DAQP 0.11; its
    ``src/hierarchical.c`` and docs, and experiments reproduced in the tests) on why its
    lower-level costs came out a few percent above the cascade's:

    1. Row normalisation — the cause of the few percent. DAQP works on the least-distance
       problem with every row of ``A R⁻¹`` (H = RᵀR) scaled to unit norm, and its soft penalty
       ``s²/(2·rho_soft)`` acts on the violation of the NORMALISED row. A level therefore
       minimises ``Σ_i (r_i / ‖a_i‖_{H⁻¹})²`` instead of ``Σ_i r_i²``: another compromise as soon
       as rows of a level conflict and have different norms. Rows ``x = 1`` and ``2x = 0`` give
       0.5 instead of 0.2. On random well-conditioned 3-level problems: median gap 2.4 %, 73 %
       of the cases above 0.1 %; native DAQP agrees (median 3e-7) with the cascade run on the
       row-normalised levels (:func:`row_normalised`). Row weights cannot undo it (a scaling is
       normalised away), the scale of H does not matter, it is not a tolerance, not the
       regularisation, and equalities need not be given as doubled inequalities (doing so
       only makes more level LDPs fail).
       Fix used here: one per-row soft weight ``rho_l = rho_u = 1e-8`` for all rows
       (``daqp.Model.soft_weights``), which DAQP applies in the ORIGINAL row scale: conflicts
       inside a level are then resolved by ``Σ s_i²`` as in eq. 5 (x = 0.2 above, for any ρ).
       ρ does not act like the cascade's ε: DAQP satisfies rows that can be satisfied (to about
       its primal tolerance) and ``½‖x‖²`` (H = I) only breaks ties, so it approximates the
       ε → 0 limit and ``regularization`` is not used by this method. Agreement with the
       cascade at ε = 1e-8: median 2e-8, ≥ 98 % of the problems within 1e-4.
       ``daqp_native_weights=True`` keeps DAQP's own penalty.
    2. The FIRST break-point block is hard: the driver softens only the later blocks. A first
       level with conflicting rows makes the setup fail (exitflag -6, "overdetermined") or
       returns exitflag 3 with x = 0. A free dummy row is passed as the first block here.
    3. Exitflag 3 is a failure in disguise: the driver returns it when a level's LDP fails,
       with x restored to an EARLIER level's solution and the remaining levels not optimised.
       Reported here as ``ok=False`` with that (finite) x. Frequency: ~1 % of well-posed random
       problems, ~3 % of the harsher random hierarchies of the tests.
    Per-level times are not available (one call).

``weighted``
    The single weighted QP (seed 001 eq. 7): ``levels = [hard, objective]`` as one QP with the
    hard level's rows as constraints — no nullspace, ~3× faster than the two-level cascade.
    Equal to the two-level cascade whenever the hard level is feasible, up to the ε effect of
    the cascade's soft first level (it trades an O(ε) violation for norm; the hard rows do
    not), i.e. exactly equal as ε → 0. If the hard level is infeasible (or the backend fails on
    the single QP, e.g. quadprog on inconsistent equality rows), the cascade result is returned
    instead, recorded in ``method`` and ``warnings``.
"""

from __future__ import annotations

import functools
import importlib.metadata
import inspect
import logging
import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.linalg import lapack, solve_triangular
from scipy.optimize import nnls

from .backends import (BACKENDS, DAQP_DEFAULTS, DAQP_EXIT, DAQP_RAW_TOL, QP_ERRORS,
                       daqp_verdict, solve_daqp, solve_daqp_unit_rows, solve_qp)
from .level import Level

try:  # the cascade, compiled (src/wholebody/native/cascade.cpp); optional
    from .._cascade import CascadeRun as _CompiledCascade
    from .._cascade import DAQP_C_VERSION as _DAQP_C_VERSION
    from .._cascade import DaqpSolver as _DaqpSolver
except ImportError:  # not built (no C++ compiler at install): the Python cascade does everything
    _CompiledCascade = _DaqpSolver = _DAQP_C_VERSION = None

__all__ = ["HierarchySolution", "FirstLevelSolution", "solve_hierarchy", "evaluate_levels",
           "row_normalised", "analytic_first_level", "BoundCascade"]

log = logging.getLogger(__name__)

_METHODS = ("cascade", "daqp", "weighted")
_DAQP_RHO = 1e-8  # per-row soft weight for the daqp method (its own hierarchical default)
_TIGHT_TOL = 1e-8  # a higher row is tight at x when |C x - bound| <= _TIGHT_TOL (1 + |C x|)


@dataclass
class HierarchySolution:
    """Result of :func:`solve_hierarchy`.

    ``costs[r] = ‖W_r(B_r x − b_r)‖² + ‖v_r‖²`` at the returned x (eq. 5 without ε);
    ``eq_residuals[r] = W_r(B_r x − b_r)``; ``ineq_violations[r] = v_r = V_r · violation ≥ 0``
    (weighted, as it enters the cost); ``timings = {"total": s, "levels": array of s}``, and
    for the compiled cascade also ``"qp"`` (s spent in the QP backends) and ``"qps"`` (their count)
    (per-level times are NaN for the daqp and weighted methods, which solve in one call).
    ``levels_solved`` counts the levels whose optimisation succeeded; ``nullspace_dims[r]`` is
    the number of free directions left after level r (cascade only);
    ``method`` is the method that produced x (``"cascade"`` after a weighted fallback).
    """

    x: np.ndarray
    costs: np.ndarray
    eq_residuals: list
    ineq_violations: list
    status: str
    ok: bool
    timings: dict
    method: str = "cascade"
    levels_solved: int = 0
    nullspace_dims: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    warnings: tuple = ()


# ---------------------------------------------------------------------------- helpers
def _check_levels(levels, n_hint=None) -> int:
    if len(levels) == 0:
        raise ValueError("solve_hierarchy: need at least one level")
    n = n_hint
    for i, L in enumerate(levels):
        if not isinstance(L, Level):
            raise ValueError(f"level {i}: expected a Level, got {type(L).__name__}")
        if L.n is None:
            continue
        if n is None:
            n = L.n
        elif L.n != n:
            part = "eq B" if L.n_eq else "ineq C"
            raise ValueError(f"Level {L.name!r} (index {i}): {part} has {L.n} columns, expected {n}")
    if n is None:
        raise ValueError("solve_hierarchy: every level is empty, the number of variables is unknown")
    return n


def _rows(L: Level, n: int):
    """(B, C) of a level with n columns, also for an empty level."""
    B = L.B if L.B.shape[1] == n else np.zeros((0, n))
    C = L.C if L.C.shape[1] == n else np.zeros((0, n))
    return B, C


def _row_norms(A: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->i", A, A))


def _sq_norms(A: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", A, A)


def evaluate_levels(levels, x):
    """Per-level costs, weighted residuals and weighted slacks at x (eq. 5 without ε)."""
    costs = np.empty(len(levels))
    res, vio = [], []
    empty = np.zeros(0)
    for i, L in enumerate(levels):
        r = L.eq_residual(x) if L.n is not None and L.B.shape[0] else empty
        s = L.ineq_violation(x) if L.n is not None and L.C.shape[0] else empty
        res.append(r)
        vio.append(s)
        costs[i] = r @ r + s @ s
    return costs, res, vio


def _finish(levels, x, status, ok, t_start, level_times, method, solved, zdims, warns):
    costs, res, vio = evaluate_levels(levels, x)
    return HierarchySolution(
        x=x, costs=costs, eq_residuals=res, ineq_violations=vio, status=status, ok=ok,
        timings={"total": time.perf_counter() - t_start, "levels": level_times},
        method=method, levels_solved=solved, nullspace_dims=np.asarray(zdims, dtype=int),
        warnings=tuple(warns),
    )


# ---------------------------------------------------------------------------- public API
def _checked_arguments(levels, method, backend, regularization, first_level_solution,
                       fallback_backend):
    """solve_hierarchy's argument checks → (levels as a list, n, first_level_solution,
    fallback_backend); ValueError naming what is wrong."""
    levels = [levels] if isinstance(levels, Level) else list(levels)
    if method not in _METHODS:
        raise ValueError(f"unknown method {method!r}; choose from {_METHODS}")
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose from {sorted(BACKENDS)}")
    if fallback_backend is not None and fallback_backend not in BACKENDS:
        raise ValueError(f"unknown fallback_backend {fallback_backend!r}; choose from {sorted(BACKENDS)}")
    if fallback_backend == backend:
        fallback_backend = None
    if not (np.isfinite(regularization) and regularization > 0):
        raise ValueError(f"regularization must be finite and > 0, got {regularization!r}")
    n_hint = None
    analytic = isinstance(first_level_solution, str)
    if first_level_solution is not None:
        if method != "cascade":
            raise ValueError("first_level_solution is only supported by method='cascade'")
        if analytic:
            if first_level_solution != "analytic":
                raise ValueError(f"first_level_solution: expected (x1, Z1) or 'analytic', got "
                                 f"{first_level_solution!r}")
            if not levels or not isinstance(levels[0], Level) or levels[0].n_eq == 0:
                raise ValueError("first_level_solution='analytic' needs equality rows in level 1")
        else:
            first_level_solution = _check_first_level(first_level_solution)
            n_hint = first_level_solution[0].shape[0]
    n = _check_levels(levels, n_hint)
    return levels, n, first_level_solution, fallback_backend


def solve_hierarchy(
    levels,
    method: str = "cascade",
    backend: str = "quadprog",
    regularization: float = 1e-4,
    *,
    first_level_solution=None,
    rank_tol: float = 1e-9,
    drop_tol: float = 1e-9,
    relax_tol: float = 1e-9,
    feas_tol: float = 1e-6,
    backend_options: dict | None = None,
    daqp_native_weights: bool = False,
    fallback_backend: str | None = None,
    compiled: bool = True,
) -> HierarchySolution:
    """Lexicographic optimum of a list of :class:`Level` (Herzog et al. 2016, eqs. 5-11).

    Parameters
    ----------
    levels : highest priority first.
    method : ``"cascade"`` (reference, eqs. 8-11), ``"daqp"`` (DAQP's hierarchical mode) or
        ``"weighted"`` (one QP over ``levels = [hard, objective]``); see the module docstring.
    backend : QP backend of the cascade / weighted QPs: ``quadprog``, ``daqp`` or ``proxsuite``.
    regularization : ε of eq. 5 (> 0) for the cascade and weighted QPs (not used by ``daqp``).
        Costs are reported without it; the module docstring says how far it moves them from
        the exact lexicographic optimum.
    first_level_solution : optional ``(x1, Z1)`` replacing the first level's QP (the analytic
        first priority of §2.4, eq. 17): ``x1`` one solution of level 1 and ``Z1`` a basis of the
        directions it leaves free (orthonormalised here if it is not). Level 1's inequalities
        are then imposed on the lower levels with zero slack (v*_1 = 0, §2.4). ``"analytic"``
        computes them here from level 1's weighted equality rows
        (:func:`analytic_first_level`; inside the compiled cascade when it runs).
    rank_tol : a direction is locked when its |R_ii| (QRCP) exceeds ``rank_tol`` times the
        largest norm of the rows being locked.
    drop_tol : an inequality row has no freedom left when ``‖C_i Z‖ ≤ drop_tol ‖C_i‖``.
    relax_tol : margin by which rows tight at x* are loosened for the next level.
    feas_tol : tolerance for checking dropped rows and the weighted method's hard level.
    backend_options : extra keyword arguments for the backend (``eps_abs`` for proxsuite,
        DAQP settings for ``daqp`` and the daqp method).
    daqp_native_weights : method ``daqp`` only — use DAQP's native (row-normalised) soft
        penalty instead of uniform per-row weights (which give eq. 5's Σ s² trade-off).
    fallback_backend : cascade only — a level QP that ``backend`` fails on is solved again with
        this backend (same QP, so the same optimum), recorded in ``warnings``. Cheaper than
        re-solving the whole cascade: each backend has rare failures of its own on these
        ill-conditioned QPs (DAQP: cycling/infeasible verdicts on ~10-20 % of Table 1 cycles).
    compiled : cascade only — run the compiled cascade (``wholebody._cascade``, when built): the
        same algorithm line for line, with the level QPs still solved by ``backend`` (and
        ``fallback_backend``) from Python; ~3x faster on the Tables 1/2 stacks. ``False`` runs
        the Python cascade (the reference). Warnings from the compiled cascade list its own
        (frozen rows) before the fallback notes.

    Bad input (NaN/inf in data, inconsistent column counts, unknown names) raises ValueError
    naming the level and field. Numerical failures never raise: the solution is flagged
    (``ok=False``, ``status`` says why) and ``x`` is the last successful level's (finite) x.
    """
    t0 = time.perf_counter()
    levels, n, first_level_solution, fallback_backend = _checked_arguments(
        levels, method, backend, regularization, first_level_solution, fallback_backend)
    analytic = isinstance(first_level_solution, str)
    opts = dict(backend_options or {})
    tols = (rank_tol, drop_tol, relax_tol, feas_tol)

    if method == "daqp":
        return _solve_daqp(levels, n, opts, t0, uniform_soft_weights=not daqp_native_weights)
    if method == "weighted":
        if len(levels) > 2:
            raise ValueError(f"method 'weighted' takes [hard, objective] levels, got {len(levels)} levels")
        sol = _solve_weighted(levels, n, backend, regularization, feas_tol, opts, t0)
        if sol is not None:
            return sol
        warn = "weighted: hard level infeasible or the single QP failed; result of the cascade"
        log.debug(warn)
        sol = _solve_cascade(levels, n, backend, regularization, None, tols, opts, t0, fallback_backend)
        sol.warnings = (warn,) + sol.warnings
        return sol
    if compiled and _CompiledCascade is not None:
        return _solve_compiled(levels, n, backend, regularization, first_level_solution, tols, opts,
                               t0, fallback_backend)
    if analytic:
        first_level_solution = analytic_first_level(levels[0])
    return _solve_cascade(levels, n, backend, regularization, first_level_solution, tols, opts, t0,
                          fallback_backend)


def _solve_compiled(levels, n, backend, eps, fls, tols, opts, t0, fallback=None):
    """The cascade compiled (``wholebody._cascade.CascadeRun``, a line-for-line mirror of
    :func:`_solve_cascade`, including :func:`_implicit_equalities` with scipy's NNLS passed in):
    it runs the levels and hands back each level QP, solved here by ``backend``, then
    ``fallback``, exactly as the Python cascade does (DAQP's QPs are solved in C++ when
    :func:`_daqp_in_cascade` allows it, with the same rows, settings and verdict)."""
    return _run_compiled(_new_run(levels, n, eps, fls, tols), levels, backend, opts, fallback, t0,
                         _daqp_in_cascade(backend, opts))


def _new_run(levels, n, eps, fls, tols):
    """A compiled cascade run on the arrays of ``levels`` (held, not copied)."""
    analytic = isinstance(fls, str)
    x1, Z1 = fls if fls is not None and not analytic else (None, None)
    return _CompiledCascade([L.B for L in levels], [L.b for L in levels], [L.w for L in levels],
                            [L.C for L in levels], [L.lower for L in levels],
                            [L.upper for L in levels], [L.v for L in levels],
                            [L.name for L in levels], n, eps, x1, Z1, analytic, *tols, nnls)


def _run_compiled(run, levels, backend, opts, fallback, t0, daqp=None):
    """Drives a compiled run from its first level: its level QPs solved by ``backend``, then
    ``fallback`` → HierarchySolution. ``daqp`` (a :func:`_daqp_in_cascade` solver) lets the run
    solve them with DAQP itself; the QPs it leaves (DAQP failed, or no rows) come back here."""
    warns = []
    qp_times = None  # of the QPs solved here (not by the run), per level
    n_qps = 0
    direct_daqp = BACKENDS.get(backend) is solve_daqp
    daqp = daqp if direct_daqp else None  # a test may have replaced the adapter since
    advance = run.advance if daqp is None else functools.partial(run.advance_daqp, daqp)
    while (kind := advance()) == "qp":
        tq = time.perf_counter()
        r = run.level
        if daqp is not None and run.daqp_status:  # DAQP failed on it in the run (counted there)
            first = (None, run.daqp_status, False)
        else:
            n_qps += 1
            first = _daqp_on_run(run, opts) if direct_daqp else None
        y, ok, status = _backend_solve(_identity_qp(run), backend, opts, fallback, r, levels,
                                       warns, first)
        if qp_times is None:
            qp_times = np.zeros(len(levels))
        qp_times[r] += time.perf_counter() - tq  # (give_qp's end of the level is cascade work)
        run.give_qp(y if ok else None, status)
    x, costs, res, vio, level_times, qp_time, run_qps, dims, run_warns, level, status = run.result()
    if qp_times is not None:
        level_times += qp_times
        qp_time += float(qp_times.sum())
    ok = kind == "done"
    return HierarchySolution(
        x=x, costs=costs, eq_residuals=res, ineq_violations=vio,
        status="optimal" if ok else status, ok=ok,
        timings={"total": time.perf_counter() - t0, "levels": level_times, "qp": qp_time,
                 "qps": n_qps + run_qps},
        method="cascade", levels_solved=level, nullspace_dims=dims,
        warnings=run_warns + tuple(warns) if warns else run_warns,
    )


class BoundCascade:
    """The compiled cascade bound to the arrays of ``levels``: solve, change the arrays'
    contents in place, solve again — a control loop's level buffers (see
    :class:`wholebody.cycle.HierarchyCycle`) — without :func:`solve_hierarchy`'s per-call
    argument checks and array hand-over (~15 µs a Table 1 cycle).

    Arguments as :func:`solve_hierarchy` with ``method="cascade"``; :meth:`solve` returns what
    ``solve_hierarchy(levels, ...)`` would for the arrays' current contents. The arrays must keep
    their shapes and stay finite (checked by the caller: nothing is copied or re-checked here).
    Needs the compiled cascade (:data:`available`).
    """

    available = _CompiledCascade is not None

    def __init__(self, levels, backend: str = "quadprog", regularization: float = 1e-4, *,
                 first_level_solution=None, fallback_backend: str | None = None,
                 rank_tol: float = 1e-9, drop_tol: float = 1e-9, relax_tol: float = 1e-9,
                 feas_tol: float = 1e-6, backend_options: dict | None = None):
        if _CompiledCascade is None:
            raise RuntimeError("BoundCascade needs the compiled cascade (wholebody._cascade), "
                               "which is not built")
        levels, n, fls, fallback = _checked_arguments(
            levels, "cascade", backend, regularization, first_level_solution, fallback_backend)
        for L in levels:  # held, not copied: a converted copy would never see the new contents
            for field_name in ("B", "b", "w", "C", "lower", "upper", "v"):
                a = getattr(L, field_name)
                if a.dtype != np.float64 or not a.flags.c_contiguous:
                    raise ValueError(f"BoundCascade: level {L.name!r} {field_name}: needs a "
                                     f"C-contiguous float64 array (it is held, not copied)")
        self.levels, self.backend, self.fallback_backend = levels, backend, fallback
        self._opts = dict(backend_options or {})
        self._run = _new_run(levels, n, regularization, fls,
                             (rank_tol, drop_tol, relax_tol, feas_tol))
        self._daqp = _daqp_in_cascade(backend, self._opts)

    def solve(self) -> HierarchySolution:
        """The cascade on the arrays' current contents."""
        t0 = time.perf_counter()
        self._run.reset()
        return _run_compiled(self._run, self.levels, self.backend, self._opts,
                             self.fallback_backend, t0, self._daqp)


def _daqp_on_run(run, opts):
    """DAQP on the compiled cascade's pending level QP, (y, status, ok) as ``solve_daqp`` gives
    them: the run scales the rows (``run.daqp_qp``) and checks the unscaled ones
    (``run.qp_violation``), which saves the generic adapter's array round trips (~10 µs a QP).
    None when the QP has no rows (the adapter's special case)."""
    g, unit_A, bu, bl, sense = run.daqp_qp()
    if unit_A.shape[0] == 0:
        return None
    opts = dict(opts)
    raw_tol = opts.pop("raw_tol", DAQP_RAW_TOL)
    try:
        x, status = solve_daqp_unit_rows(np.eye(g.shape[0]), g, unit_A, bu, bl, sense, **opts)
    except QP_ERRORS as exc:  # as solve_qp: never raises for numerical reasons
        return None, f"daqp: {type(exc).__name__}: {exc}", False
    return daqp_verdict(x, status, run.qp_violation(x) if x is not None else 0.0, raw_tol)


def _daqp_in_cascade(backend, opts):
    """A ``wholebody._cascade.DaqpSolver`` with which a compiled run solves its level QPs itself
    (``CascadeRun.advance_daqp``: the stock DAQP adapter's rows, settings, retry and verdict in
    C++, ~20 µs less a QP than :func:`_daqp_on_run`), or None: ``backend`` is not the stock DAQP
    adapter, an option is not a DAQP setting, or DAQP's C interface is not usable
    (:func:`_daqp_c_module`). Then the QPs are solved from Python, with the same results."""
    if BACKENDS.get(backend) is not solve_daqp or (path := _daqp_c_module()) is None:
        return None
    settings = {**DAQP_DEFAULTS, **opts}
    raw_tol = settings.pop("raw_tol", DAQP_RAW_TOL)
    try:
        return _DaqpSolver(path, settings, DAQP_EXIT, raw_tol)
    except (ValueError, TypeError):  # e.g. an option daqp.solve takes that is no setting
        return None


@functools.cache
def _daqp_c_module() -> str | None:
    """The file of the daqp module whose C solver the compiled cascade may call, or None.

    ``cascade.cpp`` declares DAQP's C structures as one daqp version defines them
    (``DAQP_C_VERSION``); they are used only with that version installed, and only if the
    defaults read through them (``daqp_default_settings``) equal ``daqp.solve``'s keyword
    defaults, field by field: a layout that differs would show there first."""
    if _DaqpSolver is None:
        return None
    try:
        import daqp

        version = importlib.metadata.version("daqp")
    except (ImportError, importlib.metadata.PackageNotFoundError):
        return None
    if version != _DAQP_C_VERSION:
        log.info("daqp %s: level QPs go through Python (DAQP's C interface is declared for %s)",
                 version, _DAQP_C_VERSION)
        return None
    try:
        read = _DaqpSolver(daqp.__file__, {}, {}, DAQP_RAW_TOL).settings()
        defaults = inspect.signature(daqp.solve).parameters
        expected = {name: float(defaults[name].default) for name in read}
    except (ValueError, TypeError, KeyError) as exc:
        log.warning("DAQP's C interface not usable (%s): level QPs go through Python", exc)
        return None
    if read != expected:
        log.warning("DAQP's C settings differ from daqp.solve's defaults (%s vs %s): level QPs go "
                    "through Python", read, expected)
        return None
    return daqp.__file__


def _identity_qp(run):
    """The pending QP of a compiled run as (H, g, A, lower, upper), H = I, built when called."""
    def qp():
        g, A, lower, upper = run.qp()
        return np.eye(g.shape[0]), g, A, lower, upper
    return qp


def _backend_solve(qp, backend, opts, fallback, r, levels, warns, first=None):
    """The level QP ``qp()`` → (H, g, A, lower, upper) with ``backend``, then ``fallback`` if it
    fails → (y, ok, status); a fallback success is recorded in ``warns``. ``first``, if given, is
    the backend's (y, status, ok) already computed (then ``qp`` is called only for the fallback)."""
    y, status, ok = first if first is not None else solve_qp(*qp(), backend=backend, **opts)
    if not ok and fallback is not None:
        y, status2, ok = solve_qp(*qp(), backend=fallback)
        if ok:
            msg = f"level {r} ({levels[r].name!r}): {status}; solved with {fallback}"
            log.debug(msg)
            warns.append(msg)
        else:
            status = f"{status}; {status2}"
    return y, ok, status


def analytic_first_level(level: Level) -> "FirstLevelSolution":
    """x1 = Bᵀ(B Bᵀ)⁻¹ b (least norm) and an orthonormal null-space basis Z1 of level 1's
    weighted rows B = W B_1, b = W b_1 (Herzog et al. 2016 §2.4, eq. 17: no QP for level 1).

    For Newton-Euler rows B has full row rank (the base block of M is positive definite) and the
    Gram matrix is SPD; both come from one complete QR of Bᵀ = [Q1 Q2] [R; 0] (LAPACK
    dgeqrf/dorgqr): since B Bᵀ = RᵀR, x1 = Q1 R⁻ᵀ b and Z1 = Q2 spans null(B). A rank-deficient
    B (some |R_ii| ≤ 1e-12 max |R_jj|) takes the least-squares formulas instead (Z1 then keeps
    n − k columns: the dependent rows' directions are not freed).
    """
    w = level.w
    k = w.shape[0]
    if k == 0:
        raise ValueError(f"level {level.name!r}: the analytic first level needs equality rows")
    Bt = np.array((level.B * w[:, None]).T, order="F")
    qr, tau, _, info = lapack.dgeqrf(Bt, overwrite_a=True)
    d = np.abs(qr.diagonal()[:k])
    if info == 0 and (k > Bt.shape[0] or not d.min() > 1e-12 * d.max()):
        info = -1  # (numerically) rank-deficient
    if info == 0:
        q = np.zeros((Bt.shape[0], Bt.shape[0]), order="F")
        q[:, :k] = qr
        Q, _, info = lapack.dorgqr(q, tau, overwrite_a=True)
        if info == 0:  # Rᵀ y = b with R the upper triangle of qr (dtrtrs reads only that)
            y, info = lapack.dtrtrs(qr[:k], level.b * w, lower=0, trans=1)
    if info != 0 or not np.isfinite(y).all():  # rank-deficient B: the plain formulas
        B = level.B * w[:, None]
        x1 = B.T @ np.linalg.lstsq(B @ B.T, level.b * w, rcond=None)[0]
        Q, _ = np.linalg.qr(B.T, mode="complete")
        return FirstLevelSolution(x1, Q[:, k:])
    return FirstLevelSolution(Q[:, :k] @ y, Q[:, k:])  # orthonormal by construction


class FirstLevelSolution(NamedTuple):
    """``first_level_solution`` from a caller that guarantees ``x1`` finite and ``Z1`` finite
    with orthonormal columns (e.g. from a QR, as :class:`~wholebody.formulation.Formulation`
    does every cycle): the checks of a plain ``(x1, Z1)`` pair are skipped."""

    x1: np.ndarray
    Z1: np.ndarray


def _check_first_level(fls):
    if isinstance(fls, FirstLevelSolution):
        return fls.x1, fls.Z1
    if not isinstance(fls, (tuple, list)) or len(fls) != 2:
        raise ValueError("first_level_solution must be a pair (x1, Z1)")
    x1 = np.asarray(fls[0], dtype=float).reshape(-1)
    Z1 = np.asarray(fls[1], dtype=float)
    if Z1.ndim != 2 or Z1.shape[0] != x1.shape[0]:
        raise ValueError(f"first_level_solution: Z1 has shape {Z1.shape}, expected ({x1.shape[0]}, z)")
    if not np.isfinite(x1.sum()) and not np.isfinite(x1).all():
        raise ValueError("first_level_solution: x1 contains NaN or inf")
    z = Z1.shape[1]
    G = Z1.T @ Z1  # (also the finiteness check of Z1: a NaN/inf entry spreads into G)
    if not np.isfinite(G.sum()) and not np.isfinite(Z1).all():
        raise ValueError("first_level_solution: Z1 contains NaN or inf")
    if z:
        G.flat[:: z + 1] -= 1.0
        if not np.abs(G).max() <= 1e-10:  # not orthonormal: an orthonormal basis of the same range
            U, s, _ = np.linalg.svd(Z1, full_matrices=False)
            Z1 = U[:, s > 1e-12 * max(1.0, s[0])]
    return x1, np.ascontiguousarray(Z1)


# ---------------------------------------------------------------------------- cascade
def _solve_cascade(levels, n, backend, eps, fls, tols, opts, t0, fallback=None):
    """The cascade (module docstring); the reference for its compiled mirror (_solve_compiled)."""
    rank_tol, drop_tol, relax_tol, feas_tol = tols
    drop2 = drop_tol * drop_tol  # freedom tests on squared norms: ‖C_i Z‖² > drop_tol² ‖C_i‖²
    nl = len(levels)
    times = np.zeros(nl)
    zdims = np.zeros(nl, dtype=int)
    warns: list[str] = []
    x = np.zeros(n)
    Z = None  # None stands for the identity: nothing locked yet
    z = n
    # higher-priority inequality rows that still have freedom: (C, relaxed lower, relaxed upper
    # (eq. 9), drop_tol² ‖C_i‖²), or None while there are none
    high = None
    HZ = hx = hb = None

    for r, L in enumerate(levels):
        tl = time.perf_counter()
        B, C = _rows(L, n)
        m = C.shape[0]

        if r == 0 and fls is not None:  # analytic first priority (§2.4, eq. 17), v*_1 = 0
            x, Z = fls[0].copy(), fls[1]
            z = Z.shape[1]
            if m:
                CZ1 = C @ Z if z else np.zeros((m, 0))
                high, _ = _drop_frozen((C, L.lower, L.upper, drop2 * _sq_norms(C)), CZ1, x,
                                       feas_tol, L, warns)
            zdims[0], times[0] = z, time.perf_counter() - tl
            continue
        if z == 0:  # no freedom left: the level is only evaluated
            zdims[r], times[r] = 0, time.perf_counter() - tl
            continue

        # ---- higher rows: drop those without freedom; rows tight at x* get a margin (loosened)
        tight = False
        if high is not None:
            high, HZ = _drop_frozen(high, high[0] if Z is None else high[0] @ Z, x, feas_tol, L,
                                    warns)
        if high is not None:
            hx = high[0] @ x
            gap = np.minimum(hx - high[1], high[2] - hx)  # < 0: violated (within tolerance)
            tight = not (gap > max(_TIGHT_TOL, relax_tol) * (1.0 + np.abs(hx))).all()
            hb = _loosen_tight(hx, high[1], high[2], relax_tol, feas_tol) if tight else high[1:3]

        # ---- project the level onto the remaining freedom x = x* + Z u (eq. 8); its
        # unconstrained minimiser (QR least squares) is tried first: if it satisfies the level's own rows
        # and the relaxed higher rows, it is the QP's solution (the minimiser of a relaxation,
        # feasible with zero slacks) and no QP is solved. A level of equalities below no
        # inequality is always solved so: its QP (eq. 10) is exactly a regularised least-squares
        # problem.
        wB, M, own, ls = _project_level(L, B, C, Z, z, x, eps, drop2)
        u, ok, status, Rc = _unconstrained(*ls, eps)
        rows = _qp_rows(own, high, HZ, hx, hb, x, z) if (own is not None or high is not None) else None
        solved = ok and (rows is None or not _violated(rows, u))
        if not solved and tight:
            # implicit equalities (module docstring) keep the QP well posed: looked for only when
            # a QP is solved — the optimal set is the same with or without locking them
            imp = _implicit_equalities(HZ, hx, high[1], high[2])
            if imp is not None:
                Z, z = _lock(Z, high[0][imp], None, rank_tol)
                keep = ~imp
                high = tuple(a[keep] for a in high) if keep.any() else None
                if z == 0:
                    zdims[r], times[r] = 0, time.perf_counter() - tl
                    continue
                if high is not None:
                    high, HZ = _drop_frozen(high, high[0] @ Z, x, feas_tol, L, warns)
                    if high is not None:
                        hx = high[0] @ x
                        hb = _loosen_tight(hx, high[1], high[2], relax_tol, feas_tol)
                wB, M, own, ls = _project_level(L, B, C, Z, z, x, eps, drop2)
                u, ok, status, Rc = _unconstrained(*ls, eps)
                rows = (_qp_rows(own, high, HZ, hx, hb, x, z)
                        if (own is not None or high is not None) else None)
                solved = ok and (rows is None or not _violated(rows, u))
        if not solved and rows is not None:
            u, ok, status = _level_qp(Rc, *rows, lambda *qp: _backend_solve(
                lambda: qp, backend, opts, fallback, r, levels, warns))
        if high is not None:  # the margins stay for the lower levels
            high = (high[0], hb[0], hb[1], high[3])
        if not ok:
            times[r] = time.perf_counter() - tl
            status = f"level {r} ({L.name!r}): {status}"
            log.debug("cascade failed: %s", status)
            return _finish(levels, x, status, False, t0, times, "cascade", r, zdims[:r], warns)
        x = x + (u if Z is None else Z @ u)

        # ---- this level's free inequality rows join the higher ones, relaxed by v* (eq. 9)
        if own is not None:
            Co, lo, up, nCo = own[0], own[2], own[3], own[5]
            cx = Co @ x
            viol = np.maximum(np.maximum(lo - cx, cx - up), 0.0)
            if high is None:
                high = (Co, lo - viol, up + viol, nCo)
            else:
                high = (np.concatenate((high[0], Co)), np.concatenate((high[1], lo - viol)),
                        np.concatenate((high[2], up + viol)), np.concatenate((high[3], nCo)))
        # ---- lock the directions of the weighted equality rows: Z_{r+1} = Z_r N_r (eq. 8);
        # after the last level nobody needs the null space (saves a QR/SVD per cycle)
        if wB.shape[0] and r < nl - 1:
            Z, z = _lock(Z, wB, M, rank_tol)
        zdims[r], times[r] = z, time.perf_counter() - tl

    return _finish(levels, x, "optimal", True, t0, times, "cascade", nl, zdims, warns)


def _project_level(L, B, C, Z, z, x, eps, drop2):
    """The level over x = x* + Z u (eq. 8): weighted rows W B, M = W B Z, its own inequality rows
    that still have freedom: (C, C Z, lower, upper, V, drop_tol² ‖C_i‖²) or None, and the data
    (M, r0 = W(B x* − b), Zᵀx*) of ½‖M u + r0‖² + ε/2 ‖x* + Z u‖² for :func:`_unconstrained`."""
    wB = L.w[:, None] * B
    if Z is None:
        M, zx = wB, x
    else:
        M, zx = wB @ Z, Z.T @ x
    r0 = wB @ x - L.w * L.b
    own = None
    if C.shape[0]:  # own rows without freedom keep their (fixed) violation: no slack
        CZ = C if Z is None else C @ Z
        nC = drop2 * _sq_norms(C)
        free = _sq_norms(CZ) > nC
        if free.all():
            own = (C, CZ, L.lower, L.upper, L.v, nC)
        elif free.any():
            own = (C[free], CZ[free], L.lower[free], L.upper[free], L.v[free], nC[free])
    return wB, M, own, (M, r0, zx)


def _qp_rows(own, high, HZ, hx, hb, x, z):
    """The rows of the level QP in u: own (C Z, C x*, lower, upper, V), higher (H Z, H x*,
    relaxed lower, relaxed upper) — the argument list of :func:`_level_qp` after (R, c)."""
    empty = np.zeros(0)
    own_qp = ((np.zeros((0, z)), empty, empty, empty, empty) if own is None
              else (own[1], own[0] @ x, own[2], own[3], own[4]))
    high_qp = ((np.zeros((0, z)), empty, empty, empty) if high is None else (HZ, hx, hb[0], hb[1]))
    return own_qp + high_qp


def _violated(rows, u) -> bool:
    """Some own or higher row of the level QP is violated at u (exactly, no tolerance)."""
    CZ, c0, lo, up, _, HZ, h0, hlo, hup = rows
    return bool(_outside(CZ, c0, lo, up, u).any() or _outside(HZ, h0, hlo, hup, u).any())


def _outside(A, a0, lower, upper, u):
    """Mask of the rows with A u + a0 outside [lower, upper] (exactly, no tolerance)."""
    v = A @ u
    v += a0
    return (v < lower) | (v > upper)


def _kernel(RZ: np.ndarray, tol: float) -> np.ndarray:
    """Orthonormal basis of ker(RZ) (k×z): QR with column pivoting of RZᵀ, SVD if ambiguous."""
    k, z = RZ.shape
    qr, _, tau, _, info = lapack.dgeqp3(np.array(RZ.T, order="F"))
    p = min(k, z)
    d = np.abs(qr.diagonal()[:p])
    rank = int(np.count_nonzero(d > tol))
    if info != 0 or ((d > 1e-3 * tol) & (d < 1e3 * tol)).any():
        # |R_ii| near the threshold: let the singular values decide (exact rank measure)
        U, s, _ = np.linalg.svd(RZ.T, full_matrices=True)
        return U[:, int(np.count_nonzero(s > tol)):]
    if rank == 0:
        return np.eye(z)
    if rank >= z:
        return np.zeros((z, 0))
    a = np.zeros((z, z), order="F")
    a[:, :p] = qr[:, :p]
    t = np.zeros(z)
    t[:p] = tau[:p]
    q, _, info = lapack.dorgqr(a, t, overwrite_a=True)
    if info != 0:
        U, s, _ = np.linalg.svd(RZ.T, full_matrices=True)
        return U[:, int(np.count_nonzero(s > tol)):]
    return q[:, rank:]


def _lock(Z, rows, projected, rank_tol):
    """Restrict Z to the kernel of ``rows``: Z ← Z N (eq. 8). ``projected`` is ``rows Z`` if
    already computed (None: computed here). Returns (Z, z)."""
    z = rows.shape[1] if Z is None else Z.shape[1]
    if rows.shape[0] == 0 or z == 0:
        return Z, z
    scale = math.sqrt(float(_sq_norms(rows).max()))
    if scale == 0.0:
        return Z, z
    if projected is None:
        projected = rows if Z is None else rows @ Z
    N = _kernel(projected, rank_tol * scale)
    if N.shape[1] == z:
        return Z, z
    Z = N if Z is None else Z @ N
    return Z, Z.shape[1]


def _implicit_equalities(HZ, hx, hlo, hup, tight_tol=_TIGHT_TOL, dep_tol=1e-7):
    """Rows tight at x whose signed, projected, normalised normals are positively dependent.

    With g_i = ±C_i Z oriented so that staying feasible near x means g_i d ≥ 0, a tight row i is
    an implicit equality of {d : g_j d ≥ 0} iff some y ≥ 0 with y_i > 0 has Σ y_j g_j = 0.
    Found by NNLS (min ‖Gᵀy‖ with Σy = 1 enforced by a heavy row); each dependency found is
    projected out and the search repeated. Purely geometric: a row that is tight only because
    of the ε term is locked only if the geometry really pins it. Returns a mask, or None when
    no row is an implicit equality.
    """
    m = HZ.shape[0]
    if m < 2:
        return None
    tol = tight_tol * (1.0 + np.abs(hx))
    tl = np.abs(hx - hlo) <= tol  # (a row violated at x — possible after §2.4 — is not tight)
    tu = np.abs(hup - hx) <= tol
    nt = int(np.count_nonzero(tl)) + int(np.count_nonzero(tu))
    if nt < 2:
        return None
    idx = np.concatenate((np.flatnonzero(tl), np.flatnonzero(tu)))
    G = np.concatenate((HZ[tl], -HZ[tu]))
    nrm = _row_norms(G)
    good = nrm > 0.0
    idx, G = idx[good], G[good] / nrm[good, None]
    # cheap certificate of NO dependency: a direction d with G d > 0 (Σ y_j g_j·d > 0 for y ≥ 0)
    d = G.sum(axis=0)
    if np.all(G @ d > dep_tol):
        return None
    GGt = G @ G.T
    GGt.flat[:: GGt.shape[0] + 1] += 1e-10 * GGt.shape[0]
    # d = Gᵀ (G Gᵀ)⁻¹ 1, i.e. G d ≈ 1 when the rows are independent (G Gᵀ SPD then: Cholesky)
    _, y, info = lapack.dposv(GGt, np.ones(G.shape[0]))
    if info == 0:
        d = G.T @ y
        if (G @ d > dep_tol).all():
            return None
    found = np.zeros(idx.shape[0], dtype=bool)
    P = None  # orthonormal basis of the span of the rows found so far
    while idx.shape[0] - np.count_nonzero(found) >= 2:
        rest = np.flatnonzero(~found)
        Gr = G[rest] if P is None else G[rest] - (G[rest] @ P) @ P.T
        k, z = Gr.shape
        A = np.empty((z + 1, k))
        A[:z] = Gr.T
        A[z] = 1e3
        b = np.zeros(z + 1)
        b[z] = 1e3
        try:
            y, _ = nnls(A, b)
        except (RuntimeError, ValueError):
            break
        ys = y.sum()
        if ys <= 0.0 or np.linalg.norm(Gr.T @ y) > dep_tol * ys:
            break
        found[rest[y > 1e-9 * y.max()]] = True
        P = _range_basis(G[found].T)
        # a tight row in the span of implicit equalities is one too (g·d = 0 on every feasible
        # d): taken at once rather than one NNLS each (its projected row is ~0, a dependency
        # of one row)
        rest = np.flatnonzero(~found)
        spanned = _row_norms(G[rest] - (G[rest] @ P) @ P.T) <= dep_tol
        found[rest[spanned]] = True
    if not found.any():
        return None
    out = np.zeros(m, dtype=bool)
    out[idx[found]] = True
    return out


def _range_basis(A):
    """Orthonormal columns spanning range(A) (A is z × k): Q of a QR of A (LAPACK dgeqrf/dorgqr)
    without the columns whose |R_ii| ≤ 1e-12."""
    z, k = A.shape
    p = min(z, k)
    qr, tau, _, info = lapack.dgeqrf(A)
    if info == 0:
        keep = np.abs(qr.diagonal()[:p]) > 1e-12
        Q, _, info = lapack.dorgqr(qr[:, :p], tau[:p], overwrite_a=True)
    if info != 0:
        Q, R = np.linalg.qr(A)
        keep = np.abs(R.diagonal()) > 1e-12
    return Q[:, keep]


def _loosen_tight(hx, hlo, hup, relax_tol, feas_tol):
    """Widen the bounds of rows tight at x so that they include C x with a margin δ = relax_tol
    (1 + |C x|): the next QP then has an interior and x* is feasible for it. Tight: within δ of
    a bound, or beyond it by at most the backends' feasibility tolerance feas_tol (1 + |C x|) —
    the violation a higher level's QP left within its tolerance is kept, as eq. 9 keeps a
    level's optimal violation. (Without the second part, a row left violated by ~1e-8 by DAQP
    made the next level's QP infeasible for DAQP and quadprog alike: 3 of 300 Table 1 cycles.)
    Rows violated by more (e.g. torque limits at the analytic first level's x1) stay hard."""
    a = 1.0 + np.abs(hx)
    dlt, out = relax_tol * a, feas_tol * a
    tl = (hx - hlo <= dlt) & (hlo - hx <= out)
    tu = (hup - hx <= dlt) & (hx - hup <= out)
    if tl.any():
        hlo = hlo.copy()
        hlo[tl] = np.minimum(hlo[tl], hx[tl]) - dlt[tl]
    if tu.any():
        hup = hup.copy()
        hup[tu] = np.maximum(hup[tu], hx[tu]) + dlt[tu]
    return hlo, hup


def _drop_frozen(high, HZ, x, feas_tol, L, warns):
    """Drop higher rows with ‖C_i Z‖ ≤ drop_tol ‖C_i‖ (no freedom left), checking they still hold.

    ``high = (C, lower, upper, drop_tol² ‖C_i‖²)``; returns ``(high, HZ)`` restricted to the rows
    with freedom (``high`` None if there is none left).
    """
    free = _sq_norms(HZ) > high[3]
    if free.all():
        return high, HZ
    hC, hlo, hup, hn = high
    gone = ~free
    cx = hC[gone] @ x
    over = np.maximum(hlo[gone] - cx, cx - hup[gone])
    bad = over > feas_tol * (1.0 + np.abs(cx))
    if bad.any():
        msg = (f"before level {L.name!r}: {int(bad.sum())} higher-priority inequality row(s) without "
               f"freedom violate their relaxed bounds by up to {float(over[bad].max()):.3g}")
        log.debug(msg)
        warns.append(msg)
    if not free.any():
        return None, None
    return (hC[free], hlo[free], hup[free], hn[free]), HZ[free]


def _unconstrained(M, r0, zx, eps):
    """The minimiser of ‖M u + r0‖² + ε ‖zx + u‖² (the level over x = x* + Z u, Z orthonormal so
    that ‖x* + Z u‖² = ‖Zᵀx* + u‖² + const) as the least-squares solution of the stacked system
    [M; √ε I] u ≈ [−r0; −√ε zx] by Householder QR (LAPACK dgeqrf, dormqr, dtrtrs — what dgels
    does). Returns ``(u, ok, status, (R, c))`` with R the triangular factor and c the first z
    entries of Qᵀ·rhs, so that the level's cost is ‖R u − c‖² + const: :func:`_level_qp` uses
    them to give the backend the well-conditioned problem in w = R u.

    Not by Cholesky of the normal equations MᵀM + ε I: that squares the condition number, and a
    level whose row weights span 1e4 … 1e-4 (Table 2's level 3: momentum 1e4, GRF regulariser
    1e-4) has cond(M)² ~ 1e16 — the low-weight rows then sit at rounding level, and a 1e-13
    relative change of the state moved talos14's Table 2 torques by up to 20 Nm (median 1.4 Nm).
    """
    k, z = M.shape
    A = np.empty((k + z, z), order="F")
    A[:k] = M
    A[k:] = 0.0
    root = math.sqrt(eps)
    A[k:].flat[:: z + 1] = root
    rhs = np.empty((k + z, 1), order="F")
    np.negative(r0, out=rhs[:k, 0])
    np.multiply(zx, -root, out=rhs[k:, 0])
    qr, tau, _, info = lapack.dgeqrf(A, overwrite_a=True)
    if info == 0:
        qtb, _, info = lapack.dormqr("L", "T", qr, tau, rhs, max(1, (k + z) * 64), overwrite_c=True)
    if info != 0:
        return None, False, f"least squares: QR failed (info {info})", None
    R = np.triu(qr[:z, :z])
    c = qtb[:z, 0].copy()
    u, info = lapack.dtrtrs(R, c, lower=0)
    if info != 0 or not np.isfinite(u).all():
        return None, False, f"least squares: triangular solve failed (info {info})", None
    return u, True, "optimal", (R, c)


def _level_qp(Rc, CZ, c0, lo, up, vw, HZ, h0, hlo, hup, solve):
    """QP of eqs. 10-11 over [u, s]: own rows lower − s/V ≤ C x ≤ upper + s/V, higher rows relaxed;
    ``solve(H, g, A, lower, upper) → (y, ok, status)`` solves it (:func:`_backend_solve`).

    The level's cost ½‖M u + r0‖² + ε/2 ‖Zᵀx* + u‖² is ½‖R u − c‖² + const with R, c from the QR
    of the stacked system (:func:`_unconstrained`, ``Rc = (R, c)``). The backend is given the
    problem in w = R u: Hessian I (with the slacks' I), gradient −c, rows C Z R⁻¹ (triangular
    solves); u = R⁻¹ w afterwards. Handing it Hu = MᵀM + εI instead (the normal equations) squares
    cond(R): with Table 2's level-3 weights (1e4 … 1e-4, ε = 1e-4) cond(Hu) ~ 1e16, and every
    backend's factorisation of Hu turned the weakly weighted directions (the internal wrench
    between the feet) into rounding noise (torques moved by up to 2 Nm for a 1e-13 change of the
    state). The row values A u are the same in both parametrisations, so the backends'
    feasibility tolerances keep their meaning.

    On the normal equations a weakly weighted direction can put a row of a higher level into
    the backend's active set at many times the true optimum's cost (a torque step between two
    cycles whose states differ by rounding); the problem in w does not.
    Nearly dependent active rows after normalisation give LDLᵀ pivots far below DAQP's stock
    ``sing_tol``, which it then takes for dependent ("infeasible"): hence ``sing_tol`` 1e-14 and
    ``primal_tol`` 1e-9 in ``backends.DAQP_DEFAULTS``
    (``test_daqp_settings_leave_no_table1_level_qp_to_the_fallback``).

    ``s ≥ 0`` is not imposed: it holds at the optimum (a negative slack only tightens its row
    and costs s², so it is never better than s = 0).
    """
    R, c = Rc
    z = R.shape[0]
    m = CZ.shape[0]
    nv = z + m
    H = np.eye(nv)
    g = np.zeros(nv)
    np.negative(c, out=g[:z])
    fl, fu = np.isfinite(lo), np.isfinite(up)
    il, iu = np.flatnonzero(fl), np.flatnonzero(fu)
    nl_, nu_, nh = il.size, iu.size, HZ.shape[0]
    nr = nl_ + nu_ + nh
    A = np.zeros((nr, nv))
    lower = np.empty(nr)
    upper = np.empty(nr)
    Au = np.empty((nr, z))  # the rows in u, then mapped to w: Au R⁻¹ = (R⁻ᵀ Auᵀ)ᵀ
    if m:
        VCZ = vw[:, None] * CZ
        # V C Z u + s ≥ V (lower − C x*)
        Au[:nl_] = VCZ[il]
        A[np.arange(nl_), z + il] = 1.0
        lower[:nl_] = vw[il] * (lo[il] - c0[il])
        upper[:nl_] = np.inf
        # V C Z u − s ≤ V (upper − C x*)
        Au[nl_ : nl_ + nu_] = VCZ[iu]
        A[nl_ + np.arange(nu_), z + iu] = -1.0
        lower[nl_ : nl_ + nu_] = -np.inf
        upper[nl_ : nl_ + nu_] = vw[iu] * (up[iu] - c0[iu])
    if nh:
        Au[nl_ + nu_ :] = HZ
        lower[nl_ + nu_ :] = hlo - h0
        upper[nl_ + nu_ :] = hup - h0
    if nr:
        A[:, :z] = solve_triangular(R, Au.T, trans="T", lower=False, check_finite=False).T
    y, ok, status = solve(H, g, A, lower, upper)
    if not ok:
        return None, False, status
    u = solve_triangular(R, y[:z], lower=False, check_finite=False)
    if not np.isfinite(u).all():
        return None, False, f"{status}: non-finite solution after the change of variables"
    return u, True, status


# ---------------------------------------------------------------------------- weighted
def _solve_weighted(levels, n, backend, eps, feas_tol, opts, t0):
    """One QP: rows of levels[0] as hard constraints, levels[-1] as weighted objective (seed 001, eq. 7)."""
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
    y, status, ok = solve_qp(H, g, A, lower, upper, backend=backend, **opts)
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


# ---------------------------------------------------------------------------- daqp hierarchical
def _daqp_stack(levels, n, split_equalities=False):
    """Stack the levels for DAQP's hierarchical mode: weighted rows, one break point per level.

    ``split_equalities`` passes each equality row as two one-sided soft rows instead of
    ``sense = 5`` (kept for the experiments in the module docstring; it fails more often).
    """
    # DAQP 0.11 treats the FIRST break-point block as hard constraints and softens only the
    # later ones: a free dummy row goes first so that every level of ours is soft
    free = np.zeros((1, n))
    free[0, 0] = 1.0
    As, bus, bls, senses, bps = [free], [np.full(1, np.inf)], [np.full(1, -np.inf)], [np.zeros(1, dtype=int)], [1]
    total = 1
    for L in levels:
        B, C = _rows(L, n)
        wB, wb = L.w[:, None] * B, L.w * L.b
        VC, vl, vu = L.v[:, None] * C, L.v * L.lower, L.v * L.upper
        k = wB.shape[0]
        if split_equalities:
            A = np.concatenate((wB, wB, VC))
            bu = np.concatenate((np.full(k, np.inf), wb, vu))
            bl = np.concatenate((wb, np.full(k, -np.inf), vl))
            se = np.zeros(A.shape[0], dtype=int)
        else:
            A = np.concatenate((wB, VC))
            bu = np.concatenate((wb, vu))
            bl = np.concatenate((wb, vl))
            se = np.concatenate((np.full(k, 5), np.zeros(VC.shape[0], dtype=int)))
        # DAQP normalises rows: a zero row cannot be passed; a free row carries nothing
        keep = (_row_norms(A) > 0.0) & (np.isfinite(bl) | np.isfinite(bu))
        A, bu, bl, se = A[keep], bu[keep], bl[keep], se[keep]
        if A.shape[0] == 0:
            continue
        As.append(A), bus.append(bu), bls.append(bl), senses.append(se)
        total += A.shape[0]
        bps.append(total)
    if len(bps) == 1:
        return None
    A = np.ascontiguousarray(np.concatenate(As))
    bu = np.minimum(np.concatenate(bus), 1e30)
    bl = np.maximum(np.concatenate(bls), -1e30)
    return A, bu, bl, np.concatenate(senses).astype(np.intc), np.asarray(bps, dtype=np.intc)


def _solve_daqp(levels, n, opts, t0, uniform_soft_weights=True, split_equalities=False):
    import daqp

    nl = len(levels)
    times = np.full(nl, np.nan)
    stack = _daqp_stack(levels, n, split_equalities)
    if stack is None:
        return _finish(levels, np.zeros(n), "optimal", True, t0, times, "daqp", nl, np.zeros(0), [])
    A, bu, bl, sense, bps = stack
    try:
        model = daqp.Model()
        if opts:
            model.settings = opts
        flag, _ = model.setup(np.eye(n), np.zeros(n), A, bu, bl, sense, bps)
        if flag < 0:
            status = f"daqp hierarchical: setup failed, exitflag {flag}"
            if flag == -6:
                status += " (dependent equality rows with inconsistent targets)"
            return _finish(levels, np.zeros(n), status, False, t0, times, "daqp", 0, np.zeros(0), [])
        if uniform_soft_weights:
            # one ρ for every row, in the ORIGINAL row scale: conflicts are resolved by Σ s²
            rho = np.full(A.shape[0], _DAQP_RHO)
            model.soft_weights(rho_l=rho, rho_u=rho)
        x, _, flag, _ = model.solve()
    except (ValueError, RuntimeError) as exc:
        return _finish(levels, np.zeros(n), f"daqp hierarchical: {exc}", False, t0, times, "daqp", 0,
                       np.zeros(0), [])
    x = np.array(x)
    if flag == 3 and np.all(np.isfinite(x)):
        status = "daqp hierarchical: a level's LDP failed (exitflag 3); x is an earlier level's solution"
        return _finish(levels, x, status, False, t0, times, "daqp", 0, np.zeros(0), [])
    if flag not in (1, 2) or not np.all(np.isfinite(x)):
        return _finish(levels, np.zeros(n), f"daqp hierarchical: exitflag {flag}", False, t0, times, "daqp", 0,
                       np.zeros(0), [])
    return _finish(levels, x, "optimal", True, t0, times, "daqp", nl, np.zeros(0), [])


def row_normalised(levels):
    """The levels with every weighted row scaled to unit norm — what DAQP's native soft penalty sees.

    Running the cascade on these reproduces ``method="daqp", daqp_native_weights=True``.
    """
    out = []
    for L in levels:
        if L.n is None:
            out.append(L)
            continue
        eq = ineq = None
        if L.n_eq:
            wB = L.w[:, None] * L.B
            nb = _row_norms(wB)
            nb = np.where(nb > 0, nb, 1.0)
            eq = (wB / nb[:, None], L.w * L.b / nb)
        if L.n_ineq:
            VC = L.v[:, None] * L.C
            nc = _row_norms(VC)
            ineq = (VC / nc[:, None], L.v * L.lower / nc, L.v * L.upper / nc)
        out.append(Level(eq=eq, ineq=ineq, name=L.name))
    return out
