"""From a stack of tasks to solver levels and back to (qdd, lambda, tau).

Herzog et al. 2016 Sect. 2.3: the decision vector is either the **full** y = [qdd, lambda, tau] with
all nv rows of the equations of motion (eq. 1) as a task, or the **reduced** x = [qdd, lambda] with
tau eliminated everywhere by eq. 14 (tau = M_u qdd + h_u - J_{c,u}^T lambda) and only the 6
Newton-Euler rows (eq. 13) kept. A task row ``a_q qdd + a_l lambda + a_t tau`` becomes, in reduced
form, ``(a_q + a_t M_u) qdd + (a_l - a_t J_{c,u}^T) lambda`` with ``a_t h_u`` moved to the right.

Sect. 2.4, the analytic first priority: when level 1 holds only the dynamics (Newton-Euler, or the
full eq. 1) and torque limits, y*_1 = B_1^+ b_1 via the small Gram matrix B_1 B_1^T and Z_1 spans the
null space of B_1 — no QP. tau = 0, lambda = 0, qdd = -M^{-1} h satisfies level 1 exactly (eqs. 17-18),
so the torque limits are then imposed with zero slack on every lower level.
"""

from __future__ import annotations

import functools
import logging
import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from .guard import Outcome, guard_torque
from .robot import FREE_FLYER_NV, GRAVITY, Robot
from .solvers import Level, SolverSettings, solve_hierarchy
from .solvers.compiled_cascade import BoundCascade, BoundWeighted
from .solvers.hierarchy import analytic_first_level
from .solvers.settings import settings_or_default
from .tasks.base import Task, TaskRows
from .tasks.dynamics import FullDynamics, NewtonEuler
from .tasks.limits import TorqueLimits
from .variables import Variables

log = logging.getLogger(__name__)


class Stack:
    """Prioritised levels of tasks (highest first), e.g. Herzog et al. 2016 Tables 1, 2 and 4."""

    def __init__(self, levels: Sequence[Sequence[Task]]):
        self.levels = [list(level) for level in levels]
        if not self.levels or any(not level for level in self.levels):
            raise ValueError("levels: a stack needs at least one level and no empty level")

    def tasks(self) -> list[Task]:
        return [t for level in self.levels for t in level]

    def auxiliary(self) -> dict[str, int]:
        """The auxiliary variables its tasks use (name -> size, in task order): the
        :class:`~wholebody.variables.Variables` a cycle solves for by default. A name whose size
        no task declares, or declared with two sizes, is a ValueError."""
        sizes: dict[str, int | None] = {}
        for task in self.tasks():
            for name, size in task.auxiliary().items():
                known = sizes.get(name)
                if known is not None and size is not None and size != known:
                    raise ValueError(f"task '{task.name}': auxiliary variable {name!r} has size "
                                     f"{size}, another task declares {known}")
                if known is None:
                    sizes[name] = size
        undeclared = [n for n, size in sizes.items() if size is None]
        if undeclared:
            raise ValueError(f"auxiliary: no task declares the size of {undeclared}")
        return sizes

    def find(self, name: str) -> Task:
        for t in self.tasks():
            if t.name == name:
                return t
        raise ValueError(f"task: no task named '{name}' in the stack")

    def locate(self, name: str) -> tuple[int, int]:
        """(level index, position in the level) of the task named ``name``; ValueError if absent."""
        for i, level in enumerate(self.levels):
            for j, t in enumerate(level):
                if t.name == name:
                    return i, j
        raise ValueError(f"task: no task named '{name}' in the stack")

    def insert(self, level: int, task: Task, before: str | None = None,
               after: str | None = None) -> Task:
        """Add ``task`` to ``levels[level]`` (0 = the highest priority): at the end of the level, or
        just before / after the task named ``before`` / ``after``, which must be on that level.
        Task names stay unique (ValueError otherwise). Returns ``task``."""
        if before is not None and after is not None:
            raise ValueError("insert: give 'before' or 'after', not both")
        if not 0 <= level < len(self.levels):
            raise ValueError(f"insert: level {level} is not in 0..{len(self.levels) - 1}")
        if any(t.name == task.name for t in self.tasks()):
            raise ValueError(f"insert: the stack already has a task named '{task.name}'")
        tasks = self.levels[level]
        position = len(tasks)
        anchor = before if before is not None else after
        if anchor is not None:
            i, j = self.locate(anchor)
            if i != level:
                raise ValueError(f"insert: task '{anchor}' is on level {i}, not {level}")
            position = j if before is not None else j + 1
        tasks.insert(position, task)
        return task

    def remove(self, name: str) -> Task:
        """Remove the task named ``name`` and return it; a level left empty is an error."""
        i, j = self.locate(name)
        if len(self.levels[i]) == 1:
            raise ValueError(f"remove: '{name}' is the only task of level {i}; a stack has no "
                             f"empty level")
        return self.levels[i].pop(j)

    def replace(self, name: str, task: Task) -> Task:
        """Put ``task`` in the place of the task named ``name`` and return the replaced task."""
        i, j = self.locate(name)
        if task.name != name and any(t.name == task.name for t in self.tasks()):
            raise ValueError(f"replace: the stack already has a task named '{task.name}'")
        old, self.levels[i][j] = self.levels[i][j], task
        return old

    def table(self, robot: Robot, variables: Variables) -> str:
        """The stack as a table: rank, number of eq/ineq rows, task names (at the robot's state)."""
        lines = [f"{'rank':<5} {'rows':<14} task", "-" * 48]
        for rank, level in enumerate(self.levels, start=1):
            for i, task in enumerate(level):
                rows = task.rows(robot, variables)
                kind = "eq" if rows.is_equality else "ineq"
                lines.append(f"{rank if i == 0 else '':<5} {f'{rows.m} {kind}':<14} {task.name}")
        lines.append(f"DoFs: {robot.na}   variables: {variables.n_full} full")
        return "\n".join(lines)


