"""The CoG shift's posture before single support (:mod:`wholebody.planning.support_shift`),
checked with forward kinematics on a Data of its own: both soles where they stand, the CoG over
the stance sole's centre, the swing leg at its standing length; and the reason for the drop: at
the standing CoG height the same shift stretches the swing leg (a separate least-squares
solve with scipy)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import scipy.optimize

import wholebody as wb
from wholebody.planning.support_shift import (BEND_FRACTIONS, KEY_POSE_MARGIN, KEY_POSE_TOLERANCE,
                                              MAX_DROP, automatic_swing_bend, joint_limit_margin,
                                              key_pose, key_pose_problem, shift_key_pose,
                                              shifted_posture, support_posture, swing_leg_drop)
from wholebody.robots.roles import leg_joints

from conftest import ICUB_RIGHT_LEG_INERTIAS, icub_description


def _kinematics(robot, q):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data, pin.centerOfMass(robot.model, data, q).copy()


def _leg_length(robot, data, swing):
    hip = robot.model.getJointId(leg_joints(robot, swing)[0])
    return float(np.linalg.norm(data.oMi[hip].translation
                                - data.oMf[robot.contact(swing).frame_id].translation))


@pytest.mark.parametrize("name", ["talos14", "romeo"])
@pytest.mark.parametrize("side", [0, 1])
def test_shifted_posture_meets_its_constraints_below_the_standing_height(robots, name, side):
    robot = robots[name]
    stance, swing = robot.contact_names[side], robot.contact_names[1 - side]
    q, residual = shifted_posture(robot, stance, swing)
    assert residual < 1e-8
    standing, com0 = _kinematics(robot, robot.q_ref)
    shifted, com = _kinematics(robot, q)
    for contact in (stance, swing):
        frame = robot.contact(contact).frame_id
        assert np.abs(pin.log6(standing.oMf[frame].actInv(shifted.oMf[frame])).vector).max() < 1e-7
    np.testing.assert_allclose(com[:2], shifted.oMf[robot.contact(stance).frame_id].translation[:2],
                               atol=1e-7)
    assert abs(_leg_length(robot, shifted, swing) - _leg_length(robot, standing, swing)) < 1e-7
    drop = swing_leg_drop(robot, stance, swing)
    assert drop == pytest.approx(com0[2] - com[2], abs=1e-9)
    assert 0.0 < drop < 0.1 * com0[2]


@pytest.mark.parametrize("name", ["talos14", "romeo"])
def test_the_shift_at_standing_height_stretches_the_swing_leg(robots, name):
    """The same shift with the CoG held at its standing height (scipy's least squares over the
    joint and base coordinates, the posture as soft rows): the swing leg gets longer, which is
    what the drop undoes."""
    robot = robots[name]
    model = robot.model
    stance, swing = robot.contact_names
    standing, com0 = _kinematics(robot, robot.q_ref)
    target = com0.copy()
    target[:2] = standing.oMf[robot.contact(stance).frame_id].translation[:2]
    frames = [robot.contact(c).frame_id for c in (stance, swing)]

    def residuals(dq):
        q = pin.integrate(model, robot.q_ref, dq)
        data, com = _kinematics(robot, q)
        rows = [pin.log6(standing.oMf[f].actInv(data.oMf[f])).vector * 1e3 for f in frames]
        return np.concatenate(rows + [(com - target) * 1e3, 1e-2 * dq])

    dq = scipy.optimize.least_squares(residuals, np.zeros(model.nv), xtol=1e-14, ftol=1e-14).x
    q = pin.integrate(model, robot.q_ref, dq)
    data, com = _kinematics(robot, q)
    assert np.abs(com - target).max() < 1e-4
    assert _leg_length(robot, data, swing) > _leg_length(robot, standing, swing) + 1e-3


@pytest.mark.parametrize("lift", [0.0, 0.08])
def test_support_posture_meets_its_constraints(robots, lift):
    """Forward kinematics here: the stance sole where it stands, the swing sole raised by
    ``lift`` with its standing orientation, the CoG over the stance sole and 1.5 cm lower."""
    robot = robots["talos14"]
    stance, swing = robot.contact_names
    q, residual = support_posture(robot, stance, swing, 0.015, lift)
    assert residual < 1e-8
    standing, com0 = _kinematics(robot, robot.q_ref)
    posed, com = _kinematics(robot, q)
    s_frame, w_frame = robot.contact(stance).frame_id, robot.contact(swing).frame_id
    assert np.abs(pin.log6(standing.oMf[s_frame].actInv(posed.oMf[s_frame])).vector).max() < 1e-7
    np.testing.assert_allclose(posed.oMf[w_frame].translation,
                               standing.oMf[w_frame].translation + [0.0, 0.0, lift], atol=1e-7)
    np.testing.assert_allclose(posed.oMf[w_frame].rotation, standing.oMf[w_frame].rotation,
                               atol=1e-7)
    np.testing.assert_allclose(com, np.r_[standing.oMf[s_frame].translation[:2], com0[2] - 0.015],
                               atol=1e-7)


def test_joint_limit_margin_is_the_nearest_limit_over_the_range(robots):
    robot = robots["talos14"]
    model = robot.model
    name = robot.joint_names[3]
    i = model.joints[model.getJointId(name)].idx_q
    low, high = model.lowerPositionLimit[i], model.upperPositionLimit[i]
    q = robot.q_ref.copy()
    q[i] = low + 0.1 * (high - low)
    assert joint_limit_margin(robot, q, [name]) == pytest.approx(0.1)
    q[i] = high + 0.05 * (high - low)
    assert joint_limit_margin(robot, q, [name]) == pytest.approx(-0.05)
    # a joint without a finite range does not count
    saved = model.lowerPositionLimit[i], model.upperPositionLimit[i]
    try:
        model.lowerPositionLimit[i], model.upperPositionLimit[i] = -np.inf, np.inf
        assert joint_limit_margin(robot, q, [name]) == np.inf
        assert joint_limit_margin(robot, q, [name, robot.joint_names[2]]) < np.inf
    finally:
        model.lowerPositionLimit[i], model.upperPositionLimit[i] = saved


def test_automatic_bend_keeps_the_standing_height_where_the_drop_does_not_help(robots):
    """talos14's legs keep the same joint-limit margin at every fraction (its hip yaw is the
    nearest limit, which the drop does not move), so the paper's experiment keeps the standing
    height; romeo's lifted swing ankle is the nearest limit and the drop brings it nearer."""
    for name in ("talos14", "romeo"):
        robot = robots[name]
        stance, swing = robot.contact_names
        assert automatic_swing_bend(robot, stance, swing, 0.08) == 0.0
    assert BEND_FRACTIONS[0] == 0.0


