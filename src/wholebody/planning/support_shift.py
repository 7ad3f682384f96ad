"""How low the CoG must go when it shifts over one sole, so that the other leg keeps its bend.

Before single support (Herzog et al. 2016, Sect. 5.4) the CoG moves over the stance sole with
both soles still on the floor. At the standing CoG height the pelvis then moves away from the
swing sole and the swing leg has to stretch: on robots whose legs are a large share of their
mass the pelvis moves far and the swing knee straightens onto its limit. Lowering the CoG by the
drop computed here keeps the swing leg's hip at its standing distance from its sole; lowered
too far, the lifted leg runs into its ankle or knee limits instead. :func:`automatic_swing_bend`
chooses the fraction of that drop from the legs' joint-limit margins in both key poses.
:func:`shift_key_pose` is the pose the shift ends in, inside the joint limits (the posture
reference follows it during the shift), and lowers the CoG further when the limits need it.
"""

from __future__ import annotations

import logging

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

from ..robots.roles import leg_joints

log = logging.getLogger(__name__)

#: homotopy steps from the standing CoG to the one over the stance sole, and Gauss-Newton
#: iterations per step
SHIFT_STEPS, ITERATIONS = 10, 30
#: residual (m, rad) below which the kinematic solution counts as found
RESIDUAL_TOLERANCE = 1e-8
#: gain of the pull toward the posture in the constraints' nullspace (per iteration)
POSTURE_PULL = 0.3
#: the fractions of the drop :func:`automatic_swing_bend` chooses from
BEND_FRACTIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
#: joint-limit margins (fractions of the joint's range) this close count as equal
MARGIN_TIE = 0.01
#: :func:`key_pose`: the joints stay this fraction of their range inside their limits (or where
#: the posture has them, if nearer); the CoG's and the posture's weights against the soles' 1
#: (m, rad); the largest sole or CoG error (m, rad) of a pose that counts as found
KEY_POSE_MARGIN = 0.05
KEY_POSE_COG_WEIGHT, KEY_POSE_POSTURE_WEIGHT = 0.1, 1e-4
KEY_POSE_TOLERANCE = 1e-4
#: :func:`shift_key_pose` lowers the CoG in steps of this fraction of its standing height, down
#: to MAX_DROP of it, until the shifted pose is found within the limits
DROP_STEP, MAX_DROP = 0.01, 0.15


def _homotopy(robot, constraints) -> tuple[np.ndarray, float]:
    """Gauss-Newton from the posture on ``constraints(model, data, q, s) -> (residuals,
    jacobians)`` (lists of arrays; Pinocchio's kinematics and Jacobians are computed before each
    call), the targets moved with ``s`` over :data:`SHIFT_STEPS`, the posture pulled in the
    constraints' nullspace → ``(q, largest residual)``."""
    model = robot.model
    data = model.createData()
    q = robot.q_ref.copy()
    residual = np.inf
    for s in np.linspace(0.0, 1.0, SHIFT_STEPS + 1)[1:]:
        for _ in range(ITERATIONS):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            rows, jacobians = constraints(model, data, q, s)
            r, J = np.concatenate(rows), np.vstack(jacobians)
            residual = float(np.abs(r).max())
            pinv = np.linalg.pinv(J)
            step = -pinv @ r + POSTURE_PULL * (np.eye(model.nv) - pinv @ J) @ pin.difference(
                model, q, robot.q_ref)
            q = pin.integrate(model, q, step)
    return q, residual


