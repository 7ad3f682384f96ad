"""Passive whole-body control for quadrupeds (Fahmi et al. 2019, Sect. II and IV).

One QP per control cycle over u = [q̈, F_grf] (eq. 7), posed as a two-level stack of library
tasks (:class:`~wholebody.control.passive_stack.PassiveStack`: the hard constraints, then the
weighted objective) and solved by a :class:`~wholebody.cycle.HierarchyCycle` with method
"weighted" — compiled (engine "native", what "auto" runs where it is built) or the Python
reference (engine "python"):

* cost ‖W_com − W_com,d‖²_Q + ‖u‖²_R (eqs. 7a, 8): the trunk wrench task of eq. 4
  (:class:`~wholebody.tasks.wrench.TrunkImpedance`) plus a regulariser — forces near the cone
  normals (``regularization="force-normal"``, the paper's), every force leaning like the desired
  net force (``"force-parallel"``, ours, the default: the robust reading of "GRFs closer to the
  friction cone normals" when the net force is not vertical) or, with ``"torque"``, the joint
  torques of the contact forces with per-joint weights (Sect. V-D, footnote 16:
  R_F = J_st,j R_τ J_st,jᵀ);
* floating-base dynamics (eq. 9), here in Pinocchio's base coordinates (a linear change of rows of
  the paper's CoM coordinates: the constraint set is the same);
* stance feet: eq. 10, or the stance task of eq. 32 (``K_st``, ``D_st`` > 0; the anchor follows a
  rolling foot: the contact point minus the slip integrated since touchdown);
* swing feet: eq. 6/11-12 at the acceleration level; ``swing_slack`` = "per-direction" (eq. 33 with
  one slack per direction: at the optimum ε = |A u − b| so α‖ε‖² is exactly the weighted
  least-squares term α‖A_sw u − b_sw‖², no variables added), "single" (one slack per foot, an
  auxiliary variable: the ∞-norm coupling the paper warns about) or "none" (hard equality, eq. 11);
* friction pyramid and normal-force bounds about each foot's terrain normal (eqs. 13-14), torque
  limits with joint-dependent bounds τ_min(q), τ_max(q) (eq. 15), joint limits as acceleration
  bounds with Δt = 10 dt (eqs. 16-18);
* torques by eq. 19.

The weighted QP is solved by DAQP, over the nullspace of the hard equality rows where they are
independent (:mod:`wholebody.solvers.weighted`). The native engine also
computes the controller's per-cycle references around the QP (τ bounds, stance anchors, W_d, the
posture target, the commanded wrench) in the compiled ``wholebody._passive_references`` from the
hierarchy cycle's rigid-body terms (:meth:`HierarchyCycle.terms_view
<wholebody.cycle.HierarchyCycle.terms_view>`); the Python engine computes them from
``robot.update``'s. ``extra_tasks`` adds the user's tasks to either level.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pinocchio as pin

from ..cycle import HierarchyCycle, native_available, warn_python_fallback
from ..formulation import Solution, TaskReport
from ..guard import Outcome, guard_torque
from ..robot import Robot
from ..robots.reference import froude_ratio
from ..robots.roles import leg_joints
from ..solvers import SolverSettings
from ..tasks.base import Task
from ..tasks.limits import JointAccelerationLimits, TorqueLimits
from ..tasks.wrench import (F_MAX_WEIGHTS, TrunkImpedance, contact_wrench_map, force_bound,
                            trunk_weights)
from ..validation import finite_array, nonnegative, number, positive
from .base import PlannedController
from .passive_stack import PassiveStack, passive_stack

log = logging.getLogger(__name__)

#: the posture regulariser's natural frequency on HyQ (rad/s), scaled by the robot's size
POSTURE_FREQUENCY = 8.0

#: singular values of the stance rows below this fraction of the largest count as dependent
STANCE_RANK_TOLERANCE = 1e-4


#: the plan's arrays a cycle reads (PlanState fields; ``trunk.`` those of its TrunkState)
PLAN_ARRAYS = ("touchdown_normal", "foot_position", "foot_velocity", "foot_acceleration",
               "trunk.position", "trunk.velocity", "trunk.acceleration", "trunk.rotation",
               "trunk.angular_velocity", "trunk.angular_acceleration")


_total = np.add.reduce  # an array's sum without np.sum's dispatch (a cycle sums ten)


def nonfinite_plan_field(plan) -> str | None:
    """The first of :data:`PLAN_ARRAYS` of ``plan`` with a NaN/inf entry, or None (one sum per
    array on the fast path; a finite array whose sum overflows is looked at entry by entry)."""
    trunk = plan.trunk
    arrays = (plan.touchdown_normal, plan.foot_position, plan.foot_velocity,
              plan.foot_acceleration, trunk.position, trunk.velocity, trunk.acceleration,
              trunk.rotation, trunk.angular_velocity, trunk.angular_acceleration)
    if math.isfinite(sum([float(_total(a, None)) for a in arrays])):
        return None
    for name, a in zip(PLAN_ARRAYS, arrays):
        if not np.isfinite(a).all():
            return name
    return None


def free_joints(robot) -> np.ndarray:
    """(na,) bool: the joints that point-foot tasks (three rows per foot, stance or swing) do not
    determine: every joint of a leg of more than three joints, and joints in no leg (a spine, a
    torso). The posture regulariser acts on these only; a leg of three joints is left to its
    foot's task (on such legs the regulariser made small robots' trunks track worse)."""
    free = np.ones(robot.na, dtype=bool)
    index = {name: i for i, name in enumerate(robot.joint_names)}
    for contact in robot.contact_names:
        joints = leg_joints(robot, contact)
        if len(joints) <= 3:
            free[[index[j] for j in joints if j in index]] = False
    return free


def stance_rank(robot, contacts) -> int:
    """Rank of the point contacts' stacked position Jacobians (their frames', world axes) in the
    standing posture ``robot.q_ref``, computed on a Data of its own (the robot's state is left)."""
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, robot.q_ref)
    pin.updateFramePlacements(model, data)
    J = np.vstack([pin.getFrameJacobian(model, data, robot.contact(n).frame_id,
                                        pin.LOCAL_WORLD_ALIGNED)[:3] for n in contacts])
    return independent_rank(J)


