"""Motion tasks (CoM, frame, posture, joint trajectory): their q̈ rows are the Jacobians of finite
differences of the CoM / frame pose along ``pinocchio.integrate``, their targets the PD law minus
the finite-difference drift J̇ v."""

import numpy as np
import pinocchio as pin
import pytest

from wholebody.tasks import CoMTask, FrameTask, JointTrajectoryTask, PostureTask
from wholebody.variables import Variables

from . import _fd

ROBOTS = ("talos14", "hyq")
SEEDS = (0, 1)


def _at(robot, seed):
    q, v = _fd.state_near_reference(robot, seed)
    robot.update(q, v)
    return q, v


def _com_jacobian_and_drift(robot, q, v):
    com = _fd.com_fd(robot)
    e, h = _fd.EPS, _fd.EPS2
    J = np.column_stack([(com(_fd.moved(robot, q, d, e)) - com(_fd.moved(robot, q, d, -e))) / (2 * e)
                         for d in np.eye(robot.nv)])
    drift = (com(_fd.moved(robot, q, v, h)) - 2 * com(q) + com(_fd.moved(robot, q, v, -h))) / h ** 2
    return J, drift


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", ROBOTS)
def test_com_task_rows_are_the_com_jacobian_and_drift(robots, name, seed):
    robot = robots[name]
    q, v = _at(robot, seed)
    J, drift = _com_jacobian_and_drift(robot, q, v)
    rows = CoMTask(kp=0.0, kd=0.0).rows(robot, Variables(robot))
    assert rows.lam is None and rows.tau is None and rows.is_equality
    np.testing.assert_allclose(rows.qdd, J, atol=1e-8)
    np.testing.assert_allclose(rows.target, -drift, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name", ROBOTS)
def test_com_task_target_is_the_pd_acceleration(robots, name):
    """a = a_ff + Kp (x_d - x) + Kd (v_d - v) with x, v of the CoM from finite differences;
    ``axes`` keeps the chosen rows only."""
    robot = robots[name]
    q, v = _at(robot, 2)
    J, drift = _com_jacobian_and_drift(robot, q, v)
    com, vcom = _fd.com_fd(robot)(q), J @ v
    offset, v_d, a_ff = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.0, -0.2]), np.array([1, 2, 3.0])
    task = CoMTask(kp=40.0, kd=7.0, axes="xz")
    task.position, task.velocity, task.acceleration = com + offset, v_d, a_ff
    rows = task.rows(robot, Variables(robot))
    expected = a_ff + 40.0 * offset + 7.0 * (v_d - vcom) - drift
    np.testing.assert_allclose(rows.qdd, J[[0, 2]], atol=1e-8)
    np.testing.assert_allclose(rows.target, expected[[0, 2]], rtol=1e-5, atol=1e-6)


def test_com_task_holds_the_first_seen_com(robots):
    robot = robots["talos14"]
    q, _ = _at(robot, 3)
    task = CoMTask()
    task.rows(robot, Variables(robot))
    np.testing.assert_allclose(task.position, _fd.com_fd(robot)(q), atol=1e-12)


