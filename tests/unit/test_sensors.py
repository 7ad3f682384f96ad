"""The twin's sensors: noise and bias statistics match the spec; exact sensors report the truth,
the accelerometer checked against a finite difference of the twin's own velocity."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.robot import GRAVITY
from wholebody.sim.sensors import Sensors, SensorSpec
from wholebody.sim.simulator import Simulator

ZERO = SensorSpec.exact()


@pytest.fixture(scope="module")
def hyq():
    return wb.load_robot("hyq")


def static_readings(robot, spec, n, seed=0, dt=1e-3, forces=None):
    """``n`` readings of the robot at rest at its reference posture, one every ``dt``."""
    sensors = Sensors(robot, spec, np.random.default_rng(seed))
    q, v = robot.q_ref, np.zeros(robot.nv)
    forces = np.zeros(len(robot.contact_names)) if forces is None else forces
    return sensors, [sensors.measure(k * dt, q, v, np.zeros(robot.nv), forces) for k in range(n)]


def relative_std_tolerance(samples: int) -> float:
    """Four standard errors of a sample standard deviation (relative): 4 / sqrt(2 N)."""
    return 4.0 / math.sqrt(2.0 * samples)


def test_white_noise_std_matches_the_spec(hyq):
    spec = SensorSpec(**{**ZERO.__dict__, "gyro_noise": 0.01, "accel_noise": 0.05,
                         "encoder_noise": 1e-3})
    _, readings = static_readings(hyq, spec, 2000)
    gravity_in_base = np.array([0.0, 0.0, GRAVITY])  # the base is level at q_ref
    gyro = np.array([r.gyro for r in readings])
    accel = np.array([r.accel for r in readings]) - gravity_in_base
    joints = np.array([r.joint_positions for r in readings]) - hyq.q_ref[7:]
    for values, std in ((gyro, 0.01), (accel, 0.05), (joints, 1e-3)):
        assert values.std() == pytest.approx(std, rel=relative_std_tolerance(values.size))
        assert abs(values.mean()) < 4 * std / math.sqrt(values.size)  # no bias asked for


def test_biases_spread_as_the_spec_and_hold_without_a_walk(hyq):
    spec = SensorSpec(**{**ZERO.__dict__, "gyro_bias": 0.003, "accel_bias": 0.04})
    offsets_gyro, offsets_accel = [], []
    for seed in range(300):
        _, readings = static_readings(hyq, spec, 3, seed=seed)
        gyro = np.array([r.gyro for r in readings])
        assert np.ptp(gyro, axis=0) == pytest.approx(np.zeros(3), abs=1e-15)  # constant
        offsets_gyro.append(gyro[0])
        offsets_accel.append(readings[0].accel - [0.0, 0.0, GRAVITY])
    tolerance = relative_std_tolerance(900)
    assert np.std(offsets_gyro) == pytest.approx(0.003, rel=tolerance)
    assert np.std(offsets_accel) == pytest.approx(0.04, rel=tolerance)


def test_bias_random_walk_grows_with_the_square_root_of_time(hyq):
    spec = SensorSpec(**{**ZERO.__dict__, "gyro_bias_walk": 0.01})
    duration, ends = 0.4, []
    for seed in range(200):
        _, readings = static_readings(hyq, spec, 401, seed=seed)
        ends.append(readings[-1].gyro - readings[0].gyro)
    expected = 0.01 * math.sqrt(duration)
    assert np.std(ends) == pytest.approx(expected, rel=relative_std_tolerance(600))


def test_encoders_are_quantised_and_velocities_differenced(hyq):
    step = 2 * math.pi / 2 ** 12
    spec = SensorSpec(**{**ZERO.__dict__, "encoder_resolution": step})
    sensors = Sensors(hyq, spec)
    rate = np.linspace(-1.0, 1.0, hyq.na)
    readings = []
    for k in range(50):
        q = hyq.q_ref.copy()
        q[7:] += rate * k * 1e-3
        readings.append(sensors.measure(k * 1e-3, q, np.zeros(hyq.nv), np.zeros(hyq.nv),
                                        np.zeros(4)))
        counts = readings[-1].joint_positions / step
        assert np.allclose(counts, np.round(counts), atol=1e-9)
        assert np.all(np.abs(readings[-1].joint_positions - q[7:]) <= 0.5 * step + 1e-12)
    for before, after in zip(readings[:-1], readings[1:]):
        expected = (after.joint_positions - before.joint_positions) / 1e-3
        assert np.allclose(after.joint_velocities, expected)


def test_filtered_velocity_follows_a_constant_rate(hyq):
    """A first-order low-pass at f_c, fed a rate that steps from 0 to r when the ramp starts,
    answers r (1 - exp(-t / tau)) at the samples, tau = 1 / (2 pi f_c)."""
    spec = SensorSpec(**{**ZERO.__dict__, "velocity_cutoff_hz": 50.0})
    sensors = Sensors(hyq, spec)
    rate = np.full(hyq.na, 0.7)
    tau = 1.0 / (2 * math.pi * 50.0)
    for k in range(200):
        q = hyq.q_ref.copy()
        q[7:] += rate * k * 1e-3
        reading = sensors.measure(k * 1e-3, q, np.zeros(hyq.nv), np.zeros(hyq.nv), np.zeros(4))
        step_response = rate * (1.0 - math.exp(-k * 1e-3 / tau))
        assert np.allclose(reading.joint_velocities, step_response, rtol=1e-9, atol=1e-12)
    assert np.allclose(reading.joint_velocities, rate, rtol=1e-3)


def test_contact_from_the_normal_force_threshold(hyq):
    spec = SensorSpec(contact_force_fraction=0.1)
    threshold = 0.1 * hyq.mass * GRAVITY
    forces = np.array([0.0, 0.9 * threshold, 1.1 * threshold, 10 * threshold])
    _, readings = static_readings(hyq, spec, 1, forces=forces)
    assert readings[0].contact.tolist() == [False, False, True, True]


def test_attitude_filter_yaw_drifts_roll_and_pitch_do_not(hyq):
    spec = SensorSpec(**{**ZERO.__dict__, "yaw_drift_rate": 0.01})
    sensors = Sensors(hyq, spec)
    q = hyq.q_ref.copy()
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3)).coeffs()
    reading = sensors.measure(5.0, q, np.zeros(hyq.nv), np.zeros(hyq.nv), np.zeros(4))
    attitude = pin.Quaternion(reading.orientation[3], *reading.orientation[:3])
    roll, pitch, yaw = pin.rpy.matrixToRpy(attitude.toRotationMatrix())
    assert (roll, pitch) == pytest.approx((0.1, -0.2), abs=1e-12)
    assert yaw == pytest.approx(0.3 + 0.05, abs=1e-12)


def test_exact_sensors_in_the_twin_report_the_truth():
    """An unactuated talos14 collapsing in the twin (large, varying accelerations): exact sensors
    give the twin's joints, rates and orientation, and the accelerometer the backward difference
    of the twin's world velocity of the base minus gravity, in the base frame."""
    robot = wb.load_robot("talos14")
    sim = Simulator(robot, record=False)
    sensors = Sensors(robot, ZERO)
    previous = None
    for _ in range(300):
        q, v = sim.state()
        reading = sensors.read(sim)
        rotation = pin.Quaternion(q[6], *q[3:6]).toRotationMatrix()
        assert np.array_equal(reading.joint_positions, q[7:])
        assert np.allclose(reading.gyro, v[3:6], atol=1e-12)
        assert np.allclose(reading.orientation * np.sign(reading.orientation[3] * q[6]), q[3:7],
                           atol=1e-12)
        velocity_world = rotation @ v[:3]
        if previous is not None:
            specific_force = (velocity_world - previous) / sim.dt + [0.0, 0.0, GRAVITY]
            assert np.allclose(reading.accel, rotation.T @ specific_force, atol=1e-6)
        previous = velocity_world
        sim.step(np.zeros(robot.na))
    assert np.linalg.norm(sim.state()[1][:3]) > 0.05  # it did move


@pytest.mark.parametrize("field, value", [("gyro_noise", -1.0), ("encoder_resolution", math.nan),
                                          ("contact_force_fraction", "high")])
def test_bad_spec_names_the_field(field, value):
    with pytest.raises(ValueError, match=f"SensorSpec.{field}"):
        SensorSpec(**{field: value})


def test_bad_generator_is_refused(hyq):
    with pytest.raises(ValueError, match="rng"):
        Sensors(hyq, rng=0)