def independent_rank(J: np.ndarray | None = None, singular: np.ndarray | None = None) -> int:
    """Number of singular values (of ``J``, or given) above STANCE_RANK_TOLERANCE σ_max."""
    if singular is None:
        singular = np.linalg.svd(J, compute_uv=False)
    return int((singular > STANCE_RANK_TOLERANCE * singular[0]).sum()) if singular.size else 0


SLACKS = ("per-direction", "single", "none")
ENGINES = ("auto", "native", "python")

#: how the stack's two levels are solved: one weighted QP by DAQP (eq. 7), ε negligible next to
#: the R terms, no other backend and no cascade instead (a failed or infeasible QP holds the
#: previous torque; the cascade's least-squares compromise would break the hard rows, the
#: floating-base dynamics among them)
STACK_SETTINGS = SolverSettings(method="weighted", backend="daqp", regularization=1e-12,
                                fallback_backend=None, weighted_fallback=False)
REGULARIZATIONS = ("force-normal", "force-parallel", "torque")
#: the levels of PassiveWBC's QP that take extra tasks: the hard constraints, the weighted objective
EXTRA_LEVELS = ("hard", "objective")


def extra_task_levels(extra_tasks) -> dict[str, list]:
    """``extra_tasks`` ({level: tasks}, None: none) checked: levels of EXTRA_LEVELS, tasks
    (:class:`~wholebody.tasks.base.Task`) with unique names (:class:`PassiveStack` checks them
    against the controller's own)."""
    levels = {level: [] for level in EXTRA_LEVELS}
    if extra_tasks is None:
        return levels
    if not isinstance(extra_tasks, dict):
        raise ValueError(f"extra_tasks: expected {{level: [tasks]}} with levels {EXTRA_LEVELS}, "
                         f"got {extra_tasks!r}")
    for level, tasks in extra_tasks.items():
        if level not in EXTRA_LEVELS:
            raise ValueError(f"extra_tasks: level {level!r} is not one of {EXTRA_LEVELS}")
        if isinstance(tasks, Task):
            tasks = [tasks]
        for task in tasks:
            if not isinstance(task, Task):
                raise ValueError(f"extra_tasks[{level!r}]: expected tasks, got {task!r}")
            levels[level].append(task)
    names = [t.name for tasks in levels.values() for t in tasks]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"extra_tasks: task names must be unique, got {duplicates} twice")
    return levels


