"""Declarative robot descriptions: a TOML file or a dict is all it takes to add a robot.

Fields (``*`` = required)::

    name*          short name
    model*         the robot's model file, a URDF or an MJCF (MuJoCo XML, told apart by its root
                   element ``<mujoco>``): "erd:<path inside example-robot-data/robots>" or a file
                   path (relative to the TOML); ``urdf`` is the same field under its older name
                   (give one of the two)
    srdf           same; needed when ``posture`` is a group-state name
    posture*       SRDF group-state name (e.g. "half_sitting"), "keyframe:<name>" (a keyframe of
                   an MJCF model file, e.g. "keyframe:home") or a table {joint name = angle}
    posture_overrides  {joint = angle} applied on top of the posture (e.g. an SRDF state with the
                   knees straighter), default none
    locked_joints  joints frozen at the posture (Pinocchio ``buildReducedModel``), default none
    armature       rotor inertia added to the joint-space inertia of every actuated joint (scalar or
                   {joint = value}); the MuJoCo twin uses the same value, default the model
                   file's (an MJCF joint's ``armature``; 0 for a URDF); a table replaces the
                   joints it names only
    inertia_overrides  {link = [ixx, iyy, izz]}: principal moments (kg m^2, about the link's centre
                   of mass, in its <inertial> frame) replacing the URDF's <inertia> of these links
                   (a URDF with zero or broken inertias), default none
    contacts*      list of {name, frame, type = "point", radius} or
                   {name, frame, type = "rectangle", half_size = [hx, hy]} (sole half-lengths along
                   the frame's x and y axes); ``offset = [x, y, z]`` (m, in the frame's axes,
                   default 0) places the sphere centre or the sole centre relative to the frame
                   (a foot frame below its sphere, a sole declared on the ankle link); each may
                   carry a ``role`` (one of ``ROLES``: which foot or sole it is), else the role is found
                   from where the contact is (:mod:`wholebody.robots.roles`)
    torque_limits  {scale = 1.0, overrides = {joint = Nm}, linkage = {joint = {...}}} (see
                   :mod:`wholebody.robots.torque_limits`)
    friction       nominal Coulomb friction coefficient of the feet used by controllers, default 0.8
    trunk_frame    the upper-body frame that pushes and trunk tasks address, default the base
    plant          an MJCF file (path relative to the TOML) simulated in place of the exact twin:
                   the vendor's own MuJoCo model of the robot, its joints mapped to the
                   controller's by name (:mod:`wholebody.sim.plant`); default none (the twin)

Every number is checked here, with a :class:`DescriptionError` naming its path (``posture.<joint>``,
``armature.<joint>``, ``contacts[i].radius``, ``torque_limits.overrides.<joint>``...) and the value:
all finite; radius and armature >= 0; half_size entries, friction, torque scale, overrides and
linkage a, b, force > 0. Unknown keys are errors at every level. Joint and frame names, and the
URDF's effort limits and link inertias, are checked against the model by :class:`wholebody.Robot`.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .. import validation

CONTACT_TYPES = ("point", "rectangle")
CONTACT_KEYS = {"point": ("name", "frame", "type", "radius", "offset", "role"),
                "rectangle": ("name", "frame", "type", "half_size", "offset", "role")}
#: the roles a contact can declare: a quadruped's feet, a biped's soles
ROLES = {"point": ("left-front", "right-front", "left-hind", "right-hind"),
         "rectangle": ("left", "right")}
TORQUE_LIMIT_KEYS = ("scale", "overrides", "linkage")
LINKAGE_KEYS = ("a", "b", "force", "q_peak")


class DescriptionError(ValueError):
    """A robot description is missing a field or has a bad value (the message names the field)."""


def _checked(check, value, path: str, where: str, **kwargs) -> float:
    """``check`` (a :mod:`wholebody.validation` number check) of ``value``, named ``path``; a
    DescriptionError prefixed by ``where`` otherwise. Strings and booleans are not numbers here
    (TOML ``"0.5"`` or ``true`` is a typo, not a value)."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, (str, bytes, bool)) or value is None:
        raise DescriptionError(f"{where}: {path}: expected a number, got {value!r}")
    try:
        return check(value, path, **kwargs)
    except ValueError as exc:
        raise DescriptionError(f"{where}: {exc}") from None


