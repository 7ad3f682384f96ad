"""KinematicInertialEKF(engine="native"): the compiled per-cycle numerics
(src/wholebody/native/estimator.cpp) against the Python engine — its tested reference — on the
same readings, cycle by cycle: a robot standing still (rest updates), then moving with its feet
lifting and landing at random, a bad and a stale reading (skipped), a foot lifting for a cycle
while still (the rest test restarts), with and without a ground map (sloped, with a gap), on ball
feet that roll (hyq) and soles that do not (talos14). Every output and the state agree to 1e-9."""

import math

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.estimation import EstimatorNoise, KinematicInertialEKF
from wholebody.robot import GRAVITY
from wholebody.sim.sensors import Sensors, SensorSpec

from conftest import native_cycle_or_skip

native_cycle_or_skip("_estimator")

SPEC = SensorSpec()


def recorded_readings(robot, seed: int = 0):
    """1.2 s at 1 kHz: still 0.5 s, then the base swaying and turning and the joints moving,
    each foot lifting and landing every 40 ms at random; a foot lifting for one cycle while
    still, a NaN gyro, NaN joint velocities and a stale reading along the way."""
    rng = np.random.default_rng(seed)
    sensors = Sensors(robot, SPEC, np.random.default_rng(seed + 1))
    n = len(robot.contact_names)
    weight = np.full(n, robot.mass * GRAVITY / n)
    phases = rng.uniform(0.0, 2.0 * math.pi, size=robot.na)
    pattern = rng.random((40, n)) > 0.4
    readings = []
    for k in range(1200):
        t = k * 1e-3
        q, v = robot.q_ref.copy(), np.zeros(robot.nv)
        if t >= 0.5:
            s = t - 0.5
            q[0:3] += [0.1 * s, 0.02 * math.sin(3.0 * s), 0.01 * math.sin(5.0 * s)]
            q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.05 * math.sin(4.0 * s),
                                                        0.03 * math.sin(6.0 * s), 0.2 * s)).coeffs()
            v[0:6] = [0.1, 0.06 * math.cos(3.0 * s), 0.05 * math.cos(5.0 * s),
                      0.2 * math.cos(4.0 * s), 0.18 * math.cos(6.0 * s), 0.2]
            q[7:] += 0.05 * np.sin(8.0 * s + phases)
            v[6:] = 0.4 * np.cos(8.0 * s + phases)
            forces = weight * pattern[int(s / 0.04) % 40]
        else:
            forces = weight * (np.arange(n) != 0) if k == 300 else weight
        reading = sensors.measure(t, q, v, np.zeros(robot.nv), forces)
        readings.append(reading)
    readings[700].gyro = np.array([np.nan, 0.0, 0.0])  # skipped
    readings[750].joint_velocities = np.full(robot.na, np.nan)  # skipped
    readings[800].t = readings[799].t  # stale: skipped
    return readings


def sloped_ground(x: float, y: float) -> float:
    """A 5 % slope with gaps (no ground: NaN) 1 cm wide every 10 cm of x."""
    return math.nan if 0.03 < x % 0.1 < 0.04 else 0.05 * x - 0.02 * y


def run(robot, readings, engine, ground):
    noise = EstimatorNoise.for_sensors(SPEC, rest_update=True)  # every mode: the rest update too
    ekf = KinematicInertialEKF(robot, noise, ground=ground, engine=engine)
    assert ekf.engine == engine
    estimates = [ekf.reset(readings[0], robot.q_ref[:3])]
    estimates += [ekf.update(r) for r in readings[1:]]
    return ekf, estimates


@pytest.mark.parametrize("name", ["hyq", "talos14"])
@pytest.mark.parametrize("ground", [None, sloped_ground])
def test_native_engine_matches_the_python_engine(name, ground):
    robot = wb.load_robot(name)
    readings = recorded_readings(robot)
    python, expected = run(robot, readings, "python", ground)
    native, actual = run(robot, readings, "native", ground)
    rests = [e.at_rest for e in expected]
    assert any(rests[:500]) and not all(rests[:500])  # rest updates ran, and the test restarted
    for k in (700, 750, 800):  # the bad readings
        assert expected[k] is expected[k - 1] and actual[k] is actual[k - 1]
    for k, (a, b) in enumerate(zip(actual, expected)):
        assert np.all(np.isfinite(b.q)) and np.all(np.isfinite(b.covariance)), k
        assert a.at_rest == b.at_rest, k
        scale = max(1.0, np.abs(b.covariance).max())
        for field in ("q", "v", "innovation", "foot_test", "feet"):
            np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=0, atol=1e-9,
                                       err_msg=f"{name} cycle {k}: {field}")
        np.testing.assert_allclose(a.covariance, b.covariance, rtol=0, atol=1e-9 * scale,
                                   err_msg=f"{name} cycle {k}: covariance")
    for attribute in ("gyro_bias", "accel_bias", "rotation", "position", "velocity"):
        np.testing.assert_allclose(getattr(native, attribute), getattr(python, attribute),
                                   rtol=0, atol=1e-9, err_msg=attribute)
    assert native.closed_for == pytest.approx(python.closed_for, abs=1e-12)


def test_state_set_from_outside_reaches_the_native_cycle():
    """An attribute assigned a new array between cycles (as the textbook test does) is what the
    next compiled cycle starts from."""
    robot = wb.load_robot("hyq")
    readings = recorded_readings(robot)[:3]
    filters = [KinematicInertialEKF(robot, EstimatorNoise.for_sensors(SPEC), engine=engine)
               for engine in ("python", "native")]
    for ekf in filters:
        ekf.reset(readings[0], robot.q_ref[:3])
        ekf.update(readings[1])
        ekf.gyro_bias = np.array([1e-3, -2e-3, 3e-3])
        ekf.P = ekf.P * 2.0
    a, b = (ekf.update(readings[2]) for ekf in filters)
    np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=0, atol=1e-12)
