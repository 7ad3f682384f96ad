"""The robot: a Pinocchio model, its contacts, and the per-cycle cache of rigid-body terms.

Conventions (Pinocchio's, everywhere inside the library):

* ``q = [base position (3), base quaternion x, y, z, w (4), joint positions (n)]``;
* ``v = [base linear velocity, base angular velocity (both in the LOCAL base frame), joint velocities]``;
* contact Jacobians, drifts and forces are expressed in the **LOCAL_WORLD_ALIGNED** frame of the
  contact: origin at the contact frame, axes parallel to the world axes. A point contact has a 3D
  force ``f`` (world axes); a rectangle contact has a 6D wrench ``[f; tau]`` about the contact frame
  origin (world axes). With these, the equations of motion read ``M qdd + h = S^T tau + J_c^T lambda``
  (Herzog et al. 2016, eq. 1) and the contact constraint ``J_c qdd + drift = 0`` (eq. 2), where
  ``drift`` is the classical acceleration of the contact frame at zero ``qdd``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from .robots.description import ContactSpec, DescriptionError, RobotDescription
from .robots.mjcf import KEYFRAME_PREFIX
from .robots.model_file import load_model_file, model_armature
from .robots.torque_limits import TorqueProfile

log = logging.getLogger(__name__)

FREE_FLYER_NQ = 7
FREE_FLYER_NV = 6
GRAVITY = 9.81  # m/s^2, the magnitude of the twin's and the models' gravity
# an effort limit above this many times the robot's weight times 1 m is likely a URDF placeholder
PLACEHOLDER_TORQUE_FACTOR = 10.0


@dataclass(frozen=True)
class Contact:
    """A contact of the robot: the description plus the resolved Pinocchio frame: the described
    frame itself, or a frame added at its ``offset`` (the sphere or sole centre)."""

    spec: ContactSpec
    frame_id: int
    frame: str

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def dim(self) -> int:
        return self.spec.dim


def check_vector(value, size: int, field: str) -> np.ndarray:
    """Return ``value`` as a float vector of length ``size``; ValueError naming ``field`` otherwise."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1 or arr.shape[0] != size:
        raise ValueError(f"{field}: expected a vector of size {size}, got shape {arr.shape}")
    if not math.isfinite(arr.sum()):  # one reduction on the fast path (called every cycle)
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:  # (a finite vector whose sum overflows is accepted)
            raise ValueError(f"{field}: contains NaN or inf at indices {bad.tolist()}")
    return arr


def _resolve_contact(model: pin.Model, spec: ContactSpec, index: int, where: str) -> Contact:
    """The contact's frame in ``model``; a contact with an ``offset`` gets a frame of its own,
    ``<name>_contact``, on the same joint at the offset (axes of the described frame)."""
    if not model.existFrame(spec.frame):
        raise DescriptionError(f"{where}: contacts[{index}].frame = '{spec.frame}' (contact "
                               f"'{spec.name}') is not a frame of the model")
    frame_id = int(model.getFrameId(spec.frame))
    if model.frames[frame_id].parentJoint <= 1:  # the universe or the floating base itself
        raise DescriptionError(f"{where}: contacts[{index}].frame = '{spec.frame}' (contact "
                               f"'{spec.name}') is on the floating base, not at the end of a leg: "
                               f"a contact is a foot or a sole, a frame that joints move")
    if not any(spec.offset):
        return Contact(spec, frame_id, spec.frame)
    name = f"{spec.name}_contact"
    if model.existFrame(name):
        raise DescriptionError(f"{where}: contacts[{index}]: contact '{spec.name}' has an offset, "
                               f"and the frame '{name}' it would add exists in the model already; "
                               f"rename the contact")
    parent = model.frames[frame_id]
    placement = parent.placement * pin.SE3(np.eye(3), np.array(spec.offset, dtype=float))
    added = model.addFrame(pin.Frame(name, parent.parentJoint, frame_id, placement,
                                     pin.FrameType.OP_FRAME))
    return Contact(spec, int(added), name)


def _model_joint_names(model: pin.Model) -> list[str]:
    """Names of the model's joints other than the universe and the root free flyer."""
    return list(model.names[2:])


def urdf_with_inertias(path, overrides: dict, where: str = "robot") -> str:
    """The URDF at ``path`` as text with the ``<inertia>`` of each link of ``overrides`` (link ->
    principal moments, the description's ``inertia_overrides``) replaced by that diagonal;
    DescriptionError naming ``inertia_overrides.<link>`` for a link the URDF lacks or one without
    an ``<inertial>``."""
    import xml.etree.ElementTree as ET

    try:
        tree = ET.parse(path)
    except ET.ParseError as exc:
        raise ValueError(f"not XML: {exc}") from None
    links = {link.get("name"): link for link in tree.getroot().findall("link")}
    for name, (ixx, iyy, izz) in overrides.items():
        if name not in links:
            raise DescriptionError(f"{where}: inertia_overrides.{name}: not a link of the URDF")
        inertia = links[name].find("inertial/inertia")
        if inertia is None:
            raise DescriptionError(f"{where}: inertia_overrides.{name}: the link has no "
                                   f"<inertial> (no mass) in the URDF")
        values = {"ixx": ixx, "iyy": iyy, "izz": izz, "ixy": 0.0, "ixz": 0.0, "iyz": 0.0}
        for key, value in values.items():
            inertia.set(key, repr(float(value)))
    return ET.tostring(tree.getroot(), encoding="unicode")


