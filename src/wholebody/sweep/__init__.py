"""Sweeps: many independent closed-loop runs of one scenario over a parameter grid.

:mod:`.grid` expands ``--grid``/``--set``/``--repeat`` into runs and validates them,
:mod:`.worker` runs one (the same function on every executor), :mod:`.executors` maps it serially,
on a local process pool or on Ray, :mod:`.table` writes the table and its figure,
:mod:`.command` is ``wholebody sweep``.
"""

from .executors import (Executor, LocalPoolExecutor, RayExecutor, SerialExecutor, make_executor,
                        ordered)
from .grid import SweepRun, expand, parse_grid
from .worker import run_one

__all__ = ["Executor", "LocalPoolExecutor", "RayExecutor", "SerialExecutor", "SweepRun",
           "expand", "make_executor", "ordered", "parse_grid", "run_one"]
