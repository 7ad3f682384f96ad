"""Measures shared by the humanoid scenarios, each defined once: foot tilt and slip, CoG recovery
after a push, falls, the CoP of a sole, the survival thresholds, and the per-cycle monitor of the
balance scenarios (Herzog et al. 2016 Sects. 5.2-5.4).

All are computed from the simulator (its state, sole poses and contact wrenches), not from the
controller's model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import pinocchio as pin

from ..robots import reference

#: the feet stay flat: tilt below MAX_TILT_DEG (an angle, the same on every robot); a push is
#: recovered when the CoG is back within :class:`Thresholds`' ``cog_tolerance`` of its reference
#: within RECOVERY_WINDOW_S after it
MAX_TILT_DEG = 2.0
RECOVERY_WINDOW_S = 3.0
#: a recovery counts only if the CoG error was last above its tolerance this long before the
#: record ends (s)
RECORD_TAIL_S = 0.2

#: a fall (stand): the base tilts by more than FALL_BASE_TILT_DEG or sinks below
#: FALL_HEIGHT_FRACTION of its standing height
FALL_BASE_TILT_DEG = 30.0
FALL_HEIGHT_FRACTION = 0.5

COP_MIN_FORCE = 50.0  # N: a CoP (predicted or measured) is counted only while the sole carries this
COP_ACTIVE_TOL = 5e-4  # m: a predicted CoP this close to its bound counts as an active constraint
COP_SKIP = 0.2  # s: landing transient at the start, left out of the CoP statistics


@dataclass(frozen=True)
class Thresholds:
    """The humanoid scenarios' survival and fall thresholds for one robot. The defaults are
    talos14's, on which the set-ups of Herzog et al. 2016 Sects. 5.1-5.4 were made;
    :meth:`for_robot` keeps their proportions: lengths times h / h_talos14 (h the standing base
    height), linear momenta times m sqrt(h) and angular momenta times m h^1.5 over talos14's (a
    robot of the same shape moving as fast in proportion, v ~ sqrt(g h)).

    ``max_slip``: a sole's horizontal displacement for the feet to count as in place (m);
    ``cog_tolerance``: the CoG back within this of its reference (a push recovered, a run ended
    in balance; m); ``fall_cog_error``: a CoG error that counts as a fall (m); ``max_base_drop``:
    stepping's base drop that counts as a fall (m); ``step_cog_error``: stepping's CoG back over
    the soles' midpoint within this at the end (m); ``final_linear_momentum``,
    ``final_angular_momentum``: the momenta damped at the end of a balance run (N s, N m s)."""

    max_slip: float = 0.01
    cog_tolerance: float = 5e-3
    fall_cog_error: float = 0.1
    max_base_drop: float = 0.1
    step_cog_error: float = 0.02
    final_linear_momentum: float = 1.0
    final_angular_momentum: float = 1.0

    @classmethod
    def for_robot(cls, robot) -> Thresholds:
        """talos14's thresholds in the proportions of ``robot`` (exactly the defaults on
        talos14)."""
        length = reference.humanoid_length_ratio(robot)
        mass = reference.humanoid_mass_ratio(robot)
        scale = {"final_linear_momentum": mass * length ** 0.5,
                 "final_angular_momentum": mass * length ** 1.5}
        talos14 = cls()
        return cls(**{f.name: getattr(talos14, f.name) * scale.get(f.name, length)
                      for f in fields(cls)})

    def feet_in_place(self, max_tilt: float, max_slip: float) -> bool:
        """The feet stayed flat (tilt below MAX_TILT_DEG) and in place (slip below
        ``max_slip``)."""
        return bool(max_tilt < MAX_TILT_DEG and max_slip < self.max_slip)

    def push_criteria(self) -> str:
        """What a push must meet on this robot, in words (a run's note)."""
        return (f"survived = feet tilt < {MAX_TILT_DEG:g} deg and slip < "
                f"{1e3 * self.max_slip:.1f} mm, CoG back within {1e3 * self.cog_tolerance:.1f} mm "
                f"of its reference within {RECOVERY_WINDOW_S:g} s (talos14's 10 / 5 mm in "
                f"proportion to the standing height)")

    def cog_recovered(self, t: np.ndarray, err: np.ndarray, end: float,
                      window: float = RECOVERY_WINDOW_S) -> tuple[bool, float]:
        """(recovered, recovery time) of a push ending at ``end``: the CoG error was last above
        ``cog_tolerance`` before ``end + window`` and at least RECORD_TAIL_S before the end of
        the record."""
        recovery, last = cog_recovery(t, err, end, None, self.cog_tolerance)
        return bool(last is None or last < min(end + window, t[-1] - RECORD_TAIL_S)), recovery


class TwinCentroidal:
    """The twin's CoM, its velocity and centroidal momentum [linear; angular] at a simulator state
    (q, v), through the robot's model on a Pinocchio Data of its own: the robot's own cycle is
    left as the controller made it (under real-robot conditions, at the estimate the controller
    read; the measures are the twin's). :meth:`at` returns arrays of its own (copies)."""

    def __init__(self, robot):
        self.model, self.data = robot.model, robot.model.createData()

    def at(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(com, vcom, h_G) at (q, v)."""
        data = self.data
        pin.computeCentroidalMomentum(self.model, data, q, v)
        return data.com[0].copy(), data.vcom[0].copy(), data.hg.vector.copy()


class TwinGait:
    """What a gait run measures of the twin every cycle — the base rotation, the CoM, the legs'
    foot-frame positions and the horizontal speeds of their contact points — at a simulator state
    (q, v), by one forward-kinematics pass on a Pinocchio Data of its own: none of the dynamics
    terms of ``Robot.update``, and the robot's own cycle left as the controller made it. The
    rotation, CoM and feet are Robot.update's numbers bit for bit; a contact point's velocity is
    its frame's (Pinocchio's recursive velocities) plus ω × d for a sphere's material point
    d = (0, 0, -r) below the centre, what ``J_p v`` gives up to round-off."""

    def __init__(self, robot, legs):
        self.model, self.data = robot.model, robot.model.createData()
        contacts = [robot.contact(n) for n in legs]
        self._frames = [c.frame_id for c in contacts]
        self._radii = [float(c.spec.radius) if c.dim == 3 else 0.0 for c in contacts]

    def at(self, q: np.ndarray, v: np.ndarray):
        """(base rotation, com, [foot-frame position], [horizontal contact-point speed]); the
        arrays are the Data's (read them before the next call)."""
        model, data, LWA = self.model, self.data, pin.LOCAL_WORLD_ALIGNED
        pin.forwardKinematics(model, data, q, v)
        pin.updateFramePlacements(model, data)
        com = pin.centerOfMass(model, data, pin.KinematicLevel.POSITION, False)
        placements, feet, speeds = data.oMf, [], []
        for frame, r in zip(self._frames, self._radii):
            feet.append(placements[frame].translation)
            motion = pin.getFrameVelocity(model, data, frame, LWA)
            (vx, vy, _), (wx, wy, _) = motion.linear.tolist(), motion.angular.tolist()
            x, y = vx - r * wy, vy + r * wx  # the material point: v + ω × (0, 0, -r)
            speeds.append(math.sqrt(x * x + y * y))
        return data.oMi[1].rotation, com, feet, speeds


def update_to_state(robot, q: np.ndarray, v: np.ndarray) -> None:
    """``robot.update(q, v)`` unless the robot's cycle is of that state already (the controller
    read it): the measures read the twin's state. The same bytes are the same state; other
    numbers equal in value (+0.0 and -0.0) count as the same too, as ``np.array_equal`` says."""
    if ((robot.q.tobytes() == q.tobytes() and robot.v.tobytes() == v.tobytes())
            or (np.array_equal(robot.q, q) and np.array_equal(robot.v, v))):
        return
    robot.update(q, v)


def tilt_deg(rotation: np.ndarray) -> float:
    """Angle (deg) between the z axis of ``rotation`` and the world's (or the support's, for a
    rotation relative to it). Measured every cycle: Python's min/max clip one number (np.clip's
    own cost is many times the arithmetic's), the same value."""
    return np.degrees(np.arccos(min(max(rotation[2, 2], -1.0), 1.0)))


def _norm(x: np.ndarray) -> float:
    """np.linalg.norm of a float vector, as it computes it (sqrt(x . x)), without its dispatch."""
    return math.sqrt(x.dot(x))


def rotation_angle_deg(quat: np.ndarray, quat_ref: np.ndarray) -> float:
    """Angle (deg) of the rotation between two unit quaternions (any component order, the same for
    both): 2 arccos |<q, q_ref>|."""
    quat, quat_ref = np.asarray(quat, dtype=float), np.asarray(quat_ref, dtype=float)
    dot = abs(float(quat.dot(quat_ref))) / (_norm(quat) * _norm(quat_ref))
    return float(np.degrees(2.0 * np.arccos(min(dot, 1.0))))


def sole_slip(position: np.ndarray, start: np.ndarray) -> float:
    """Horizontal displacement of a sole frame origin from its start (m)."""
    return _norm(np.asarray(position - start, dtype=float)[:2])


def cog_recovery(t: np.ndarray, err: np.ndarray, end: float, window: np.ndarray | None,
                 tolerance: float) -> tuple[float, float | None]:
    """(recovery time after ``end``, time of the last sample with the CoG error ``err`` above
    ``tolerance``, or None if there is none) over the samples from ``end`` on (and in ``window``)."""
    after = t >= end
    if window is not None:
        after = after & window
    outside = np.flatnonzero(after & (err > tolerance))
    if outside.size == 0:
        return 0.0, None
    return float(t[outside[-1]] - end), t[outside[-1]]


def fallen(base_tilt_deg: float, base_height: float, standing_height: float) -> bool:
    """The base tilted by more than FALL_BASE_TILT_DEG or sank below FALL_HEIGHT_FRACTION of its
    standing height."""
    return bool(base_tilt_deg > FALL_BASE_TILT_DEG
                or base_height < FALL_HEIGHT_FRACTION * standing_height)


def cop_in_sole(wrench: np.ndarray, rotation: np.ndarray,
                min_force: float = 1e-9) -> tuple[np.ndarray, float]:
    """(CoP (x, y) in the sole's axes about its origin, normal force) of a world-axes wrench [f;
    moment about the sole origin]; the CoP is nan while the normal force is at most ``min_force``."""
    f = rotation.T @ wrench[:3]
    tau = rotation.T @ wrench[3:]
    if f[2] <= min_force:
        return np.full(2, np.nan), float(f[2])
    return np.array([-tau[1] / f[2], tau[0] / f[2]]), float(f[2])


def sole_midpoint(robot) -> np.ndarray:
    """Midpoint of the contact frames at the reference posture (resting on z = 0)."""
    robot.update(robot.q_ref, np.zeros(robot.nv))
    return np.mean([robot.frame_placement(robot.contact(n).frame)[0]
                    for n in robot.contact_names], axis=0)


def limit_notes(metrics: dict) -> list[str]:
    """A note when a joint reached its position limit (the twin's limits are hard stops)."""
    if metrics["min_joint_limit_margin_rad"] < 0.01:
        return [f"{metrics['closest_to_limit_joint']} reached its position limit (margin "
                f"{metrics['min_joint_limit_margin_rad']:.3f} rad); the controller has no "
                f"joint-position limit task"]
    return []


class BalanceMonitor:
    """Per-cycle measurements of a balance run on a (possibly moving) support (definitions: the
    docstring of :mod:`wholebody.scenarios.platform`).

    Called as ``on_result(t, solution)`` by :func:`run_closed_loop`, i.e. before the step that
    applies the solution; the simulator's contact wrenches are those of the step that just ended.
    A predicted CoP counts as at its bound within the controller's ``cop_margin``.
    """

    def __init__(self, robot, sim, ctrl):
        self.robot, self.sim, self.ctrl = robot, sim, ctrl
        self.thresholds = Thresholds.for_robot(robot)
        self.names = robot.contact_names
        self.half = {n: np.asarray(robot.contact(n).spec.half_size, dtype=float)
                     for n in self.names}
        self.bound = {n: (1.0 - ctrl.cop_margin) * self.half[n] for n in self.names}
        p_s, R_s = sim.support_pose()
        poses = sim.contact_frame_poses()
        self.start = {n: R_s.T @ (poses[n][0] - p_s) for n in self.names}
        self.rows: dict[str, list] = {k: [] for k in (
            "t", "com", "com_ref", "cog_error", "dh", "tilt", "slip", "cop_pred", "cop_meas",
            "fz_meas", "active", "support_p", "support_R", "joints", "qdd")}
        self.twin = TwinCentroidal(robot)
        #: the twin's (com, vcom, h_G) of the last call
        self.last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def __call__(self, t: float, sol) -> None:
        robot, sim, r = self.robot, self.sim, self.rows
        q, v = sim.state()
        com, vcom, h_G = self.last = self.twin.at(q, v)
        p_s, R_s = sim.support_pose()
        poses = sim.contact_frame_poses()
        wrenches = sim.contact_wrenches()
        tilt, slip, pred, meas, fz, active = [], [], [], [], [], False
        for n in self.names:
            p, R = poses[n]
            tilt.append(tilt_deg(R_s.T @ R))
            slip.append(sole_slip(R_s.T @ (p - p_s), self.start[n]))
            cp, fp = cop_in_sole(np.asarray(sol.forces[n]), R) if n in sol.forces else (
                np.full(2, np.nan), 0.0)
            cm, f = cop_in_sole(wrenches[n], R)
            pred.append(cp if fp > COP_MIN_FORCE else np.full(2, np.nan))
            meas.append(cm if f > COP_MIN_FORCE else np.full(2, np.nan))
            fz.append(f)
            if np.all(np.isfinite(cp)) and np.any(np.abs(cp) >= self.bound[n] - COP_ACTIVE_TOL):
                active = True
        r["t"].append(t)
        r["com"].append(com)
        r["com_ref"].append(self.ctrl.com_ref.copy())
        r["cog_error"].append(com - self.ctrl.com_ref)
        r["dh"].append(h_G - self.ctrl.h_ref)
        r["tilt"].append(tilt)
        r["slip"].append(slip)
        r["cop_pred"].append(pred)
        r["cop_meas"].append(meas)
        r["fz_meas"].append(fz)
        r["active"].append(active)
        r["support_p"].append(p_s)
        r["support_R"].append(R_s)
        r["joints"].append(robot.joint_error(robot.q_ref, q))
        r["qdd"].append(np.asarray(sol.qdd)[6:])

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.rows.items()}

    def joint_limit_margin(self, deviations: np.ndarray, name: bool = False):
        """Smallest distance of any joint to its position limits over the run (rad), or with
        ``name`` the joint where it occurs."""
        robot = self.robot
        q = deviations + robot.joint_angles(robot.q_ref)
        lo, hi = robot.q_min, robot.q_max
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
        """No failed cycle, the feet flat and in place, the CoG error below ``max_cog_error``
        and the run ended in balance (:meth:`balanced_at_end`)."""
        th = self.thresholds
        return bool(failures == 0
                    and th.feet_in_place(metrics["max_foot_tilt_deg"], metrics["max_foot_slip_m"])
                    and metrics["max_cog_error_m"] < max_cog_error
                    and self.balanced_at_end(metrics))

    def balanced_at_end(self, metrics: dict) -> bool:
        """The CoG back within the thresholds' ``cog_tolerance`` and the momenta damped."""
        th = self.thresholds
        return bool(metrics["final_cog_error_m"] < th.cog_tolerance
                    and metrics["final_linear_momentum_Ns"] < th.final_linear_momentum
                    and metrics["final_angular_momentum_Nms"] < th.final_angular_momentum)
