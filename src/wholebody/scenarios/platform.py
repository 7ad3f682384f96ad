"""``platform``: balancing on a rolling platform moved and rotated quickly (Herzog et al. 2016
Sect. 5.2.3, Fig. 8).

Setup. talos14 stands on a kinematic board (:class:`~wholebody.sim.environment.Platform`) whose
top-centre is under the midpoint of the soles. The board follows a chain of minimum-jerk moves
between waypoints (offset along ``direction``, yaw): 0 -> +d -> (0, +psi) -> -d -> (0, -psi) -> 0,
each lasting ``move_time``, back to back, so the direction changes abruptly (peak acceleration of a
move 5.77 d / T^2). The controller is :class:`~wholebody.control.balance.MomentumBalance` (Table 2,
torques only, LQR or PD momentum gains); it knows nothing of the platform.

CoG reference (our choice, stated in the summary notes). The paper does not say in which frame its
CoG reference lives on the platform; its estimator (Sect. 4.3) fuses leg kinematics assuming the
feet do not move, so the reference was effectively attached to the feet. Here it is attached to the
soles explicitly (:class:`~wholebody.control.balance.SoleFrameReference`): x_ref = midpoint of the
soles + the reference posture's CoG offset rotated by the soles' yaw; h_ref = m x_ref' (and the yaw
rate times the centroidal inertia), both from the measured sole velocities; hdot_ref = 0 unless
``feedforward`` feeds the platform's acceleration (an IMU on the board, which the paper had but did
not use for control). A world-fixed reference cannot work: the board carries the feet 15 cm away.

Metrics (every control cycle, all from the simulator's state, poses and contact forces; measured by
:class:`~wholebody.scenarios.measures.BalanceMonitor`, shared with ``tilt-board`` and ``squat``):

- CoG error e = x_cog - x_ref (world axes; x_cog of the simulated state): ``max_cog_error_m`` (max
  |e|), ``rms_cog_error_m`` (sqrt of the mean |e|^2), ``final_cog_error_m`` (max |e| over the last
  ``window`` s).
- Momentum deviation dh = h_G - h_ref: ``max_linear_momentum_Ns``, ``max_angular_momentum_Nms``
  (max norms), ``final_linear_momentum_Ns``, ``final_angular_momentum_Nms`` (max over the last
  ``window`` s; "damped" = below 1 N s and 1 N m s).
- ``max_foot_tilt_deg``: angle between each sole's normal and the support surface's normal
  (simulator frames), max over soles and time. ``max_foot_slip_m``: horizontal displacement of each
  sole frame origin expressed in the support's frame, relative to its start, max over soles/time.
- CoP of each sole in its own axes, relative to the sole frame origin: predicted = from the QP's
  contact wrench, measured = from the simulator's contact wrench (each counted while its normal
  force exceeds ``COP_MIN_FORCE`` of :mod:`~wholebody.scenarios.measures`). ``cop_rms_error_m`` /
  ``cop_max_error_m``: RMS / max distance between them; ``max_cop_edge_ratio``: max of |cop_x| / h_x and |cop_y| / h_y of the MEASURED CoP
  (1 = on the sole's edge). The CoP statistics skip the first ``COP_SKIP`` s (the robot is placed
  on the support at t = 0 and lands on it within a few ms).
- ``max_joint_deviation_rad`` / ``max_deviation_joint``: largest |q_j - q_ref,j| (the posture);
  ``min_joint_limit_margin_rad`` / ``closest_to_limit_joint``: smallest distance of a joint to its
  position limits, and which joint. ``max_commanded_joint_acceleration_radps2`` /
  ``max_commanded_acceleration_joint``: the largest joint acceleration of the QP solutions.
- ``cop_active_fraction``: fraction of cycles in which a CoP row of the QP solution is at its bound
  (predicted CoP within ``COP_ACTIVE_TOL`` of the admissible rectangle's edge).
- Platform "IMU" (Sect. 4.5): ``peak_platform_acceleration_mps2`` (the board point under the soles)
  and ``peak_platform_angular_velocity_radps``, by finite differences of the simulated board pose.

Success: every cycle solved, feet flat (tilt < 2 deg) and in place on the support (slip < 1 cm),
CoG error bounded (max < ``max_cog_error``), back within 5 mm at the end and momentum damped
(final deviations < 1 N s, 1 N m s).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..control.balance import MomentumBalance, SoleFrameReference
from ..planning.blend import WaypointMotion
from ..report.balance_figures import balance_figure
from ..sim.environment import Environment, Platform
from ..sim.simulator import Simulator
from .base import (COP_MARGIN, ENGINE, INTEGRAL_LIMIT, PD_PARAMETERS, POSTURE_PARAMETERS,
                   Q_ANGULAR, Q_INTEGRAL, TIME_SPAN,
                   Parameter, Scenario, ScenarioResult, check_biped, format_mm, momentum_gains,
                   paper_q_notes, task_gains)
from .loop import run_closed_loop
from .measures import BalanceMonitor, limit_notes, sole_midpoint
from .pushes import HumanoidScaled

PARAMETERS = (
    Parameter("direction", "sagittal", "translation axis of the board: sagittal (robot's x, the "
                                       "paper's Fig. 8 'facing the disturbance') or lateral",
              choices=("sagittal", "lateral")),
    Parameter("distance", 0.15, "translation of each move (m)", low=0.0, high=Parameter.H),
    Parameter("yaw", 15.0, "rotation of the rotating moves (deg)", low=-90.0, high=90.0),
    Parameter("move_time", 1.0, "duration of each minimum-jerk move (s); peak acceleration "
                                "5.77 distance / move_time^2",
              **TIME_SPAN),
    Parameter("moves", 5, "number of moves of the sequence 0, +d, (0, +yaw), -d, (0, -yaw), 0 "
                          "(1-5)", low=1, high=5),
    Parameter("start", 0.5, "time of the first move (s)", low=0.0, high=Parameter.MAX_TIME),
    Parameter("settle", 2.0, "simulated time after the last move (s)",
              low=0.0, high=Parameter.MAX_TIME),
    Parameter("feedforward", False, "feed the board's acceleration (an IMU on it) forward as "
                                    "hdot_ref = m a (not in the paper)"),
    Q_ANGULAR,
    Q_INTEGRAL,
    INTEGRAL_LIMIT,
    *PD_PARAMETERS,
    *POSTURE_PARAMETERS,
    COP_MARGIN,
    Parameter("max_cog_error", HumanoidScaled(0.05, "m", height_power=1),
              "bound on the CoG error counted as 'bounded' (m)",
              low=0.0, low_open=True, high=Parameter.H),
    ENGINE,
)

WAYPOINTS = ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (0.0, 0.0))


def validate(robot, params: dict) -> None:
    check_biped(robot, params)
    if params["direction"] not in ("sagittal", "lateral"):
        raise ValueError(f"--set direction: expected sagittal or lateral, got "
                         f"'{params['direction']}'")
    if not 1 <= params["moves"] <= len(WAYPOINTS) - 1:
        raise ValueError(f"--set moves: expected 1-{len(WAYPOINTS) - 1}, got {params['moves']}")
    if params["move_time"] <= 0:
        raise ValueError("--set move_time: must be > 0")


def platform_motion(params: dict, center_z: float) -> WaypointMotion:
    """Pose coordinates (x, y, z, roll, pitch, yaw) of the board's top-centre over time."""
    d, psi = params["distance"], np.radians(params["yaw"])
    axis = 0 if params["direction"] == "sagittal" else 1
    points = []
    for offset, yaw in WAYPOINTS[:params["moves"] + 1]:
        pose = np.zeros(6)
        pose[axis], pose[5] = offset * d, yaw * psi
        points.append(pose)
    return WaypointMotion(points, params["move_time"], params["start"])


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    mid = sole_midpoint(robot)
    height = 0.1
    motion = platform_motion(params, height)
    env = Environment(platform=Platform(half_size=(0.6, 0.6, 0.02),
                                        center=(mid[0], mid[1], height),
                                        motion=lambda t: (motion(t)[:3], motion(t)[3:])))
    sim = Simulator(robot, env, observers=observers, label=controller)
    support_acc = None
    if params["feedforward"]:
        # acceleration of the board point under the soles (top-centre: translation + yaw about it)
        support_acc = lambda t: np.r_[motion.acceleration(t)[:3]]  # noqa: E731
    reference = SoleFrameReference(robot, support_acceleration=support_acc)
    ctrl = MomentumBalance(robot, gains=controller, reference=reference,
                           **momentum_gains(controller, params), **task_gains(params),
                           cop_margin=params["cop_margin"], engine=params["engine"])
    monitor = BalanceMonitor(robot, sim, ctrl)
    duration = motion.end + params["settle"]
    failures = run_closed_loop(sim, ctrl, duration, progress=progress, on_result=monitor)
    metrics = monitor.metrics()
    metrics["failed_cycles"] = failures
    metrics["commanded_peak_acceleration_mps2"] = 5.77 * params["distance"] / params["move_time"] ** 2
    success = monitor.success(metrics, failures, params["max_cog_error"])
    notes = ["CoG reference attached to the soles (midpoint + yaw), h_ref from the soles' measured "
             "velocity; the contact constraint still assumes stationary feet (eq. 2), as the paper's "
             "controller did"]
    notes += paper_q_notes(robot, controller, params)
    half_sole = min(c.spec.half_size[0] for c in robot.contacts)
    robot.update(robot.q_ref, np.zeros(robot.nv))
    cog_height = robot.com[2]
    notes.append(f"physical limit: keeping the feet flat under a board acceleration a needs the CoP "
                 f"a z_cog / g ahead of the CoG: a <= g h_x / z_cog ~ "
                 f"{9.81 * half_sole / cog_height:.2f} m/s^2 for {robot.name}'s "
                 f"{100 * half_sole:.1f} cm half-sole and {cog_height:.2f} m CoG height (no angular "
                 f"momentum used)")
    m = metrics
    notes.append(f"paper (Fig. 8): CoG error bounded, momentum damped, feet stationary, predicted "
                 f"CoPs approximately correct; measured: max CoG error {100 * m['max_cog_error_m']:.2f}"
                 f" cm (RMS {100 * m['rms_cog_error_m']:.2f}), final momentum deviation "
                 f"{m['final_linear_momentum_Ns']:.2f} N s / {m['final_angular_momentum_Nms']:.2f} "
                 f"N m s, foot slip {1000 * m['max_foot_slip_m']:.1f} mm, tilt "
                 f"{m['max_foot_tilt_deg']:.2f} deg, predicted-vs-measured CoP RMS "
                 f"{format_mm(m['cop_rms_error_m'])} mm at {m['peak_platform_acceleration_mps2']:.2f} m/s^2")
    notes += limit_notes(metrics)
    result = ScenarioResult("platform", robot.name, controller, success, metrics, params, notes,
                            log=sim.log)
    if out_dir is not None:
        shaded = [(motion.start + k * motion.move_time, motion.start + (k + 1) * motion.move_time)
                  for k in range(params["moves"]) if k % 2 == 0]
        result.figures = [str(balance_figure(
            monitor, Path(out_dir) / "platform.png",
            f"rolling platform ({params['direction']}, {params['distance']:.2f} m, "
            f"{params['yaw']:.0f}°, {params['move_time']:.2f} s moves) — {robot.name}, "
            f"{controller} momentum gains", shaded=shaded))]
    return result


SCENARIO = Scenario(
    name="platform",
    summary="Sect. 5.2.3 / Fig. 8: balancing on a rolling platform moved and rotated quickly "
            "(Table 2, no joint PD); success = feet flat and in place on the board, CoG error "
            "bounded and recovered, momentum damped",
    parameters=PARAMETERS,
    controllers=("lqr", "pd"),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
    simulations=1,
)
