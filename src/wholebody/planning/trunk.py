"""Trunk reference: desired CoM position/velocity/acceleration and trunk orientation/angular
velocity/acceleration from a velocity command.

The trunk task of Fahmi et al. 2019 (eq. 4) is a Cartesian impedance at the CoM with a
feed-forward term: it needs ``x_com,d`` (CoM position and trunk orientation), ``v_com,d`` (CoM
velocity and trunk angular velocity) and ``v̇_com,d`` (for ``W_ff = M_com v̇_com,d``). This module
turns a high-level velocity command (Fig. 1: "Given high-level user velocity commands, the planner
generates a reference motion online") into those signals:

* horizontal CoM: the integral of the command (forward/lateral speed in the heading frame, yaw
  rate), in closed form, including a linear speed ramp such as the 0.04 -> 0.15 m/s ramp of Fig. 5;
  a :class:`CommandSchedule` (walk, turn, side-step, stop) ramps the yaw rate too, and the
  pieces where it does are integrated by quadrature;
* CoM height: held at a constant height above the terrain under the CoM;
* orientation: heading = integrated yaw, and, on inclined terrain, roll/pitch aligned with the
  terrain normal under the CoM (the ramps of Figs. 4, 7, 8);
* for a crawl, which is quasi-static, an optional sway (:class:`CrawlSway`) that moves the CoM
  toward the support triangle of the next swing;
* for a gait that starts on two feet (a trot), an optional :class:`StartShift` that puts the CoM
  on the line of the first two stance feet and brings it back to the nominal path.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .gait import GaitSchedule
from .swing import _blend_scalar
from .terrain import Terrain

_SERIES_N = np.arange(25)
_FACT = np.array([math.factorial(n) for n in range(27)], dtype=float)
_C0 = 1.0 / _FACT[1:26]                       # 1/(n+1)!
_C1 = 1.0 / (_FACT[:25] * (_SERIES_N + 2.0))  # 1/(n! (n+2))


def _heading_integral(psi: float, omega: float, a: complex, b: complex, length: float) -> complex:
    """Closed form of  int_0^L exp(i (psi + omega s)) (a + b s) ds  (complex plane = x-y plane):
    the displacement over L seconds of a body heading psi + omega s whose heading-frame velocity is
    a + b s. A power series for |omega L| < 0.5 avoids the cancellation of the closed form."""
    x = omega * length
    if abs(x) < 0.5:
        powers = (1j * x) ** _SERIES_N
        e0 = length * complex(np.dot(_C0, powers))
        e1 = length * length * complex(np.dot(_C1, powers))
    else:
        ex = complex(math.cos(x), math.sin(x))
        e0 = (ex - 1.0) / (1j * omega)
        e1 = (length * ex - e0) / (1j * omega)
    return complex(math.cos(psi), math.sin(psi)) * (a * e0 + b * e1)


@dataclass(frozen=True)
class VelocityCommand:
    """A velocity command: horizontal velocity (forward, lateral) in the heading frame [m/s] going
    linearly from ``v_start`` to ``v_end`` over the time interval ``ramp`` = (t_a, t_b) (constant
    outside it), and a constant ``yaw_rate`` [rad/s]."""

    v_start: Sequence[float] = (0.0, 0.0)
    v_end: Sequence[float] | None = None
    ramp: Sequence[float] = (0.0, 0.0)
    yaw_rate: float = 0.0

    def __post_init__(self):
        v0 = np.asarray(self.v_start, dtype=float).reshape(2)
        v1 = v0 if self.v_end is None else np.asarray(self.v_end, dtype=float).reshape(2)
        ta, tb = (float(x) for x in self.ramp)
        if not (np.all(np.isfinite(v0)) and np.all(np.isfinite(v1)) and np.isfinite(ta)
                and np.isfinite(tb) and np.isfinite(self.yaw_rate)):
            raise ValueError("VelocityCommand: every field must be finite")
        if tb < ta:
            raise ValueError(f"ramp: expected (t_start, t_end) with t_end >= t_start, got {self.ramp}")
        object.__setattr__(self, "v_start", (float(v0[0]), float(v0[1])))
        object.__setattr__(self, "v_end", (float(v1[0]), float(v1[1])))
        object.__setattr__(self, "ramp", (ta, tb))
        object.__setattr__(self, "yaw_rate", float(self.yaw_rate))

    @classmethod
    def constant(cls, forward: float = 0.0, lateral: float = 0.0, yaw_rate: float = 0.0
                 ) -> "VelocityCommand":
        return cls((forward, lateral), None, (0.0, 0.0), yaw_rate)

    @classmethod
    def speed_ramp(cls, v0: float = 0.04, v1: float = 0.15, t_start: float = 0.0,
                   t_end: float = 20.0) -> "VelocityCommand":
        """Forward speed increasing linearly from ``v0`` to ``v1`` between ``t_start`` and
        ``t_end`` (Fahmi et al. 2019, Sect. V-E / Fig. 5: "we increase linearly the forward speed
        from 0.04 m/s to 0.15 m/s"; the ramp duration is not stated there, 20 s is our default)."""
        return cls((v0, 0.0), (v1, 0.0), (t_start, t_end), 0.0)

    def velocity(self, t: float) -> np.ndarray:
        """Heading-frame (forward, lateral) velocity at ``t``."""
        ta, tb = self.ramp
        if tb == ta:
            u = 0.0 if t < ta else 1.0
        else:
            u = min(max((t - ta) / (tb - ta), 0.0), 1.0)
        return np.array([self.v_start[0] + u * (self.v_end[0] - self.v_start[0]),
                         self.v_start[1] + u * (self.v_end[1] - self.v_start[1])])

    def acceleration(self, t: float) -> np.ndarray:
        """Heading-frame derivative of :meth:`velocity` (piecewise constant; 0 at the ramp ends)."""
        ta, tb = self.ramp
        if tb > ta and ta < t < tb:
            return np.array([(self.v_end[0] - self.v_start[0]) / (tb - ta),
                             (self.v_end[1] - self.v_start[1]) / (tb - ta)])
        return np.zeros(2)

    def yaw_rate_at(self, t: float) -> float:
        """The yaw rate at ``t``: the constant ``yaw_rate``."""
        return self.yaw_rate

    def yaw_acceleration_at(self, t: float) -> float:
        return 0.0

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """The times where the command's linear pieces meet (the ramp's ends)."""
        return tuple(sorted(set(self.ramp)))


@dataclass(frozen=True)
class CommandPhase:
    """One part of a :class:`CommandSchedule`: ``duration`` s (the ramp into it included) of the
    heading-frame command (``forward``, ``lateral`` [m/s], ``yaw_rate`` [rad/s])."""

    name: str
    duration: float
    forward: float = 0.0
    lateral: float = 0.0
    yaw_rate: float = 0.0

    def __post_init__(self):
        values = (self.duration, self.forward, self.lateral, self.yaw_rate)
        if not all(math.isfinite(float(x)) for x in values):
            raise ValueError(f"phase '{self.name}': every field must be finite, got {values}")
        if self.duration <= 0.0:
            raise ValueError(f"phase '{self.name}': duration must be > 0, got {self.duration}")


class CommandSchedule:
    """A velocity command that changes over time: heading-frame forward and lateral speed and yaw
    rate, linear between keyframes ``times[k]`` -> ``commands[k]`` = (forward, lateral, yaw_rate),
    constant before the first keyframe and after the last. Unlike :class:`VelocityCommand` the
    yaw rate varies too (a joystick's twist: walk, turn, side-step, stop), so the heading it
    integrates to is piecewise quadratic in time.

    :meth:`from_phases` builds one from named :class:`CommandPhase` s, each ramped into linearly;
    ``phases`` then lists (name, start, end) of each.
    """

    def __init__(self, times, commands, phases=()):
        t = np.array(times, dtype=float).reshape(-1)
        c = np.array(commands, dtype=float).reshape(len(t), 3)
        if len(t) < 1 or not (np.all(np.isfinite(t)) and np.all(np.isfinite(c))):
            raise ValueError("CommandSchedule: expected >= 1 keyframe of finite times and commands")
        if np.any(np.diff(t) < 0.0):
            raise ValueError(f"times: must not decrease, got {t.tolist()}")
        t.setflags(write=False)
        c.setflags(write=False)
        self.times, self.commands = t, c
        self.phases = tuple((str(n), float(a), float(b)) for n, a, b in phases)

    @classmethod
    def from_phases(cls, phases, start: float = 0.0, ramp: float = 0.5) -> "CommandSchedule":
        """Zero command until ``start``, then each phase in turn: the command goes linearly from
        the previous phase's to this one's over the phase's first ``min(ramp, duration)`` s and
        holds for the rest of it; the last phase's command holds after its end."""
        if not (math.isfinite(ramp) and ramp >= 0.0):
            raise ValueError(f"ramp: expected a finite time >= 0, got {ramp}")
        times, commands, spans = [float(start)], [(0.0, 0.0, 0.0)], []
        t = float(start)
        for p in phases:
            cmd = (float(p.forward), float(p.lateral), float(p.yaw_rate))
            times.append(t + min(ramp, p.duration))
            commands.append(cmd)
            spans.append((p.name, t, t + p.duration))
            t += p.duration
            times.append(t)
            commands.append(cmd)
        return cls(times, commands, spans)

    @property
    def end(self) -> float:
        return float(self.times[-1])

    @property
    def breakpoints(self) -> tuple[float, ...]:
        return tuple(sorted(set(self.times.tolist())))

    def command(self, t: float) -> np.ndarray:
        """(forward, lateral, yaw_rate) at ``t``."""
        ts, cs = self.times, self.commands
        if t <= ts[0]:
            return cs[0].copy()
        if t >= ts[-1]:
            return cs[-1].copy()
        k = int(np.searchsorted(ts, t, side="right")) - 1
        w = ts[k + 1] - ts[k]
        u = (t - ts[k]) / w if w > 0.0 else 1.0
        return cs[k] + u * (cs[k + 1] - cs[k])

    def rate(self, t: float) -> np.ndarray:
        """d/dt of :meth:`command` (piecewise constant; 0 outside the ramps)."""
        ts, cs = self.times, self.commands
        if t <= ts[0] or t >= ts[-1]:
            return np.zeros(3)
        k = int(np.searchsorted(ts, t, side="right")) - 1
        w = ts[k + 1] - ts[k]
        return (cs[k + 1] - cs[k]) / w if w > 0.0 else np.zeros(3)

    def velocity(self, t: float) -> np.ndarray:
        """Heading-frame (forward, lateral) velocity at ``t``."""
        return self.command(t)[:2]

    def acceleration(self, t: float) -> np.ndarray:
        return self.rate(t)[:2]

    def yaw_rate_at(self, t: float) -> float:
        return float(self.command(t)[2])

    def yaw_acceleration_at(self, t: float) -> float:
        return float(self.rate(t)[2])

    def heading_change(self, t0: float, t1: float) -> float:
        """The integral of the yaw rate over [t0, t1] (trapezoids: exact, it is piecewise
        linear)."""
        cuts = [t0] + [b for b in self.breakpoints if t0 < b < t1] + [t1]
        return float(sum(0.5 * (self.yaw_rate_at(a) + self.yaw_rate_at(b)) * (b - a)
                         for a, b in zip(cuts[:-1], cuts[1:]) if b > a))


_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)


