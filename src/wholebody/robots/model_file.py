"""The model file of a robot description (its ``model`` / ``urdf`` field): a URDF or an MJCF file,
read into the full Pinocchio model (root joint: the free flyer of the floating base).

* A URDF is read by Pinocchio's URDF parser. Its floating base is the root link, under a free
  flyer added by the parser, unless the URDF declares its own: a ``floating`` joint from a root link
  (a massless "world" link) to the base, which then is the free flyer (named as in the URDF).
* An MJCF file (root element ``<mujoco>``) is compiled by MuJoCo and converted
  (:mod:`wholebody.robots.mjcf`): its ``<freejoint>`` is the free flyer, its keyframes become the
  model's reference configurations ``keyframe:<name>``, its armature the default armature.

urdfdom's parser warnings (printed on stderr by the C++ library, e.g. for an unknown element) are
caught and summarised in one log record instead of reaching the terminal.
"""

from __future__ import annotations

import logging
import os
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from .description import DescriptionError, RobotDescription
from .locate import resolve_model_path
from .mjcf import KEYFRAME_PREFIX, is_mjcf

log = logging.getLogger(__name__)


@dataclass
class ModelSource:
    """The full Pinocchio model read from a description's model file, and where it came from."""

    model: pin.Model
    path: Path
    format: str  # "urdf" or "mjcf"
    #: True when the file declares the floating joint itself (URDF ``floating`` joint, MJCF
    #: ``<freejoint>``); False when the free flyer was added at the root link
    own_floating_joint: bool = False
    armature: dict[str, float] = field(default_factory=dict)  # the file's, joint -> kg m^2
    effort_sources: dict[str, str] = field(default_factory=dict)
    mujoco_model: object = None  # MJCF: the compiled mujoco.MjModel (its geoms, for init-robot)


@contextmanager
def captured_stderr(what: str):
    """Collect what C/C++ code writes on file descriptor 2 during the block, and log it as one
    record (INFO, the first lines and a count) instead of letting it reach the terminal."""
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to redirect (a daemon): nothing to collect
        yield
        return
    with tempfile.TemporaryFile(mode="w+b") as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            lines = [ln for ln in sink.read().decode(errors="replace").splitlines() if ln.strip()]
            if lines:
                shown = "; ".join(lines[:3]) + (f" (and {len(lines) - 3} more lines)"
                                                 if len(lines) > 3 else "")
                log.info("%s: the parser said: %s", what, shown)


def urdf_floating_joint(path: Path) -> str | None:
    """The name of the URDF's ``floating`` joint from its root link, None if it has none;
    DescriptionError for a floating joint elsewhere in the tree (a second floating body)."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError:
        return None  # Pinocchio's parser says what is wrong
    joints = root.findall("joint")
    children = {j.find("child").get("link") for j in joints if j.find("child") is not None}
    floating = [j for j in joints if j.get("type") == "floating"]
    if not floating:
        return None
    at_root = [j for j in floating if j.find("parent") is not None
               and j.find("parent").get("link") not in children]
    if len(floating) > 1 or not at_root:
        names = [j.get("name") for j in floating]
        raise DescriptionError(f"URDF {path.name}: floating joint(s) {names} inside the tree; "
                               f"wholebody reads one floating joint, from the root link to the "
                               f"base")
    return at_root[0].get("name")


def _load_urdf(path: Path, d: RobotDescription, where: str) -> ModelSource:
    from ..robot import urdf_with_inertias

    floating = urdf_floating_joint(path)
    root = () if floating else (pin.JointModelFreeFlyer(),)
    with captured_stderr(f"{where}: URDF {path.name}"):
        if d.inertia_overrides:
            model = pin.buildModelFromXML(urdf_with_inertias(path, d.inertia_overrides, where),
                                          *root)
        else:
            model = pin.buildModelFromUrdf(str(path), *root)
    if floating:
        log.info("%s: the URDF's floating joint '%s' is the floating base", where, floating)
    return ModelSource(model, path, "urdf", own_floating_joint=bool(floating))


def _load_mjcf(path: Path, d: RobotDescription, where: str) -> ModelSource:
    import mujoco

    from .mjcf import build_model, compile_mjcf

    m = compile_mjcf(path, where)
    for link, moments in d.inertia_overrides.items():
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, link)
        if b < 0:
            raise DescriptionError(f"{where}: inertia_overrides.{link}: not a body of the MJCF")
        if m.body_mass[b] <= 0:
            raise DescriptionError(f"{where}: inertia_overrides.{link}: the body has no mass in "
                                   f"the MJCF")
        m.body_inertia[b] = moments  # principal moments, in the body's inertial frame
    built = build_model(m, where)
    model = built.model
    for key, angles in built.keyframes.items():
        q = pin.neutral(model)
        for joint, angle in angles.items():
            q[model.joints[model.getJointId(joint)].idx_q] = angle
        model.referenceConfigurations[KEYFRAME_PREFIX + key] = q
    own = any(int(t) == int(mujoco.mjtJoint.mjJNT_FREE) for t in m.jnt_type)
    return ModelSource(model, path, "mjcf", own_floating_joint=own, armature=built.armature,
                       effort_sources=built.effort_sources, mujoco_model=m)


def load_model_file(d: RobotDescription, where: str) -> ModelSource:
    """The full model of the description's model file (URDF or MJCF, told apart by the root
    element); DescriptionError naming the field and the file for one that is neither."""
    path = resolve_model_path(d.urdf, d.base_dir)
    mjcf = is_mjcf(path)
    try:
        return (_load_mjcf if mjcf else _load_urdf)(path, d, where)
    except ValueError as exc:
        if isinstance(exc, DescriptionError):
            raise
        raise DescriptionError(f"{where}: field '{d.model_key}' = '{d.urdf}': {exc} (only URDF and MJCF "
                               f"files are read)") from None


def model_armature(source: ModelSource, joint_names, armature) -> np.ndarray:
    """Armature of each of ``joint_names``: the model file's (MJCF), replaced by the description's
    ``armature`` (a scalar: every joint; a table: the joints it names)."""
    values = np.array([source.armature.get(j, 0.0) for j in joint_names])
    if isinstance(armature, dict):
        for joint, value in armature.items():
            if joint in joint_names:
                values[list(joint_names).index(joint)] = value
    elif armature is not None:
        values[:] = float(armature)
    return values
