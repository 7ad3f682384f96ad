"""Closed-loop quadruped locomotion runs shared by the scenarios of Fahmi et al. 2019 (Sect. V).

:func:`run_gait` builds a gait planner (crawl, trot or stand) with a velocity command, one of the
two controllers (``passive``: :class:`~wholebody.control.passive.PassiveWBC`; ``quasi-static``: the
baseline of Sect. V-E), and a MuJoCo twin with the given environment; it runs the WBC at
``control_period`` (250 Hz, Sect. V) with the simulator at 1 kHz holding the last torque, and
records a :class:`GaitLog`. Everything measured for success criteria (feet slip, fall, torques
sent) comes from the simulator, not from the controller's own model.

Also shared by the quadruped scenarios: their common parameters (``GAIT``, ``CRAWL_SPEED``,
``DURATION``, ``RUN_DURATION``), checks of the robot and of the parameters, the two velocity
commands (:func:`steady_command`, :func:`ramped_command`) and the simulator's world for a terrain
course (:func:`course_environment`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from ..control.passive import REGULARIZATIONS, PassiveConfig, PassiveWBC, SwingGains
from ..control.quasi_static import QuasiStaticController
from ..planning.gait import CRAWL_PERIOD, TROT_PERIOD, crawl, stand, stride_capped, trot
from ..planning.planner import GaitPlanner
from ..planning.terrain import Terrain
from ..planning.trunk import VelocityCommand
from ..robots import reference
from ..robots.reference import froude_ratio
from ..robots.roles import check_gait_legs, quadruped_legs
from ..sim.environment import Box, Environment
from ..sim.series import SeriesLog
from ..sim.simulator import Simulator
from ..tasks.wrench import DAMPING_RATIO_THETA, DAMPING_RATIO_X, TrunkImpedance, trunk_weights
from .base import TIME_SPAN, BaseHeight, Parameter, RobotRelative
from .loop import run_closed_loop
from .measures import FALL_HEIGHT_FRACTION, TwinGait, update_to_state

CONTROLLERS = ("passive", "quasi-static")

#: the trunk impedance of eq. 4 (both controllers) as scenario parameters: loop frequencies and
#: damping ratios on the robot's mass and trunk inertia (:meth:`TrunkImpedance.for_robot`)
TRUNK_GAINS = (
    Parameter("trunk_frequency", 0.0, "trunk impedance (eq. 4): CoM loop frequency (Hz) on the "
              "robot's mass (0: the paper's K_x on HyQ, Froude-scaled)", low=0.0, high=100.0),
    Parameter("trunk_damping_ratio", round(DAMPING_RATIO_X, 6), "trunk impedance: damping ratio "
              "of the CoM loop (the paper's D_x on HyQ)", low=0.0, high=100.0),
    Parameter("trunk_angular_frequency", 0.0, "trunk impedance: orientation loop frequency (Hz) "
              "on the trunk inertia (0: the paper's K_theta on HyQ, Froude-scaled)", low=0.0,
              high=100.0),
    Parameter("trunk_angular_damping_ratio", round(DAMPING_RATIO_THETA, 6), "trunk impedance: "
              "damping ratio of the orientation loop (the paper's D_theta on HyQ)", low=0.0,
              high=100.0),
    Parameter("trunk_pitch_weight", 0.0, "trunk wrench task (eq. 7a): weight of the pitch moment "
              "against the forces' and the other moments' 1 (0: tan psi / tan psi_HyQ, psi the "
              "angle of a diagonal of the standing feet to the heading; 1 on HyQ)", low=0.0,
              high=1e3),
)


#: the swing impedance of eq. 6 (the passive WBC; accelerations, the same on every robot)
SWING_GAINS = (
    Parameter("swing_stiffness", SwingGains.K, "passive WBC swing impedance (eq. 6): K_sw, foot "
              "acceleration per metre of error (1/s^2; the paper's 2000)", low=0.0, high=1e6),
    Parameter("swing_damping", SwingGains.D, "passive WBC swing impedance: D_sw (1/s; the "
              "paper's 20)", low=0.0, high=1e4),
)
#: the stance task of eq. 32 (the passive WBC; accelerations, the same on every robot)
STANCE_GAINS = (
    Parameter("stance_stiffness", PassiveConfig.K_st, "passive WBC stance task (eq. 32): K_st, "
              "foot acceleration per metre of slip (1/s^2; 0 with stance_damping 0: eq. 10)",
              low=0.0, high=1e6),
    Parameter("stance_damping", PassiveConfig.D_st, "passive WBC stance task: D_st, per m/s of "
              "slip velocity (1/s)", low=0.0, high=1e4),
)
#: the posture regulariser of both controllers (ours): the joints no foot task determines pulled
#: toward the standing posture (:class:`~wholebody.control.passive.PassiveConfig`)
POSTURE_REGULARIZER_GAINS = (
    Parameter("posture_frequency", 0.0, "posture regulariser (both controllers): frequency (Hz) "
              "of the pull of the joints no foot task determines toward the standing posture (0: "
              "HyQ's 8 rad/s, Froude-scaled)", low=0.0, high=100.0),
    Parameter("posture_damping_ratio", PassiveConfig.posture_damping, "posture regulariser: "
              "damping ratio", low=0.0, high=100.0),
)
#: every gain of the quadruped controllers a scenario takes (:func:`wbc_gains`): the paper's
WBC_GAINS = (*TRUNK_GAINS, *SWING_GAINS, *STANCE_GAINS, *POSTURE_REGULARIZER_GAINS)
#: the CoM loop's damping ratio of ``steer``, the velocity-command schedule: critically damped.
#: The paper's D_x gives 0.48 on HyQ, tuned for its 0.04-0.15 m/s crawl; every change of a
#: velocity command then rings at the loop's 0.76 Hz (Froude-scaled on other robots). Not a
#: default elsewhere: at Froude 0.5 and under pushes while trotting it lost ANYmal C
#: (docs/results.md, "Steering")
CRITICAL_DAMPING_RATIO = 1.0
#: :data:`WBC_GAINS` with the CoM loop critically damped (:data:`CRITICAL_DAMPING_RATIO`)
CRITICALLY_DAMPED_WBC_GAINS = tuple(
    replace(p, default=CRITICAL_DAMPING_RATIO, help="trunk impedance: damping ratio of the CoM "
            f"loop (1: critically damped; the paper's D_x on HyQ: {DAMPING_RATIO_X:.3f})")
    if p.name == "trunk_damping_ratio" else p for p in WBC_GAINS)
#: the quasi-static baseline's Cartesian swing PD (force-level), for the scenarios that run it
BASELINE_GAINS = (
    Parameter("baseline_swing_stiffness", 0.0, "quasi-static baseline: swing legs' Cartesian "
              "stiffness (N/m; 0: HyQ's 2000 times the robot's mass over HyQ's)",
              low=0.0, high=1e7),
    Parameter("baseline_swing_damping", 0.0, "quasi-static baseline: swing legs' Cartesian "
              "damping (N s/m; 0: HyQ's 50 times the robot's mass over HyQ's)",
              low=0.0, high=1e6),
)


#: the crawl's lateral sway (:class:`~wholebody.planning.trunk.CrawlSway`) as a parameter
SWAY_GAIN = Parameter("sway_gain", 1.0, "crawl: lateral CoM sway toward the centroid of the "
                      "three stance feet (1: onto its lateral coordinate, 0: no sway); a gentler "
                      "sway asks less lateral acceleration of the trunk", low=0.0, high=1.0)


#: the passive WBC's force regulariser (:class:`~wholebody.control.passive.PassiveConfig`)
REGULARIZATION = Parameter("regularization", "force-parallel", "passive WBC's force "
                           "regulariser: force-parallel (ours: every foot at the net force's "
                           "friction ratio), force-normal (the paper's: tangential forces small) "
                           "or torque", choices=REGULARIZATIONS)


def sway_options(params: dict) -> dict:
    """The planner options of :data:`SWAY_GAIN` (missing: the default)."""
    return {"sway_gain": (0.0, params.get(SWAY_GAIN.name, SWAY_GAIN.default))}


def trunk_gains(params: dict) -> dict:
    """Keyword arguments of :meth:`TrunkImpedance.for_robot` from the :data:`TRUNK_GAINS`
    parameters (missing ones at their defaults; a frequency of 0 keeps the robot-relative
    default)."""
    get = {p.name: params.get(p.name, p.default) for p in TRUNK_GAINS}
    return {"frequency_x_hz": get["trunk_frequency"] or None,
            "damping_ratio_x": get["trunk_damping_ratio"],
            "frequency_theta_hz": get["trunk_angular_frequency"] or None,
            "damping_ratio_theta": get["trunk_angular_damping_ratio"]}
GAITS = ("crawl", "trot", "stand")
FALL_TILT = np.radians(45.0)
#: a gait run goes on this long (s) after the robot has fallen, so that its figures show the fall,
#: then stops: what follows a fall measures nothing
FALL_GRACE = 1.0
#: the set-ups of Fahmi et al. 2019 are HyQ's, whose standing base height this is:
#: :func:`paper_length` and :class:`PaperSpeed` keep their proportions on any other robot
PAPER_BASE_HEIGHT = reference.BASE_HEIGHT


@dataclass(frozen=True)
class PaperLength(BaseHeight):
    """A length of the paper's set-ups, ``metres`` on HyQ, as a robot-relative parameter default:
    the same fraction of any robot's standing base height h (exactly ``metres`` on HyQ)."""

    metres: float = 0.0

    def value(self, robot) -> float:
        return self.metres * (float(robot.q_ref[2]) / PAPER_BASE_HEIGHT)


    def as_data(self) -> dict[str, float]:
        return {"base_height": self.factor, "metres_on_reference": self.metres,
                "reference_base_height_m": PAPER_BASE_HEIGHT}


