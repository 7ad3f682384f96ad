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

from wholebody.planning.support_shift import shifted_posture, swing_leg_drop
from wholebody.robots.roles import leg_joints


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
