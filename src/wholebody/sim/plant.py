"""The vendor's own MuJoCo model as the simulated plant, in place of the exact twin.

The exact twin (:mod:`wholebody.sim.twin`) is generated from the controller's Pinocchio model, so
the controller knows the plant to round-off. A robot's vendor usually ships an MJCF of its own
(masses, armature, joint damping and friction loss, collision geoms, actuators) that differs from
the model the controller uses, the way the real robot does. :func:`build_plant` loads that file as
the plant, with the controller keeping its own model: a model-mismatch test against a second,
independently written model of the same robot.

How the vendor's model is joined to the controller's:

* **joints by name**: every actuated joint of the controller must be a hinge or slide of the
  plant's robot with the same name (the order may differ: the state is read and written through
  each joint's own address). A joint of the plant the controller does not have is refused, unless
  the description locks it (``locked_joints``): the plant then holds it at the posture with a
  joint equality constraint. Missing joints, extra joints and type mismatches are all named;
* **the floating base** is the body of the plant's free joint; a file without one gets a free
  joint on the world's moving child body (noted);
* **same kinematics**: at the reference posture, each mapped joint's anchor and axis are compared
  with the controller's; an axis more than :data:`AXIS_TOLERANCE_DEG` apart or an anchor more than
  :data:`ANCHOR_TOLERANCE` standing base heights apart is refused (not the same robot, or a joint
  whose zero or sign differs), smaller differences are noted;
* **torques through the vendor's actuators** when each controller joint is driven by exactly one
  direct-torque motor (fixed gain, no bias, no activation dynamics): the control is
  ``tau / (gear * gain)`` and the vendor's control, force and actuator-force ranges become torque
  bounds of their own, applied by the simulator before MuJoCo would clamp silently. Otherwise
  (position or velocity servos, a joint without an actuator or with several) the vendor's
  actuators are removed and each joint gets a motor of gear 1: the controller commands torques,
  and a servo's own feedback would be a second controller;
* **contacts from the vendor's geoms**: every geom of the robot that collides with a default
  geom (``contype`` or ``conaffinity`` bit 0) touches the environment through an explicit contact
  pair carrying the vendor geom's ``condim``, ``solref``, ``solimp``, ``margin``, ``gap`` and
  torsional/rolling friction, with the environment's sliding friction (a scenario's floor
  friction holds on the plant as on the twin). A controller contact measures the force on the
  vendor geoms of its body near its frame (within the geom's bounding sphere plus the contact's
  size); a contact with none is refused;
* **the world is the simulator's**: the file's static world geoms (a scene's floor) are removed
  and the environment (floor, boxes, platform) added as for the twin; pushes land on the plant's
  bodies at the controller's frames;
* **solver settings are the simulator's** (:class:`~wholebody.sim.twin.SimOptions`: timestep,
  integrator, cone, no-slip iterations) and gravity the controller's, so that a difference between
  the twin and the plant is the robot model's, not the solver's.
"""

from __future__ import annotations

import logging
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin

from ..robot import FREE_FLYER_NQ, FREE_FLYER_NV, Robot
from .environment import Environment
from .mismatch import Mismatch
from .twin import SimOptions, Twin, _add_environment, _wxyz

log = logging.getLogger(__name__)

#: an anchor of the plant this far (in standing base heights) from the controller's: not the robot
ANCHOR_TOLERANCE = 0.05
#: anchors closer than this (m) are the same; farther ones are noted
ANCHOR_NOTE = 1e-3
#: a joint axis this far (deg) from the controller's: refused
AXIS_TOLERANCE_DEG = 5.0
_HINGE, _SLIDE = int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)


class PlantError(ValueError):
    """The plant file cannot be used with this robot; the message names the field and the value
    (``where``: "robot 'x': plant = 'FILE'") and then ``reason``."""

    def __init__(self, where: str, reason: str):
        self.where, self.reason = where, reason
        super().__init__(f"{where}: {reason}")


