"""The cascade and the weighted QP compiled: the bridge to ``wholebody._cascade``
(src/wholebody/native/cascade.cpp).

``wholebody._cascade.CascadeRun`` is the algorithm of :mod:`.cascade` line for line in C++
(Eigen: Householder QR, QR with column pivoting, the same tolerances); it hands each level QP
back to Python, where :func:`~.common._backend_solve` calls the backend (and the fallback)
exactly as the Python cascade does — except DAQP's, which it solves itself through DAQP's C
interface with the adapter's rows, settings and verdict (:func:`_daqp_in_cascade`; bitwise the
same results) — and calls scipy's NNLS for the implicit-equality search. It is the default when
built (``compiled=True``); the Python cascade is the reference the tests compare it with (x to
1e-7 on the random hierarchies, torques to 1e-6 Nm on Tables 1/2). Results differ only by
rounding: Eigen's and LAPACK's factorisations pivot alike but round differently.

:class:`BoundCascade` keeps a compiled run bound to a control loop's level arrays.

``wholebody._cascade.WeightedRun`` is :func:`.weighted._solve_weighted` line for line in C++: it
assembles the single weighted QP (Fahmi et al. 2019, eq. 7) into buffers sized once, solves it
with DAQP through the same ``DaqpSolver`` as the cascade's level QPs (the adapter's rows,
settings, retry and verdict) and checks the hard level with ``feas_tol``; another backend gets
the assembled QP from Python (:func:`_run_weighted`). ``solve_hierarchy(method="weighted")`` uses
it when built (``compiled=True``), :class:`BoundWeighted` keeps it bound to a control loop's
level arrays; where it gives no solution the cascade's result is returned, as in Python.
"""

from __future__ import annotations

import functools
import importlib.metadata
import inspect
import time

import numpy as np

from . import cascade
from .backends import (BACKENDS, DAQP_DEFAULTS, DAQP_EXIT, DAQP_RAW_TOL, QP_ERRORS,
                       daqp_verdict, solve_daqp, solve_daqp_unit_rows, solve_qp)
from .common import HierarchySolution, _backend_solve, _checked_arguments, _finish, log
from .settings import HIERARCHY_DEFAULT, SolverSettings, settings_or_default
from .weighted import _without_weighted_solution

try:  # the cascade, compiled (src/wholebody/native/cascade.cpp); optional
    from .._cascade import CascadeRun as _CompiledCascade
    from .._cascade import DAQP_C_VERSION as _DAQP_C_VERSION
    from .._cascade import DaqpSolver as _DaqpSolver
    from .._cascade import WeightedRun as _WeightedRun
except ImportError:  # not built (no C++ compiler at install): the Python cascade does everything
    _CompiledCascade = _DaqpSolver = _DAQP_C_VERSION = _WeightedRun = None

__all__ = ["BoundCascade", "BoundWeighted"]

_NO_DIMS = np.zeros(0, dtype=int)  # the weighted QP's null-space dimensions: none (shared: empty)


def _solve_compiled(levels, n, settings, fls, tols, t0):
    """The cascade compiled (``wholebody._cascade.CascadeRun``, a line-for-line mirror of
    :func:`.cascade._solve_cascade`, including :func:`.cascade._implicit_equalities` with its
    NNLS, ``cascade.nnls``, passed in): it runs the levels and hands back each level QP, solved
    here by ``settings.backend``, then its fallback, exactly as the Python cascade does (DAQP's
    QPs are solved in C++ when :func:`_daqp_in_cascade` allows it, with the same rows, settings
    and verdict)."""
    return _run_compiled(_new_run(levels, n, settings.regularization, fls, tols), levels, settings,
                         t0, _daqp_in_cascade(settings.backend, settings.options))


def _new_run(levels, n, eps, fls, tols):
    """A compiled cascade run on the arrays of ``levels`` (held, not copied)."""
    analytic = isinstance(fls, str)
    x1, Z1 = fls if fls is not None and not analytic else (None, None)
    return _CompiledCascade([L.B for L in levels], [L.b for L in levels], [L.w for L in levels],
                            [L.C for L in levels], [L.lower for L in levels],
                            [L.upper for L in levels], [L.v for L in levels],
                            [L.name for L in levels], n, eps, x1, Z1, analytic, *tols, cascade.nnls)


