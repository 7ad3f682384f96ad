"""What the legs can reach within their joint limits: how high a foot can rise, and how far a
slope stance moves them from their posture.

A swing lifts the foot by the planner's clearance above the higher of its lift-off and touchdown
points. On a slope, or where the trunk is lower than usual above the foot, that can ask more of a
leg than its joints allow (a knee folded onto its limit, a hip pitch at its stop), and the first
joint limit reached in swing is often where a run starts to fail. :func:`foot_lift` measures, once
per leg, how far the foot can go up along the trunk's vertical axis from its position in a
posture, its horizontal position in the trunk held, every leg joint kept ``margin`` (a share of its
range) inside its limits; :class:`~wholebody.planning.planner.GaitPlanner` caps each swing's apex
with it.

The search is a sequence of linear programs over the leg's joint steps (scipy's HiGHS): maximise
the foot's rise along the trunk's z axis, the horizontal drift a penalised slack (a leg that cannot
hold it, such as a two-joint leg sideways, still rises as far as it can), within the joints'
bounds and a trust region, until no step raises it.

:func:`slope_stance_change` stands the robot on a slope the way the gait planner does (the CoM at
its standing height above the slope, the feet at their horizontal offsets from it, the trunk
inclined by a share of the slope) and finds each leg's joints by joint-limited least squares
(scipy's ``lsq_linear``): how far that stance moves the legs from their posture.
:func:`terrain_alignment_for` uses it to choose how far the trunk follows a slope: the posture is
what the legs are built and tuned to stand in, and the controllers pull them toward it.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.optimize import linprog, lsq_linear

from ..robots.roles import leg_joints
from .footholds import Footprint
from .support_shift import joint_range, joint_step_bounds

#: share of each joint's range the reach keeps clear of its limits
REACH_MARGIN = 0.1
#: largest joint step of one linear program (rad or m)
_TRUST = 0.1
#: cost of a metre of horizontal drift against a metre of rise
_DRIFT_COST = 100.0


def _leg(robot, contact: str):
    """``contact``'s one-direction leg joints (revolute, prismatic, continuous): (idx_v, their
    ranges as (n, 2), (-inf, inf) rows for a joint without limits)."""
    model = robot.model
    joints = [model.joints[model.getJointId(j)] for j in leg_joints(robot, contact)]
    joints = [j for j in joints if j.nv == 1]
    ranges = [joint_range(model, j) or (-np.inf, np.inf) for j in joints]
    return (np.array([j.idx_v for j in joints], dtype=int), np.array(ranges).reshape(-1, 2),
            joints)


def _angles(q, joints) -> np.ndarray:
    """The joints' coordinates in ``q``: a one-coordinate joint's entry, a continuous joint's
    angle from its (cos, sin)."""
    return np.array([q[j.idx_q] if j.nq == 1 else np.arctan2(q[j.idx_q + 1], q[j.idx_q])
                     for j in joints])


def _moved(model, q, iv, step) -> np.ndarray:
    """``q`` moved by ``step`` of the joints at velocity indices ``iv`` (pin.integrate, so a
    continuous joint's (cos, sin) stays on its circle)."""
    dv = np.zeros(model.nv)
    dv[iv] = step
    return pin.integrate(model, q, dv)


def foot_lift(robot, contact: str, q=None, margin: float = REACH_MARGIN,
              up_to: float = np.inf, iterations: int = 60) -> float:
    """How far (m) ``contact``'s frame can rise along the base's z axis from where it is in ``q``
    (default: the posture ``robot.q_ref``), its position along the base's x and y held, with only
    its leg's joints moving and each kept ``margin`` times its range inside its limits (a joint
    already closer in ``q`` keeps where it is as its bound; :func:`~.support_shift.
    joint_step_bounds`); the search stops at ``up_to``. 0 when the leg cannot raise it."""
    model = robot.model
    data = model.createData()
    q = robot.q_ref.copy() if q is None else np.array(q, dtype=float)
    iv, _, _ = _leg(robot, contact)
    if len(iv) == 0:
        return 0.0
    lower, upper = joint_step_bounds(robot, margin, q)
    lo, hi = lower[iv], upper[iv]  # of the total step from q
    moved = np.zeros(len(iv))
    frame = robot.contact(contact).frame_id
    axes = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()  # base x, y, z in world
    pin.framesForwardKinematics(model, data, q)
    start = data.oMf[frame].translation.copy()
    n = len(iv)
    # variables: joint steps (n), drift slacks s+ (2), s- (2); minimise -rise + cost * |drift|
    cost = np.concatenate([np.zeros(n), np.full(4, _DRIFT_COST)])
    for _ in range(iterations):
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        J = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)[:3, iv]
        drift = axes[:, :2].T @ (data.oMf[frame].translation - start)
        cost[:n] = -(axes[:, 2] @ J)
        A_eq = np.hstack([axes[:, :2].T @ J, -np.eye(2), np.eye(2)])
        bounds = [(max(lo[k] - moved[k], -_TRUST), min(hi[k] - moved[k], _TRUST))
                  for k in range(n)] + [(0.0, None)] * 4
        step = linprog(cost, A_eq=A_eq, b_eq=-drift, bounds=bounds, method="highs")
        if step.status != 0:
            break
        dq = np.clip(moved + step.x[:n], lo, hi) - moved
        moved += dq
        q = _moved(model, q, iv, dq)
        pin.framesForwardKinematics(model, data, q)
        if (np.max(np.abs(dq)) < 1e-6
                or axes[:, 2] @ (data.oMf[frame].translation - start) >= up_to):
            break
    rise = float(axes[:, 2] @ (data.oMf[frame].translation - start))
    return min(max(rise, 0.0), up_to)


