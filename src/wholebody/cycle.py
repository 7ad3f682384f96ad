"""One control cycle of hierarchical inverse dynamics — robot update, task rows, solve, tau — with
the rigid-body terms and the task rows in compiled code (Herzog et al. 2016, Sect. 2 and 5.1).

:class:`HierarchyCycle` does what ``robot.update(q, v)`` followed by
``Formulation(robot).solve(stack, variables)`` does, with the same results (tests/parity/test_cycle.py
compares the level arrays and the torques): the compiled part (``wholebody._hierarchy_cycle``,
src/wholebody/native/hierarchy_cycle.cpp) computes Pinocchio's terms and every task's rows into
the level arrays, the cascade solves them (compiled as well, its level QPs by DAQP/quadprog), and
the compiled part returns tau of eq. 14. Each task's current parameters (gains, references,
weights) are read from the task objects every cycle (``ParameterPacker``), so a controller keeps
changing them on the tasks as before; in the common case one compiled call packs them, fills the
rows, runs the bound cascade or weighted QP (DAQP in C++) and recovers tau.

A task with a compiled kernel (``Task.kernel``; every task of Tables 1, 2 and 4) has its rows
written in C++ from the parameters its schema declares (:mod:`wholebody.tasks.schema`); a task
without one (a user's own) writes its rows from Python (:meth:`Task.rows`) into the same arrays,
and the rest of the stack stays compiled. With the native engine the Python robot's cache
(``robot.com``, ``robot.M``...) is updated only when the stack has such a task: read the cycle's
own :attr:`HierarchyCycle.com`, :attr:`~HierarchyCycle.vcom`, :attr:`~HierarchyCycle.h_G`.
"""

from __future__ import annotations

import functools
import logging
import time
from types import SimpleNamespace
from typing import NamedTuple, Sequence

import numpy as np

from .formulation import (Formulation, Solution, Stack, _without_fallback, eq14_blocks,
                          make_solution, overflow_status, place_rows, solve_levels,
                          unsolved_solution)
from .guard import Outcome
from .robot import Robot
from .solvers import Level, SolverSettings
from .solvers.compiled_cascade import BoundCascade, BoundWeighted
from .solvers.settings import settings_or_default
from .tasks import FullDynamics
from .tasks.base import Task, contact_subset
from .tasks.schema import KernelTask, LayoutContext, Param, Size
from .variables import Variables

try:
    from . import _hierarchy_cycle
except ImportError:  # built without the compiled parts (see setup.py)
    _hierarchy_cycle = None

log = logging.getLogger(__name__)

ENGINES = ("auto", "native", "python")


def native_available() -> bool:
    """True when the compiled cycle was built."""
    return _hierarchy_cycle is not None


@functools.lru_cache(maxsize=None)
def warn_python_fallback(what: str, reason: str) -> None:
    """Log once per (controller, reason) that ``engine="auto"`` runs the Python reference."""
    log.warning("%s: engine 'auto' runs the Python engine: %s", what, reason)


# ---------------------------------------------------------------------------- kernels
def kernel_tasks() -> dict[str, type]:
    """Every task class with a compiled kernel, by kernel name (``Task.kernel``)."""
    found, todo = {}, [Task]
    while todo:
        cls = todo.pop()
        todo.extend(cls.__subclasses__())
        if cls.has_kernel():
            found[cls.kernel] = cls
    return found


def python_tasks(stack: Stack) -> list[Task]:
    """The stack's tasks without a compiled kernel: the native engine has them write their rows
    from Python (:meth:`Task.rows`) into its arrays every cycle."""
    return [t for t in stack.tasks() if not type(t).has_kernel()]


class _Slot:
    """One task in a program: its rows [start, stop) (equalities or inequalities), the active
    contacts it applies to and, for a task with a kernel, its parameters' views in the program's
    parameter array."""

    def __init__(self, rank, order, task, eq, start, stop, layout, params=()):
        self.rank, self.order, self.task, self.eq = rank, order, task, eq
        self.start, self.stop, self.layout, self.params = start, stop, layout, list(params)


# ---------------------------------------------------------------------------- programs
class _ProgramKey(NamedTuple):
    """What a program is built for: the active contacts, the auxiliary variables, the stack's
    structure (task ids, level lengths), the tasks' layout keys and the Python tasks' row
    signatures."""

    contacts: tuple
    auxiliary: tuple
    structure: tuple
    layout: tuple
    python_rows: tuple