def _standing(robot, frames) -> tuple[dict, np.ndarray, pin.Data]:
    """The placements of ``frames``, the CoG and the kinematics (joint placements) in the
    posture."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    return ({f: data.oMf[f].copy() for f in frames},
            pin.centerOfMass(robot.model, data, robot.q_ref).copy(), data)


def _held(model, data, placements) -> tuple[list, list]:
    """Residuals and Jacobians (LOCAL) of frames held at ``placements``."""
    return ([pin.log6(M.actInv(data.oMf[f])).vector for f, M in placements.items()],
            [pin.getFrameJacobian(model, data, f, pin.LOCAL) for f in placements])


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
    stance_frame, swing_frame = robot.contact(stance).frame_id, robot.contact(swing).frame_id
    hip = robot.model.getJointId(leg_joints(robot, swing)[0])
    held, com0, data0 = _standing(robot, (stance_frame, swing_frame))
    leg_length = float(np.linalg.norm(data0.oMi[hip].translation - held[swing_frame].translation))
    target = held[stance_frame].translation[:2]

    def constraints(model, data, q, s):
        rows, jacobians = _held(model, data, held)
        com = pin.centerOfMass(model, data, q, False)
        rows.append(com[:2] - (com0[:2] + s * (target - com0[:2])))
        jacobians.append(pin.jacobianCenterOfMass(model, data, q, False)[:2])
        leg = data.oMi[hip].translation - data.oMf[swing_frame].translation
        length = float(np.linalg.norm(leg))
        rows.append(np.array([length - leg_length]))
        J_hip = pin.getJointJacobian(model, data, hip, pin.LOCAL_WORLD_ALIGNED)[:3]
        J_sole = pin.getFrameJacobian(model, data, swing_frame, pin.LOCAL_WORLD_ALIGNED)[:3]
        jacobians.append((leg / length) @ (J_hip - J_sole)[None])
        return rows, jacobians

    return _homotopy(robot, constraints)


def support_posture(robot, stance: str, swing: str, drop: float, lift: float
                    ) -> tuple[np.ndarray, float]:
    """A configuration of single support's key poses → ``(q, residual)``: ``stance``'s sole in
    place, ``swing``'s sole raised by ``lift`` (m, 0 for the shift with both soles down) with its
    standing orientation, the CoG over the stance sole's centre and ``drop`` (m) below its standing
    height; the rest as close to the posture as that allows (as :func:`shifted_posture`)."""
    stance_frame, swing_frame = robot.contact(stance).frame_id, robot.contact(swing).frame_id
    held, com0, _ = _standing(robot, (stance_frame, swing_frame))
    target = np.r_[held[stance_frame].translation[:2], com0[2] - drop]

    def constraints(model, data, q, s):
        raised = held[swing_frame].copy()
        raised.translation = raised.translation + np.array([0.0, 0.0, s * lift])
        rows, jacobians = _held(model, data, {stance_frame: held[stance_frame],
                                              swing_frame: raised})
        rows.append(pin.centerOfMass(model, data, q, False) - (com0 + s * (target - com0)))
        jacobians.append(pin.jacobianCenterOfMass(model, data, q, False))
        return rows, jacobians

    return _homotopy(robot, constraints)


def joint_range(model, joint) -> tuple[float, float] | None:
    """(lower, upper) position limits of a single-coordinate joint with a finite range, else
    None (continuous and multi-coordinate joints, the free flyer, and a joint whose URDF gives
    no limits, which Pinocchio stores as +-max float: a range that overflows)."""
    i = joint.idx_q
    low, high = model.lowerPositionLimit[i], model.upperPositionLimit[i]
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.isfinite(high - low)
    if joint.nq != 1 or not (finite and high > low):
        return None
    return float(low), float(high)


def joint_step_bounds(robot, margin: float, q=None) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of a tangent step from ``q`` (default the posture; nv): ``margin`` of each limited
    joint's range inside its limits (no further than ``q`` itself is); the base and unlimited or
    multi-coordinate joints free."""
    model = robot.model
    q0 = robot.q_ref if q is None else np.asarray(q, dtype=float)
    lower, upper = np.full(model.nv, -np.inf), np.full(model.nv, np.inf)
    for joint in model.joints[1:]:
        limits = joint_range(model, joint)
        if limits is None:
            continue
        (low, high), i, k = limits, joint.idx_q, joint.idx_v
        inset = min(margin * (high - low), q0[i] - low, high - q0[i])
        lower[k], upper[k] = low + inset - q0[i], high - inset - q0[i]
    return lower, upper


def key_pose_problem(robot, stance: str, swing: str, drop: float, lift: float = 0.0):
    """The least squares of :func:`key_pose` → ``(errors, jacobian)``, functions of a step from
    the posture (nv): the soles' placement errors (log6, weight 1), the CoG's error
    (:data:`KEY_POSE_COG_WEIGHT`) and the step itself (:data:`KEY_POSE_POSTURE_WEIGHT`), and their
    derivative through the tangent map of ``pin.integrate``."""
    model = robot.model
    data = model.createData()
    stance_frame, swing_frame = robot.contact(stance).frame_id, robot.contact(swing).frame_id
    held, com0, _ = _standing(robot, (stance_frame, swing_frame))
    held[swing_frame].translation = held[swing_frame].translation + np.array([0.0, 0.0, lift])
    target = np.r_[held[stance_frame].translation[:2], com0[2] - drop]

    def errors(step):
        q = pin.integrate(model, robot.q_ref, step)
        pin.framesForwardKinematics(model, data, q)
        soles = [pin.log6(M.actInv(data.oMf[f])).vector for f, M in held.items()]
        return np.concatenate([*soles, KEY_POSE_COG_WEIGHT * (pin.centerOfMass(model, data, q)
                                                              - target),
                               KEY_POSE_POSTURE_WEIGHT * step])

    def jacobian(step):
        q = pin.integrate(model, robot.q_ref, step)
        d_q = pin.dIntegrate(model, robot.q_ref, step, pin.ArgumentPosition.ARG1)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        rows = [pin.Jlog6(M.actInv(data.oMf[f])) @ pin.getFrameJacobian(model, data, f, pin.LOCAL)
                for f, M in held.items()]
        rows.append(KEY_POSE_COG_WEIGHT * pin.jacobianCenterOfMass(model, data, q, False))
        return np.vstack([np.vstack(rows) @ d_q, KEY_POSE_POSTURE_WEIGHT * np.eye(model.nv)])

    return errors, jacobian


