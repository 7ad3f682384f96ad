"""Output directories of the command line (``run``, ``sweep``, ``report``): checked writable
before anything is simulated, cleared of what an earlier command left that would now mislead."""

from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO, Iterable

#: the file in an output directory that the command writing there holds locked
LOCK_NAME = ".wholebody.lock"


class OutputInUse(OSError):
    """Another command is writing into the output directory."""


def claim_output(out_dir: Path) -> IO:
    """Lock ``out_dir`` for this process (an exclusive lock on :data:`LOCK_NAME` in it, which the
    system drops when the process ends however it ends); the open lock file, to keep while
    writing there. :class:`OutputInUse` naming the other process if it is locked: two commands
    on one output directory would interleave their files."""
    out_dir.mkdir(parents=True, exist_ok=True)
    handle = open(out_dir / LOCK_NAME, "a+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        other = handle.read().strip() or "?"
        handle.close()
        raise OutputInUse(0, f"in use by another wholebody command (pid {other})") from None
    handle.seek(0)
    handle.truncate()
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    return handle


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
