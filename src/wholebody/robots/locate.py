"""Locate robot model files shipped by the `example-robot-data` distribution.

example-robot-data 6.x ships its URDF/SRDF/meshes under ``cmeel.prefix/share/example-robot-data``
inside the installed distribution and has no Python loader, so the files are found through the
distribution's own file list (``importlib.metadata``), never through a hard-coded site-packages path.
"""

from __future__ import annotations

import functools
import importlib.metadata
from pathlib import Path

ERD_PREFIX = "erd:"
_MARKER = "share/example-robot-data/robots/"


@functools.lru_cache(maxsize=1)
def example_robot_data_dir() -> Path:
    """The ``robots`` directory of the installed example-robot-data distribution."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:  # pragma: no cover - install problem
        raise FileNotFoundError(
            "example-robot-data is not installed; `pip install example-robot-data` (6.x)"
        ) from exc
    for entry in dist.files or ():
        text = str(entry).replace("\\", "/")
        pos = text.find(_MARKER)
        if pos >= 0:
            root = Path(dist.locate_file(text[: pos + len(_MARKER)]))
            if root.is_dir():
                return root
    raise FileNotFoundError("example-robot-data is installed but ships no robots/ directory")


def resolve_model_path(spec: str, base_dir: Path | None = None) -> Path:
    """Resolve a model file reference from a robot description.

    ``erd:talos_data/robots/talos_reduced.urdf`` points into example-robot-data; any other string is a
    path, relative to ``base_dir`` (the folder of the description file) when not absolute.
    """
    if spec.startswith(ERD_PREFIX):
        path = example_robot_data_dir() / spec[len(ERD_PREFIX):]
    else:
        path = Path(spec).expanduser()
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
    if not path.is_file():
        raise FileNotFoundError(f"model file not found: {spec} (resolved to {path})")
    return path