def _heading_integral_quadratic(psi: float, w0: float, w1: float, a: complex, b: complex,
                                length: float) -> complex:
    """int_0^L exp(i (psi + w0 s + w1 s^2 / 2)) (a + b s) ds: :func:`_heading_integral` when the
    yaw rate is constant (w1 = 0), else (a Fresnel integral) Gauss-Legendre quadrature on pieces
    over which the heading turns by at most 0.25 rad (16 nodes: exact to rounding)."""
    if w1 == 0.0:
        return _heading_integral(psi, w0, a, b, length)
    turn = max(abs(w0), abs(w0 + w1 * length)) * length
    n = max(1, math.ceil(turn / 0.25))
    h = length / n
    z = 0.0j
    for k in range(n):
        s = (k + 0.5 * (_GL_NODES + 1.0)) * h
        phase = psi + w0 * s + 0.5 * w1 * s * s
        z += 0.5 * h * complex(np.dot(_GL_WEIGHTS, np.exp(1j * phase) * (a + b * s)))
    return z


@dataclass
class TrunkState:
    """A trunk reference sample (world axes): CoM position/velocity/acceleration, trunk rotation
    matrix, angular velocity/acceleration, and the heading angle (yaw)."""

    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    angular_acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0

    def copy(self) -> "TrunkState":
        return TrunkState(self.position.copy(), self.velocity.copy(), self.acceleration.copy(),
                          self.rotation.copy(), self.angular_velocity.copy(),
                          self.angular_acceleration.copy(), self.yaw)


