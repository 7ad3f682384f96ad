"""One control cycle of hierarchical inverse dynamics — robot update, task rows, solve, tau — with
the rigid-body terms and the task rows in compiled code (Herzog et al. 2016, Sect. 2 and 5.1).

:class:`HierarchyCycle` does what ``robot.update(q, v)`` followed by
``Formulation(robot).solve(stack, variables)`` does, with the same results (tests/test_cycle.py
compares the level arrays and the torques): the compiled part (``wholebody._hierarchy_cycle``,
src/wholebody/native/hierarchy_cycle.cpp) computes Pinocchio's terms and every task's rows into
the level arrays, the cascade solves them (compiled as well, its level QPs by DAQP/quadprog), and
the compiled part returns tau of eq. 14. Python only copies each task's current parameters (gains,
references, weights) into a flat array every cycle, so a controller keeps changing them on the
task objects as before.

Every task of Tables 1, 2 and 4 has a compiled counterpart (``KINDS``); a stack with another task
runs with ``engine="python"`` (the reference), which ``engine="auto"`` picks by itself. With the
native engine the Python robot's cache (``robot.com``, ``robot.M``...) is *not* updated: read the
cycle's own :attr:`HierarchyCycle.com`, :attr:`~HierarchyCycle.vcom`, :attr:`~HierarchyCycle.h_G`.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .formulation import (Formulation, Solution, Stack, make_solution, overflow_status,
                          solve_levels, unsolved_solution)
from .robot import FREE_FLYER_NQ, Robot
from .solvers import Level
from .solvers.compiled_cascade import BoundCascade
from .tasks import (CenterOfPressure, CoMTask, ContactConstraint, ForceRegularizer, FrameTask,
                    FrictionCone, FullDynamics, JointAccelerationLimits, JointTrajectoryTask,
                    MomentumForce, MomentumPD, NewtonEuler, PostureTask, TorqueLimits)
from .tasks.base import Task, contact_subset
from .tasks.contact import WORLD_UP, NormalForceBounds
from .tasks.regularization import AccelerationRegularizer
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


# ---------------------------------------------------------------------------- task kinds
@dataclass(frozen=True)
class _Kind:
    """A task class's compiled counterpart: its name in hierarchy_cycle.cpp, whether its rows are
    equalities, the structure its row layout depends on, its parameter count and its packer
    (task, parameter view, cycle, names) -> None."""

    name: str
    eq: bool
    structure: Callable[[Task], object]
    n_params: Callable[[Task, Robot, tuple], int]
    pack: Callable


def _names(task, variables: Variables) -> tuple[str, ...]:
    return contact_subset(variables, getattr(task, "contacts", None))


def _set(view: np.ndarray, value, task: Task, field: str) -> None:
    """view[:] = value (broadcast), with an error naming the task's field."""
    try:
        view[:] = value
    except (ValueError, TypeError):
        shape = np.shape(value)
        raise ValueError(f"task '{task.name}': field '{field}' has shape {shape}; the native cycle "
                         f"takes a scalar or {view.shape[0]} values (use engine='python' for "
                         f"other forms)") from None


def _pack_nothing(task, p, cycle, names):
    pass


def _pack_torque_limits(task: TorqueLimits, p, cycle, names):
    p[0] = task.scale
    cap = p[1:]
    cap[:] = np.inf
    for joint, value in task.upper_override.items():
        if joint not in cycle.robot.joint_names:
            raise ValueError(f"upper_override: unknown joint '{joint}'")
        i = cycle.robot.joint_names.index(joint)
        cap[i] = min(cap[i], value)


def _pack_joint_limits(task: JointAccelerationLimits, p, cycle, names):
    p[0] = task.mode == "tanh"
    p[1], p[2], p[3] = task.horizon, task.a_max, task.steepness


def _pack_contacts(task: ContactConstraint, p, cycle, names):
    p[0], p[1] = task.kp, task.kd
    if task.kp or task.kd:
        for i, n in enumerate(names):
            if n not in task.anchors:  # touchdown position: the contact frame where first seen
                task.anchors[n] = cycle.contact_frame_position(n)
            p[2 + 3 * i:5 + 3 * i] = task.anchors[n]


def _pack_normals(task, p, names):
    for i, n in enumerate(names):
        p[3 * i:3 * i + 3] = task.normals.get(n, WORLD_UP)


def _pack_friction(task: FrictionCone, p, cycle, names):
    p[0] = task.mu
    _pack_normals(task, p[1:], names)


