"""Thin QP backend adapters with one contract.

Every adapter solves the strictly convex QP

    minimise ½ xᵀ H x + gᵀ x   subject to   lower ≤ A x ≤ upper

(rows with ``lower == upper`` are equalities; ±inf bounds make one-sided or free rows) and
returns ``(x, status, ok)``. Adapters never raise for numerical reasons: on failure ``ok`` is
False, ``status`` names the reason and ``x`` is None (DAQP, for one, returns uninitialised
memory on failure, so a failed x is never passed on).

* ``quadprog`` — Goldfarb–Idnani dual active set (the method used by Herzog et al. 2016, §5):
  two-sided rows are split into two one-sided rows ``Cᵀx ≥ b``, equalities go first (``meq``).
  It has no iteration limit and can cycle forever on a degenerate vertex; as a fallback
  (:data:`FALLBACK_OPTIONS`) its inequality rows are relaxed by ~1e-12 relative, which breaks the
  ties (:func:`quadprog_tie_break`).
* ``daqp`` — dual active set on the LDP (Arnström et al. 2022): native two-sided rows,
  equalities flagged with ``sense = 5``; infinite bounds are passed as ±1e30 (DAQP_INF); rows are
  scaled to unit norm and the solution is checked on the unscaled rows (see the adapter). For
  ill-conditioned H (cond ≳ 1e9, tiny ε) its infeasibility test misfires on feasible QPs, and
  at degenerate vertices it may cycle; an "infeasible" or "cycling" verdict is retried once
  with proximal iterations (``eps_prox = 1e-6``), which converge to the same solution.
* ``proxsuite`` — ProxQP dense (augmented Lagrangian); equalities as its ``A x = b`` block.
  Its accuracy is a tolerance, not active-set exactness: ``eps_abs`` defaults to 1e-9 here.
  Its infeasibility certificates misfire on small feasible problems; see the adapter.

Keyword options are passed to the solver (e.g. ``eps_abs`` for proxsuite, DAQP settings).

Single QPs that DAQP solves on their own rows and senses, with simple bounds and a warm start
(PassiveWBC's eq. 7 of Fahmi et al. 2019, the quasi-static baseline), go through
:func:`solve_daqp_qp`, which returns a :class:`DaqpResult` (exit flag, iterations, multipliers).
"""

from __future__ import annotations

import logging
import math
from typing import NamedTuple

import numpy as np

__all__ = ["solve_qp", "BACKENDS", "solve_daqp_qp", "DaqpResult"]

log = logging.getLogger(__name__)

_DAQP_INF = 1e30
# what a backend may raise on bad numbers: turned into a failed (x, status, ok), never raised
QP_ERRORS = (ValueError, ArithmeticError, RuntimeError, np.linalg.LinAlgError)
DAQP_EXIT = {  # DAQP's exit flags by name (daqp 0.11's constants.h)
    5: "feasible, optimality not proven",
    4: "optimal only at the rounding level (a row violated beyond primal_tol)",
    3: "constrained point",
    1: "optimal",
    2: "soft optimal",
    -1: "infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "iteration limit",
    -5: "nonconvex (H not positive definite)",
    -6: "overdetermined initial active set (inconsistent equalities)",
    -7: "time limit",
    -8: "unsupported",
}
# DAQP's settings where the caller gives none (solve_daqp says why)
DAQP_DEFAULTS = {"primal_tol": 1e-9, "sing_tol": 1e-14}
DAQP_RAW_TOL = 1e-6  # a DAQP solution's largest violation of an unscaled row beyond rounding
DAQP_OK = (1, 2)  # DAQP's success flags: optimal, soft optimal
DAQP_SENSE_EQ, DAQP_SENSE_INEQ = 5, 0  # DAQP's row senses: equality, (two-sided) inequality
# DAQP's settings for solve_daqp_qp where the caller gives none: daqp.solve's own defaults (nothing
# overridden). The single weighted QPs it serves (PassiveWBC, Fahmi et al. 2019 eq. 7, and the
# quasi-static baseline) are solved on their own rows, not on the cascade's relaxed level QPs that
# DAQP_DEFAULTS is chosen for.
DAQP_QP_DEFAULTS: dict = {}