class CrawlSway:
    """Quasi-static CoM shift for a crawl (Fahmi et al. 2019 crawl, Sect. V; the quasi-static
    controller they compare against in Sect. V-E is their ref. [13]).

    While a leg swings the CoM must lie inside the triangle of the other three feet. The offset of
    the CoM from its nominal path (heading frame) is, around swing ``k`` of leg ``i``,
    ``gain * centroid(nominal feet except i)`` (feet relative to the nominal CoM); between two
    consecutive swings a and b it is blended with a quintic (C2) over a window of length
    ``min(blend_time, mid_b - mid_a)`` centred between a's touchdown and b's lift-off. Before the
    first swing it blends from 0 over the window ending at the first lift-off (starting no earlier
    than ``t_begin``; give the schedule a start delay so that the first shift is not a jump).

    ``gain`` = (longitudinal, lateral). Default (0, 1): the lateral coordinate of the CoM goes to
    the lateral coordinate of the triangle centroid. In the LH -> LF -> RH -> RF crawl the lateral
    target only changes at the two diagonal hand-overs (LF -> RH, RF -> LH), where the CoM has to
    cross the diagonal shared by the two triangles; the longitudinal centroid coordinate flips sign
    at every step (+-1/3 of the half body length) and following it would surge the trunk back and
    forth, so it is off by default.

    Limitation: the targets come from the *nominal* footprint, not from where the feet actually
    are. In steady walking the two agree closely, but when a forward speed is commanded as a step
    from rest the feet that have not stepped yet lag behind the trunk during the first cycle and the
    CoM reference leaves their triangle.
    Ramp the speed up from rest (e.g. over two cycles) to avoid it.
    """

    def __init__(self, schedule: GaitSchedule, feet_from_com, gain=(0.0, 1.0),
                 blend_time: float | None = None, t_begin: float = 0.0):
        feet = np.asarray(feet_from_com, dtype=float)[:, :2]
        if feet.shape[0] != schedule.n_legs:
            raise ValueError(f"feet_from_com: expected {schedule.n_legs} rows, got {feet.shape[0]}")
        g = np.asarray(gain, dtype=float).reshape(2)
        self.schedule = schedule
        self.gain = g
        self.blend_time = math.inf if blend_time is None else float(blend_time)
        self.t_begin = float(t_begin)
        n = feet.shape[0]
        self.targets = np.array([g * feet[np.arange(n) != i].mean(axis=0) for i in range(n)])

    def __call__(self, t: float):
        """(offset, d offset/dt, d2 offset/dt2) at ``t``, each (2,) in the heading frame."""
        sch = self.schedule
        swings = sch.swings(t - 2.0 * sch.period, t + 2.0 * sch.period)
        a = b = None
        for s in swings:
            if s.mid <= t:
                a = s
            else:
                b = s
                break
        zero = np.zeros(2)
        if b is None:
            if a is None:
                return zero, zero.copy(), zero.copy()
            return self.targets[sch.index(a.leg)].copy(), zero, zero.copy()
        ob = self.targets[sch.index(b.leg)]
        if a is None:
            oa = zero
            w = max(0.0, min(self.blend_time, b.liftoff - self.t_begin))
            w_start = b.liftoff - w
        else:
            oa = self.targets[sch.index(a.leg)]
            w = min(self.blend_time, b.mid - a.mid)
            centre = 0.5 * (a.touchdown + b.liftoff)
            w_start = min(max(centre - 0.5 * w, a.mid), b.mid - w)
        delta = ob - oa
        if w <= 0.0:
            return (ob.copy() if t >= w_start else oa.copy()), zero, zero.copy()
        s, ds, dds = _blend_scalar((t - w_start) / w)
        return oa + s * delta, (ds / w) * delta, (dds / (w * w)) * delta