@dataclass(frozen=True)
class PassiveConfig:
    """Weights, gains and limits of :class:`PassiveWBC` (Fahmi et al. 2019; defaults of Sect. V).

    ``mu`` friction coefficient of eq. 13 (None: the robot's); ``f_min``/``f_max`` normal-force
    bounds of eq. 14 (N; ``f_max`` None: ``f_max_weights`` times the robot's weight m g, whose
    default is the paper's 2000 N on HyQ, :func:`~wholebody.tasks.wrench.force_bound`);
    ``swing_slack`` one of ``SLACKS`` (eq. 11 / 33) with weight
    ``slack_weight`` α; ``K_st``/``D_st`` stance task of eq. 32 (both 0: eq. 10); ``Q`` (6, trunk
    wrench, N² / (Nm)², about the trunk reference's heading frame; None: the robot-relative
    :func:`~wholebody.tasks.wrench.trunk_weights`, all 1 on HyQ), ``R_qdd`` and ``R_force`` the
    ‖u‖²_R term of eq. 7a;
    ``regularization`` one of ``REGULARIZATIONS`` with ``tangential_weight`` (force-normal, the
    paper's: tangential forces ≈ 0, which shares the tangential force equally among the feet;
    force-parallel, ours and the default: every stance force leaning like the desired net force
    W_d, the same friction ratio on every foot, identical to force-normal when W_d is vertical) or
    ``torque_weights`` (per joint, torque; None: 1e-4 each; footnote 16);
    ``posture_frequency`` ω (rad/s; None: POSTURE_FREQUENCY on HyQ, divided by the robot's
    :func:`~wholebody.robots.reference.froude_ratio`; 0: off) and ``posture_damping`` ζ (ours): the
    ‖q̈‖²_R term of eq. 7a pulls the accelerations of the joints no foot task determines (legs of
    more than three joints, joints in no leg: :func:`free_joints`) toward ω² (q_ref − q) − 2ζω q̇
    instead of 0, which holds them near the standing posture;
    ``torque_limit_override`` lowers named joints' limits (the weak knee of Sect. V-C);
    ``control_period`` sets Δt = 10 dt of eq. 18 and the observer's time step; ``engine`` one of
    ``ENGINES`` (the QP's stack of library tasks, :class:`PassiveStack`, solved by a
    :class:`~wholebody.cycle.HierarchyCycle` of that engine: "native" compiled, "python" the
    reference; "auto": native when it is built, else Python with one logged warning).
    """

    mu: float | None = None
    f_min: float = 0.0
    f_max: float | None = None
    f_max_weights: float = F_MAX_WEIGHTS
    swing_slack: str = "per-direction"
    slack_weight: float = 1e4
    K_st: float = 200.0
    D_st: float = 30.0
    Q: tuple | None = None
    R_qdd: float = 1e-4
    R_force: float = 1e-4
    regularization: str = "force-parallel"
    tangential_weight: float = 1e-3
    posture_frequency: float | None = None
    posture_damping: float = 1.0
    torque_weights: tuple | None = None
    torque_limit_override: dict[str, float] | None = None
    control_period: float = 0.004
    engine: str = "auto"

    def __post_init__(self):
        if self.swing_slack not in SLACKS:
            raise ValueError(f"swing_slack: expected one of {SLACKS}, got '{self.swing_slack}'")
        if self.regularization not in REGULARIZATIONS:
            raise ValueError(f"regularization: expected one of {REGULARIZATIONS}, "
                             f"got '{self.regularization}'")
        if self.engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, got '{self.engine}'")
        if self.mu is not None:
            number(self.mu, "mu", low=0.0, low_open=True)
        number(self.f_min, "f_min", low=0.0)
        if self.f_max is not None and not (self.f_max == math.inf
                                           or number(self.f_max, "f_max") > self.f_min):
            raise ValueError(f"f_max: must exceed f_min = {self.f_min}, got {self.f_max!r}")
        for name in ("slack_weight", "R_qdd", "R_force", "control_period", "f_max_weights"):
            positive(getattr(self, name), name)
        if self.posture_frequency is not None:
            nonnegative(self.posture_frequency, "posture_frequency")
        for name in ("K_st", "D_st", "tangential_weight", "posture_damping"):
            nonnegative(getattr(self, name), name)
        # arrays as tuples of floats (exact), so that configurations compare by value
        if self.Q is not None:
            Q = np.broadcast_to(finite_array(self.Q, "Q", nonnegative=True), 6)
            object.__setattr__(self, "Q", tuple(Q.tolist()))
        if self.torque_weights is not None:
            weights = np.ravel(finite_array(self.torque_weights, "torque_weights",
                                            nonnegative=True))
            object.__setattr__(self, "torque_weights", tuple(weights.tolist()))
        if self.torque_limit_override is not None:
            override = {joint: positive(value, f"torque_limit_override.{joint}")
                        for joint, value in dict(self.torque_limit_override).items()}
            object.__setattr__(self, "torque_limit_override", override)


_CONFIG_FIELDS = frozenset(f.name for f in dataclasses.fields(PassiveConfig))


@dataclass
class SwingGains:
    """Acceleration-level swing impedance of eq. 6 (Sect. V: K_sw = 2000, D_sw = 20);
    ``feedforward`` False drops v̇_sw,ff (Assumption 2 of the passivity analysis)."""

    K: float = 2000.0
    D: float = 20.0
    feedforward: bool = True

    def __post_init__(self):
        self.K, self.D = nonnegative(self.K, "swing.K"), nonnegative(self.D, "swing.D")


