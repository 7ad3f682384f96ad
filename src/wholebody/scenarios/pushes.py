"""Pushes on the standing humanoid (Herzog et al. 2016 Sect. 5.2.2), shared by ``push``,
``push-series``, ``robust-push`` and ``single-support``: the paper's push points, the push itself,
the momentum-balance options and one push trial; and what every push scenario shares (the
direction of an ``angle``, the force of a ``dv``, a series of angles and the bisection of the
strongest survived ``dv``: ``push-step``, ``walk-push``, ``trot-push``).

The push is a half-sine force applied at one of the paper's 7 points (front, right, back, left on
the torso above the hip; front, right, left at the hip) or along any ``angle`` and ``height``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..control.balance import MomentumBalance
from ..control.stacks import ANGULAR_MOMENTUM_WEIGHT
from ..robots import reference
from ..robots.roles import biped_soles
from ..sim.disturbance import Push
from ..sim.simulator import Simulator
from .base import (COP_MARGIN, ENGINE, INTEGRAL_LIMIT, PD_PARAMETERS, POSTURE_PARAMETERS, Q_ANGULAR,
                   Q_INTEGRAL, Parameter,
                   RobotRelative, check_engine, momentum_gains, parse_list, task_gains)
from .loop import run_closed_loop
from .measures import Thresholds, TwinCentroidal, rotation_angle_deg, sole_slip, tilt_deg

# location -> (the robot's frame, ``trunk_frame`` or ``base_frame``, direction of the force, point
# of application in that frame, in m on talos14: scaled by the robot's standing height,
# :func:`push_point`)
TORSO_OFFSET, SURFACE = 0.1, 0.12
LOCATIONS = {
    "front": ("trunk_frame", (-1.0, 0.0, 0.0), (SURFACE, 0.0, TORSO_OFFSET)),
    "right": ("trunk_frame", (0.0, 1.0, 0.0), (0.0, -SURFACE, TORSO_OFFSET)),
    "back": ("trunk_frame", (1.0, 0.0, 0.0), (-SURFACE, 0.0, TORSO_OFFSET)),
    "left": ("trunk_frame", (0.0, -1.0, 0.0), (0.0, SURFACE, TORSO_OFFSET)),
    "hip-front": ("base_frame", (-1.0, 0.0, 0.0), (SURFACE, 0.0, 0.0)),
    "hip-right": ("base_frame", (0.0, 1.0, 0.0), (0.0, -SURFACE, 0.0)),
    "hip-left": ("base_frame", (0.0, -1.0, 0.0), (0.0, SURFACE, 0.0)),
}


def push_point(robot, part: str, offset) -> tuple[str, np.ndarray]:
    """(frame name, point in it) of a push point: ``part`` the robot's attribute naming the frame
    (``trunk_frame`` or ``base_frame``), ``offset`` in m on talos14, scaled by the robot's
    standing base height."""
    frame = getattr(robot, part)
    scale = reference.humanoid_length_ratio(robot)
    return frame, scale * np.asarray(offset, dtype=float)

@dataclass(frozen=True)
class HumanoidScaled(RobotRelative):
    """A quantity of the humanoid set-ups, ``amount`` on talos14, as a robot-relative default:
    times (m / m_talos14)^``mass_power`` (h / h_talos14)^``height_power``
    (s / s_talos14)^``stretch_power`` — a force with mass power 1 gives the same velocity change,
    a length with height power 1 the same proportion, a vertical CoG motion with stretch power 1
    the same share of how far the legs can stretch (s, :func:`~wholebody.robots.reference.
    leg_stretch`). ``listed``: the value is the text of a list parameter, ``amount`` one number
    or a tuple of them (each scaled). Exactly ``amount`` on talos14."""

    amount: float | tuple[float, ...]
    unit: str
    mass_power: int = 0
    height_power: int = 0
    listed: bool = False
    stretch_power: int = 0

    def value(self, robot):
        scale = (reference.humanoid_mass_ratio(robot) ** self.mass_power
                 * reference.humanoid_length_ratio(robot) ** self.height_power)
        if self.stretch_power:
            stretch = reference.leg_stretch(robot) / reference.HUMANOID_LEG_STRETCH
            scale *= stretch ** self.stretch_power
        if isinstance(self.amount, tuple):
            return ",".join(f"{a * scale:.4g}" for a in self.amount)
        x = self.amount * scale
        return f"{x:.4g}" if self.listed else x

    def __str__(self) -> str:
        factors = " ".join(f for f, p in (("m", self.mass_power), ("h", self.height_power),
                                          ("s", self.stretch_power)) if p)
        reference = f"{factors}_talos14" if " " not in factors else f"({factors})_talos14"
        amount = (",".join(f"{a:g}" for a in self.amount) if isinstance(self.amount, tuple)
                  else f"{self.amount:g}")
        return f"{amount} {self.unit} x {factors} / {reference}"

    def as_data(self) -> dict[str, float]:
        amount = list(self.amount) if isinstance(self.amount, tuple) else self.amount
        return {"amount_on_reference": amount, "mass_power": self.mass_power,
                "height_power": self.height_power, "stretch_power": self.stretch_power,
                "reference_mass_kg": reference.HUMANOID_MASS,
                "reference_base_height_m": reference.HUMANOID_BASE_HEIGHT,
                "reference_leg_stretch_m": reference.HUMANOID_LEG_STRETCH}


@dataclass(frozen=True)
class FroudeScaled(HumanoidScaled):
    """A speed (``height_power`` 0.5) or a rate (-0.5) at talos14's Froude number: ``amount``
    times (h / h_talos14) ** height_power."""

    def __str__(self) -> str:
        ratio = "h / h_talos14" if self.height_power > 0 else "h_talos14 / h"
        return f"{self.amount:g} {self.unit} x sqrt({ratio})"


#: momentum-balance options of the push scenarios (see :func:`controller_options`)
ANGULAR_WEIGHT = Parameter(
    "angular_weight", ANGULAR_MOMENTUM_WEIGHT,
    "weight of the momentum task's angular rows in Table 2 (1e4: the paper's single momentum "
    "weight, which lets the pelvis drift under model errors)", low=0.0)
Q_ORIENTATION = Parameter("q_orientation", 0.0, "LQR only: weight of the base orientation error "
                                                "in the LQR state (ours, not the paper's; 0 = "
                                                "off, the paper's controller)", low=0.0)
CONTROLLER_PARAMETERS = (Q_ANGULAR, ANGULAR_WEIGHT, Q_INTEGRAL, INTEGRAL_LIMIT, Q_ORIENTATION,
                         *PD_PARAMETERS, *POSTURE_PARAMETERS, COP_MARGIN, ENGINE)

#: the push parameters of one trial that push-series and robust-push do not vary
FIXED_PUSH = {"angle": 0.0, "height": 0.1}


def controller_options(controller: str, params: dict) -> dict:
    """Keyword arguments of :class:`MomentumBalance` from the scenario parameters (``q_angular``,
    ``angular_weight``, ``engine``, for LQR the integral action ``q_integral``/``integral_limit``
    and the orientation state ``q_orientation``,
    for PD eq. 22's gains ``pd_stiffness``/``pd_damping``/``pd_angular_damping``, the posture
    task's ``posture_stiffness``/``posture_damping``, the soles' ``cop_margin``; missing keys
    take the defaults of :data:`CONTROLLER_PARAMETERS`)."""
    defaults = {p.name: p.default for p in CONTROLLER_PARAMETERS}
    get = lambda key: params.get(key, defaults[key])  # noqa: E731
    opts = {"angular_weight": get("angular_weight"), "engine": get("engine"),
            "cop_margin": get("cop_margin"),
            **momentum_gains(controller, params),
            **task_gains({p.name: get(p.name) for p in POSTURE_PARAMETERS})}
    if controller == "lqr" and get("q_orientation") > 0:
        opts["q_orientation"] = get("q_orientation")
    return opts


def ignored_option_notes(controller: str, params: dict) -> list[str]:
    """Notes for options of the other gains' law given a non-default value (LQR's integral action
    with PD, eq. 22's gains with LQR): they are ignored, not errors, so that one parameter set
    runs both controllers."""
    options = (Q_INTEGRAL, INTEGRAL_LIMIT, Q_ORIENTATION) if controller != "lqr" else PD_PARAMETERS
    law = "an LQR" if controller != "lqr" else "a PD"
    return [f"{p.name} is {law} option; ignored with the {controller.upper()} gains"
            for p in options if p.name in params and params[p.name] != p.default]


def push_direction(angle: float) -> tuple[float, float, float]:
    """The world direction of a push along ``angle`` (deg) in the horizontal plane: the force
    along (-cos, -sin), so 0 pushes the front backwards (toward -x), 90 the left side toward -y,
    180 the back forwards."""
    a = np.radians(angle)
    return (-float(np.cos(a)), -float(np.sin(a)), 0.0)


def peak_force_for(mass: float, dv: float, duration: float) -> float:
    """The peak of the half-sine force of ``duration`` s that gives ``mass`` the velocity change
    ``dv``: its impulse 2 F T / pi is m dv."""
    return 0.5 * np.pi * mass * dv / duration


def series_parameters(low, high) -> tuple[Parameter, ...]:
    """The parameters of a series of pushes along ``angles`` and of a bisection of the strongest
    survived dv per angle between ``bisect_low`` and ``bisect_high`` (defaults ``low``, ``high``;
    :func:`push_angles`, :func:`bisect_dv`)."""
    return (
        Parameter("angles", "", "series: comma-separated push angles (deg), one trial (or "
                  "bisection) each ('': the single angle)", low=-360.0, high=360.0, items=float),
        Parameter("bisect", False, "per angle, bisect the strongest survived dv between "
                                   "bisect_low and bisect_high"),
        Parameter("bisect_low", low, "lower end of the bisection (m/s)", low=0.0, high=5.0),
        Parameter("bisect_high", high, "upper end of the bisection (m/s)", low=0.0,
                  low_open=True, high=5.0),
        Parameter("bisect_steps", 6, "bisection iterations per angle (each one simulation)",
                  low=1, high=30),
    )


def push_angles(params: dict) -> list[float]:
    """The angles of :func:`series_parameters`' ``angles``, or the single ``angle``."""
    text = str(params["angles"]).strip()
    return parse_list(text, float, "angles") if text else [float(params["angle"])]


