"""The kinematic-inertial EKF against the twin's truth: run open-loop beside closed-loop runs that
read the exact state, in free flight with exact sensors (the conventions), on data with a slipping
foot; its covariance stays symmetric positive definite. Bounds come from the sensor spec and the
robot's size, not from the filter's own numbers."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.control.standing import StandingController
from wholebody.estimation import EstimatorNoise, KinematicInertialEKF, TwinEstimation
from wholebody.planning.trunk import VelocityCommand
from wholebody.robot import GRAVITY
from wholebody.scenarios.locomotion import run_gait
from wholebody.scenarios.loop import run_closed_loop
from wholebody.sim.sensors import Sensors, SensorSpec
from wholebody.sim.simulator import Simulator

SPEC = SensorSpec()


def rotation(q):
    return pin.Quaternion(q[6], *q[3:6]).toRotationMatrix()


def tilt_and_yaw_errors(q_true, q_hat):
    """Per sample: the angle between the true and estimated vertical in the base frame (roll and
    pitch) and the heading error (yaw), rad."""
    tilt, yaw = [], []
    for a, b in zip(q_true, q_hat):
        Ra, Rb = rotation(a), rotation(b)
        tilt.append(math.acos(min(1.0, Ra[2] @ Rb[2])))
        yaw.append(abs(pin.rpy.matrixToRpy(Ra.T @ Rb)[2]))
    return np.array(tilt), np.array(yaw)


def leg_length(robot):
    """The largest distance from the base to a contact frame at the reference posture (m)."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    return max(np.linalg.norm(data.oMf[robot.contact(n).frame_id].translation - robot.q_ref[:3])
               for n in robot.contact_names)


def source_alone_velocity_errors(robot, spec, duration):
    """What either source alone gives for the base velocity (m/s): differencing the legs'
    kinematics at 1 kHz (a joint reading's error, quantisation and noise, times sqrt(2) over
    1 ms, times the leg's length) and integrating the accelerometer (its bias over the run)."""
    joint_error = math.sqrt(spec.encoder_resolution ** 2 / 12 + spec.encoder_noise ** 2)
    kinematics = leg_length(robot) * math.sqrt(2.0) * joint_error / 1e-3
    inertial = spec.accel_bias * duration
    return kinematics, inertial


def tilt_bound(spec):
    """Three standard deviations of the tilt a static accelerometer bias cannot be told from:
    |b_xy| / g, plus the attitude filter's error the filter starts from."""
    return 3.0 * (math.sqrt(2.0) * spec.accel_bias / GRAVITY + spec.attitude_noise)


@pytest.fixture(scope="module")
def standing_run():
    """talos14 standing 3 s under the standing controller reading the exact state."""
    robot = wb.load_robot("talos14")
    estimation = TwinEstimation.for_robot(robot, SPEC, seed=1)
    sim = Simulator(robot, observers=[estimation], record=False)
    run_closed_loop(sim, StandingController(robot), 3.0)
    return robot, estimation.log.arrays()


@pytest.fixture(scope="module")
def trotting_run():
    """hyq trotting at 0.3 m/s for 3 s after 1 s of standing, passive WBC on the exact state."""
    robot = wb.load_robot("hyq")
    estimation = TwinEstimation.for_robot(robot, SPEC, seed=2)
    command = VelocityCommand.speed_ramp(0.3, 0.3, 1.0, 2.0)
    run = run_gait(robot, "passive", "trot", command, 4.0, observers=[estimation])
    assert not run.fell and run.failures == 0
    return robot, estimation.log.arrays()


@pytest.mark.slow  # closed loop in the twin
def test_standing_talos14(standing_run):
    robot, log = standing_run
    duration = log["t"][-1]
    error = log["v_hat"][:, :3] - log["v_true"][:, :3]
    rms = math.sqrt(np.mean(np.sum(error ** 2, axis=1)))
    kinematics, inertial = source_alone_velocity_errors(robot, SPEC, duration)
    assert rms < 0.25 * min(kinematics, inertial), (rms, kinematics, inertial)
    tilt, yaw = tilt_and_yaw_errors(log["q_true"], log["q_hat"])
    assert tilt.max() < tilt_bound(SPEC), tilt.max()
    # the heading: the attitude filter's start error plus an unobserved gyro bias over the run
    assert yaw.max() < 3.0 * (SPEC.attitude_noise + SPEC.gyro_bias * duration), yaw.max()
    # standing feet anchor the position: the tilt bound times the leg's length, each axis
    drift = np.abs(log["q_hat"][:, :3] - log["q_true"][:, :3]).max(axis=0)
    assert np.all(drift < tilt_bound(SPEC) * leg_length(robot)), drift