def relative_slack_weight(robot: Robot, ratio: float, Q=None) -> float:
    """The slack weight α of eq. 33 for a ``ratio`` to the trunk wrench task: α = ratio · max(Q) · m²
    (m the robot's mass). The slack ε is a foot acceleration (m/s²), the trunk task a wrench error
    (N, Nm) weighed by Q; a CoM acceleration error a costs max(Q) (m a)², so ``ratio`` 1 weighs a
    swing foot's acceleration error as much as the same acceleration error of the whole robot's
    CoM, on any robot. The paper only asks for "a high weight α"; the default α = 1e4 is a ratio of
    1.3 on HyQ (86.8 kg, Q = 1). ``Q`` None: the robot's :func:`trunk_weights`."""
    Q = trunk_weights(robot) if Q is None else Q
    q_max = float(np.max(np.asarray(Q, dtype=float)))
    if not q_max > 0.0:
        raise ValueError(f"Q: the trunk weights must not all be zero, got {Q!r}")
    return positive(ratio, "slack ratio") * q_max * robot.mass ** 2


def default_planner(robot: Robot):
    """A planner that keeps every foot in stance under the standing posture."""
    from ..planning.gait import stand
    from ..planning.planner import GaitPlanner
    return GaitPlanner.for_robot(robot, stand(legs=robot.contact_names))