class _Program:
    """The level arrays of one stack and contact set, filled by the compiled cycle: per level its
    equality rows then its inequality rows (as Formulation's plan), one buffer each for all
    levels; plus the flat parameter array the tasks' schemas are packed into (offsets derived
    from :attr:`Task.params`, sent to the kernels by name). Tasks without a kernel write their
    rows from Python (``python_rows``: their rows of this cycle, which fix their row counts)."""

    def __init__(self, cycle: "HierarchyCycle", variables: Variables, key, python_rows: dict):
        robot, stack = cycle.robot, cycle.stack
        self.key = key
        self.variables = variables
        n = cycle.formulation.size(variables)
        contact_index = {c: i for i, c in enumerate(robot.contact_names)}
        active = {c: i for i, c in enumerate(variables.contacts)}
        self.slots: list[_Slot] = []
        self.level_bounds: list[tuple[int, int]] = []
        compiled = []
        start = n_params = 0
        for rank, tasks in enumerate(stack.levels, start=1):
            level = {True: [], False: []}
            for order, task in enumerate(tasks):
                layout = cycle.layout_of(task, variables)
                if id(task) in python_rows:
                    rows = python_rows[id(task)]
                    m, eq = rows.m, rows.is_equality
                else:
                    m, eq = task.row_count(layout), task.kind == "eq"
                if m:  # a task without rows here (e.g. CoP rows of point feet) has no slot
                    level[eq].append((order, task, layout, m))
            first = start
            for eq in (True, False):
                for order, task, layout, m in level[eq]:
                    slot = _Slot(rank, order, task, eq, start, start + m, layout)
                    if id(task) not in python_rows:
                        params = {}
                        for param in task.params:
                            size = param.size.resolve(layout)
                            params[param.name] = [n_params, size]
                            slot.params.append((param, n_params, size))
                            n_params += size
                        compiled.append({
                            "kernel": task.kernel, "start": start, "m": m, "eq": eq,
                            "contacts": [active[c] for c in layout.contacts], "params": params,
                            "selection": cycle.selection_of(task, layout)})
                    self.slots.append(slot)
                    start += m
            self.level_bounds.append((first, start))
        rows = start
        self.mat = np.zeros((rows, n))
        self.target, self.weights = np.zeros(rows), np.ones(rows)
        self.lower, self.upper = np.zeros(rows), np.zeros(rows)
        self.params = np.zeros(max(n_params, 1))
        self.qdd, self.lam = np.zeros(robot.nv), np.zeros(variables.n_lambda)
        self.tau, self.tau_lo, self.tau_hi = (np.zeros(robot.na) for _ in range(3))
        self.scales = cycle.formulation.scales(variables).copy()
        # a weight's least value: 0 on equality rows, above 0 on inequality rows (the fill checks)
        w_min = np.zeros(rows)
        for s in self.slots:
            w_min[s.start:s.stop] = 0.0 if s.eq else np.nextafter(0.0, 1.0)
        self.description = {
            "contacts": [contact_index[c] for c in variables.contacts],
            "reduced": cycle.formulation.reduced, "auxiliary": variables.n_aux, "rows": rows,
            "nparams": self.params.shape[0],
            "scales": self.scales, "slots": compiled, "w_min": w_min,
            "buffers": {"mat": self.mat, "target": self.target, "lower": self.lower,
                        "upper": self.upper, "weights": self.weights, "params": self.params,
                        "qdd": self.qdd, "lam": self.lam, "tau": self.tau,
                        "tau_lo": self.tau_lo, "tau_hi": self.tau_hi}}
        self.id = cycle.engine.compile(self.description)  # what was sent (tests re-send it)
        # every compiled task's parameters and weight as the packer's sources (views made once)
        self.sources = [source for s in self.slots if id(s.task) not in python_rows
                        for source in self._sources(s, cycle)]
        self.packer = _hierarchy_cycle.ParameterPacker(self.sources)
        self.python = [(s.task, s.eq, self.mat[s.start:s.stop], self.target[s.start:s.stop],
                        self.lower[s.start:s.stop], self.upper[s.start:s.stop],
                        self.weights[s.start:s.stop])
                       for s in self.slots if id(s.task) in python_rows]
        self.rows_of = {id(s.task): (self.mat[s.start:s.stop], self.target[s.start:s.stop])
                        if s.eq else (self.mat[s.start:s.stop], self.lower[s.start:s.stop],
                                      self.upper[s.start:s.stop])
                        for s in self.slots}
        self.levels, self.meta = [], []
        for rank, (first, last) in enumerate(self.level_bounds, start=1):
            entries = sorted((s for s in self.slots if s.rank == rank), key=lambda s: s.order)
            k = sum(s.stop - s.start for s in entries if s.eq)
            eq_rows, in_rows = slice(first, first + k), slice(first + k, last)
            self.levels.append(Level.trusted(
                self.mat[eq_rows], self.target[eq_rows], self.weights[eq_rows], self.mat[in_rows],
                self.lower[in_rows], self.upper[in_rows], self.weights[in_rows], name=f"level {rank}"))
            # in the declared task order, as Formulation's (for the task reports)
            self.meta.append([(s.task, "eq", self.mat[s.start:s.stop], self.target[s.start:s.stop], None)
                              if s.eq else
                              (s.task, "ineq", self.mat[s.start:s.stop], self.lower[s.start:s.stop],
                               self.upper[s.start:s.stop]) for s in entries])
        self._bound: BoundCascade | BoundWeighted | None = None  # compiled, on self.levels
        self._bound_key = None

    def _sources(self, slot: _Slot, cycle: "HierarchyCycle") -> list[tuple]:
        """The packer's sources of a compiled task: its schema's parameters, then its weight."""
        weight = Param("weight", Size(1, "rows"))  # a number or one per row
        return [param.source(slot.task, self.params[a:a + size], slot.layout, cycle)
                for param, a, size in slot.params] + \
            [weight.source(slot.task, self.weights[slot.start:slot.stop], slot.layout, cycle)]

    def bound(self, cycle: "HierarchyCycle") -> BoundCascade | BoundWeighted | None:
        """The compiled cascade or weighted QP bound to these levels for the cycle's current
        solver settings (rebuilt if they changed: equal settings share it; the weighted QP's
        without the fallback backend, as :func:`solve_levels` solves it), None where it does not
        apply (method "daqp", not built)."""
        key = cycle.settings  # (with the cycle's stack, it decides cycle.analytic too)
        if key is not self._bound_key and key != self._bound_key:  # (frozen: the same is equal)
            self._bound_key, self._bound = key, None
            if key.method == "cascade" and BoundCascade.available:
                self._bound = BoundCascade(
                    self.levels, key,
                    first_level_solution="analytic" if cycle.analytic else None)
            elif key.method == "weighted" and BoundWeighted.available:
                self._bound = BoundWeighted(self.levels, _without_fallback(key))
        return self._bound

    def write_python_rows(self, cycle: "HierarchyCycle", python_rows: dict) -> None:
        """The rows of the tasks without a kernel (unscaled, as Formulation places them; the
        compiled fill scales the lambda and tau columns of every row)."""
        if not self.python:
            return
        robot, variables = cycle.robot, self.variables
        eq14 = functools.partial(eq14_blocks, robot, variables) if cycle.formulation.reduced else None
        for task, eq, A, target, lower, upper, weights in self.python:
            A[:] = 0.0
            place_rows(python_rows[id(task)], A, target if eq else None, lower, upper,
                       variables.nv, variables.n_lambda, eq14)
            weights[:] = task.weight

    def raise_invalid(self) -> None:
        """Name the task whose rows are NaN/inf, whose bounds cross or whose weight is bad."""
        for s in self.slots:
            rows = slice(s.start, s.stop)
            w = self.weights[rows]
            if s.eq:
                total = self.mat[rows].sum() + self.target[rows].sum() + w.sum()
                good = np.isfinite(total) and (w >= 0).all()
            else:
                lo, up = self.lower[rows], self.upper[rows]
                good = (np.isfinite(self.mat[rows].sum() + w.sum()) and (w > 0).all()
                        and (lo <= up).all())
            if not good:
                raise ValueError(f"level {s.rank}: task '{s.task.name}' produced NaN/inf rows "
                                 f"(or entries whose sum overflows), lower > upper or a bad "
                                 f"weight")