class StartShift:
    """A transient horizontal CoM offset through keyframes: ``offsets[k]`` (heading frame) at
    ``times[k]``, joined by quintic (C2) blends, zero before the first keyframe and after the last
    (whose offset should be zero). Same call protocol as :class:`CrawlSway`.

    :meth:`GaitPlanner.for_robot <wholebody.planning.planner.GaitPlanner.for_robot>` builds one for
    gaits whose first supports are two feet (a trot): the standing feet are not where the footholds
    planned around the CoM will be, and a CoM off the line between two point feet tips the trunk
    about that line (no force on the two feet has a moment about it). The offset brings the CoM
    onto the first stance's line before the first lift-off and back to the nominal path through
    the next hand-overs (see :meth:`GaitPlanner.start_shift
    <wholebody.planning.planner.GaitPlanner.start_shift>`).
    """

    def __init__(self, times, offsets):
        self.times = np.asarray(times, dtype=float).reshape(-1)
        self.offsets = np.asarray(offsets, dtype=float).reshape(len(self.times), 2)
        if len(self.times) < 2 or not np.all(np.isfinite(self.times)) \
                or np.any(np.diff(self.times) <= 0.0):
            raise ValueError(f"times: expected >= 2 finite increasing times, got {times}")
        if not np.all(np.isfinite(self.offsets)):
            raise ValueError("offsets: must be finite")

    @property
    def end(self) -> float:
        return float(self.times[-1])

    def __call__(self, t: float):
        """(offset, d offset/dt, d2 offset/dt2) at ``t``, each (2,) in the heading frame."""
        ts, os_ = self.times, self.offsets
        zero = np.zeros(2)
        if t <= ts[0] or t >= ts[-1]:
            return (os_[0] if t <= ts[0] else os_[-1]).copy(), zero, zero.copy()
        k = int(np.searchsorted(ts, t, side="right")) - 1
        w = ts[k + 1] - ts[k]
        s, ds, dds = _blend_scalar((t - ts[k]) / w)
        delta = os_[k + 1] - os_[k]
        return os_[k] + s * delta, (ds / w) * delta, (dds / (w * w)) * delta