class PassiveWBC(PlannedController):
    """Passive whole-body controller: ``compute(q, v, t) -> Solution`` (Fahmi et al. 2019).

    ``PassiveWBC(robot, planner=None, config=None, **overrides)``: ``config`` a
    :class:`PassiveConfig` (default: the paper's), ``overrides`` any of its fields by name
    (``PassiveWBC(robot, planner, mu=0.5, K_st=0.0)``). ``planner`` (a
    :class:`~wholebody.planning.planner.GaitPlanner`, default: stand still) gives, every cycle,
    the stance/swing split, swing references, stance anchors, terrain normals and the trunk
    reference. ``solve(plan)`` runs one cycle on a given plan at the robot's cached state.

    ``impedance`` (the trunk wrench task of eq. 4, default
    :meth:`TrunkImpedance.for_robot <wholebody.tasks.wrench.TrunkImpedance.for_robot>`: the
    paper's gains on HyQ, the same CoM and trunk frequencies and damping ratios on any other
    robot), ``swing``
    (:class:`SwingGains`) and ``observer`` (a :class:`~wholebody.control.observer.MomentumObserver`,
    default none: it estimates W_ext of eq. 4 every cycle from the centroidal momentum and the
    contact wrench commanded the cycle before, and writes it into ``impedance.external_wrench``)
    are live objects. The configuration's values are copied into attributes of the same names
    (``Q`` an array, ``torque_weights`` one per joint, ``torque_limits``/``joint_limits`` the
    limit tasks); ``config`` keeps what it was built with. The QP's tasks take the weights and
    gains when they are built: after changing any of them call :meth:`configure`.

    ``engine="native"`` (what "auto" runs where the compiled extensions are built) solves the QP
    in compiled code (faster: docs/results.md, benchmarks/bench_passive.py) with the Python
    engine's results. It keeps its own rigid-body terms: ``compute``/``cycle`` do not refresh
    ``robot``'s Python cache (``robot.M``, ``robot.com``... stay those of the last
    ``robot.update``).

    ``extra_tasks`` adds library or user tasks to the QP (``{"hard": [...], "objective":
    [...]}``: constraints beside the dynamics, contacts, friction and limits, or weighted terms
    beside the trunk wrench — a task's ``weight`` scales its rows, so a row costs weight² times
    its squared residual, as the trunk wrench's √Q); the tasks are live objects, read every
    cycle.
    """

    def __init__(self, robot: Robot, planner=None, config: PassiveConfig | None = None, *,
                 impedance: TrunkImpedance | None = None, swing: SwingGains | None = None,
                 observer=None, extra_tasks: dict | None = None, **overrides):
        unknown = sorted(set(overrides) - _CONFIG_FIELDS)
        if unknown:
            raise TypeError(f"PassiveWBC: unknown option(s) {unknown}; expected PassiveConfig "
                            f"fields {sorted(_CONFIG_FIELDS)}")
        config = dataclasses.replace(config or PassiveConfig(), **overrides)
        if any(c.dim != 3 for c in robot.contacts):
            raise ValueError(f"robot '{robot.name}': PassiveWBC needs point contacts (3D forces)")
        unknown = sorted(set(config.torque_limit_override or ()) - set(robot.joint_names))
        if unknown:
            raise ValueError(f"torque_limit_override: unknown joint(s) {unknown} of robot "
                             f"'{robot.name}'")
        self.config = config
        self.robot = robot
        self.contacts = robot.contact_names
        self.planner = planner if planner is not None else default_planner(robot)
        self._leg = np.array([tuple(self.planner.legs).index(n) for n in self.contacts])
        self.mu = robot.friction if config.mu is None else float(config.mu)
        omega = (POSTURE_FREQUENCY / froude_ratio(robot) if config.posture_frequency is None
                 else config.posture_frequency)
        #: the posture regulariser's gains: q̈_posture = K (q_ref − q) − D q̇ (1/s², 1/s), on
        #: the joints no point-foot task determines (:func:`free_joints`)
        self.posture_K, self.posture_D = omega ** 2, 2.0 * config.posture_damping * omega
        self.posture_mask = free_joints(robot).astype(float)
        self.f_min = config.f_min
        self.f_max = (force_bound(robot, config.f_max_weights) if config.f_max is None
                      else config.f_max)
        if not self.f_max > self.f_min:
            raise ValueError(f"f_max_weights: {config.f_max_weights!r} x the robot's weight is "
                             f"{self.f_max!r} N, which must exceed f_min = {self.f_min}")
        self.impedance = impedance or TrunkImpedance.for_robot(robot)
        self.swing = swing or SwingGains()
        self.swing_slack = config.swing_slack
        self.slack_weight = float(config.slack_weight)
        self.K_st, self.D_st = config.K_st, config.D_st
        self.Q = np.array(trunk_weights(robot) if config.Q is None else config.Q, dtype=float)
        self.R_qdd, self.R_force = config.R_qdd, config.R_force
        self.regularization = config.regularization
        self.tangential_weight = config.tangential_weight
        na, c = robot.na, len(self.contacts)
        self.torque_weights = (np.ones(na) * 1e-4 if config.torque_weights is None else
                               np.broadcast_to(np.asarray(config.torque_weights, float), na).copy())
        self.torque_limits = TorqueLimits(upper_override=config.torque_limit_override)
        self.joint_limits = JointAccelerationLimits(mode="braking",
                                                    horizon=10 * config.control_period)
        self.control_period = config.control_period
        self.nf = 3 * c
        self._G = np.zeros((6, self.nf))  # contact wrench map of eq. 8
        self._anchors = np.zeros((c, 3))  # stance task (eq. 32): x̂_st of the last cycle
        self._slip = np.zeros((c, 3))  # material contact point's displacement since touchdown
        self._was_stance = np.zeros(c, dtype=bool)
        self._swing_names = [f"swing {name}" for name in self.contacts]
        self._override_key = None
        self._radii = np.array([robot.contact(name).spec.radius for name in self.contacts])
        self._contact_order = np.array([robot.contact_names.index(n) for n in self.contacts])
        self.last_tau: np.ndarray | None = None
        self.last_desired_wrench: np.ndarray | None = None  # W_d of the last cycle (eq. 8)
        self.last_plan = None
        self._failing = 0  # length of the current streak of failed cycles
        #: cycles run (the native engine leaves ``robot.cycle`` as it is)
        self.cycles = 0
        self.observer = observer
        self._commanded_wrench: np.ndarray | None = None  # G F of the last solved cycle
        #: the stance feet's rows are linearly dependent in the standing posture (legs of fewer
        #: than three joints): each cycle they are replaced by an independent set
        self.dependent_stance = stance_rank(robot, self.contacts) < 3 * c
        #: the stance task's rank tolerance (0: its rows as they are)
        self.stance_rank_tolerance = STANCE_RANK_TOLERANCE if self.dependent_stance else 0.0
        #: the user's tasks of each level ("hard", "objective"), see the class docstring
        self.extra_tasks = extra_task_levels(extra_tasks)
        self.engine = self._resolve_engine(config)
        self._build_stack()

    # ------------------------------------------------------------------ per cycle
    def solve(self, plan) -> Solution:
        """One QP (eq. 7) at the robot's cached state for ``plan`` (a PlanState-like object)."""
        self._stack_cycle.update(self.robot.q, self.robot.v)
        return self._solve(plan)

    def posture_acceleration(self, q=None, v=None) -> np.ndarray:
        """The joints' q̈ the ‖q̈‖²_R term pulls toward: K (q_ref − q) − D q̇ (Lie difference, so
        continuous joints count their angle); (q, v) default to the robot's cached state."""
        robot = self.robot
        q = robot.q if q is None else q
        v = robot.v if v is None else v
        error = pin.difference(robot.model, q, robot.q_ref)[6:]
        return self.posture_mask * (self.posture_K * error - self.posture_D * v[6:])

    def _stance_anchors(self, stance, points, velocity) -> None:
        """Writes x̂_st of eq. 32 into ``_anchors``, consistent with a rolling foot: the contact
        point minus the slip, the material contact point's velocity J v integrated since touchdown
        (one control period per cycle), at most the foot's radius (a foot rolls by less than a
        radian; an absurd velocity sample would otherwise move the anchor for good). The
        sphere's lowest point moves as the foot rolls without slipping; anchoring it at
        touchdown would demand foot acceleration from rolling alone (Fahmi et al. 2019 make the
        task active only when the foot slips)."""
        slip = self._slip
        held = (stance & self._was_stance)[:, None]
        moved = slip + self.control_period * velocity
        slip.fill(0.0)
        np.copyto(slip, moved, where=held)
        norm = np.sqrt(np.einsum("ij,ij->i", slip, slip))
        over = norm > self._radii
        if over.any():  # one absurd velocity sample must not wind the anchor up for good
            scale = np.divide(self._radii, norm, out=np.zeros_like(norm), where=norm > 0.0)
            slip[over] *= scale[over, None]
        self._was_stance[:] = stance
        np.subtract(points, slip, out=self._anchors)

    def _overrides(self) -> None:
        """The torque-limit task's weak-joint overrides as indices, values and a per-joint cap
        (inf: none), taken again when they change."""
        limits, robot = self.torque_limits, self.robot
        key = tuple(limits.upper_override.items())
        if key != self._override_key:
            limits.bounds(robot)  # validates the joint names
            self._override_index = np.array([robot.joint_names.index(j) for j, _ in key], int)
            self._override_value = np.array([value for _, value in key], float)
            self._override_cap = np.full(robot.na, np.inf)
            np.minimum.at(self._override_cap, self._override_index, self._override_value)
            self._override_key = key

    def _torque_bounds(self, q=None, upper=None) -> tuple[np.ndarray, np.ndarray]:
        """τ_min(q), τ_max(q) of eq. 15 with the weak-joint overrides (indices cached); ``q``
        defaults to the robot's cached state, ``upper`` (the robot's τ_max(q), when known) to
        ``robot.torque_limits.upper(q)``."""
        limits, robot = self.torque_limits, self.robot
        self._overrides()
        if upper is None:
            upper = robot.torque_limits.upper((robot.q if q is None else q)[7:])
        hi = upper * limits.scale
        if self._override_index.size:
            hi[self._override_index] = np.minimum(hi[self._override_index], self._override_value)
        return -hi, hi

    def _bad_plan(self, plan, field: str, q, gravity_torque, t0: float) -> Solution:
        """A plan with a NaN/inf entry (e.g. a planner evaluated at an absurd time): no QP, the
        previous torque held (both engines alike, before anything of the cycle is assembled:
        stance anchors and the observer are left as they were)."""
        self._tau_bounds = self._torque_bounds(q)
        qdd, F, tau, status = self._failed(f"plan: {field} is not finite", gravity_torque)
        return self._report(False, qdd, F, tau, status, np.zeros(6), np.full(6, np.nan),
                            plan.contact[self._leg], None,
                            {"assemble": time.perf_counter() - t0, "solve": 0.0})

    def _failed(self, reason: str, gravity_torque):
        """A failed solve (``reason``: the solver's status): hold the previous torque (or the
        nonlinear effects); :meth:`_report` clips it."""
        tau = self.last_tau if self.last_tau is not None else gravity_torque
        if not np.isfinite(gravity_torque).all():  # at a finite state: |v|² overflowed
            reason = (f"v: the rigid-body terms at this state are not finite (products of the "
                      f"velocity overflow); {reason}")
        status = f"{reason}: previous torque held (clipped to limits)"
        if self._failing == 0:  # one warning per streak of failed cycles, not one per cycle
            log.warning("PassiveWBC cycle %d: %s", self.cycles, status)
        return np.zeros(self.robot.nv), np.zeros(self.nf), tau, status

    def _report(self, ok, qdd, F, tau, status, commanded, W_d, stance, swing_errors,
                timings, auxiliary=None) -> Solution:
        """The Solution of one cycle (every engine; ``ok``: the QP was solved): the torque
        through the guard, failure streaks, the observer's input, task reports (trunk wrench; swing
        feet when the solve succeeded), the single swing slacks as ``auxiliary`` ("slack
        <contact>" of each swing foot)."""
        if not ok:  # the caller sees a streak in the status, not only in the log
            status = f"{status} ({self._failing + 1} failed cycle(s) in a row)"
        tau, outcome, status = guard_torque(tau, *self._tau_bounds,
                                            Outcome.SOLVED if ok else Outcome.HELD, status)
        if ok and self._failing:
            log.warning("PassiveWBC cycle %d: solved again after %d failed cycles",
                        self.cycles, self._failing)
        self._failing = 0 if ok else self._failing + 1
        self.last_tau = tau
        self.last_desired_wrench = W_d
        self._commanded_wrench = commanded if ok else None
        if not ok and self.observer is not None:  # the applied wrench is unknown: start afresh
            self.observer.reset()
        wrench_error = commanded - W_d
        reports = [TaskReport("trunk wrench", 2, "eq", 6, math.sqrt(wrench_error @ wrench_error))]
        in_stance = stance.tolist()  # Python bools: iterating a numpy array is slow per item
        if swing_errors is not None:
            errors = swing_errors.tolist()
            reports += [TaskReport(self._swing_names[i], 2, "eq", 3, errors[i])
                        for i, st in enumerate(in_stance) if not st]
        per_foot = F.reshape(-1, 3)
        forces = {name: per_foot[i] for i, name in enumerate(self.contacts) if in_stance[i]}
        return Solution(qdd=qdd, lam=F, tau=tau, forces=forces, outcome=outcome, status=status,
                        level_costs=np.array([wrench_error @ (self.Q * wrench_error)]),
                        tasks=reports, timings=timings, contacts=tuple(forces),
                        auxiliary=auxiliary or {})

    # ------------------------------------------------------------------ the engines
    @staticmethod
    def _resolve_engine(config: PassiveConfig) -> str:
        """``config.engine``, with "auto" resolved: native where the compiled hierarchy cycle is
        built, else Python (one logged warning)."""
        if config.engine == "native" and not native_available():
            raise ValueError("engine: 'native' needs the compiled extension "
                             "wholebody._hierarchy_cycle (install with a C++ compiler)")
        if config.engine != "auto":
            return config.engine
        if native_available():
            return "native"
        warn_python_fallback("PassiveWBC", "the compiled wholebody._hierarchy_cycle is not built")
        return "python"

    def _references_spec(self) -> dict:
        """What the compiled references are built with: the model (the posture's Lie
        difference), the contacts' radii and legs, the mass, the reference posture."""
        robot = self.robot
        return robot.native_model_spec() | {
            "radii": self._radii, "leg": [int(i) for i in self._leg],
            "n_legs": len(self.planner.legs), "mass": robot.mass, "posture": robot.q_ref}

    def configure(self) -> None:
        """Hand changed weights, gains or limits to the stack's tasks (built anew, the stance
        history kept)."""
        self._build_stack()

    def _build_stack(self) -> None:
        """The QP's tasks, the hierarchy cycle of the engine that solves them and the terms the
        controller reads every cycle (its references compiled on the native engine)."""
        self._stack = PassiveStack(self)
        self._stack_cycle = HierarchyCycle(self.robot, self._stack.stack, engine=self.engine,
                                           settings=STACK_SETTINGS)
        self._terms = self._stack_cycle.terms_view()
        #: per leg of the planner, its contact (the planner's feet are in leg order)
        self._leg_contact = self._contact_order[np.argsort(self._leg)]
        self._references = self._compiled_references() if self.engine == "native" else None

    def _compiled_references(self):
        """The native engine's state-dependent references (τ bounds, stance anchors, W_d, the
        posture target) computed by the compiled ``PassiveReferences.update`` from the
        hierarchy cycle's terms, written into the stack's task parameters (made once; on
        :meth:`configure` bound to the new arrays, its stance history kept); None where
        ``wholebody._passive_references`` is not built (they are then computed in Python)."""
        try:
            from .. import _passive_references
        except ImportError:
            return None
        robot, terms = self.robot, self._terms
        references = getattr(self, "_references", None)
        if references is None:
            references = _passive_references.PassiveReferences(self._references_spec())
        self._W_d = np.zeros(6)
        self._lean = self._W_d[:3]  # (one view: the tangential task keeps it, see PassiveStack)
        self._commanded = np.zeros(6)
        self._tau_lo, self._tau_hi = np.zeros(robot.na), np.zeros(robot.na)
        references.bind({
            "q": terms.q, "v": terms.v, "points": terms.points,
            "point_velocities": terms.point_velocities, "com": terms.com, "vcom": terms.vcom,
            "rotation": terms.rotation, "Ig": terms.Ig, "tau_max": terms.tau_max,
            "anchors": self._anchors, "anchor_frames": self._stack.anchor_frames,
            "posture_target": self._stack.posture.target, "tau_lo": self._tau_lo,
            "tau_hi": self._tau_hi, "wrench_d": self._W_d,
            "errors": self.impedance.last_errors, "commanded": self._commanded})
        return references

    def compute(self, q, v, t: float = 0.0) -> Solution:
        """Torques for the state (q, v) at time ``t`` (see PlannedController.compute)."""
        self._stack_cycle.update(q, v)
        terms = self._terms
        plan = self.planner.update(t, feet=terms.frame_positions[self._leg_contact],
                                   com_velocity=terms.vcom.copy())
        return self._solve(plan)

    def cycle(self, q, v, plan) -> Solution:
        """One cycle at the state (q, v) for a given ``plan``: update + QP + torques."""
        self._stack_cycle.update(q, v)
        return self._solve(plan)

    def _solve(self, plan) -> Solution:
        """:meth:`solve`, the hierarchy cycle updated to the state already: the controller's
        state-dependent references (stance anchors, observer, W_d) from the cycle's terms
        (:meth:`HierarchyCycle.terms_view <wholebody.cycle.HierarchyCycle.terms_view>`), then
        the persistent :class:`PassiveStack` updated and solved by its
        :class:`~wholebody.cycle.HierarchyCycle` (weighted, one program per stance set on the
        native engine)."""
        t0 = time.perf_counter()
        self.cycles += 1
        self.last_plan = plan
        terms = self._terms
        references, observer = self._references, self.observer
        if references is None or observer is not None:  # (the plan checked before the observer)
            bad = nonfinite_plan_field(plan)
            if bad is not None:
                return self._bad_plan(plan, bad, terms.q, terms.nle[6:], t0)
        stance = plan.contact[self._leg]
        if observer is not None and self._commanded_wrench is not None:
            self.impedance.external_wrench = observer.update(
                terms.h_G, self._commanded_wrench, terms.mass, self.control_period)
        bad, W_d, lean, finite = self._state_references(plan, stance)
        if bad is not None:
            return self._bad_plan(plan, bad, terms.q, terms.nle[6:], t0)
        t1 = time.perf_counter()
        # failed cycles are values: a W_d that is not finite (e.g. the external wrench), NaN/inf
        # task rows (the state was checked by the update)
        sol = SimpleNamespace(ok=False, status="the desired trunk wrench W_d is not finite",
                              timings={})
        if finite:
            _, variables = self._stack.update(plan, lean)
            t1 = time.perf_counter()
            try:
                sol = self._stack_cycle.solve_updated(variables)
            except ValueError as exc:
                sol.status = str(exc)
        t2 = time.perf_counter()
        F, swing_errors = np.zeros(self.nf), None
        if sol.ok:
            qdd, tau, status = sol.qdd, sol.tau, "solved"
            F[self._stack.force_index] = sol.lam  # the stance feet's forces, contact order
            if self._stack.swinging:  # the swing tasks' residuals J_sw q̈ − (v̇_d − J̇ v), eq. 11
                swing_errors = np.zeros(len(self.contacts))
                nv = self.robot.nv
                for i, task in enumerate(self._stack.swing):
                    if not stance[i]:
                        # (A, target), or (A, lower, upper) of |J q̈ − target| ≤ ε (its
                        # first three upper bounds are the target)
                        A, *bounds = self._stack_cycle.task_rows(task)
                        residual = A[:3, :nv] @ qdd - bounds[-1][:3]
                        swing_errors[i] = math.sqrt(residual @ residual)
        else:
            qdd, F, tau, status = self._failed(sol.status, terms.nle[6:])
        parts = sol.timings
        rows = parts.get("rows", 0.0)
        if references is not None:
            references.commanded(F)
            commanded = self._commanded.copy()
        else:
            commanded = contact_wrench_map(terms, self.contacts, self._G,
                                           terms.points[self._contact_order]) @ F
        return self._report(sol.ok, qdd, F, tau, status, commanded, W_d, stance, swing_errors,
                            {"assemble": t1 - t0 + rows, "solve": t2 - t1 - rows,
                             "prepare": t1 - t0, "update": parts.get("update", np.nan),
                             "rows": parts.get("rows", np.nan),
                             "qp": parts.get("solve", np.nan)},
                            sol.auxiliary if sol.ok else None)

    def _state_references(self, plan, stance) -> tuple[str | None, np.ndarray, np.ndarray, bool]:
        """The references of the cycle from the hierarchy cycle's terms: τ bounds, stance
        anchors, W_d, the posture target (written into its task); (the plan's first non-finite
        field or None, W_d, the lean force, whether W_d is finite). Compiled on the native
        engine (``PassiveReferences.update``, the plan checked first) where built, else in
        Python."""
        terms, references = self._terms, self._references
        if references is None:
            self._tau_bounds = self._torque_bounds(terms.q, terms.tau_max)
            self._stance_anchors(stance, terms.points[self._contact_order],
                                 terms.point_velocities[self._contact_order])
            self._stack.set_state_references(terms.q, terms.v)
            R = terms.rotation
            W_d = self.impedance.wrench_at(R, R @ terms.v[3:6], terms.com, terms.vcom,
                                           terms.mass, terms.Ig, plan.trunk)
            return None, W_d, W_d[:3], math.isfinite(W_d.sum())
        self._overrides()  # the settings as they are now, as the tasks read theirs
        references.settings(self.torque_limits.scale, self._override_cap, self.posture_K,
                            self.posture_D, self.posture_mask, self.control_period)
        trunk, imp = plan.trunk, self.impedance
        code = references.update(
            plan.contact, plan.touchdown_normal, plan.foot_position, plan.foot_velocity,
            plan.foot_acceleration, trunk.position, trunk.velocity, trunk.acceleration,
            trunk.rotation, trunk.angular_velocity, trunk.angular_acceleration,
            imp.external_wrench, imp.K_x, imp.D_x, imp.K_theta, imp.D_theta, imp.feedforward)
        bad = PLAN_ARRAYS[code] if 0 <= code < len(PLAN_ARRAYS) else None
        self._tau_bounds = self._tau_lo, self._tau_hi
        return bad, self._W_d.copy(), self._lean, code < 0

    # ------------------------------------------------------------------ the same problem as a stack
    def as_stack(self, plan):
        """The QP of :meth:`solve` for ``plan`` as a two-level stack of library tasks (see
        :func:`~wholebody.control.passive_stack.passive_stack`) → (stack, variables)."""
        return passive_stack(self, plan)