def paper_length(metres: float) -> PaperLength:
    """``metres`` of the paper's HyQ set-ups as a :class:`PaperLength` (``--set`` shows it in h)."""
    return PaperLength(metres / PAPER_BASE_HEIGHT, float(metres))


#: the trot's longest stance travel of a foot relative to its hip on HyQ (m; :func:`make_schedule`),
#: 2/3 of its base height: the default trot period reaches it at 1.0 m/s. Chosen by the speed ramps
#: to Froude 0.5 of docs/results.md ("Top speed of the trot"): the only cap of 0.2, 0.25, 0.3, 0.35
#: and 0.4 m with which all six quadrupeds got there
MAX_STRIDE = 0.4

#: the gait's step height, period and stride cap: HyQ's, kept in proportion on any robot
#: (:func:`gait_options`, :func:`make_schedule`)
GAIT_SHAPE = (
    Parameter("clearance", paper_length(0.1), "swing feet's highest point above the higher of "
              "their lift-off and touchdown points (m)", low=0.0, high=0.5 * Parameter.H),
    Parameter("period", 0.0, "gait period (s; 0: HyQ's crawl or trot period times "
              "sqrt(h / 0.599))", low=0.0, high=Parameter.MAX_TIME),
    Parameter("max_stride", paper_length(MAX_STRIDE), "trot: longest travel of a stance foot "
              "relative to its hip (m; duty x speed x period); above the speed where the period "
              "reaches it, the period shortens as max_stride / (duty x speed); 0: fixed period",
              low=0.0, high=Parameter.H),
)