def series_simulations(params: dict, controller: str) -> int:
    """Simulations of a series (one per angle) or of its bisections (``bisect_steps`` each)."""
    return len(push_angles(params)) * (int(params["bisect_steps"]) if params["bisect"] else 1)


def check_bisection(params: dict) -> None:
    """ValueError unless ``bisect_low`` < ``bisect_high`` when ``bisect`` is on."""
    if params["bisect"] and not params["bisect_low"] < params["bisect_high"]:
        raise ValueError(f"--set bisect_low ({params['bisect_low']:g}) must be below bisect_high "
                         f"({params['bisect_high']:g})")


@dataclass
class PushSeries:
    """What :func:`push_series` found: ``metrics`` (a single trial's own, else per angle under
    ``angles``), ``success``, and ``runs``, angle text -> (metrics, run) of each trial (empty when
    bisecting)."""

    metrics: dict
    success: bool
    runs: dict
    bisected: bool

    def single(self):
        """The (metrics, run) of the only trial, None when bisecting or with several angles."""
        return next(iter(self.runs.values())) if len(self.runs) == 1 else None

    def bar_values(self, key: str) -> list[float]:
        """Per angle, 100 x the strongest survived dv when bisecting, else 100 x ``key`` of each
        trial's metrics (0 where it is None or missing): the bars of a series figure."""
        if self.bisected:
            return [100 * (r["strongest_survived_dv_mps"] or 0.0)
                    for r in self.metrics["angles"].values()]
        return [100 * (m.get(key) or 0.0) for m, _ in self.runs.values()]


