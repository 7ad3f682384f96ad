"""Matplotlib figures of scenario logs (PNG, headless)."""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

log = logging.getLogger(__name__)


def save_figure(fig, path) -> Path:
    """Lay out ``fig``, save it as a PNG at ``path`` (parents created), close it; the path. A
    figure that cannot be written (a full disk, a folder gone) is logged and left out: the
    path is returned all the same, and a run's summary lists only the figures that exist."""
    fig.tight_layout()
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110)
    except OSError as exc:
        log.warning("could not write the figure %s: %s", path, exc.strerror or exc)
        with contextlib.suppress(OSError):
            path.unlink()  # no half-written file
    finally:
        plt.close(fig)
    return path


def time_series_figure(path: Path, t: np.ndarray,
                       panels: Sequence[tuple[str, str, dict[str, np.ndarray]]],
                       title: str = "", shaded: Sequence[tuple[float, float]] = ()) -> Path:
    """One stacked panel per (title, y label, {label: series}) sharing the time axis; saves a PNG.

    ``shaded`` intervals (t0, t1) are drawn grey on every panel (e.g. pushes, single support).
    """
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(8, 2.2 * len(panels) + 0.6),
                             squeeze=False)
    for ax, (panel_title, ylabel, series) in zip(axes[:, 0], panels):
        for label, values in series.items():
            ax.plot(t, values, label=label, linewidth=1.0)
        for t0, t1 in shaded:
            ax.axvspan(t0, t1, color="0.85", zorder=0)
        ax.set_title(panel_title, fontsize=9)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.grid(True, alpha=0.3)
        if len(series) > 1:
            ax.legend(fontsize=7, ncol=min(len(series), 4), loc="best")
    axes[-1, 0].set_xlabel("time (s)")
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def grouped_bar_figure(path: Path, groups: Sequence[str], series: dict[str, Sequence[float]],
                       title: str = "", ylabel: str = "") -> Path:
    """Grouped bars: one group per entry of ``groups``, one bar per ``series`` (label -> values)."""
    fig, ax = plt.subplots(figsize=(max(5.0, 1.4 * len(groups) + 2.0), 3.4))
    width = 0.8 / max(1, len(series))
    x = np.arange(len(groups))
    for i, (label, values) in enumerate(series.items()):
        bars = ax.bar(x + (i - (len(series) - 1) / 2) * width, values, width, label=label)
        ax.bar_label(bars, fmt="%.0f", fontsize=7)
    ax.set_xticks(x, groups)
    if ylabel:
        ax.set_ylabel(ylabel, fontsize=8)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    return save_figure(fig, path)
