"""Build the MuJoCo twin of a :class:`wholebody.Robot` from its Pinocchio model through ``mujoco.MjSpec``.

MuJoCo's URDF import fails on the example-robot-data robots (``package://`` paths, ``.dae`` meshes,
tiny inertias, a lost root mass), so the twin is generated from the Pinocchio model instead: one body
per Pinocchio joint (fixed links are already merged into it by Pinocchio), the same inertias and
armature, a free joint at the root, one motor per actuated joint, contact geometry at the contact
frames (spheres for points, boxes for soles) that collides only with the environment, and the
environment's floor, boxes and platform. Mass, CoM, M(q) and the nonlinear effects then agree with
Pinocchio to machine precision (``tests/test_twin.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
import pinocchio as pin

from ..robot import FREE_FLYER_NV, Robot
from .environment import Environment
from .mismatch import Mismatch

ROBOT_CONTYPE, ROBOT_CONAFFINITY = 1, 0  # robot geoms never collide with each other...
ENV_CONTYPE, ENV_CONAFFINITY = 0, 1  # ...only with the environment
SOLE_THICKNESS = 0.01  # half-height of the sole boxes (m)
# platform pose coordinates: translation x, y, z then roll, pitch, yaw (nested hinges about x, y, z)
PLATFORM_JOINTS = tuple((f"platform_{n}", kind, axis) for kind, names in
                        (("slide", "xyz"), ("hinge", ("roll", "pitch", "yaw")))
                        for axis, n in enumerate(names))


@dataclass(frozen=True)
class SimOptions:
    """MuJoCo solver settings of the twin (see docs/architecture.md, "The MuJoCo twin")."""

    timestep: float = 1e-3
    integrator: str = "implicitfast"
    noslip_iterations: int = 8
    contact_solref: tuple[float, float] = (0.01, 1.0)


@dataclass
class Twin:
    """A compiled twin: the MuJoCo model plus the name maps the simulator needs.

    The exact twin has the controller's coordinate layout (the maps below are the identity); a
    vendor's plant (:mod:`wholebody.sim.plant`) has its own, read and written through them."""

    model: mujoco.MjModel
    contact_geoms: dict[str, list[int]]  # contact name -> geom ids
    contact_sites: dict[str, int]  # contact name -> site id (at the contact frame)
    joint_bodies: dict[str, int]  # Pinocchio joint name -> MuJoCo body id
    platform_qpos: np.ndarray | None  # qpos addresses of the platform joints
    platform_qvel: np.ndarray | None
    #: qpos address of each coordinate of the controller's q (free flyer, then the joints);
    #: None: the first nq
    qpos_index: np.ndarray | None = None
    #: qvel address of each coordinate of the controller's v; None: the first nv
    dof_index: np.ndarray | None = None
    #: the actuator of each actuated joint and its control per N m (1 / (gear x gain)); None:
    #: actuator i drives joint i with gear 1
    actuator_index: np.ndarray | None = None
    actuator_scale: np.ndarray | None = None
    #: the plant's own actuator torque bounds per joint (None: none beyond the robot's)
    torque_lower: np.ndarray | None = None
    torque_upper: np.ndarray | None = None
    #: Pinocchio joint name -> its frame in the MuJoCo body's frame (None: the same frames)
    joint_frames: dict[str, pin.SE3] | None = None
    #: the MuJoCo bodies of the robot (None: those of ``joint_bodies``)
    robot_bodies: frozenset[int] | None = None
    #: (qpos address, value) of the plant's joints held at the posture (locked joints)
    held_qpos: list[tuple[int, float]] = field(default_factory=list)
    #: what the simulated plant is, for summaries
    label: str = "exact twin"
    notes: list[str] = field(default_factory=list)

    def bodies(self) -> frozenset[int]:
        """The MuJoCo bodies of the robot."""
        return self.robot_bodies or frozenset(self.joint_bodies.values())


def _wxyz(rotation: np.ndarray) -> np.ndarray:
    quat = pin.Quaternion(rotation)
    return np.array([quat.w, quat.x, quat.y, quat.z])


def _rpy_to_wxyz(rpy) -> np.ndarray:
    return _wxyz(pin.rpy.rpyToMatrix(np.asarray(rpy, dtype=float)))