def push_series(params: dict, bisection, trial) -> PushSeries:
    """Pushes along each of :func:`push_angles`: with ``bisect`` ``bisection(angle)`` each
    (success: every angle survived some push), else ``trial(dv, angle)`` -> (metrics with
    ``survived``, run) each (success: every one survived)."""
    angles = push_angles(params)
    if params["bisect"]:
        per_angle = {f"{a:g}": bisection(a) for a in angles}
        return PushSeries({"angles": per_angle}, all(
            r["strongest_survived_dv_mps"] is not None for r in per_angle.values()), {}, True)
    runs = {f"{a:g}": trial(params["dv"], a) for a in angles}
    public = {k: m for k, (m, _) in runs.items()}
    metrics = next(iter(public.values())) if len(runs) == 1 else {"angles": public}
    return PushSeries(metrics, all(m["survived"] for m in public.values()), runs, False)


def bisect_dv(survives, low: float, high: float, steps: int) -> dict:
    """The strongest velocity change ``survives(dv)`` (one simulation each) holds for, bisecting
    [``low``, ``high``] ``steps`` times from its middle: the strongest survived dv (None if no trial
    survived), the weakest not survived (None if all did) and every trial's (dv, survived)."""
    best, trials = None, []
    for _ in range(int(steps)):
        dv = 0.5 * (low + high)
        ok = bool(survives(dv))
        trials.append({"dv_mps": dv, "survived": ok})
        if ok:
            best, low = dv, dv
        else:
            high = dv
    return {"strongest_survived_dv_mps": best, "weakest_fallen_dv_mps":
            min((x["dv_mps"] for x in trials if not x["survived"]), default=None),
            "trials": trials}