def _frames(robot):
    return [c.frame for c in robot.contacts]


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", ROBOTS)
def test_frame_task_rows_are_the_frame_jacobian_and_drift(robots, name, seed):
    robot = robots[name]
    q, v = _at(robot, seed)
    for frame in _frames(robot):
        pose = _fd.BodyPoint(robot, robot.frame_id(frame)).pose
        J, drift = _fd.jacobian_fd(robot, pose, q), _fd.drift_fd(robot, pose, q, v)
        rows = FrameTask(frame, kp=0.0, kd=0.0).rows(robot, Variables(robot))
        np.testing.assert_allclose(rows.qdd, J, atol=1e-8)
        np.testing.assert_allclose(rows.target, -drift, rtol=1e-5, atol=1e-6)
        for mask, s in (("position", slice(0, 3)), ("orientation", slice(3, 6))):
            part = FrameTask(frame, kp=0.0, kd=0.0, mask=mask).rows(robot, Variables(robot))
            np.testing.assert_allclose(part.qdd, J[s], atol=1e-8)
            np.testing.assert_allclose(part.target, -drift[s], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name", ROBOTS)
def test_frame_task_pd_drives_toward_the_reference_pose(robots, name):
    """A reference shifted by dp and rotated by theta about a world axis w asks for the
    acceleration Kp [dp; theta w] - Kd (frame twist) on top of the drift."""
    robot = robots[name]
    q, v = _at(robot, 4)
    frame = _frames(robot)[0]
    pose = _fd.BodyPoint(robot, robot.frame_id(frame)).pose
    p, R = pose(q)
    twist, drift = _fd.twist_fd(robot, pose, q, v), _fd.drift_fd(robot, pose, q, v)
    dp, axis, theta = np.array([0.02, -0.01, 0.03]), np.array([1.0, 2.0, -2.0]) / 3.0, 0.1
    task = FrameTask(frame, kp=30.0, kd=5.0)
    task.position, task.rotation = p + dp, pin.exp3(theta * axis) @ R
    rows = task.rows(robot, Variables(robot))
    expected = 30.0 * np.concatenate([dp, theta * axis]) - 5.0 * twist - drift
    np.testing.assert_allclose(rows.target, expected, rtol=1e-5, atol=1e-6)


def test_frame_task_rejects_an_unknown_mask():
    with pytest.raises(ValueError, match="mask"):
        FrameTask("base_link", mask="xyz")


@pytest.mark.parametrize("name", ROBOTS)
def test_posture_task_targets_the_difference_to_the_reference(robots, name):
    """Joint rows select the joint accelerations; with base gains all nv rows, the error being
    pinocchio.difference(q, q_ref) (the v-space displacement to the reference)."""
    robot = robots[name]
    q, v = _at(robot, 5)
    diff = pin.difference(robot.model, q, robot.q_ref)
    qdd = np.random.default_rng(0).normal(size=robot.nv)
    rows = PostureTask(kp=50.0, kd=10.0).rows(robot, Variables(robot))
    np.testing.assert_array_equal(rows.qdd @ qdd, qdd[6:])
    np.testing.assert_allclose(rows.target, 50.0 * diff[6:] - 10.0 * v[6:], rtol=1e-10, atol=1e-10)
    full = PostureTask(kp=50.0, kd=10.0, base_kp=20.0, base_kd=4.0).rows(robot, Variables(robot))
    np.testing.assert_array_equal(full.qdd @ qdd, qdd)
    expected = np.concatenate([20.0 * diff[:6] - 4.0 * v[:6], 50.0 * diff[6:] - 10.0 * v[6:]])
    np.testing.assert_allclose(full.target, expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", ROBOTS)
def test_joint_trajectory_task_selects_the_named_joints(robots, name):
    robot = robots[name]
    q, v = _at(robot, 6)
    joints = list(robot.joint_names[1::4])
    idx_q = [robot.model.joints[robot.model.getJointId(j)].idx_q for j in joints]
    idx_v = [robot.model.joints[robot.model.getJointId(j)].idx_v for j in joints]
    task = JointTrajectoryTask(joints, kp=100.0, kd=20.0)
    rows = task.rows(robot, Variables(robot))  # holds the first seen positions
    np.testing.assert_array_equal(task.position, q[idx_q])
    qdd = np.random.default_rng(1).normal(size=robot.nv)
    np.testing.assert_array_equal(rows.qdd @ qdd, qdd[idx_v])
    np.testing.assert_allclose(rows.target, -20.0 * v[idx_v], atol=1e-12)
    task.position = q[idx_q] + 0.1
    task.velocity = np.full(len(joints), 0.5)
    task.acceleration = np.full(len(joints), 2.0)
    np.testing.assert_allclose(task.rows(robot, Variables(robot)).target,
                               2.0 + 100.0 * 0.1 + 20.0 * (0.5 - v[idx_v]), atol=1e-9)
    with pytest.raises(ValueError, match="unknown joints"):
        JointTrajectoryTask(["no_such_joint"]).rows(robot, Variables(robot))


def test_the_checks_detect_a_wrong_jacobian_or_drift(robots):
    """The comparisons above fail for rows of the right shape but the wrong kinematics: the
    frame Jacobian in the LOCAL frame instead of world axes, or the drift without its
    velocity-product part (the spatial instead of the classical acceleration)."""
    robot = robots["talos14"]
    q, v = _at(robot, 0)
    frame = _frames(robot)[0]
    pose = _fd.BodyPoint(robot, robot.frame_id(frame)).pose
    J, drift = _fd.jacobian_fd(robot, pose, q), _fd.drift_fd(robot, pose, q, v)
    fid = robot.frame_id(frame)
    local = pin.getFrameJacobian(robot.model, robot.data, fid, pin.LOCAL)
    spatial = pin.getFrameAcceleration(robot.model, robot.data, fid, pin.LOCAL_WORLD_ALIGNED).vector
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(local, J, atol=1e-8)
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(-spatial, -drift, rtol=1e-5, atol=1e-6)
    perturbed = robot.J_com.copy()
    perturbed[0, 7] += 1e-5
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(perturbed, _com_jacobian_and_drift(robot, q, v)[0], atol=1e-8)
