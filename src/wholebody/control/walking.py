"""Humanoid walking and push recovery by stepping on the strict hierarchy (Tables 2 and 4 of
Herzog et al. 2016), with a capture-point (DCM) reference.

One controller stands, walks and steps. A footstep plan (a velocity command, an explicit list of
footsteps, or a push that carries the capture point out of the feet) becomes a piecewise-linear
ZMP reference (constant at the stance sole's centre in single support, moving linearly to the next
sole over the double support) and the closed-form DCM and CoM trajectories of the linear inverted
pendulum (:mod:`~wholebody.planning.dcm`, Englsberger et al. 2015). The phases of one step:

1. double support (Table 2): the ZMP moves from the old stance sole to the new one; a force
   regulariser gives the leaving sole the normal force that puts the CoP at the commanded ZMP
   (all the weight at touchdown, none at lift-off), so that lift-off and touchdown leave the
   torques continuous (Sect. 5.4's unloading);
2. single support (Table 4): the swing sole follows a swing trajectory with a clearance apex to its
   footstep, its yaw turning from the lift-off heading to the footstep's, and lands
   ``touchdown_depth`` below the floor so that it surely touches.

Feedback. DCM tracking, xi' = xi_ref' - k (xi - xi_ref) with xi = c + c'/omega, is the PD law of
eq. 22 on the CoM trajectory of the plan: c'' = c_ref'' + omega k (c_ref - c) + (omega + k)
(c_ref' - c'), so the momentum task's P and D are omega k and omega + k (horizontal rows), and the
hierarchy's CoP rows keep the CoP inside the supports. When the CoP cannot follow, the capture
point drifts from the plan; while the swing is early enough (``adjust_until``), the footstep moves
by the predicted DCM error at touchdown, xi_T - xi_ref(T) with xi_T = p + e^(omega tau) (xi - p)
(step adjustment), clamped to the leg's reach (:class:`~wholebody.planning.footsteps.StepLimits`).
Every touchdown re-plans from the measured CoM and DCM: the ZMP starts where it was commanded
(the forces stay continuous) and a knot halfway through the double support is solved so that the
plan starts at the measured DCM (kept inside the soles; beyond them the feedback takes the rest).

Standing, the capture point is watched: when it leaves the soles' support polygon (shrunk by
``capture_margin``), a recovery starts: steps in place with the short ``recovery_double_support``,
the first with the sole farther from the capture point (the nearer one stands), each moved by the step adjustment,
until the robot stands again (N-step capturability, Pratt et al. 2012). With ``stepping=False``
the robot never steps by itself (the feet-flat ankle/hip strategy of :class:`MomentumBalance`).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull

from ..cycle import ENGINES, HierarchyCycle
from ..formulation import Formulation
from ..guard import Outcome
from ..planning.dcm import DCMPlan, lipm_frequency, predicted_dcm
from ..planning.support_shift import KEY_POSE_TOLERANCE, shift_key_pose
from ..planning.footsteps import Footstep, FootstepPlanner, StepLimits, clamp_step
from ..planning.blend import quintic_blend
from ..planning.swing import SwingTrajectory
from ..robot import FREE_FLYER_NV
from ..robots.reference import humanoid_length_ratio
from ..robots.roles import biped_soles, leg_joints
from ..tasks import ForceRegularizer
from ..validation import finite_array, nonnegative, number, positive
from ..variables import Variables
from .base import FailureStreak
from .standing import gravity_compensation
from .stacks import (COP_MARGIN, POSTURE_PD, POSTURE_WEIGHT, SWING_FOOT_PD, TORSION, table2_stack,
                     table4_stack)

log = logging.getLogger(__name__)

GRAVITY = 9.81
#: weights of the unloading regulariser's rows [fx, fy, fz, mx, my, mz] of the leaving sole: its
#: force follows its share of the commanded net force; the tangential rows keep the soles from
#: squeezing each other sideways, which handed the landed sole a tangential force at once, and
#: are light (a recovery step's weight shift needs them to give way: at weight 1 a 0.6 m/s push
#: from the front falls); the moments stay free (a CoP target for the leaving sole fights the
#: momentum task's angular rows)
UNLOAD_ROWS = np.array([0.01, 0.01, 1.0, 0.0, 0.0, 0.0])
#: weight of the posture task's base-orientation rows (as the Table 2/4 stacks of
#: :class:`ContactSwitch`)
BASE_ORIENTATION_WEIGHT = 1.0
#: weight of the legs' posture rows while walking: the soles and the base fix the legs, and a
#: posture row pulling a walking leg toward its standing angles only fights the swing task
LEG_POSTURE_WEIGHT = 1e-3


def _scaled(robot, value: float, power: float) -> float:
    """talos14's ``value`` scaled by (h / h_talos14) ** power (lengths: 1, times: 1/2)."""
    return value * humanoid_length_ratio(robot) ** power


#: the walking CoM height is chosen this far below (positive) or above (negative) the standing
#: one, in talos14's metres (scaled by the robot's height), in steps of WALKING_DROP_STEP
WALKING_DROP_RANGE = (-0.05, 0.05)
WALKING_DROP_STEP = 0.01


class SingleSupportLoad(NamedTuple):
    """The most loaded joint holding ``robot`` still on one sole (the CoG over it) at a CoM
    drop: its share of its torque limit, its name, the torque and the limit (Nm), the sole."""
    share: float
    joint: str
    torque: float
    limit: float
    stance: str


