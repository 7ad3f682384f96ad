"""A kinematic-inertial extended Kalman filter for a legged robot's floating base (Bloesch et al.
2013, "State estimation for legged robots: consistent fusion of leg kinematics and IMU").

State (Sect. III-A): the IMU's position r and velocity v in the world, its orientation R (IMU ->
world), the position p_i of every point of the feet in the world (a point foot's contact frame,
a sole's heel and toe: two points fix its heading), and the accelerometer
and gyroscope biases b_f, b_w. The IMU drives the prediction (Sect. III-B, eqs. 5-11); the feet's
positions relative to the IMU from forward kinematics of the measured joints are the measurement
(Sect. III-C, eq. 12). A foot in contact stays put up to a small process noise, a swinging foot
gets a large one, so it follows its measurement and is anchored again where it lands (eq. 9).
A sole's two points walk together along the ground in stance (their horizontal walks fully
correlated, their vertical ones independent): the sole may slip and tilt with what it stands on
(a tilting board), it does not turn about the vertical, so in single support its heel and toe
hold the heading.
A ball foot in contact rolls: its centre (the contact frame) moves by omega_foot x (radius z) on
flat ground, which the prediction adds (without it, HyQ's feet rolling forward in stance make the
estimate lag 2-3 % of the distance trotted).
While the readings show the robot at rest (every contact closed, the joints and the
bias-corrected gyro still within their noise over a short window) the gyro reads its bias: a
zero angular-rate update, the standard one of inertial navigation, observes the gyro bias about
the vertical, which the legs' kinematics leave unobserved (Bloesch et al. 2013, observability
analysis) and which otherwise integrates into the heading.

The filter works on the error state [dr, dv, dphi, dp_1 .. dp_n, db_f, db_w] with the orientation
error about the world axes (R = exp(dphi) R_hat), which gives the linearisations below in the
world frame instead of the paper's body-frame form; the models are the same. The measurement
Jacobian is taken in world axes too (the IMU-frame one rotated by the orthogonal blockdiag(R),
which leaves the gain, the correction and the normalised innovations as they are). Each cycle costs
a few dense products: the prediction touches only the rows and columns of r, v and phi, the update
solves with one Cholesky factor and subtracts W W^T (W = P H^T L^-T), the symmetric form of the
Joseph update for the optimal gain.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, fields

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack

from ..cycle import ENGINES, warn_python_fallback
from ..robot import GRAVITY, Robot
from ..robots.reference import length_ratio
from ..sim.sensors import SensorReading, SensorSpec
from .kinematics import LegKinematics

log = logging.getLogger(__name__)

_GRAVITY_WORLD = np.array([0.0, 0.0, -GRAVITY])
_MINUS_ONES3 = -np.ones(3)
_NO_HEIGHTS = np.zeros(0)  # the compiled cycle's ground heights without a ground map
# [x]x's off-diagonal entries (0,1) (0,2) (1,0) (1,2) (2,0) (2,1): sign * x[component]
_SKEW_ROWS, _SKEW_COLUMNS = np.array([0, 0, 1, 1, 2, 2]), np.array([1, 2, 0, 2, 0, 1])
_SKEW_COMPONENT = np.array([2, 1, 2, 0, 1, 0])
_SKEW_SIGN = np.array([-1.0, 1.0, 1.0, -1.0, -1.0, 1.0])


def _skew_at(columns: int, row: int, column: int) -> np.ndarray:
    """Flat indices of a [x]x block's off-diagonal entries at (row, column) of a C-ordered
    matrix with ``columns`` columns."""
    return (row + _SKEW_ROWS) * columns + column + _SKEW_COLUMNS


def _skew(x: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors (numpy.cross costs ten times more on 3-vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


@dataclass(frozen=True)
class EstimatorNoise:
    """The filter's noise model (Bloesch et al. 2013, Sect. III-B and III-C).

    gyro_noise, accel_noise          IMU white noise, std per sample (rad/s, m/s^2)
    gyro_bias_walk, accel_bias_walk  bias random walks (per sqrt(s))
    stance_foot_walk                 random walk of a foot in contact (m per sqrt(s)): slip, rolling
    swing_foot_walk                  random walk of a foot in the air (m per sqrt(s))
    kinematics_noise                 std of a foot's position from the joints (m): encoders, the
                                     kinematic model, the contact point moving on the foot
    initial_position                 std of the initial position (m)
    initial_velocity                 std of the initial velocity (m/s)
    initial_orientation              std of the initial roll, pitch and yaw (rad)
    initial_gyro_bias, initial_accel_bias  std of the initial biases (rad/s, m/s^2)
    ground_noise                     std of a stance foot's height above the known ground (m):
                                     the contact's give, the ground map (with ``ground`` only)
    encoder_noise                    std of a joint position reading (rad): its quantisation
                                     (step / sqrt(12)) and noise; a joint velocity reading at rest
                                     (differenced over dt) then has std sqrt(2) encoder_noise / dt
    rest_update                      the zero angular-rate update (off by default): while the
                                     robot is at rest the gyro reads its bias (gyro - b_w = 0 +
                                     noise); a surer bias lets the filter lean on the gyro
                                     rather than the stance feet, which cost the small
                                     quadrupeds heading over 10 m (docs/results.md)
    rest_window                      time constant (s) of the averages that detect rest, and how
                                     long every contact must have been closed first
    rest_gate                        at rest when the averages of the bias-corrected gyro and of
                                     the joint velocities are within rest_gate standard
                                     deviations of zero (their spread at rest from gyro_noise and
                                     b_w's variance, from encoder_noise): each a chi-square with
                                     as many degrees of freedom as axes, below that number times
                                     rest_gate^2
    rest_rate_noise                  std of the angular rate a robot detected at rest may still
                                     have (rad/s), in the rest update, correlated over
                                     rest_window: what the rest test lets pass, rest_gate times
                                     the spread of the joint velocities' average at 1 kHz (the
                                     base turns as fast as the joints that hold it;
                                     :meth:`for_sensors`)
    """

    gyro_noise: float = 3e-3
    accel_noise: float = 3e-2
    gyro_bias_walk: float = 1e-4
    accel_bias_walk: float = 1e-3
    stance_foot_walk: float = 2e-3
    swing_foot_walk: float = 1.0
    kinematics_noise: float = 2e-3
    initial_position: float = 1e-3
    initial_velocity: float = 1e-2
    initial_orientation: float = 1e-2
    initial_gyro_bias: float = 2e-3
    initial_accel_bias: float = 2e-2
    ground_noise: float = 2e-3
    encoder_noise: float = 3.4e-5
    rest_update: bool = False
    rest_window: float = 0.05
    rest_gate: float = 2.0
    rest_rate_noise: float = 1.4e-3

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type in (bool, "bool"):
                if not isinstance(value, (bool, np.bool_)):
                    raise ValueError(f"EstimatorNoise.{f.name} must be True or False, got "
                                     f"{value!r}")
                continue
            if not (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and math.isfinite(value) and value > 0):
                raise ValueError(f"EstimatorNoise.{f.name} must be a finite number > 0, got "
                                 f"{value!r}")

    @classmethod
    def for_robot(cls, robot: Robot, spec: SensorSpec, **overrides) -> "EstimatorNoise":
        """:meth:`for_sensors`, with the legs' two lengths, ``kinematics_noise`` and
        ``stance_foot_walk``, in proportion to the robot's size
        (:func:`~wholebody.robots.reference.length_ratio`: the defaults on HyQ and talos14, where
        they were set): a robot of go1's size with the defaults weighs its legs too little
        against the gyro, whose bias walk then turns the heading (docs/results.md)."""
        ratio = length_ratio(robot)
        scaled = {name: getattr(cls, name) * ratio
                  for name in ("kinematics_noise", "stance_foot_walk")}
        return cls.for_sensors(spec, **{**scaled, **overrides})

    @classmethod
    def for_sensors(cls, spec: SensorSpec, **overrides) -> "EstimatorNoise":
        """The IMU terms, initial biases and the encoders' noise from a sensor spec (each at
        least a small floor so that the filter stays well posed for exact sensors), the rate
        left at rest from the encoders' (``rest_rate_noise``), the rest from the defaults."""
        floor = 1e-6
        values = dict(gyro_noise=max(spec.gyro_noise, floor),
                      accel_noise=max(spec.accel_noise, floor),
                      gyro_bias_walk=max(spec.gyro_bias_walk, floor),
                      accel_bias_walk=max(spec.accel_bias_walk, floor),
                      initial_gyro_bias=max(spec.gyro_bias, floor),
                      initial_accel_bias=max(spec.accel_bias, floor),
                      initial_orientation=max(spec.attitude_noise, floor) + 1e-3,
                      encoder_noise=max(math.hypot(spec.encoder_resolution / math.sqrt(12.0),
                                                   spec.encoder_noise), floor))
        values.update(overrides)
        defaults = cls()
        window = values.get("rest_window", defaults.rest_window)
        alpha = (1.0 - math.exp(-1e-3 / window)
                 if isinstance(window, (int, float)) and window > 0 else 1.0)
        values.setdefault("rest_rate_noise", values.get("rest_gate", defaults.rest_gate)
                          * values["encoder_noise"] * alpha / 1e-3
                          * math.sqrt(2.0 / (2.0 - alpha)))
        return cls(**values)


