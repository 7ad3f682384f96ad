"""``squat``: CoG sine tracking in double support with the Table 2 hierarchy (Herzog et al. 2016
Sect. 5.3, Fig. 10).

The CoG reference is x_ref(t) = x0 + e(t) [a_x sin(2 pi f t), 0, a_z sin(2 pi f t)] (2 cm forward
and 3 cm vertical on talos14, f = 0.3 or 0.5 Hz, both axes in phase; e rises from 0 to 1 over
``ramp`` s) with the feed-forward h_ref = m x_ref' and hdot_ref = [m x_ref''; 0]
(:class:`~wholebody.control.balance.CoMSineReference`). Torques from the hierarchy only. On
another robot a_x scales with the standing height and a_z with how far its legs can stretch
from the posture (:func:`~wholebody.robots.reference.leg_stretch`): a robot standing on nearly
straight legs squats less rather than straightening them onto their limits.

Variants:

- ``tracking``: the CoP rows' default margin (``cop_margin``); they should stay inactive.
- ``cop-active`` (Fig. 10): the admissible CoP rectangle of each sole is shrunk by ``active_margin``
  so that the CoP constraints (level 2) become active during the motion and level 3 gives way.
  How the paper made its constraints active is not said; its Sarcos feet have a flexible toe that
  makes "the effectively used part of the sole rather small" (Sect. 4.1), which a shrunk region
  imitates. The default (``active_margin`` 0: derived, :func:`active_margin`) puts the bound,
  along the soles' forward axis, midway between the peaks of two quantities of the reference
  (linear inverted pendulum of the standing CoG height z, from the sole centres): its capture
  point xi = c + c'/omega0 (omega0 = sqrt(g/z)) and the CoP it needs, p = c - z c''_x/(g + c''_z).
  Below the capture point's peak the reference leaves the capturable region (no CoP inside the
  bound brings it back); below the required CoP's peak the CoG cannot follow the reference with
  the CoP alone, so the rows bind at every forward peak. On talos14 (21 x 13 cm soles, the CoG
  0.6 cm ahead of the sole centres, z 0.87 m, 0.5 Hz) the peaks are 3.31 and 4.39 cm: margin
  0.63, a bound of +-3.85 cm. The cascade's own CoP goes further than the LIP's (up to 6.7 cm in
  the ``tracking`` variant: the posture's motions add angular-momentum rates), so the rows bind
  for most of each period; level 3 then keeps the CoG on its reference by pitching the trunk
  (the angular-momentum rows weigh 1e-4) and the posture is what gives way. The former default
  0.7 (+-3.15 cm) is below the capture point's peak and falls (docs/results.md).

Metrics: those of :mod:`wholebody.scenarios.platform` (measured by
:class:`~wholebody.scenarios.measures.BalanceMonitor`: CoG error, momentum deviation from h_ref,
foot tilt and slip on the floor, predicted vs measured CoP, fraction of cycles with an active CoP
constraint), plus per axis ``max/rms_cog_error_{x,z}_m``, ``rms_cog_velocity_error_mps`` (|x_cog' -
x_ref'|), ``max_cop_bound_ratio`` (max of |measured CoP| / admissible half-size; <= 1 means the real
CoP stayed in the admissible region) and ``tracked_amplitude_{x,z}_m`` (half the peak-to-peak CoG
motion measured after the ramp).
Success: every cycle solved, feet flat (< 2 deg) and in place (< 1 cm) — "feet never tilt" — and
the CoG error bounded by ``max_cog_error`` (default 1 cm when tracking, 2 cm with active CoP
constraints, where the CoG task is sacrificed by design).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..control.balance import CoMSineReference, MomentumBalance
from ..report.balance_figures import squat_figure
from ..robots.reference import humanoid_length_ratio
from ..sim.simulator import Simulator
from .base import (COP_MARGIN, ENGINE, INTEGRAL_LIMIT, PD_PARAMETERS, POSTURE_PARAMETERS,
                   Q_ANGULAR, Q_INTEGRAL, Parameter,
                   Scenario, ScenarioResult, check_biped, format_mm, momentum_gains,
                   paper_q_notes, task_gains)
from .loop import run_closed_loop
from .measures import COP_SKIP, BalanceMonitor, limit_notes
from .pushes import HumanoidScaled

VARIANTS = ("tracking", "cop-active")

PARAMETERS = (
    Parameter("variant", "tracking", "tracking (the CoP region of cop_margin) or cop-active "
                                     "(Fig. 10: shrunk CoP region, constraints become active)",
              choices=VARIANTS),
    Parameter("frequency", 0.5, "sine frequency (Hz), 0.3 or 0.5 in the paper", low=0.1, high=5.0),
    Parameter("amplitude_x", HumanoidScaled(0.02, "m", height_power=1),
              "forward amplitude (m; the paper's 2 cm in proportion to the height)",
              low=-0.3 * Parameter.H, high=0.3 * Parameter.H),
    Parameter("amplitude_z", HumanoidScaled(0.03, "m", stretch_power=1),
              "vertical amplitude (m; the paper's 3 cm as the same share of how far the legs "
              "can stretch, s)", low=-0.3 * Parameter.H, high=0.3 * Parameter.H),
    Parameter("periods", 3.0, "number of sine periods after the ramp",
              low=0.0, low_open=True, high=60.0),
    Parameter("ramp", 1.0, "amplitude ramp-in time (s)", low=0.0, high=Parameter.MAX_TIME),
    Parameter("active_margin", 0.0, "cop-active: fraction by which the admissible CoP half-sizes "
                                    "shrink; 0 = derived from the reference (the bound midway "
                                    "between the peaks of its capture point and of the CoP it "
                                    "needs)", low=0.0, high=1.0, high_open=True),
    Parameter("torsion", True, "the soles' yaw moments bounded (FrictionCone torsion rows, the "
                               "stacks' default); false: the paper's friction pyramid only"),
    Q_ANGULAR,
    Q_INTEGRAL,
    INTEGRAL_LIMIT,
    *PD_PARAMETERS,
    *POSTURE_PARAMETERS,
    COP_MARGIN,
    Parameter("max_cog_error", 0.0, "bound on the CoG error (m); 0 = 0.01 tracking, 0.02 "
                                    "cop-active on talos14, times h / h_talos14 on another "
                                    "robot", low=0.0, high=Parameter.H),
    ENGINE,
)


def reference_peaks(robot, amplitude_x: float, amplitude_z: float, frequency: float,
                    g: float = 9.81) -> tuple[float, float]:
    """Peaks (m, largest over a period of |value|, along the soles' mean forward axis from the
    mean of the sole centres) of the steady squat reference's capture point xi = c + c'/omega0 and
    of the CoP it needs, p = c - z c''_x / (g + c''_z) (linear inverted pendulum; z: the standing
    CoG height above the sole centres, omega0 = sqrt(g/z))."""
    robot.update(robot.q_ref, np.zeros(robot.nv))
    poses = [robot.data.oMf[robot.contact(n).frame_id] for n in robot.contact_names]
    centre = np.mean([P.translation for P in poses], axis=0)
    forward = np.mean([P.rotation[:, 0] for P in poses], axis=0)
    forward[2] = 0.0
    forward /= np.linalg.norm(forward)
    c0 = robot.com.copy()
    z = c0[2] - centre[2]
    x0 = float(np.dot(c0 - centre, forward))
    w = 2 * np.pi * frequency
    phase = np.linspace(0.0, 2 * np.pi, 3601)
    s, c = np.sin(phase), np.cos(phase)
    # the reference moves along world x; its forward component along the soles' axis
    ax = amplitude_x * forward[0]
    xi = x0 + ax * (s + w * c / np.sqrt(g / z))
    p = x0 + ax * s + z * ax * w ** 2 * s / (g - amplitude_z * w ** 2 * s)
    return float(np.abs(xi).max()), float(np.abs(p).max())


def active_margin(robot, params: dict) -> float:
    """The cop-active variant's margin: ``params["active_margin"]`` if > 0, else derived from the
    reference (:func:`reference_peaks`): the bound along the soles' forward axis midway between
    the capture point's and the required CoP's peaks, as a fraction of the smallest sole
    half-length, margin = 1 - bound / hx."""
    if params["active_margin"] > 0:
        return float(params["active_margin"])
    xi, p = reference_peaks(robot, params["amplitude_x"], params["amplitude_z"],
                            params["frequency"])
    hx = min(robot.contact(n).spec.half_size[0] for n in robot.contact_names
             if robot.contact(n).spec.type == "rectangle")
    margin = 1.0 - 0.5 * (xi + p) / hx
    if not 0.0 < margin < 1.0:
        raise ValueError(f"--set variant=cop-active: the derived active_margin {margin:.3f} is "
                         f"outside (0, 1) (capture point peak {100 * xi:.2f} cm, required CoP "
                         f"peak {100 * p:.2f} cm, sole half-length {100 * hx:.2f} cm); give "
                         f"--set active_margin")
    return float(margin)


def validate(robot, params: dict) -> None:
    check_biped(robot, params)
    if params["variant"] not in VARIANTS:
        raise ValueError(f"--set variant: expected one of {', '.join(VARIANTS)}, got "
                         f"'{params['variant']}'")
    if not params["frequency"] > 0 or not params["periods"] > 0:
        raise ValueError("--set frequency and periods must be > 0")
    if not 0.0 <= params["active_margin"] < 1.0:
        raise ValueError("--set active_margin: expected 0 <= margin < 1")
    if params["variant"] == "cop-active":
        active_margin(robot, params)  # a derived margin outside (0, 1): refused before simulating


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    f = params["frequency"]
    margin = (active_margin(robot, params) if params["variant"] == "cop-active"
              else params["cop_margin"])
    bound = params["max_cog_error"] or (  # 1 / 2 cm on talos14, in proportion on another robot
        (0.02 if params["variant"] == "cop-active" else 0.01)
        * humanoid_length_ratio(robot))
    reference = CoMSineReference(robot, amplitude=(params["amplitude_x"], 0.0, params["amplitude_z"]),
                                 frequency=(f, f, f), ramp=params["ramp"])
    ctrl = MomentumBalance(robot, gains=controller, reference=reference, cop_margin=margin,
                           **momentum_gains(controller, params), **task_gains(params),
                           engine=params["engine"], torsion=params["torsion"])
    sim = Simulator(robot, observers=observers, label=controller)
    monitor = BalanceMonitor(robot, sim, ctrl)
    thresholds = monitor.thresholds
    vel = []

    def observe(t, sol):
        monitor(t, sol)
        vel.append((monitor.last[1], reference.terms(t)[1]))  # the twin's CoM velocity

    duration = params["ramp"] + params["periods"] / f
    failures = run_closed_loop(sim, ctrl, duration, progress=progress, on_result=observe)
    metrics = monitor.metrics()
    for key in ("peak_platform_acceleration_mps2", "peak_platform_angular_velocity_radps"):
        metrics.pop(key)
    a = monitor.arrays()
    t, err, com = a["t"], a["cog_error"], a["com"]
    vel = np.array(vel)
    after = t >= params["ramp"]
    for i, axis in ((0, "x"), (2, "z")):
        metrics[f"max_cog_error_{axis}_m"] = float(np.abs(err[:, i]).max())
        metrics[f"rms_cog_error_{axis}_m"] = float(np.sqrt(np.mean(err[:, i] ** 2)))
        metrics[f"tracked_amplitude_{axis}_m"] = float(np.ptp(com[after, i]) / 2)
    metrics["rms_cog_velocity_error_mps"] = float(
        np.sqrt(np.mean(np.sum((vel[:, 0] - vel[:, 1]) ** 2, axis=1))))
    bounds = np.array([monitor.bound[n] for n in monitor.names])
    settled = t >= t[0] + COP_SKIP
    ratio = (np.abs(a["cop_meas"]) / bounds)[settled]
    metrics["max_cop_bound_ratio"] = float(np.nanmax(ratio)) if np.isfinite(ratio).any() else None
    metrics["failed_cycles"] = failures
    metrics["cop_margin"] = margin
    success = bool(failures == 0
                   and thresholds.feet_in_place(metrics["max_foot_tilt_deg"],
                                                metrics["max_foot_slip_m"])
                   and metrics["max_cog_error_m"] < bound)
    notes = [f"CoG error bound for success: {100 * bound:.1f} cm"]
    m = metrics
    measured = (f"max CoG error {1000 * m['max_cog_error_m']:.1f} mm (RMS x "
                f"{1000 * m['rms_cog_error_x_m']:.2f}, z {1000 * m['rms_cog_error_z_m']:.2f} mm), "
                f"CoP constraints active {100 * m['cop_active_fraction']:.0f} % of the time, "
                f"predicted-vs-measured CoP RMS {format_mm(m['cop_rms_error_m'])} mm, measured CoP up to "
                f"{m['max_cop_bound_ratio'] or 0:.2f} of the admissible half-size, foot tilt "
                f"{m['max_foot_tilt_deg']:.2f} deg, largest posture deviation "
                f"{m['max_joint_deviation_rad']:.2f} rad ({m['max_deviation_joint']})")
    if margin:
        notes.append("paper (Fig. 10): CoP constraints active in most of the experiment, real CoPs "
                     "follow the predicted ones and stay inside, feet do not tilt, CoG tracking "
                     "not ideal but reasonable; measured: " + measured)
    else:
        notes.append("paper: the CoG tracks 0.3/0.5 Hz sines of 2 cm forward and 3 cm vertical "
                     "(video only); measured: " + measured)
    if m["max_cog_error_m"] > thresholds.fall_cog_error:
        notes.append(f"the robot fell (CoG error > {100 * thresholds.fall_cog_error:.1f} cm)")
    notes += paper_q_notes(robot, controller, params)
    notes += limit_notes(metrics)
    result = ScenarioResult("squat", robot.name, controller, success, metrics, params, notes,
                            log=sim.log)
    if out_dir is not None:
        joint = metrics["max_deviation_joint"]
        result.figures = [str(squat_figure(
            Path(out_dir) / "squat.png", monitor, vel, joint, robot.joint_names.index(joint),
            bounds[0, 0], title=f"squat {params['variant']} {f} Hz — {robot.name}, {controller} "
                                f"momentum gains"))]
    return result


SCENARIO = Scenario(
    name="squat",
    summary="Sect. 5.3 / Fig. 10: CoG sine tracking (2 cm forward, 3 cm vertical, 0.3/0.5 Hz) in "
            "double support, optionally with active CoP constraints; success = feet never tilt, "
            "CoG error bounded",
    parameters=PARAMETERS,
    controllers=("lqr", "pd"),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
    simulations=1,
)
