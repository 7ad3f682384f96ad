"""Measures of legged locomotion runs, defined once for every quadruped scenario (Fahmi et al. 2019,
Sect. V).

They read the per-cycle arrays of a :class:`~wholebody.scenarios.locomotion.GaitRun` log (``t``,
``stance`` flags of the planner, ``contact_speed`` of the simulator's contact points, ``ok``):

* :func:`outcome` — fall, failed WBC cycles, distance walked;
* :func:`intervals` — (start, end) times of the runs of a flag (swing phases, active slacks, ...);
* :func:`stance_phases` — index ranges of every stance phase of every leg;
* :func:`settled_stance` — stance samples from ``skip`` after touchdown (the impact excluded);
* :func:`slip_events` — stance feet whose contact point keeps sliding (Sect. V-B).
"""

from __future__ import annotations

import numpy as np

IMPACT_SKIP = 0.02  # s after touchdown ignored by the slip measures (the impact)


def outcome(run) -> dict:
    """Whether the run fell (and when: ``fell_at_s``, only if it fell), how many WBC cycles failed
    and the distance walked (simulator base)."""
    out = {"fell": run.fell, "failed_cycles": int(run.failures), "distance_m": run.distance}
    if run.fell_at is not None:
        out["fell_at_s"] = float(run.fell_at)
    return out


def intervals(t: np.ndarray, flags: np.ndarray) -> list[tuple[float, float]]:
    """(start, end) times of the runs of True in ``flags`` (one flag per sample of ``t``)."""
    col = np.concatenate([[False], np.asarray(flags, bool), [False]]).astype(int)
    edges = np.flatnonzero(np.diff(col))
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return [(float(t[a]), float(t[b - 1] + dt)) for a, b in zip(edges[::2], edges[1::2])]


def stance_phases(t: np.ndarray, stance: np.ndarray) -> list[tuple[int, int, int]]:
    """(leg, first index, end index) of every stance phase in a (cycles, legs) stance-flag log."""
    out = []
    for leg in range(stance.shape[1]):
        col = np.concatenate([[False], stance[:, leg].astype(bool), [False]])
        edges = np.flatnonzero(np.diff(col.astype(int)))
        out.extend((leg, int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]))
    return out


def settled_stance(t: np.ndarray, stance: np.ndarray, skip: float = IMPACT_SKIP) -> np.ndarray:
    """(cycles, legs) mask: in stance and at least ``skip`` s after that stance's touchdown."""
    mask = np.zeros_like(stance, dtype=bool)
    for leg, a, b in stance_phases(t, stance):
        mask[a:b, leg] = t[a:b] - t[a] >= skip
    return mask


def slip_events(log: dict, slip_speed: float = 0.02, slip_time: float = 0.02,
                skip: float = IMPACT_SKIP) -> list[dict]:
    """Slip events of a :class:`GaitRun` log: a stance foot whose contact-point speed stays above
    ``slip_speed`` for at least ``slip_time`` without interruption, ignoring the first ``skip`` s
    after touchdown (the foot arrives at swing speed). Each event gives the leg, the touchdown time,
    the start relative to touchdown, the duration and the peak speed."""
    t, speed = log["t"], log["contact_speed"]
    period = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    events = []
    for leg, a, b in stance_phases(t, log["stance"]):
        k0 = a + int(np.searchsorted(t[a:b], t[a] + skip - 1e-9))
        fast = speed[k0:b, leg] > slip_speed
        col = np.concatenate([[False], fast, [False]]).astype(int)
        edges = np.flatnonzero(np.diff(col))
        for s, e in zip(edges[::2], edges[1::2]):
            duration = (e - s) * period
            if duration >= slip_time - 1e-9:
                events.append({"leg": leg, "touchdown_s": float(t[a]),
                               "start_after_touchdown_s": float(t[k0 + s] - t[a]),
                               "duration_s": float(duration),
                               "peak_speed_m_s": float(speed[k0 + s:k0 + e, leg].max())})
    return events
