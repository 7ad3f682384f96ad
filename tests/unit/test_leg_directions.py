"""The directions a leg cannot move its contact (:func:`wholebody.robots.roles.
leg_missing_directions`) and the humanoid stacks' contact damping where there is one."""

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.control.stacks import POSTURE_PD, table1_stack, table2_stack, table4_stack
from wholebody.robots.roles import leg_joints, leg_missing_directions


def finite_difference_leg_jacobian(robot, contact: str, eps: float = 1e-7) -> np.ndarray:
    """The contact frame's motion (log of its placement change, in its own axes; linear rows in
    standing base heights) per leg joint's angle, by forward finite differences of the
    kinematics at the reference posture."""
    frame = robot.contact(contact).frame_id

    def placement(q):
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, q)
        return data.oMf[frame].copy()

    M0 = placement(robot.q_ref)
    columns = []
    for joint in leg_joints(robot, contact):
        q = robot.q_ref.copy()
        q[7 + robot.joint_names.index(joint)] += eps
        columns.append(pin.log6(M0.actInv(placement(q))).vector / eps)
    J = np.array(columns).T
    J[:3] /= robot.q_ref[2]
    return J


@pytest.fixture(scope="module")
def five_joint(tmp_path_factory):
    from conftest import talos14_five_joint_toml

    path = tmp_path_factory.mktemp("five") / "talos14_five.toml"
    path.write_text(talos14_five_joint_toml())
    return wb.load_robot(path)


def test_a_five_joint_leg_cannot_roll_its_sole(five_joint):
    """talos14 with its ankle rolls locked: one direction per sole, orthogonal to every column
    of the finite-difference leg Jacobian, whose smallest singular value vanishes along it. As a
    wrench (linear part over the base height, the rows' scaling) it is a sideways force through
    the hip-roll joint's origin (Pinocchio's placement): a roll moment at the sole with a
    sideways force, which no leg joint resists."""
    data = five_joint.model.createData()
    pin.framesForwardKinematics(five_joint.model, data, five_joint.q_ref)
    for name in five_joint.contact_names:
        directions = leg_missing_directions(five_joint, name)
        assert directions.shape == (1, 6)
        u = directions[0]
        assert np.linalg.norm(u) == pytest.approx(1.0)
        force, moment = u[:3] / five_joint.q_ref[2], u[3:]
        assert abs(force[1]) > 100 * max(abs(force[0]), abs(force[2]))
        hip_roll = five_joint.model.getJointId(leg_joints(five_joint, name)[1])
        sole = data.oMf[five_joint.contact(name).frame_id]
        p = sole.actInv(data.oMi[hip_roll]).translation
        assert np.allclose(moment - np.cross(p, force), 0.0, atol=1e-6)
        assert abs(moment[0]) > 0.5  # the sole's roll moment, its lateral CoP
        J = finite_difference_leg_jacobian(five_joint, name)
        assert np.abs(u @ J).max() < 1e-5 * np.abs(J).max()
        left, sv, _ = np.linalg.svd(J)
        assert sv[-1] > 1e-2 * sv[0]  # five independent motions: the sixth is u
        assert abs(left[:, 5] @ u) == pytest.approx(1.0, abs=1e-5)


@pytest.mark.parametrize("name", ["talos14", "hyq"])
def test_six_joint_legs_and_three_joint_legs_miss_nothing(robots, name):
    """talos14's soles on six-joint legs, HyQ's point feet on three-joint legs: the leg moves its
    contact every way it constrains (full rank of the finite-difference Jacobian's rows)."""
    robot = robots[name]
    for contact in robot.contact_names:
        dim = robot.contact(contact).dim
        assert leg_missing_directions(robot, contact).shape == (0, dim)
        J = finite_difference_leg_jacobian(robot, contact)[:dim] if dim == 6 else None
        if J is not None:
            sv = np.linalg.svd(J, compute_uv=False)
            assert sv[-1] > 1e-2 * sv[0]


def test_the_stacks_damp_the_contacts_of_five_joint_legs_only(robots, five_joint):
    """Eq. 2's constraint as the paper writes it (no damping) on six-joint legs; with the
    posture's damping on five-joint legs, in Tables 1, 2 and 4 alike."""
    talos14 = robots["talos14"]
    for robot, damped in ((talos14, False), (five_joint, True)):
        left, right = robot.contact_names
        for gains in (POSTURE_PD, (50.0, 7.0)):
            for stack in (table2_stack(robot, posture_gains=gains),
                          table4_stack(robot, [left], posture_gains=gains),
                          table1_stack(robot, [left, right], posture_gains=gains)):
                task = stack.find("contacts")
                assert task.kd == (gains[1] if damped else 0.0) and task.kp == 0.0
