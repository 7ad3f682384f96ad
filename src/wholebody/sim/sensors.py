"""What a legged robot's sensors report, made from the twin's true state (simulator side only).

Each control cycle :meth:`Sensors.read` turns the twin's exact state into the readings a real
robot gives its estimator: an IMU on the base (angular rate and specific force in the IMU frame
with white noise and a random-walk bias, orientation as an onboard attitude filter reports it:
roll and pitch accurate, yaw drifting), joint encoders (quantised, noisy), joint velocities by
finite differences of the encoder positions (optionally low-pass filtered) and a binary contact
signal per foot from a normal-force threshold.

The IMU's specific force needs the twin's acceleration. It is taken from MuJoCo's ``data.qacc``
as the last step left it: the acceleration that integrated the previous velocity into the present
one (v_k = v_{k-1} + dt qacc), i.e. exactly the backward difference of the twin's velocity. That is
what an accelerometer sampled now has measured (the torques of the coming step have not acted yet),
it costs no extra MuJoCo call (``mj_rnePostConstraint``/``cacc`` would recompute the body
accelerations for the same answer) and it is consistent with the integrator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import pinocchio as pin

from ..robot import GRAVITY, Robot

_GRAVITY_WORLD = np.array([0.0, 0.0, -GRAVITY])


@dataclass(frozen=True)
class SensorSpec:
    """Noise of the sensors, per sample at the rate they are read (datasheet-like defaults: a
    tactical-grade MEMS IMU read at 1 kHz, 16-bit absolute joint encoders).

    gyro_noise            white noise on each angular-rate axis (rad/s, std per sample)
    gyro_bias             std of each axis's initial gyro bias (rad/s)
    gyro_bias_walk        random walk of the gyro bias (rad/s per sqrt(s))
    accel_noise           white noise on each specific-force axis (m/s^2, std per sample)
    accel_bias            std of each axis's initial accelerometer bias (m/s^2)
    accel_bias_walk       random walk of the accelerometer bias (m/s^2 per sqrt(s))
    attitude_noise        white noise on the attitude filter's roll, pitch and yaw (rad, std)
    yaw_drift_rate        the attitude filter's yaw drift (rad/s, constant)
    encoder_resolution    joint encoder step (rad); 0: not quantised
    encoder_noise         white noise on each joint position (rad, std per sample)
    velocity_cutoff_hz    first-order low-pass on the differenced joint velocities (Hz); 0: none
    contact_force_fraction  a foot is in contact when its contact force exceeds this fraction of
                          the robot's weight
    """

    gyro_noise: float = 3e-3
    gyro_bias: float = 2e-3
    gyro_bias_walk: float = 1e-4
    accel_noise: float = 3e-2
    accel_bias: float = 2e-2
    accel_bias_walk: float = 1e-3
    attitude_noise: float = 2e-3
    yaw_drift_rate: float = 1e-3
    encoder_resolution: float = 2.0 * math.pi / 2 ** 16
    encoder_noise: float = 2e-5
    velocity_cutoff_hz: float = 100.0
    contact_force_fraction: float = 0.05

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"SensorSpec.{f.name} must be a finite number >= 0, got {value!r}")

    @classmethod
    def exact(cls) -> "SensorSpec":
        """Sensors without noise, bias, drift or quantisation (and unfiltered velocities)."""
        return cls(**{f.name: 0.0 for f in fields(cls) if f.name != "contact_force_fraction"})


@dataclass
class SensorReading:
    """One cycle's readings (Pinocchio conventions; quaternion x, y, z, w).

    t                time (s)
    gyro             angular rate of the IMU frame in the IMU frame (rad/s)
    accel            specific force a - g of the IMU frame's origin in the IMU frame (m/s^2)
    orientation      the attitude filter's orientation of the IMU frame (x, y, z, w)
    joint_positions  encoder positions (rad), one per actuated joint
    joint_velocities differenced (and filtered) encoder positions (rad/s)
    contact          per contact of the robot (``robot.contact_names``): True when loaded
    """

    t: float
    gyro: np.ndarray
    accel: np.ndarray
    orientation: np.ndarray
    joint_positions: np.ndarray
    joint_velocities: np.ndarray
    contact: np.ndarray


class Sensors:
    """The sensors of ``robot``'s twin, with an IMU at ``imu_frame`` (default: the base's frame).

    ``rng``: the generator of every noise and bias draw (default ``numpy.random.default_rng(0)``);
    the biases are drawn here, once. Call :meth:`read` (from a :class:`Simulator`) or
    :meth:`measure` (from a true state) once per cycle, in time order."""

    def __init__(self, robot: Robot, spec: SensorSpec | None = None,
                 rng: np.random.Generator | None = None, imu_frame: str | None = None):
        self.robot = robot
        self.spec = spec or SensorSpec()
        if not isinstance(self.spec, SensorSpec):
            raise ValueError(f"spec: expected a SensorSpec, got {type(self.spec).__name__}")
        self.rng = rng if rng is not None else np.random.default_rng(0)
        if not isinstance(self.rng, np.random.Generator):
            raise ValueError(f"rng: expected a numpy.random.Generator, got "
                             f"{type(self.rng).__name__}")
        self.imu_frame = imu_frame or robot.base_frame
        self._imu_id = robot.frame_id(self.imu_frame, "imu_frame")
        self._data = robot.model.createData()
        self.gyro_bias = self.rng.normal(scale=self.spec.gyro_bias, size=3)
        self.accel_bias = self.rng.normal(scale=self.spec.accel_bias, size=3)
        self._contact_threshold = self.spec.contact_force_fraction * robot.mass * GRAVITY
        self._last_t: float | None = None
        self._last_positions = np.zeros(robot.na)
        self._velocities = np.zeros(robot.na)
        self.last_contact = np.zeros(len(robot.contact_names), dtype=bool)

    # ------------------------------------------------------------------ from the twin
    def read(self, sim) -> SensorReading:
        """The readings at the simulator's present state (see the module docstring for the
        acceleration; before the first step after a reset the robot is taken at rest)."""
        q, v = sim.state()
        a = np.zeros(self.robot.nv)
        if sim.t > 0.5 * sim.dt:
            a[:] = sim.acceleration()
            # MuJoCo's free-joint linear acceleration is d/dt of the world velocity; Pinocchio's
            # is d/dt of the local one: R^T a_world - omega x v_local
            rotation = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
            a[:3] = rotation.T @ a[:3] - np.cross(v[3:6], v[:3])
        forces = np.linalg.norm(sim.contact_wrenches_array()[:, :3], axis=1)
        return self.measure(sim.t, q, v, a, forces)

    # ------------------------------------------------------------------ from a true state
    def measure(self, t: float, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                contact_forces: np.ndarray) -> SensorReading:
        """The readings for the true state ``q, v``, acceleration ``a`` (Pinocchio convention, nv)
        and the magnitude of each contact's force (N) at time ``t``."""
        spec, rng, robot = self.spec, self.rng, self.robot
        dt = 0.0 if self._last_t is None else t - self._last_t
        if dt > 0.0:  # the biases walk
            self.gyro_bias = self.gyro_bias + rng.normal(scale=spec.gyro_bias_walk * math.sqrt(dt),
                                                         size=3)
            self.accel_bias = self.accel_bias + rng.normal(
                scale=spec.accel_bias_walk * math.sqrt(dt), size=3)
        model, data = robot.model, self._data
        pin.forwardKinematics(model, data, q, v, a)
        placement = pin.updateFramePlacement(model, data, self._imu_id)
        rotation = placement.rotation
        omega = pin.getFrameVelocity(model, data, self._imu_id, pin.LOCAL).angular
        acc = pin.getFrameClassicalAcceleration(model, data, self._imu_id, pin.LOCAL).linear
        gyro = omega + self.gyro_bias + rng.normal(scale=spec.gyro_noise, size=3)
        accel = acc - rotation.T @ _GRAVITY_WORLD + self.accel_bias + rng.normal(
            scale=spec.accel_noise, size=3)
        error = rng.normal(scale=spec.attitude_noise, size=3)
        error[2] += spec.yaw_drift_rate * t
        attitude = pin.Quaternion(pin.exp3(error) @ rotation)  # error about the world axes
        attitude.normalize()

        joints = self.robot.joint_angles(q)
        if spec.encoder_noise:
            joints += rng.normal(scale=spec.encoder_noise, size=robot.na)
        if spec.encoder_resolution:
            joints = np.round(joints / spec.encoder_resolution) * spec.encoder_resolution
        if dt > 0.0:
            raw = (joints - self._last_positions) / dt
            if spec.velocity_cutoff_hz:
                alpha = 1.0 - math.exp(-2.0 * math.pi * spec.velocity_cutoff_hz * dt)
                self._velocities = self._velocities + alpha * (raw - self._velocities)
            else:
                self._velocities = raw
        self._last_t, self._last_positions = t, joints
        contact = np.asarray(contact_forces, dtype=float) > self._contact_threshold
        self.last_contact = contact
        return SensorReading(t=float(t), gyro=gyro, accel=accel, orientation=attitude.coeffs().copy(),
                             joint_positions=joints, joint_velocities=self._velocities.copy(),
                             contact=contact)
