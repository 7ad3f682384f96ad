"""SIGTERM handled like Ctrl-C by the commands that run simulations (``run``, ``sweep``): inside
:func:`sigterm_raises` a SIGTERM raises :class:`Terminated` where the program is, so the command
writes what it has (marked interrupted) and exits :data:`EXIT_TERMINATED`."""

from __future__ import annotations

import contextlib
import signal
import threading

#: a command ended by SIGTERM exits 128 + 15, as a shell reports a process killed by it
EXIT_TERMINATED = 143


class Terminated(Exception):
    """SIGTERM arrived."""


def _raise(signum, frame):
    raise Terminated()


@contextlib.contextmanager
def sigterm_raises():
    """SIGTERM raises :class:`Terminated` inside the block (main thread only: signal handlers
    live there; elsewhere the block runs unchanged); the previous handler is restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