def _run_compiled(run, levels, settings, t0, daqp=None):
    """Drives a compiled run from its first level: its level QPs solved by ``settings.backend``,
    then ``settings.fallback_backend`` → HierarchySolution. ``daqp`` (a :func:`_daqp_in_cascade`
    solver) lets the run solve them with DAQP itself; the QPs it leaves (DAQP failed, or no rows)
    come back here."""
    warns = []
    qp_times = None  # of the QPs solved here (not by the run), per level
    n_qps = 0
    direct_daqp = BACKENDS.get(settings.backend) is solve_daqp
    daqp = daqp if direct_daqp else None  # a test may have replaced the adapter since
    advance = run.advance if daqp is None else functools.partial(run.advance_daqp, daqp)
    while (kind := advance()) == "qp":
        tq = time.perf_counter()
        r = run.level
        if daqp is not None and run.daqp_status:  # DAQP failed on it in the run (counted there)
            first = (None, run.daqp_status, False)
        else:
            n_qps += 1
            first = _daqp_on_run(run, settings.options) if direct_daqp else None
        y, ok, status = _backend_solve(_identity_qp(run), settings, r, levels, warns, first)
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
    argument checks and array hand-over.

    Arguments as :func:`solve_hierarchy` (``settings.method`` "cascade"); :meth:`solve` returns what
    ``solve_hierarchy(levels, ...)`` would for the arrays' current contents. The arrays must keep
    their shapes and stay finite (checked by the caller: nothing is copied or re-checked here).
    Needs the compiled cascade (:data:`available`).
    """

    available = _CompiledCascade is not None

    def __init__(self, levels, settings: SolverSettings | None = None, *,
                 first_level_solution=None, rank_tol: float = 1e-9, drop_tol: float = 1e-9,
                 relax_tol: float = 1e-9, feas_tol: float = 1e-6):
        levels, n, fls, settings = _bound_arguments("BoundCascade", "cascade", self.available,
                                                    levels, settings, first_level_solution)
        self.levels, self.settings = levels, settings
        self._run = _new_run(levels, n, settings.regularization, fls,
                             (rank_tol, drop_tol, relax_tol, feas_tol))
        self._daqp = _daqp_in_cascade(settings.backend, settings.options)

    def solve(self) -> HierarchySolution:
        """The cascade on the arrays' current contents."""
        t0 = time.perf_counter()
        self._run.reset()
        return _run_compiled(self._run, self.levels, self.settings, t0, self._daqp)

    def solve_quick(self) -> tuple | None:
        """The common case in fewer calls than :meth:`solve`: (x, level costs, seconds in the QPs,
        their count) when the run solves every level QP itself (DAQP in C++) and ends without a
        warning, its costs finite — the x and costs :meth:`solve` returns then, status
        "optimal". None otherwise: call :meth:`solve`."""
        return _solve_quick(self.quick_calls())

    def quick_calls(self) -> tuple | None:
        """(solve, daqp, result) that :meth:`solve_quick` makes — ``solve(daqp)`` is "done", then
        ``result()`` is its tuple or None — for a caller that makes them itself (the compiled
        cycle); None where the run cannot solve its QPs itself (another backend, DAQP's C
        interface not usable)."""
        if self._daqp is None or BACKENDS.get(self.settings.backend) is not solve_daqp:
            return None
        return self._run.solve_daqp, self._daqp, self._run.quick


def _bound_arguments(who, method, built, levels, settings, first_level_solution):
    """A bound run's arguments checked → (levels, n, first_level_solution, settings):
    RuntimeError if the extension is not ``built``, ValueError for another method than
    ``method``, for what :func:`solve_hierarchy` refuses, or for arrays a compiled run cannot hold
    (held, not copied: a converted copy would never see the new contents)."""
    if not built:
        raise RuntimeError(f"{who} needs wholebody._cascade, which is not built")
    settings = settings_or_default(settings, HIERARCHY_DEFAULT)
    if settings.method != method:
        raise ValueError(f"settings: {who} runs method {method!r}, got {settings.method!r}")
    levels, n, fls = _checked_arguments(levels, settings, first_level_solution)
    for L in levels:
        for field_name in ("B", "b", "w", "C", "lower", "upper", "v"):
            a = getattr(L, field_name)
            if a.dtype != np.float64 or not a.flags.c_contiguous:
                raise ValueError(f"{who}: level {L.name!r} {field_name}: needs a C-contiguous "
                                 f"float64 array (it is held, not copied)")
    return levels, n, fls, settings


def _new_weighted_run(levels, n, eps, feas_tol):
    """A compiled weighted QP on the arrays of ``levels`` = [hard, objective] (held, not copied)."""
    return _WeightedRun([L.B for L in levels], [L.b for L in levels], [L.w for L in levels],
                        [L.C for L in levels], [L.lower for L in levels],
                        [L.upper for L in levels], [L.v for L in levels],
                        [L.name for L in levels], n, eps, feas_tol)