class TrunkReference:
    """Trunk reference from a :class:`VelocityCommand` or a :class:`CommandSchedule`, starting
    at time ``t0`` from CoM ``com0`` with heading ``yaw0``; held still before ``t0``.

    ``height``: CoM height kept above the terrain under the CoM (default: ``com0``'s);
    ``terrain_alignment``: how far roll and pitch follow the terrain under the CoM: the trunk's z
    axis is the terrain normal with its horizontal part scaled by this share, so that the tangent
    of the trunk's inclination is that share of the terrain's (1: along the normal, as on the
    ramps of Figs. 4, 7, 8; 0: level); ``sway``: optional :class:`CrawlSway` added to the
    horizontal CoM; ``start_shift``: optional :class:`StartShift` added to it too.
    """

    def __init__(self, command: VelocityCommand | CommandSchedule | None, com0, yaw0: float = 0.0,
                 height: float | None = None, terrain: Terrain | None = None, t0: float = 0.0,
                 sway: CrawlSway | None = None, terrain_alignment: float = 1.0,
                 fd_step: float = 1e-3, start_shift: StartShift | None = None):
        self.command = VelocityCommand() if command is None else command
        self.com0 = np.array(com0, dtype=float).reshape(3)
        self.yaw0 = float(yaw0)
        self.terrain = Terrain.flat() if terrain is None else terrain
        self.height = (self.com0[2] - self.terrain.height(self.com0[0], self.com0[1])
                       if height is None else float(height))
        self.t0 = float(t0)
        self.sway = sway
        self.start_shift = start_shift
        self.terrain_alignment = float(terrain_alignment)
        if not 0.0 <= self.terrain_alignment <= 1.0:
            raise ValueError(f"terrain_alignment: expected a share in [0, 1], got "
                             f"{terrain_alignment}")
        self.fd_step = float(fd_step)

    # ------------------------------------------------------------------ nominal path
    def _path_pieces(self):
        """(cuts, pieces, headings, displacements): the command's linear pieces from ``t0`` on
        (piece k on [cuts[k], cuts[k + 1]), the last one unbounded), each as (a, b, w0, w1) --
        heading-frame velocity a + b s and yaw rate w0 + w1 s, s the time into the piece -- and the
        heading and displacement (complex) at each cut. Cached; rebuilt if the command, ``t0`` or
        ``yaw0`` change."""
        cache = getattr(self, "_pieces_cache", None)
        if cache is not None and cache[0][0] is self.command and cache[0][1:] == (self.t0,
                                                                                  self.yaw0):
            return cache[1]
        cmd = self.command
        cuts = [self.t0] + [b for b in cmd.breakpoints if b > self.t0]
        pieces, headings, displacements = [], [self.yaw0], [0.0j]
        for k, lo in enumerate(cuts):
            hi = cuts[k + 1] if k + 1 < len(cuts) else lo + 2.0
            mid = 0.5 * (lo + hi)
            acc = cmd.acceleration(mid)
            vel = cmd.velocity(mid)
            b = complex(acc[0], acc[1])
            a = complex(vel[0], vel[1]) - b * (mid - lo)
            w1 = float(cmd.yaw_acceleration_at(mid))
            w0 = float(cmd.yaw_rate_at(mid)) - w1 * (mid - lo)
            pieces.append((a, b, w0, w1))
            if k + 1 < len(cuts):
                L = hi - lo
                displacements.append(displacements[-1] + _heading_integral_quadratic(
                    headings[-1], w0, w1, a, b, L))
                headings.append(headings[-1] + w0 * L + 0.5 * w1 * L * L)
        value = (cuts, pieces, headings, displacements)
        self._pieces_cache = ((cmd, self.t0, self.yaw0), value)
        return value

    def _piece_at(self, t: float):
        cuts, pieces, headings, displacements = self._path_pieces()
        k = bisect.bisect_right(cuts, t) - 1
        return t - cuts[k], pieces[k], headings[k], displacements[k]

    def heading(self, t: float) -> float:
        """Integrated yaw at ``t``."""
        if t <= self.t0:
            return self.yaw0
        s, (_, _, w0, w1), psi, _ = self._piece_at(t)
        return psi + w0 * s + 0.5 * w1 * s * s

    def _displacement(self, t: float) -> complex:
        """int_{t0}^{t} R(yaw(s)) v(s) ds as a complex number (x + i y): in closed form over the
        pieces where the command is constant or ramping with a constant yaw rate, by quadrature
        where the yaw rate ramps (:func:`_heading_integral_quadratic`); the integrals up to each
        piece are cached, so O(1) whatever ``t``."""
        if t <= self.t0:
            return 0.0j
        s, (a, b, w0, w1), psi, z = self._piece_at(t)
        return z + _heading_integral_quadratic(psi, w0, w1, a, b, s)

    def yaw_acceleration(self, t: float) -> float:
        """d/dt of the commanded yaw rate at ``t`` (0 before ``t0``)."""
        return 0.0 if t < self.t0 else float(self.command.yaw_acceleration_at(t))

    def nominal(self, t: float):
        """Horizontal CoM path without sway: (xy, v_xy, a_xy, yaw, yaw_rate), world axes."""
        z = self._displacement(t)
        xy = np.array([self.com0[0] + z.real, self.com0[1] + z.imag])
        if t < self.t0:
            return xy, np.zeros(2), np.zeros(2), self.yaw0, 0.0
        psi = self.heading(t)
        om = float(self.command.yaw_rate_at(t))
        c, s = math.cos(psi), math.sin(psi)
        u = self.command.velocity(t)
        du = self.command.acceleration(t)
        v_h = u
        a_h = du + om * np.array([-u[1], u[0]])
        v = np.array([c * v_h[0] - s * v_h[1], s * v_h[0] + c * v_h[1]])
        a = np.array([c * a_h[0] - s * a_h[1], s * a_h[0] + c * a_h[1]])
        return xy, v, a, psi, om

    def _horizontal(self, t: float):
        """Horizontal CoM reference with sway: (xy, v, a, yaw, yaw_rate)."""
        xy, v, a, psi, om = self.nominal(t)
        dom = self.yaw_acceleration(t) if (self.sway or self.start_shift) else 0.0
        for offset in (self.sway, self.start_shift):
            if offset is None:
                continue
            o, do, ddo = offset(t)
            # heading-frame offset o rotated by R(psi):  d/dt (R o) = R (o' + om J o),
            # d2/dt2 (R o) = R (o'' + 2 om J o' + om' J o - om^2 o)   (J = 90 deg rotation)
            Jo = np.array([-o[1], o[0]])
            Jdo = np.array([-do[1], do[0]])
            dv = do + om * Jo
            da = ddo + 2.0 * om * Jdo + dom * Jo - om * om * o
            c, s = math.cos(psi), math.sin(psi)
            R = np.array([[c, -s], [s, c]])
            xy = xy + R @ o
            v = v + R @ dv
            a = a + R @ da
        return xy, v, a, psi, om

    def _rotation(self, xy, psi: float) -> np.ndarray:
        c, s = math.cos(psi), math.sin(psi)
        if self.terrain_alignment == 0.0 or self.terrain.is_flat:
            return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        n = self.terrain.normal(xy[0], xy[1])
        if self.terrain_alignment != 1.0:
            n = np.array([self.terrain_alignment * n[0], self.terrain_alignment * n[1], n[2]])
            n = n / math.sqrt(float(n @ n))
        # x axis: in the terrain plane and in the vertical plane of the heading, so that the yaw
        # (ZYX Euler) of the result is exactly psi; pitch and roll come from the terrain
        x0, x1, x2 = c, s, -(c * n[0] + s * n[1]) / n[2]
        k = 1.0 / math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        x0, x1, x2 = x0 * k, x1 * k, x2 * k
        n0, n1, n2 = float(n[0]), float(n[1]), float(n[2])
        y0, y1, y2 = n1 * x2 - n2 * x1, n2 * x0 - n0 * x2, n0 * x1 - n1 * x0  # y = n x x
        return np.array([[x0, y0, n0], [x1, y1, n1], [x2, y2, n2]])

    def rotation(self, t: float) -> np.ndarray:
        """Desired trunk orientation at ``t``: yaw (ZYX) = the integrated heading, z axis along the
        terrain normal under the CoM (or +z if not aligned to the terrain)."""
        xy, _, _, psi, _ = self._horizontal(t)
        return self._rotation(xy, psi)

    @staticmethod
    def _vee_rate(Rm: np.ndarray, R0: np.ndarray, Rp: np.ndarray, d: float) -> np.ndarray:
        """World angular velocity from rotations at t - d, t, t + d: vee(Rdot R^T), O(d^2)."""
        W = ((Rp - Rm) / (2.0 * d)) @ R0.T
        return 0.5 * np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]])

    # ------------------------------------------------------------------ full sample
    def evaluate(self, t: float, out: TrunkState | None = None) -> TrunkState:
        """The reference at ``t``; written into ``out`` (and returned) if given."""
        out = TrunkState() if out is None else out
        xy, v, a, psi, om = self._horizontal(t)
        ter = self.terrain
        out.position[:2] = xy
        out.velocity[:2] = v
        out.acceleration[:2] = a
        out.position[2] = ter.height(xy[0], xy[1]) + self.height
        if ter.is_flat:
            out.velocity[2] = 0.0
            out.acceleration[2] = 0.0
        else:
            g = ter.gradient(xy[0], xy[1])
            out.velocity[2] = g @ v
            out.acceleration[2] = g @ a + ter.second_derivative(xy[0], xy[1], v)
        out.rotation[:] = self._rotation(xy, psi)
        out.yaw = psi
        if self.terrain_alignment == 0.0 or ter.is_flat:
            out.angular_velocity[:] = (0.0, 0.0, om if t >= self.t0 else 0.0)
            out.angular_acceleration[:] = (0.0, 0.0, self.yaw_acceleration(t))
        else:
            # terrain-aligned: central differences of the orientation over 5 samples (O(d^2) error),
            # the CoM path near t taken from its Taylor expansion (the orientation depends on t
            # through the CoM position, which selects the terrain normal, and the heading)
            d = self.fd_step
            dom = self.yaw_acceleration(t)
            R = [self._rotation(xy + (k * d) * v + (0.5 * (k * d) ** 2) * a,
                                psi + om * k * d + 0.5 * dom * (k * d) ** 2)
                 if k else out.rotation for k in (-2, -1, 0, 1, 2)]
            out.angular_velocity[:] = self._vee_rate(R[1], R[2], R[3], d)
            w_p = self._vee_rate(R[2], R[3], R[4], d)
            w_m = self._vee_rate(R[0], R[1], R[2], d)
            out.angular_acceleration[:] = (w_p - w_m) / (2.0 * d)
        return out