def build_spec(robot: Robot, environment: Environment | None = None,
               mismatch: Mismatch | None = None, options: SimOptions | None = None,
               skeleton: bool = False) -> mujoco.MjSpec:
    """The MjSpec of the twin (compile it with ``spec.compile()``); ``skeleton`` adds the
    robot's visual-only stick figure (for MuJoCo's viewer)."""
    environment = environment or Environment()
    mismatch = mismatch or Mismatch()
    options = options or SimOptions()
    model = robot.model
    spec = mujoco.MjSpec()
    spec.modelname = robot.name
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.option.timestep = options.timestep
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{options.integrator.upper()}")
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.noslip_iterations = options.noslip_iterations
    spec.option.gravity = model.gravity.linear

    factors, offsets = mismatch.link_perturbations(model.njoints)
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    bodies = {0: spec.worldbody}
    for jid in range(1, model.njoints):
        name = model.names[jid]
        placement = model.jointPlacements[jid]
        body = bodies[model.parents[jid]].add_body()
        body.name = name
        body.pos = placement.translation
        body.quat = _wxyz(placement.rotation)
        inertia = model.inertias[jid]
        body.mass = inertia.mass * factors[jid]
        body.ipos = inertia.lever + offsets[jid]
        I = inertia.inertia * factors[jid]
        body.fullinertia = [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
        body.explicitinertial = True
        bodies[jid] = body
        if jid == 1:
            body.add_freejoint().name = name
            continue
        motion = np.asarray(data.joints[jid].S).reshape(6, -1)[:, 0]
        joint = body.add_joint()
        joint.name = name
        is_hinge = np.linalg.norm(motion[3:]) > 0.5
        joint.type = mujoco.mjtJoint.mjJNT_HINGE if is_hinge else mujoco.mjtJoint.mjJNT_SLIDE
        joint.axis = motion[3:] if is_hinge else motion[:3]
        idx_q, idx_v = model.joints[jid].idx_q, model.joints[jid].idx_v
        # the model's own (URDF/MJCF) limits, not the controller's (a scenario may move those);
        # a continuous joint (two coordinates) has none
        lo, hi = ((model.lowerPositionLimit[idx_q], model.upperPositionLimit[idx_q])
                  if model.joints[jid].nq == 1 else (-np.inf, np.inf))
        if np.isfinite(lo) and np.isfinite(hi) and hi > lo:
            joint.range = [lo, hi]
            joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        joint.armature = model.armature[idx_v]
        joint.damping = [mismatch.joint_damping, 0.0, 0.0]
        actuator = spec.add_actuator()
        actuator.name = name
        actuator.target = name
        actuator.trntype = mujoco.mjtTrn.mjTRN_JOINT
        actuator.set_to_motor()
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE  # the simulator saturates itself

    for contact in robot.contacts:
        frame = model.frames[contact.frame_id]
        body = bodies[frame.parentJoint]
        site = body.add_site()
        site.name = contact.name
        site.pos = frame.placement.translation
        site.quat = _wxyz(frame.placement.rotation)
        geom = body.add_geom()
        geom.name = contact.name
        geom.contype, geom.conaffinity = ROBOT_CONTYPE, ROBOT_CONAFFINITY
        geom.condim = 3
        geom.solref = list(options.contact_solref)
        geom.mass = 0.0
        geom.rgba = [0.9, 0.4, 0.1, 1.0]
        if contact.spec.type == "point":
            geom.type = mujoco.mjtGeom.mjGEOM_SPHERE
            geom.size = [max(contact.spec.radius, 1e-3), 0, 0]
            geom.pos = frame.placement.translation
        else:
            hx, hy = contact.spec.half_size
            geom.type = mujoco.mjtGeom.mjGEOM_BOX
            geom.size = [hx, hy, SOLE_THICKNESS]
            # box bottom face on the sole frame
            geom.pos = frame.placement.act(np.array([0.0, 0.0, SOLE_THICKNESS]))
            geom.quat = _wxyz(frame.placement.rotation)

    if skeleton:
        _add_skeleton(robot, bodies)
    _add_environment(spec, environment, options)
    return spec


SKELETON_RADIUS = 0.02  # of the skeleton's capsules, in standing base heights
SKELETON_GROUP = 1  # MuJoCo geom group of the skeleton
SKELETON_RGBA = (0.55, 0.6, 0.7, 1.0)


def skeleton_segments(robot: Robot) -> list[tuple[int, int, np.ndarray]]:
    """The bones of the robot's stick figure: (joint id, index among that joint's bones, far end
    in the joint's frame), one from each joint to each child joint and to each contact frame (the
    near end is the joint's origin; bones of zero length are left out)."""
    model = robot.model
    ends: dict[int, list[np.ndarray]] = {j: [] for j in range(1, model.njoints)}
    for j in range(2, model.njoints):
        ends[model.parents[j]].append(model.jointPlacements[j].translation)
    for contact in robot.contacts:
        frame = model.frames[contact.frame_id]
        ends[frame.parentJoint].append(frame.placement.translation)
    return [(j, k, end) for j, points in ends.items()
            for k, end in enumerate(p for p in points if np.linalg.norm(p) > 1e-6)]


def _add_skeleton(robot: Robot, bodies: dict) -> None:
    """A stick figure of the robot for MuJoCo's viewer (the twin has no meshes): a capsule for each
    of :func:`skeleton_segments`. Visual only: no collision, no mass (the bodies' inertias are
    explicit), so the dynamics are unchanged."""
    model = robot.model
    radius = SKELETON_RADIUS * float(robot.q_ref[2])
    for j, k, end in skeleton_segments(robot):
        geom = bodies[j].add_geom()
        geom.name = f"skeleton_{model.names[j]}_{k}"
        geom.type = mujoco.mjtGeom.mjGEOM_CAPSULE
        geom.fromto = [0.0, 0.0, 0.0, *end]
        geom.size = [radius, 0, 0]
        geom.contype = geom.conaffinity = 0
        geom.mass = 0.0
        geom.group = SKELETON_GROUP
        geom.rgba = list(SKELETON_RGBA)


def _env_geom(body, name: str, friction: float, options: SimOptions, geoms: list):
    geom = body.add_geom()
    geom.name = name
    geom.contype, geom.conaffinity = ENV_CONTYPE, ENV_CONAFFINITY
    geom.friction = [friction, 0.005, 0.0001]
    geom.priority = 1  # the environment's friction is the one used in a contact
    geom.solref = list(options.contact_solref)
    geom.rgba = [0.6, 0.6, 0.65, 1.0]
    geoms.append(geom)
    return geom


def _add_environment(spec: mujoco.MjSpec, env: Environment, options: SimOptions) -> list:
    """Add the environment's geoms (and the platform's body) to ``spec``; returns the geoms."""
    world = spec.worldbody
    geoms: list = []
    if env.floor:
        floor = _env_geom(world, "floor", env.floor_friction, options, geoms)
        floor.type = mujoco.mjtGeom.mjGEOM_PLANE
        floor.size = [0, 0, 1]
        floor.pos = [0, 0, env.ground_height]
    for i, box in enumerate(env.boxes):
        geom = _env_geom(world, f"box{i}", box.friction or env.floor_friction, options, geoms)
        geom.type = mujoco.mjtGeom.mjGEOM_BOX
        geom.size = list(box.half_size)
        geom.pos = list(box.center)
        geom.quat = _rpy_to_wxyz(box.rpy)
    if env.platform is not None:
        p = env.platform
        body = world.add_body()
        body.name = "platform"
        body.pos = list(p.center)
        body.mass = 1e4
        body.inertia = [1e3, 1e3, 1e3]
        body.explicitinertial = True
        body.gravcomp = 1.0
        for name, kind, axis in PLATFORM_JOINTS:
            joint = body.add_joint()
            joint.name = name
            joint.type = (mujoco.mjtJoint.mjJNT_SLIDE if kind == "slide"
                          else mujoco.mjtJoint.mjJNT_HINGE)
            joint.axis = np.eye(3)[axis]
        geom = _env_geom(body, "platform", p.friction or env.floor_friction, options, geoms)
        geom.type = mujoco.mjtGeom.mjGEOM_BOX
        geom.size = list(p.half_size)
        geom.pos = [0, 0, -p.half_size[2]]
    return geoms


def build_twin(robot: Robot, environment: Environment | None = None,
               mismatch: Mismatch | None = None, options: SimOptions | None = None,
               skeleton: bool = False) -> Twin:
    """Compile the twin and check that its robot joints use Pinocchio's coordinate layout."""
    spec = build_spec(robot, environment, mismatch, options, skeleton)
    m = spec.compile()
    for jid in range(2, robot.model.njoints):
        name = robot.model.names[jid]
        mj = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
        pj = robot.model.joints[jid]
        # MuJoCo and Pinocchio both order bodies depth-first, so joint addresses coincide; a
        # hinge has one qpos per velocity (a continuous joint's angle, where Pinocchio keeps
        # its (cos, sin)), so MuJoCo's qpos after the free joint is the joints' angles
        if m.jnt_qposadr[mj] != pj.idx_v + 1 or m.jnt_dofadr[mj] != pj.idx_v:
            raise RuntimeError(f"twin: joint '{name}' has MuJoCo address {m.jnt_qposadr[mj]}, "
                               f"Pinocchio's angle {pj.idx_v + 1}")
    contact_geoms = {c.name: [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, c.name)]
                     for c in robot.contacts}
    contact_sites = {c.name: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, c.name)
                     for c in robot.contacts}
    joint_bodies = {robot.model.names[j]: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY,
                                                            robot.model.names[j])
                    for j in range(1, robot.model.njoints)}
    platform_qpos = platform_qvel = None
    if environment is not None and environment.platform is not None:
        ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n, _, _ in PLATFORM_JOINTS]
        platform_qpos = np.array([m.jnt_qposadr[i] for i in ids])
        platform_qvel = np.array([m.jnt_dofadr[i] for i in ids])
    assert m.nu == robot.na
    assert FREE_FLYER_NV + robot.na == robot.nv
    return Twin(m, contact_geoms, contact_sites, joint_bodies, platform_qpos, platform_qvel)
