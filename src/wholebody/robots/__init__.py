"""Robot presets and the loader: a preset name or a path to a robot description file."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from .description import ContactSpec, DescriptionError, RobotDescription

__all__ = ["ContactSpec", "DescriptionError", "RobotDescription", "load_robot", "preset_names",
           "preset_description"]


class UnknownRobotError(ValueError):
    """The name is neither a preset nor an existing description file."""


def preset_names() -> list[str]:
    """Names of the shipped presets (``talos14``, ``talos``, ``hyq``...)."""
    folder = resources.files(__package__) / "presets"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def preset_description(name: str) -> RobotDescription:
    folder = resources.files(__package__) / "presets"
    path = folder / f"{name}.toml"
    if not path.is_file():
        raise UnknownRobotError(f"unknown robot '{name}'; presets: {', '.join(preset_names())}")
    with resources.as_file(path) as real:
        return RobotDescription.from_toml(real)


def load_robot(name_or_path: str | Path | Mapping[str, Any] | RobotDescription):
    """Build a :class:`wholebody.Robot` from a preset name, a TOML file path, a dict or a description."""
    from ..robot import Robot

    if isinstance(name_or_path, RobotDescription):
        return Robot(name_or_path)
    if isinstance(name_or_path, Mapping):
        return Robot(RobotDescription.from_dict(name_or_path))
    text = str(name_or_path)
    if text in preset_names():
        return Robot(preset_description(text))
    path = Path(text).expanduser()
    if is_model_file(path):
        return Robot(drafted_description(path))
    if path.suffix == ".toml" or path.exists():
        if path.is_dir():
            raise UnknownRobotError(f"robot file: {path} is a folder, not a .toml file")
        if path.exists() and not path.is_file():
            raise UnknownRobotError(f"robot file: {path} is not a regular file (a device?)")
        if not path.exists():
            raise UnknownRobotError(f"robot file not found: {path}")
        return Robot(RobotDescription.from_toml(path))
    raise UnknownRobotError(
        f"unknown robot '{text}'; presets: {', '.join(preset_names())} (or a path to a .toml "
        f"description, or to a .urdf or MJCF .xml model file)")


#: suffixes of model files that ``load_robot`` drafts a description for
MODEL_SUFFIXES = (".urdf", ".xml", ".mjcf")


def is_model_file(path: str | Path) -> bool:
    """True for an existing file with a model file's suffix (URDF or MJCF, not a description)."""
    path = Path(path).expanduser()
    return path.suffix.lower() in MODEL_SUFFIXES and path.is_file()


def drafted_description(path: str | Path) -> RobotDescription:
    """The description :func:`wholebody.robots.draft.draft_description` drafts for the model
    file at ``path`` (what ``wholebody init-robot`` writes), logged as a draft; DescriptionError
    when the draft cannot be used as it is (a joint without an effort limit)."""
    import logging

    from .draft import draft_description

    draft = draft_description(path)
    missing = draft.data.get("torque_limits", {}).get("overrides", {})
    if missing:
        raise DescriptionError(
            f"robot file {path}: the model file gives no effort limit for joint(s) "
            f"{sorted(missing)}: write a description with `wholebody init-robot {path} --out "
            f"FILE.toml` and fill its torque_limits.overrides")
    logging.getLogger(__name__).info("robot file %s: a model file, used through a drafted "
                                     "description (%s)", path, "; ".join(draft.notes))
    return RobotDescription.from_dict(draft.data, base_dir=Path(path).expanduser().parent)