def key_pose(robot, stance: str, swing: str, drop: float, lift: float = 0.0
             ) -> tuple[np.ndarray, float]:
    """:func:`support_posture`'s key pose inside the joint limits → ``(q, residual)``:
    ``stance``'s sole in place, ``swing``'s raised by ``lift`` (m), the CoG over the stance sole's
    centre and ``drop`` (m) below its standing height, every joint at least
    :data:`KEY_POSE_MARGIN` of its range inside its limits: :func:`key_pose_problem` solved by
    scipy's bounded least squares (trust-region reflective), the step's weight keeping the rest
    near the posture. ``residual``: the largest sole (m, rad) or CoG (m) error; the pose is found
    when it is below :data:`KEY_POSE_TOLERANCE`."""
    errors, jacobian = key_pose_problem(robot, stance, swing, drop, lift)
    fit = least_squares(errors, np.zeros(robot.model.nv), jac=jacobian,
                        bounds=joint_step_bounds(robot, KEY_POSE_MARGIN),
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    residual = np.abs(fit.fun[:15] / np.r_[np.ones(12), np.full(3, KEY_POSE_COG_WEIGHT)]).max()
    return pin.integrate(robot.model, robot.q_ref, fit.x), float(residual)


def shift_key_pose(robot, stance: str, swing: str, drop: float
                   ) -> tuple[float, np.ndarray, float]:
    """The pose the CoG shift ends in and its drop → ``(drop, q, residual)``: :func:`key_pose`
    with both soles down, at ``drop`` or, when the joint limits leave no such pose (a swing hip
    whose abduction range ends before the pelvis is over the stance sole), at the smallest drop in
    steps of :data:`DROP_STEP` of the standing CoG height that has one (logged); if none down to
    :data:`MAX_DROP` has, ``drop``, its closest pose and that pose's residual (above
    :data:`KEY_POSE_TOLERANCE`; logged)."""
    com_height = float(pin.centerOfMass(robot.model, robot.model.createData(), robot.q_ref)[2])
    q, residual = key_pose(robot, stance, swing, drop)
    if residual <= KEY_POSE_TOLERANCE:
        return drop, q, residual
    first = (q, residual)
    step = DROP_STEP * com_height
    for lower in np.arange(drop + step, MAX_DROP * com_height, step):
        q, residual = key_pose(robot, stance, swing, float(lower))
        if residual <= KEY_POSE_TOLERANCE:
            log.info("single support on %s: the joint limits need the CoG %.1f mm lower for the "
                     "shift over %s (%.1f mm asked)", robot.name, 1e3 * lower, stance, 1e3 * drop)
            return float(lower), q, residual
    log.warning("single support on %s: no pose within the joint limits puts the CoG over %s "
                "(residual %.3g m at the %.1f mm drop asked); the shift goes on toward the "
                "closest", robot.name, stance, first[1], 1e3 * drop)
    return drop, first[0], first[1]


def joint_limit_margin(robot, q, joints) -> float:
    """The smallest distance of ``joints`` (names) from their nearest position limit, as a
    fraction of their range (negative beyond a limit); joints without a finite range (continuous
    ones) do not count (inf if none has one)."""
    model = robot.model
    margins = [np.inf]
    for name in joints:
        joint = model.joints[model.getJointId(name)]
        limits = joint_range(model, joint)
        if limits is None:
            continue
        (low, high), i = limits, joint.idx_q
        margins.append(min(q[i] - low, high - q[i]) / (high - low))
    return float(min(margins))


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


def automatic_swing_bend(robot, stance: str, swing: str, lift: float,
                         drop: float | None = None) -> float:
    """The fraction of :func:`swing_leg_drop` single support should lower the CoG by: of
    :data:`BEND_FRACTIONS`, the one whose key poses (:func:`support_posture` for the shift and
    for the lift by ``lift``) keep both legs' joints farthest from their limits
    (:func:`joint_limit_margin`, the worse pose counts), the smallest within
    :data:`MARGIN_TIE` of the best (the standing height when the drop does not matter).
    ``drop``: :func:`swing_leg_drop`'s value when the caller has it already."""
    drop = swing_leg_drop(robot, stance, swing) if drop is None else drop
    if drop <= 0.0:
        return 0.0
    joints = leg_joints(robot, stance) + leg_joints(robot, swing)
    margins = []
    for fraction in BEND_FRACTIONS:
        worst = np.inf
        for height in (0.0, lift):
            q, residual = support_posture(robot, stance, swing, fraction * drop, height)
            worst = min(worst, joint_limit_margin(robot, q, joints)
                        if residual <= RESIDUAL_TOLERANCE else -np.inf)
        margins.append(worst)
    best = max(margins)
    chosen = next(f for f, m in zip(BEND_FRACTIONS, margins) if m >= best - MARGIN_TIE)
    log.info("single support on %s: swing_bend %.2g (CoG %.1f mm lower; joint-limit margins %s "
             "for %s)", robot.name, chosen, 1e3 * chosen * drop,
             [round(m, 3) for m in margins], list(BEND_FRACTIONS))
    return chosen
