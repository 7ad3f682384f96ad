"""``platform``: balancing on a rolling platform moved and rotated quickly (Herzog et al. 2016
Sect. 5.2.3, Fig. 8), plus the measurements shared by ``tilt-board`` and ``squat``.

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

Metrics (every control cycle, all from the simulator's state, poses and contact forces):

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
  force exceeds ``COP_MIN_FORCE``). ``cop_rms_error_m`` / ``cop_max_error_m``: RMS / max distance
  between them; ``max_cop_edge_ratio``: max of |cop_x| / h_x and |cop_y| / h_y of the MEASURED CoP
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
from ..report.plots import time_series_figure
from ..sim.environment import Environment, Platform
from ..sim.simulator import Simulator
from .base import ENGINE, Parameter, Scenario, ScenarioResult, check_engine
from .loop import run_closed_loop

COP_MIN_FORCE = 50.0  # N: a CoP (predicted or measured) is counted only while the sole carries this
COP_ACTIVE_TOL = 5e-4  # m: a predicted CoP this close to its bound counts as an active constraint
COP_SKIP = 0.2  # s: landing transient at the start, left out of the CoP statistics
TILT_LIMIT_DEG, SLIP_LIMIT_M = 2.0, 0.01
FINAL_COG_LIMIT_M, FINAL_LIN_MOM, FINAL_ANG_MOM = 5e-3, 1.0, 1.0


# ------------------------------------------------------------------------- shared helpers
def _mm(value) -> str:
    return "n/a" if value is None else f"{1000 * value:.1f}"


def limit_notes(metrics: dict) -> list[str]:
    """A note when a joint reached its position limit (the twin's limits are hard stops)."""
    if metrics["min_joint_limit_margin_rad"] < 0.01:
        return [f"{metrics['closest_to_limit_joint']} reached its position limit (margin "
                f"{metrics['min_joint_limit_margin_rad']:.3f} rad); the controller has no "
                f"joint-position limit task"]
    return []


def min_jerk(s: float) -> tuple[float, float, float]:
    """Minimum-jerk profile 10 s^3 - 15 s^4 + 6 s^5 on [0, 1] and its 1st/2nd derivatives in s."""
    if s <= 0.0:
        return 0.0, 0.0, 0.0
    if s >= 1.0:
        return 1.0, 0.0, 0.0
    return (s ** 3 * (10 - 15 * s + 6 * s ** 2), 30 * s ** 2 * (1 - s) ** 2,
            60 * s * (1 - s) * (1 - 2 * s))


class WaypointMotion:
    """Back-to-back minimum-jerk moves between waypoints of a coordinate vector, from ``start``.

    ``__call__(t)`` gives the vector, ``rate(t)`` and ``acceleration(t)`` its derivatives.
    """

    def __init__(self, waypoints, move_time: float, start: float):
        self.waypoints = np.asarray(waypoints, dtype=float)
        self.move_time, self.start = float(move_time), float(start)

    @property
    def end(self) -> float:
        return self.start + self.move_time * (len(self.waypoints) - 1)

    def _terms(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w, T = self.waypoints, self.move_time
        k = int(np.clip(np.floor((t - self.start) / T), 0, len(w) - 2))
        s = (t - self.start - k * T) / T
        p, dp, ddp = min_jerk(s)
        delta = w[k + 1] - w[k]
        return w[k] + p * delta, dp / T * delta, ddp / T ** 2 * delta

    def __call__(self, t: float) -> np.ndarray:
        return self._terms(t)[0]

    def rate(self, t: float) -> np.ndarray:
        return self._terms(t)[1]

    def acceleration(self, t: float) -> np.ndarray:
        return self._terms(t)[2]


def sole_midpoint(robot) -> np.ndarray:
    """Midpoint of the contact frames at the reference posture (resting on z = 0)."""
    robot.update(robot.q_ref, np.zeros(robot.nv))
    return np.mean([robot.frame_placement(robot.contact(n).spec.frame)[0]
                    for n in robot.contact_names], axis=0)


def lqr_q(q_angular: float) -> np.ndarray:
    """Eq. 26's Q with the angular-momentum weight replaced by ``q_angular``."""
    return np.diag([30, 30, 50, .5, .5, .5] + [q_angular] * 3)


def cop_in_sole(wrench: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, float]:
    """(CoP (x, y) in the sole's axes about its origin, normal force) of a world-axes wrench."""
    f = rotation.T @ wrench[:3]
    tau = rotation.T @ wrench[3:]
    if f[2] <= 1e-9:
        return np.full(2, np.nan), float(f[2])
    return np.array([-tau[1] / f[2], tau[0] / f[2]]), float(f[2])


class BalanceMonitor:
    """Per-cycle measurements of a balance run (see the module docstring for the definitions).

    Called as ``on_result(t, solution)`` by :func:`run_closed_loop`, i.e. before the step that
    applies the solution; the simulator's contact wrenches are those of the step that just ended.
    """

    def __init__(self, robot, sim: Simulator, ctrl: MomentumBalance, cop_margin: float = 0.0):
        self.robot, self.sim, self.ctrl = robot, sim, ctrl
        self.names = robot.contact_names
        self.half = {n: np.asarray(robot.contact(n).spec.half_size, dtype=float)
                     for n in self.names}
        self.bound = {n: (1.0 - cop_margin) * self.half[n] for n in self.names}
        p_s, R_s = sim.support_pose()
        poses = sim.contact_frame_poses()
        self.start = {n: R_s.T @ (poses[n][0] - p_s) for n in self.names}
        self.rows: dict[str, list] = {k: [] for k in (
            "t", "com", "com_ref", "cog_error", "dh", "tilt", "slip", "cop_pred", "cop_meas",
            "fz_meas", "active", "support_p", "support_R", "joints", "qdd")}

    def __call__(self, t: float, sol) -> None:
        robot, sim, r = self.robot, self.sim, self.rows
        p_s, R_s = sim.support_pose()
        poses = sim.contact_frame_poses()
        wrenches = sim.contact_wrenches()
        tilt, slip, pred, meas, fz, active = [], [], [], [], [], False
        for n in self.names:
            p, R = poses[n]
            tilt.append(np.degrees(np.arccos(np.clip((R_s.T @ R)[2, 2], -1.0, 1.0))))
            slip.append(np.linalg.norm((R_s.T @ (p - p_s) - self.start[n])[:2]))
            cp, fp = cop_in_sole(np.asarray(sol.forces[n]), R) if n in sol.forces else (
                np.full(2, np.nan), 0.0)
            cm, f = cop_in_sole(wrenches[n], R)
            pred.append(cp if fp > COP_MIN_FORCE else np.full(2, np.nan))
            meas.append(cm if f > COP_MIN_FORCE else np.full(2, np.nan))
            fz.append(f)
            if np.all(np.isfinite(cp)) and np.any(np.abs(cp) >= self.bound[n] - COP_ACTIVE_TOL):
                active = True
        r["t"].append(t)
        r["com"].append(robot.com.copy())
        r["com_ref"].append(self.ctrl.com_ref.copy())
        r["cog_error"].append(robot.com - self.ctrl.com_ref)
        r["dh"].append(robot.h_G - self.ctrl.h_ref)
        r["tilt"].append(tilt)
        r["slip"].append(slip)
        r["cop_pred"].append(pred)
        r["cop_meas"].append(meas)
        r["fz_meas"].append(fz)
        r["active"].append(active)
        r["support_p"].append(p_s)
        r["support_R"].append(R_s)
        r["joints"].append(robot.q[7:] - robot.q_ref[7:])
        r["qdd"].append(np.asarray(sol.qdd)[6:])

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.rows.items()}

    def joint_limit_margin(self, deviations: np.ndarray, name: bool = False):
        """Smallest distance of any joint to its position limits over the run (rad), or with
        ``name`` the joint where it occurs."""
        model = self.robot.model
        q = deviations + self.robot.q_ref[7:]
        lo, hi = model.lowerPositionLimit[7:], model.upperPositionLimit[7:]
        margin = np.minimum(q - lo, hi - q).min(axis=0)
        return self.robot.joint_names[int(margin.argmin())] if name else float(margin.min())

    def support_imu(self, point_offset=None) -> tuple[np.ndarray, np.ndarray]:
        """(linear acceleration of a point fixed to the support, angular velocity), world axes, by
        finite differences of the logged support pose; ``point_offset`` in the support's frame
        (default: the soles' midpoint at the start)."""
        a = self.arrays()
        t, p, R = a["t"], a["support_p"], a["support_R"]
        if point_offset is None:
            point_offset = np.mean([self.start[n] for n in self.names], axis=0)
        x = p + np.einsum("kij,j->ki", R, point_offset)
        acc = np.gradient(np.gradient(x, t, axis=0), t, axis=0)
        dR = np.gradient(R, t, axis=0)
        W = np.einsum("kij,kjl->kil", dR, np.transpose(R, (0, 2, 1)))  # R' R^T = [w]x
        omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        return acc, omega

    def metrics(self, window: float = 0.5) -> dict[str, float]:
        a = self.arrays()
        t = a["t"]
        late = t >= t[-1] - window
        err = np.linalg.norm(a["cog_error"], axis=1)
        lin = np.linalg.norm(a["dh"][:, :3], axis=1)
        ang = np.linalg.norm(a["dh"][:, 3:], axis=1)
        settled = t >= t[0] + COP_SKIP
        diff = np.linalg.norm(a["cop_pred"] - a["cop_meas"], axis=2)[settled]  # nan: unloaded
        diff = diff[np.isfinite(diff)]
        ratio = (np.abs(a["cop_meas"]) / np.array([self.half[n] for n in self.names]))[settled]
        acc, omega = self.support_imu()
        return {
            "max_cog_error_m": float(err.max()),
            "rms_cog_error_m": float(np.sqrt(np.mean(err ** 2))),
            "final_cog_error_m": float(err[late].max()),
            "max_linear_momentum_Ns": float(lin.max()),
            "max_angular_momentum_Nms": float(ang.max()),
            "final_linear_momentum_Ns": float(lin[late].max()),
            "final_angular_momentum_Nms": float(ang[late].max()),
            "max_foot_tilt_deg": float(a["tilt"].max()),
            "max_foot_slip_m": float(a["slip"].max()),
            "cop_rms_error_m": float(np.sqrt(np.mean(diff ** 2))) if diff.size else None,
            "cop_max_error_m": float(diff.max()) if diff.size else None,
            "max_cop_edge_ratio": float(np.nanmax(ratio)) if np.isfinite(ratio).any() else None,
            "cop_active_fraction": float(np.mean(a["active"][settled])),
            "max_joint_deviation_rad": float(np.abs(a["joints"]).max()),
            "max_deviation_joint": self.robot.joint_names[int(np.abs(a["joints"]).max(axis=0)
                                                              .argmax())],
            "min_joint_limit_margin_rad": self.joint_limit_margin(a["joints"]),
            "closest_to_limit_joint": self.joint_limit_margin(a["joints"], name=True),
            "max_commanded_joint_acceleration_radps2": float(np.abs(a["qdd"]).max()),
            "max_commanded_acceleration_joint": self.robot.joint_names[
                int(np.abs(a["qdd"]).max(axis=0).argmax())],
            "peak_platform_acceleration_mps2": float(np.linalg.norm(acc, axis=1).max()),
            "peak_platform_angular_velocity_radps": float(np.linalg.norm(omega, axis=1).max()),
        }

    def success(self, metrics: dict, failures: int, max_cog_error: float) -> bool:
        return bool(failures == 0 and metrics["max_foot_tilt_deg"] < TILT_LIMIT_DEG
                    and metrics["max_foot_slip_m"] < SLIP_LIMIT_M
                    and metrics["max_cog_error_m"] < max_cog_error
                    and metrics["final_cog_error_m"] < FINAL_COG_LIMIT_M
                    and metrics["final_linear_momentum_Ns"] < FINAL_LIN_MOM
                    and metrics["final_angular_momentum_Nms"] < FINAL_ANG_MOM)

    def figure(self, path: Path, title: str, imu: bool = True, shaded=(), extra=()) -> Path:
        """Figs. 8-10 style: CoG error, momentum, (platform IMU), predicted vs measured CoPs."""
        a = self.arrays()
        t = a["t"]
        panels = [("CoG error", "cm", {c: 100 * a["cog_error"][:, i] for i, c in enumerate("xyz")}),
                  ("linear momentum - reference", "N s",
                   {c: a["dh"][:, i] for i, c in enumerate("xyz")}),
                  ("angular momentum - reference", "N m s",
                   {c: a["dh"][:, 3 + i] for i, c in enumerate("xyz")})]
        panels += list(extra)
        if imu:
            acc, omega = self.support_imu()
            panels += [("platform angular velocity", "rad/s",
                        {c: omega[:, i] for i, c in enumerate("xyz")}),
                       ("platform linear acceleration (under the soles)", "m/s²",
                        {c: acc[:, i] for i, c in enumerate("xyz")})]
        for axis, c in enumerate("xy"):
            series = {}
            for j, n in enumerate(self.names):
                short = n.split("_")[0][0].upper()
                series[f"{short} predicted"] = 100 * a["cop_pred"][:, j, axis]
                series[f"{short} measured"] = 100 * a["cop_meas"][:, j, axis]
            panels.append((f"CoP {c} in the sole (bound ±{100 * self.bound[n][axis]:.1f} cm)",
                           "cm", series))
        return time_series_figure(path, t, panels, title=title, shaded=shaded)


# ------------------------------------------------------------------------- the scenario
PARAMETERS = (
    Parameter("direction", "sagittal", "translation axis of the board: sagittal (robot's x, the "
                                       "paper's Fig. 8 'facing the disturbance') or lateral"),
    Parameter("distance", 0.15, "translation of each move (m)"),
    Parameter("yaw", 15.0, "rotation of the rotating moves (deg)"),
    Parameter("move_time", 1.0, "duration of each minimum-jerk move (s); peak acceleration "
                                "5.77 distance / move_time^2"),
    Parameter("moves", 5, "number of moves of the sequence 0, +d, (0, +yaw), -d, (0, -yaw), 0 "
                          "(1-5)"),
    Parameter("start", 0.5, "time of the first move (s)"),
    Parameter("settle", 2.0, "simulated time after the last move (s)"),
    Parameter("feedforward", False, "feed the board's acceleration (an IMU on it) forward as "
                                    "hdot_ref = m a (not in the paper)"),
    Parameter("q_angular", 0.1, "LQR weight on angular momentum (eq. 26 uses 0.1)"),
    Parameter("cop_margin", 0.0, "shrink the admissible CoP rectangle by this fraction (0: the "
                                 "whole sole)"),
    Parameter("max_cog_error", 0.05, "bound on the CoG error counted as 'bounded' (m)"),
    ENGINE,
)

WAYPOINTS = ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (0.0, 0.0))