@dataclass
class StateEstimate:
    """The filter's output (Pinocchio conventions, see :mod:`wholebody.robot`).

    q, v         configuration (base position, quaternion x y z w, joints) and velocity (base
                 twist in the base frame, joint rates)
    covariance   the error-state covariance [dr, dv, dphi, dp_i..., db_f, db_w] (world axes)
    innovation   (npoint, 3): last measured minus predicted point position in the IMU frame (m)
    foot_test    (npoint,): each point's squared innovation normalised by its covariance (a
                 chi-square with 3 degrees of freedom when the foot behaves as modelled)
    feet         (npoint, 3): the estimated points' positions in the world

    The points are the feet's (:class:`~wholebody.estimation.kinematics.LegKinematics`): one per
    point foot, two per sole (heel, toe); ``KinematicInertialEKF.contact_of`` maps them to the
    robot's contacts.
    at_rest      the readings showed the robot at rest (the zero angular-rate update ran)
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    covariance: np.ndarray
    innovation: np.ndarray
    foot_test: np.ndarray
    feet: np.ndarray
    at_rest: bool = False


class KinematicInertialEKF:
    """Floating-base state of ``robot`` from an IMU at ``imu_frame`` and its joint encoders.

    Call :meth:`reset` with a first :class:`~wholebody.sim.sensors.SensorReading` and the base's
    position (unobservable: the filter keeps it relative to where it starts), then :meth:`update`
    with every following reading. The contacts are the robot description's, in its order; a
    reading's ``contact`` flags which of them are loaded.

    ``ground``: optionally the height of the ground under a point, ``ground(x, y)`` (m; the
    terrain map a legged robot's planner has, Fahmi et al. 2019 Sect. V-G). Each foot in contact
    then also measures its height: on the ground, its frame one radius above it. Without it the
    base height is observed only through the feet's anchors, which each touchdown re-sets where
    the kinematics put them: the height drifts, and a controller that places its swings on the
    ground by the estimate lands them short or deep, which the next anchors take as base motion
    (a trot on the estimate sank 11 cm in 6 s).

    ``engine``: "python" runs the cycle's numerics here (the reference), "native" in the compiled
    ``wholebody._estimator`` (the same numbers, faster; the forward kinematics and the ground
    map's queries stay in Python), "auto" (default) the compiled one where it is built."""

    def __init__(self, robot: Robot, noise: EstimatorNoise | None = None,
                 imu_frame: str | None = None, ground=None, engine: str = "auto"):
        self.robot = robot
        self.ground = ground
        self.noise = noise or EstimatorNoise()
        if not isinstance(self.noise, EstimatorNoise):
            raise ValueError(f"noise: expected an EstimatorNoise, got {type(self.noise).__name__}")
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, got {engine!r}")
        self.kinematics = LegKinematics(robot, imu_frame)
        n_feet = self.kinematics.count  # the feet's points (a sole has two)
        if n_feet == 0:
            raise ValueError(f"robot '{robot.name}': contacts: the estimator needs at least one "
                             f"contact frame (a foot)")
        self.n_points = n_feet
        #: the contact (index in the robot's contacts) of every point
        self.contact_of = self.kinematics.contact_of
        self._n_contacts = len(robot.contacts)
        self.size = 15 + 3 * n_feet
        self._feet = slice(9, 9 + 3 * n_feet)
        self._accel_bias = slice(9 + 3 * n_feet, 12 + 3 * n_feet)
        self._gyro_bias = slice(12 + 3 * n_feet, 15 + 3 * n_feet)
        size, m = self.size, 3 * n_feet
        noise = self.noise
        # the measurement Jacobian in world axes: foot i's rows [-I, 0, [p_i - r]x, .. I ..]
        self._G = np.zeros((m, size))
        for i in range(n_feet):
            self._G[3 * i:3 * i + 3, 0:3] = -np.eye(3)
            self._G[3 * i:3 * i + 3, 9 + 3 * i:12 + 3 * i] = np.eye(3)
        # G's [p_i - r]x entries: where, from which component of (p - r).ravel(), which sign
        self._skew_at = np.concatenate([_skew_at(size, 3 * i, 6) for i in range(n_feet)])
        self._skew_from = np.concatenate([3 * i + _SKEW_COMPONENT for i in range(n_feet)])
        self._skew_sign = np.tile(_SKEW_SIGN, n_feet)
        # the rows of r, v and phi of the transition matrix F (the others are the identity's)
        self._F9 = np.zeros((9, size))
        self._F9[:, 0:9] = np.eye(9)
        # flat indices in F9 of dt I (r from v), [f]x (v from phi), R (v from b_f, phi from b_w)
        ab, gb = 9 + 3 * n_feet, 12 + 3 * n_feet
        block = np.arange(3)[:, None] * size + np.arange(3)  # a 3x3 block's flat offsets
        self._transition_at = np.concatenate((
            [3, size + 4, 2 * size + 5], _skew_at(size, 3, 6),
            (3 * size + ab + block).ravel(), (6 * size + gb + block).ravel()))
        # Q's diagonal = basis @ (dt^4, dt^2, dt, dt * swinging_1 .. dt * swinging_n)
        basis = np.zeros((size, 3 + n_feet))
        basis[0:3, 0] = 0.25 * noise.accel_noise ** 2
        basis[3:6, 1] = noise.accel_noise ** 2
        basis[6:9, 1] = noise.gyro_noise ** 2
        basis[self._feet, 2] = noise.stance_foot_walk ** 2
        basis[self._accel_bias, 2] = noise.accel_bias_walk ** 2
        basis[self._gyro_bias, 2] = noise.gyro_bias_walk ** 2
        for i in range(n_feet):
            basis[9 + 3 * i:12 + 3 * i, 3 + i] = (noise.swing_foot_walk ** 2
                                                  - noise.stance_foot_walk ** 2)
        self._noise_basis = basis
        self._noise_coefficients = np.zeros(3 + n_feet)
        # a sole's heel and toe walk together along the ground in stance (the sole slips, it does
        # not turn about the vertical): their horizontal walks' cross-covariance,
        # stance_foot_walk^2 dt, at these flat indices of P (x and y of each point's partner)
        contact_of = self.contact_of
        #: each point's other point on the same sole, -1 for a point foot
        self.partner = np.array([next((j for j in range(n_feet) if j != i
                                       and contact_of[j] == contact_of[i]), -1)
                                 for i in range(n_feet)])
        self._pair_point = np.flatnonzero(self.partner >= 0)
        self._pair_at = np.array([(9 + 3 * i + k) * size + 9 + 3 * self.partner[i] + k
                                  for i in self._pair_point for k in range(2)], dtype=int)
        # [P G^T ; innovation^T]: the right-hand sides of the triangular solve
        self._right_sides = np.zeros((size + 1, m))
        self._blocks = np.zeros((m, m))
        self._block_mask = np.kron(np.eye(n_feet, dtype=bool), np.ones((3, 3), dtype=bool))
        self._radii = self.kinematics.radii
        self._rolls = bool(np.any(self._radii > 0.0))
        self._kinematics_variance = noise.kinematics_noise ** 2
        imu = self.kinematics.imu_in_base
        self._imu_rotation, self._imu_translation = imu.rotation.copy(), imu.translation.copy()
        self._lever_imu = self._imu_rotation.T @ self._imu_translation  # base -> IMU, IMU axes
        # the base's twist (base frame) from the IMU's velocity and angular velocity (IMU frame):
        # v_base = R_i (v_imu - omega x lever), omega_base = R_i omega
        self._twist_from_imu = np.zeros((6, 6))
        self._twist_from_imu[0:3, 0:3] = self._twist_from_imu[3:6, 3:6] = self._imu_rotation
        self._twist_from_imu[0:3, 3:6] = self._imu_rotation @ _skew(self._lever_imu)
        self.estimate: StateEstimate | None = None
        self._t = 0.0
        self._warned = False
        self.engine = self._resolve_engine(engine)
        self._native = self._build_native() if self.engine == "native" else None
        self._nb: dict[str, np.ndarray] = {}

    # ------------------------------------------------------------------ start
    def reset(self, reading: SensorReading, base_position=(0.0, 0.0, 0.0),
              base_velocity=(0.0, 0.0, 0.0)) -> StateEstimate:
        """Start from ``reading``: the orientation from its attitude filter, the base at
        ``base_position`` (world, m) with linear velocity ``base_velocity`` (base frame, m/s;
        default at rest), the feet where the joints put them."""
        position = np.asarray(base_position, dtype=float)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ValueError(f"base_position: expected 3 finite numbers, got {base_position!r}")
        velocity = np.asarray(base_velocity, dtype=float)
        if velocity.shape != (3,) or not np.all(np.isfinite(velocity)):
            raise ValueError(f"base_velocity: expected 3 finite numbers, got {base_velocity!r}")
        noise = self.noise
        attitude = np.asarray(reading.orientation, dtype=float)
        self.rotation = pin.Quaternion(attitude[3], *attitude[:3]).normalized().toRotationMatrix()
        base_rotation = self.rotation @ self._imu_rotation.T
        self.position = position + base_rotation @ self._imu_translation
        omega_world = self.rotation @ np.asarray(reading.gyro, dtype=float)
        self.velocity = base_rotation @ velocity + _cross(omega_world,
                                                          base_rotation @ self._imu_translation)
        self.accel_bias, self.gyro_bias = np.zeros(3), np.zeros(3)
        measured, _ = self.kinematics.feet_in_imu(reading.joint_positions, reading.gyro,
                                                  reading.joint_velocities)
        self.feet = self.position + measured @ self.rotation.T
        variances = np.concatenate([
            np.full(3, noise.initial_position ** 2), np.full(3, noise.initial_velocity ** 2),
            np.full(3, noise.initial_orientation ** 2),
            np.full(3 * self.n_points, noise.initial_position ** 2 + noise.kinematics_noise ** 2),
            np.full(3, noise.initial_accel_bias ** 2), np.full(3, noise.initial_gyro_bias ** 2)])
        self.P = np.diag(variances)
        self._t = float(reading.t)
        self._omega = np.asarray(reading.gyro, dtype=float).copy()
        self._innovation = np.zeros((self.n_points, 3))
        self._foot_test = np.zeros(self.n_points)
        # the rest test's averages start at this reading at rest, the contacts' closed time at 0
        self._rest_gyro, self._rest_joints = self._omega.copy(), np.zeros(self.robot.na)
        self._closed_for = 0.0
        self._at_rest = False
        if self._native is not None:
            self._bind_native()
        self.estimate = self._output(reading)
        return self.estimate

    # ------------------------------------------------------------------ each cycle
    def update(self, reading: SensorReading) -> StateEstimate:
        """Predict with the IMU up to ``reading.t``, correct with the legs' kinematics; returns the
        new estimate. Never raises: a reading that is not finite or not later than the last one is
        skipped (logged once) and the last estimate returned."""
        if self.estimate is None:
            raise RuntimeError("KinematicInertialEKF.update before reset: call reset(reading, "
                               "base_position) with the first reading")
        dt = float(reading.t) - self._t
        gyro = np.asarray(reading.gyro, dtype=float)
        accel = np.asarray(reading.accel, dtype=float)
        joints = np.asarray(reading.joint_positions, dtype=float)
        joint_velocities = np.asarray(reading.joint_velocities, dtype=float)
        # a sum is finite when every term is (short of overflowing past 1e308)
        if not (dt > 0.0 and math.isfinite(gyro.sum() + accel.sum() + joints.sum()
                                           + joint_velocities.sum())):
            self._warn(f"reading at t = {reading.t!r} skipped (not finite or not after "
                       f"t = {self._t:.6f})")
            return self.estimate
        contact = np.asarray(reading.contact, bool)
        contact = (contact[self.contact_of] if contact.shape == (self._n_contacts,)
                   else np.zeros(self.n_points, bool))
        omega = gyro - self.gyro_bias
        measured, foot_rates = self.kinematics.feet_in_imu(joints, omega, joint_velocities)
        if self._native is not None:
            self._native_cycle(dt, gyro, accel, contact, joint_velocities, measured, foot_rates)
        else:
            self._at_rest = self.noise.rest_update and self._detect_rest(
                gyro, joint_velocities, contact, dt)
            self._predict(omega, accel, contact, foot_rates, dt)
            self._correct(measured)
            if self.ground is not None:
                self._correct_ground(self._ground_heights(contact))
            if self._at_rest:
                self._correct_rest(gyro, dt)
        self._t = float(reading.t)
        self.estimate = self._output(reading, native=self._native is not None)
        return self.estimate

    def _predict(self, omega: np.ndarray, accel: np.ndarray, contact: np.ndarray,
                 foot_rates: np.ndarray, dt: float) -> None:
        """Bloesch et al. 2013, eqs. 5-11: IMU integration (``omega`` the bias-corrected gyro)
        and the error-state covariance; the stance feet roll by their angular velocity
        ``foot_rates`` (IMU frame)."""
        R = self.rotation
        force_world = R @ (accel - self.accel_bias)
        acc = force_world + _GRAVITY_WORLD
        self.position = self.position + dt * self.velocity + 0.5 * dt * dt * acc
        self.velocity = self.velocity + dt * acc
        if self._rolls:  # omega x (radius z) = radius (omega_y, -omega_x, 0), world axes
            rates_world = foot_rates @ R.T
            step = dt * contact * self._radii
            self.feet[:, 0] += step * rates_world[:, 1]
            self.feet[:, 1] -= step * rates_world[:, 0]
        self.rotation = R @ pin.exp3(omega * dt)
        self._omega = omega
        # F's entries that depend on the step: dt I, -dt [f]x, -dt R (twice), in one write
        self._F9.reshape(-1)[self._transition_at] = -dt * np.concatenate(
            (_MINUS_ONES3, _SKEW_SIGN * force_world[_SKEW_COMPONENT], R.reshape(-1),
             R.reshape(-1)))
        # F P F^T: F differs from the identity in its first nine rows only
        P, F9 = self.P, self._F9
        P[0:9] = F9 @ P
        P[:, 0:9] = P @ F9.T
        coefficients = self._noise_coefficients
        coefficients[0:3] = dt ** 4, dt * dt, dt
        np.multiply(~contact, dt, out=coefficients[3:])
        P.reshape(-1)[::self.size + 1] += self._noise_basis @ coefficients
        if self._pair_at.size:
            P.reshape(-1)[self._pair_at] += (dt * self.noise.stance_foot_walk ** 2) * np.repeat(
                contact[self._pair_point], 2)

    def _correct(self, measured: np.ndarray) -> None:
        """Bloesch et al. 2013, eq. 12: the feet relative to the IMU, s_i = R^T (p_i - r)."""
        R, G, P, size = self.rotation, self._G, self.P, self.size
        relative = self.feet - self.position
        innovation = measured @ R.T - relative  # world axes
        G.reshape(-1)[self._skew_at] = self._skew_sign * relative.reshape(-1)[self._skew_from]
        right = self._right_sides
        np.dot(P, G.T, out=right[:size])
        right[size] = innovation.reshape(-1)
        S = G @ right[:size]
        S.reshape(-1)[::S.shape[0] + 1] += self._kinematics_variance
        blocks = self._blocks
        np.copyto(blocks, S, where=self._block_mask)
        factor, info = lapack.dpotrf(S, lower=1)
        if info == 0:
            # L^-1 [P G^T | innovation] = [W^T | u], W = P G^T L^-T
            solved, info = lapack.dtrtrs(factor, right.T, lower=1, overwrite_b=1)
        if info == 0:
            whitened, info = lapack.dposv(blocks, innovation.reshape(-1, 1), lower=1)[1:]
        if info != 0:
            self._warn("kinematic update skipped: singular innovation covariance")
            return
        W = solved.T[:size]
        dx = W @ solved[:, size]
        self._inject(dx)
        P -= W @ W.T  # = (I - KH) P (I - KH)^T + K R_meas K^T for K = P H^T S^-1
        np.add(P, P.T, out=P)  # symmetric to the last bit (numpy buffers the overlap)
        P *= 0.5
        self._innovation = innovation @ R
        self._foot_test = (innovation.reshape(-1) * whitened[:, 0]).reshape(-1, 3).sum(axis=1)

    def _inject(self, dx: np.ndarray) -> None:
        """The error state ``dx`` of a correction added to the nominal state (the orientation's
        part as a rotation, Bloesch et al. 2013)."""
        self.position = self.position + dx[0:3]
        self.velocity = self.velocity + dx[3:6]
        self.rotation = pin.exp3(dx[6:9]) @ self.rotation
        self.feet = self.feet + dx[self._feet].reshape(-1, 3)
        self.accel_bias = self.accel_bias + dx[self._accel_bias]
        self.gyro_bias = self.gyro_bias + dx[self._gyro_bias]

    def _ground_heights(self, contact: np.ndarray) -> np.ndarray:
        """The ground's height under each foot in contact, where the kinematic update put it;
        NaN for the others and over no ground (a gap)."""
        heights = np.full(self.n_points, np.nan)
        for i in np.flatnonzero(contact):
            heights[i] = float(self.ground(float(self.feet[i, 0]), float(self.feet[i, 1])))
        return heights

    def _correct_ground(self, heights: np.ndarray) -> None:
        """Each foot in contact on the known ground: its frame's height is the ground's under it
        (``heights``, NaN: not measured) plus its radius (a sole's: the ground's), one scalar
        update per foot (noise ``ground_noise``)."""
        sigma2 = self.noise.ground_noise ** 2
        for i in np.flatnonzero(np.isfinite(heights)):
            j = 9 + 3 * i + 2  # the foot's z in the error state
            column = self.P[:, j].copy()
            gain = column / (column[j] + sigma2)
            dx = gain * (heights[i] + self._radii[i] - self.feet[i, 2])
            self._inject(dx)
            P = self.P - np.outer(gain, column)
            self.P = 0.5 * (P + P.T)

    def _detect_rest(self, gyro: np.ndarray, joint_velocities: np.ndarray,
                     contact: np.ndarray, dt: float) -> bool:
        """At rest from the readings alone: every contact closed for ``rest_window``, and the
        averages (first order, time constant ``rest_window``) of the gyro less the present bias
        estimate and of the joint velocities within ``rest_gate`` standard deviations of zero
        (their spread at rest: the gyro's white noise averaged plus b_w's variance; the encoders'
        noise differenced and averaged). Joints still with every foot down hold the base still:
        the evidence that the gyro then reads its bias. The raw gyro is averaged, so that the
        test does not lag the bias's estimate. A push or a step moves the averages past the gate
        within a cycle or two."""
        noise = self.noise
        alpha = 1.0 - math.exp(-dt / noise.rest_window)
        self._rest_gyro += alpha * (gyro - self._rest_gyro)
        self._rest_joints += alpha * (joint_velocities - self._rest_joints)
        # a first-order average of white noise of variance s^2: s^2 alpha / (2 - alpha); of
        # encoder noise e differenced, (e_k - e_k-1) / dt, which telescopes:
        # 2 (e alpha / dt)^2 / (2 - alpha)
        gyro_variance = (noise.gyro_noise ** 2 * alpha / (2.0 - alpha)
                         + self.P.diagonal()[self._gyro_bias])
        joint_variance = 2.0 * (noise.encoder_noise * alpha / dt) ** 2 / (2.0 - alpha)
        self._closed_for = self._closed_for + dt if contact.all() else 0.0
        gate = noise.rest_gate ** 2
        return (self._closed_for >= noise.rest_window
                and float(np.sum((self._rest_gyro - self.gyro_bias) ** 2 / gyro_variance))
                < 3.0 * gate
                and float(self._rest_joints @ self._rest_joints) / joint_variance
                < self._rest_joints.size * gate)

    def _correct_rest(self, gyro: np.ndarray, dt: float) -> None:
        """The zero angular-rate update of inertial navigation: at rest the gyro reads its bias,
        gyro = b_w + noise, three rows on b_w; it makes the bias about the vertical observable,
        which the legs' kinematics do not (Bloesch et al. 2013, observability analysis). The
        noise: the gyro's white noise and the rate left at rest (``rest_rate_noise``), which is
        correlated over the rest window: counted once per window (its variance times
        rest_window / dt per sample)."""
        noise, b = self.noise, self._gyro_bias
        columns = self.P[:, b].copy()  # P H^T
        variance = noise.gyro_noise ** 2 + noise.rest_rate_noise ** 2 * noise.rest_window / dt
        S = columns[b] + variance * np.eye(3)
        gain = np.linalg.solve(S, columns.T).T
        self._inject(gain @ (gyro - self.gyro_bias))
        P = self.P - gain @ columns.T
        self.P = 0.5 * (P + P.T)

    # ------------------------------------------------------------------ native engine
    def _resolve_engine(self, engine: str) -> str:
        """``engine``, with "auto" resolved: native when the compiled estimator is built."""
        if engine != "auto":
            return engine
        try:
            from .. import _estimator  # noqa: F401
        except ImportError:
            warn_python_fallback("KinematicInertialEKF", "the compiled estimator "
                                                         "wholebody._estimator is not built")
            return "python"
        return "native"

    def _build_native(self):
        try:
            from .. import _estimator
        except ImportError as exc:
            raise ValueError(
                "engine: 'native' needs the compiled estimator wholebody._estimator, which was "
                "not built with this install (it needs a C++17 compiler at 'pip install' time; "
                "WHOLEBODY_NO_NATIVE=1 skips it); use engine='python'") from exc
        noise = {f.name: float(getattr(self.noise, f.name)) for f in fields(self.noise)
                 if f.name != "rest_update"}
        return _estimator.Estimator(noise | {
            "n_feet": self.n_points, "n_joints": self.robot.na, "radii": self._radii,
            "partner": self.partner.astype(float),
            "imu_rotation": self._imu_rotation, "lever_imu": self._lever_imu})

    # the state the compiled cycle updates in place: attribute -> buffer name
    _NATIVE_STATE = {"position": "position", "velocity": "velocity", "rotation": "rotation",
                     "feet": "feet", "accel_bias": "accel_bias", "gyro_bias": "gyro_bias",
                     "P": "P", "_innovation": "innovation", "_foot_test": "foot_test",
                     "_omega": "omega", "_rest_gyro": "rest_gyro", "_rest_joints": "rest_joints"}

    def _bind_native(self) -> None:
        """The state's arrays (copied, C-ordered) handed to the compiled cycle by name."""
        nb = {name: np.array(getattr(self, attribute), dtype=float, order="C")
              for attribute, name in self._NATIVE_STATE.items()}
        nb |= {"closed_for": np.array([self._closed_for]), "base": np.zeros(7),
               "twist": np.zeros(6)}
        for attribute, name in self._NATIVE_STATE.items():
            setattr(self, attribute, nb[name])
        self._nb = nb
        self._native.bind(nb)

    def _native_cycle(self, dt, gyro, accel, contact, joint_velocities, measured,
                      foot_rates) -> None:
        """The cycle in the compiled estimator; state set from outside since (an attribute
        assigned a new array) is copied into its buffer first."""
        nb = self._nb
        for attribute, name in self._NATIVE_STATE.items():
            value = getattr(self, attribute)
            if value is not nb[name]:
                np.copyto(nb[name], value)
                setattr(self, attribute, nb[name])
        native = self._native
        self._at_rest = native.predict_correct(
            dt=dt, gyro=gyro, accel=accel, contact=contact, joint_velocities=joint_velocities,
            measured=measured, foot_rates=foot_rates, rest_update=self.noise.rest_update)
        if native.skipped:
            self._warn("kinematic update skipped: singular innovation covariance")
        heights = self._ground_heights(contact) if self.ground is not None else _NO_HEIGHTS
        native.finish(heights=heights, at_rest=self._at_rest, gyro=gyro, dt=dt)

    @property
    def closed_for(self) -> float:
        """How long every contact has been closed (s), as the rest test counts it."""
        return float(self._nb["closed_for"][0]) if self._native is not None else self._closed_for

    # ------------------------------------------------------------------ output
    def _output(self, reading: SensorReading, native: bool = False) -> StateEstimate:
        """The IMU's state carried to the free-flyer (base joint) in Pinocchio's conventions
        (``native``: as the compiled cycle wrote it)."""
        q = self.kinematics.configuration.copy()  # the joints at this reading's angles
        v = np.empty(self.robot.nv)
        if native:
            q[0:7] = self._nb["base"]
            v[0:6] = self._nb["twist"]
        else:
            R_imu = self.rotation
            q[0:3] = self.position - R_imu @ self._lever_imu
            q[3:7] = pin.Quaternion(R_imu @ self._imu_rotation.T).normalized().coeffs()
            v[0:6] = self._twist_from_imu @ np.concatenate((self.velocity @ R_imu, self._omega))
        v[6:] = reading.joint_velocities
        return StateEstimate(t=self._t, q=q, v=v, covariance=self.P.copy(),
                             innovation=self._innovation.copy(), foot_test=self._foot_test.copy(),
                             feet=self.feet.copy(), at_rest=bool(self._at_rest))

    def _warn(self, message: str) -> None:
        if not self._warned:
            log.warning("state estimator: %s", message)
            self._warned = True