def plant_path(robot: Robot) -> Path | None:
    """The plant file of ``robot``'s description (relative paths from the description's folder),
    None for the exact twin."""
    plant = getattr(robot.description, "plant", None)
    if not plant:
        return None
    path = Path(plant).expanduser()
    base = robot.description.base_dir
    if not path.is_absolute() and base is not None:
        path = Path(base) / path
    return path


def plant_label(robot: Robot) -> str:
    """What a run summary says the plant was: ``"exact twin"`` or ``"vendor MJCF <file>"``."""
    path = plant_path(robot)
    return "exact twin" if path is None else f"vendor MJCF {path}"


def with_plant(robot: Robot, plant: str | Path) -> Robot:
    """``robot`` with its description's ``plant`` set to ``plant`` (a path from the current
    folder; the controller's model is shared, not rebuilt)."""
    import copy
    import dataclasses

    out = copy.copy(robot)
    out.description = dataclasses.replace(robot.description,
                                          plant=str(Path(plant).expanduser().resolve()))
    return out


def _where(robot: Robot, path: Path) -> str:
    return f"robot '{robot.name}': plant = '{path}'"


def _compile(spec: mujoco.MjSpec, where: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as exc:
        raise PlantError(where, f"MuJoCo does not compile it: "
                         f"{str(exc).strip().replace(chr(10), ' ')}") from None


def _load_spec(path: Path, where: str) -> mujoco.MjSpec:
    from ..robots.mjcf import is_mjcf

    if not path.exists():
        raise PlantError(where, "no such file")
    if not path.is_file():
        raise PlantError(where, "not a file")
    if not is_mjcf(path):
        raise PlantError(where, "not an MJCF file (its root element is not <mujoco>); the "
                         "plant is the vendor's MuJoCo model")
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise PlantError(where, f"MuJoCo does not read it: "
                         f"{str(exc).strip().replace(chr(10), ' ')}") from None


def _name_everything(spec: mujoco.MjSpec) -> None:
    """Unnamed bodies, geoms and actuators get a name (pairs and look-ups go by name)."""
    for i, body in enumerate(spec.bodies):
        if body is not spec.worldbody and not body.name:
            body.name = f"plant_body{i}"
    for i, geom in enumerate(spec.geoms):
        if not geom.name:
            geom.name = f"plant_geom{i}"
    for i, actuator in enumerate(spec.actuators):
        if not actuator.name:
            actuator.name = f"plant_actuator{i}"


def _base_body(m: mujoco.MjModel, where: str) -> tuple[int, bool]:
    """(the plant's base body id, whether it has a free joint)."""
    free = [j for j in range(m.njnt) if m.jnt_type[j] == _FREE]
    if len(free) > 1:
        names = [m.body(int(m.jnt_bodyid[j])).name for j in free]
        raise PlantError(where, f"{len(free)} free joints (bodies {names}); the plant is one "
                         f"robot: give the robot's file, not a scene with other free objects")
    if free:
        body = int(m.jnt_bodyid[free[0]])
        if m.body_parentid[body] != 0:
            raise PlantError(where, f"the free joint of body '{m.body(body).name}' is not on a "
                             f"child of the world")
        return body, True
    roots = [b for b in range(1, m.nbody) if m.body_parentid[b] == 0
             and any(m.body_rootid[c] == b and m.body_jntnum[c] > 0 for c in range(1, m.nbody))]
    if len(roots) != 1:
        raise PlantError(where, f"no free joint and {len(roots)} moving bodies under the world "
                         f"({[m.body(b).name for b in roots]}); the plant needs one robot")
    return roots[0], False


def _motor(m: mujoco.MjModel, a: int) -> bool:
    """A direct-torque actuator: fixed gain, no bias, no activation dynamics, no delay."""
    return (m.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
            and m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE
            and m.actuator_dyntype[a] == mujoco.mjtDyn.mjDYN_NONE
            and m.actuator_gainprm[a, 0] * m.actuator_gear[a, 0] != 0)


def _actuator_kind(m: mujoco.MjModel, a: int) -> str:
    if m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE:
        return "a position or velocity servo"
    if m.actuator_dyntype[a] != mujoco.mjtDyn.mjDYN_NONE:
        return "an actuator with activation dynamics"
    return "not a direct torque motor"


def _actuator_bounds(m: mujoco.MjModel, a: int, joint: int) -> tuple[float, float]:
    """The joint torque range a motor can apply (its control, force and the joint's
    actuator-force ranges), in the joint's direction."""
    scale = float(m.actuator_gainprm[a, 0] * m.actuator_gear[a, 0])
    lo, hi = -np.inf, np.inf
    if m.actuator_ctrllimited[a]:
        lo, hi = sorted(scale * np.asarray(m.actuator_ctrlrange[a], float))
    if m.actuator_forcelimited[a]:
        gear = float(m.actuator_gear[a, 0])
        flo, fhi = sorted(gear * np.asarray(m.actuator_forcerange[a], float))
        lo, hi = max(lo, flo), min(hi, fhi)
    if m.jnt_actfrclimited[joint]:
        lo, hi = max(lo, m.jnt_actfrcrange[joint, 0]), min(hi, m.jnt_actfrcrange[joint, 1])
    return float(lo), float(hi)


def _locked_values(robot: Robot) -> dict[str, float]:
    """The posture angle of each locked joint of the description."""
    locked = tuple(robot.description.locked_joints)
    if not locked:
        return {}
    full = robot.source.model
    q = Robot.full_posture(full, robot.description)
    return {j: float(q[full.joints[full.getJointId(j)].idx_q]) for j in locked}


def build_plant(robot: Robot, path: str | Path, environment: Environment | None = None,
                mismatch: Mismatch | None = None, options: SimOptions | None = None) -> Twin:
    """The vendor MJCF at ``path`` as the simulated plant of ``robot`` (see the module docstring);
    :class:`PlantError` naming the field ``plant``, the file and what does not fit."""
    environment = environment or Environment()
    mismatch = mismatch or Mismatch()
    options = options or SimOptions()
    path = Path(path)
    where = _where(robot, path)
    notes: list[str] = []
    spec = _load_spec(path, where)
    _name_everything(spec)
    m0 = _compile(spec, where)
    base, has_free = _base_body(m0, where)
    in_robot = [b for b in range(m0.nbody) if b and m0.body_rootid[b] == base]
    outside = [b for b in range(1, m0.nbody) if m0.body_rootid[b] != base]
    # bodies outside the robot that move (a dummy on a hinge): removed with what they carry
    moving = [b for b in outside if m0.body_parentid[b] == 0
              and any(m0.body_rootid[c] == b and m0.body_jntnum[c] > 0 for c in outside)]

    # ---------------------------------------------------------------- joints by name
    plant_joints = {m0.joint(j).name: j for j in range(m0.njnt)
                    if m0.jnt_type[j] != _FREE and m0.body_rootid[m0.jnt_bodyid[j]] == base}
    bad_type = [n for n, j in plant_joints.items() if m0.jnt_type[j] not in (_HINGE, _SLIDE)]
    if bad_type:
        raise PlantError(where, f"joint(s) {bad_type} are not hinges or slides")
    wanted = list(robot.joint_names)
    missing = [n for n in wanted if n not in plant_joints]
    if missing:
        raise PlantError(where, f"the plant has no joint named {missing} (the controller's "
                         f"joints; the plant's are {sorted(plant_joints)})")
    locked = _locked_values(robot)
    extra = [n for n in plant_joints if n not in wanted and n not in locked]
    if extra:
        raise PlantError(where, f"the plant has joint(s) {extra} the controller's model does "
                         f"not; lock them in the description (locked_joints) to hold them at the "
                         f"posture, or give a plant without them")
    for jid in range(2, robot.model.njoints):
        name = robot.model.names[jid]
        revolute = np.linalg.norm(_joint_axis_motion(robot.model, jid)[3:]) > 0.5
        hinge = m0.jnt_type[plant_joints[name]] == _HINGE
        if revolute != hinge:
            raise PlantError(where, f"joint '{name}' is a {'hinge' if hinge else 'slide'} in "
                             f"the plant but {'revolute' if revolute else 'prismatic'} in the "
                             f"controller's model")
    order = [n for n in sorted(plant_joints, key=lambda n: m0.jnt_qposadr[plant_joints[n]])
             if n in wanted]
    if order != wanted:
        notes.append("joint order differs from the controller's (mapped by name)")

    # ---------------------------------------------------------------- actuators
    drives: dict[str, list[int]] = {n: [] for n in plant_joints}
    for a in range(m0.nu):
        if m0.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            joint = m0.joint(int(m0.actuator_trnid[a, 0])).name
            if joint in drives:
                drives[joint].append(a)
    why_not = []
    for n in wanted:
        if len(drives[n]) != 1:
            why_not.append(f"joint '{n}' has {len(drives[n])} actuators")
        elif not _motor(m0, drives[n][0]):
            why_not.append(f"joint '{n}''s actuator '{m0.actuator(drives[n][0]).name}' is "
                           f"{_actuator_kind(m0, drives[n][0])}")
    use_vendor = not why_not
    other = [a for a in range(m0.nu) if m0.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT
             or m0.joint(int(m0.actuator_trnid[a, 0])).name not in wanted]
    removed = list(range(m0.nu)) if not use_vendor else other
    for a in sorted(removed, reverse=True):
        spec.delete(spec.actuator(m0.actuator(a).name))
    if use_vendor:
        torques = "through the vendor's motors (control = torque / (gear x gain))"
    else:
        torques = (f"as joint torques (gear-1 motors replace the vendor's actuators: "
                   f"{why_not[0]}{' ...' if len(why_not) > 1 else ''})")
        for n in wanted:
            actuator = spec.add_actuator()
            actuator.name = f"plant_{n}"
            actuator.target = n
            actuator.trntype = mujoco.mjtTrn.mjTRN_JOINT
            actuator.set_to_motor()
            actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    if other and use_vendor:
        notes.append(f"{len(other)} actuator(s) on joints the controller does not drive removed")

    # ---------------------------------------------------------------- locked joints, damping
    for n, value in locked.items():
        eq = spec.add_equality()
        eq.type = mujoco.mjtEq.mjEQ_JOINT
        eq.name = f"plant_lock_{n}"
        eq.name1 = n
        eq.objtype = mujoco.mjtObj.mjOBJ_JOINT
        data = np.zeros(11)
        data[0] = value
        eq.data = data
    if locked:
        notes.append(f"locked joint(s) {sorted(locked)} held at the posture by equality "
                     f"constraints")
    if mismatch.joint_damping:
        for n in wanted:
            joint = spec.joint(n)
            joint.damping = float(m0.dof_damping[m0.jnt_dofadr[plant_joints[n]]]) + \
                mismatch.joint_damping
    factors, offsets = mismatch.link_perturbations(m0.nbody)
    if mismatch.moves_links:
        for b in in_robot:
            body = spec.body(m0.body(b).name)
            rot = _matrix(m0.body_iquat[b])
            inertia = rot @ np.diag(m0.body_inertia[b]) @ rot.T * factors[b]
            body.mass = float(m0.body_mass[b] * factors[b])
            body.ipos = np.asarray(m0.body_ipos[b]) + offsets[b]
            body.fullinertia = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1],
                                inertia[0, 2], inertia[1, 2]]
            body.explicitinertial = True

    # ---------------------------------------------------------------- the world and the solver
    base_name = m0.body(base).name
    if not has_free:
        spec.body(base_name).add_freejoint().name = "plant_root"
        notes.append(f"the file has no free joint: one added at body '{base_name}'")
    for b in moving:
        spec.delete(spec.body(m0.body(b).name))
    if moving:
        notes.append(f"moving bodies outside the robot removed: "
                     f"{[m0.body(b).name for b in moving]}")
    world_geoms = [g for g in range(m0.ngeom) if m0.body_rootid[m0.geom_bodyid[g]] != base
                   and m0.body_rootid[m0.geom_bodyid[g]] not in moving]
    for g in world_geoms:
        spec.delete(spec.geom(m0.geom(g).name))
    if world_geoms:
        notes.append(f"{len(world_geoms)} world geom(s) of the file removed (the environment is "
                     f"the simulator's)")
    spec.option.timestep = options.timestep
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{options.integrator.upper()}")
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.noslip_iterations = options.noslip_iterations
    spec.option.gravity = robot.model.gravity.linear
    env_geoms = _add_environment(spec, environment, options)
    colliding = [g for g in range(m0.ngeom) if m0.body_rootid[m0.geom_bodyid[g]] == base
                 and (m0.geom_contype[g] & 1 or m0.geom_conaffinity[g] & 1)]
    if not colliding:
        raise PlantError(where, "no geom of the robot collides with the floor (contype or "
                         "conaffinity bit 0); the plant's contacts are its own geoms")
    for env in env_geoms:
        env.contype = env.conaffinity = 0  # the explicit pairs below only
        mu = float(env.friction[0])
        for g in colliding:
            pair = spec.add_pair()
            pair.geomname1 = m0.geom(g).name
            pair.geomname2 = env.name
            pair.condim = int(m0.geom_condim[g])
            f = m0.geom_friction[g]
            pair.friction = [mu, mu, float(f[1]), float(f[2]), float(f[2])]
            pair.solref = [float(x) for x in m0.geom_solref[g]]
            pair.solimp = [float(x) for x in m0.geom_solimp[g]]
            pair.margin = float(m0.geom_margin[g])
            pair.gap = float(m0.geom_gap[g])
    m = _compile(spec, where)
    return _finish(robot, m, spec, base_name, plant_joints.keys(), locked, colliding, m0,
                   use_vendor, torques, notes, environment, path, where)


