"""Torque and joint-acceleration limits as inequality rows: the τ bounds are the robot's limits
(URDF efforts, and for HyQ's hydraulic joints the lever arm of the cylinder linkage recomputed
here from the preset's geometry), and a τ or q̈ just outside a bound is rejected."""

import numpy as np
import pytest

from wholebody.tasks import JointAccelerationLimits, TorqueLimits
from wholebody.variables import Variables

from . import _fd

ROBOTS = ("talos14", "hyq")


def _at(robot, seed):
    q, v = _fd.state_near_reference(robot, seed, scale=0.2)
    robot.update(q, v)
    return q, v


def _linkage_torque(a, b, force, q_peak, q):
    """Cylinder force times the distance from the joint axis to the cylinder line, the cylinder
    spanning the attachment points at distances a and b from the axis, at angle
    pi/2 + (q - q_peak) from each other."""
    t = np.pi / 2 + (q - q_peak)
    A, B = np.array([a, 0.0]), np.array([b * np.cos(t), b * np.sin(t)])
    return force * abs(A[0] * B[1] - A[1] * B[0]) / np.linalg.norm(B - A)


def _expected_upper(robot, q):
    hi = np.asarray(robot.model.effortLimit[6:], dtype=float).copy()
    for joint, p in dict(robot.description.torque_limits or {}).get("linkage", {}).items():
        i = robot.joint_names.index(joint)
        hi[i] = _linkage_torque(p["a"], p["b"], p["force"], p["q_peak"], q[7 + i])
    return hi


@pytest.mark.parametrize("seed", (0, 1))
@pytest.mark.parametrize("name", ROBOTS)
def test_torque_bounds_are_the_robot_limits(robots, name, seed):
    robot = robots[name]
    q, _ = _at(robot, seed)
    rows = TorqueLimits().rows(robot, Variables(robot))
    assert rows.qdd is None and rows.lam is None and not rows.is_equality
    tau = np.random.default_rng(seed).normal(size=robot.na)
    np.testing.assert_array_equal(rows.tau @ tau, tau)
    hi = _expected_upper(robot, q)
    np.testing.assert_allclose(rows.upper, hi, rtol=1e-12)
    np.testing.assert_allclose(rows.lower, -hi, rtol=1e-12)
    if name == "hyq":  # the linkage makes the bound depend on q
        assert len(set(np.round(rows.upper, 6))) > 2


@pytest.mark.parametrize("name", ROBOTS)
def test_a_torque_just_outside_is_rejected(robots, name):
    robot = robots[name]
    q, _ = _at(robot, 2)
    rows = TorqueLimits().rows(robot, Variables(robot))
    hi = _expected_upper(robot, q)
    assert _fd.satisfies(rows, tau=0.999 * hi, tol=0) and _fd.satisfies(rows, tau=-0.999 * hi, tol=0)
    for i in range(robot.na):
        for sign in (1, -1):
            tau = 0.5 * hi
            tau[i] = sign * 1.001 * hi[i]
            assert not _fd.satisfies(rows, tau=tau, tol=0)


def test_torque_limit_scale_and_override(robots):
    robot = robots["hyq"]
    q, _ = _at(robot, 3)
    joint = robot.joint_names[2]
    task = TorqueLimits(scale=0.8, upper_override={joint: 5.0})
    rows = task.rows(robot, Variables(robot))
    hi = 0.8 * _expected_upper(robot, q)
    hi[2] = min(hi[2], 5.0)
    np.testing.assert_allclose(rows.upper, hi, rtol=1e-12)
    np.testing.assert_allclose(rows.lower, -hi, rtol=1e-12)
    with pytest.raises(ValueError, match="unknown joint"):
        TorqueLimits(upper_override={"no_such_joint": 1.0}).rows(robot, Variables(robot))


@pytest.mark.parametrize("name", ROBOTS)
def test_braking_bounds_reach_the_limit_in_the_horizon(robots, name):
    """Fahmi et al. 2019, eqs. 17-18: from (q, q̇), the constant acceleration q̈_max reaches q_max
    exactly after ``horizon`` seconds (q + h q̇ + h² q̈ / 2 = q_max), likewise q̈_min and q_min;
    the rows select the joint accelerations."""
    robot = robots[name]
    q, v = _at(robot, 4)
    h = 0.02
    rows = JointAccelerationLimits(mode="braking", horizon=h).rows(robot, Variables(robot))
    qdd = np.random.default_rng(4).normal(size=robot.nv)
    np.testing.assert_array_equal(rows.qdd @ qdd, qdd[6:])
    qj, vj = q[7:], v[6:]
    np.testing.assert_allclose(qj + h * vj + 0.5 * h ** 2 * rows.upper, robot.q_max, atol=1e-12)
    np.testing.assert_allclose(qj + h * vj + 0.5 * h ** 2 * rows.lower, robot.q_min, atol=1e-12)
    assert np.all(rows.lower < rows.upper)
    inside = np.r_[np.zeros(6), 0.5 * (rows.lower + rows.upper)]
    assert _fd.satisfies(rows, qdd=inside, tol=0)
    for i in range(robot.na):
        above = inside.copy()
        above[6 + i] = rows.upper[i] + 1e-6 * abs(rows.upper[i]) + 1e-9
        assert not _fd.satisfies(rows, qdd=above, tol=0)


def test_tanh_bounds_vanish_at_the_limits_and_saturate_far_from_them(robots):
    """Herzog et al. 2016 Sect. 2.1: q̈_max = a_max tanh(k (q_max - q)): zero at the limit,
    -> a_max far inside, pushing back (negative) beyond it."""
    robot = robots["talos14"]
    task = JointAccelerationLimits(mode="tanh", a_max=150.0, steepness=10.0)
    for where, check in (("at", lambda lo, hi: np.allclose(hi, 0, atol=1e-9) and np.all(lo < 0)),
                         ("beyond", lambda lo, hi: np.all(hi < 0))):
        q = robot.q_ref.copy()
        q[7:] = robot.q_max + (0.0 if where == "at" else 0.05)
        robot.update(q, np.zeros(robot.nv))
        rows = task.rows(robot, Variables(robot))
        assert check(rows.lower, rows.upper), where
    q = robot.q_ref.copy()
    q[7:] = 0.5 * (robot.q_min + robot.q_max)
    robot.update(q, np.zeros(robot.nv))
    rows = task.rows(robot, Variables(robot))
    far = (robot.q_max - robot.q_min) > 1.0  # more than 0.5 rad from both limits
    assert far.any()
    np.testing.assert_allclose(rows.upper[far], 150.0, rtol=1e-3)
    np.testing.assert_allclose(rows.lower[far], -150.0, rtol=1e-3)
    with pytest.raises(ValueError, match="mode"):
        JointAccelerationLimits(mode="linear")


def test_the_checks_detect_wrong_bounds(robots):
    """The linkage check rejects the constant URDF effort on HyQ's hydraulic joints, and the
    braking check rejects the paper's printed sign (-2 (q_max - q - h q̇) / h²)."""
    robot = robots["hyq"]
    q, v = _at(robot, 0)
    rows = TorqueLimits().rows(robot, Variables(robot))
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(robot.model.effortLimit[6:], _expected_upper(robot, q), rtol=1e-6)
    np.testing.assert_allclose(rows.upper, _expected_upper(robot, q), rtol=1e-12)
    h = 0.02
    printed = -2.0 * (robot.q_max - q[7:] - h * v[6:]) / h ** 2
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(q[7:] + h * v[6:] + 0.5 * h ** 2 * printed, robot.q_max, atol=1e-12)
