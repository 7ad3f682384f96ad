"""Robots described in MJCF (MuJoCo's XML): the Pinocchio model built from MuJoCo's own compile.

Why not Pinocchio's MJCF parser (``pin.buildModelFromMJCF``)? MJCF is defined by what MuJoCo's
compiler makes of it: default classes and ``childclass``, ``<compiler angle eulerseq autolimits
inertiafromgeom>``, ``<include>``, ``<frame>``, orientations given five ways, inertias computed from
meshes. Pinocchio's parser re-implements a part of that and refuses or misreads files that MuJoCo
compiles (e.g. Unitree H1's: "Keyframe size does not match model size"). Building from
``mujoco.MjModel`` takes the compiled numbers instead: every body's pose relative to its parent,
its mass, centre of mass and principal inertia, every joint's type, axis, position, range and
armature, the actuators' gear and force/control ranges, the keyframes and the geoms, all as
MuJoCo simulates them. The Pinocchio model then has MuJoCo's M(q) to round-off
(``tests/unit/test_robot_mjcf.py`` checks it at random configurations, and against the same robot
written as a URDF). The cost is the compile itself (meshes are read: 0.3-0.6 s for a Menagerie
robot).

What becomes of each MJCF element:

* the body holding a ``<freejoint>`` (or, in a file without one, the world's single child body) is
  the floating base; Pinocchio's root free flyer is put at that body's frame;
* a body with one hinge or slide joint becomes a Pinocchio revolute or prismatic joint at the
  joint's position in the body (axis along x, y or z gives RX/RY/RZ, any other axis an unaligned
  joint, as Pinocchio's URDF parser does); a hinge's ``range`` (when limited) is its position limit,
  an unlimited hinge has infinite limits;
* a body without joints is welded to its parent: its inertia is merged into the parent's joint,
  and it keeps a frame of its own name (``BODY`` frame) as a URDF fixed link does;
* every body gives a ``BODY`` frame, every joint a ``JOINT`` frame, every named site an
  ``OP_FRAME`` of the site's name;
* a joint's effort limit is its ``actuatorfrcrange`` when limited, else that of the actuators
  driving it: ``|gear| * forcerange`` when force-limited, else, for a motor (a direct torque
  actuator), ``|gear * gain| * ctrlrange``; a position or velocity servo without a force range
  gives no limit (the description must then give ``torque_limits.overrides``);
* ``armature`` of the joints comes along (:attr:`MjcfModel.armature`);
* keyframes are postures (``posture = "keyframe:<name>"``).

Refused with a message naming the body or the joint: ball joints, a second free joint, bodies with
more than one joint (MuJoCo's chained joints in one body have massless intermediate bodies in a
tree of one joint per body, which the twin cannot simulate), and a world with several moving
bodies.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from .description import DescriptionError

log = logging.getLogger(__name__)

#: the posture string prefix naming an MJCF keyframe
KEYFRAME_PREFIX = "keyframe:"
#: an axis whose components differ from a unit axis by less than this is taken as that axis
AXIS_TOLERANCE = 1e-9


@dataclass
class MjcfModel:
    """The Pinocchio model of an MJCF robot plus what the file says beyond the model."""

    model: pin.Model  # root joint: the free flyer at the floating base
    armature: dict[str, float]  # joint name -> armature (kg m^2), the nonzero ones
    keyframes: dict[str, dict[str, float]]  # keyframe name -> {joint name: angle}
    base_body: str
    #: joint name -> where its effort limit came from ("actuatorfrcrange", "forcerange", ...)
    effort_sources: dict[str, str] = field(default_factory=dict)
    mujoco_model: object = None  # the compiled mujoco.MjModel (geoms, for init-robot)


def is_mjcf(path: str | Path) -> bool:
    """True for an MJCF file: a ``.xml``/``.mjcf`` suffix whose root element is ``<mujoco>``, or
    any file whose root element is ``<mujoco>`` (read up to the first element)."""
    path = Path(path)
    if path.suffix.lower() == ".urdf":
        return False
    import xml.etree.ElementTree as ET

    try:
        for _, element in ET.iterparse(path, events=("start",)):
            return element.tag == "mujoco"
    except ET.ParseError:
        return False
    return False


def compile_mjcf(path: str | Path, where: str = "robot"):
    """``mujoco.MjModel`` of the MJCF file at ``path``; DescriptionError with MuJoCo's message when
    it does not compile (a missing mesh file, an unknown attribute...)."""
    import mujoco

    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:
        message = str(exc).strip().replace("\n", " ")
        raise DescriptionError(f"{where}: MJCF file {path} does not compile in MuJoCo: "
                               f"{message}") from None


def _se3(pos, quat_wxyz) -> pin.SE3:
    w, x, y, z = (float(v) for v in quat_wxyz)
    return pin.SE3(pin.Quaternion(w, x, y, z).normalized().matrix(), np.asarray(pos, float))


def _axis_joint(kind: str, axis: np.ndarray):
    """Pinocchio joint model of a hinge (``kind`` "hinge") or slide about ``axis`` (unit)."""
    for i, letter in enumerate("XYZ"):
        if np.allclose(axis, np.eye(3)[i], atol=AXIS_TOLERANCE):
            return getattr(pin, f"JointModel{'R' if kind == 'hinge' else 'P'}{letter}")()
    if kind == "hinge":
        return pin.JointModelRevoluteUnaligned(axis)
    return pin.JointModelPrismaticUnaligned(axis)


def _effort_limits(m) -> tuple[np.ndarray, dict[int, str]]:
    """Per MuJoCo joint: the effort limit (N m or N; 0 for none) and where it came from."""
    import mujoco

    limit = np.zeros(m.njnt)
    source: dict[int, str] = {}
    for a in range(m.nu):
        if m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            continue
        j = int(m.actuator_trnid[a, 0])
        gear = abs(float(m.actuator_gear[a, 0]))
        motor = (m.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
                 and m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE)
        value, where = 0.0, ""
        if m.actuator_forcelimited[a]:
            value, where = gear * float(np.max(np.abs(m.actuator_forcerange[a]))), "forcerange"
        elif motor and m.actuator_ctrllimited[a]:
            gain = abs(float(m.actuator_gainprm[a, 0]))
            value = gear * gain * float(np.max(np.abs(m.actuator_ctrlrange[a])))
            where = "ctrlrange"
        if value > 0:
            limit[j] += value  # several actuators on one joint add up
            source[j] = where
    for j in range(m.njnt):
        if m.jnt_actfrclimited[j]:
            limit[j] = float(np.max(np.abs(m.jnt_actfrcrange[j])))
            source[j] = "actuatorfrcrange"
    return limit, source


def _floating_body(m, where: str) -> int:
    """The MuJoCo body id of the floating base."""
    import mujoco

    free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
    if len(free) > 1:
        names = [m.body(int(m.jnt_bodyid[j])).name for j in free]
        raise DescriptionError(f"{where}: the MJCF has {len(free)} free joints (bodies {names}); "
                               f"wholebody controls one floating robot: keep the robot's file "
                               f"only, not a scene with other free objects")
    if free:
        body = int(m.jnt_bodyid[free[0]])
        if m.body_parentid[body] != 0:
            raise DescriptionError(f"{where}: the free joint of body '{m.body(body).name}' is not "
                                   f"on a child of the world")
        return body
    roots = [b for b in range(1, m.nbody) if m.body_parentid[b] == 0
             and (m.body_jntnum[b] > 0 or any(m.body_rootid[c] == b and m.body_jntnum[c] > 0
                                              for c in range(1, m.nbody)))]
    if len(roots) != 1:
        names = [m.body(b).name for b in roots]
        raise DescriptionError(f"{where}: the MJCF has no free joint and {len(roots)} moving "
                               f"bodies under the world ({names}); give the robot's base a "
                               f"<freejoint/>")
    return roots[0]


def build_model(m, where: str = "robot") -> MjcfModel:
    """The Pinocchio model of the compiled MJCF ``m`` (a ``mujoco.MjModel``), floating base at the
    body of its free joint. DescriptionError naming the body or joint for what cannot be built."""
    import mujoco

    base = _floating_body(m, where)
    efforts, sources = _effort_limits(m)
    model = pin.Model()
    free = [j for j in range(m.njnt) if m.jnt_bodyid[j] == base
            and int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE)]
    root_name = (m.joint(free[0]).name if free else "") or "root_joint"
    root = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), root_name)
    model.addJointFrame(root, 0)
    # each MuJoCo body: (Pinocchio joint it moves with, its placement in that joint's frame, the
    # frame id of its BODY frame)
    where_is: dict[int, tuple[int, pin.SE3, int]] = {}
    armature: dict[str, float] = {}
    effort_sources: dict[str, str] = {}
    hinge, slide = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)

    def body_name(b: int) -> str:
        return m.body(b).name or f"body{b}"

    def add_body(b: int, joint: int, placement: pin.SE3, parent_frame: int) -> None:
        mass = float(m.body_mass[b])
        if mass > 0:
            rot = _se3(np.zeros(3), m.body_iquat[b]).rotation
            inertia = rot @ np.diag(m.body_inertia[b]) @ rot.T
            local = pin.Inertia(mass, np.asarray(m.body_ipos[b], float), inertia)
            model.appendBodyToJoint(joint, local, placement)
        frame = model.addBodyFrame(body_name(b), joint, placement, parent_frame)
        where_is[b] = (joint, placement, frame)

    add_body(base, root, pin.SE3.Identity(), int(model.getFrameId(model.names[root])))
    for b in range(base + 1, m.nbody):  # MuJoCo numbers bodies depth-first: parents first
        if m.body_rootid[b] != base:
            continue
        parent = int(m.body_parentid[b])
        parent_joint, parent_placement, parent_frame = where_is[parent]
        body_in_parent = parent_placement * _se3(m.body_pos[b], m.body_quat[b])
        njnt = int(m.body_jntnum[b])
        if njnt == 0:
            add_body(b, parent_joint, body_in_parent, parent_frame)
            continue
        if njnt > 1:
            names = [m.joint(int(m.body_jntadr[b]) + k).name for k in range(njnt)]
            raise DescriptionError(f"{where}: body '{body_name(b)}' has {njnt} joints {names}; "
                                   f"wholebody needs one joint per body: nest a body for each "
                                   f"joint in the MJCF")
        j = int(m.body_jntadr[b])
        name = m.joint(j).name or f"joint{j}"
        kind = int(m.jnt_type[j])
        if kind not in (hinge, slide):
            what = {int(mujoco.mjtJoint.mjJNT_BALL): "a ball joint",
                    int(mujoco.mjtJoint.mjJNT_FREE): "a free joint"}.get(int(kind), str(kind))
            raise DescriptionError(f"{where}: joint '{name}' of body '{body_name(b)}' is {what}; "
                                   f"wholebody reads hinge and slide joints only below the "
                                   f"floating base")
        axis = np.asarray(m.jnt_axis[j], float)
        axis = axis / np.linalg.norm(axis)
        joint_model = _axis_joint("hinge" if kind == hinge else "slide", axis)
        offset = pin.SE3(np.eye(3), np.asarray(m.jnt_pos[j], float))  # joint position in the body
        lo, hi = (m.jnt_range[j] if m.jnt_limited[j] else (-np.inf, np.inf))
        jid = model.addJoint(parent_joint, joint_model, body_in_parent * offset, name,
                             np.array([efforts[j]]), np.array([np.inf]),
                             np.array([float(lo)]), np.array([float(hi)]))
        joint_frame = model.addJointFrame(jid, parent_frame)
        add_body(b, jid, offset.inverse(), joint_frame)
        dof = int(m.jnt_dofadr[j])
        if m.dof_armature[dof] > 0:
            armature[name] = float(m.dof_armature[dof])
        if j in sources:
            effort_sources[name] = sources[j]
    _add_sites(m, model, where_is)
    keyframes = _keyframes(m, model)
    return MjcfModel(model, armature, keyframes, body_name(base), effort_sources, m)


def _add_sites(m, model: pin.Model, where_is) -> None:
    for s in range(m.nsite):
        name, b = m.site(s).name, int(m.site_bodyid[s])
        if not name or b not in where_is:
            continue
        if model.existFrame(name):
            log.debug("MJCF site '%s' has the name of another frame: not added", name)
            continue
        joint, placement, frame = where_is[b]
        model.addFrame(pin.Frame(name, joint, frame,
                                 placement * _se3(m.site_pos[s], m.site_quat[s]),
                                 pin.FrameType.OP_FRAME))


def _keyframes(m, model: pin.Model) -> dict[str, dict[str, float]]:
    """Each keyframe as {joint name: angle} over the model's joints below the floating base."""
    import mujoco

    out = {}
    for k in range(m.nkey):
        name = m.key(k).name or f"key{k}"
        angles = {}
        for jid in range(2, model.njoints):
            j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, model.names[jid])
            angles[model.names[jid]] = float(m.key_qpos[k, m.jnt_qposadr[j]])
        out[name] = angles
    return out


def load_mjcf(path: str | Path, where: str = "robot") -> MjcfModel:
    """Compile the MJCF file at ``path`` with MuJoCo and build its Pinocchio model."""
    return build_model(compile_mjcf(path, where), where)