@dataclass
class TaskReport:
    """How well one task was achieved: residual (eq) or violation (ineq) norm, active rows."""

    name: str
    level: int
    kind: str
    rows: int
    error: float
    active: int = 0


@dataclass
class Solution:
    """Result of one control cycle (Herzog et al. 2016 eq. 14 for tau): ``tau`` is finite and
    within the torque limits whatever happened (made by :func:`wholebody.guard.guard_torque`);
    ``outcome`` says what happened (:class:`~wholebody.guard.Outcome`) and ``status`` why."""

    qdd: np.ndarray
    lam: np.ndarray
    tau: np.ndarray
    forces: dict[str, np.ndarray]
    outcome: Outcome
    status: str
    level_costs: np.ndarray
    tasks: list[TaskReport] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    contacts: tuple[str, ...] = ()
    #: the values of the auxiliary variables (e.g. slacks), by name
    auxiliary: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """The cycle solved its problem (outcome SOLVED or FALLBACK)."""
        return self.outcome.ok

    def sacrificed(self, tol: float = 1e-6) -> list[TaskReport]:
        """Tasks not achieved (error above ``tol``), worst first."""
        return sorted((t for t in self.tasks if t.error > tol), key=lambda t: -t.error)

    @property
    def contact_forces(self) -> dict[str, np.ndarray]:
        return self.forces