def single_support_load(robot, drop: float) -> SingleSupportLoad | None:
    """The torques that hold ``robot`` still on either sole at ``drop`` below the standing CoM
    height, the CoG over that sole (:func:`~wholebody.planning.support_shift.shift_key_pose`;
    Herzog et al. 2016, eq. 14 with that sole alone), against the limits: the worst joint of
    the two stances, or None when no pose within the joint limits has the CoG over a sole."""
    worst = None
    for stance, swing in (robot.contact_names, robot.contact_names[::-1]):
        _, q, residual = shift_key_pose(robot, stance, swing, drop)
        if residual > KEY_POSE_TOLERANCE:
            robot.update(robot.q_ref, np.zeros(robot.nv))
            return None
        robot.update(q, np.zeros(robot.nv))
        need, _ = gravity_compensation(robot, [stance])
        lo, hi = robot.torque_bounds(q)
        ratio = np.maximum(need / np.maximum(hi, 1e-12), need / np.minimum(lo, -1e-12))
        k = int(np.argmax(ratio))
        if worst is None or ratio[k] > worst.share:
            worst = SingleSupportLoad(float(ratio[k]), robot.joint_names[k], float(need[k]),
                                      float(hi[k] if need[k] > 0 else lo[k]), stance)
    robot.update(robot.q_ref, np.zeros(robot.nv))
    return worst


def walking_com_drop(robot) -> float:
    """The CoM drop below standing (negative: above) ``robot`` walks at: of the drops of
    :data:`WALKING_DROP_RANGE`, the one with the longest stride
    (:meth:`StepLimits.from_robot`, the legs' reach at that height) among those where one sole
    can hold the robot within its torque limits (:func:`single_support_load`). Bending the
    knees lengthens the stride until a joint nears a limit: talos14's stride grows with the
    drop across the range, romeo's ankle pitch stands near its stop, so its stride is longest
    when the knees straighten. The range's top when no drop qualifies (check-robot says why)."""
    scale = humanoid_length_ratio(robot)
    lo, hi = WALKING_DROP_RANGE
    drops = scale * np.arange(lo, hi + 0.5 * WALKING_DROP_STEP, WALKING_DROP_STEP)
    strides = []
    for drop in drops:
        try:
            strides.append((StepLimits.from_robot(robot, com_height_drop=float(drop)).forward,
                            float(drop)))
        except ValueError:  # a sole cannot stand flat at that height
            continue
    for _, drop in sorted(strides, reverse=True):
        load = single_support_load(robot, drop)
        if load is not None and load.share <= 1.0:
            return drop
    return float(scale * hi)


@dataclass(frozen=True)
class WalkingConfig:
    """Settings of :class:`Walking` (s, m, rad). :meth:`for_robot` gives defaults in proportion to
    the robot (talos14's numbers times h / h_talos14 for lengths, its square root for times).

    ``single_support``, ``double_support``: durations of a step's phases;
    ``recovery_single_support``: of a recovery step's swing (short: the capture point diverges
    by e^(omega T) over a swing of T);
    ``initial_double_support``: of the first weight shift from standing; ``final_double_support``:
    of the last one, to the middle of the soles before standing (the capture point comes from a
    sole's centre to between the soles); ``recovery_double_support``: of a recovery step's
    weight shift; ``com_drop``: the walking CoM height below the standing one;
    ``clearance``: the swing apex above the higher end; ``touchdown_depth``: the swing target ends
    this far below the floor; ``dcm_gain``: k / omega of the DCM feedback;
    ``height_gains``: (kp, kd) of the CoM height; ``adjust_until``: share of the single support
    after which the footstep is no longer adjusted; ``capture_margin``: share of each sole's half-lengths the standing
    capture point may be inside the support polygon's edges (0: the soles' edges) before a
    recovery step; ``recovery_reach``: the share of the legs' reach a recovery step's adjustment
    may use (walking steps use :data:`~wholebody.planning.footsteps.STEP_SHARE` of it);
    ``swing_weight``, ``recovery_swing_weight``: the swing sole task's weight in the level of
    the momentum task (whose linear rows weigh 1e4) while walking and in a recovery (from the
    push until the robot stands again): with the CoP at a sole's edge, a light swing task lets
    the hierarchy swing the leg to make the momentum the CoP cannot, a leg strategy that helps
    a recovery, while a walking step pushed that way lands late and off its footstep; ``step_horizon``: footsteps planned ahead (the plan ends at rest);
    ``stepping``: recover pushes by stepping; ``cop_margin``, ``torsion``: the hierarchies' CoP
    margin and yaw-moment rows; ``posture_gains``, ``swing_gains``: as in the Table 2/4 stacks;
    ``joint_braking``: the horizon over which the joint-limit rows brake a joint to its limit
    (:class:`~wholebody.tasks.JointAccelerationLimits`, Fahmi et al. 2019, eqs. 17-18; the
    stacks' default is 10 ms): with the CoP at a sole's edge the hierarchy swings the upper body
    for the momentum the CoP cannot make, and braking that within 10 ms asks more than the
    torque limits give: the joint hits its stop and the body pitches over it."""

    single_support: float
    recovery_single_support: float
    double_support: float
    initial_double_support: float
    final_double_support: float
    recovery_double_support: float
    com_drop: float
    clearance: float
    touchdown_depth: float
    dcm_gain: float = 2.0
    height_gains: tuple[float, float] = (50.0, 15.0)
    adjust_until: float = 0.7
    capture_margin: float = 0.2
    recovery_reach: float = 1.0
    swing_weight: float = 10.0
    recovery_swing_weight: float = 1.0
    step_horizon: int = 3
    stepping: bool = True
    cop_margin: float = COP_MARGIN
    torsion: bool = TORSION
    posture_gains: tuple[float, float] = POSTURE_PD
    swing_gains: tuple[float, float] = SWING_FOOT_PD
    joint_braking: float = 0.05

    @classmethod
    def for_robot(cls, robot, **overrides) -> "WalkingConfig":
        base = cls(single_support=_scaled(robot, 0.6, 0.5),
                   recovery_single_support=_scaled(robot, 0.3, 0.5),
                   double_support=_scaled(robot, 0.1, 0.5),
                   initial_double_support=_scaled(robot, 0.6, 0.5),
                   final_double_support=_scaled(robot, 0.6, 0.5),
                   recovery_double_support=_scaled(robot, 0.05, 0.5),
                   com_drop=(overrides["com_drop"] if "com_drop" in overrides
                             else walking_com_drop(robot)),
                   clearance=_scaled(robot, 0.05, 1.0),
                   touchdown_depth=_scaled(robot, 0.002, 1.0),
                   joint_braking=_scaled(robot, 0.05, 0.5))
        return replace(base, **overrides).checked()

    def checked(self) -> "WalkingConfig":
        for name in ("single_support", "recovery_single_support", "double_support",
                     "initial_double_support", "final_double_support", "recovery_double_support",
                     "dcm_gain", "joint_braking"):
            positive(getattr(self, name), name)
        number(self.com_drop, "com_drop")
        for name in ("clearance", "touchdown_depth", "capture_margin"):
            nonnegative(getattr(self, name), name)
        number(self.adjust_until, "adjust_until", low=0.0, high=1.0)
        number(self.recovery_reach, "recovery_reach", low=0.0, low_open=True, high=1.0)
        for name in ("swing_weight", "recovery_swing_weight"):
            positive(getattr(self, name), name)
        number(self.cop_margin, "cop_margin", low=0.0, high=1.0, high_open=True)
        if int(self.step_horizon) != self.step_horizon or self.step_horizon < 1:
            raise ValueError(f"step_horizon: expected an integer >= 1, got {self.step_horizon!r}")
        return self