@dataclass(frozen=True)
class PaperSpeed(RobotRelative):
    """A speed of the paper's HyQ set-ups (``mps`` on HyQ) as a robot-relative default: scaled by
    :func:`froude_ratio`, so that a small robot walks as fast relative to its size."""

    mps: float

    def value(self, robot) -> float:
        return self.mps * froude_ratio(robot)

    def __str__(self) -> str:
        return f"{self.mps:g} sqrt(h / {PAPER_BASE_HEIGHT:.3g})"

    def as_data(self) -> dict[str, float]:
        return {"mps_on_reference": self.mps, "reference_base_height_m": PAPER_BASE_HEIGHT}

COURSE_BOX_THICKNESS = 1.0  # thickness of the simulator's level ground boxes of a course (m)
COURSE_SLOPE_THICKNESS = 0.1  # thickness of the simulator's ramp boxes of a course (m)

#: the trot's forward speed on HyQ (m/s; ``steer``, ``trot-push``), Froude-scaled on other robots
TROT_SPEED = 0.4

#: parameters declared alike by several quadruped scenarios
GAIT = Parameter("gait", "crawl", "crawl or trot", choices=("crawl", "trot"))
CRAWL_SPEED = Parameter("speed", PaperSpeed(0.11),
                        "forward crawl speed (m/s), reached 1 s after the gait starts",
                        low=0.0, low_open=True, high=5.0)