class Formulation:
    """Maps task rows to solver levels over the reduced [qdd, lambda] or full [qdd, lambda, tau].

    The solver sees the decision vector in scaled units, x = s * x_scaled, with s = 1 for
    accelerations, the robot's weight m g for contact forces and tau_max for torques, so that the
    regulariser eps ||x_scaled||^2 of eq. 5 weighs rad/s^2, N and Nm alike. (Unscaled, eps ||lambda||^2
    with lambda ~ 500 N outweighs task costs of 1e-2 and visibly trades off the contact constraint.)
    """

    def __init__(self, robot: Robot, reduced: bool = True):
        self.robot = robot
        self.reduced = reduced
        self._tau_scale = np.abs(robot.torque_limits.upper(robot.q_ref[7:]))
        self._plan: _Plan | None = None
        self._scales_key = None
        self._variables: dict[tuple, tuple] = {}  # see variables_for

    def variables_for(self, stack: Stack, variables: Variables | None = None) -> Variables:
        """``variables`` (None: all the robot's contacts) with the auxiliary variables the
        stack's tasks use and ``variables`` lacks added after its own (a task inserted into a
        controller's stack may bring a slack); made again only when the stack's levels change
        (compared by task identity)."""
        key = (id(stack), id(variables))
        entry = self._variables.get(key)
        levels = stack.levels
        if entry is not None and entry[0] is variables and entry[1] == levels:
            return entry[2]
        base = Variables(self.robot) if variables is None else variables
        own = dict(base.auxiliary)
        needed = stack.auxiliary()
        for name, size in needed.items():
            if own.get(name, size) != size:
                raise ValueError(f"variables: auxiliary variable {name!r} has size {own[name]}, "
                                 f"the stack's tasks declare {size}")
        missing = {n: size for n, size in needed.items() if n not in own}
        result = Variables(self.robot, base.contacts, {**own, **missing}) if missing else base
        if len(self._variables) > 64:  # (variables made anew every cycle: keep a few)
            self._variables.clear()
        self._variables[key] = (variables, [list(level) for level in levels], result)
        return result

    def size(self, variables: Variables) -> int:
        return (variables.nv + variables.n_lambda + (0 if self.reduced else variables.na)
                + variables.n_aux)

    def scales(self, variables: Variables) -> np.ndarray:
        """s with x = s * x_scaled (see class docstring; auxiliary variables unscaled)."""
        key = (variables.nv, variables.n_lambda, variables.n_aux)
        if self._scales_key != key:
            parts = [np.ones(variables.nv), np.full(variables.n_lambda, self.robot.mass * GRAVITY)]
            if not self.reduced:
                parts.append(self._tau_scale)
            parts.append(np.ones(variables.n_aux))
            self._scales, self._scales_key = np.concatenate(parts), key
        return self._scales

    # ------------------------------------------------------------------ rows -> x
    def levels(self, stack: Stack, variables: Variables) -> tuple[list[Level], list[list[tuple]]]:
        """Solver levels over the scaled x, plus per level (task, kind, A, rhs...) for diagnostics.

        The level matrices are allocated once per stack structure and contact set (a plan) and
        refilled in place every cycle; the returned arrays are only valid until the next call.
        """
        robot = self.robot
        key = (id(stack), tuple(id(t) for tasks in stack.levels for t in tasks), variables.contacts,
               variables.auxiliary, self.reduced)
        rows_now = [[task.rows(robot, variables) for task in tasks] for tasks in stack.levels]
        plan = self._plan
        if plan is not None and plan.key == key:
            filled = plan.fill(self, variables, rows_now)
            if filled is not None:
                return filled
        for task in stack.tasks():
            if self.reduced and isinstance(task, FullDynamics):
                raise ValueError("FullDynamics belongs to the full formulation; the reduced "
                                 "one uses NewtonEuler (tau is eliminated by eq. 14)")
        plan = self._plan = _Plan(key, stack, rows_now, self.size(variables))
        return plan.fill(self, variables, rows_now)

    # ------------------------------------------------------------------ analytic level 1
    @staticmethod
    def analytic_first_level(stack: Stack) -> bool:
        """True when level 1 is dynamics (+ torque limits) only, as Herzog et al. 2016 Sect. 2.4."""
        first = stack.levels[0]
        return (any(isinstance(t, (NewtonEuler, FullDynamics)) for t in first)
                and all(isinstance(t, (NewtonEuler, FullDynamics, TorqueLimits)) for t in first))

    @staticmethod
    def first_level_solution(level: Level) -> tuple[np.ndarray, np.ndarray]:
        """x1 = B⁺ b and an orthonormal null-space basis Z1 of level 1 (eq. 17); see
        :func:`wholebody.solvers.hierarchy.analytic_first_level`."""
        return analytic_first_level(level)

    @staticmethod
    def uses_analytic_first_level(stack: Stack, settings: SolverSettings) -> bool:
        """Whether level 1 is solved in closed form (eq. 17) with ``settings``: as its
        ``analytic_first_level`` says, None = when :meth:`analytic_first_level` allows it;
        True where level 1 does not allow it is a ValueError."""
        possible = Formulation.analytic_first_level(stack)
        if settings.analytic_first_level is None:
            return possible
        if settings.analytic_first_level and not possible:
            raise ValueError("analytic_first_level: True, but level 1 must hold only dynamics "
                             "and torque limits")
        return settings.analytic_first_level

    # ------------------------------------------------------------------ solve
    def solve(self, stack: Stack, variables: Variables | None = None,
              settings: SolverSettings | None = None, diagnostics: bool = True) -> Solution:
        """Solve the stack at the robot's cached state (call ``robot.update`` first).

        ``settings`` (None: ``SolverSettings()``): ``settings.backend`` solves the QPs
        (``backend_options``: its settings, e.g. DAQP's ``primal_tol``; see
        :func:`~wholebody.solvers.hierarchy.solve_hierarchy`); if it fails, the cycle is solved
        again with ``settings.fallback_backend`` (each backend has rare failure modes
        of its own on these ill-conditioned cascades — measured in
        ``benchmarks/bench_wbc.py``). ``diagnostics`` computes the per-task report (extra
        work every cycle). Never raises for numerical reasons: a
        failed solve returns a :class:`Solution` with outcome ``HELD`` (``ok`` False), the reason,
        and a torque computed from the best available solution, clipped to the torque limits; a
        cached state whose rigid-body terms are not finite (products of a velocity ~1e155
        overflow) returns ``HELD`` with zero torque and a reason naming ``v``.
        ``settings.regularization`` is the eps of eq. 5
        on the scaled variables; the paper's 1e-4 visibly trades tasks off (see the tests), 1e-6
        does not, and much smaller values make quadprog cycle. ``settings.analytic_first_level``:
        see :meth:`uses_analytic_first_level`.
        """
        settings = settings_or_default(settings)
        robot = self.robot
        variables = self.variables_for(stack, variables)
        t0 = time.perf_counter()
        try:
            levels, meta = self.levels(stack, variables)
        except ValueError:
            if robot.terms_finite():
                raise
            return unsolved_solution(robot.nv, variables, robot.torque_bounds(),
                                     len(stack.levels), overflow_status(robot.v))
        t_rows = time.perf_counter()
        result, outcome, status = solve_levels(
            levels, self.uses_analytic_first_level(stack, settings), settings)
        t_solve = time.perf_counter()
        x = result.x * self.scales(variables)
        solution = self._recover(x, variables, outcome, status, result.costs)
        if diagnostics:
            solution.tasks = self.task_reports(result.x, meta)
        solution.timings = {"rows": t_rows - t0, "solve": t_solve - t_rows,
                            "total": time.perf_counter() - t0,
                            "qp": result.timings.get("qp", np.nan),
                            "qps": result.timings.get("qps", 0)}
        return solution

    def _recover(self, x, variables: Variables, outcome: Outcome, status: str,
                 costs) -> Solution:
        robot, nv, nl = self.robot, variables.nv, variables.n_lambda
        qdd, lam = x[:nv].copy(), x[nv:nv + nl].copy()
        if self.reduced:
            J_u = robot.stacked_contact_jacobian(variables.contacts)[:, FREE_FLYER_NV:]
            tau = robot.M[FREE_FLYER_NV:] @ qdd + robot.h[FREE_FLYER_NV:] - J_u.T @ lam  # eq. 14
        else:
            tau = x[nv + nl:nv + nl + variables.na].copy()
        return make_solution(qdd, lam, tau, robot.torque_bounds(), outcome, status, costs,
                             variables, x=x)

    def task_rows(self, task: Task) -> tuple[np.ndarray, ...]:
        """(A, target) of an equality task's rows, (A, lower, upper) of an inequality task's, in
        the last :meth:`solve`'s level arrays (views, valid until the next solve; A over the
        solver's scaled variables)."""
        for level in (self._plan.levels if self._plan is not None else ()):
            for entry in level.meta:
                if entry[0] is task:
                    return entry[2:4] if entry[1] == "eq" else entry[2:5]
        raise ValueError(f"task '{task.name}': no rows in the last solve")

    @staticmethod
    def task_reports(x, meta, active_tol: float = 1e-7) -> list[TaskReport]:
        reports = []
        for rank, level_meta in enumerate(meta, start=1):
            for task, kind, A, first, second in level_meta:
                value = A @ x
                if kind == "eq":
                    reports.append(TaskReport(task.name, rank, kind, len(value),
                                              float(np.linalg.norm(value - first))))
                else:
                    violation = np.maximum(0.0, np.maximum(first - value, value - second))
                    scale = active_tol * (1.0 + np.abs(value))
                    active = int(np.sum((value - first <= scale) | (second - value <= scale)))
                    reports.append(TaskReport(task.name, rank, kind, len(value),
                                              float(np.linalg.norm(violation)), active))
        return reports