@dataclass
class Phase:
    """One phase of the plan: "double" (weight shift onto ``stance``; ``leaving`` unloads) or
    "single" (``footstep.contact`` swings to ``footstep``); "stand" is the open-ended end."""

    kind: str
    start: float
    end: float
    stance: str | None = None
    leaving: str | None = None
    footstep: Footstep | None = None


@dataclass
class StepRecord:
    """A step taken: its lift-off and touchdown times, the planned and the landed footstep."""

    contact: str
    lift_off: float
    touchdown: float
    planned: np.ndarray
    target: np.ndarray
    yaw: float
    recovery: bool


class Walking:
    """Standing, walking and stepping controller of a biped: ``compute(q, v, t) -> Solution``.

    Drive it with :meth:`set_command` (forward, lateral, yaw rate in the heading frame, m/s and
    rad/s; zero stops at the next chance) or :meth:`walk_footsteps` (an explicit list); with
    neither it stands and, if ``config.stepping``, steps to recover pushes.
    ``engine``: "auto" (native when built), "native" or "python" (the reference).
    """

    def __init__(self, robot, config: WalkingConfig | None = None, engine: str = "auto",
                 limits: StepLimits | None = None):
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, got {engine!r}")
        self.robot = robot
        self.failures = FailureStreak("Walking")  # HELD cycles in a row, in the status
        self.config = (WalkingConfig.for_robot(robot) if config is None else config).checked()
        c = self.config
        self.left, self.right = biped_soles(robot)
        self.soles = (self.left, self.right)
        self.frames = {s: robot.contact(s).frame for s in self.soles}
        self.limits = StepLimits.from_robot(robot, com_height_drop=c.com_drop) \
            if limits is None else limits
        # a recovery step may use the legs' whole reach (their joints' margins kept)
        self.recovery_limits = StepLimits.from_robot(robot, com_height_drop=c.com_drop,
                                                     share=c.recovery_reach) \
            if limits is None else limits
        self.planner = FootstepPlanner(robot, self.limits)
        robot.update(robot.q_ref, np.zeros(robot.nv))
        self.com_standing = robot.com.copy()
        self.com_height = float(self.com_standing[2]
                                - np.mean([robot.frame_placement(f)[0][2]
                                           for f in self.frames.values()]) - c.com_drop)
        self.omega = lipm_frequency(self.com_height, GRAVITY)
        self.base_offset = robot.q_ref[:3] - self.com_standing  # base from CoM, standing
        self.base_rotation = pin.Quaternion(robot.q_ref[3:7]).toRotationMatrix()  # standing
        self.formulation = Formulation(robot)
        task = {"posture_gains": c.posture_gains, "cop_margin": c.cop_margin,
                "torsion": c.torsion, "base_orientation_weight": BASE_ORIENTATION_WEIGHT}
        self.double = table2_stack(robot, self.soles, **task)
        self.unload = {s: ForceRegularizer(name=f"unload {s}", contacts=[s], weight=0.0)
                       for s in self.soles}
        for reg in self.unload.values():
            self.double.insert(2, reg)
        self.single, self.swing_task = {}, {}
        for stance in self.soles:
            swing = self._other(stance)
            self.single[stance] = table4_stack(robot, [stance], [self.frames[swing]],
                                               swing_gains=c.swing_gains, **task)
            self.swing_task[stance] = self.single[stance].find(f"swing {self.frames[swing]}")
        self.stacks = [self.double, *self.single.values()]
        self.variables = {None: Variables(robot, self.soles),
                          **{s: Variables(robot, [s]) for s in self.soles}}
        self._set_gains()
        self.cycles = None
        if engine != "python":
            self.cycles = {id(st): HierarchyCycle(robot, st, engine=engine) for st in self.stacks}
            if not all(cy.native for cy in self.cycles.values()):
                self.cycles = None
        # state
        self.command = np.zeros(3)
        self.queue: list[Footstep] = []
        self.phases: list[Phase] = []
        self.phase_index = 0
        self.plan: DCMPlan | None = None
        self.swing: SwingTrajectory | None = None
        self.swing_yaw = (0.0, 0.0)
        self.steps: list[StepRecord] = []
        self.recovering = False
        self.recovery_walk = False
        self.last = None
        self.last_cycle = None
        self.feet = {s: (robot.frame_placement(f)[0].copy(), _yaw(robot.frame_placement(f)[1]))
                     for s, f in self.frames.items()}
        self.standing_offset = self.com_standing[:2] - 0.5 * (self.feet[self.left][0][:2]
                                                              + self.feet[self.right][0][:2])
        self.standing_heading = self._heading()  # the soles', which need not be the base's
        # (from, to, start, end) of the heading reference
        self.base_yaw = (self.standing_heading, self.standing_heading, 0.0, 1.0)
        self.com_ref = self._standing_com()
        self.dcm_ref = self.com_ref[:2].copy()
        self._support_phase: Phase | None = None
        self._touchdown_dcm: tuple = (None, None)
        self._capture_polygon: tuple = (None, None)  # (the feet it is of, the polygon)
        self._support_polygon: SupportPolygon | None = None
        self.zmp_command = self.com_ref[:2].copy()
        self._start_share: tuple | None = None  # (carried, ZMP's) shares as a double support began
        self.cycle_times: list[float] = []
        self.events: list[tuple[float, str]] = []
        self._stand(0.0)

    # ------------------------------------------------------------------ set-up
    def _other(self, sole: str) -> str:
        return self.right if sole == self.left else self.left

    def _set_gains(self) -> None:
        """eq. 22's P and D: zero on the horizontal rows (the DCM feedback gives their
        feed-forward, :meth:`_horizontal_acceleration`), the height's PD on the vertical, damping
        of the angular momentum as the stacks have it; the legs' posture rows light and without
        stiffness; the joint-limit rows braking over ``joint_braking``."""
        c = self.config
        kp_z, kd_z = c.height_gains
        for stack in self.stacks:
            momentum = stack.find("momentum")
            P, D = np.diag(momentum.P).copy(), np.diag(momentum.D).copy()
            P[:3] = [0.0, 0.0, kp_z]
            D[:3] = [0.0, 0.0, kd_z]
            momentum.P, momentum.D = P, D
            posture = stack.find("posture")
            w = np.full(self.robot.nv, POSTURE_WEIGHT) if np.ndim(posture.weight) == 0 \
                else np.array(posture.weight, dtype=float)
            kp = np.full(self.robot.na, float(np.mean(posture.kp)))
            for sole in self.soles:
                idx = [self.robot.joint_names.index(j) for j in leg_joints(self.robot, sole)]
                w[FREE_FLYER_NV + np.array(idx)] = LEG_POSTURE_WEIGHT
                kp[idx] = 0.0
            posture.weight, posture.kp = w, kp
            stack.find("joint acceleration limits").horizon = c.joint_braking

    def _standing_com(self, feet=None) -> np.ndarray:
        """The standing CoM reference over the soles' midpoint: the posture's offset from it,
        turned with the heading, at the walking height (``feet``: the soles' placements, default
        the measured)."""
        feet = self.feet if feet is None else feet
        mid = 0.5 * (feet[self.left][0] + feet[self.right][0])
        yaw = _mean_angle([feet[s][1] for s in self.soles]) - self.standing_heading
        offset = np.array([[math.cos(yaw), -math.sin(yaw)],
                           [math.sin(yaw), math.cos(yaw)]]) @ self.standing_offset
        return np.array([mid[0] + offset[0], mid[1] + offset[1], mid[2] + self.com_height])

    # ------------------------------------------------------------------ commands
    def set_command(self, forward: float = 0.0, lateral: float = 0.0,
                    yaw_rate: float = 0.0) -> None:
        """The velocity command (heading frame; m/s, m/s, rad/s), read at every touchdown."""
        self.command = finite_array([forward, lateral, yaw_rate], "command", shape=(3,))

    def walk_footsteps(self, footsteps) -> None:
        """Queue explicit footsteps (:class:`~wholebody.planning.footsteps.Footstep`), taken in
        order after the current plan, each clamped to the leg's reach."""
        for k, f in enumerate(footsteps):
            if not isinstance(f, Footstep) or f.contact not in self.soles:
                raise ValueError(f"footsteps[{k}]: expected a Footstep of {list(self.soles)}, "
                                 f"got {f!r}")
        self.queue.extend(footsteps)

    @property
    def walking(self) -> bool:
        return self.phase.kind != "stand"

    @property
    def phase(self) -> Phase:
        return self.phases[self.phase_index]

    # ------------------------------------------------------------------ planning
    def _wants_to_walk(self) -> bool:
        return bool(self.queue) or bool(np.any(self.command != 0.0))

    def _next_footsteps(self, stance: str, n: int) -> list[Footstep]:
        """The next ``n`` footsteps, the first swinging the sole other than ``stance``."""
        feet = {s: self.feet[s] for s in self.soles}
        if self.queue:
            steps = []
            for f in self.queue[:n]:
                other = self._other(f.contact)
                xy, yaw = clamp_step(feet[other], 1 if other == self.left else -1,
                                     f.position[:2], f.yaw, self.limits)
                z = feet[other][0][2]
                step = Footstep(f.contact, np.array([xy[0], xy[1], z]), float(yaw))
                feet[f.contact] = (step.position, step.yaw)
                steps.append(step)
            return steps
        last = self.steps[-1] if self.steps else None
        if last is not None and last.contact == stance and math.isfinite(last.touchdown):
            # the path's heading goes on from the planned one: a sole landing a little turned
            # does not turn the rest of the walk with it
            feet[stance] = (feet[stance][0], last.yaw)
        period = self.config.single_support + self.config.double_support
        return self.planner.from_velocity(feet, self._other(stance), tuple(self.command),
                                          period, n)

    def _replan(self, t: float, com, dcm, stance: str, first_ds: float,
                footsteps: list[Footstep]) -> None:
        """Phases and the DCM plan from ``t``: a weight shift onto ``stance`` over ``first_ds``,
        then ``footsteps`` (single support, double support each), then the last weight shift to
        the middle of the soles and standing."""
        c = self.config
        single = c.recovery_single_support if self.recovering else c.single_support
        phases, times, zmp = [], [t], [self._support_center()]
        feet = dict(self.feet)
        ds, now, support = first_ds, t, stance
        for step in footsteps:
            phases.append(Phase("double", now, now + ds, support, step.contact))
            now += ds
            times.append(now)
            zmp.append(feet[support][0][:2])
            phases.append(Phase("single", now, now + single, support, footstep=step))
            now += single
            times.append(now)
            zmp.append(feet[support][0][:2])
            feet[step.contact] = (step.position, step.yaw)
            support = step.contact
            ds = c.double_support
        end_ds = c.final_double_support
        standing = self._standing_com(feet)[:2]
        phases.append(Phase("double", now, now + end_ds, None, self._other(support)))
        now += end_ds
        times.append(now)
        zmp.append(standing)
        phases.append(Phase("stand", now, math.inf))
        # the ZMP starts where it was commanded; a knot halfway through the first double
        # support is solved to start the plan at the measured DCM, kept inside the soles
        times.insert(1, t + 0.5 * first_ds)
        zmp.insert(1, zmp[0])
        zmp[0] = self.zmp_command
        times, zmp = np.array(times), np.array(zmp)
        plan = DCMPlan(self.omega, times, zmp, com[:2], dcm0=dcm[:2], solve_knot=1)
        inside = self.support(self.soles, self.config.cop_margin).project(plan.zmp_knots[1])
        if np.linalg.norm(inside - plan.zmp_knots[1]) > 1e-9:
            zmp[1] = inside
            plan = self._plan_from_a_later_knot(times, zmp, com, dcm, stance, footsteps)
        self.plan, self.phases, self.phase_index = plan, phases, 0
        yaws = [self.feet[s][1] for s in self.soles]
        if footsteps:
            yaws = [footsteps[0].yaw, self.feet[stance][1]]
        self.base_yaw = (self._heading(), _mean_angle(yaws), t, t + first_ds + single)

    def _plan_from_a_later_knot(self, times, zmp, com, dcm, stance: str, footsteps) -> DCMPlan:
        """The plan when the first double support's knot would leave the soles: that knot held
        inside them, the next one (where single support starts, under the stance sole) solved to
        start the plan at the measured DCM if it stays inside the stance sole; else the plan
        from the held knot (its DCM starts off the measured one)."""
        if footsteps:
            plan = DCMPlan(self.omega, times, zmp, com[:2], dcm0=dcm[:2], solve_knot=2)
            sole = self.support([stance], self.config.cop_margin)
            if np.linalg.norm(sole.project(plan.zmp_knots[2]) - plan.zmp_knots[2]) <= 1e-9:
                return plan
            log.debug("walking: the re-plan's knots cannot start at the measured DCM")
        return DCMPlan(self.omega, times, zmp, com[:2])

    def _support_center(self) -> np.ndarray:
        return 0.5 * (self.feet[self.left][0][:2] + self.feet[self.right][0][:2])

    def support(self, soles, margin: float) -> SupportPolygon:
        """The support polygon of ``soles`` at their last measured placements, each sole's
        rectangle shrunk by ``margin`` of its half-lengths."""
        return SupportPolygon(np.vstack([self._sole_corners(s, margin) for s in soles]))

    def _sole_corners(self, sole: str, margin: float) -> np.ndarray:
        pos, yaw = self.feet[sole]
        hx, hy = np.asarray(self.robot.contact(sole).spec.half_size) * (1.0 - margin)
        R = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
        corners = np.array([[hx, hy], [hx, -hy], [-hx, -hy], [-hx, hy]])
        return pos[:2] + corners @ R.T

    def _heading(self) -> float:
        return _mean_angle([self.feet[s][1] for s in self.soles])

    def _stand(self, t: float) -> None:
        """Standing: after a walk the plan's tail brings the CoM over the soles (its last ZMP
        knot), else the standing CoM is the reference."""
        self.phases = [Phase("stand", t, math.inf)]
        self.phase_index = 0
        self.recovering = False
        if self.plan is None:
            self.com_ref = self._standing_com()
        for s in self.soles:
            self.unload[s].weight = 0.0

    # ------------------------------------------------------------------ measurement
    def _measure(self, cycle, q, v):
        """CoM, its velocity, and the soles' placements at the last solved state."""
        if cycle is None:
            self.robot.update(q, v)
            return self.robot.com.copy(), self.robot.vcom.copy()
        return cycle.com, cycle.vcom

    def _sole_pose(self, sole: str, cycle) -> tuple[np.ndarray, float]:
        frame = self.frames[sole]
        pos, R = (self.robot.frame_placement(frame) if cycle is None
                  else cycle.frame_placement(frame))
        return np.array(pos, dtype=float), _yaw(R)

    def capture_point(self) -> np.ndarray:
        """The measured capture point (DCM) at the last cycle, world x, y."""
        return self._dcm.copy()

    # ------------------------------------------------------------------ the cycle
    def compute(self, q, v, t: float):
        t0 = time.perf_counter()
        robot = self.robot
        cycle = self.last_cycle
        held = self.last is not None and self.last.outcome is Outcome.HELD
        if self.cycles is None or cycle is None or held:  # (a held cycle's state: maybe absurd)
            robot.update(q, v)
            com, vcom = robot.com.copy(), robot.vcom.copy()
            cycle = None
        else:
            com, vcom = cycle.com, cycle.vcom  # the last cycle's state (one period old)
        dcm = com[:2] + vcom[:2] / self.omega
        self._dcm = dcm
        self._advance(t, com, vcom, dcm, cycle)
        ph = self.phase
        stack, variables = self._references(t, ph, dcm, com, vcom)
        if self.cycles is None:
            sol = self.formulation.solve(stack, variables, diagnostics=False)
        else:
            self.last_cycle = self.cycles[id(stack)]
            sol = self.last_cycle.solve(q, v, variables)
        sol = self.failures.note(sol)
        self.last = sol
        self.cycle_times.append(time.perf_counter() - t0)
        return sol

    def _advance(self, t, com, vcom, dcm, cycle) -> None:
        """Phase changes: touchdown re-plans, lift-off starts the swing, standing watches the
        capture point."""
        c = self.config
        while t >= self.phase.end:
            self._leave(self.phase, t, cycle)
            self.phase_index += 1
            self._enter(self.phase, t, com, vcom, dcm, cycle)
        ph = self.phase
        if ph.kind == "stand":
            if self._wants_to_walk():
                self._start_walking(t, com, vcom, dcm, cycle, recovery=False)
            elif c.stepping and self._capture_point_outside(dcm):
                self._start_walking(t, com, vcom, dcm, cycle, recovery=True)

    def _start_walking(self, t, com, vcom, dcm, cycle, recovery: bool) -> None:
        c = self.config
        for s in self.soles:
            self.feet[s] = self._sole_pose(s, cycle)
        self.recovery_walk = recovery  # steps until standing again are a recovery's
        if recovery:
            swing = self._recovery_swing(dcm)
            self.recovering = True
            self.events.append((t, "recovery step"))
            log.info("capture point left the support polygon at t=%.3f s: recovery steps", t)
            steps = self._steps_in_place(self._other(swing))
            first_ds = c.recovery_double_support
        else:
            stance = self._first_stance()
            steps = self._next_footsteps(stance, c.step_horizon)
            first_ds = c.initial_double_support
        stance = self._other(steps[0].contact)
        self._replan(t, com, dcm, stance, first_ds, steps)
        self._enter(self.phase, t, com, vcom, dcm, cycle)

    def _first_stance(self) -> str:
        """Walking starts with the sole toward which the command turns or moves as the swing."""
        _, vy, wz = self.command
        if self.queue:
            return self._other(self.queue[0].contact)
        lateral = vy if abs(vy) > 1e-9 else wz
        return self.left if lateral < 0 else self.right

    def _recovery_swing(self, dcm) -> str:
        """The sole farther from the capture point: the other, nearer one stands, where the
        capture point diverges the least from the CoP during the swing (after a sideways push
        the loaded outer sole stands, the inner one closes in, then the outer one steps out)."""
        distance = {s: float(np.linalg.norm(dcm - self.support((s,), self.config.cop_margin)
                                             .project(dcm))) for s in self.soles}
        return max(self.soles, key=lambda s: distance[s])

    def _capture_point_outside(self, dcm) -> bool:
        feet = tuple((tuple(p), y) for p, y in (self.feet[s] for s in self.soles))
        if self._capture_polygon[0] != feet:  # the soles moved: a new polygon
            self._capture_polygon = (feet, self.support(self.soles, self.config.capture_margin))
        return not self._capture_polygon[1].contains(dcm)

    def _leave(self, ph: Phase, t: float, cycle) -> None:
        if ph.kind == "single":
            sole = ph.footstep.contact
            self.feet[sole] = self._sole_pose(sole, cycle)
            self.steps[-1].touchdown = t

    def _enter(self, ph: Phase, t, com, vcom, dcm, cycle) -> None:
        c = self.config
        if ph.kind == "double":
            if self.phase_index > 0 and self.phases[self.phase_index - 1].kind == "single":
                self._touchdown(t, com, dcm, cycle)  # re-plans: the phase is the new plan's first
            self._setup_unload(self.phase)
        elif ph.kind == "single":
            sole = ph.footstep.contact
            pos, yaw = self._sole_pose(sole, cycle)
            target = ph.footstep.position.copy()
            target[2] -= c.touchdown_depth
            self.swing = SwingTrajectory(pos, target, ph.end - ph.start, c.clearance, t0=ph.start,
                                         floor=ph.footstep.position[2])
            self.swing_yaw = (yaw, ph.footstep.yaw)
            self.swing_planned = ph.footstep
            self.swing_task[ph.stance].weight = (c.recovery_swing_weight if self.recovery_walk
                                                 else c.swing_weight)
            self.steps.append(StepRecord(sole, t, math.nan, ph.footstep.position.copy(),
                                         ph.footstep.position.copy(), ph.footstep.yaw,
                                         self.recovering))
        elif ph.kind == "stand":
            self._stand(t)

    def _setup_unload(self, ph: Phase) -> None:
        """The leaving sole's regulariser on (its target: :meth:`_leaving_force`)."""
        for s in self.soles:
            self.unload[s].weight = 0.0
        if ph.leaving is not None:
            self.unload[ph.leaving].weight = UNLOAD_ROWS
            measured = self._measured_share(ph.leaving)
            self._start_share = None if measured is None else (
                measured, self._along(ph, self.zmp_command))

    def _along(self, ph: Phase, point) -> float:
        """``point``'s position on the line between the soles' centres, 1 at ``ph``'s leaving
        sole and 0 at the other."""
        a = self.feet[ph.leaving][0][:2]
        b = self.feet[self._other(ph.leaving)][0][:2]
        return float((point - b) @ (a - b)) / max(float((a - b) @ (a - b)), 1e-18)

    def _measured_share(self, sole: str) -> float | None:
        """``sole``'s share of the soles' normal force in the last solution (None: none yet)."""
        forces = {} if self.last is None else self.last.forces
        total = sum(max(float(w[2]), 0.0) for w in forces.values())
        if total <= 0.0:
            return None
        return max(float(forces[sole][2]), 0.0) / total if sole in forces else 0.0

    def _leaving_share(self, ph: Phase, t: float) -> float:
        """The leaving sole's share of the contact force: the commanded ZMP's position between
        the soles' centres (:meth:`_along`), plus the difference to the share the sole carried
        as the double support began, fading linearly over it (1 after a touchdown, about half
        when walking starts from standing: the ZMP stands off the sole's centre, and without
        this the other sole would take that difference at once). Kept within the shares the
        commanded ZMP admits (both soles' CoPs inside them, along the line between their
        centres)."""
        a = self.feet[ph.leaving][0]
        b = self.feet[self._other(ph.leaving)][0]
        dx, dy = float(a[0] - b[0]), float(a[1] - b[1])
        length = max(math.hypot(dx, dy), 1e-9)
        ux, uy = dx / length, dy / length
        x = float(self.zmp_command[0] - b[0]) * ux + float(self.zmp_command[1] - b[1]) * uy
        share = x / length  # the ZMP's along the centres' line (:meth:`_along`)
        if self._start_share is not None:
            carried, zmp_share = self._start_share
            share += (carried - zmp_share) * max(0.0, 1.0 - (t - ph.start)
                                                   / max(ph.end - ph.start, 1e-9))
        reach_a = self._sole_reach(ph.leaving, ux, uy)
        reach_b = self._sole_reach(self._other(ph.leaving), ux, uy)
        low = max(0.0, (x - reach_b) / max(length + reach_a - reach_b, 1e-9))
        high = min(1.0, (x + reach_b) / max(length - reach_a + reach_b, 1e-9))
        return min(max(share, low), max(low, high))

    def _sole_reach(self, sole: str, ux: float, uy: float) -> float:
        """How far ``sole``'s CoP may go from its centre along the unit (ux, uy): its rectangle's
        support function, the half-lengths shrunk by the CoP margin."""
        yaw = self.feet[sole][1]
        hx, hy = self.robot.contact(sole).spec.half_size
        c, s = math.cos(yaw), math.sin(yaw)
        return (1.0 - self.config.cop_margin) * (hx * abs(c * ux + s * uy)
                                                 + hy * abs(-s * ux + c * uy))

    def _leaving_force(self, ph: Phase, t: float, com, vcom, horizontal) -> np.ndarray:
        """The leaving sole's force target (its wrench's moments untargeted): its share
        (:meth:`_leaving_share`) of the vertical force of the momentum task's height law and of
        the commanded horizontal force ``horizontal``. The soles' forces then split as the ZMP
        asks and the whole force is handed over continuously at touchdown (all of it on the
        stance sole) and at lift-off (none on the leaving sole)."""
        share = self._leaving_share(ph, t)
        kp_z, kd_z = self.config.height_gains
        vertical = self.robot.mass * (GRAVITY + kp_z * (self.com_ref[2] - com[2]) - kd_z * vcom[2])
        return np.array([share * horizontal[0], share * horizontal[1],
                         share * max(vertical, 0.0), 0.0, 0.0, 0.0])

    def _touchdown(self, t, com, dcm, cycle) -> None:
        """Re-plan from the measured state at a touchdown: keep walking while there is a command
        or queued footsteps (or the recovery is not over), else stop."""
        c = self.config
        for s in self.soles:
            self.feet[s] = self._sole_pose(s, cycle)
        stance = self.phase.stance
        if self.queue and self.steps:
            self.queue.pop(0)
        if self.recovering and not self._capture_point_outside(dcm):
            self.recovering = False  # captured: the remaining steps at the walking pace
        if self._wants_to_walk():
            steps = self._next_footsteps(stance, c.step_horizon)
        elif self._feet_together(stance) and not self._capture_point_outside(dcm):
            self.recovering = False
            steps = []  # the last weight shift to the middle, then standing
        else:  # steps in place (the step adjustment moves them) until the robot can stop
            steps = self._steps_in_place(stance)
        self._replan(t, com, dcm, stance, c.double_support, steps)

    def _steps_in_place(self, stance: str) -> list[Footstep]:
        """``step_horizon`` steps with a zero command, the first putting the other sole beside
        ``stance`` at the nominal width (the stop, or a recovery's nominal steps)."""
        pos, yaw = self.feet[stance]
        swing = self._other(stance)
        side = 1.0 if swing == self.left else -1.0
        beside = pos + side * self.limits.nominal_width * np.array([-math.sin(yaw),
                                                                    math.cos(yaw), 0.0])
        first = Footstep(swing, beside, yaw)
        feet = dict(self.feet)
        feet[swing] = (beside, yaw)
        rest = self.planner.from_velocity(feet, stance, (0.0, 0.0, 0.0),
                                          self.config.single_support
                                          + self.config.double_support,
                                          self.config.step_horizon - 1) \
            if self.config.step_horizon > 1 else []
        return [first, *rest]

    def _feet_together(self, stance: str) -> bool:
        """The soles side by side at the nominal width, as a zero command leaves them."""
        (p, yaw), (p_other, yaw_other) = self.feet[stance], self.feet[self._other(stance)]
        d = p_other[:2] - p[:2]
        forward = math.cos(yaw) * d[0] + math.sin(yaw) * d[1]
        lateral = abs(-math.sin(yaw) * d[0] + math.cos(yaw) * d[1])
        tol = 0.1 * self.limits.nominal_width
        return (abs(forward) < tol and abs(lateral - self.limits.nominal_width) < tol
                and abs(_wrap(yaw_other - yaw)) < 0.05)

    # ------------------------------------------------------------------ references
    def _references(self, t: float, ph: Phase, dcm, com, vcom):
        robot = self.robot
        if self.plan is None:
            com_ref, vel, acc = self.com_ref, np.zeros(3), np.zeros(3)
        else:
            cxy, dcxy, ddcxy = self.plan.com(t)
            com_ref = np.array([cxy[0], cxy[1], self.com_ref[2]])
            vel, acc = np.array([dcxy[0], dcxy[1], 0.0]), np.array([ddcxy[0], ddcxy[1], 0.0])
            self.com_ref = com_ref
            self.dcm_ref = self.plan.dcm(t)[0]
        if ph.kind == "single":
            stack, variables = self.single[ph.stance], self.variables[ph.stance]
            self._swing_references(t, ph, dcm)
        else:
            stack, variables = self.double, self.variables[None]
        m = robot.mass
        momentum = stack.find("momentum")
        momentum.com_ref = com_ref
        a = self._horizontal_acceleration(ph, com_ref, vel, acc, com, vcom)
        momentum.h_ref = np.array([m * vel[0], m * vel[1], m * vel[2], 0.0, 0.0, 0.0])
        momentum.hdot_ref = np.array([m * a[0], m * a[1], 0.0, 0.0, 0.0, 0.0])
        if ph.kind == "double" and ph.leaving is not None:
            self.unload[ph.leaving].targets[ph.leaving] = self._leaving_force(
                ph, t, com, vcom, m * a)
        posture = stack.find("posture")
        q_ref = robot.q_ref.copy()
        # the standing base pose relative to the soles, turned with the heading
        Rz = _yaw_matrix(self._base_yaw(t) - self.standing_heading)
        q_ref[:3] = com_ref + Rz @ self.base_offset
        q_ref[3:7] = pin.Quaternion(Rz @ self.base_rotation).coeffs()
        posture.q_ref = q_ref
        return stack, variables

    def _horizontal_acceleration(self, ph: Phase, com_ref, vel, acc, com, vcom) -> np.ndarray:
        """The CoM's horizontal acceleration of the DCM feedback, c'' = c_ref'' + omega k (c_ref
        - c) + (omega + k)(c_ref' - c') (eq. 22's PD with P = omega k, D = omega + k), with the
        ZMP it implies, c - c'' / omega^2, kept inside the support polygon (the CoP rows would
        clip it anyway; the hierarchy would then make the missing force by rotating the body)."""
        w, k = self.omega, self.config.dcm_gain * self.omega
        a = acc[:2] + w * k * (com_ref[:2] - com[:2]) + (w + k) * (vel[:2] - vcom[:2])
        if self._support_phase is not ph:
            soles = (ph.stance,) if ph.kind == "single" else self.soles
            self._support_polygon = self.support(soles, self.config.cop_margin)
            self._support_phase = ph
        zmp = self._support_polygon.project(com[:2] - a / (w * w))
        self.zmp_command = zmp
        return w * w * (com[:2] - zmp)

    def _base_yaw(self, t: float) -> float:
        y0, y1, ta, tb = self.base_yaw
        s = min(max((t - ta) / max(tb - ta, 1e-9), 0.0), 1.0)
        s = s * s * (3.0 - 2.0 * s)
        return y0 + s * _wrap(y1 - y0)

    def _swing_references(self, t: float, ph: Phase, dcm) -> None:
        c = self.config
        task = self.swing_task[ph.stance]
        if c.adjust_until > 0 and t - ph.start <= c.adjust_until * (ph.end - ph.start):
            self._adjust_step(t, ph, dcm)
        pos, vel, acc = np.empty(3), np.empty(3), np.empty(3)
        self.swing.evaluate_into(t, pos, vel, acc)
        s, ds, _ = quintic_blend((t - ph.start) / (ph.end - ph.start), ph.end - ph.start)
        y0, y1 = self.swing_yaw
        dyaw = _wrap(y1 - y0)
        task.position = pos
        task.rotation = _yaw_matrix(y0 + s * dyaw)
        task.velocity = np.array([vel[0], vel[1], vel[2], 0.0, 0.0, ds * dyaw])
        task.acceleration = np.array([acc[0], acc[1], acc[2], 0.0, 0.0, 0.0])

    def _adjust_step(self, t: float, ph: Phase, dcm) -> None:
        """Step adjustment: the footstep moves by the predicted DCM error at touchdown."""
        stance_pos, stance_yaw = self.feet[ph.stance]
        xi_T = predicted_dcm(dcm, stance_pos[:2], self.omega, ph.end - t)
        if self._touchdown_dcm[0] is not ph:  # the reference at touchdown: once per swing
            self._touchdown_dcm = (ph, self.plan.dcm(ph.end)[0])
        xi_ref_T = self._touchdown_dcm[1]
        planned = ph.footstep
        target = planned.position[:2] + (xi_T - xi_ref_T)
        side = 1 if ph.stance == self.left else -1
        limits = self.recovery_limits if self.recovering else self.limits
        xy, yaw = clamp_step(self.feet[ph.stance], side, target, planned.yaw, limits)
        if np.linalg.norm(xy - self.swing.p1[:2]) > 1e-4:  # (the swing's heights, floor kept)
            self.swing = self.swing.with_landing_xy(xy)
            self.steps[-1].target = np.array([xy[0], xy[1], planned.position[2]])