# ---------------------------------------------------------------------------- the cycle
class HierarchyCycle:
    """Robot update + task rows + hierarchical solve + tau for a stack, one call per control cycle.

    Parameters
    ----------
    robot, stack : the robot and the task hierarchy (e.g. :func:`~wholebody.control.stacks.table2_stack`).
    reduced : the reduced [qdd, lambda] (default) or the full [qdd, lambda, tau] formulation.
    engine : ``"native"`` (compiled rigid-body terms, and rows for every task with a kernel; a
        task without one writes its rows from Python into the same arrays), ``"python"``
        (``robot.update`` + :meth:`Formulation.solve`, the reference) or ``"auto"`` (native when
        built).
    settings : the :class:`~wholebody.solvers.SolverSettings` (None: ``SolverSettings()``), as
        :meth:`Formulation.solve`; the attribute ``settings`` may be given new ones between
        cycles.
    """

    def __init__(self, robot: Robot, stack: Stack, reduced: bool = True, engine: str = "auto",
                 settings: SolverSettings | None = None):
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, got '{engine}'")
        if engine == "native" and _hierarchy_cycle is None:
            raise ValueError("engine: 'native' needs the compiled extension "
                             "wholebody._hierarchy_cycle (install with a C++ compiler)")
        if engine == "auto":
            engine = "native" if _hierarchy_cycle is not None else "python"
            if engine == "python":
                warn_python_fallback("HierarchyCycle", "the compiled extension "
                                     "wholebody._hierarchy_cycle is not built")
        self.robot, self.stack, self.engine_name = robot, stack, engine
        self.formulation = Formulation(robot, reduced=reduced)
        self.settings = settings
        for task in stack.tasks():
            if reduced and isinstance(task, FullDynamics):
                raise ValueError("FullDynamics belongs to the full formulation; the reduced "
                                 "one uses NewtonEuler (tau is eliminated by eq. 14)")
        self._programs: dict = {}
        self._program: _Program | None = None
        self._levels_seen = None  # the stack's levels when _structure, _python, _layout_keys were taken
        self._variables_of = (None, None)  # see _solve_native
        self._qv = None  # the state of the last update (native engine)
        self._terms = None  # terms_view's arrays, bound on first use
        self.engine = None
        if engine == "native":
            self._frames: dict[int, int] = {}  # model frame id -> the compiled cycle's frame index
            for c in robot.contacts:
                self._frames.setdefault(c.frame_id, len(self._frames))
            self.engine = _hierarchy_cycle.HierarchyCycle(self._spec())
            for task in stack.tasks():  # the frames known now (a task inserted later adds its own)
                self.selection_of(task)

    @property
    def settings(self) -> SolverSettings:
        """The solver settings of the next cycles (assign new ones between cycles)."""
        return self._settings

    @settings.setter
    def settings(self, settings: SolverSettings | None) -> None:
        settings = settings_or_default(settings)
        self.analytic = (Formulation.uses_analytic_first_level(self.stack, settings)
                         and settings.method == "cascade")
        self._settings = settings

    @property
    def native(self) -> bool:
        return self.engine is not None

    def _spec(self) -> dict:
        robot, model = self.robot, self.robot.model
        frames = [model.frames[fid] for fid in self._frames]
        rows, params = robot.torque_limits.linkage
        return robot.native_model_spec() | {
            "frame_joints": [int(f.parentJoint) for f in frames],
            "frame_placements": np.array([f.placement.homogeneous for f in frames]).reshape(-1),
            "contact_frames": [self._frames[c.frame_id] for c in robot.contacts],
            "contact_dims": [c.dim for c in robot.contacts],
            "contact_radii": np.array([c.spec.radius if c.dim == 3 else 0.0 for c in robot.contacts]),
            "contact_half_sizes": np.array([c.spec.half_size for c in robot.contacts], float).reshape(-1),
            "torque_constant": robot.torque_limits.constant, "torque_scale": robot.torque_limits.scale,
            "linkage_rows": [int(i) for i in rows], "linkage_params": params.reshape(-1),
            "q_min": robot.q_min, "q_max": robot.q_max, "mass": robot.mass}

    # ------------------------------------------------------------------ state read by packers
    @property
    def com(self) -> np.ndarray:
        """CoM position at the last solved state."""
        return self.engine.com if self.native else self.robot.com.copy()

    @property
    def vcom(self) -> np.ndarray:
        return self.engine.vcom if self.native else self.robot.vcom.copy()

    @property
    def h_G(self) -> np.ndarray:
        """Centroidal momentum [linear; angular] at the last solved state."""
        return self.engine.h_G if self.native else self.robot.h_G.copy()

    def terms_view(self) -> SimpleNamespace:
        """Arrays rewritten at every :meth:`update` (bound on first call, the same objects
        afterwards): ``q``, ``v``, ``nle`` (h), ``h_G``, ``com``, ``vcom``, ``rotation`` (the
        base's), ``Ig`` (locked centroidal inertia, world axes); per contact (robot order)
        ``points`` (sphere bottoms, as ``Robot.contact_points``) and their
        ``point_velocities``, and of the contact frames' origins ``frame_positions``,
        ``frame_jacobians`` (linear rows, (nc, 3, nv)), ``frame_drifts`` (classical
        accelerations) and ``frame_velocities``; ``tau_max`` the robot's torque bounds
        τ_max(q) (``robot.torque_limits.upper``). The native engine writes them in its compiled
        update; the Python engine copies them from the robot's cache after ``robot.update``."""
        if self._terms is None:
            robot, nc = self.robot, len(self.robot.contacts)
            arrays = {"q": (robot.nq,), "v": (robot.nv,), "nle": (robot.nv,), "h_G": (6,),
                      "com": (3,), "vcom": (3,), "rotation": (3, 3), "Ig": (3, 3),
                      "points": (nc, 3), "point_velocities": (nc, 3),
                      "frame_positions": (nc, 3), "frame_jacobians": (nc, 3, robot.nv),
                      "frame_drifts": (nc, 3), "frame_velocities": (nc, 3),
                      "tau_max": (robot.na,)}
            buffers = {name: np.zeros(shape) for name, shape in arrays.items()}
            self._terms = SimpleNamespace(mass=robot.mass, **buffers)
            if self.native:
                self.engine.bind_state(buffers)
            elif self._qv is not None:
                self._copy_terms()
        return self._terms

    def _copy_terms(self) -> None:
        """terms_view's arrays from the Python robot's cache (the Python engine's update)."""
        robot, terms = self.robot, self._terms
        terms.q[:], terms.v[:], terms.nle[:] = robot.q, robot.v, robot.h
        terms.h_G[:], terms.com[:], terms.vcom[:] = robot.h_G, robot.com, robot.vcom
        terms.rotation[:] = robot.data.oMi[1].rotation
        terms.Ig[:] = robot.data.Ig.inertia
        terms.points[:] = robot.contact_points
        terms.point_velocities[:] = [robot.contact_jacobians[name][:3] @ robot.v
                                     for name in robot.contact_names]
        frames = robot.contact_frame_jacobians[:, :3]
        terms.frame_positions[:] = [robot.data.oMf[c.frame_id].translation
                                    for c in robot.contacts]
        terms.frame_jacobians[:] = frames
        terms.frame_drifts[:] = robot.contact_frame_drifts[:, :3]
        terms.frame_velocities[:] = frames @ robot.v
        terms.tau_max[:] = robot.torque_limits.upper(robot.q[7:])

    def frame_index(self, frame: str) -> int:
        """The compiled cycle's index of a model frame (added to it on first use)."""
        return self.frame_slot(self.robot.frame_id(frame, "frame"))

    def frame_slot(self, fid: int) -> int:
        """The compiled cycle's index of the model frame ``fid`` (added to it on first use)."""
        if fid not in self._frames:
            f = self.robot.model.frames[fid]
            self._frames[fid] = self.engine.add_frame(int(f.parentJoint), f.placement.homogeneous)
            self._q = None  # the compiled state must be updated again
        return self._frames[fid]

    def layout_of(self, task: Task, variables: Variables) -> LayoutContext:
        """What the task's schema sizes resolve against: its active contacts, its rows, the
        auxiliary columns it uses."""
        contacts = contact_subset(variables, task.contacts) if task.per_contact else ()
        auxiliary = task.auxiliary()
        columns = (variables.auxiliary_columns(auxiliary, f"task '{task.name}'") if auxiliary
                   else ())
        return LayoutContext(self.robot, contacts, task.selection(self.robot).get("rows", ()),
                             columns)

    def selection_of(self, task: Task, layout: LayoutContext | None = None) -> dict[str, list[int]]:
        """The task's selection for its kernel, a model frame id turned into the cycle's index;
        a task that uses auxiliary variables also gets their columns ("auxiliary")."""
        selection = {k: [int(i) for i in v] for k, v in task.selection(self.robot).items()}
        if "frame" in selection:
            selection["frame"] = [self.frame_slot(fid) for fid in selection["frame"]]
        if layout is not None and task.auxiliary():
            selection["auxiliary"] = list(layout.auxiliary)
        return selection

    def frame_placement(self, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """(position, rotation) of a contact frame or a FrameTask's frame at the last state."""
        if not self.native:
            return self.robot.frame_placement(frame)
        fid = self.robot.frame_id(frame, "frame")
        if fid not in self._frames:
            raise ValueError(f"frame: '{frame}' is neither a contact's nor a FrameTask's frame")
        return self.engine.frame_placement(self._frames[fid])

    def contact_frame_position(self, contact: str) -> np.ndarray:
        return self.frame_placement(self.robot.model.frames[self.robot.contact(contact).frame_id].name)[0]

    def joint_positions(self, joints: Sequence[str]) -> np.ndarray:
        idx = [self.robot.joint_names.index(j) for j in joints]
        return self.robot.joint_angles(self.engine.q if self.native else self.robot.q)[idx]

    # ------------------------------------------------------------------ solve
    def solve(self, q, v, variables: Variables | None = None, diagnostics: bool = False) -> Solution:
        """The torques for state (q, v) with the active contacts of ``variables`` (default all;
        the auxiliary variables the stack's tasks use are added, :meth:`Formulation.variables_for
        <wholebody.formulation.Formulation.variables_for>`).

        Never raises for numerical reasons (a failed solve is flagged, its torque finite and
        within limits, as :meth:`Formulation.solve`; so is a finite state whose rigid-body terms
        overflow, its status naming ``v``); bad input — q/v of the wrong size or with NaN, a
        task producing NaN rows — raises ValueError naming the field or task."""
        if not self.native:
            self.update(q, v)
            return self._solve_python(variables, diagnostics)
        return self._solve_native(variables, diagnostics, (q, v))

    def update(self, q, v) -> None:
        """The rigid-body terms at (q, v), for :meth:`solve_updated` (which :meth:`solve` makes
        in its one call; a controller reads the terms in between, :meth:`terms_view`): the
        native engine's compiled update, the Python engine's ``robot.update``. Bad q/v (size,
        NaN) raise ValueError naming the field."""
        t0 = time.perf_counter()
        if self.native:
            self.engine.update(q, v)
            self._q = q
        else:
            self.robot.update(q, v)
            if self._terms is not None:
                self._copy_terms()
        self._qv = (q, v)
        self._update_time = time.perf_counter() - t0

    def solve_updated(self, variables: Variables | None = None,
                      diagnostics: bool = False) -> Solution:
        """:meth:`solve` at the state of the last :meth:`update`."""
        if self._qv is None:
            raise RuntimeError("solve_updated: call update(q, v) first (or solve(q, v))")
        if not self.native:
            return self._solve_python(variables, diagnostics)
        return self._solve_native(variables, diagnostics, None)

    def _solve_python(self, variables: Variables | None, diagnostics: bool) -> Solution:
        """The Python engine's solve at the robot's state of the last :meth:`update`."""
        t0 = time.perf_counter()
        variables = self.formulation.variables_for(self.stack, variables)
        sol = self.formulation.solve(self.stack, variables, self.settings,
                                     diagnostics=diagnostics)
        sol.timings["update"] = self._update_time
        sol.timings["total"] = self._update_time + time.perf_counter() - t0
        return sol

    def _solve_native(self, variables: Variables | None, diagnostics: bool, state) -> Solution:
        """The native cycle at ``state`` = (q, v), updated in the same compiled call as the rows
        and the solve, or (``state`` None) at the state of the last :meth:`update`; ``variables``
        as :meth:`solve` takes them."""
        robot = self.robot
        q, v = state if state is not None else self._qv
        t0 = time.perf_counter()
        python_rows = {}
        if self._levels_seen is None or self.stack.levels != self._levels_seen:
            self._take_stack()
        given, resolved = self._variables_of
        if variables is not given or resolved is None:  # (kept while the stack is unchanged)
            resolved = self.formulation.variables_for(self.stack, variables)
            self._variables_of = (variables, resolved)
        variables = resolved
        if self._python:  # tasks without a kernel read the Python robot's cache
            robot.update(q, v)
            python_rows = {id(t): t.rows(robot, variables) for t in self._python}
        program = self._program_for(variables, python_rows)
        if state is None and self._q is None:  # a frame was added since the last update
            self.engine.update(q, v)
            self._q = q
        t1 = time.perf_counter()
        program.write_python_rows(self, python_rows)
        bound = program.bound(self)
        # update, packing, rows and, in the common case, the compiled run's QPs and tau in one call
        filled, update_time, rows_time, quick = self.engine.cycle(
            program.id, program.packer, bound.quick_calls() if bound is not None else None,
            *(state or (None, None)))
        earlier_update = self._update_time if state is None else 0.0
        if state is not None:
            self._q, self._qv, self._update_time = q, state, update_time
        if not filled:  # (rows, bounds and weights checked)
            if not all(np.isfinite(term).all() for term in self.engine.terms().values()):
                return unsolved_solution(robot.nv, variables,
                                         robot.torque_bounds(np.asarray(q, float)),
                                         len(self.stack.levels), overflow_status(v))
            program.raise_invalid()
            raise ValueError("task rows: NaN/inf or crossed bounds (no task named; report this)")
        t_rows = t1 + update_time + rows_time if state is not None else t1 + rows_time
        if quick is not None:  # every QP solved in C++ without a warning, tau recovered
            x, costs, qp_time, qps, excess = quick
            outcome, status = Outcome.SOLVED, "optimal"
        else:
            result, outcome, status = solve_levels(program.levels, self.analytic, self.settings,
                                                   bound)
            x, costs = result.x, result.costs
            qp_time, qps = result.timings.get("qp", np.nan), result.timings.get("qps", 0)
            excess = self.engine.recover(program.id, x)
        t_solve = time.perf_counter()
        solution = make_solution(program.qdd.copy(), program.lam.copy(), program.tau.copy(),
                                 (program.tau_lo, program.tau_hi), outcome, status, costs,
                                 variables, excess, x)
        if diagnostics:
            solution.tasks = Formulation.task_reports(x, program.meta)
        solution.timings = {"update": self._update_time + t1 - t0, "rows": rows_time,
                            "solve": t_solve - t_rows,
                            "total": earlier_update + time.perf_counter() - t0,
                            "qp": qp_time, "qps": qps}
        return solution

    def _take_stack(self) -> None:
        """What the program lookup keeps of the stack's structure, taken again when it changes:
        its task ids and level lengths, the tasks without a kernel, the layout keys of the tasks
        whose layout has one, and a copy of its levels that tells a change (compared by task
        identity: where a task class defines its own ``==``, no copy, and all is taken again
        every cycle)."""
        stack = self.stack
        tasks = stack.tasks()
        self._structure = (tuple(map(id, tasks)), tuple(map(len, stack.levels)))
        self._python = python_tasks(stack)
        self._layout_keys = [t.layout_key for t in tasks
                             if type(t).layout_key is not KernelTask.layout_key]
        by_identity = all(type(t).__eq__ is object.__eq__ for t in tasks)
        self._levels_seen = [list(level) for level in stack.levels] if by_identity else None
        self._variables_of = (None, None)  # (the variables given, with the stack's auxiliaries)

    def _program_for(self, variables: Variables, python_rows: dict) -> _Program:
        """The program of the stack as it is now (its levels and tasks, their layouts, the
        Python tasks' row signatures) and the active contacts; built on first use."""
        layout = tuple([layout_key() for layout_key in self._layout_keys])
        program = self._program
        if (program is not None and program.variables is variables and not python_rows
                and program.key.structure is self._structure and program.key.layout == layout):
            return program  # the common case: the last cycle's (its key's other parts the same)
        key = _ProgramKey(variables.contacts, variables.auxiliary, self._structure, layout,
                          tuple([(i, r.m, r.is_equality, r.qdd is None, r.lam is None,
                                  r.tau is None, r.aux is None) for i, r in python_rows.items()]))
        if program is None or program.key != key:
            program = self._programs.get(key)
            if program is None:
                program = self._programs[key] = _Program(self, variables, key, python_rows)
            self._program = program
        return program

    def task_rows(self, task: Task) -> tuple[np.ndarray, ...]:
        """(A, target) of an equality task's rows, (A, lower, upper) of an inequality task's, in
        the last cycle's level arrays (views, valid until the next solve; A over the solver's
        scaled variables)."""
        if self.native:
            return self._program.rows_of[id(task)]
        return self.formulation.task_rows(task)

    @property
    def levels(self) -> list[Level]:
        """The solver levels of the last cycle (views, valid until the next solve)."""
        if self.native:
            return self._program.levels
        return [lp.level for lp in self.formulation._plan.levels]
