"""Contact roles: which contact is a quadruped's left-front foot, which a biped's left sole.

Controllers and scenarios address feet and soles by role, never by name, so that a robot's own
contact names (``FL_foot``, ``LF_FOOT``, ``l_sole``) work as they are. A role is declared in the
description (``role = "left-front"`` on a contact) or, where none is, found from where the
contacts are in the reference posture, in the base frame (x forward, y left): four point contacts
are the feet of a quadruped, front/hind by the sign of x about their centre and left/right by the
sign of y (the base's sagittal plane); two rectangles are the soles of a biped, left/right by y.
"""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin

from .description import ROLES, DescriptionError

#: a quadruped's feet in the order the gait schedules take them (LF, RF, LH, RH)
QUADRUPED_ROLES = ROLES["point"]
#: a biped's soles (left, right)
BIPED_ROLES = ROLES["rectangle"]


def contact_roles(robot) -> dict[str, str]:
    """{role: contact name} for a quadruped (four point contacts) or a biped (two rectangles);
    {} for any other set of contacts. Declared roles are used when every contact declares one;
    otherwise all are found from the geometry (module docstring). DescriptionError when some but
    not all contacts declare a role, or when the geometry does not tell them apart (e.g. two feet
    on the same side), naming the contacts and what to declare."""
    contacts = robot.contacts
    kinds = {c.spec.type for c in contacts}
    if len(kinds) != 1 or len(contacts) != {"point": 4, "rectangle": 2}[kinds.pop()]:
        return {}
    kind = contacts[0].spec.type
    declared = [c.spec.role for c in contacts]
    where = f"robot '{robot.name}'"
    if all(role is not None for role in declared):
        return {c.spec.role: c.name for c in contacts}
    if any(role is not None for role in declared):
        missing = [c.name for c in contacts if c.spec.role is None]
        raise DescriptionError(f"{where}: contacts {missing} declare no role while others do; "
                               f"declare one of {ROLES[kind]} on every contact or on none")
    xy = _base_frame_positions(robot)[:, :2]
    xy[:, 0] -= xy[:, 0].mean()  # front/hind about the feet's centre, left/right about the base
    if kind == "point":
        roles = [("left" if y > 0 else "right") + ("-front" if x > 0 else "-hind") for x, y in xy]
    else:
        roles = ["left" if y > 0 else "right" for y in xy[:, 1]]
    if len(set(roles)) != len(roles):
        found = ", ".join(f"{c.name}: {r}" for c, r in zip(contacts, roles))
        raise DescriptionError(f"{where}: the contacts' positions do not tell which is which "
                               f"({found}); declare role = one of {ROLES[kind]} on each contact")
    return {role: c.name for role, c in zip(roles, contacts)}


_SIDES = {"l": "left", "r": "right"}
_ENDS = {"f": "front", "h": "hind", "b": "hind", "r": "hind"}  # r: rear (FL, FR, RL, RR)


def role_in_name(name: str, kind: str) -> str | None:
    """The role a contact's name spells, or None: the words left/right (and front/fore,
    hind/rear/back for a foot), or a foot's two-letter tag side-first (``LF``, ``RH``, ``LB``)
    or end-first (``FL``, ``RR``, ``BL``). Only a hint for check-robot, never used to assign."""
    low = name.lower()
    words = [w for w in re.split(r"[^a-z]+", low) if w]
    side = next((s for s in ("left", "right") if s in low), None)
    if side is None and kind == "rectangle":
        side = next((_SIDES[w] for w in words if w in _SIDES), None)
    if kind == "rectangle":
        return side
    end = next((e for word, e in (("front", "front"), ("fore", "front"), ("hind", "hind"),
                                  ("rear", "hind"), ("back", "hind")) if word in low), None)
    for w in words:
        if side is not None and end is not None:
            break
        if len(w) == 2 and w[0] in _SIDES and w[1] in "fhb":
            side, end = side or _SIDES[w[0]], end or _ENDS[w[1]]
        elif len(w) == 2 and w[0] in _ENDS and w[1] in _SIDES:
            side, end = side or _SIDES[w[1]], end or _ENDS[w[0]]
    return f"{side}-{end}" if side and end else None


def quadruped_legs(robot) -> tuple[str, ...]:
    """The contact names of the four feet in the order (LF, RF, LH, RH); ValueError unless the
    robot has four point contacts."""
    roles = contact_roles(robot)
    if set(roles) != set(QUADRUPED_ROLES):
        raise ValueError(f"robot '{robot.name}': a quadruped needs four point-foot contacts; it has "
                         f"{_listed(robot)}")
    return tuple(roles[r] for r in QUADRUPED_ROLES)


def biped_soles(robot) -> tuple[str, str]:
    """The contact names of the (left, right) soles; ValueError unless the robot has two
    rectangular contacts."""
    roles = contact_roles(robot)
    if set(roles) != set(BIPED_ROLES):
        raise ValueError(f"robot '{robot.name}': a biped needs two rectangular sole contacts; it "
                         f"has {_listed(robot)}")
    return roles["left"], roles["right"]


