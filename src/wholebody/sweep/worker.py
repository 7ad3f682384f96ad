"""One run of a sweep, the same function on every executor: :func:`run_one`."""

from __future__ import annotations

import logging
import math
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from .grid import SweepRun

log = logging.getLogger(__name__)


def flatten_metrics(metrics: dict, prefix: str = "") -> dict[str, Any]:
    """Numeric metrics (numbers, booleans, None) of a nested dict, keys joined with ``/``
    (``table3/pd/front/peak_force_N``); text and lists are left out, NaN and +-inf become None."""
    flat: dict[str, Any] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten_metrics(value, f"{name}/"))
        elif value is None:
            flat[name] = None
        elif isinstance(value, (bool, np.bool_)):
            flat[name] = bool(value)
        elif isinstance(value, (int, np.integer)):
            flat[name] = int(value)
        elif isinstance(value, (float, np.floating)):
            flat[name] = float(value) if math.isfinite(value) else None
        elif isinstance(value, np.ndarray) and value.ndim == 0:
            flat.update(flatten_metrics({key: value.item()}, prefix))
    return flat


def _plain(value: Any) -> Any:
    """A parameter value as plain JSON data."""
    if isinstance(value, (np.generic,)):
        return value.item()
    return value


def run_one(run: SweepRun) -> dict[str, Any]:
    """Run ``run`` (robot loaded by name or path; into ``run.out_dir`` if it has one, else no
    output directory) and return its row:
    the run's identity and ``grid`` values, ``parameters`` (all, resolved), ``success``,
    ``metrics`` (:func:`flatten_metrics`), ``wall_time_s`` and ``error`` (the exception's text if
    it raised, else None); with an ``out_dir`` (where the scenario writes its figures) also
    ``summary``, the whole summary for the caller to write (nested metrics, notes, figures; None
    if the run raised or diverged). A simulation that diverges is a completed run that failed, with
    ``metrics["diverged_at_s"]``. Never raises (but for Ctrl-C)."""
    from ..robots import load_robot
    from ..scenarios import get_scenario
    from ..sim.simulator import SimulationDiverged

    start = time.perf_counter()
    row: dict[str, Any] = {"index": run.index, "scenario": run.scenario, "robot": run.robot,
                           "controller": run.controller, "repeat": run.repeat,
                           "grid": dict(run.grid), "parameters": {}, "success": False,
                           "metrics": {}, "error": None}
    if run.out_dir is not None:
        row["summary"] = None
    try:
        scenario = get_scenario(run.scenario)
        robot = load_robot(run.robot)
        row["robot"] = robot.name
        params = scenario.validate(robot, run.overrides)
        row["parameters"] = {k: _plain(v) for k, v in params.items()}
        row["grid"] = {k: _plain(params[k]) for k in run.grid}
        try:
            result = scenario.run(robot, run.controller, run.overrides,
                                  out_dir=None if run.out_dir is None else Path(run.out_dir))
        except SimulationDiverged as exc:
            row["metrics"] = {"diverged_at_s": float(exc.t)}
        else:
            row["success"] = bool(result.success)
            row["metrics"] = flatten_metrics(result.metrics)
            if run.out_dir is not None:
                row["summary"] = result.summary()
    except Exception as exc:  # noqa: BLE001 - a run's error is a result of the sweep
        row["error"] = f"{type(exc).__name__}: {exc}"
        log.debug("sweep run %d (%s) raised:\n%s", run.index, run.label(), traceback.format_exc())
    row["wall_time_s"] = time.perf_counter() - start
    return row
