"""Periodic contact schedules for quadruped gaits: crawl, trot, stand.

Fahmi et al. 2019 evaluate their passive whole-body controller on HyQ with two gaits
(Sect. V): a *crawl* -- one leg at a time, statically stable, used for the friction, torque-limit and
speed-ramp experiments (Sects. V-B, V-C, V-E, Figs. 3, 5) -- and a *trot* -- diagonal pairs, "an
under-actuated gait" (Sect. V-H, Fig. 8). The controller's equality constraints (eqs. 10-12) need to
know, every cycle, which feet are in stance and which are swinging; this module answers that.

Conventions
-----------
Each leg ``i`` has a phase offset ``offset_i`` in [0, 1) and a duty factor ``duty_i`` (fraction of the
cycle spent in stance). The gait starts at ``start``; before that every leg is in stance. Leg ``i``
lifts off at ``start + (k + offset_i) * period`` for ``k = 0, 1, ...``, swings for
``(1 - duty_i) * period`` and is in stance for the rest of the cycle, i.e. its gait phase (0 at
lift-off) is ``phi = frac((t - start) / period - offset_i)`` and it swings iff ``phi < 1 - duty_i``.
Event instants belong to the new phase: at its lift-off time a leg is swinging, at its touchdown
time it is in stance (a tolerance of 1e-9 cycle absorbs rounding).

A schedule may let its period change from one gait cycle to the next (``period_at``, e.g.
:func:`stride_capped`): ``(t - start) / period`` above is then the number of cycles elapsed, the
integral of 1 / period, so the phase stays continuous where the period changes.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field, replace
from typing import Callable, NamedTuple, Sequence

import numpy as np

#: the default legs of the schedules: a quadruped's foot roles (:mod:`wholebody.robots.roles`),
#: LF, RF, LH, RH; :meth:`GaitPlanner.for_robot <wholebody.planning.planner.GaitPlanner.for_robot>`
#: addresses them to the robot's own contacts
LEGS = ("left-front", "right-front", "left-hind", "right-hind")

_EPS = 1e-9  # in cycles: event instants belong to the phase that starts there


class GaitEvent(NamedTuple):
    """A lift-off or touchdown of one leg."""

    time: float
    leg: str
    kind: str  # "liftoff" or "touchdown"
    index: int  # which swing of that leg (0 = the first after ``start``)


class Swing(NamedTuple):
    """One swing interval [liftoff, touchdown) of one leg."""

    liftoff: float
    touchdown: float
    leg: str
    index: int

    @property
    def mid(self) -> float:
        return 0.5 * (self.liftoff + self.touchdown)


@dataclass(frozen=True)
class GaitSchedule:
    """A periodic contact schedule: cycle ``period`` [s], per-leg phase ``offsets`` (lift-off phase,
    in cycles) and ``duty`` factors (stance fraction, in (0, 1]; a scalar applies to every leg),
    optional ``start`` time before which all legs are in stance. ``period_at(t)``, if given, is the
    period of the cycle that begins at time ``t`` (cycle boundaries: phase 0 of the cycle count);
    before ``start`` and without it the period is ``period``.

    Legs are addressed by name (``"left-front"``, or a robot's contact name) or index into ``legs``.
    """

    period: float
    offsets: Sequence[float]
    duty: float | Sequence[float]
    legs: Sequence[str] = LEGS
    start: float = 0.0
    name: str = "gait"
    period_at: Callable[[float], float] | None = None
    # (t_j, c_j, T_j): from time t_j (cycle c_j, an integer) on, the period is T_j; grown lazily
    _segments: list = field(init=False, repr=False, compare=False, default=None)
    _horizon: list = field(init=False, repr=False, compare=False, default=None)
    # [t, cycles(t)] of the last call: a planner's cycle asks for the same t once per question
    _last_cycles: list = field(init=False, repr=False, compare=False, default=None)

    def __post_init__(self):
        n = len(self.legs)
        if not (np.isfinite(self.period) and self.period > 0):
            raise ValueError(f"period: must be a positive finite time, got {self.period}")
        offsets = np.asarray(self.offsets, dtype=float).reshape(-1)
        if offsets.shape[0] != n or not np.all(np.isfinite(offsets)):
            raise ValueError(f"offsets: expected {n} finite phases, got {self.offsets}")
        duty = np.broadcast_to(np.asarray(self.duty, dtype=float), (n,)).copy()
        if np.any(~np.isfinite(duty)) or np.any(duty <= 0.0) or np.any(duty > 1.0):
            raise ValueError(f"duty: each duty factor must lie in (0, 1], got {self.duty}")
        if len(set(self.legs)) != n:
            raise ValueError(f"legs: names must be unique, got {self.legs}")
        if not np.isfinite(self.start):
            raise ValueError(f"start: must be finite, got {self.start}")
        object.__setattr__(self, "offsets", tuple(float(o) for o in np.mod(offsets, 1.0)))
        object.__setattr__(self, "duty", tuple(float(d) for d in duty))
        object.__setattr__(self, "legs", tuple(self.legs))
        object.__setattr__(self, "period", float(self.period))
        object.__setattr__(self, "start", float(self.start))
        if self.period_at is not None and not callable(self.period_at):
            raise ValueError(f"period_at: expected a function of time or None, "
                             f"got {self.period_at!r}")
        object.__setattr__(self, "_segments", [(self.start, 0, self.period)])
        object.__setattr__(self, "_horizon", [self.start, 0])  # the next boundary to decide
        object.__setattr__(self, "_last_cycles", [math.nan, math.nan])

    # ------------------------------------------------------------------ the cycle clock
    def _grow(self, t: float = -math.inf, c: float = -math.inf) -> None:
        """Decide the periods of the cycles beginning up to time ``t`` and cycle ``c``."""
        if self.period_at is None:
            return
        seg, hz = self._segments, self._horizon
        while (hz[0] <= t < math.inf) or (hz[1] <= c < math.inf):
            t_k, k = hz
            T = float(self.period_at(t_k))
            if not (math.isfinite(T) and T > 0.0):
                T = seg[-1][2]  # a law without an answer: keep the period
            if T != seg[-1][2]:
                seg.append((t_k, k, T))
            t_j, c_j, T_j = seg[-1]
            hz[0], hz[1] = t_j + (k + 1 - c_j) * T_j, k + 1

    def _segment_at_time(self, t: float) -> tuple[float, int, float]:
        self._grow(t=t)
        seg = self._segments
        return seg[max(0, bisect.bisect_right(seg, (t, math.inf, math.inf)) - 1)]

    def cycles(self, t: float) -> float:
        """Gait cycles elapsed since ``start`` at time ``t`` (negative before it). The last
        answer is kept: the segment holding a time, once decided, never changes."""
        last = self._last_cycles
        if t == last[0]:
            return last[1]
        t_j, c_j, T_j = self._segment_at_time(t)
        last[0], last[1] = t, c_j + (t - t_j) / T_j
        return last[1]

    def cycle_time(self, c: float) -> float:
        """The time at which ``c`` cycles have elapsed since ``start`` (the inverse of
        :meth:`cycles`)."""
        self._grow(c=c)
        seg = self._segments
        j = max(0, bisect.bisect_right([s[1] for s in seg], c) - 1)
        t_j, c_j, T_j = seg[j]
        return t_j + (c - c_j) * T_j

    def period_of(self, t: float) -> float:
        """The period of the gait cycle in progress at ``t``."""
        return self._segment_at_time(t)[2]

    # ------------------------------------------------------------------ basics
    @property
    def n_legs(self) -> int:
        return len(self.legs)

    def index(self, leg: str | int) -> int:
        """Index of ``leg`` (a name in ``legs`` or an integer index)."""
        if isinstance(leg, (int, np.integer)):
            i = int(leg)
            if not 0 <= i < len(self.legs):
                raise ValueError(f"leg: index {leg} out of range for {self.n_legs} legs")
            return i
        try:
            return self.legs.index(leg)
        except ValueError:
            raise ValueError(f"leg: unknown leg '{leg}'; have {list(self.legs)}") from None

    def swing_duration(self, leg: str | int) -> float:
        """(1 - duty) * period: how long one swing of ``leg`` lasts."""
        return (1.0 - self.duty[self.index(leg)]) * self.period

    def stance_duration(self, leg: str | int, t: float | None = None) -> float:
        """duty * period: how long ``leg`` stays in stance between two swings (T_stance). With
        ``t`` and a changing period: the stance in progress at ``t``, or the one after the swing
        in progress."""
        i = self.index(leg)
        if t is None or self.period_at is None or self.duty[i] >= 1.0:
            return self.duty[i] * self.period
        k = self.swing_index(i, t)
        if self.in_swing(i, t):
            k += 1
        touchdown, liftoff = self.touchdown_time(i, k - 1), self.liftoff_time(i, k)
        segment = self._segment_at_time(touchdown)
        if segment is self._segment_at_time(liftoff):  # one period throughout
            return self.duty[i] * segment[2]
        return liftoff - touchdown

    def _cycle(self, i: int, t: float) -> tuple[int, float]:
        x = self.cycles(t) - self.offsets[i] + _EPS
        k = math.floor(x)
        return k, x - k

    # ------------------------------------------------------------------ state at time t
    def phase(self, leg: str | int, t: float) -> float:
        """Gait phase of ``leg`` in [0, 1): 0 at lift-off, 1 - duty at touchdown (periodic, also
        defined before ``start`` although every leg is then held in stance)."""
        return min(self._cycle(self.index(leg), t)[1], np.nextafter(1.0, 0.0))

    def in_swing(self, leg: str | int, t: float) -> bool:
        i = self.index(leg)
        k, phi = self._cycle(i, t)
        return k >= 0 and phi < 1.0 - self.duty[i]

    def in_stance(self, leg: str | int, t: float) -> bool:
        """True if ``leg`` is (scheduled to be) on the ground at time ``t``."""
        return not self.in_swing(leg, t)

    def stance_legs(self, t: float) -> tuple[str, ...]:
        return tuple(leg for i, leg in enumerate(self.legs) if not self.in_swing(i, t))

    def swing_legs(self, t: float) -> tuple[str, ...]:
        return tuple(leg for i, leg in enumerate(self.legs) if self.in_swing(i, t))

    def swing_phase(self, leg: str | int, t: float) -> float:
        """Progress of the current swing in [0, 1) (0 at lift-off); NaN while in stance."""
        i = self.index(leg)
        k, phi = self._cycle(i, t)
        if k < 0 or phi >= 1.0 - self.duty[i]:
            return float("nan")
        return min(max(phi - _EPS, 0.0) / (1.0 - self.duty[i]), np.nextafter(1.0, 0.0))

    def stance_phase(self, leg: str | int, t: float) -> float:
        """Progress of the current stance in [0, 1) (0 at touchdown); NaN while swinging and before
        the first swing (the initial stance has no touchdown)."""
        i = self.index(leg)
        k, phi = self._cycle(i, t)
        sw = 1.0 - self.duty[i]
        if k < 0 or phi < sw:
            return float("nan")
        return min((phi - sw) / self.duty[i], np.nextafter(1.0, 0.0))

    # ------------------------------------------------------------------ events
    def liftoff_time(self, leg: str | int, k: int) -> float:
        """Lift-off time of swing number ``k`` (k = 0 is the first swing after ``start``)."""
        return self._liftoff(self.index(leg), k)

    def _liftoff(self, i: int, k: int) -> float:
        if self.period_at is None:
            return self.start + (k + self.offsets[i]) * self.period
        return self.cycle_time(k + self.offsets[i])

    def touchdown_time(self, leg: str | int, k: int) -> float:
        """Touchdown time ending swing number ``k``."""
        return self._touchdown(self.index(leg), k)

    def _touchdown(self, i: int, k: int) -> float:
        if self.period_at is None:
            return self.start + (k + self.offsets[i] + 1.0 - self.duty[i]) * self.period
        return self.cycle_time(k + self.offsets[i] + 1.0 - self.duty[i])

    def swing_index(self, leg: str | int, t: float) -> int | None:
        """Index of the current swing of ``leg`` if it swings at ``t``, else of its next swing;
        None if the leg never swings (duty = 1)."""
        i = self.index(leg)
        if self.duty[i] >= 1.0:
            return None
        k, phi = self._cycle(i, t)
        if k < 0:
            return 0
        return k if phi < 1.0 - self.duty[i] else k + 1

    def current_swing(self, leg: str | int, t: float) -> Swing | None:
        """(liftoff, touchdown, leg, index) of the swing in progress at ``t``, or None in stance."""
        i = self.index(leg)
        if not self.in_swing(i, t):
            return None
        k = self.swing_index(i, t)
        return Swing(self.liftoff_time(i, k), self.touchdown_time(i, k), self.legs[i], k)

    def next_liftoff(self, leg: str | int, t: float) -> float:
        """First lift-off strictly after ``t`` (inf if the leg never swings)."""
        i = self.index(leg)
        k = self.swing_index(i, t)
        if k is None:
            return math.inf
        return self.liftoff_time(i, k + 1 if self.in_swing(i, t) else k)

    def next_touchdown(self, leg: str | int, t: float) -> float:
        """First touchdown strictly after ``t``: the end of the current swing, or of the next one
        if ``leg`` is in stance (inf if the leg never swings)."""
        i = self.index(leg)
        k = self.swing_index(i, t)
        return math.inf if k is None else self.touchdown_time(i, k)

    def last_touchdown(self, leg: str | int, t: float) -> float | None:
        """Most recent touchdown at or before ``t``; None if the leg has not landed since ``start``."""
        i = self.index(leg)
        k = self.swing_index(i, t)
        if k is None:
            return None
        # k is the current swing (swinging) or the next one (stance): either way k - 1 landed last
        return None if k < 1 else self.touchdown_time(i, k - 1)

    def swings(self, t0: float, t1: float, legs: Sequence[str | int] | None = None) -> list[Swing]:
        """Every swing interval overlapping [t0, t1), sorted by lift-off time then leg order."""
        idx = range(self.n_legs) if legs is None else [self.index(leg) for leg in legs]
        found: list[tuple[float, int, Swing]] = []  # (lift-off, leg index, swing): the sort key
        for i in idx:
            if self.duty[i] >= 1.0:
                continue
            sw = 1.0 - self.duty[i]
            k = max(0, math.floor(self.cycles(t0) - self.offsets[i] - sw))
            while True:
                lo = self._liftoff(i, k)
                if lo >= t1:
                    break
                td = lo + sw * self.period if self.period_at is None else self._touchdown(i, k)
                if td > t0:
                    found.append((lo, i, Swing(lo, td, self.legs[i], k)))
                k += 1
        found.sort(key=lambda entry: entry[:2])
        return [swing for _, _, swing in found]

    def events(self, t0: float, t1: float) -> list[GaitEvent]:
        """Lift-offs and touchdowns with time in [t0, t1), sorted by time (touchdowns first at equal
        times, then leg order)."""
        out: list[GaitEvent] = []
        back = (t0 - self.period if self.period_at is None
                else self.cycle_time(self.cycles(t0) - 1.0))
        for s in self.swings(back, t1):
            if t0 <= s.liftoff < t1:
                out.append(GaitEvent(s.liftoff, s.leg, "liftoff", s.index))
            if t0 <= s.touchdown < t1:
                out.append(GaitEvent(s.touchdown, s.leg, "touchdown", s.index))
        order = {"touchdown": 0, "liftoff": 1}
        out.sort(key=lambda e: (e.time, order[e.kind], self.legs.index(e.leg)))
        return out

    def max_swing_legs(self) -> int:
        """Largest number of legs swinging together in the steady gait (1 for a crawl, 2 for a
        trot, 0 for standing)."""
        if all(d >= 1.0 for d in self.duty):
            return 0
        t0 = self.start + self.period  # every leg has started
        times = sorted({e.time for e in self.events(t0, t0 + self.period)} | {t0, t0 + self.period})
        probes = [0.5 * (a + b) for a, b in zip(times[:-1], times[1:]) if b > a]
        return max(len(self.swing_legs(t)) for t in probes)


# ---------------------------------------------------------------------- factories
#: the default gait periods (s), set for HyQ (see :func:`crawl`, :func:`trot`)
CRAWL_PERIOD, TROT_PERIOD = 2.5, 0.8


def crawl(period: float = CRAWL_PERIOD, duty: float = 0.85, start: float = 0.0,
          legs: Sequence[str] = LEGS) -> GaitSchedule:
    """Crawl: one leg at a time in the classic LH -> LF -> RH -> RF sequence (phase offsets 0, 1/4,
    1/2, 3/4), as HyQ crawls in Fahmi et al. 2019 (Sect. V-B, V-C, V-E).

    ``legs`` are given in the order (LF, RF, LH, RH). ``duty`` must lie in [0.75, 1) so that at most
    one leg swings. Defaults (our engineering choice; the paper does not state its gait timings):

    * ``duty = 0.85``: after every swing, a four-leg support window of (duty - 0.75) * period =
      0.25 s. With duty = 0.75 exactly there is none, and at the LF -> RH and RF -> LH hand-overs the
      two support triangles share only their diagonal: the CoM would have zero static margin there.
      The window is where the crawl sway (:class:`~wholebody.planning.trunk.CrawlSway`) crosses it.
    * ``period = 2.5 s``: 0.375 s swings. With the default sway this keeps the CoM reference inside
      the support triangle of every swing by >= 2 cm (a unit test checks it) and its cart-table ZMP
      inside it too, on flat ground for speeds 0 - 0.15 m/s (Fahmi's crawl speeds, Sect. V-B/V-E)
      in steady state or ramped up from rest over two cycles; a 2.0 s period at duty 0.8 pushes the
      ZMP out of the triangle.
      At 0.15 m/s the stride is 0.375 m (touchdown 0.16 m ahead of the hip), within HyQ's reach.
    """
    if duty < 0.75 or duty >= 1.0:
        raise ValueError(f"duty: a crawl needs 0.75 <= duty < 1 (one leg at a time), got {duty}")
    if len(legs) != 4:
        raise ValueError(f"legs: a crawl needs 4 legs (LF, RF, LH, RH), got {legs}")
    # LF, RF, LH, RH lift off at 1/4, 3/4, 0, 1/2 of the cycle: LH -> LF -> RH -> RF.
    return GaitSchedule(period, (0.25, 0.75, 0.0, 0.5), duty, legs, start, "crawl")


def trot(period: float = TROT_PERIOD, duty: float = 0.5, start: float = 0.0,
         legs: Sequence[str] = LEGS) -> GaitSchedule:
    """Trot: diagonal pairs (LF with RH, RF with LH) swing together, half a cycle apart (Fahmi et
    al. 2019, Sect. V-H: "the robot uses only two legs at the time").

    ``legs`` are given in the order (LF, RF, LH, RH). Default duty 0.5 (always exactly one diagonal
    pair on the ground; duty > 0.5 adds four-leg support at the hand-overs, < 0.5 flight phases).
    The default 0.8 s period gives 0.4 s swings, near half the pendulum period of HyQ's ~0.55 m
    CoM height (2 pi sqrt(0.55 / 9.81) / 2 = 0.74 s) -- our engineering choice, not a value from
    the paper.
    """
    if len(legs) != 4:
        raise ValueError(f"legs: a trot needs 4 legs (LF, RF, LH, RH), got {legs}")
    return GaitSchedule(period, (0.0, 0.5, 0.5, 0.0), duty, legs, start, "trot")


def stand(legs: Sequence[str] = LEGS, period: float = 1.0) -> GaitSchedule:
    """All legs in stance forever (duty 1)."""
    return GaitSchedule(period, (0.0,) * len(legs), 1.0, legs, 0.0, "stand")


def stride_capped(schedule: GaitSchedule, speed: Callable[[float], float], max_stride: float,
                  min_period: float = 0.0) -> GaitSchedule:
    """``schedule`` with a period that shortens with the commanded ``speed(t)`` [m/s] so that a
    stance foot travels at most ``max_stride`` [m] relative to its hip (the Raibert footholds put
    it v T_stance / 2 ahead of the hip at touchdown and as far behind at lift-off): each cycle's
    period is ``min(period, max_stride / (duty v))``, no shorter than ``min_period``, ``v`` the
    larger commanded speed at the cycle's two ends. Below ``max_stride / (duty period)`` the
    period is ``period`` exactly; above it the stride ``v T`` stays ``max_stride / duty``.
    """
    if not (math.isfinite(max_stride) and max_stride > 0.0):
        raise ValueError(f"max_stride: must be a positive length, got {max_stride}")
    base, duty = schedule.period, max(schedule.duty)

    def capped(v: float) -> float:
        if duty * v * base <= max_stride:
            return base
        return max(max_stride / (duty * v), min_period)

    def period_at(t: float) -> float:
        v = abs(float(speed(t)))
        return capped(max(v, abs(float(speed(t + capped(v))))))

    return replace(schedule, period_at=period_at)