def _matrix(quat_wxyz) -> np.ndarray:
    w, x, y, z = (float(v) for v in quat_wxyz)
    return pin.Quaternion(w, x, y, z).normalized().matrix()


def _finish(robot: Robot, m: mujoco.MjModel, spec, base_name: str, plant_joints, locked,
            colliding, m0, use_vendor: bool, torques: str, notes: list[str],
            environment: Environment, path: Path, where: str) -> Twin:
    """Index maps, the kinematic check, contact sites and geoms of the compiled plant."""
    model = robot.model
    obj = mujoco.mjtObj
    base = mujoco.mj_name2id(m, obj.mjOBJ_BODY, base_name)
    free = int(m.body_jntadr[base])
    qpos_index = [int(m.jnt_qposadr[free]) + k for k in range(FREE_FLYER_NQ)]
    dof_index = [int(m.jnt_dofadr[free]) + k for k in range(FREE_FLYER_NV)]
    actuator_index, scale, lower, upper = [], [], [], []
    joint_bodies = {model.names[1]: base}
    for jid in range(2, model.njoints):
        name = model.names[jid]
        j = mujoco.mj_name2id(m, obj.mjOBJ_JOINT, name)
        qpos_index.append(int(m.jnt_qposadr[j]))
        dof_index.append(int(m.jnt_dofadr[j]))
        joint_bodies[name] = int(m.jnt_bodyid[j])
        a = next(a for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
                 and int(m.actuator_trnid[a, 0]) == j)
        actuator_index.append(a)
        scale.append(1.0 / float(m.actuator_gainprm[a, 0] * m.actuator_gear[a, 0]))
        lo, hi = _actuator_bounds(m, a, j) if use_vendor else (
            (m.jnt_actfrcrange[j, 0], m.jnt_actfrcrange[j, 1]) if m.jnt_actfrclimited[j]
            else (-np.inf, np.inf))
        lower.append(lo)
        upper.append(hi)
    held = [(int(m.jnt_qposadr[mujoco.mj_name2id(m, obj.mjOBJ_JOINT, n)]), v)
            for n, v in locked.items()]

    # the plant at the controller's reference posture: poses of the mapped bodies
    data = mujoco.MjData(m)
    q_ref = robot.q_ref.copy()
    from . import convert

    data.qpos[qpos_index], _ = convert.pin_to_mj(q_ref, np.zeros(robot.nv))
    for adr, value in held:
        data.qpos[adr] = value
    mujoco.mj_kinematics(m, data)
    pin_data = model.createData()
    pin.forwardKinematics(model, pin_data, q_ref)
    pin.updateFramePlacements(model, pin_data)
    height = float(robot.q_ref[2])
    joint_frames: dict[str, pin.SE3] = {}
    far = []
    for jid in range(1, model.njoints):
        name = model.names[jid]
        b = joint_bodies[name]
        body = pin.SE3(data.xmat[b].reshape(3, 3).copy(), data.xpos[b].copy())
        joint_frames[name] = body.actInv(pin_data.oMi[jid])
        if jid == 1:
            continue
        j = mujoco.mj_name2id(m, obj.mjOBJ_JOINT, name)
        gap = float(np.linalg.norm(data.xanchor[j] - pin_data.oMi[jid].translation))
        motion = np.asarray(pin_data.oMi[jid].rotation @ _joint_axis(model, jid))
        cos = float(np.dot(motion, data.xaxis[j]) / np.linalg.norm(motion))
        angle = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
        if angle > AXIS_TOLERANCE_DEG:
            raise PlantError(where, f"joint '{name}' turns about a different axis in the plant "
                             f"({angle:.0f} deg from the controller's{', reversed' if cos < 0 else ''}"
                             f"): not the same robot, or a joint whose sign differs")
        if gap > ANCHOR_TOLERANCE * height:
            raise PlantError(where, f"joint '{name}' is {1000 * gap:.0f} mm from where the "
                             f"controller's model has it at the posture (more than "
                             f"{ANCHOR_TOLERANCE:g} x the base height {height:.3f} m): not the "
                             f"same robot, or a joint whose zero differs")
        if gap > ANCHOR_NOTE:
            far.append((gap, name))
    base_offset = joint_frames[model.names[1]]
    if (np.linalg.norm(base_offset.translation) > 1e-6
            or np.linalg.norm(base_offset.rotation - np.eye(3)) > 1e-6):
        raise PlantError(where, f"the plant's base body '{base_name}' is not at the "
                         f"controller's base frame (offset "
                         f"{np.round(base_offset.translation, 4).tolist()} m): the base state "
                         f"would be read at another point")
    if far:
        gap, name = max(far)
        notes.append(f"{len(far)} joint anchor(s) more than {1000 * ANCHOR_NOTE:g} mm from the "
                     f"controller's (largest: '{name}', {1000 * gap:.1f} mm)")

    # contact sites at the controller's contact frames, and the vendor geoms of each contact
    owner = _owners(m, set(joint_bodies.values()), base)
    contact_sites, contact_geoms = {}, {}
    sites = []
    for contact in robot.contacts:
        frame = model.frames[contact.frame_id]
        jname = model.names[frame.parentJoint]
        placement = joint_frames[jname] * frame.placement
        body = spec.body(m.body(joint_bodies[jname]).name)
        site = body.add_site()
        site.name = f"plant_contact_{contact.name}"
        site.pos = placement.translation
        site.quat = _wxyz(placement.rotation)
        sites.append((contact, joint_bodies[jname], placement))
    size = {c.name: (c.spec.radius if c.spec.type == "point" else float(np.hypot(*c.spec.half_size)))
            for c in robot.contacts}
    m = _compile(spec, where)  # with the sites (indices of everything else unchanged)
    data = mujoco.MjData(m)
    for contact, b, placement in sites:
        contact_sites[contact.name] = mujoco.mj_name2id(m, obj.mjOBJ_SITE,
                                                        f"plant_contact_{contact.name}")
        geoms = []
        for g0 in colliding:
            g = mujoco.mj_name2id(m, obj.mjOBJ_GEOM, m0.geom(g0).name)
            if owner[int(m.geom_bodyid[g])] != b:
                continue
            centre = _geom_in_body(m, g, b)
            if np.linalg.norm(centre - placement.translation) <= (
                    float(m.geom_rbound[g]) + size[contact.name] + 0.01 * height):
                geoms.append(g)
        if not geoms:
            raise PlantError(where, f"contact '{contact.name}' (frame '{contact.spec.frame}') "
                             f"has no colliding geom of the plant near it on body "
                             f"'{m.body(b).name}'")
        contact_geoms[contact.name] = geoms
    taken = {g for gs in contact_geoms.values() for g in gs}
    if len(taken) < len(colliding):
        log.debug("plant %s: %d colliding geom(s) are not at a contact (their forces are not "
                  "contact wrenches)", path, len(colliding) - len(taken))
    platform_qpos = platform_qvel = None
    if environment.platform is not None:
        from .twin import PLATFORM_JOINTS

        ids = [mujoco.mj_name2id(m, obj.mjOBJ_JOINT, n) for n, _, _ in PLATFORM_JOINTS]
        platform_qpos = np.array([m.jnt_qposadr[i] for i in ids])
        platform_qvel = np.array([m.jnt_dofadr[i] for i in ids])
    robot_bodies = frozenset(b for b in range(1, m.nbody) if m.body_rootid[b] == base)
    notes.insert(0, f"torques {torques}")
    for note in notes:
        log.info("plant %s: %s", path, note)
    return Twin(m, contact_geoms, contact_sites, joint_bodies, platform_qpos, platform_qvel,
                qpos_index=np.array(qpos_index), dof_index=np.array(dof_index),
                actuator_index=np.array(actuator_index), actuator_scale=np.array(scale),
                torque_lower=np.array(lower, float), torque_upper=np.array(upper, float),
                joint_frames=joint_frames, robot_bodies=robot_bodies, held_qpos=held,
                label=f"vendor MJCF {path}", notes=notes)