DURATION = Parameter("duration", 10.0, "simulated time (s)",
                     **TIME_SPAN)
RUN_DURATION = Parameter("duration", 10.0, "simulated time per run (s); the crawl starts at 1 s",
                         **TIME_SPAN)


def check_quadruped(robot, scenario: str, gait: str = "crawl") -> None:
    """ValueError unless ``robot`` has four point-foot contacts whose roles are known and legs
    with the moving joints ``gait`` needs (:func:`~wholebody.robots.roles.check_gait_legs`)."""
    try:
        legs = quadruped_legs(robot)
    except ValueError as exc:
        raise ValueError(f"{scenario}: {exc}") from None
    check_gait_legs(robot, legs, gait, scenario)


def check_joint(robot, joint: str) -> None:
    """ValueError naming ``--set joint`` unless ``joint`` is one of the robot's joints."""
    if joint not in robot.joint_names:
        raise ValueError(f"--set joint: unknown joint '{joint}'; joints: "
                         f"{', '.join(robot.joint_names)}")


#: the shortest gait period (s) taken: each phase must last a few cycles of the 250 Hz WBC
MIN_GAIT_PERIOD = 0.1


def check_gait(params: dict, gaits=("crawl", "trot")) -> None:
    """ValueError naming ``--set gait`` unless it is one of ``gaits``, or ``--set period`` if it
    is set (not 0) below :data:`MIN_GAIT_PERIOD`."""
    if params["gait"] not in gaits:
        raise ValueError(f"--set gait: expected {' or '.join(gaits)}, got '{params['gait']}'")
    period = params.get("period", 0.0)
    if 0.0 < period < MIN_GAIT_PERIOD:
        raise ValueError(f"--set period: {period:g} s is shorter than {MIN_GAIT_PERIOD:g} s (0: "
                         f"the default period)")


def check_positive(params: dict, keys) -> None:
    """ValueError naming the first of ``keys`` whose value is not positive."""
    for key in keys:
        if not params[key] > 0:
            raise ValueError(f"--set {key}: must be positive, got {params[key]}")


def parse_positive_floats(text, name: str, allow_empty: bool = False) -> list[float]:
    """A comma-separated ``--set name=...`` value as positive finite floats (ValueError naming it)."""
    try:
        values = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--set {name}: expected comma-separated numbers, got '{text}'") from None
    if (not values and not allow_empty) or any(not (np.isfinite(v) and v > 0) for v in values):
        raise ValueError(f"--set {name}: need positive numbers, got '{text}'")
    return values


def steady_command(speed: float) -> VelocityCommand:
    """Forward ``speed`` reached by a linear ramp over [1, 2] s (the gaits start at 1 s)."""
    return VelocityCommand((0.0, 0.0), (speed, 0.0), (1.0, 2.0))


def ramped_command(speed: float) -> VelocityCommand:
    """Forward ``speed`` reached by a linear ramp over [1, 3] s."""
    return VelocityCommand.speed_ramp(0.0, speed, 1.0, 3.0)


def gait_options(robot, shape: dict | None = None) -> dict:
    """The planner options that scale with the robot: the swing apex ``clearance``, the
    :data:`GAIT_SHAPE` parameter in ``shape`` if given, else 0.1 m on HyQ (:func:`paper_length`)."""
    clearance = (shape or {}).get("clearance")
    return {"clearance": paper_length(0.1).value(robot) if clearance is None else clearance}