def check_inertias(model: pin.Model, where: str = "robot") -> None:
    """Every body of ``model`` (``model.inertias``: each joint's link with the links and frames
    merged into it by fixed joints) has a finite mass > 0, a finite centre of mass and a
    positive-definite rotational inertia; DescriptionError naming the body (its URDF link) and the
    joint moving it otherwise. A massless moving body (e.g. the intermediate link of a ball joint
    split into three revolutes) is refused: the MuJoCo twin cannot compile it. Bodies whose only
    fault is their rotational inertia are listed together, with the ``inertia_overrides`` that
    would replace it."""
    singular = []
    for jid in range(1, model.njoints):
        inertia = model.inertias[jid]
        mass, lever = float(inertia.mass), np.asarray(inertia.lever)
        rot = np.asarray(inertia.inertia)
        links = [f.name for f in model.frames
                 if f.parentJoint == jid and f.type == pin.FrameType.BODY]
        body = (f"body '{links[0]}'" if links else "the body") + f" of joint '{model.names[jid]}'"
        if not (math.isfinite(mass) and mass >= 0):
            raise DescriptionError(f"{where}: {body} has mass {mass!r} kg; fix the <inertial> "
                                   f"<mass> of the link in the URDF")
        if not (np.all(np.isfinite(lever)) and np.all(np.isfinite(rot))):
            raise DescriptionError(f"{where}: {body} has a non-finite centre of mass or inertia; "
                                   f"fix the <inertial> of the link in the URDF")
        if mass == 0:
            raise DescriptionError(
                f"{where}: {body} has no mass: the MuJoCo twin needs a positive mass and inertia "
                f"on every moving body; give the link an <inertial> in the URDF, or lock the joint "
                f"(locked_joints)")
        eig = np.linalg.eigvalsh(0.5 * (rot + rot.T))
        if eig[0] <= 1e-12 * mass:  # radius of gyration below 1 micrometre
            singular.append((links[0] if links else model.names[jid], body, mass, eig))
    if singular:
        _, body, mass, eig = singular[0]
        more = (f" (and {len(singular) - 1} more: "
                f"{', '.join(repr(link) for link, *_ in singular[1:])})" if len(singular) > 1
                else "")
        example = ", ".join(f"{link} = [ixx, iyy, izz]" for link, *_ in singular)
        raise DescriptionError(
            f"{where}: {body} has mass {mass:g} kg but its rotational inertia is not positive "
            f"definite (eigenvalues {[float(f'{e:.3g}') for e in eig]} kg m^2){more}; fix the "
            f"<inertia> of the link in the URDF, or give its principal moments in the "
            f"description: inertia_overrides = {{ {example} }}")