def leg_joints(robot, contact: str) -> tuple[str, ...]:
    """The actuated joints between the floating base and ``contact``'s frame, base first (a
    quadruped leg's hip abduction, hip flexion, knee; a humanoid's hip yaw ... ankle roll)."""
    model = robot.model
    joint = model.frames[robot.contact(contact).frame_id].parentJoint
    chain = []
    while joint > 1:  # 0 is the universe, 1 the free flyer
        chain.append(model.names[joint])
        joint = model.parents[joint]
    return tuple(reversed(chain))


def leg_missing_directions(robot, contact: str) -> np.ndarray:
    """The directions in which ``contact``'s leg cannot move the contact frame relative to the
    trunk, in the reference posture: the left null space of the leg's Jacobian (its joints'
    columns, :func:`leg_joints`; the rows the contact constrains, [linear; angular] in the
    contact frame, linear rows in standing base heights so that translations and rotations
    compare). One unit row per direction: none (shape (0, dim)) when the leg moves its contact
    every way the contact constrains (a sole on a six-joint leg, a point foot on a three-joint
    leg), all of them for a contact on the base. A five-joint leg (no ankle roll) leaves its
    sole one, a roll about the sole's x axis with a sideways slide: as a wrench, a sideways force
    through the hip-roll axis."""
    c = robot.contact(contact)
    columns = [6 + robot.joint_names.index(j) for j in leg_joints(robot, contact)]
    if not columns:
        return np.eye(c.dim)
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, robot.q_ref)
    leg = pin.getFrameJacobian(robot.model, data, c.frame_id, pin.LOCAL)[:c.dim][:, columns]
    leg[:3] /= float(robot.q_ref[2])
    u, sv, _ = np.linalg.svd(leg)
    rank = int(np.sum(sv > 1e-6 * sv[0]))
    return u[:, rank:].T.copy()


def moving_leg_joints(robot, contact: str) -> tuple[str, ...]:
    """:func:`leg_joints` of ``contact`` that can move: a range wider than 1e-6 rad (a joint
    whose limits are equal is a fixed joint in disguise)."""
    index = {name: i for i, name in enumerate(robot.joint_names)}
    return tuple(j for j in leg_joints(robot, contact)
                 if j not in index or not robot.q_max[index[j]] - robot.q_min[index[j]] <= 1e-6)


#: moving joints per leg each gait needs: a crawl steps one foot at a time, a foot moving in the
#: leg's plane; a trot stands on two point feet and must also move them sideways
GAIT_LEG_JOINTS = {"crawl": 2, "trot": 3}


def check_gait_legs(robot, legs, gait: str, what: str) -> None:
    """ValueError naming ``what`` unless every leg of ``legs`` (contact names) has the moving
    joints ``gait`` needs (:data:`GAIT_LEG_JOINTS`)."""
    need = GAIT_LEG_JOINTS.get(gait, 0)
    short = {leg: moving_leg_joints(robot, leg) for leg in legs}
    short = {leg: joints for leg, joints in short.items() if len(joints) < need}
    if short:
        listed = "; ".join(f"{leg}: {', '.join(j) or 'none'}" for leg, j in short.items())
        raise ValueError(f"{what}: a {gait} needs legs of at least {need} moving joints; "
                         f"{robot.name}'s have fewer ({listed}; joints with equal limits do not "
                         f"count)" + ("; --set gait=crawl walks it" if gait == "trot" and all(
                             len(j) >= GAIT_LEG_JOINTS["crawl"] for j in short.values()) else ""))


def joint_axis(robot, joint: str, data=None) -> np.ndarray:
    """The unit rotation axis of the revolute ``joint`` in its own frame (from its motion
    subspace; the axis is fixed in that frame). ``data``: a Pinocchio data after forward
    kinematics (default: a new one at the reference posture)."""
    model = robot.model
    jid = model.getJointId(joint)
    if data is None:
        data = model.createData()
        pin.forwardKinematics(model, data, robot.q_ref)
    angular = np.asarray(data.joints[jid].S).reshape(6, -1)[3:, 0]
    return angular / np.linalg.norm(angular)


def pitch_joints(robot, contact: str) -> tuple[tuple[str, float], ...]:
    """The joints of ``contact``'s leg that flex it in the sagittal plane, base first (a humanoid's
    hip flexion, knee, ankle flexion), each with the sign of its axis along the base's y (left):
    those whose axis is within 30 deg of the base's lateral axis in the reference posture."""
    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, robot.q_ref)
    base = data.oMi[1].rotation
    out = []
    for joint in leg_joints(robot, contact):
        axis = base.T @ data.oMi[model.getJointId(joint)].rotation @ joint_axis(robot, joint, data)
        if abs(axis[1]) > np.cos(np.radians(30.0)):
            out.append((joint, float(np.sign(axis[1]))))
    return tuple(out)


def foot_of_joint(robot, joint: str) -> str | None:
    """The contact whose leg (:func:`leg_joints`) holds ``joint``; None if no contact's does."""
    return next((c.name for c in robot.contacts if joint in leg_joints(robot, c.name)), None)


def _base_frame_positions(robot) -> np.ndarray:
    """(n, 3) contact frame origins in the base frame at the reference posture."""
    q = robot.q_ref
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
    return np.array([R.T @ (data.oMf[c.frame_id].translation - q[:3]) for c in robot.contacts])


def _listed(robot) -> str:
    return ", ".join(f"{c.name} ({c.spec.type})" for c in robot.contacts) or "no contacts"