def _principal_moments(value: Any, path: str, where: str) -> tuple[float, float, float]:
    """Three principal moments of inertia: each finite and > 0, and each at most the sum of the
    other two (the triangle inequality every rigid body satisfies)."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise DescriptionError(f"{where}: {path}: expected three principal moments [ixx, iyy, "
                               f"izz] (kg m^2), got {value!r}")
    moments = tuple(_checked(validation.positive, v, f"{path}[{i}]", where)
                    for i, v in enumerate(value))
    if any(2 * m > sum(moments) * (1 + 1e-9) for m in moments):
        raise DescriptionError(f"{where}: {path}: {list(moments)} is no rigid body's inertia (each "
                               f"principal moment must be at most the sum of the other two)")
    return moments


def _table(value: Any, path: str, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise DescriptionError(f"{where}: {path}: expected a table, got {value!r}")
    return value


def _no_unknown_keys(table: Mapping[str, Any], allowed, path: str, where: str,
                     what: str = "") -> None:
    unknown = sorted(str(k) for k in set(table) - set(allowed))
    if unknown:
        raise DescriptionError(f"{where}: {path}: unknown key(s) {unknown}; allowed{what}: "
                               f"{sorted(allowed)}")


def _list(value: Any, path: str, where: str, expected: str) -> list:
    """``value`` as a list (a string or a table is not a list here)."""
    items = None
    if not isinstance(value, (str, bytes, Mapping)):
        try:
            items = list(value)
        except TypeError:
            pass
    if items is None:
        raise DescriptionError(f"{where}: {path}: expected {expected}, got {value!r}")
    return items


def _name(value: Any, path: str, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise DescriptionError(f"{where}: {path}: expected a non-empty string, got {value!r}")
    return value


#: what a robot's or a contact's own name may hold: it becomes a folder's name, figure text and
#: page text, so no path separators, no leading dot, nothing a plot or a page would interpret
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9 _.+()-]*")


def _label(value: Any, path: str, where: str) -> str:
    """A name given in the description (the robot's, a contact's): :data:`NAME_PATTERN`."""
    value = _name(value, path, where)
    if not NAME_PATTERN.fullmatch(value) or ".." in value:
        raise DescriptionError(f"{where}: {path}: {value!r} is not a name: use letters, digits, "
                               f"spaces and _ . + ( ) -, starting with a letter or a digit")
    return value


def check_torque_limits(raw: Any, where: str = "robot description") -> dict[str, Any]:
    """The ``torque_limits`` table with its numbers checked (joint names are checked against the
    model by :class:`wholebody.robots.torque_limits.TorqueProfile`): ``scale`` finite > 0,
    ``overrides`` finite > 0 Nm, each ``linkage`` entry exactly {a, b, force, q_peak} with lengths
    a != b and force finite > 0, q_peak finite. Returns the table with floats (keys as given)."""
    config = _table({} if raw is None else raw, "torque_limits", where)
    _no_unknown_keys(config, TORQUE_LIMIT_KEYS, "torque_limits", where)
    out: dict[str, Any] = {}
    if "scale" in config:
        out["scale"] = _checked(validation.positive, config["scale"], "torque_limits.scale", where)
    if "overrides" in config:
        overrides = _table(config["overrides"], "torque_limits.overrides", where)
        out["overrides"] = {str(j): _checked(validation.positive, v, f"torque_limits.overrides.{j}",
                                             where) for j, v in overrides.items()}
    if "linkage" in config:
        linkage = _table(config["linkage"], "torque_limits.linkage", where)
        out["linkage"] = {str(j): _linkage(p, f"torque_limits.linkage.{j}", where)
                          for j, p in linkage.items()}
    both = sorted(set(out.get("overrides", {})) & set(out.get("linkage", {})))
    if both:
        raise DescriptionError(
            f"{where}: torque_limits.overrides.{both[0]}: joint '{both[0]}' also has a "
            f"torque_limits.linkage profile, which replaces its constant bound; keep one of the "
            f"two")
    return out


def _linkage(raw: Any, path: str, where: str) -> dict[str, float]:
    p = _table(raw, path, where)
    for key in LINKAGE_KEYS:
        if key not in p:
            raise DescriptionError(f"{where}: field '{path}' misses key '{key}'")
    _no_unknown_keys(p, LINKAGE_KEYS, path, where)
    a = _checked(validation.positive, p["a"], f"{path}.a", where)
    b = _checked(validation.positive, p["b"], f"{path}.b", where)
    force = _checked(validation.positive, p["force"], f"{path}.force", where)
    q_peak = _checked(validation.number, p["q_peak"], f"{path}.q_peak", where)
    if a == b:  # the cylinder length sqrt(a^2 + b^2 - 2ab cos t) vanishes at t = 0: 0/0
        raise DescriptionError(f"{where}: {path}: a and b must differ, got a = b = {a!r} (the "
                               f"bound is 0/0 where the cylinder length vanishes)")
    return {"a": a, "b": b, "force": force, "q_peak": q_peak}


@dataclass(frozen=True)
class ContactSpec:
    """A contact: a frame plus its geometry (a point with a radius, or a rectangle)."""

    name: str
    frame: str
    type: str
    radius: float = 0.0
    half_size: tuple[float, float] = (0.0, 0.0)
    #: which foot or sole this is (one of ``ROLES[type]``); None: found from the geometry
    role: str | None = None
    #: the sphere centre (point) or the sole centre (rectangle) in the frame's coordinates (m)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def dim(self) -> int:
        """Size of the contact force: 3 for a point (force), 6 for a rectangle (force and torque)."""
        return 3 if self.type == "point" else 6


@dataclass(frozen=True)
class RobotDescription:
    """Everything needed to build a :class:`wholebody.Robot`, validated at construction."""

    name: str
    urdf: str
    posture: str | dict[str, float]
    contacts: tuple[ContactSpec, ...]
    posture_overrides: dict[str, float] = field(default_factory=dict)
    srdf: str | None = None
    locked_joints: tuple[str, ...] = ()
    #: None: the model file's armature (MJCF), else a scalar for every joint or {joint: value}
    armature: float | dict[str, float] | None = None
    inertia_overrides: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    torque_limits: dict[str, Any] = field(default_factory=dict)
    friction: float = 0.8
    trunk_frame: str | None = None
    #: the vendor's MJCF simulated in place of the exact twin (None: the twin)
    plant: str | None = None
    base_dir: Path | None = None
    #: the key the model file was given under ("model" or "urdf"), for messages
    model_key: str = field(default="urdf", compare=False)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], base_dir: Path | None = None) -> "RobotDescription":
        """Check every field (numbers finite and in range, tables with known keys only) and build
        the description; DescriptionError naming the field path and the bad value otherwise.
        Names of joints and frames are checked against the model by :class:`wholebody.Robot`."""
        if not isinstance(data, Mapping):
            raise DescriptionError(f"robot description: expected a table of fields, got {data!r}")
        where = f"robot description '{data.get('name', '?')}'"

        def need(key: str) -> Any:
            if key == "contacts" and isinstance(data.get(key), (list, tuple)) and not data[key]:
                raise DescriptionError(
                    f"{where}: field 'contacts' is empty; wholebody controls robots that stand on "
                    f"their feet: give at least the feet (point contacts) or the soles "
                    f"(rectangles), docs/robots.md; a robot without feet cannot be used")
            if key not in data or data[key] in (None, "", [], ()):
                raise DescriptionError(f"{where}: missing required field '{key}'")
            return data[key]

        known = {"name", "model", "urdf", "srdf", "posture", "posture_overrides", "locked_joints",
                 "armature", "inertia_overrides", "contacts", "torque_limits", "friction",
                 "trunk_frame", "description", "plant"}
        unknown = sorted(str(k) for k in set(data) - known)
        if unknown:
            raise DescriptionError(f"{where}: unknown field(s) {unknown}; known: {sorted(known)}")
        name = _label(need("name"), "name", where)
        if "model" in data and "urdf" in data:
            raise DescriptionError(f"{where}: fields 'model' and 'urdf' are both given "
                                   f"({data['model']!r}, {data['urdf']!r}); 'urdf' is the older "
                                   f"name of 'model': keep one")
        model_key = "urdf" if "urdf" in data else "model"
        if data.get(model_key) in (None, ""):
            raise DescriptionError(f"{where}: missing required field 'model' (the URDF or MJCF "
                                   f"file; 'urdf' is its older name)")
        urdf = _name(data[model_key], model_key, where)
        posture = need("posture")
        if isinstance(posture, Mapping):
            posture = {str(k): _checked(validation.number, v, f"posture.{k}", where)
                       for k, v in posture.items()}
        elif not isinstance(posture, str):
            raise DescriptionError(f"{where}: field 'posture' must be a group-state name or a "
                                   f"table {{joint = angle}}, got {posture!r}")
        overrides = _table(data.get("posture_overrides", {}), "posture_overrides", where)
        overrides = {str(k): _checked(validation.number, v, f"posture_overrides.{k}", where)
                     for k, v in overrides.items()}
        srdf = data.get("srdf")
        if srdf is not None and srdf != "":
            srdf = _name(srdf, "srdf", where)
        if isinstance(posture, str) and not srdf and not posture.startswith("keyframe:"):
            raise DescriptionError(f"{where}: field 'srdf' is required when 'posture' is a group-"
                                   f"state name (a keyframe of an MJCF file is "
                                   f"'keyframe:<name>'), got posture = {posture!r}")
        raw_contacts = _list(need("contacts"), "contacts", where, "a list of contact tables")
        contacts = tuple(_parse_contact(c, i, where) for i, c in enumerate(raw_contacts))
        names = [c.name for c in contacts]
        if len(set(names)) != len(names):
            raise DescriptionError(f"{where}: field 'contacts' has duplicate names {names}")
        roles = [c.role for c in contacts if c.role is not None]
        if len(set(roles)) != len(roles):
            raise DescriptionError(f"{where}: field 'contacts' gives a role to more than one "
                                   f"contact: {roles}")
        locked = _list(data.get("locked_joints", ()), "locked_joints", where,
                       "a list of joint names")
        locked = tuple(_name(j, f"locked_joints[{i}]", where) for i, j in enumerate(locked))
        armature = data.get("armature")
        if armature is None:
            pass
        elif isinstance(armature, Mapping):
            armature = {str(k): _checked(validation.nonnegative, v, f"armature.{k}", where)
                        for k, v in armature.items()}
        else:
            armature = _checked(validation.nonnegative, armature, "armature", where)
        inertias = {str(k): _principal_moments(v, f"inertia_overrides.{k}", where)
                    for k, v in _table(data.get("inertia_overrides", {}), "inertia_overrides",
                                       where).items()}
        friction = _checked(validation.positive, data.get("friction", 0.8), "friction", where)
        trunk = data.get("trunk_frame")
        trunk = None if trunk is None else _name(trunk, "trunk_frame", where)
        plant = data.get("plant")
        plant = None if plant is None else _name(plant, "plant", where)
        return cls(
            name=name, urdf=urdf, srdf=srdf or None, posture=posture, contacts=contacts,
            posture_overrides=overrides,
            locked_joints=locked, armature=armature, inertia_overrides=inertias,
            torque_limits=check_torque_limits(data.get("torque_limits"), where),
            friction=friction, trunk_frame=trunk, plant=plant, base_dir=base_dir,
            model_key=model_key,
        )

    @classmethod
    def from_toml(cls, path: str | Path) -> "RobotDescription":
        path = Path(path)
        try:
            with path.open("rb") as fh:
                data = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise DescriptionError(f"robot file {path}: invalid TOML: {exc}") from exc
        return cls.from_dict(data, base_dir=path.parent.resolve())


def _parse_contact(raw: Any, index: int, where: str) -> ContactSpec:
    path = f"contacts[{index}]"
    if not isinstance(raw, Mapping):
        raise DescriptionError(f"{where}: field '{path}' must be a table, got {raw!r}")
    for key in ("name", "frame", "type"):
        if key not in raw:
            raise DescriptionError(f"{where}: missing required field '{path}.{key}'")
    kind = raw["type"]
    if kind not in CONTACT_TYPES:
        raise DescriptionError(
            f"{where}: field '{path}.type' is {kind!r}, expected one of {CONTACT_TYPES}")
    _no_unknown_keys(raw, CONTACT_KEYS[kind], path, where, f" for a {kind} contact")
    name = _label(raw["name"], f"{path}.name", where)
    frame = _name(raw["frame"], f"{path}.frame", where)
    role = raw.get("role")
    if role is not None and role not in ROLES[kind]:
        raise DescriptionError(f"{where}: field '{path}.role' is {role!r}, expected one of "
                               f"{ROLES[kind]} for a {kind} contact")
    offset = (0.0, 0.0, 0.0)
    if "offset" in raw:
        expected = "three numbers [x, y, z] (m, in the frame's axes)"
        values = _list(raw["offset"], f"{path}.offset", where, expected)
        if len(values) != 3:
            raise DescriptionError(f"{where}: {path}.offset: expected {expected}, got "
                                   f"{raw['offset']!r}")
        offset = tuple(_checked(validation.number, x, f"{path}.offset[{k}]", where)
                       for k, x in enumerate(values))
    if kind == "point":
        if "radius" not in raw:
            raise DescriptionError(f"{where}: missing required field '{path}.radius'")
        radius = _checked(validation.nonnegative, raw["radius"], f"{path}.radius", where)
        return ContactSpec(name, frame, kind, radius=radius, role=role, offset=offset)
    if "half_size" not in raw:
        raise DescriptionError(f"{where}: missing required field '{path}.half_size'")
    expected = "two positive numbers [hx, hy] (half-lengths in m)"
    half = _list(raw["half_size"], f"{path}.half_size", where, expected)
    if len(half) != 2:
        raise DescriptionError(f"{where}: {path}.half_size: expected {expected}, got "
                               f"{raw['half_size']!r}")
    hx, hy = (_checked(validation.positive, x, f"{path}.half_size[{k}]", where)
              for k, x in enumerate(half))
    return ContactSpec(name, frame, kind, half_size=(hx, hy), role=role, offset=offset)