def _inside_limits(robot, q, margin):
    """Whether every limited single-coordinate joint of ``q`` is ``margin`` of its range inside
    its limits (or no further out than the posture has it)."""
    model = robot.model
    for joint in model.joints[1:]:
        i = joint.idx_q
        low, high = model.lowerPositionLimit[i], model.upperPositionLimit[i]
        if joint.nq != 1 or not (np.isfinite(low) and np.isfinite(high)):
            continue
        inset = min(margin * (high - low), robot.q_ref[i] - low, high - robot.q_ref[i])
        if not low + inset - 1e-9 <= q[i] <= high - inset + 1e-9:
            return False
    return True


@pytest.mark.parametrize("name", ["talos14", "romeo"])
@pytest.mark.parametrize("lift", [0.0, 0.05])
def test_key_pose_meets_its_targets_inside_the_joint_limits(robots, name, lift):
    robot = robots[name]
    stance, swing = robot.contact_names
    drop = 0.02
    q, residual = key_pose(robot, stance, swing, drop, lift)
    assert residual < KEY_POSE_TOLERANCE
    standing, com0 = _kinematics(robot, robot.q_ref)
    posed, com = _kinematics(robot, q)
    for contact, rise in ((stance, 0.0), (swing, lift)):
        frame = robot.contact(contact).frame_id
        target = standing.oMf[frame].copy()
        target.translation = target.translation + np.array([0.0, 0.0, rise])
        assert np.abs(pin.log6(target.actInv(posed.oMf[frame])).vector).max() < KEY_POSE_TOLERANCE
    stance_centre = standing.oMf[robot.contact(stance).frame_id].translation
    np.testing.assert_allclose(com, [*stance_centre[:2], com0[2] - drop], atol=KEY_POSE_TOLERANCE)
    assert _inside_limits(robot, q, KEY_POSE_MARGIN)


def test_the_shift_goes_lower_when_the_joint_limits_need_it():
    """iCub's swing hip abduction ends before its pelvis is over the stance sole at the standing
    CoG height: the unbounded Gauss-Newton pose there takes a leg joint beyond its limits, no
    pose inside them is found, and the shift's key pose is lower, inside them, on its targets
    (forward kinematics)."""
    robot = wb.load_robot(icub_description(inertia_overrides=ICUB_RIGHT_LEG_INERTIAS))
    stance, swing = "left_sole", "right_sole"
    joints = leg_joints(robot, stance) + leg_joints(robot, swing)
    unbounded, _ = support_posture(robot, stance, swing, 0.0, 0.0)
    assert joint_limit_margin(robot, unbounded, joints) < 0.0
    assert key_pose(robot, stance, swing, 0.0)[1] > KEY_POSE_TOLERANCE
    drop, q, residual = shift_key_pose(robot, stance, swing, 0.0)
    assert residual < KEY_POSE_TOLERANCE
    assert 0.0 < drop <= MAX_DROP * _kinematics(robot, robot.q_ref)[1][2]
    assert _inside_limits(robot, q, KEY_POSE_MARGIN)
    standing, com0 = _kinematics(robot, robot.q_ref)
    posed, com = _kinematics(robot, q)
    for contact in (stance, swing):
        frame = robot.contact(contact).frame_id
        assert np.abs(pin.log6(standing.oMf[frame].actInv(posed.oMf[frame])).vector).max() < 1e-4
    np.testing.assert_allclose(com, [*standing.oMf[robot.contact(stance).frame_id].translation[:2],
                                     com0[2] - drop], atol=1e-4)


def test_shift_key_pose_keeps_a_drop_that_the_limits_allow(robots):
    robot = robots["talos14"]
    stance, swing = robot.contact_names
    drop, q, _ = shift_key_pose(robot, stance, swing, 0.01)
    assert drop == 0.01 and _inside_limits(robot, q, KEY_POSE_MARGIN)


def test_key_pose_jacobian_matches_finite_differences(robots):
    robot = robots["talos14"]
    errors, jacobian = key_pose_problem(robot, *robot.contact_names, 0.02, 0.03)
    step = 0.05 * np.random.default_rng(0).standard_normal(robot.model.nv)
    h = 1e-7
    numeric = np.column_stack([(errors(step + h * e) - errors(step - h * e)) / (2 * h)
                               for e in np.eye(robot.model.nv)])
    np.testing.assert_allclose(jacobian(step), numeric, atol=1e-7)