def _yaw_matrix(yaw: float) -> np.ndarray:
    """The rotation by ``yaw`` about z."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _yaw(R) -> float:
    R = np.asarray(R)
    return float(math.atan2(R[1, 0], R[0, 0]))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _mean_angle(angles) -> float:
    return float(math.atan2(np.mean(np.sin(angles)), np.mean(np.cos(angles))))


class SupportPolygon:
    """The convex hull of soles' rectangles in the floor plane, and the nearest point in it."""

    def __init__(self, corners: np.ndarray):
        pts = np.asarray(corners, dtype=float).reshape(-1, 2)
        self.vertices = pts[ConvexHull(pts).vertices]  # counter-clockwise
        self.edges = np.roll(self.vertices, -1, axis=0) - self.vertices
        self.normals = np.stack([self.edges[:, 1], -self.edges[:, 0]], axis=1)  # outward
        # (normal, vertex) per edge as Python floats: the point test of every control cycle
        # costs a tenth of numpy's calls over a handful of edges (the same products and sums)
        self._edge_rows = np.hstack([self.normals, self.vertices]).tolist()

    def contains(self, p) -> bool:
        """``p`` is inside or on the boundary (within 1e-12 of each edge's line)."""
        px, py = float(p[0]), float(p[1])
        for nx, ny, vx, vy in self._edge_rows:
            if not nx * (px - vx) + ny * (py - vy) <= 1e-12:
                return False
        return True

    def project(self, p) -> np.ndarray:
        """``p`` itself if inside, else the nearest point of the boundary."""
        p = np.asarray(p, dtype=float)
        if self.contains(p):
            return p.copy()
        d = p - self.vertices
        s = np.clip(np.einsum("ij,ij->i", d, self.edges)
                    / np.einsum("ij,ij->i", self.edges, self.edges), 0.0, 1.0)
        nearest = self.vertices + s[:, None] * self.edges
        return nearest[int(np.argmin(np.linalg.norm(p - nearest, axis=1)))]