def solve_levels(levels: list[Level], analytic_first_level: bool, settings: SolverSettings,
                 bound: BoundCascade | BoundWeighted | None = None):
    """The levels solved as :meth:`Formulation.solve` does with ``settings`` → (HierarchySolution,
    Outcome, status): the analytic first level (eq. 17) when ``analytic_first_level`` (resolved
    by :meth:`Formulation.uses_analytic_first_level`), a failed cascade level QP retried with
    ``settings.fallback_backend`` (one QP, not the whole cascade again; outcome FALLBACK), other
    methods re-solved as a cascade with it. ``bound``: a :class:`BoundCascade` made with these
    same settings, or a :class:`BoundWeighted` made with them without the fallback backend, on
    these levels' arrays, used for the first attempt (a control loop's fast path). ``backend_options`` are ``backend``'s (not passed to the fallback backend)."""
    cascade = settings.method == "cascade"
    fls = "analytic" if analytic_first_level and cascade else None
    backend, fallback = settings.backend, settings.fallback_backend
    result = bound.solve() if bound is not None else solve_hierarchy(
        levels, settings=settings if cascade else _without_fallback(settings),
        first_level_solution=fls)
    status, outcome = result.status, Outcome.SOLVED if result.ok else Outcome.HELD
    retried = [w for w in result.warnings if w.endswith(f"solved with {fallback}")]
    if result.ok and retried:
        outcome = Outcome.FALLBACK
        status = f"optimal ({fallback} after {backend}: {'; '.join(retried)})"
    if not result.ok and fallback:
        retry = solve_hierarchy(levels, settings=_fallback_cascade(settings),
                                first_level_solution=fls)
        if retry.ok:
            log.debug("%s failed (%s); solved with %s", backend, result.status, fallback)
            status = f"optimal ({fallback} after {backend}: {result.status})"
            result, outcome = retry, Outcome.FALLBACK
    return result, outcome, status


