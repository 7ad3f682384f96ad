"""What the methods of :func:`~wholebody.solvers.hierarchy.solve_hierarchy` share: the solution
type, the argument checks, the rows of a level, the per-level evaluation (eq. 5 without ε) and
the call of a level QP's backend with its fallback.

The method modules (:mod:`.cascade`, :mod:`.compiled_cascade`, :mod:`.daqp_hierarchy`,
:mod:`.weighted`) and :mod:`.hierarchy` import from here, never from each other's callers.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.linalg import lapack

from .backends import FALLBACK_OPTIONS, solve_qp
from .level import Level

# one logger for solve_hierarchy, whichever method's module writes to it
log = logging.getLogger(f"{__package__}.hierarchy")

@dataclass
class HierarchySolution:
    """Result of :func:`~wholebody.solvers.hierarchy.solve_hierarchy`.

    ``costs[r] = ‖W_r(B_r x − b_r)‖² + ‖v_r‖²`` at the returned x (eq. 5 without ε);
    ``eq_residuals[r] = W_r(B_r x − b_r)``; ``ineq_violations[r] = v_r = V_r · violation ≥ 0``
    (weighted, as it enters the cost); ``timings = {"total": s, "levels": array of s}``, and
    for the compiled cascade and the compiled weighted QP also ``"qp"`` (s spent in the QP
    backends) and ``"qps"`` (their count)
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


def regular_nullspace(B: np.ndarray, b: np.ndarray):
    """(x1, Z) of the rows B x = b (k × n): x1 = Bᵀ(B Bᵀ)⁻¹ b, the least-norm solution, and Z
    an orthonormal basis of null(B), from one complete QR of Bᵀ = [Q1 Q2] [R; 0] (LAPACK
    dgeqrf/dorgqr; Herzog et al. 2016 §2.4, eq. 17): since B Bᵀ = RᵀR, x1 = Q1 R⁻ᵀ b and
    Z = Q2. None where B is not regular: more rows than columns, some |R_ii| ≤ 1e-12
    max |R_jj|, or a result that is not finite."""
    k = b.shape[0]
    Bt = np.array(B.T, order="F")
    if k == 0 or k > Bt.shape[0]:
        return None
    qr, tau, _, info = lapack.dgeqrf(Bt, overwrite_a=True)
    d = np.abs(qr.diagonal()[:k])
    if info != 0 or not d.min() > 1e-12 * d.max():
        return None
    q = np.zeros((Bt.shape[0], Bt.shape[0]), order="F")
    q[:, :k] = qr
    Q, _, info = lapack.dorgqr(q, tau, overwrite_a=True)
    if info != 0:
        return None
    y, info = lapack.dtrtrs(qr[:k], b, lower=0, trans=1)  # Rᵀ y = b (reads R's triangle only)
    if info != 0 or not np.isfinite(y).all():
        return None
    return Q[:, :k] @ y, Q[:, k:]  # Z orthonormal by construction


class FirstLevelSolution(NamedTuple):
    """``first_level_solution`` from a caller that guarantees ``x1`` finite and ``Z1`` finite
    with orthonormal columns (e.g. from a QR, as :class:`~wholebody.formulation.Formulation`
    does every cycle): the checks of a plain ``(x1, Z1)`` pair are skipped."""

    x1: np.ndarray
    Z1: np.ndarray


# ---------------------------------------------------------------------------- argument checks
def _checked_arguments(levels, settings, first_level_solution):
    """solve_hierarchy's argument checks (``settings`` checked themselves) → (levels as a list,
    n, first_level_solution); ValueError naming what is wrong."""
    levels = [levels] if isinstance(levels, Level) else list(levels)
    method = settings.method
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
    return levels, n, first_level_solution


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


# ---------------------------------------------------------------------------- levels
def _rows(L: Level, n: int):
    """(B, C) of a level with n columns, also for an empty level."""
    B = L.B if L.B.shape[1] == n else np.zeros((0, n))
    C = L.C if L.C.shape[1] == n else np.zeros((0, n))
    return B, C


def _row_norms(A: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->i", A, A))


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


def _finish(levels, x, status, ok, t_start, level_times, method, solved, zdims, warns,
            evaluated=None, timings=None):
    """The HierarchySolution of x; ``evaluated``: :func:`evaluate_levels` at x if already computed
    (compiled), ``timings``: entries besides "total" and "levels"."""
    costs, res, vio = evaluated if evaluated is not None else evaluate_levels(levels, x)
    if ok and not math.isfinite(np.add.reduce(costs)):  # entries so large the products overflow
        ok = False
        status = (f"level costs not finite at the solution (level "
                  f"{int(np.argmin(np.isfinite(costs)))}: entries too large, the products overflow)")
    return HierarchySolution(
        x=x, costs=costs, eq_residuals=res, ineq_violations=vio, status=status, ok=ok,
        timings={"total": time.perf_counter() - t_start, "levels": level_times, **(timings or {})},
        method=method, levels_solved=solved, nullspace_dims=np.asarray(zdims, dtype=int),
        warnings=tuple(warns),
    )


def _backend_solve(qp, settings, r, levels, warns, first=None):
    """The level QP ``qp()`` → (H, g, A, lower, upper) with ``settings.backend``, then
    ``settings.fallback_backend`` if it fails → (y, ok, status); a fallback success is recorded
    in ``warns``. ``first``, if given, is the backend's (y, status, ok) already computed (then
    ``qp`` is called only for the fallback)."""
    fallback = settings.fallback_backend
    y, status, ok = first if first is not None else solve_qp(*qp(), backend=settings.backend,
                                                             **settings.options)
    if not ok and fallback is not None:
        y, status2, ok = solve_qp(*qp(), backend=fallback, **FALLBACK_OPTIONS.get(fallback, {}))
        if ok:
            msg = f"level {r} ({levels[r].name!r}): {status}; solved with {fallback}"
            log.debug(msg)
            warns.append(msg)
        else:
            status = f"{status}; {status2}"
    return y, ok, status