def make_schedule(robot, gait: str, start: float = 1.0, shape: dict | None = None,
                  command=None):
    """The ``gait`` schedule (crawl, trot or stand) of ``robot``'s four feet, addressed by role
    (:func:`~wholebody.robots.roles.quadruped_legs`), starting at ``start`` s, its period the
    :data:`GAIT_SHAPE` parameter in ``shape`` if given and > 0, else HyQ's times
    :func:`froude_ratio` (dynamically similar steps). Given the ``command`` (a
    :class:`VelocityCommand` or a ``CommandSchedule``: its ``velocity(t)``), a trot's period
    shortens with its speed so that its stride stays within ``max_stride``
    (:func:`~wholebody.planning.gait.stride_capped`)."""
    legs = quadruped_legs(robot)
    period = (shape or {}).get("period") or None
    if gait == "crawl":
        return crawl(period or CRAWL_PERIOD * froude_ratio(robot), start=start, legs=legs)
    if gait == "trot":
        schedule = trot(period or TROT_PERIOD * froude_ratio(robot), start=start, legs=legs)
        max_stride = (shape or {}).get("max_stride")
        if max_stride is None:
            max_stride = paper_length(MAX_STRIDE).value(robot)
        if command is None or max_stride == 0.0:
            return schedule
        return stride_capped(schedule, lambda t: float(np.linalg.norm(command.velocity(t))),
                             max_stride, MIN_GAIT_PERIOD)
    if gait == "stand":
        return stand(legs=legs)
    raise ValueError(f"gait: expected one of {GAITS}, got '{gait}'")


def make_controller(robot, name: str, planner, **options):
    if name == "passive":
        return PassiveWBC(robot, planner, **options)
    if name == "quasi-static":
        return QuasiStaticController(robot, planner, **options)
    raise ValueError(f"controller: expected one of {CONTROLLERS}, got '{name}'")


def course_environment(course) -> Environment:
    """The simulator's world for a :class:`~wholebody.planning.courses.Course`: no floor plane, one
    box per surface strip (so a gap is a real hole) with the course's width and friction. Level
    strips are deep boxes, slopes thin ones (a tilted box's end face leans over its neighbour; next
    to a gap it narrows the hole, but only below 5 cm under the surface); rough ground is one deep
    box per cell of its height field."""
    boxes = []
    for s in course.strips:
        if s.field is None:
            boxes.append(_strip_box(s, course.width, COURSE_BOX_THICKNESS if s.z0 == s.z1
                                    else COURSE_SLOPE_THICKNESS))
            continue
        f, half = s.field, 0.5 * COURSE_BOX_THICKNESS
        for (i, j), dz in np.ndenumerate(f.heights):
            top = s.z0 + float(dz)
            boxes.append(Box((f.x0 + (i + 0.5) * f.cx, f.y0 + (j + 0.5) * f.cy, top - half),
                             (0.5 * f.cx, 0.5 * f.cy, half)))
    return Environment(floor_friction=course.friction, floor=False, boxes=boxes)


def _strip_box(s, width: float, thickness: float) -> Box:
    """A box whose top face is the strip (tilted by its slope), ``thickness`` deep."""
    angle = math.atan2(s.z1 - s.z0, s.x1 - s.x0)
    length = math.hypot(s.x1 - s.x0, s.z1 - s.z0)
    n = np.array([-math.sin(angle), 0.0, math.cos(angle)])
    top_mid = np.array([0.5 * (s.x0 + s.x1), 0.0, 0.5 * (s.z0 + s.z1)])
    centre = top_mid - 0.5 * thickness * n
    return Box(tuple(centre), (0.5 * length, 0.5 * width, 0.5 * thickness), (0.0, -angle, 0.0))


class GaitLog(SeriesLog):
    """One row per control cycle. Errors are reference minus measured (world axes): CoM position,
    trunk orientation (log3(R_d Rᵀ)); ``feet`` are the simulator's foot-frame positions; ``stance``
    the planner's contact flags; ``tau``/``tau_min``/``tau_max`` the command and its limits;
    ``contact_speed`` the horizontal speed of each foot's material contact point (zero while a
    foot sphere rolls, nonzero when it slips). Stored as numbers in chunks
    (:class:`~wholebody.sim.series.SeriesLog`)."""

    FIELDS = ("t", "com_error", "orientation_error", "com", "com_ref", "feet", "stance", "tau",
              "tau_min", "tau_max", "ok", "swing_error", "cycle_time", "forces", "contact_speed")