def _run_weighted(run, levels, settings, t0, daqp=None):
    """:func:`.weighted._solve_weighted` on a compiled run → HierarchySolution, or the reason (a
    str) where the Python function gives one (the QP failed, or the hard level does not hold).
    ``daqp`` (a :func:`_daqp_in_cascade` solver) lets the run solve the QP itself; otherwise, or
    when the QP has no rows, ``settings.backend`` solves it from Python."""
    if daqp is not None and BACKENDS.get(settings.backend) is solve_daqp:
        kind = run.solve_daqp(daqp)
    else:
        kind = "qp"
    qp_time = None  # of the QP solved here (not by the run)
    if kind == "qp":
        tq = time.perf_counter()
        y, status, ok = solve_qp(*run.qp(), backend=settings.backend, **settings.options)
        qp_time = time.perf_counter() - tq
        if not ok:
            log.debug("weighted QP failed: %s", status)
            return status
        kind = run.give(y)
    if kind != "done":
        log.debug("weighted QP: %s", run.status)
        return run.status
    x, costs, res, vio, level_times, run_qp_time = run.result()
    return _finish(levels, x, "optimal", True, t0, level_times, "weighted",
                   len(levels), _NO_DIMS, (), evaluated=(costs, res, vio),
                   timings={"qp": run_qp_time if qp_time is None else qp_time, "qps": 1})


def _solve_weighted_compiled(levels, n, settings, feas_tol, t0):
    """:func:`.weighted._solve_weighted`, compiled (``wholebody._cascade.WeightedRun``)."""
    return _run_weighted(_new_weighted_run(levels, n, settings.regularization, feas_tol), levels,
                         settings, t0, _daqp_in_cascade(settings.backend, settings.options))


class BoundWeighted:
    """The compiled weighted QP bound to the arrays of ``levels`` = [hard, objective], as
    :class:`BoundCascade` is for the cascade: :meth:`solve` returns what
    ``solve_hierarchy(levels, settings)`` (``settings.method`` "weighted") would for the arrays'
    current contents — where the weighted QP gives none, the cascade's result, recorded in
    ``method`` and ``warnings`` (or the failure, ``settings.weighted_fallback`` False).
    ``feas_tol`` checks the hard level; the other tolerances are those of that cascade (as
    :func:`solve_hierarchy`'s). The arrays must keep their shapes and stay
    finite (not re-checked). Needs the compiled extension (:data:`available`)."""

    available = _WeightedRun is not None

    def __init__(self, levels, settings: SolverSettings | None = None, *, rank_tol: float = 1e-9,
                 drop_tol: float = 1e-9, relax_tol: float = 1e-9, feas_tol: float = 1e-6):
        levels, n, _, settings = _bound_arguments("BoundWeighted", "weighted", self.available,
                                                  levels, settings, None)
        if len(levels) > 2:
            raise ValueError(f"method 'weighted' takes [hard, objective] levels, got {len(levels)} levels")
        self.levels, self.settings, self.n = levels, settings, n
        self._tols = (rank_tol, drop_tol, relax_tol, feas_tol)
        self._run = _new_weighted_run(levels, n, settings.regularization, feas_tol) if n else None
        self._daqp = _daqp_in_cascade(settings.backend, settings.options)

    def solve(self) -> HierarchySolution:
        """The weighted QP on the arrays' current contents (or the cascade's result)."""
        t0 = time.perf_counter()
        if self._run is None:  # no variable: the cascade evaluates, as in solve_hierarchy
            return _solve_compiled(self.levels, 0, self.settings, None, self._tols, t0)
        sol = _run_weighted(self._run, self.levels, self.settings, t0, self._daqp)
        if isinstance(sol, str):
            sol = _without_weighted_solution(self.levels, self.n, self.settings, self._tols, t0,
                                             sol)
        return sol

    def solve_quick(self) -> tuple | None:
        """As :meth:`BoundCascade.solve_quick`: (x, level costs, seconds in DAQP, 1) when DAQP
        (in C++) solves the weighted QP and the hard level holds, its costs finite; None
        otherwise: call :meth:`solve`."""
        return _solve_quick(self.quick_calls())

    def quick_calls(self) -> tuple | None:
        """As :meth:`BoundCascade.quick_calls` (None also without variables)."""
        if (self._run is None or self._daqp is None
                or BACKENDS.get(self.settings.backend) is not solve_daqp):
            return None
        return self._run.solve_daqp, self._daqp, self._run.quick


def _solve_quick(calls) -> tuple | None:
    """What a bound run's ``solve_quick`` returns, from its ``quick_calls()``."""
    if calls is None:
        return None
    solve, daqp, result = calls
    return result() if solve(daqp) == "done" else None


def _daqp_on_run(run, opts):
    """DAQP on the compiled cascade's pending level QP, (y, status, ok) as ``solve_daqp`` gives
    them: the run scales the rows (``run.daqp_qp``) and checks the unscaled ones
    (``run.qp_violation``), which saves the generic adapter's array round trips.
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
    C++, without :func:`_daqp_on_run`'s calls into Python), or None: ``backend`` is not the stock DAQP
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