def _joint_axis_motion(model: pin.Model, jid: int) -> np.ndarray:
    """The motion subspace S (6,) of a 1-DoF joint in its own frame: [linear; angular]."""
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    return np.asarray(data.joints[jid].S).reshape(6, -1)[:, 0]


def _joint_axis(model: pin.Model, jid: int) -> np.ndarray:
    """The unit axis of a 1-DoF joint in its own frame (angular part of S for a revolute joint,
    linear part for a prismatic one)."""
    s = _joint_axis_motion(model, jid)
    return s[3:] if np.linalg.norm(s[3:]) > 0.5 else s[:3]


def _owners(m: mujoco.MjModel, jointed: set[int], base: int) -> dict[int, int]:
    """Each body of the robot -> the body of its nearest mapped joint (itself or an ancestor):
    the body Pinocchio merges it into."""
    out = {}
    for b in range(1, m.nbody):
        c = b
        while c not in jointed and c != 0:
            c = int(m.body_parentid[c])
        out[b] = c
    return out


def _geom_in_body(m: mujoco.MjModel, g: int, body: int) -> np.ndarray:
    """The centre of geom ``g`` in the frame of its ancestor ``body`` (model poses)."""
    pos = np.asarray(m.geom_pos[g], float)
    b = int(m.geom_bodyid[g])
    while b != body:
        pos = _matrix(m.body_quat[b]) @ pos + m.body_pos[b]
        b = int(m.body_parentid[b])
    return pos


def check_plant(robot: Robot) -> Twin | None:
    """Build ``robot``'s plant once (the description's ``plant``), so that a bad file is found
    before anything is simulated; None for the exact twin. :class:`PlantError` otherwise."""
    path = plant_path(robot)
    return None if path is None else build_plant(robot, path)