@functools.lru_cache(maxsize=64)
def _without_fallback(settings: SolverSettings) -> SolverSettings:
    """``settings`` for a first attempt that is not a cascade (its whole cascade is retried)."""
    return replace(settings, fallback_backend=None)


@functools.lru_cache(maxsize=64)
def _fallback_cascade(settings: SolverSettings) -> SolverSettings:
    """The cascade by ``settings.fallback_backend`` alone, with its own options, at the same ε."""
    return SolverSettings(method="cascade", backend=settings.fallback_backend,
                          fallback_backend=None, regularization=settings.regularization)


def make_solution(qdd: np.ndarray, lam: np.ndarray, tau: np.ndarray,
                  bounds: tuple[np.ndarray, np.ndarray], outcome: Outcome, status: str, costs,
                  variables: Variables, excess: float | None = None, x=None) -> Solution:
    """A :class:`Solution` whose torque went through :func:`~wholebody.guard.guard_torque` with
    ``bounds`` = (tau_min, tau_max) (and ``excess``, if known); ``x``: the solution vector whose
    last entries are the auxiliary variables (unscaled), if there are any."""
    tau, outcome, status = guard_torque(tau, bounds[0], bounds[1], outcome, status, excess)
    forces = {n: lam[s] for n, s in variables.lambda_slices.items()}  # (in contact order)
    solution = Solution(qdd, lam, tau, forces, outcome, status, np.asarray(costs),
                        contacts=variables.contacts)
    if variables.n_aux and x is not None:
        tail = np.array(x[len(x) - variables.n_aux:])
        solution.auxiliary = {n: tail[s] for n, s in variables.auxiliary_slices.items()}
    return solution


def overflow_status(v) -> str:
    """The reason of a cycle whose rigid-body terms are not finite at a finite state: products of
    the velocity ``v`` overflow (Coriolis terms and contact drifts go as |v|², which overflows
    beyond ~1e154)."""
    largest = float(np.max(np.abs(np.asarray(v, dtype=float))))
    return (f"v: the rigid-body terms at this state are not finite (largest |v| {largest:.3g}: "
            f"products of the velocity overflow); not solved, zero torque")


def unsolved_solution(nv: int, variables: Variables, bounds: tuple[np.ndarray, np.ndarray],
                      n_levels: int, status: str) -> Solution:
    """A cycle that could not be posed (no QP solved): zero q̈, λ and torque (inside any limits),
    outcome ``HELD``, the reason ``status``; NaN level costs."""
    sol = make_solution(np.zeros(nv), np.zeros(variables.n_lambda), np.zeros(bounds[0].shape),
                        bounds, Outcome.HELD, status, np.full(n_levels, np.nan), variables)
    sol.timings = {"qps": 0}
    return sol


