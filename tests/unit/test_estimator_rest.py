"""The estimator's zero angular-rate update: on synthetic readings of a robot standing still with a
known, constant gyro bias, the bias estimate converges to it within the average of the gyro's
white noise and the heading stops drifting; a robot turning in place, one moving its joints, and
one pushed are not taken as at rest."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.estimation import EstimatorNoise, KinematicInertialEKF
from wholebody.robot import GRAVITY
from wholebody.sim.sensors import Sensors, SensorSpec

BIAS = np.array([2e-3, -3e-3, 4e-3])  # rad/s, a constant gyro bias (no walk)
SPEC = SensorSpec(gyro_bias=4e-3, gyro_bias_walk=0.0)  # the filter's prior: 4 mrad/s per axis


@pytest.fixture(scope="module")
def hyq():
    return wb.load_robot("hyq")


def readings(robot, steps, yaw_rate=lambda t: 0.0, joint_offset=lambda t: 0.0, seed=0):
    """1 kHz readings of ``robot`` at its reference posture with every foot loaded, the base
    turning about the vertical at ``yaw_rate(t)`` (rad/s) and ``joint_offset(t)`` added to the
    joints; the gyro with the bias BIAS."""
    sensors = Sensors(robot, SPEC, np.random.default_rng(seed))
    sensors.gyro_bias = BIAS.copy()
    weight = np.full(len(robot.contact_names), robot.mass * GRAVITY / len(robot.contact_names))
    yaw, out = 0.0, []
    for k in range(steps):
        t = k * 1e-3
        q, v = robot.q_ref.copy(), np.zeros(robot.nv)
        q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, yaw)).coeffs()
        v[5] = yaw_rate(t)
        q[7:] += joint_offset(t)
        out.append(sensors.measure(t, q, v, np.zeros(robot.nv), weight))
        yaw += 1e-3 * yaw_rate(t)
    return out


def run(robot, data, **noise):
    noise.setdefault("rest_update", True)  # the update under test (off by default)
    ekf = KinematicInertialEKF(robot, EstimatorNoise.for_sensors(SPEC, **noise))
    estimates = [ekf.reset(data[0], robot.q_ref[:3])]
    estimates += [ekf.update(reading) for reading in data[1:]]
    return ekf, estimates


def heading(estimate):
    return pin.rpy.matrixToRpy(pin.Quaternion(estimate.q[6], *estimate.q[3:6])
                               .toRotationMatrix())[2]


def test_a_still_robot_gyro_bias_converges_and_the_heading_stops_drifting(hyq):
    steps = 2000
    data = readings(hyq, steps)
    ekf, estimates = run(hyq, data)
    rest = np.array([e.at_rest for e in estimates])
    # still, every foot loaded: at rest after the first window, but for the gate's tail (a
    # chi-square of 3 above 3 rest_gate^2 = 12: 0.7 % of the time)
    assert rest[200:].mean() > 0.95, rest[200:].mean()
    # the mean of N gyro samples at rest, each with the gyro's white noise and the rate the
    # rest test lets pass (counted once per window): std sqrt(variance / N) per axis (4 std)
    noise = ekf.noise
    variance = noise.gyro_noise ** 2 + noise.rest_rate_noise ** 2 * noise.rest_window / 1e-3
    bound = 4.0 * math.sqrt(variance / int(rest.sum()))
    np.testing.assert_allclose(ekf.gyro_bias, BIAS, atol=bound)
    # the heading over the last second moves by what is left of the bias, not by the bias
    drift = abs(heading(estimates[-1]) - heading(estimates[-1001]))
    assert drift < bound * 1.0, drift  # rad over 1 s
    # without the update nothing is taken as rest
    _, without = run(hyq, data[:300], rest_update=False)
    assert not any(e.at_rest for e in without)


def test_a_robot_turning_in_place_is_not_at_rest(hyq):
    rate = 0.05  # rad/s: far above the bias's prior std
    assert rate > 10.0 * SPEC.gyro_bias
    _, estimates = run(hyq, readings(hyq, 500, yaw_rate=lambda t: rate))
    assert not any(e.at_rest for e in estimates)


def test_moving_joints_are_not_at_rest(hyq):
    # each joint 0.01 rad at 2 Hz, in its own phase: rates of 0.13 rad/s at most
    phases = np.random.default_rng(1).uniform(0.0, 2.0 * math.pi, size=hyq.na)
    _, estimates = run(hyq, readings(
        hyq, 600, joint_offset=lambda t: 0.01 * np.sin(2.0 * math.pi * 2.0 * t + phases)))
    assert not any(e.at_rest for e in estimates[100:])


def test_a_push_stops_the_rest_update_at_once(hyq):
    push_at = 0.4  # s: a 0.2 rad/s yaw rate from then on

    def rate(t):
        return 0.2 if t >= push_at else 0.0

    _, estimates = run(hyq, readings(hyq, 500, yaw_rate=rate))
    times = np.array([e.t for e in estimates])
    rest = np.array([e.at_rest for e in estimates])
    assert rest[(times > 0.2) & (times < push_at)].all()
    assert not rest[times >= push_at + 2e-3].any()  # within two cycles


def test_rest_update_must_be_a_flag():
    with pytest.raises(ValueError, match="EstimatorNoise.rest_update"):
        EstimatorNoise(rest_update=1)
    with pytest.raises(ValueError, match="EstimatorNoise.rest_window"):
        EstimatorNoise(rest_window=0.0)
