"""A sweep's table: ``sweep.csv``, ``sweep.json`` (rows in grid order) and the ``sweep.png``
summary figure."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

FILES = ("sweep.csv", "sweep.json", "sweep.png")


def sort_rows(rows: list[dict]) -> list[dict]:
    """Rows in grid order (their ``index``), whatever order they completed in."""
    return sorted(rows, key=lambda r: r["index"])


def metric_names(rows: list[dict]) -> list[str]:
    """Every metric key of the rows, in the order they first appear (grid order)."""
    names: dict[str, None] = {}
    for row in sort_rows(rows):
        names.update(dict.fromkeys(row["metrics"]))
    return list(names)


def columns(rows: list[dict], grid_keys: list[str]) -> list[str]:
    """The CSV columns: the grid parameters, repeat, success, error, the metrics, wall time."""
    return [*grid_keys, "repeat", "success", "error", *metric_names(rows), "wall_time_s"]


def flat_row(row: dict, grid_keys: list[str]) -> dict[str, Any]:
    """One row as ``{column: value}`` (metrics a run lacks are absent)."""
    return {**{k: row["grid"].get(k) for k in grid_keys}, "repeat": row["repeat"],
            "success": row["success"], "error": row["error"], **row["metrics"],
            "wall_time_s": round(row["wall_time_s"], 3)}


def write_csv(path: Path, rows: list[dict], grid_keys: list[str]) -> Path:
    """``path`` with one line per run in grid order; empty cells for missing or None values."""
    names = columns(rows, grid_keys)
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=names, restval="")
        writer.writeheader()
        for row in sort_rows(rows):
            writer.writerow({k: ("" if v is None else v)
                             for k, v in flat_row(row, grid_keys).items()})
    return path


def write_json(path: Path, header: dict[str, Any], rows: list[dict]) -> Path:
    """``path``: ``header`` (scenario, robot, grid, ...) and ``rows`` in grid order."""
    path.write_text(json.dumps({**header, "rows": sort_rows(rows)}, indent=2) + "\n",
                    encoding="utf-8")
    return path


def _number(text: Any) -> float | None:
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def _series(rows: list[dict], grid_keys: list[str], value) -> tuple[list, dict[str, list]]:
    """x values (the first grid key's, in grid order) and, per value of the second key, the mean
    of ``value(row)`` over the rows at each x (None where no row has a value)."""
    first = grid_keys[0] if grid_keys else None
    second = grid_keys[1] if len(grid_keys) > 1 else None
    xs = list(dict.fromkeys(r["grid"][first] if first else "all" for r in rows))
    lines = list(dict.fromkeys(r["grid"][second] for r in rows)) if second else [None]
    out = {}
    for line in lines:
        means = []
        for x in xs:
            values = [value(r) for r in rows
                      if (first is None or r["grid"][first] == x)
                      and (second is None or r["grid"][second] == line)]
            values = [v for v in values if v is not None]
            means.append(float(np.mean(values)) if values else None)
        out[f"{second}={line}" if second else "all runs"] = means
    return xs, out


#: metrics that measure the computer, not the robot: never a sweep's default plot
_TIMING = ("wall_time", "cycle_time", "_us")


def default_metric(rows: list[dict], grid_keys: list[str]) -> str | None:
    """The metric ``sweep.png`` plots when every run has the same success and no ``--metric`` is
    given: the first (in the scenario's order) whose mean changes along the grid by more than
    1e-9 of its size, timing metrics left out; None if none does."""
    for name in metric_names(rows):
        if any(part in name for part in _TIMING):
            continue
        _, lines = _series(rows, grid_keys, lambda r, n=name: _number(r["metrics"].get(n)))
        values = [m for means in lines.values() for m in means if m is not None]
        if len(values) > 1 and max(values) - min(values) > 1e-9 * max(1.0, *map(abs, values)):
            return name
    return None


def write_figure(path: Path, rows: list[dict], grid_keys: list[str], title: str,
                 metric: str | None = None) -> Path:
    """``path``: success rate (and the mean of ``metric`` if given) vs the first grid key, one
    line per value of the second key (means over the other keys and the repeats). When every
    run has the same success and no ``metric`` is given, the panel is :func:`default_metric`'s
    instead (the title says the success), if a metric varies."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = [r for r in sort_rows(rows) if r["error"] is None]
    panels = [("success rate", lambda r: float(r["success"]))]
    if metric is None and rows and len({bool(r["success"]) for r in rows}) == 1:
        chosen = default_metric(rows, grid_keys)  # a flat success line says nothing more
        if chosen is not None:
            rate = "every" if rows[0]["success"] else "no"
            title = f"{title} (success in {rate} run)"
            panels = [(chosen, lambda r: _number(r["metrics"].get(chosen)))]
    if metric is not None:
        panels.append((metric, lambda r: _number(r["metrics"].get(metric))))
    fig = Figure(figsize=(6.4 * len(panels), 4.2), layout="constrained")
    FigureCanvasAgg(fig)
    for k, (label, value) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1)
        if not rows:
            ax.text(0.5, 0.5, "no completed run", ha="center", va="center",
                    transform=ax.transAxes)
            continue
        xs, lines = _series(rows, grid_keys, value)
        numeric = all(_number(x) is not None for x in xs)
        positions = [float(x) for x in xs] if numeric else list(range(len(xs)))
        for j, (name, means) in enumerate(lines.items()):  # markers tell overlapping lines
            ax.plot(positions, [np.nan if m is None else m for m in means], label=name,
                    marker="osD^v<>"[j % 7], linestyle=("-", "--", ":", "-.")[j % 4],
                    markersize=7 - 0.5 * (j % 5), alpha=0.85)
        if not numeric:
            ax.set_xticks(positions, [str(x) for x in xs])
        ax.set_xlabel(grid_keys[0] if grid_keys else "")
        ax.set_ylabel(label)
        if label == "success rate":
            ax.set_ylim(-0.05, 1.05)
        if len(lines) > 1:
            ax.legend(fontsize="small")
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize="medium")
    fig.savefig(path, dpi=120)
    return path