def _pack_normal_bounds(task: NormalForceBounds, p, cycle, names):
    p[0], p[1] = task.f_min, task.f_max
    _pack_normals(task, p[2:], names)


def _pack_momentum_pd(task: MomentumPD, p, cycle, names):
    if task.com_ref is None:
        task.com_ref = cycle.com
    _set(p[:36], np.ravel(task.P), task, "P")
    _set(p[36:72], np.ravel(task.D), task, "D")
    _set(p[72:75], task.com_ref, task, "com_ref")
    _set(p[75:81], task.h_ref, task, "h_ref")
    _set(p[81:87], task.hdot_ref, task, "hdot_ref")


def _pack_momentum_force(task: MomentumForce, p, cycle, names):
    if task.K is None or task.k is None:
        raise ValueError(f"{task.name}: gains K and k are not set")
    nl = (p.shape[0]) // 10
    if task.K.shape != (nl, 9) or task.k.shape != (nl,):
        raise ValueError(f"{task.name}: K must be ({nl}, 9) and k ({nl},) for contacts {list(names)}; "
                         f"got {task.K.shape} and {task.k.shape}")
    p[:9 * nl] = task.K.ravel()
    p[9 * nl:] = task.k


def _pack_com(task: CoMTask, p, cycle, names):
    if task.position is None:
        task.position = cycle.com
    _set(p[0:3], task.position, task, "position")
    _set(p[3:6], task.velocity, task, "velocity")
    _set(p[6:9], task.acceleration, task, "acceleration")
    _set(p[9:12], task.kp, task, "kp")
    _set(p[12:15], task.kd, task, "kd")


def _pack_frame(task: FrameTask, p, cycle, names):
    if task.position is None or task.rotation is None:
        pos, rot = cycle.frame_placement(task.frame)
        if task.position is None:
            task.position = pos
        if task.rotation is None:
            task.rotation = rot
    _set(p[0:3], task.position, task, "position")
    _set(p[3:12], np.ravel(task.rotation), task, "rotation")
    _set(p[12:18], task.velocity, task, "velocity")
    _set(p[18:24], task.acceleration, task, "acceleration")
    _set(p[24:30], task.kp, task, "kp")
    _set(p[30:36], task.kd, task, "kd")


def _pack_posture(task: PostureTask, p, cycle, names):
    robot = cycle.robot
    nq, na = robot.nq, robot.na
    _set(p[:nq], robot.q_ref if task.q_ref is None else task.q_ref, task, "q_ref")
    _set(p[nq:nq + na], task.kp, task, "kp")
    _set(p[nq + na:nq + 2 * na], task.kd, task, "kd")
    _set(p[nq + 2 * na:nq + 2 * na + 6], task.base_kp, task, "base_kp")
    _set(p[nq + 2 * na + 6:], task.base_kd, task, "base_kd")


def _pack_force_regularizer(task: ForceRegularizer, p, cycle, names):
    if not task.targets:
        p[:] = 0.0
        return
    r = 0
    for n in names:
        d = cycle.robot.contact(n).dim
        target = task.targets.get(n)
        if target is None:
            p[r:r + d] = 0.0
        else:
            _set(p[r:r + d], target, task, f"targets['{n}']")
        r += d


def _pack_joint_trajectory(task: JointTrajectoryTask, p, cycle, names):
    k = len(task.joints)
    if task.position is None:
        task.position = cycle.joint_positions(task.joints)
    for i, (field, value) in enumerate((("position", task.position), ("velocity", task.velocity),
                                        ("acceleration", task.acceleration), ("kp", task.kp),
                                        ("kd", task.kd))):
        _set(p[i * k:(i + 1) * k], value, task, field)


def _dims(robot: Robot, names) -> int:
    return sum(robot.contact(n).dim for n in names)


def _posture_base(task: PostureTask) -> bool:
    return bool(task.base_kp or task.base_kd)


def _no_structure(task) -> None:
    return None


def _contacts_structure(task):
    return task.contacts