def _split_rows(lower: np.ndarray, upper: np.ndarray):
    """Masks of equality rows, finite-lower inequality rows and finite-upper inequality rows."""
    eq = lower == upper
    lo = np.isfinite(lower) & ~eq
    up = np.isfinite(upper) & ~eq
    return eq, lo, up


def _check_x(x, name: str):
    if x is None or not np.all(np.isfinite(x)):
        return None, f"{name}: non-finite solution", False
    return x, "optimal", True


#: With ``tie_break``, quadprog's inequality rows are relaxed by this times (1 + a distinct
#: fraction) times (‖a_i‖ + |b_i|).
QUADPROG_TIE_BREAK = 1e-12
_GOLDEN_FRACTION = 0.6180339887498949


def quadprog_tie_break(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distinct relaxations of the inequality rows ``A x >= b`` handed to quadprog.

    Goldfarb–Idnani (quadprog) has no iteration limit and no anti-cycling rule: at a vertex where
    more rows are active than there are variables it can add and drop the same rows forever
    (tests/solvers/test_quadprog_adapter.py keeps such QPs). Moving each row outwards by a
    different amount makes the vertex non-degenerate (the perturbation method against
    degeneracy); the fractions ``frac(i φ)`` are deterministic, so results are reproducible.
    1e-15 relative is too little on those QPs, 1e-13 enough on 1e5 random ones. The price is
    quadprog's exactness: on ill-conditioned hierarchies the higher levels' costs then move
    beyond tests/solvers/test_hierarchy.py's tolerances, which is why only the fallback uses it."""
    fractions = (np.arange(1, b.size + 1) * _GOLDEN_FRACTION) % 1.0
    return QUADPROG_TIE_BREAK * (1.0 + fractions) * (np.linalg.norm(A, axis=1) + np.abs(b))


def solve_quadprog(H, g, A, lower, upper, tie_break: bool = False, **_):
    """Goldfarb–Idnani via ``quadprog.solve_qp`` (min ½xᵀGx − aᵀx s.t. Cᵀx ≥ b, first meq equal).

    Rows are passed as given; with ``tie_break`` the inequality rows are relaxed by
    :func:`quadprog_tie_break` (≤ 2e-12 relative), which keeps quadprog from cycling forever on
    degenerate vertices. Scaling the rows to unit norm instead also avoids the one QP kept in
    the tests, but costs accuracy elsewhere (2.5e-4 on another degenerate QP, "inconsistent" on
    feasible ones)."""
    import quadprog

    n = H.shape[0]
    if A.shape[0]:
        eq, lo, up = _split_rows(lower, upper)
        inequality_rows = np.concatenate((A[lo], -A[up]), axis=0)
        inequality_bounds = np.concatenate((lower[lo], -upper[up]))
        if tie_break:
            inequality_bounds = inequality_bounds - quadprog_tie_break(inequality_rows,
                                                                       inequality_bounds)
        Ct = np.concatenate((A[eq], inequality_rows), axis=0).T
        bb = np.concatenate((lower[eq], inequality_bounds))
        meq = int(np.count_nonzero(eq))
    else:
        Ct, bb, meq = np.zeros((n, 0)), np.zeros(0), 0
    try:
        if Ct.shape[1]:
            x = quadprog.solve_qp(H, -g, Ct, bb, meq)[0]
        else:
            x = quadprog.solve_qp(H, -g)[0]
    except ValueError as exc:  # "constraints are inconsistent", "G is not positive definite"
        return None, f"quadprog: {exc}", False
    return _check_x(x, "quadprog")


def solve_daqp(H, g, A, lower, upper, raw_tol=DAQP_RAW_TOL, **opts):
    """DAQP via ``daqp.solve(H, f, A, bupper, blower, sense)``; equalities have sense 5; rows
    scaled to unit norm, the solution refused if a row is violated by more than ``raw_tol``
    beyond the rounding of its product (:func:`_row_violation_numpy`).

    Two settings differ from DAQP's defaults (``DAQP_DEFAULTS``, chosen for the cascade's level
    QPs, which keep higher-priority rows active at their relaxed bounds):

    * ``sing_tol`` (the smallest pivot DAQP accepts in the LDLᵀ of its active rows): 1e-14
      instead of 3.7e-11 (1e-14 is the floor DAQP itself uses in branch and bound). On unit rows
      a pivot is about σ_min² of the active rows, so nearly dependent active rows (σ_min ~ 1e-6)
      were taken for dependent with the default and feasible level QPs declared "infeasible".
    * ``primal_tol``: 1e-9 instead of 1e-6. DAQP's tolerance holds on the unit rows, i.e. ‖row‖
      times looser on the caller's rows (norms up to ~1e6), which the check on the raw rows then
      refuses; the tighter tolerance keeps DAQP's solutions within it, at a small cost per QP.

    tests/solvers/test_hierarchy.py checks both choices on random hierarchies against quadprog.
    """
    if A.shape[0] == 0:
        # DAQP needs at least one row: add a free one (not a zero row: DAQP normalises rows)
        A = np.zeros((1, H.shape[0]))
        A[0, 0] = 1.0
        lower, upper = np.full(1, -np.inf), np.full(1, np.inf)
    # DAQP is given rows of unit norm (same feasible set): the cascade's level QPs in w = R u have
    # row norms from ~0.1 to ~1e6 (directions without objective are scaled by 1/sqrt(eps)), and
    # on the raw rows DAQP declared feasible QPs infeasible/cycling at degenerate vertices far
    # more often than on unit rows. Its tolerance then holds on the unit rows, i.e. ‖row‖ times
    # looser on the raw ones: the solution is checked on the caller's rows and refused beyond
    # `raw_tol` plus what rounding the product a_i x allows (a fallback backend then solves the
    # QP). Without that allowance rows of norm ~1e10 (value ~1e6) refused solutions that were
    # exact to rounding on the unit rows and agreed with quadprog's to 1e-8.
    unit_A, bu, bl, sense = _daqp_rows(A, lower, upper)
    x, status = solve_daqp_unit_rows(H, g, unit_A, bu, bl, sense, **opts)
    return daqp_verdict(x, status, _row_violation(A, x, lower, upper) if x is not None else 0.0,
                        raw_tol)


def solve_daqp_unit_rows(H, g, unit_A, bupper, blower, sense, **opts):
    """DAQP on rows already scaled as :func:`solve_daqp` scales them (``_daqp_rows``) → (x, status),
    x None on failure; an "infeasible" or "cycling" verdict is retried once with proximal
    iterations."""
    opts = {**DAQP_DEFAULTS, **opts}
    H, g = np.ascontiguousarray(H), np.ascontiguousarray(g)
    x, _, flag, _ = _daqp().solve(H, g, unit_A, bupper, blower, sense, **opts)
    if flag in (-1, -2) and "eps_prox" not in opts:
        # DAQP works on the LDP with R⁻¹ (H = RᵀR); for cond(H) ≳ 1e9 (tiny ε in the cascade)
        # its infeasibility test misfires on feasible problems, and at a degenerate vertex (more
        # active rows than the dimension, as at an edge of a sole's contact wrench cone, where 8-9
        # of its 16 facets meet) it may cycle. Proximal-point iterations (eps_prox > 0) converge
        # to the same strictly convex QP's solution: retry once.
        x, _, flag, _ = _daqp().solve(H, g, unit_A, bupper, blower, sense, eps_prox=1e-6, **opts)
    if flag not in (1, 2):
        return None, f"daqp: {DAQP_EXIT.get(flag, 'exitflag')} ({flag})"
    return np.asarray(x), "optimal"


class DaqpResult(NamedTuple):
    """What :func:`solve_daqp_qp` found: ``x`` (None unless ``ok``), DAQP's exit ``flag``, its
    ``iterations``, the multipliers ``dual`` (None unless ``ok``; the next cycle's warm start)
    and a ``status`` naming the flag (``DAQP_EXIT``)."""

    x: np.ndarray | None
    flag: int
    iterations: int
    dual: np.ndarray | None
    status: str

    @property
    def ok(self) -> bool:
        return self.x is not None


def solve_daqp_qp(H, g, A, upper, lower, sense, dual_start=None, **settings) -> DaqpResult:
    """min ½xᵀHx + gᵀx s.t. lower ≤ A x ≤ upper by DAQP on the caller's rows (not scaled) with
    the caller's senses (5: equality) → :class:`DaqpResult`.

    General H (positive definite, not the cascade's unit Hessian). ``upper``/``lower`` longer than
    A's rows bound the first variables directly (DAQP's simple bounds), as in ``daqp.solve``.
    ``dual_start`` (multipliers of an earlier solve of the same layout) warm-starts DAQP; a warm
    start that fails is retried cold. ``settings`` override ``DAQP_QP_DEFAULTS``. Success is exit
    flag 1 or 2 (``DAQP_OK``) with a finite x; on failure x is None (DAQP returns uninitialised
    memory then).
    """
    daqp, opts = _daqp(), {**DAQP_QP_DEFAULTS, **settings}
    args = (H, g, A, upper, lower, sense)
    if dual_start is not None:
        x, _, flag, info = daqp.solve(*args, dual_start=dual_start, **opts)
        if flag not in DAQP_OK:
            x, _, flag, info = daqp.solve(*args, **opts)
    else:
        x, _, flag, info = daqp.solve(*args, **opts)
    iterations = info.get("iterations", 0)
    if flag not in DAQP_OK:
        return DaqpResult(None, flag, iterations, None,
                          f"daqp: {DAQP_EXIT.get(flag, 'exit flag')} ({flag})")
    if not math.isfinite(np.add.reduce(x)):  # x.sum() without its Python-level wrapper
        return DaqpResult(None, flag, iterations, None, f"daqp: non-finite solution (flag {flag})")
    return DaqpResult(x, flag, iterations, info["lam"], "optimal")


def daqp_verdict(x, status: str, over: float, raw_tol: float = DAQP_RAW_TOL):
    """(x, status, ok) for a DAQP solution ``x`` (None: failed with ``status``) whose unscaled rows
    are violated by ``over`` at most beyond rounding (:func:`_row_violation_numpy`): refused
    beyond ``raw_tol`` or if not finite."""
    if x is None:
        return None, status, False
    if not math.isfinite(over):
        return None, "daqp: non-finite solution", False
    if over > raw_tol:
        return None, f"daqp: solution outside its rows by {over:.3g} (> {raw_tol:g})", False
    return x, "optimal", True


def _daqp():
    """The daqp module (imported on first use: an optional backend)."""
    import daqp

    return daqp


def _daqp_rows_numpy(A, lower, upper):
    """(unit rows, upper, lower, sense) for DAQP: rows and bounds divided by the row norms, bounds
    clipped to ±1e30 (DAQP_INF), sense 5 on equality rows (compiled: ``_cascade.daqp_rows``)."""
    norms = np.sqrt(np.einsum("ij,ij->i", A, A))
    norms[norms == 0.0] = 1.0
    return (A / norms[:, None], np.minimum(upper / norms, _DAQP_INF),
            np.maximum(lower / norms, -_DAQP_INF), np.where(lower == upper, 5, 0).astype(np.intc))


def _row_violation_numpy(A, x, lower, upper) -> float:
    """Largest violation of lower ≤ A x ≤ upper beyond rounding, inf if x is not finite (compiled:
    ``_cascade.row_violation``): max(0, lower_i − a_i x, a_i x − upper_i) less the rounding
    bound n ε ‖a_i‖ ‖x‖ of the product a_i x (n = len(x); Higham, "Accuracy and Stability of
    Numerical Algorithms", §3.1). A level QP's rows in w = R u reach norms ~1e10 with values ~1e6,
    where a_i x carries an error of ~1e-6 whichever backend computed x."""
    if not np.isfinite(x).all():
        return math.inf
    ax = A @ x
    off = np.maximum(lower - ax, ax - upper)
    if not (off > 0.0).any():
        return 0.0
    unit = x.size * np.finfo(float).eps * float(np.linalg.norm(x))
    return float(max(np.max(off - unit * np.sqrt(np.einsum("ij,ij->i", A, A))), 0.0))


try:  # the same two helpers compiled (a few µs instead of ~40 µs of small numpy calls per QP)
    from .._cascade import daqp_rows as _daqp_rows, row_violation as _row_violation
except ImportError:
    _daqp_rows, _row_violation = _daqp_rows_numpy, _row_violation_numpy


def solve_proxsuite(H, g, A, lower, upper, eps_abs=1e-9, max_iter=10_000, **opts):
    """ProxQP dense via ``proxsuite.proxqp.dense.solve``; equality rows go to its A x = b block.

    ProxQP's infeasibility certificates misfire on small, strictly convex, feasible problems
    (DUAL_INFEASIBLE with H positive definite, PRIMAL_INFEASIBLE on degenerate but feasible
    rows); both are retried once without the Ruiz preconditioner, and a remaining
    PRIMAL_INFEASIBLE once more as a closest-feasible solve, accepted only if that point is in
    fact feasible.
    """
    from proxsuite import proxqp

    n = H.shape[0]
    eq = lower == upper
    Ae, be = A[eq], lower[eq]
    iq = ~eq & (np.isfinite(lower) | np.isfinite(upper))
    Ci, li, ui = A[iq], np.maximum(lower[iq], -1e20), np.minimum(upper[iq], 1e20)
    args = (
        H, g,
        Ae if Ae.shape[0] else None, be if Ae.shape[0] else None,
        Ci if Ci.shape[0] else None, li if Ci.shape[0] else None, ui if Ci.shape[0] else None,
    )
    base = {"eps_abs": eps_abs, "eps_rel": 0.0, "max_iter": max_iter, **opts}
    retry_on = (proxqp.PROXQP_DUAL_INFEASIBLE, proxqp.PROXQP_PRIMAL_INFEASIBLE, proxqp.PROXQP_MAX_ITER_REACHED)
    try:
        res = proxqp.dense.solve(*args, **base)
        status = res.info.status
        if status in retry_on and "compute_preconditioner" not in opts:
            res = proxqp.dense.solve(*args, **{**base, "compute_preconditioner": False})
            status = res.info.status
        if status == proxqp.PROXQP_PRIMAL_INFEASIBLE and "primal_infeasibility_solving" not in opts:
            res = proxqp.dense.solve(*args, **{**base, "primal_infeasibility_solving": True})
            status = res.info.status
            if status == proxqp.PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE:
                ax = A @ np.asarray(res.x[:n])
                tol = 10.0 * eps_abs * (1.0 + np.abs(ax))
                if np.all(ax >= lower - tol) and np.all(ax <= upper + tol):
                    status = proxqp.PROXQP_SOLVED
    except (ValueError, RuntimeError) as exc:
        return None, f"proxsuite: {exc}", False
    if status != proxqp.PROXQP_SOLVED:
        return None, f"proxsuite: {str(status).rsplit('.', 1)[-1]}", False
    return _check_x(np.array(res.x[:n]), "proxsuite")


BACKENDS = {"quadprog": solve_quadprog, "daqp": solve_daqp, "proxsuite": solve_proxsuite}
#: Options of a backend when it solves, as the fallback, a QP the first backend failed on: those
#: QPs are the degenerate and ill-posed ones, where returning at all matters more than the last
#: digits (quadprog's tie-break; see :func:`quadprog_tie_break`).
FALLBACK_OPTIONS = {"quadprog": {"tie_break": True}}


def solve_qp(H, g, A, lower, upper, backend: str = "quadprog", **options):
    """min ½xᵀHx + gᵀx s.t. lower ≤ A x ≤ upper with the named backend → ``(x, status, ok)``.

    H must be symmetric positive definite (the cascade of Herzog et al. 2016, eq. 5, is made
    strictly convex by its ε term). Never raises for numerical reasons; unknown backend names
    raise ValueError.
    """
    try:
        fn = BACKENDS[backend]
    except KeyError:
        raise ValueError(f"unknown backend {backend!r}; choose from {sorted(BACKENDS)}") from None
    try:
        return fn(H, g, A, lower, upper, **options)
    except QP_ERRORS as exc:
        log.debug("backend %s failed: %s", backend, exc)
        return None, f"{backend}: {type(exc).__name__}: {exc}", False