class Robot:
    """A floating-base robot built from a :class:`RobotDescription`.

    Call :meth:`update` once per control cycle; tasks then read the cached terms (``M``, ``h``,
    ``com``, ``A_G``, contact Jacobians...). Nothing is recomputed within a cycle: other frames'
    Jacobians and drifts are computed on first request and cached until the next ``update``.
    """

    def __init__(self, description: RobotDescription):
        self.description = description
        self.name = description.name
        where = f"robot '{self.name}'"
        source = load_model_file(description, where)
        full = source.model
        self.source = source
        q_posture = self.full_posture(full, description)
        if description.locked_joints:
            joints = _model_joint_names(full)
            missing = [j for j in description.locked_joints if j not in joints]
            if missing:
                raise DescriptionError(f"{where}: field 'locked_joints' names unknown joints "
                                       f"{missing}; joints of the model: {joints}")
            lock_ids = [full.getJointId(j) for j in description.locked_joints]
            model = pin.buildReducedModel(full, lock_ids, q_posture)
        else:
            model = full
        self.model: pin.Model = model
        self.nq, self.nv = model.nq, model.nv
        self.na = model.nv - FREE_FLYER_NV
        self.joint_names: tuple[str, ...] = tuple(model.names[2:])
        self._check_joint_types()
        if self.na == 0:
            raise DescriptionError(f"{where}: the model has no joints besides the floating base "
                                   f"(model = '{description.urdf}'): not a legged robot")
        check_inertias(model, where)
        self._set_armature(description.armature, source)
        self.contacts: tuple[Contact, ...] = tuple(
            _resolve_contact(model, spec, i, where) for i, spec in enumerate(description.contacts))
        self.data: pin.Data = model.createData()
        self.mass = float(pin.computeTotalMass(model))
        self.contact_names = tuple(c.name for c in self.contacts)
        self._contacts_by_name = {c.name: c for c in self.contacts}
        self._contact_index = {c.name: i for i, c in enumerate(self.contacts)}
        starts = np.cumsum([0] + [c.dim for c in self.contacts])
        self._contact_slices = [slice(int(a), int(b)) for a, b in zip(starts[:-1], starts[1:])]
        self._contact_rows = int(starts[-1])
        nc = len(self.contacts)
        self._contact_frame_ids = tuple(c.frame_id for c in self.contacts)
        self._radii = np.array([c.spec.radius if c.dim == 3 else 0.0 for c in self.contacts])
        # -[d]x with d = (0, 0, -r) (world axes) for each contact: maps angular to point terms
        self._offset_skew = np.zeros((nc, 3, 3))
        self._offset_skew[:, 0, 1] = -self._radii
        self._offset_skew[:, 1, 0] = self._radii
        self._all_points = bool(nc) and all(c.dim == 3 for c in self.contacts)
        self._all_rectangles = bool(nc) and all(c.dim == 6 for c in self.contacts)
        self.friction = description.friction
        #: the frame of the floating base's link, and the upper-body frame that pushes and trunk
        #: tasks address (the description's ``trunk_frame``, default the base)
        self.base_frame = next(f.name for f in model.frames
                               if f.parentJoint == 1 and f.type == pin.FrameType.BODY)
        self.trunk_frame = description.trunk_frame or self.base_frame
        if not model.existFrame(self.trunk_frame):
            raise DescriptionError(f"{where}: field 'trunk_frame' = '{self.trunk_frame}' is not a "
                                   f"frame of the model")

        # the joints' angle coordinates: q[_angle_q] for 1-DoF joints; a continuous joint (nq = 2:
        # cos, sin) has its angle atan2(q[_sin_q], q[_cos_q]) at index _unbounded of the angles
        kinds = [model.joints[j] for j in range(2, model.njoints)]
        self._unbounded = np.array([i for i, j in enumerate(kinds) if j.nq == 2], dtype=int)
        self._bounded = np.array([i for i, j in enumerate(kinds) if j.nq == 1], dtype=int)
        self._angle_q = np.array([j.idx_q for j in kinds if j.nq == 1], dtype=int)
        self._cos_q = np.array([j.idx_q for j in kinds if j.nq == 2], dtype=int)
        self._sin_q = self._cos_q + 1
        #: True when every joint has one coordinate: the angles are q[7:] as they are
        self.angles_are_coordinates = self._unbounded.size == 0
        #: the joints' angle limits (na,): a continuous joint has none (-inf, inf)
        self.q_min = np.full(self.na, -np.inf)
        self.q_max = np.full(self.na, np.inf)
        self.q_min[self._bounded] = model.lowerPositionLimit[self._angle_q]
        self.q_max[self._bounded] = model.upperPositionLimit[self._angle_q]
        self.v_max = model.velocityLimit[FREE_FLYER_NV:].copy()
        self.torque_limits = TorqueProfile(self.joint_names, model.effortLimit[FREE_FLYER_NV:],
                                          description.torque_limits, where)
        self._warn_placeholder_limits(description.torque_limits)
        self.q_ref = self.rest_on_ground(self._reduce_posture(full, model, q_posture))
        self._check_contact_sizes(where)

        selection = np.zeros((self.na, self.nv))
        selection[:, FREE_FLYER_NV:] = np.eye(self.na)
        selection.flags.writeable = False
        self.joint_selection = selection  # S: picks the actuated joints out of v (read-only)
        self.cycle = 0
        lower = np.tril_indices(self.nv, -1)  # flat indices of M's strict lower triangle and mirror
        self._lower_flat = np.ravel_multi_index(lower, (self.nv, self.nv))
        self._upper_flat = np.ravel_multi_index(lower[::-1], (self.nv, self.nv))
        self._frame_cache: dict[tuple, np.ndarray] = {}
        # quantities derived from the description by iterative searches (a leg's reach, ...),
        # kept by the modules that compute them under a key naming all they depend on
        self.derived: dict[tuple, object] = {}
        self._a0 = np.zeros(self.nv)
        self.q = self.q_ref.copy()
        self.v = np.zeros(self.nv)
        self.update(self.q_ref, np.zeros(self.nv))

    # ------------------------------------------------------------------ construction helpers
    @staticmethod
    def full_posture(full: pin.Model, d: RobotDescription) -> np.ndarray:
        """The posture of ``d`` as a configuration of the unreduced model ``full`` (its URDF, locked
        joints included): the SRDF group state or the joint table (other joints at 0), then the
        ``posture_overrides``."""
        if isinstance(d.posture, str) and d.posture.startswith(KEYFRAME_PREFIX):
            if d.posture not in full.referenceConfigurations:
                keys = [getattr(k, "key", lambda k=k: k)() for k in full.referenceConfigurations]
                have = [k[len(KEYFRAME_PREFIX):] for k in keys if k.startswith(KEYFRAME_PREFIX)]
                raise DescriptionError(f"robot '{d.name}': field 'posture' = '{d.posture}': the "
                                       f"model file has no such keyframe; keyframes: {have} "
                                       f"(keyframes are read from MJCF files only)")
        elif isinstance(d.posture, str):
            from .robots.locate import resolve_model_path

            srdf = resolve_model_path(d.srdf, d.base_dir)  # type: ignore[arg-type]
            pin.loadReferenceConfigurations(full, str(srdf), False)
            if d.posture not in full.referenceConfigurations:
                raise DescriptionError(f"robot '{d.name}': field 'posture' = '{d.posture}' is not "
                                       f"a group state of {srdf.name}; have "
                                       f"{list(full.referenceConfigurations)}")
        if isinstance(d.posture, str):
            q = np.array(full.referenceConfigurations[d.posture], dtype=float)
            Robot._check_group_state(full, q, d)
        else:
            q = Robot._set_joint_angles(full, pin.neutral(full), d.posture, "posture", d.name)
        return Robot._set_joint_angles(full, q, d.posture_overrides, "posture_overrides", d.name)

    @staticmethod
    def _check_group_state(full: pin.Model, q: np.ndarray, d: RobotDescription) -> None:
        """The SRDF group state puts every joint that stays in the model (not locked, not set again
        by ``posture_overrides``) within its URDF limits; DescriptionError naming each joint
        outside and the way out otherwise."""
        outside = []
        for joint in _model_joint_names(full):
            j = full.joints[full.getJointId(joint)]
            if joint in d.locked_joints or joint in d.posture_overrides or j.nq != 1:
                continue
            lo, hi = full.lowerPositionLimit[j.idx_q], full.upperPositionLimit[j.idx_q]
            if not lo - 1e-9 <= q[j.idx_q] <= hi + 1e-9:
                outside.append(f"'{joint}' at {float(q[j.idx_q]):g} (limits [{float(lo):g}, "
                               f"{float(hi):g}])")
        if outside:
            raise DescriptionError(
                f"robot '{d.name}': field 'posture' = '{d.posture}' puts joints outside their "
                f"limits in the model file: {', '.join(outside)}; set posture_overrides for them to angles inside")

    @staticmethod
    def _set_joint_angles(full: pin.Model, q: np.ndarray, table, field: str,
                          name: str) -> np.ndarray:
        """``q`` with the angles of ``table`` {joint: angle}, each a 1-DoF joint of the model
        within its URDF limits (DescriptionError naming ``field``.joint otherwise)."""
        joints = _model_joint_names(full)
        for joint, value in table.items():
            if joint not in joints:
                raise DescriptionError(f"robot '{name}': field '{field}' names unknown joint "
                                       f"'{joint}'; joints of the model: {joints}")
            j = full.joints[full.getJointId(joint)]
            if j.nq == 2 and j.nv == 1:  # a continuous joint: (cos, sin) of the angle, no limits
                q[j.idx_q:j.idx_q + 2] = math.cos(value), math.sin(value)
                continue
            if j.nq != 1:
                raise DescriptionError(f"robot '{name}': {field}.{joint}: joint '{joint}' "
                                       f"({j.shortname()}) has no single angle")
            lo, hi = full.lowerPositionLimit[j.idx_q], full.upperPositionLimit[j.idx_q]
            if not lo - 1e-9 <= value <= hi + 1e-9:
                raise DescriptionError(f"robot '{name}': {field}.{joint} = {value!r} is outside "
                                       f"the joint's URDF limits [{float(lo):g}, {float(hi):g}]")
            q[j.idx_q] = value
        return q

    @staticmethod
    def _reduce_posture(full: pin.Model, model: pin.Model, q_full: np.ndarray) -> np.ndarray:
        q = pin.neutral(model)
        q[:FREE_FLYER_NQ] = q_full[:FREE_FLYER_NQ]
        for jid in range(2, model.njoints):
            src = full.joints[full.getJointId(model.names[jid])]
            dst = model.joints[jid]
            q[dst.idx_q:dst.idx_q + dst.nq] = q_full[src.idx_q:src.idx_q + src.nq]
        return q

    def _check_contact_sizes(self, where: str) -> None:
        """Each contact's size (a sphere's radius, a sole's half lengths) below the height of
        the base above that contact's frame in the posture: a foot larger than the leg it ends
        is a typo (a radius of 1e6 m made a robot standing 1000 km tall, whose thresholds,
        relative to that height, passed anything)."""
        pin.framesForwardKinematics(self.model, self.data, self.q_ref)
        for i, c in enumerate(self.contacts):
            leg = float(self.q_ref[2] - self.data.oMf[c.frame_id].translation[2])
            size = (("radius", c.spec.radius) if c.spec.type == "point" else
                    ("half_size", max(c.spec.half_size)))
            if not size[1] < leg:
                raise DescriptionError(
                    f"{where}: field 'contacts[{i}].{size[0]}' = {size[1]!r} m: the contact "
                    f"'{c.name}' is larger than the {leg:.3f} m from its frame up to the base in "
                    f"the posture")

    def _check_joint_types(self) -> None:
        root = self.model.joints[1]
        if root.nq != FREE_FLYER_NQ or root.nv != FREE_FLYER_NV:
            raise DescriptionError(f"robot '{self.name}': the root joint must be a free flyer")
        for jid in range(2, self.model.njoints):
            j = self.model.joints[jid]
            if j.nv != 1 or j.nq not in (1, 2):  # nq = 2: a continuous joint (cos, sin)
                raise DescriptionError(f"robot '{self.name}': joint '{self.model.names[jid]}' "
                                       f"({j.shortname()}) is not a 1-DoF revolute, continuous "
                                       f"or prismatic joint (lock it with 'locked_joints')")

    def _set_armature(self, armature, source) -> None:
        """The joint-space armature: the model file's (MJCF ``armature``; a URDF has none),
        replaced by the description's ``armature`` (scalar: all joints; table: the joints named)."""
        arm = np.zeros(self.nv)
        if isinstance(armature, dict):
            for joint in armature:
                if joint not in self.joint_names:
                    locked = joint in self.description.locked_joints
                    raise DescriptionError(
                        f"robot '{self.name}': armature.{joint}: "
                        + ("the joint is locked" if locked else "no such actuated joint")
                        + f"; actuated joints: {list(self.joint_names)}")
        arm[FREE_FLYER_NV:] = model_armature(source, self.joint_names, armature)
        if not (np.all(np.isfinite(arm)) and np.all(arm >= 0)):  # RobotDescription checked it
            raise DescriptionError(f"robot '{self.name}': armature: expected finite numbers >= 0, "
                                   f"got {armature!r}")
        self.model.armature = arm

    def _warn_placeholder_limits(self, config) -> None:
        """Log a warning naming the joints whose URDF effort limit (times ``scale``, joints with
        an override or a linkage excepted) exceeds 10x the robot's weight times 1 m: such limits
        (e.g. Solo12's 1000 Nm on a 2.5 kg robot) are placeholders, not the actuators'."""
        given = set(config.get("overrides", {})) | set(config.get("linkage", {}))
        threshold = PLACEHOLDER_TORQUE_FACTOR * self.mass * GRAVITY * 1.0
        tl = self.torque_limits
        big = [f"{j} ({tl.scale * c:g} Nm)" for j, c in zip(self.joint_names, tl.constant)
               if j not in given and tl.scale * c > threshold]
        if big:
            log.warning("robot '%s': effort limit of joint(s) %s exceeds %g x the robot's weight "
                        "times 1 m (%.0f Nm); likely a URDF placeholder: give the actuators' "
                        "limits with torque_limits.overrides", self.name, ", ".join(big),
                        PLACEHOLDER_TORQUE_FACTOR, threshold)

    def frame_id(self, frame: str, field: str = "frame") -> int:
        """The model's id of ``frame``; ValueError naming ``field`` if the model has no such frame."""
        if not self.model.existFrame(frame):
            raise ValueError(f"robot '{self.name}': {field} = '{frame}' is not a frame of the model")
        return int(self.model.getFrameId(frame))

    def rest_on_ground(self, q: np.ndarray) -> np.ndarray:
        """Shift the base vertically so that the lowest contact touches the ground z = 0."""
        pin.framesForwardKinematics(self.model, self.data, q)
        heights = [self.contact_lowest_point(c, self.data.oMf[c.frame_id])[2] for c in self.contacts]
        q = q.copy()
        q[2] -= min(heights)
        return q

    @staticmethod
    def contact_lowest_point(contact: Contact, placement: pin.SE3) -> np.ndarray:
        """Lowest point of a contact's geometry (sphere bottom, or lowest sole corner) in the world."""
        if contact.spec.type == "point":
            return placement.translation - np.array([0.0, 0.0, contact.spec.radius])
        hx, hy = contact.spec.half_size
        corners = np.array([[sx * hx, sy * hy, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
        world = corners @ placement.rotation.T + placement.translation
        return world[np.argmin(world[:, 2])]

    # ------------------------------------------------------------------ per-cycle cache
    def update(self, q, v) -> None:
        """One Pinocchio pass for this control cycle (state in Pinocchio convention).

        Caches: ``M`` (symmetric), ``h`` (nonlinear effects), ``com``, ``vcom``, ``J_com``,
        ``com_drift`` (= J̇_com v), ``A_G`` (centroidal momentum matrix), ``h_G``, ``A_G_dot_v``
        (= Ȧ_G v), and for every contact its Jacobian and drift (LOCAL_WORLD_ALIGNED).
        """
        q = check_vector(q, self.nq, "q")
        v = check_vector(v, self.nv, "v")
        quat = q[3:7]
        quat_norm = math.sqrt(float(quat @ quat))
        if abs(quat_norm - 1.0) > 1e-3:
            raise ValueError(f"q: base quaternion q[3:7] must be unit, has norm {quat_norm:.6f}")
        model, data = self.model, self.data
        self.q, self.v = q.copy(), v.copy()
        self.cycle += 1
        self._frame_cache.clear()
        # computeAllTerms: FK with zero acceleration (data.a = bias accelerations), crba, nle,
        # joint Jacobians, CoM and its Jacobian, CCRBA (A_G, h_G).
        pin.computeAllTerms(model, data, q, v)
        pin.updateFramePlacements(model, data)
        dh = pin.computeCentroidalMomentumTimeVariation(model, data)
        M = data.M  # crba fills the upper triangle
        flat = M.reshape(-1)
        flat[self._lower_flat] = flat[self._upper_flat]
        self.M = M
        self.h = data.nle
        self.com = data.com[0].copy()
        self.vcom = data.vcom[0].copy()
        self.J_com = data.Jcom
        self.A_G = data.Ag
        self.h_G = data.hg.vector.copy()
        self.A_G_dot_v = dh.vector.copy()
        self.com_drift = self.A_G_dot_v[:3] / self.mass
        self._update_contacts()

    def terms_finite(self) -> bool:
        """True when the cycle's cached terms (M, h, Ȧ_G v, the contact Jacobians and drifts) are
        finite. A finite state can make them inf/NaN: products of a velocity beyond ~1e154
        overflow."""
        J = self._frame_cache[("stacked J", self.contact_names)]
        drift = self._frame_cache[("stacked drift", self.contact_names)]
        return all(bool(np.isfinite(a).all()) for a in (self.M, self.h, self.A_G_dot_v, J, drift))

    def _update_contacts(self) -> None:
        """Contact Jacobians, drifts and points of every contact, filled into one stacked array
        per cycle (``contact_jacobians[name]`` are views of it, so stacking all contacts is free).

        Point contacts with a radius are the material point under the foot sphere's centre,
        d = (0, 0, -r) in world axes (:meth:`_contact_jacobian`); robots whose contacts are all
        points (or all rectangles) are handled in one vectorised pass."""
        model, data, LWA = self.model, self.data, pin.LOCAL_WORLD_ALIGNED
        ids = self._contact_frame_ids
        J6, acc6 = np.empty((len(ids), 6, self.nv)), np.empty((len(ids), 6))
        oMf, points = data.oMf, np.empty((len(ids), 3))
        for i, fid in enumerate(ids):
            J6[i] = pin.getFrameJacobian(model, data, fid, LWA)
            acc6[i] = pin.getFrameClassicalAcceleration(model, data, fid, LWA).vector
            points[i] = oMf[fid].translation
        if self._all_points:
            J_ang = J6[:, 3:]
            J = (J6[:, :3] + self._offset_skew @ J_ang).reshape(-1, self.nv)  # J_lin - [d]x J_ang
            w = J_ang @ self.v  # angular velocities (world axes)
            # α x d + ω x (ω x d) = -[d]x α + r (ẑ |ω|² - ω_z ω)  for d = (0, 0, -r)
            rot = w * -w[:, 2:3]
            rot[:, 2] += np.einsum("ij,ij->i", w, w)
            rot *= self._radii[:, None]
            rot += acc6[:, :3]
            rot += (self._offset_skew @ acc6[:, 3:, None])[:, :, 0]
            drift = rot.reshape(-1)
        elif self._all_rectangles:
            J = J6.reshape(-1, self.nv).copy()
            drift = acc6.reshape(-1).copy()
        else:
            J = np.empty((self._contact_rows, self.nv))
            drift = np.empty(self._contact_rows)
            for i, (c, rows) in enumerate(zip(self.contacts, self._contact_slices)):
                omega = J6[i, 3:] @ self.v
                J[rows] = self._contact_jacobian(c, J6[i])
                drift[rows] = self._contact_drift(c, acc6[i], omega)
        points[:, 2] -= self._radii
        slices = self._contact_slices
        self.contact_jacobians = {n: J[rows] for n, rows in zip(self.contact_names, slices)}
        self.contact_drifts = {n: drift[rows] for n, rows in zip(self.contact_names, slices)}
        self.contact_points = points  # (n_contacts, 3), world: sole origins / sphere bottoms
        self.contact_frame_jacobians = J6  # (n_contacts, 6, nv): the contact frames' origins
        self.contact_frame_drifts = acc6  # (n_contacts, 6): their classical accelerations
        self._frame_cache[("stacked J", self.contact_names)] = J
        self._frame_cache[("stacked drift", self.contact_names)] = drift

    def _contact_jacobian(self, c: Contact, J: np.ndarray) -> np.ndarray:
        """From the frame's 6D Jacobian ``J``: rectangles keep it; points take the linear Jacobian
        of the material point under the foot sphere's centre, d = (0, 0, -radius) below it in
        world axes (for a rolling sphere that point is at rest while the centre moves):
        J_p = J_lin - [d]x J_ang."""
        if c.dim == 6:
            return J
        Jp = J[:3].copy()
        r = c.spec.radius  # -[d]x J_ang with d = (0, 0, -r): rows (-r J_wy, r J_wx, 0)
        Jp[0] -= r * J[4]
        Jp[1] += r * J[3]
        return Jp

    def _contact_drift(self, c: Contact, acc: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """J̇v of the same point from the frame's classical acceleration ``acc`` (6) and angular
        velocity ``omega``: a_f + α x d + ω x (ω x d) at zero joint acceleration."""
        if c.dim == 6:
            return acc
        a = acc[:3].copy()
        r, al, w = c.spec.radius, acc[3:], omega
        a[0] -= r * (al[1] + w[0] * w[2])  # α x d + ω(ω·d) − d|ω|², d = (0, 0, -r)
        a[1] += r * (al[0] - w[1] * w[2])
        a[2] += r * (w[0] * w[0] + w[1] * w[1])
        return a

    def contact_point(self, name: str) -> np.ndarray:
        """World position of a contact's point: the sole frame origin, or the bottom of a foot
        sphere (frame origin minus radius along world z)."""
        self.contact(name)  # a clear error for unknown names
        return self.contact_points[self._contact_index[name]].copy()

    def frame_jacobian(self, frame: str) -> np.ndarray:
        """6×nv Jacobian [linear; angular] of ``frame`` (LOCAL_WORLD_ALIGNED), cached per cycle."""
        key = (frame, 0)
        if key not in self._frame_cache:
            fid = self.frame_id(frame, "frame")
            self._frame_cache[key] = pin.getFrameJacobian(self.model, self.data, fid,
                                                          pin.LOCAL_WORLD_ALIGNED)
        return self._frame_cache[key]

    def frame_drift(self, frame: str) -> np.ndarray:
        """Classical acceleration [linear; angular] of ``frame`` at zero qdd (J̇v), cached per cycle."""
        key = (frame, 1)
        if key not in self._frame_cache:
            fid = self.frame_id(frame, "frame")
            self._frame_cache[key] = pin.getFrameClassicalAcceleration(
                self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED).vector.copy()
        return self._frame_cache[key]

    def frame_placement(self, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """(position, rotation matrix) of ``frame`` in the world."""
        oMf = self.data.oMf[self.frame_id(frame, "frame")]
        return oMf.translation.copy(), oMf.rotation.copy()

    def frame_velocity(self, frame: str) -> np.ndarray:
        """Spatial velocity [linear; angular] of ``frame`` (LOCAL_WORLD_ALIGNED)."""
        return pin.getFrameVelocity(self.model, self.data, self.frame_id(frame, "frame"),
                                    pin.LOCAL_WORLD_ALIGNED).vector.copy()

    def centroidal_inertia(self, q=None) -> np.ndarray:
        """The locked (composite rigid body) centroidal inertia I_G (3x3, world axes, about the
        CoM) at ``q`` (default: the last :meth:`update`'s), from Pinocchio's ``ccrba`` on its own
        ``Data``."""
        q = self.q if q is None else check_vector(q, self.nq, "q")
        data = self.model.createData()
        pin.ccrba(self.model, data, np.asarray(q, float), np.zeros(self.nv))
        return data.Ig.inertia.copy()

    def contact(self, name: str) -> Contact:
        try:  # called by several tasks every cycle: a dict, not a search
            return self._contacts_by_name[name]
        except KeyError:
            raise ValueError(f"contact: unknown contact '{name}'; have "
                             f"{list(self.contact_names)}") from None

    # ------------------------------------------------------------------ stacked contact terms
    def stacked_contact_jacobian(self, names: Sequence[str] | None = None) -> np.ndarray:
        """Contact Jacobians of ``names`` (default: all contacts) stacked row-wise."""
        names = self.contact_names if names is None else tuple(names)
        key = ("stacked J", names)
        if key not in self._frame_cache:  # cached for the cycle: several tasks need it
            self._frame_cache[key] = (np.vstack([self.contact_jacobians[n] for n in names])
                                      if names else np.zeros((0, self.nv)))
        return self._frame_cache[key]

    def stacked_contact_drift(self, names: Sequence[str] | None = None) -> np.ndarray:
        names = self.contact_names if names is None else tuple(names)
        key = ("stacked drift", names)
        if key not in self._frame_cache:
            self._frame_cache[key] = (np.concatenate([self.contact_drifts[n] for n in names])
                                      if names else np.zeros(0))
        return self._frame_cache[key]

    # ------------------------------------------------------------------ helpers
    def torque_bounds(self, q=None) -> tuple[np.ndarray, np.ndarray]:
        """(tau_min(q), tau_max(q)) for the actuated joints at ``q`` (default: the cached state)."""
        q = self.q if q is None else q
        return self.torque_limits.bounds(self.joint_angles(q))

    # ------------------------------------------------------------------ joint angles
    def joint_angles(self, q) -> np.ndarray:
        """The ``na`` joint angles (or slide positions) of configuration ``q``, in joint order:
        ``q[7:]`` when every joint has one coordinate; a continuous joint's (cos, sin) pair gives
        ``atan2(sin, cos)`` in (-pi, pi]."""
        q = np.asarray(q, dtype=float)
        if self.angles_are_coordinates:
            return q[FREE_FLYER_NQ:].copy()
        angles = np.empty(self.na)
        angles[self._bounded] = q[self._angle_q]
        angles[self._unbounded] = np.arctan2(q[self._sin_q], q[self._cos_q])
        return angles

    def with_joint_angles(self, q, angles) -> np.ndarray:
        """A copy of configuration ``q`` with the joints at ``angles`` (``na``): the inverse of
        :meth:`joint_angles` (a continuous joint gets (cos, sin) of its angle)."""
        q = np.array(q, dtype=float)
        angles = np.asarray(angles, dtype=float)
        q[self._angle_q] = angles[self._bounded]
        q[self._cos_q] = np.cos(angles[self._unbounded])
        q[self._sin_q] = np.sin(angles[self._unbounded])
        return q

    def joint_error(self, q, q_ref) -> np.ndarray:
        """``q_ref``'s joints relative to ``q``'s, in velocity coordinates (``na``):
        ``pin.difference(q, q_ref)[6:]`` (``q_ref[7:] - q[7:]`` for one-coordinate joints; the
        shortest signed angle, in (-pi, pi], for a continuous joint), what a posture task drives
        to zero."""
        if self.angles_are_coordinates:
            return np.asarray(q_ref, float)[FREE_FLYER_NQ:] - np.asarray(q, float)[FREE_FLYER_NQ:]
        return pin.difference(self.model, np.asarray(q, float),
                              np.asarray(q_ref, float))[FREE_FLYER_NV:]

    def random_state(self, rng: np.random.Generator, velocity_scale: float = 1.0
                     ) -> tuple[np.ndarray, np.ndarray]:
        """A random (q, v) with joints inside their limits (for tests and benchmarks)."""
        q = self.q_ref.copy()
        lo = np.where(np.isfinite(self.q_min), self.q_min, -np.pi)
        hi = np.where(np.isfinite(self.q_max), self.q_max, np.pi)
        q = self.with_joint_angles(q, rng.uniform(lo, hi))
        q[:3] += rng.normal(scale=0.1, size=3)
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
        v = rng.normal(scale=velocity_scale, size=self.nv)
        return q, v

    def smooth_motion(self, cycles: int, dt: float = 1e-3, seed: int = 0
                      ) -> list[tuple[np.ndarray, np.ndarray]]:
        """``cycles`` states (q, v) of a smooth motion around the reference posture, ``dt`` apart
        (for tests and benchmarks): every joint a sine of amplitude 0.02-0.1 rad and 0.3-1 Hz
        (kept 0.05 rad inside its limits), the base at rest with a small oscillating twist."""
        rng = np.random.default_rng(seed)
        amp = rng.uniform(0.02, 0.1, self.na)
        freq = rng.uniform(0.3, 1.0, self.na)
        phase = rng.uniform(0, 2 * np.pi, self.na)
        lo, hi = self.q_min + 0.05, self.q_max - 0.05
        states = []
        for k in range(cycles):
            t = k * dt
            q = self.q_ref.copy()
            q = self.with_joint_angles(q, np.clip(
                self.joint_angles(self.q_ref) + amp * np.sin(2 * np.pi * freq * t + phase), lo, hi))
            v = np.zeros(self.nv)
            v[FREE_FLYER_NV:] = amp * 2 * np.pi * freq * np.cos(2 * np.pi * freq * t + phase)
            v[:FREE_FLYER_NV] = 0.05 * np.sin(2 * np.pi * 0.5 * t + np.arange(FREE_FLYER_NV))
            states.append((q, v))
        return states

    def native_model_spec(self) -> dict:
        """The model's joints, bodies and armature for the compiled cycles (``src/wholebody/native``,
        ``add_joints``), which rebuild the same Pinocchio model from these arrays (copied)."""
        model = self.model
        joints = range(1, model.njoints)
        kinds = [model.joints[j].shortname() for j in joints]
        return {
            "parents": [int(model.parents[j]) for j in joints],
            "kinds": kinds,
            # the axis of an unaligned revolute/prismatic joint (a URDF axis such as "-1 0 0"),
            # zero for the others
            "axes": np.array([model.joints[j].extract().axis if "Unaligned" in kind
                              else np.zeros(3) for j, kind in zip(joints, kinds)]),
            "placements": np.array([model.jointPlacements[j].homogeneous for j in joints]),
            "masses": np.array([model.inertias[j].mass for j in joints]),
            "levers": np.array([model.inertias[j].lever for j in joints]),
            "inertias": np.array([model.inertias[j].inertia for j in joints]),
            "armature": np.asarray(model.armature, float),
        }

    def summary(self) -> dict:
        """Name, DoF, mass and contacts (for ``wholebody robots``)."""
        return {
            "name": self.name,
            "actuated_dof": self.na,
            "nq": self.nq,
            "nv": self.nv,
            "mass_kg": round(self.mass, 3),
            "contacts": [f"{c.name} ({c.spec.type})" for c in self.contacts],
        }

    def __repr__(self) -> str:
        return (f"Robot({self.name!r}, {self.na} actuated DoF, {self.mass:.1f} kg, "
                f"contacts={list(self.contact_names)})")