#: Task classes with a compiled counterpart (exact classes: a subclass may change the rows).
KINDS: dict[type, _Kind] = {
    NewtonEuler: _Kind("newton_euler", True, _no_structure, lambda t, r, n: 0, _pack_nothing),
    FullDynamics: _Kind("full_dynamics", True, _no_structure, lambda t, r, n: 0, _pack_nothing),
    TorqueLimits: _Kind("torque_limits", False, _no_structure, lambda t, r, n: 1 + r.na,
                        _pack_torque_limits),
    JointAccelerationLimits: _Kind("joint_acceleration_limits", False, _no_structure,
                                   lambda t, r, n: 4, _pack_joint_limits),
    ContactConstraint: _Kind("contact_constraint", True, _contacts_structure,
                             lambda t, r, n: 2 + 3 * len(n), _pack_contacts),
    CenterOfPressure: _Kind("center_of_pressure", False, _contacts_structure, lambda t, r, n: 1,
                            lambda t, p, c, n: p.__setitem__(0, t.margin)),
    FrictionCone: _Kind("friction_cone", False, lambda t: (t.contacts, t.torsion),
                        lambda t, r, n: 1 + 3 * len(n), _pack_friction),
    NormalForceBounds: _Kind("normal_force_bounds", False, _contacts_structure,
                             lambda t, r, n: 2 + 3 * len(n), _pack_normal_bounds),
    MomentumPD: _Kind("momentum_pd", True, _no_structure, lambda t, r, n: 87, _pack_momentum_pd),
    MomentumForce: _Kind("momentum_force", True, _contacts_structure,
                         lambda t, r, n: 10 * _dims(r, n), _pack_momentum_force),
    CoMTask: _Kind("com", True, lambda t: tuple(t.rows_idx), lambda t, r, n: 15, _pack_com),
    FrameTask: _Kind("frame", True, lambda t: (t.frame, t.mask), lambda t, r, n: 36, _pack_frame),
    PostureTask: _Kind("posture", True, _posture_base, lambda t, r, n: r.nq + 2 * r.na + 12,
                       _pack_posture),
    ForceRegularizer: _Kind("force_regularizer", True, _contacts_structure,
                            lambda t, r, n: _dims(r, n), _pack_force_regularizer),
    AccelerationRegularizer: _Kind("acceleration_regularizer", True, _no_structure,
                                   lambda t, r, n: 0, _pack_nothing),
    JointTrajectoryTask: _Kind("joint_trajectory", True, lambda t: t.joints,
                               lambda t, r, n: 5 * len(t.joints), _pack_joint_trajectory),
}

_PER_CONTACT = {"contact_constraint", "center_of_pressure", "friction_cone", "normal_force_bounds",
                "momentum_force", "force_regularizer"}


def unsupported_tasks(stack: Stack) -> list[Task]:
    """The stack's tasks without a compiled counterpart (they need ``engine="python"``)."""
    return [t for t in stack.tasks() if type(t) not in KINDS]