def validate_biped(robot, params: dict) -> None:
    check_engine(params)
    if len(robot.contact_names) != 2 or any(c.spec.type != "rectangle" for c in robot.contacts):
        raise ValueError(f"robot '{robot.name}': momentum balance on a board needs a biped with "
                         f"two rectangular soles (talos14, talos)")


def validate(robot, params: dict) -> None:
    validate_biped(robot, params)
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


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool) -> ScenarioResult:
    mid = sole_midpoint(robot)
    height = 0.1
    motion = platform_motion(params, height)
    env = Environment(platform=Platform(half_size=(0.6, 0.6, 0.02),
                                        center=(mid[0], mid[1], height),
                                        motion=lambda t: (motion(t)[:3], motion(t)[3:])))
    sim = Simulator(robot, env)
    support_acc = None
    if params["feedforward"]:
        # acceleration of the board point under the soles (top-centre: translation + yaw about it)
        support_acc = lambda t: np.r_[motion.acceleration(t)[:3]]  # noqa: E731
    reference = SoleFrameReference(robot, support_acceleration=support_acc)
    ctrl = MomentumBalance(robot, gains=controller, reference=reference,
                           Q=lqr_q(params["q_angular"]) if controller == "lqr" else None,
                           cop_margin=params["cop_margin"], engine=params["engine"])
    monitor = BalanceMonitor(robot, sim, ctrl, cop_margin=params["cop_margin"])
    duration = motion.end + params["settle"]
    failures = run_closed_loop(sim, ctrl, duration, progress=progress, on_result=monitor)
    metrics = monitor.metrics()
    metrics["failed_cycles"] = failures
    metrics["commanded_peak_acceleration_mps2"] = 5.77 * params["distance"] / params["move_time"] ** 2
    success = monitor.success(metrics, failures, params["max_cog_error"])
    notes = ["CoG reference attached to the soles (midpoint + yaw), h_ref from the soles' measured "
             "velocity; the contact constraint still assumes stationary feet (eq. 2), as the paper's "
             "controller did"]
    if controller == "lqr" and params["q_angular"] == 0.1:
        notes.append("eq. 26's Q (0.1 on angular momentum) leaves talos14's trunk poorly damped; "
                     "compare --set q_angular=10")
    notes.append("physical limit: keeping the feet flat under a board acceleration a needs the CoP "
                 "a z_cog / g ahead of the CoG: a <= g h_x / z_cog ~ 1.2 m/s^2 for talos14's 10.5 cm "
                 "half-sole and ~0.87 m CoG height (no angular momentum used)")
    m = metrics
    notes.append(f"paper (Fig. 8): CoG error bounded, momentum damped, feet stationary, predicted "
                 f"CoPs approximately correct; measured: max CoG error {100 * m['max_cog_error_m']:.2f}"
                 f" cm (RMS {100 * m['rms_cog_error_m']:.2f}), final momentum deviation "
                 f"{m['final_linear_momentum_Ns']:.2f} N s / {m['final_angular_momentum_Nms']:.2f} "
                 f"N m s, foot slip {1000 * m['max_foot_slip_m']:.1f} mm, tilt "
                 f"{m['max_foot_tilt_deg']:.2f} deg, predicted-vs-measured CoP RMS "
                 f"{_mm(m['cop_rms_error_m'])} mm at {m['peak_platform_acceleration_mps2']:.2f} m/s^2")
    notes += limit_notes(metrics)
    result = ScenarioResult("platform", robot.name, controller, success, metrics, params, notes,
                            log=sim.log)
    if out_dir is not None:
        shaded = [(motion.start + k * motion.move_time, motion.start + (k + 1) * motion.move_time)
                  for k in range(params["moves"]) if k % 2 == 0]
        result.figures = [str(monitor.figure(
            Path(out_dir) / "platform.png",
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
)