def _signature(r: TaskRows) -> tuple:
    """What the preallocated layout depends on: row count, kind and which blocks are present."""
    return (r.m, r.target is not None, r.qdd is None, r.lam is None, r.tau is None, r.aux is None)


class _LevelPlan:
    """Where each task's rows go in one level (views into the plan's buffers) and its solver Level."""

    def __init__(self, rank: int, tasks: Sequence[Task], rows: Sequence[TaskRows], start: int, n: int):
        self.rank = rank
        self.slots = []  # (index of the task in the level, task, is_eq, start, stop, signature)
        k = m = 0
        for i, (task, r) in enumerate(zip(tasks, rows)):
            if r.m == 0:
                continue
            if r.is_equality:
                self.slots.append((i, task, True, k, k + r.m, _signature(r)))
                k += r.m
            else:
                self.slots.append((i, task, False, m, m + r.m, _signature(r)))
                m += r.m
        self.start, self.k, self.m = start, k, m  # equality rows at start, inequality rows after
        self.empty = [i for i, r in enumerate(rows) if r.m == 0]  # tasks without rows (for now)

    def bind(self, mat: np.ndarray, vec: np.ndarray, lo: np.ndarray, up: np.ndarray) -> None:
        """Take views of the plan's buffers: rows [E; C] of ``mat``, [e; w | 0; vw] of ``vec``."""
        s, k, m = self.start, self.k, self.m
        self.E, self.C = mat[s:s + k], mat[s + k:s + k + m]
        self.e, self.w = vec[0, s:s + k], vec[1, s:s + k]
        self.vw = vec[1, s + k:s + k + m]
        self.lo, self.up = lo[s + k:s + k + m], up[s + k:s + k + m]
        self.meta = [(task, "eq", self.E[a:b], self.e[a:b], None) if eq else
                     (task, "ineq", self.C[a:b], self.lo[a:b], self.up[a:b])
                     for _, task, eq, a, b, _ in self.slots]
        self.level = Level.trusted(self.E, self.e, self.w, self.C, self.lo, self.up, self.vw,
                                   name=f"level {self.rank}")

    def raise_invalid(self) -> None:
        """Name the task whose rows are NaN/inf, whose bounds cross or whose weight is bad."""
        for _, task, eq, a, b, _ in self.slots:
            if not self._valid(slice(a, b), eq):
                raise ValueError(f"level {self.rank}: task '{task.name}' produced NaN/inf rows "
                                 f"(or entries whose sum overflows), lower > upper or a bad "
                                 f"weight")

    def _valid(self, rows: slice, eq: bool) -> bool:
        if eq:
            w = self.w[rows]
            return bool(np.isfinite(self.E[rows].sum() + self.e[rows].sum() + w.sum())
                        and (w >= 0).all())
        lo, up, vw = self.lo[rows], self.up[rows], self.vw[rows]
        return bool(np.isfinite(self.C[rows].sum() + vw.sum()) and (vw > 0).all()
                    and (lo <= up).all())