# ---------------------------------------------------------------------------- programs
class _Program:
    """The level arrays of one stack structure and contact set, filled by the compiled cycle:
    per level its equality rows then its inequality rows (as Formulation's plan), one buffer
    each for all levels; plus the flat parameter array the tasks are packed into."""

    def __init__(self, cycle: "HierarchyCycle", variables: Variables, key):
        robot, stack = cycle.robot, cycle.stack
        self.key = key
        self.variables = variables
        n = cycle.formulation.size(variables)
        contact_index = {c: i for i, c in enumerate(robot.contact_names)}
        active = {c: i for i, c in enumerate(variables.contacts)}
        slots, self.packs, self.level_slots = [], [], []
        start = n_params = 0
        for rank, tasks in enumerate(stack.levels, start=1):
            level = {True: [], False: []}
            for order, task in enumerate(tasks):
                kind = KINDS[type(task)]
                names = _names(task, variables) if kind.name in _PER_CONTACT else ()
                m = self._rows(task, kind, robot, variables, names)
                if m:  # a task without rows here (e.g. CoP rows of point feet) has no slot
                    level[kind.eq].append((order, task, kind, names, m))
            first = start
            for eq in (True, False):
                for order, task, kind, names, m in level[eq]:
                    n_p = kind.n_params(task, robot, names)
                    slots.append(self._slot(task, kind, cycle, names, active, start, m, n_params))
                    self.packs.append((task, kind.pack, (start, start + m), (n_params, n_params + n_p),
                                       names))
                    self.level_slots.append((rank, order, task, eq, start, start + m))
                    start += m
                    n_params += n_p
            self.level_slots.append((rank, None, None, None, first, start))
        rows = start
        self.mat = np.zeros((rows, n))
        self.target, self.weights = np.zeros(rows), np.ones(rows)
        self.lower, self.upper = np.zeros(rows), np.zeros(rows)
        self.params = np.zeros(max(n_params, 1))
        self.qdd, self.lam = np.zeros(robot.nv), np.zeros(variables.n_lambda)
        self.tau, self.tau_lo, self.tau_hi = (np.zeros(robot.na) for _ in range(3))
        self.scales = cycle.formulation.scales(variables).copy()
        self.id = cycle.engine.compile({
            "contacts": [contact_index[c] for c in variables.contacts],
            "reduced": cycle.formulation.reduced, "rows": rows, "nparams": self.params.shape[0],
            "scales": self.scales, "slots": slots,
            "buffers": {"mat": self.mat, "target": self.target, "lower": self.lower,
                        "upper": self.upper, "params": self.params, "qdd": self.qdd,
                        "lam": self.lam, "tau": self.tau, "tau_lo": self.tau_lo,
                        "tau_hi": self.tau_hi}})
        # the packers' views (made once) and the solver's levels (views of the buffers)
        self.packs = [(task, pack, self.weights[a:b], self.params[c:d], names)
                      for task, pack, (a, b), (c, d), names in self.packs]
        self.ineq_rows = np.zeros(rows, dtype=bool)
        self.levels, self.meta = [], []
        for rank, tasks in enumerate(stack.levels, start=1):
            entries = sorted(e for e in self.level_slots if e[0] == rank and e[2] is not None)
            first, last = [(a, b) for r, _, t, _, a, b in self.level_slots if r == rank and t is None][0]
            k = sum(b - a for _, _, _, eq, a, b in entries if eq)
            eq_rows, in_rows = slice(first, first + k), slice(first + k, last)
            self.ineq_rows[in_rows] = True
            self.levels.append(Level.trusted(
                self.mat[eq_rows], self.target[eq_rows], self.weights[eq_rows], self.mat[in_rows],
                self.lower[in_rows], self.upper[in_rows], self.weights[in_rows], name=f"level {rank}"))
            # in the declared task order, as Formulation's (for the task reports)
            self.meta.append([(task, "eq", self.mat[a:b], self.target[a:b], None) if eq else
                              (task, "ineq", self.mat[a:b], self.lower[a:b], self.upper[a:b])
                              for _, _, task, eq, a, b in entries])
        self.w_min = np.where(self.ineq_rows, np.nextafter(0.0, 1.0), 0.0)
        self._bound: BoundCascade | None = None  # the compiled cascade on self.levels
        self._bound_key = None

    def bound(self, cycle: "HierarchyCycle") -> BoundCascade | None:
        """The compiled cascade bound to these levels for the cycle's current solver settings
        (rebuilt if they changed), None where it does not apply (another method, not built)."""
        key = (cycle.method, cycle.backend, cycle.regularization, cycle.fallback_backend,
               cycle.analytic, tuple(sorted(cycle.backend_options.items())))
        if key != self._bound_key:
            self._bound_key, self._bound = key, None
            if cycle.method == "cascade" and BoundCascade.available:
                self._bound = BoundCascade(
                    self.levels, cycle.backend, cycle.regularization,
                    first_level_solution="analytic" if cycle.analytic else None,
                    fallback_backend=cycle.fallback_backend,
                    backend_options=cycle.backend_options)
        return self._bound

    @staticmethod
    def _rows(task, kind: _Kind, robot: Robot, variables: Variables, names) -> int:
        dims = [robot.contact(n).dim for n in names]
        rect = sum(d == 6 for d in dims)
        return {
            "newton_euler": lambda: 6, "full_dynamics": lambda: robot.nv,
            "torque_limits": lambda: robot.na, "joint_acceleration_limits": lambda: robot.na,
            "contact_constraint": lambda: sum(dims), "force_regularizer": lambda: sum(dims),
            "center_of_pressure": lambda: 4 * rect,
            "friction_cone": lambda: 4 * len(names) + (8 * rect if task.torsion else 0),
            "normal_force_bounds": lambda: len(names), "momentum_pd": lambda: 6,
            "momentum_force": lambda: 6, "com": lambda: len(task.rows_idx),
            "frame": lambda: len(range(6)[FrameTask.MASKS[task.mask]]),
            "posture": lambda: robot.nv if _posture_base(task) else robot.na,
            "acceleration_regularizer": lambda: robot.nv,
            "joint_trajectory": lambda: len(task.joints),
        }[kind.name]()

    @staticmethod
    def _slot(task, kind: _Kind, cycle, names, active, start, m, param) -> dict:
        robot = cycle.robot
        rows, frame = [], -1
        if kind.name == "com":
            rows = list(task.rows_idx)
        elif kind.name == "frame":
            rows = list(range(6)[FrameTask.MASKS[task.mask]])
            frame = cycle.frame_index(task.frame)
        elif kind.name == "joint_trajectory":
            missing = [j for j in task.joints if j not in robot.joint_names]
            if missing:
                raise ValueError(f"joints: unknown joints {missing}")
            rows = [robot.joint_names.index(j) for j in task.joints]
        return {"kind": kind.name, "start": start, "m": m, "param": param,
                "contacts": [active[n] for n in names], "rows": rows, "frame": frame,
                "base": kind.name == "posture" and _posture_base(task),
                "torsion": kind.name == "friction_cone" and bool(task.torsion)}

    def pack(self, cycle: "HierarchyCycle") -> None:
        """Every task's current parameters and weights into the arrays (Python, every cycle)."""
        for task, pack, weights, params, names in self.packs:
            weights[:] = task.weight
            pack(task, params, cycle, names)

    def raise_invalid(self) -> None:
        """Name the task whose rows are NaN/inf, whose bounds cross or whose weight is bad."""
        for rank, _, task, eq, a, b in self.level_slots:
            if task is None:
                continue
            rows = slice(a, b)
            w = self.weights[rows]
            if eq:
                total = self.mat[rows].sum() + self.target[rows].sum() + w.sum()
                good = np.isfinite(total) and (w >= 0).all()
            else:
                lo, up = self.lower[rows], self.upper[rows]
                good = (np.isfinite(self.mat[rows].sum() + w.sum()) and (w > 0).all()
                        and (lo <= up).all())
            if not good:
                raise ValueError(f"level {rank}: task '{task.name}' produced NaN/inf rows, "
                                 f"lower > upper or a bad weight")