def make_push(params: dict, robot) -> Push:
    """The half-sine push on ``robot`` at ``location`` (or along ``angle``, ``height`` m above the
    base), ``peak_force``, ``start``, ``push_duration``."""
    location = params["location"]
    if location == "angle":
        a = np.radians(params["angle"])
        direction = push_direction(params["angle"])
        frame, offset = push_point(robot, "base_frame", (SURFACE * np.cos(a), SURFACE * np.sin(a), 0.0))
        offset[2] = params["height"]
    elif location in LOCATIONS:
        part, direction, offset = LOCATIONS[location]
        frame, offset = push_point(robot, part, offset)
    else:
        raise ValueError(f"--set location: '{location}' is not one of {', '.join(LOCATIONS)}, angle")
    return Push(frame, direction, params["peak_force"], params["start"], params["push_duration"],
                offset=tuple(float(x) for x in offset))


def location_of(push: Push, robot) -> str:
    """The name in :data:`LOCATIONS` of a push's point on ``robot``."""
    return next(k for k, (part, direction, offset) in LOCATIONS.items()
                if push_point(robot, part, offset)[0] == push.frame
                and np.allclose(direction, push.direction))


def check_push(robot, params: dict) -> None:
    """ValueError unless the engine is known, ``robot`` has the push's frame and rectangular soles."""
    check_engine(params)
    biped_soles(robot)  # ValueError unless two rectangular soles
    make_push(params, robot)


def check_locations(locations) -> None:
    for location in locations:
        if location not in LOCATIONS:
            raise ValueError(f"--set locations: '{location}' is not one of {', '.join(LOCATIONS)}")


@dataclass
class PushTrial:
    """One push on the exact twin: survived, metrics, and the records of every control cycle."""

    success: bool
    metrics: dict
    push: Push
    log: object  # the simulator's log
    cog_error: np.ndarray  # (N, 3) robot.com - com_ref
    momentum: np.ndarray  # (N, 6) h_G


def push_trial(robot, controller: str, params: dict, progress: bool = False,
               observers=(), balance: MomentumBalance | None = None) -> PushTrial:
    """One push (``make_push(params)``) on the standing robot under :class:`MomentumBalance` for
    ``duration`` s. Survived: the feet stay flat and in place and the CoG returns within 5 mm of its
    reference within 3 s after the push (:mod:`~wholebody.scenarios.measures`). ``observers``
    watch the simulation. ``balance``: a controller built by the caller (e.g. with a
    ``reference``) instead of the one ``controller`` and ``params`` describe."""
    push = make_push(params, robot)
    ctrl = balance if balance is not None else MomentumBalance(
        robot, gains=controller, **controller_options(controller, params))
    sim = Simulator(robot, observers=observers, label=controller)
    sim.add_push(push)
    start_feet = sim.contact_frame_poses()
    com, momentum, feet_tilt, feet_slip, trunk = [], [], [], [], []
    base_quat0 = robot.q_ref[3:7]
    twin = TwinCentroidal(robot)

    def observe(t, result):
        q, v = sim.state()
        twin_com, _, h_G = twin.at(q, v)
        trunk.append(rotation_angle_deg(q[3:7], base_quat0))
        com.append(twin_com - ctrl.com_ref)
        momentum.append(h_G)
        poses = sim.contact_frame_poses()
        feet_tilt.append(max(tilt_deg(R) for _, R in poses.values()))
        feet_slip.append(max(sole_slip(poses[n][0], start_feet[n][0]) for n in poses))

    failures = run_closed_loop(sim, ctrl, params["duration"], progress=progress, on_result=observe)
    t = sim.log.arrays()["t"]
    com, momentum = np.array(com), np.array(momentum)
    err = np.linalg.norm(com, axis=1)
    thresholds = Thresholds.for_robot(robot)
    recovered, recovery = thresholds.cog_recovered(t, err, push.start + push.duration)
    metrics = {
        "peak_force_N": push.peak_force,
        "impulse_Ns": push.impulse,
        "delta_v_mps": push.impulse / robot.mass,
        "max_cog_error_m": float(err.max()),
        "final_cog_error_m": float(err[-1]),
        "max_linear_momentum_Ns": float(np.linalg.norm(momentum[:, :3], axis=1).max()),
        "max_angular_momentum_Nms": float(np.linalg.norm(momentum[:, 3:], axis=1).max()),
        "cog_recovery_time_s": recovery,
        "max_foot_tilt_deg": float(max(feet_tilt)),
        "max_foot_slip_m": float(max(feet_slip)),
        "max_trunk_rotation_deg": float(max(trunk)),
        "final_trunk_rotation_deg": float(trunk[-1]),
        "failed_cycles": failures,
    }
    success = recovered and thresholds.feet_in_place(metrics["max_foot_tilt_deg"],
                                                     metrics["max_foot_slip_m"])
    return PushTrial(success, metrics, push, sim.log, com, momentum)
