"""Output directories of the command line (``run``, ``sweep``, ``report``): checked writable
before anything is simulated, cleared of what an earlier command left that would now mislead."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Iterable


def prepare_output(out_dir: Path, stale: Iterable[str] = ()) -> None:
    """Make ``out_dir``, check that a file can be written in it and remove the files ``stale``
    (names inside it) an earlier command left, so that a command cut short leaves none of its
    predecessor's; OSError otherwise (NotADirectoryError when ``out_dir`` is a file)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise NotADirectoryError(0, "not a directory")
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=out_dir, prefix=".wholebody-write-test-"):
        pass
    for name in stale:
        path = out_dir / name
        if path.exists() or path.is_symlink():
            path.unlink()
