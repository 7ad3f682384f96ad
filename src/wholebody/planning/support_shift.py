"""How low the CoG must go when it shifts over one sole, so that the other leg keeps its bend.

Before single support (Herzog et al. 2016, Sect. 5.4) the CoG moves over the stance sole with
both soles still on the floor. At the standing CoG height the pelvis then moves away from the
swing sole and the swing leg has to stretch: on robots whose legs are a large share of their
mass the pelvis moves far and the swing knee straightens onto its limit. Lowering the CoG by the
drop computed here keeps the swing leg's hip at its standing distance from its sole.
"""

from __future__ import annotations

import logging

import numpy as np
import pinocchio as pin

from ..robots.roles import leg_joints

log = logging.getLogger(__name__)

#: homotopy steps from the standing CoG to the one over the stance sole, and Gauss-Newton
#: iterations per step
SHIFT_STEPS, ITERATIONS = 10, 30
#: residual (m, rad) below which the kinematic solution counts as found
RESIDUAL_TOLERANCE = 1e-8
#: gain of the pull toward the posture in the constraints' nullspace (per iteration)
POSTURE_PULL = 0.3


def shifted_posture(robot, stance: str, swing: str) -> tuple[np.ndarray, float]:
    """A configuration with the CoG over ``stance``'s sole centre and the swing leg at its
    standing length → ``(q, residual)``.

    Kinematics only: from the robot's posture, both soles held in place, the CoG's horizontal
    position moved over the centre of ``stance``'s sole and the distance from the swing leg's
    first joint to ``swing``'s contact frame held at its standing value; the rest of the robot
    stays as close to the posture as those constraints allow (Gauss-Newton on Pinocchio's
    kinematics and CoG Jacobian with the posture pulled in the constraints' nullspace, the CoG
    target moved in :data:`SHIFT_STEPS`). ``residual``: the largest constraint error (m, rad).
    """
    model = robot.model
    data = model.createData()
    q = robot.q_ref.copy()
    stance_frame, swing_frame = robot.contact(stance).frame_id, robot.contact(swing).frame_id
    hip = model.getJointId(leg_joints(robot, swing)[0])
    pin.framesForwardKinematics(model, data, q)
    held = {f: data.oMf[f].copy() for f in (stance_frame, swing_frame)}
    leg_length = float(np.linalg.norm(data.oMi[hip].translation - data.oMf[swing_frame].translation))
    com0 = pin.centerOfMass(model, data, q).copy()
    target = held[stance_frame].translation[:2]
    residual = np.inf
    for s in np.linspace(0.0, 1.0, SHIFT_STEPS + 1)[1:]:
        goal = com0[:2] + s * (target - com0[:2])
        for _ in range(ITERATIONS):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            com = pin.centerOfMass(model, data, q, False)
            rows, jacobians = [], []
            for frame, placement in held.items():
                rows.append(pin.log6(placement.actInv(data.oMf[frame])).vector)
                jacobians.append(pin.getFrameJacobian(model, data, frame, pin.LOCAL))
            rows.append(com[:2] - goal)
            jacobians.append(pin.jacobianCenterOfMass(model, data, q, False)[:2])
            leg = data.oMi[hip].translation - data.oMf[swing_frame].translation
            length = float(np.linalg.norm(leg))
            rows.append(np.array([length - leg_length]))
            J_hip = pin.getJointJacobian(model, data, hip, pin.LOCAL_WORLD_ALIGNED)[:3]
            J_sole = pin.getFrameJacobian(model, data, swing_frame, pin.LOCAL_WORLD_ALIGNED)[:3]
            jacobians.append((leg / length) @ (J_hip - J_sole)[None])
            r, J = np.concatenate(rows), np.vstack(jacobians)
            residual = float(np.abs(r).max())
            pinv = np.linalg.pinv(J)
            step = -pinv @ r + POSTURE_PULL * (np.eye(model.nv) - pinv @ J) @ pin.difference(
                model, q, robot.q_ref)
            q = pin.integrate(model, q, step)
    return q, residual


def swing_leg_drop(robot, stance: str, swing: str) -> float:
    """The CoG drop (m, >= 0) that keeps the swing leg's bend once the CoG is over the stance sole:
    how far the CoG of :func:`shifted_posture` ends below its standing height; 0 if it would
    rise or that posture is not found (logged)."""
    q, residual = shifted_posture(robot, stance, swing)
    if not residual <= RESIDUAL_TOLERANCE:
        log.warning("swing_leg_drop: no posture puts the CoG over %s with %s's leg at its "
                    "standing length (residual %.3g); the shift keeps the standing height",
                    stance, swing, residual)
        return 0.0
    model = robot.model
    data = model.createData()
    standing = pin.centerOfMass(model, data, robot.q_ref)[2]
    return max(0.0, float(standing - pin.centerOfMass(model, data, q)[2]))