@pytest.mark.slow  # closed loop in the twin
def test_trotting_hyq(trotting_run):
    robot, log = trotting_run
    assert log["contact"][-2000:].mean() < 0.8  # feet did lift: a trot, not a stand
    q_true, q_hat = log["q_true"], log["q_hat"]
    path = np.sum(np.linalg.norm(np.diff(q_true[:, :2], axis=0), axis=1))
    assert path > 0.6
    drift = np.linalg.norm(q_hat[-1, :2] - q_true[-1, :2])
    assert drift < 0.02 * path, (drift, path)  # the target: 2 % of the distance travelled
    error = log["v_hat"][:, :3] - log["v_true"][:, :3]
    rms = math.sqrt(np.mean(np.sum(error ** 2, axis=1)))
    kinematics, inertial = source_alone_velocity_errors(robot, SPEC, log["t"][-1])
    assert rms < 0.25 * min(kinematics, inertial), (rms, kinematics, inertial)
    tilt, _ = tilt_and_yaw_errors(q_true, q_hat)
    assert tilt.max() < tilt_bound(SPEC), tilt.max()


@pytest.mark.slow  # closed loop in the twin
def test_covariance_positive_along_the_runs(standing_run, trotting_run):
    for _, log in (standing_run, trotting_run):
        assert np.all(log["variance"] > 0.0)


def test_free_flight_with_exact_sensors_follows_the_twin():
    """hyq thrown tumbling and yawed, no contact: exact IMU integration must follow the twin;
    a frame mix-up (world vs base velocity, w-first quaternion) would err by the speed itself."""
    robot = wb.load_robot("hyq")
    sim = Simulator(robot, record=False)
    q0 = robot.q_ref.copy()
    q0[2] += 2.0
    q0[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.3, -0.2, 2.0)).coeffs()
    v0 = np.zeros(robot.nv)
    v0[:6] = [1.0, -0.5, 0.8, 0.6, -0.4, 1.2]
    sim.reset(q0, v0)
    sensors = Sensors(robot, SensorSpec.exact())
    ekf = KinematicInertialEKF(robot, EstimatorNoise.for_sensors(SensorSpec.exact()))
    ekf.reset(sensors.read(sim), q0[:3], v0[:3])
    for _ in range(300):
        sim.step(np.zeros(robot.na))
        estimate = ekf.update(sensors.read(sim))
    q, v = sim.state()
    speed = np.linalg.norm(v[:3])
    assert speed > 1.0
    assert np.allclose(estimate.v[:3], v[:3], atol=0.01 * speed)
    assert np.allclose(estimate.v[3:], v[3:], atol=1e-9)
    assert np.allclose(estimate.q[:3], q[:3], atol=0.003)
    assert np.linalg.norm(pin.log3(rotation(q).T @ rotation(estimate.q))) < 1e-3


def synthetic_stance(robot, steps, joint_offset=lambda k: 0.0, contact=None, seed=0):
    """The EKF on readings of ``robot`` at rest at its reference posture (noisy sensors), all
    feet loaded unless ``contact(k)`` says otherwise; ``joint_offset(k)`` (rad vector or 0) is
    added to the encoders. Returns the estimates and the filter."""
    sensors = Sensors(robot, SPEC, np.random.default_rng(seed))
    ekf = KinematicInertialEKF(robot, EstimatorNoise.for_sensors(SPEC))
    weight = np.full(len(robot.contact_names), robot.mass * GRAVITY / len(robot.contact_names))
    estimates = []
    for k in range(steps):
        forces = weight if contact is None else weight * contact(k)
        reading = sensors.measure(k * 1e-3, robot.q_ref, np.zeros(robot.nv), np.zeros(robot.nv),
                                  forces)
        reading.joint_positions = reading.joint_positions + joint_offset(k)
        if k == 0:
            estimates.append(ekf.reset(reading, robot.q_ref[:3]))
        else:
            estimates.append(ekf.update(reading))
    return estimates, ekf


