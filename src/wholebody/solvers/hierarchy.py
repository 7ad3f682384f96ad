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
``cascade`` (the reference): :mod:`.cascade`
    One QP per level over the nullspace coordinates u, plus one slack per inequality row of the
    level that still has freedom (eqs. 8-11), each level first solved in closed form. Its
    numerical devices (implicit equalities, margins, the kernel by QR with column pivoting and
    an SVD guard) and how far ε moves the costs from the exact lexicographic optimum are
    described there. :mod:`.compiled_cascade` runs the same algorithm compiled
    (``wholebody._cascade``, the default when built), its level QPs solved by the same
    backends; :class:`BoundCascade` keeps it bound to a control loop's level arrays.

``daqp``: :mod:`.daqp_hierarchy`
    DAQP's native hierarchical mode, all levels in one call. Why its row normalisation gives
    another compromise than eq. 5, and the per-row soft weights that restore eq. 5, are
    described there (:func:`row_normalised`).

``weighted``: :mod:`.weighted`
    One QP over ``levels = [hard, objective]`` (Fahmi et al. 2019, eq. 7), the hard level's rows as
    constraints; if the hard level is infeasible or the QP fails, the cascade's result is
    returned, recorded in ``method`` and ``warnings``. :mod:`.compiled_cascade` assembles and
    (DAQP) solves it compiled, the default when built; :class:`BoundWeighted` keeps it bound to
    a control loop's level arrays.

The solution type and what the methods share are in :mod:`.common`; the analytic first level
(§2.4, eq. 17) is :func:`analytic_first_level`.
"""

from __future__ import annotations

import time

import numpy as np

from . import compiled_cascade
from .cascade import _solve_cascade
from .common import (FirstLevelSolution, HierarchySolution, _checked_arguments, evaluate_levels,
                     regular_nullspace)
from .compiled_cascade import BoundCascade, BoundWeighted, _solve_compiled, _solve_weighted_compiled
from .daqp_hierarchy import _solve_daqp, row_normalised
from .level import Level
from .settings import HIERARCHY_DEFAULT, SolverSettings, settings_or_default
from .weighted import _solve_weighted, _without_weighted_solution

__all__ = ["HierarchySolution", "FirstLevelSolution", "solve_hierarchy", "evaluate_levels",
           "row_normalised", "analytic_first_level", "BoundCascade", "BoundWeighted"]


def solve_hierarchy(
    levels,
    settings: SolverSettings | None = None,
    *,
    first_level_solution=None,
    rank_tol: float = 1e-9,
    drop_tol: float = 1e-9,
    relax_tol: float = 1e-9,
    feas_tol: float = 1e-6,
    daqp_native_weights: bool = False,
    compiled: bool = True,
) -> HierarchySolution:
    """Lexicographic optimum of a list of :class:`Level` (Herzog et al. 2016, eqs. 5-11).

    Parameters
    ----------
    levels : highest priority first.
    settings : a :class:`~wholebody.solvers.SolverSettings` (None:
        :data:`~wholebody.solvers.settings.HIERARCHY_DEFAULT`, quadprog without a fallback and
        ε = 1e-4). Its ``method``: ``"cascade"`` (reference, eqs. 8-11), ``"daqp"`` (DAQP's
        hierarchical mode) or ``"weighted"`` (one QP over ``levels = [hard, objective]``); see
        the module docstring. ``backend``: QP backend of the cascade / weighted QPs, with its
        ``backend_options`` (``eps_abs`` for proxsuite, DAQP settings for ``daqp`` and the daqp
        method). ``regularization``: ε of eq. 5 for the cascade and weighted QPs (not used by
        ``daqp``); costs are reported without it, :mod:`.cascade`'s docstring says how far it
        moves them from the exact lexicographic optimum. ``fallback_backend``: cascade only — a
        level QP that ``backend`` fails on is solved again with it (same QP, so the same
        optimum), recorded in ``warnings``; cheaper than re-solving the whole cascade, each
        backend having rare failures of its own on these ill-conditioned QPs.
        ``analytic_first_level`` is read by the whole-body callers, which know what level 1
        holds; here ``first_level_solution`` says it.
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
    daqp_native_weights : method ``daqp`` only — use DAQP's native (row-normalised) soft
        penalty instead of uniform per-row weights (which give eq. 5's Σ s² trade-off).
    compiled : cascade and weighted — run the compiled cascade or weighted QP
        (``wholebody._cascade``, when built): the same algorithm line for line, with the QPs
        still solved by the backend (and, in the cascade, the fallback) from Python, except
        DAQP's, solved in C++ with the adapter's rows, settings and verdict. ``False`` runs the
        Python reference.
        Warnings from the compiled cascade list its own (frozen rows) before the fallback notes.

    Bad input (NaN/inf in data, inconsistent column counts, unknown names) raises ValueError
    naming the level and field. Numerical failures never raise: the solution is flagged
    (``ok=False``, ``status`` says why) and ``x`` is the last successful level's (finite) x.
    """
    t0 = time.perf_counter()
    settings = settings_or_default(settings, HIERARCHY_DEFAULT)
    levels, n, first_level_solution = _checked_arguments(levels, settings, first_level_solution)
    analytic = isinstance(first_level_solution, str)
    method = settings.method
    tols = (rank_tol, drop_tol, relax_tol, feas_tol)

    if n == 0 and method != "cascade":  # no variable: nothing to optimise, the cascade evaluates
        method = "cascade"
    if method == "daqp":
        return _solve_daqp(levels, n, settings.options, t0,
                           uniform_soft_weights=not daqp_native_weights)
    if method == "weighted":
        if len(levels) > 2:
            raise ValueError(f"method 'weighted' takes [hard, objective] levels, got {len(levels)} levels")
        solve = (_solve_weighted_compiled if compiled and compiled_cascade._WeightedRun is not None
                 else _solve_weighted)
        sol = solve(levels, n, settings, feas_tol, t0)
        if isinstance(sol, str):  # the reason the weighted QP has no solution
            return _without_weighted_solution(levels, n, settings, tols, t0, sol)
        return sol
    if compiled and compiled_cascade._CompiledCascade is not None:
        return _solve_compiled(levels, n, settings, first_level_solution, tols, t0)
    if analytic:
        first_level_solution = analytic_first_level(levels[0])
    return _solve_cascade(levels, n, settings, first_level_solution, tols, t0)


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
    B, b = level.B * w[:, None], level.b * w
    regular = regular_nullspace(B, b)
    if regular is None:  # rank-deficient B: the plain formulas
        x1 = B.T @ np.linalg.lstsq(B @ B.T, b, rcond=None)[0]
        Q, _ = np.linalg.qr(B.T, mode="complete")
        return FirstLevelSolution(x1, Q[:, k:])
    return FirstLevelSolution(*regular)