@dataclass
class GaitRun:
    """A gait run's log and outcome; ``fell_at``: the time of the fall (None: it did not fall),
    after which the run went on for at most ``FALL_GRACE`` s."""

    log: dict[str, np.ndarray]
    fell: bool
    failures: int
    distance: float
    controller: object
    sim: Simulator
    fell_at: float | None = None

    def tracking(self, t_from: float = 0.0) -> dict[str, float]:
        """l2 norms of the linear and angular trunk errors (Fig. 5): RMS and max over t ≥ t_from."""
        sel = self.log["t"] >= t_from
        ex = np.linalg.norm(self.log["com_error"][sel], axis=1)
        eth = np.linalg.norm(self.log["orientation_error"][sel], axis=1)
        return {"linear_rms_m": float(np.sqrt(np.mean(ex ** 2))), "linear_max_m": float(ex.max()),
                "angular_rms_rad": float(np.sqrt(np.mean(eth ** 2))),
                "angular_max_rad": float(eth.max())}

    def stance_slip(self, skip: float = 0.02) -> np.ndarray:
        """Per leg, the largest distance slipped during one stance phase: the integral of the
        contact point's horizontal speed, from ``skip`` s after touchdown (the impact) to lift-off."""
        t, speed, stance = self.log["t"], self.log["contact_speed"], self.log["stance"]
        dt = np.diff(t, prepend=t[0])
        worst = np.zeros(speed.shape[1])
        for leg in range(speed.shape[1]):
            slipped, since = 0.0, None
            for k in range(len(t)):
                if not stance[k, leg]:
                    since, slipped = None, 0.0
                    continue
                since = t[k] if since is None else since
                if t[k] - since >= skip:
                    slipped += speed[k, leg] * dt[k]
                    worst[leg] = max(worst[leg], slipped)
        return worst


def wbc_gains(params: dict) -> dict:
    """The :data:`WBC_GAINS` and :data:`BASELINE_GAINS` parameters (missing ones at their defaults)
    as ``run_gait``'s ``gains``: ``{"impedance": trunk_gains(params), "swing": (K_sw, D_sw),
    "pitch_weight": w, "stance": (K_st, D_st), "posture": (ω, ζ), "baseline_swing": (K, D)}`` (w,
    ω, K or D None: the robot-relative default; ω in rad/s)."""
    get = {p.name: params.get(p.name, p.default) for p in (*WBC_GAINS, *BASELINE_GAINS)}
    frequency = get["posture_frequency"]
    return {"impedance": trunk_gains(params),
            "swing": (get["swing_stiffness"], get["swing_damping"]),
            "pitch_weight": get["trunk_pitch_weight"] or None,
            "stance": (get["stance_stiffness"], get["stance_damping"]),
            "posture": (2.0 * math.pi * frequency if frequency else None,
                        get["posture_damping_ratio"]),
            "baseline_swing": (get["baseline_swing_stiffness"] or None,
                               get["baseline_swing_damping"] or None)}


def gain_options(robot, controller: str, gains: dict, options: dict) -> dict:
    """``options`` for ``controller`` (``make_controller``'s keywords) with what the
    :func:`wbc_gains` ``gains`` set for it added, except what ``options`` already gives: the trunk
    impedance and weights (both controllers), the swing impedance and stance task (passive), the
    Cartesian swing PD (quasi-static), the posture regulariser (both)."""
    extra = {}
    if "impedance" in gains:
        extra["impedance"] = TrunkImpedance.for_robot(robot, **gains["impedance"])
    if gains.get("pitch_weight") is not None:
        extra["Q"] = trunk_weights(robot, pitch=gains["pitch_weight"])
    if "posture" in gains:
        extra["posture_frequency"], extra["posture_damping"] = gains["posture"]
    if controller == "passive" and "swing" in gains:
        extra["swing"] = SwingGains(*gains["swing"])
    if controller == "passive" and "stance" in gains:
        extra["K_st"], extra["D_st"] = gains["stance"]
    if controller != "passive" and "baseline_swing" in gains:
        extra["swing_K"], extra["swing_D"] = gains["baseline_swing"]
    return {**extra, **options}