def test_a_slipping_stance_foot_shows_in_its_innovation():
    """One hyq foot is moved 3 cm in 60 ms while it reads as loaded: that foot's normalised
    innovation rises far above its own level before the slip and above the other feet's."""
    robot = wb.load_robot("hyq")
    slipping = 0  # the first contact; the joint that carries its frame moves it
    joint = robot.model.frames[robot.contact(robot.contact_names[slipping]).frame_id].parentJoint
    knee = robot.model.joints[joint].idx_q - 7
    slip_start, slip_end = 600, 660
    radians = 0.03 / leg_length(robot)

    def offset(k):
        out = np.zeros(robot.na)
        out[knee] = radians * min(max(k - slip_start, 0), slip_end - slip_start) / (
            slip_end - slip_start)
        return out

    estimates, _ = synthetic_stance(robot, 800, offset)
    tests = np.array([e.foot_test for e in estimates])
    before = tests[100:slip_start].max(axis=0)
    during = tests[slip_start:slip_end + 20].max(axis=0)
    assert during[slipping] > 10.0 * before[slipping], (during, before)
    assert during[slipping] > 3.0 * np.delete(during, slipping).max(), during


def test_covariance_stays_symmetric_positive_definite_through_contact_changes():
    robot = wb.load_robot("hyq")
    pattern = np.random.default_rng(3).random((60, 4)) > 0.4  # feet on and off every 25 ms
    estimates, _ = synthetic_stance(robot, 1500, contact=lambda k: pattern[k // 25 % 60])
    for estimate in estimates[::50]:
        P = estimate.covariance
        assert np.allclose(P, P.T, rtol=0.0, atol=1e-15 * np.abs(P).max())
        assert np.linalg.eigvalsh(P).min() > 0.0


def test_bad_readings_are_skipped_not_raised():
    robot = wb.load_robot("hyq")
    estimates, ekf = synthetic_stance(robot, 20)
    bad = Sensors(robot, SPEC).measure(1.0, robot.q_ref, np.zeros(robot.nv), np.zeros(robot.nv),
                                       np.zeros(4))
    bad.gyro = np.array([np.nan, 0.0, 0.0])
    assert ekf.update(bad) is estimates[-1]
    stale = Sensors(robot, SPEC).measure(0.0, robot.q_ref, np.zeros(robot.nv),
                                         np.zeros(robot.nv), np.zeros(4))
    assert ekf.update(stale) is estimates[-1]


def test_bad_construction_names_the_field():
    robot = wb.load_robot("hyq")
    with pytest.raises(ValueError, match="EstimatorNoise.kinematics_noise"):
        EstimatorNoise(kinematics_noise=0.0)
    with pytest.raises(ValueError, match="imu_frame"):
        KinematicInertialEKF(robot, imu_frame="no_such_frame")
    ekf = KinematicInertialEKF(robot)
    reading = Sensors(robot, SPEC).measure(0.0, robot.q_ref, np.zeros(robot.nv),
                                           np.zeros(robot.nv), np.zeros(4))
    with pytest.raises(ValueError, match="base_position"):
        ekf.reset(reading, base_position=(0.0, 1.0))


def test_one_sole_holds_the_heading_against_a_gyro_bias():
    """talos14 at rest on one sole with a gyro biased about the vertical: the sole's heel and toe
    hold the heading (integrating the bias alone would turn it by bias x time)."""
    robot = wb.load_robot("talos14")
    sensors = Sensors(robot, SPEC, np.random.default_rng(0))
    bias, seconds = 0.005, 5.0
    ekf = KinematicInertialEKF(robot, EstimatorNoise.for_sensors(SPEC))
    forces = np.zeros(len(robot.contact_names))
    forces[0] = robot.mass * GRAVITY
    yaw = []
    for k in range(int(seconds / 1e-3)):
        sensors.gyro_bias = np.array([0.0, 0.0, bias])
        reading = sensors.measure(k * 1e-3, robot.q_ref, np.zeros(robot.nv), np.zeros(robot.nv),
                                  forces)
        estimate = ekf.reset(reading, robot.q_ref[:3]) if k == 0 else ekf.update(reading)
        yaw.append(tilt_and_yaw_errors([robot.q_ref], [estimate.q])[1][0])
    assert bias * seconds > 0.02
    assert max(yaw) < 0.1 * bias * seconds, max(yaw)