def slope_stance_change(robot, angle: float, alignment: float = 1.0, q=None,
                        iterations: int = 60) -> float:
    """How much a slope of ``angle`` (rad, rising along the heading; negative: descending) changes
    the legs' posture when the robot stands on it as the gait planner places it: the CoM at its
    standing height above the slope point under it, the trunk's inclination ``alignment`` times
    the slope's (:class:`~.trunk.TrunkReference`'s ``terrain_alignment``), each foot at its
    horizontal offset from the CoM (:meth:`Footprint.centered_on_com`) on the slope, its frame one
    radius along the slope's normal. Each leg's joints are solved from ``q`` (default the posture)
    by joint-limited least squares; the result is the largest move of a leg joint from ``q`` as a
    share of its range (inf if a foot cannot be reached within 1 mm)."""
    model = robot.model
    data = model.createData()
    q0 = robot.q_ref if q is None else np.asarray(q, dtype=float)
    q = q0.copy()
    footprint = Footprint.from_robot(robot, q).centered_on_com()
    tilt = np.arctan(alignment * np.tan(angle))
    R = pin.rpy.rpyToMatrix(0.0, -tilt, 0.0)  # nose up on a rising slope
    com = np.array([0.0, 0.0, footprint.com[2] + footprint.base_height])
    q[:3] = com - R @ footprint.com
    q[3:7] = pin.Quaternion(R).coeffs()
    normal = np.array([-np.sin(angle), 0.0, np.cos(angle)])
    change = 0.0
    feet = footprint.feet_from_com()
    for k, leg in enumerate(footprint.legs):
        iv, ranges, joints = _leg(robot, leg)
        if len(iv) == 0:
            continue
        lo, hi = ranges[:, 0], ranges[:, 1]
        x, y = feet[k]
        target = np.array([x, y, np.tan(angle) * x]) + footprint.foot_radius[k] * normal
        frame = robot.contact(leg).frame_id
        for _ in range(iterations):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            error = target - data.oMf[frame].translation
            if np.linalg.norm(error) < 1e-6:
                break
            J = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)[:3, iv]
            angles = _angles(q, joints)
            step = lsq_linear(J, error, bounds=(lo - angles, hi - angles + 1e-12))
            q = _moved(model, q, iv, np.clip(angles + step.x, lo, hi) - angles)
        pin.framesForwardKinematics(model, data, q)
        if np.linalg.norm(target - data.oMf[frame].translation) > 1e-3:
            return np.inf
        # a joint without limits moves no share of a range
        change = max(change, float(np.max(np.abs(_angles(q, joints) - _angles(q0, joints))
                                           / (hi - lo))))
    return change


def terrain_alignment_for(robot, angle: float) -> tuple[float, dict]:
    """How far the trunk should follow slopes of ``angle`` (rad, up and down): whichever of 1
    (parallel to the slope, as on the ramps of Fahmi et al. 2019, Figs. 4, 7, 8) and 0 (level)
    changes the legs' posture less (:func:`slope_stance_change`, the worse of up and down); 1 on
    a tie. Returns the share and the two changes ({1.0: ..., 0.0: ...})."""
    changes = {a: max(slope_stance_change(robot, angle, a), slope_stance_change(robot, -angle, a))
               for a in (1.0, 0.0)}
    return (0.0 if changes[0.0] < changes[1.0] else 1.0), changes
