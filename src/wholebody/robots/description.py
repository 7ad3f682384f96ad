"""Declarative robot descriptions: a TOML file or a dict is all it takes to add a robot.

Fields (``*`` = required)::

    name*          short name
    urdf*          "erd:<path inside example-robot-data/robots>" or a file path (relative to the TOML)
    srdf           same; needed when ``posture`` is a group-state name
    posture*       SRDF group-state name (e.g. "half_sitting") or a table {joint name = angle}
    locked_joints  joints frozen at the posture (Pinocchio ``buildReducedModel``), default none
    armature       rotor inertia added to the joint-space inertia of every actuated joint (scalar or
                   {joint = value}); the MuJoCo twin uses the same value, default 0
    contacts*      list of {name, frame, type = "point", radius} or
                   {name, frame, type = "rectangle", half_size = [hx, hy]} (sole half-lengths along
                   the frame's x and y axes, centred on the frame origin)
    torque_limits  {scale = 1.0, overrides = {joint = Nm}, linkage = {joint = {...}}} (see
                   :mod:`wholebody.robots.torque_limits`)
    friction       nominal Coulomb friction coefficient of the feet used by controllers, default 0.8
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

CONTACT_TYPES = ("point", "rectangle")


class DescriptionError(ValueError):
    """A robot description is missing a field or has a bad value (the message names the field)."""


@dataclass(frozen=True)
class ContactSpec:
    """A contact: a frame plus its geometry (a point with a radius, or a rectangle)."""

    name: str
    frame: str
    type: str
    radius: float = 0.0
    half_size: tuple[float, float] = (0.0, 0.0)

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
    srdf: str | None = None
    locked_joints: tuple[str, ...] = ()
    armature: float | dict[str, float] = 0.0
    torque_limits: dict[str, Any] = field(default_factory=dict)
    friction: float = 0.8
    base_dir: Path | None = None

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], base_dir: Path | None = None) -> "RobotDescription":
        where = f"robot description '{data.get('name', '?')}'"

        def need(key: str) -> Any:
            if key not in data or data[key] in (None, "", []):
                raise DescriptionError(f"{where}: missing required field '{key}'")
            return data[key]

        known = {"name", "urdf", "srdf", "posture", "locked_joints", "armature", "contacts",
                 "torque_limits", "friction", "description"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise DescriptionError(f"{where}: unknown field(s) {unknown}; known: {sorted(known)}")
        name = str(need("name"))
        urdf = str(need("urdf"))
        posture = need("posture")
        if isinstance(posture, Mapping):
            posture = {str(k): float(v) for k, v in posture.items()}
        elif not isinstance(posture, str):
            raise DescriptionError(f"{where}: field 'posture' must be a group-state name or a table")
        srdf = data.get("srdf")
        if isinstance(posture, str) and not srdf:
            raise DescriptionError(f"{where}: field 'srdf' is required when 'posture' is a name")
        contacts = tuple(_parse_contact(c, i, where) for i, c in enumerate(need("contacts")))
        names = [c.name for c in contacts]
        if len(set(names)) != len(names):
            raise DescriptionError(f"{where}: field 'contacts' has duplicate names {names}")
        armature = data.get("armature", 0.0)
        if isinstance(armature, Mapping):
            armature = {str(k): float(v) for k, v in armature.items()}
        else:
            armature = float(armature)
        friction = float(data.get("friction", 0.8))
        if not friction > 0:
            raise DescriptionError(f"{where}: field 'friction' must be > 0, got {friction}")
        return cls(
            name=name, urdf=urdf, srdf=str(srdf) if srdf else None, posture=posture,
            contacts=contacts, locked_joints=tuple(str(j) for j in data.get("locked_joints", ())),
            armature=armature, torque_limits=dict(data.get("torque_limits", {})),
            friction=friction, base_dir=base_dir,
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
    field_name = f"contacts[{index}]"
    if not isinstance(raw, Mapping):
        raise DescriptionError(f"{where}: field '{field_name}' must be a table")
    for key in ("name", "frame", "type"):
        if key not in raw:
            raise DescriptionError(f"{where}: missing required field '{field_name}.{key}'")
    kind = str(raw["type"])
    if kind not in CONTACT_TYPES:
        raise DescriptionError(
            f"{where}: field '{field_name}.type' is '{kind}', expected one of {CONTACT_TYPES}")
    if kind == "point":
        if "radius" not in raw:
            raise DescriptionError(f"{where}: missing required field '{field_name}.radius'")
        radius = float(raw["radius"])
        if radius < 0:
            raise DescriptionError(f"{where}: field '{field_name}.radius' must be >= 0")
        return ContactSpec(str(raw["name"]), str(raw["frame"]), kind, radius=radius)
    if "half_size" not in raw:
        raise DescriptionError(f"{where}: missing required field '{field_name}.half_size'")
    half = tuple(float(x) for x in raw["half_size"])
    if len(half) != 2 or min(half) <= 0:
        raise DescriptionError(
            f"{where}: field '{field_name}.half_size' must be two positive lengths [hx, hy]")
    return ContactSpec(str(raw["name"]), str(raw["frame"]), kind, half_size=half)  # type: ignore[arg-type]