def run_gait(robot, controller: str = "passive", gait: str = "crawl",
             command: VelocityCommand | None = None, duration: float = 10.0,
             environment: Environment | None = None, terrain: Terrain | None = None,
             control_period: float = 0.004, controller_options: dict | None = None,
             planner_options: dict | None = None, start: float = 1.0, progress: bool = False,
             on_cycle=None, planner=None, observers=(), q0=None,
             gains: dict | None = None, after_fall: float | None = FALL_GRACE,
             shape: dict | None = None, pushes=()) -> GaitRun:
    """Walk ``robot`` with ``controller`` in the twin for ``duration`` s (see module docstring).

    ``terrain`` is the controller's/planner's view (footholds, normals, trunk height); the simulator
    sees ``environment``. ``on_cycle(t, result, ctrl, sim)`` is called after every WBC cycle.
    ``planner``: a ready-made planner (e.g. with foothold adjustment or its own trunk terrain) used
    instead of building one; ``gait``, ``command``, ``terrain``, ``planner_options`` and ``start``
    are then ignored. ``observers`` watch the simulation (labelled with the controller's name).
    ``q0``: the initial configuration (default: the standing posture ``robot.q_ref``), resting on
    the support surface; the planner starts from it. ``gains``: the controllers' gains
    (:func:`wbc_gains`; :func:`gain_options` says which each takes), unless ``controller_options``
    gives the same keyword. ``after_fall``: once the robot has fallen,
    the run stops this many seconds later (None: it runs its whole ``duration``). ``shape``: the
    :data:`GAIT_SHAPE` parameters (step height, period, stride cap) for the planner built here.
    ``pushes``: the simulator applies these (:class:`~wholebody.sim.disturbance.Push`).
    """
    if q0 is not None:
        q0 = np.asarray(q0, dtype=float).copy()
    if planner is None:
        planner = GaitPlanner.for_robot(robot, make_schedule(robot, gait, start, shape, command),
                                        command, terrain, q=q0, t0=0.0,
                                        **{**gait_options(robot, shape), **(planner_options or {})})
    options = gain_options(robot, controller, gains or {}, controller_options or {})
    if controller == "passive":
        options.setdefault("control_period", control_period)
    ctrl = make_controller(robot, controller, planner, **options)
    sim = Simulator(robot, environment, observers=observers, label=controller)
    for push in pushes:
        sim.add_push(push)
    if q0 is not None:
        q0[2] += sim.environment.support_height()
        sim.reset(q0)
    log = GaitLog()
    base0 = sim.state()[0][:3].copy()
    # fallen: the base below FALL_HEIGHT_FRACTION of its standing height above the terrain under it
    fall_height = FALL_HEIGHT_FRACTION * float(robot.q_ref[2])
    fell_at = None
    legs = planner.legs
    twin = TwinGait(robot, legs)

    def observe(t, result):
        nonlocal fell_at
        plan = ctrl.last_plan
        q, v = sim.state()
        if on_cycle is not None:  # it may read the robot's cycle: at the twin's state
            update_to_state(robot, q, v)
        rotation, com, feet, speeds = twin.at(q, v)
        # the twin's trunk errors (eq. 4's, against the plan's trunk reference): under real-robot
        # conditions the controller's own (impedance.last_errors) are the estimate's
        com_error, orientation_error = TrunkImpedance.pose_errors(rotation, com, plan.trunk)
        lo, hi = ctrl.torque_limits.bounds(robot, q)
        log.append(
            t=t, com_error=com_error, orientation_error=orientation_error,
            com=com, com_ref=plan.trunk.position, feet=feet, stance=plan.contact,
            tau=result.tau, tau_min=lo, tau_max=hi, ok=result.ok,
            swing_error=max((r.error for r in result.tasks if r.name.startswith("swing")),
                            default=0.0),
            cycle_time=sum(result.timings.get(k, 0.0) for k in ("assemble", "solve")),
            forces=result.lam, contact_speed=speeds)
        # (one number clipped with min/max: np.clip's own cost is many times the arithmetic's)
        tilt = np.arccos(min(max(pin.Quaternion(q[3:7]).toRotationMatrix()[2, 2], -1.0), 1.0))
        if fell_at is None and (q[2] - planner.terrain.height(q[0], q[1]) < fall_height
                                or tilt > FALL_TILT):
            fell_at = t
        if on_cycle is not None:
            on_cycle(t, result, ctrl, sim)

    def stop() -> bool:
        return after_fall is not None and fell_at is not None and sim.t >= fell_at + after_fall

    failures = run_closed_loop(sim, ctrl, duration, control_period=control_period,
                               progress=progress, on_result=observe, until=stop)
    q, _ = sim.state()
    return GaitRun(log.arrays(), fell_at is not None, failures, float(q[0] - base0[0]), ctrl, sim,
                   fell_at)