class _Plan:
    """Level layout for one stack structure and contact set (see ``Formulation.levels``)."""

    def __init__(self, key, stack: Stack, rows: list[list[TaskRows]], n: int):
        self.key = key
        self.levels, start = [], 0
        for rank, (tasks, level_rows) in enumerate(zip(stack.levels, rows), start=1):
            lp = _LevelPlan(rank, tasks, level_rows, start, n)
            self.levels.append(lp)
            start += lp.k + lp.m
        # one buffer for all levels' rows (and one per vector kind): the per-cycle column scaling
        # and the boundary check are then a few whole-buffer operations, not a few per level
        self.mat = np.zeros((start, n))
        self.vec = np.ones((2, start))  # [targets e (eq rows; 0 for ineq rows); weights w | V]
        self.vec[0] = 0.0
        self.lo, self.up = np.zeros(start), np.zeros(start)
        for lp in self.levels:
            lp.bind(self.mat, self.vec, self.lo, self.up)
        # weights must be >= 0 (equality rows) and > 0 (inequality rows): w >= w_min
        self.w_min = np.zeros(start)
        for lp in self.levels:
            self.w_min[lp.start + lp.k:lp.start + lp.k + lp.m] = np.nextafter(0.0, 1.0)

    def check(self) -> None:
        """The boundary check of the refilled arrays: finite rows, lower <= upper, valid weights.

        A NaN reference or gain set on a task ends here as a ValueError naming the level and task.
        A sum is non-finite iff some entry is NaN/inf (or it overflows, which is as bad); NaN
        bounds and weights fail the comparisons.
        """
        vec = self.vec
        if (np.isfinite(self.mat.sum() + vec.sum()) and (self.lo <= self.up).all()
                and (vec[1] >= self.w_min).all()):
            return
        for lp in self.levels:
            lp.raise_invalid()

    def fill(self, formulation: "Formulation", variables: Variables, rows: list[list[TaskRows]]):
        """Refill the level arrays in place; None if a task's rows no longer fit the layout."""
        robot, nv, nl = formulation.robot, variables.nv, variables.n_lambda
        scale_tail = formulation.scales(variables)[nv:]
        eq14 = _memo(lambda: eq14_blocks(robot, variables)) if formulation.reduced else None
        for lp, level_rows in zip(self.levels, rows):
            for i in lp.empty:
                if level_rows[i].m:
                    return None
            for i, task, eq, a, b, sig in lp.slots:
                r = level_rows[i]
                if _signature(r) != sig:
                    return None
                if eq:
                    place_rows(r, lp.E[a:b], lp.e[a:b], None, None, nv, nl, eq14)
                    lp.w[a:b] = task.weight
                else:
                    place_rows(r, lp.C[a:b], None, lp.lo[a:b], lp.up[a:b], nv, nl, eq14)
                    lp.vw[a:b] = task.weight
        self.mat[:, nv:] *= scale_tail
        self.check()
        return [lp.level for lp in self.levels], [lp.meta for lp in self.levels]


def eq14_blocks(robot: Robot, variables: Variables) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M_u, -J_u^T, h_u) of eq. 14, tau = M_u qdd + h_u - J_u^T lambda, at the robot's cached
    state for the active contacts."""
    J_u = robot.stacked_contact_jacobian(variables.contacts)[:, FREE_FLYER_NV:]
    return robot.M[FREE_FLYER_NV:], -J_u.T, robot.h[FREE_FLYER_NV:]


def _memo(make):
    """``make()`` evaluated on the first call only."""
    cache = []

    def get():
        if not cache:
            cache.append(make())
        return cache[0]
    return get


def place_rows(r: TaskRows, A: np.ndarray, target, lower, upper, nv: int, nl: int,
               eq14=None) -> None:
    """A task's rows into ``A`` (its rows over [qdd, lambda, aux] or [qdd, lambda, tau, aux],
    unscaled; the auxiliary columns last) and into ``target`` (equalities) or ``lower``/``upper``
    (inequalities). ``eq14``: None for the full formulation (tau columns after lambda), else a
    callable giving :func:`eq14_blocks` (the reduced one: a tau block is replaced by eq. 14,
    Herzog et al. 2016). ``A``'s columns without a block are left as they are."""
    lam_cols = slice(nv, nv + nl)
    if r.qdd is not None:
        A[:, :nv] = r.qdd
    if r.lam is not None:
        A[:, lam_cols] = r.lam
    offset = None
    if r.tau is not None:
        if eq14 is not None:  # eq. 14: tau = M_u qdd + h_u - J_u^T lambda
            M_u, mJ_uT, h_u = eq14()
            if r.tau_identity:
                tau_qdd, tau_lam, offset = M_u, mJ_uT, h_u
            else:
                tau_qdd, tau_lam, offset = r.tau @ M_u, r.tau @ mJ_uT, r.tau @ h_u
            if r.qdd is None:
                A[:, :nv] = tau_qdd
            else:
                A[:, :nv] += tau_qdd
            if r.lam is None:
                A[:, lam_cols] = tau_lam
            else:
                A[:, lam_cols] += tau_lam
        else:
            A[:, nv + nl:nv + nl + r.tau.shape[1]] = r.tau
    if r.aux is not None:
        A[:, A.shape[1] - r.aux.shape[1]:] = r.aux
    if r.target is not None:
        if offset is None:
            target[:] = r.target
        else:
            np.subtract(r.target, offset, out=target)
    else:
        if offset is None:
            lower[:], upper[:] = r.lower, r.upper
        else:
            np.subtract(r.lower, offset, out=lower)
            np.subtract(r.upper, offset, out=upper)