# ---------------------------------------------------------------------------- the cycle
class HierarchyCycle:
    """Robot update + task rows + hierarchical solve + tau for a stack, one call per control cycle.

    Parameters
    ----------
    robot, stack : the robot and the task hierarchy (e.g. :func:`~wholebody.control.stacks.table2_stack`).
    reduced : the reduced [qdd, lambda] (default) or the full [qdd, lambda, tau] formulation.
    engine : ``"native"`` (compiled rigid-body terms and rows; every task must be in ``KINDS``),
        ``"python"`` (``robot.update`` + :meth:`Formulation.solve`, the reference) or ``"auto"``
        (native when built and supported).
    method, backend, fallback_backend, regularization, backend_options : as
        :meth:`Formulation.solve` (``backend_options`` with scalar values, e.g. DAQP's
        ``{"primal_tol": 1e-7}``); ``backend``, ``fallback_backend``, ``regularization`` and
        ``backend_options`` may be changed between cycles.
    """

    def __init__(self, robot: Robot, stack: Stack, reduced: bool = True, engine: str = "auto",
                 method: str = "cascade", backend: str = "daqp",
                 fallback_backend: str | None = "quadprog", regularization: float = 1e-6,
                 backend_options: dict | None = None):
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, got '{engine}'")
        missing = unsupported_tasks(stack)
        if engine == "native":
            if _hierarchy_cycle is None:
                raise ValueError("engine: 'native' needs the compiled extension "
                                 "wholebody._hierarchy_cycle (install with a C++ compiler)")
            if missing:
                raise ValueError(f"engine: 'native' has no compiled counterpart for tasks "
                                 f"{[t.name for t in missing]} (types "
                                 f"{sorted({type(t).__name__ for t in missing})}); use engine='python'")
        if engine == "auto":
            engine = "native" if _hierarchy_cycle is not None and not missing else "python"
            if engine == "python":
                reason = ("the compiled extension wholebody._hierarchy_cycle is not built"
                          if _hierarchy_cycle is None else
                          f"no compiled counterpart for tasks {[t.name for t in missing]}")
                warn_python_fallback("HierarchyCycle", reason)
        self.robot, self.stack, self.engine_name = robot, stack, engine
        self.formulation = Formulation(robot, reduced=reduced)
        self.method, self.backend = method, backend
        self.fallback_backend, self.regularization = fallback_backend, regularization
        self.backend_options = dict(backend_options or {})
        self.analytic = Formulation.analytic_first_level(stack) and method == "cascade"
        for task in stack.tasks():
            if reduced and isinstance(task, FullDynamics):
                raise ValueError("FullDynamics belongs to the full formulation; the reduced "
                                 "one uses NewtonEuler (tau is eliminated by eq. 14)")
        self._programs: dict = {}
        self._program: _Program | None = None
        self.engine = None
        if engine == "native":
            self._frames: dict[int, int] = {}  # model frame id -> the compiled cycle's frame index
            for c in robot.contacts:
                self._frames.setdefault(c.frame_id, len(self._frames))
            for task in stack.tasks():
                if isinstance(task, FrameTask):
                    fid = robot.frame_id(task.frame, f"task '{task.name}'.frame")
                    self._frames.setdefault(fid, len(self._frames))
            self.engine = _hierarchy_cycle.HierarchyCycle(self._spec())

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

    def frame_index(self, frame: str) -> int:
        return self._frames[self.robot.frame_id(frame, "frame")]

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
        return np.asarray(self._q, dtype=float)[FREE_FLYER_NQ + np.asarray(idx, dtype=int)]

    # ------------------------------------------------------------------ solve
    def solve(self, q, v, variables: Variables | None = None, diagnostics: bool = False) -> Solution:
        """The torques for state (q, v) with the active contacts of ``variables`` (default all).

        Never raises for numerical reasons (a failed solve is flagged, its torque finite and
        within limits, as :meth:`Formulation.solve`; so is a finite state whose rigid-body terms
        overflow, its status naming ``v``); bad input — q/v of the wrong size or with NaN, a
        task producing NaN rows — raises ValueError naming the field or task."""
        robot = self.robot
        variables = variables or self._default_variables()
        if not self.native:
            t0 = time.perf_counter()
            robot.update(q, v)
            t1 = time.perf_counter()
            sol = self.formulation.solve(self.stack, variables, method=self.method,
                                         backend=self.backend, regularization=self.regularization,
                                         fallback_backend=self.fallback_backend,
                                         diagnostics=diagnostics,
                                         backend_options=self.backend_options)
            sol.timings["update"] = t1 - t0
            sol.timings["total"] = time.perf_counter() - t0
            return sol
        t0 = time.perf_counter()
        self.engine.update(q, v)
        self._q = q
        t1 = time.perf_counter()
        program = self._program_for(variables)
        program.pack(self)
        if not (self.engine.fill(program.id) and math.isfinite(program.weights.sum())
                and (program.weights >= program.w_min).all()):
            if not all(np.isfinite(term).all() for term in self.engine.terms().values()):
                return unsolved_solution(robot.nv, variables,
                                         robot.torque_limits.bounds(np.asarray(q, float)[7:]),
                                         len(self.stack.levels), overflow_status(v))
            program.raise_invalid()
            raise ValueError("task rows: NaN/inf or crossed bounds (no task named; report this)")
        t_rows = time.perf_counter()
        result, outcome, status = solve_levels(program.levels, self.analytic, self.method,
                                               self.backend, self.regularization,
                                               self.fallback_backend, program.bound(self),
                                               self.backend_options)
        t_solve = time.perf_counter()
        self.engine.recover(program.id, result.x)
        solution = make_solution(program.qdd.copy(), program.lam.copy(), program.tau.copy(),
                                 (program.tau_lo, program.tau_hi), outcome, status, result.costs,
                                 variables)
        if diagnostics:
            solution.tasks = Formulation.task_reports(result.x, program.meta)
        solution.timings = {"update": t1 - t0, "rows": t_rows - t1, "solve": t_solve - t_rows,
                            "total": time.perf_counter() - t0,
                            "qp": result.timings.get("qp", np.nan),
                            "qps": result.timings.get("qps", 0)}
        return solution

    def _default_variables(self) -> Variables:
        if getattr(self, "_all_contacts", None) is None:
            self._all_contacts = Variables(self.robot)
        return self._all_contacts

    def _program_for(self, variables: Variables) -> _Program:
        key = (variables.contacts, tuple(KINDS[type(t)].structure(t) for t in self.stack.tasks()))
        program = self._program
        if program is None or program.key != key:
            program = self._programs.get(key)
            if program is None:
                program = self._programs[key] = _Program(self, variables, key)
            self._program = program
        return program

    @property
    def levels(self) -> list[Level]:
        """The solver levels of the last cycle (views, valid until the next solve)."""
        if self.native:
            return self._program.levels
        return [lp.level for lp in self.formulation._plan.levels]
