"""Terrain courses for the quadruped experiments: one description -> the planner's terrain
(Fahmi et al. 2019, Sect. V-G, Figs. 7-8).

A course is a sequence of segments along +x (the walking direction), starting at ``x_start`` on
level ground at z = 0 and continuing level after the last segment:

* ``("flat", length)`` — level ground at the current height;
* ``("slope", length, angle)`` — a ramp of horizontal length ``length`` rising with slope ``angle``
  (rad; negative: descending);
* ``("step", height)`` — a vertical step of ``height`` (m; negative: down) at the current x;
* ``("gap", length)`` — a hole (nothing underneath; the ground after it continues at the current
  height, so a step after a gap is ``("gap", 0.22), ("step", 0.07)``).

:func:`build_course` turns it into a :class:`Course` with

* ``strips`` (one planar surface strip each) and ``gaps``, from which the simulator's boxes are
  built (:func:`wholebody.scenarios.locomotion.course_environment`);
* a :class:`~wholebody.planning.terrain.Terrain` with the exact height (gaps ``GAP_DEPTH`` below the
  lowest surface) and exact per-strip normals, for the footholds and friction cones (footnote 17:
  the real terrain normal under each foot);
* a smoothed ``trunk_terrain`` for the trunk reference: the course profile with gaps bridged,
  averaged over a window of the robot's hip-to-hip length, so that the desired trunk pitch is the
  slope of the line between the terrain under the hind and the front hips (a kink of the course
  does not become a jump of the desired pitch) and its height the mean terrain height under the
  body;
* :meth:`Course.safe_x` moves a foothold out of a gap (used by :class:`CoursePlanner`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .footholds import Foothold
from .planner import GaitPlanner
from .terrain import Terrain

GAP_DEPTH = 1.0  # planner's view of a hole: this far below the lowest surface (m)
FAR = 50.0  # the level ground before/after the course extends this far (m)


@dataclass(frozen=True)
class Strip:
    """A planar surface strip across the course: from (x0, z0) to (x1, z1)."""

    x0: float
    x1: float
    z0: float
    z1: float

    @property
    def slope(self) -> float:
        return (self.z1 - self.z0) / (self.x1 - self.x0)

    def height(self, x: float) -> float:
        return self.z0 + self.slope * (x - self.x0)


@dataclass
class Course:
    """A built course (see the module docstring). ``strips`` are sorted along x; ``gaps`` are the
    (x0, x1) intervals without ground; ``width`` (across y) and ``friction`` describe the surface
    for the simulator."""

    strips: list[Strip]
    gaps: list[tuple[float, float]]
    width: float
    friction: float
    smoothing: float
    terrain: Terrain = field(init=False)
    trunk_terrain: Terrain = field(init=False)

    def __post_init__(self):
        self._x0 = np.array([s.x0 for s in self.strips])
        self._bottom = min(min(s.z0, s.z1) for s in self.strips) - GAP_DEPTH
        self.terrain = Terrain(height=lambda x, y: self.height(x),
                               normal=lambda x, y: self._normal(self.slope(x)))
        self.trunk_terrain = Terrain(height=lambda x, y: self.smooth_height(x),
                                     normal=lambda x, y: self._normal(self.smooth_slope(x)))

    # ------------------------------------------------------------------ exact profile
    def strip_at(self, x: float) -> Strip | None:
        """The strip under x (None over a gap)."""
        i = int(np.searchsorted(self._x0, x, side="right")) - 1
        if i < 0:
            return None
        s = self.strips[i]
        return s if x <= s.x1 else None

    def height(self, x: float, y: float = 0.0) -> float:
        """Exact course height at x (the course is uniform across y)."""
        s = self.strip_at(x)
        return self._bottom if s is None else s.height(x)

    def slope(self, x: float, y: float = 0.0) -> float:
        """dz/dx of the exact course (0 over a gap)."""
        s = self.strip_at(x)
        return 0.0 if s is None else s.slope

    @staticmethod
    def _normal(slope: float) -> np.ndarray:
        n = np.array([-slope, 0.0, 1.0])
        return n / np.linalg.norm(n)

    def in_gap(self, x: float, margin: float = 0.0) -> bool:
        """True if x is within ``margin`` of a gap (or in it)."""
        return any(a - margin < x < b + margin for a, b in self.gaps)

    def safe_x(self, x: float, margin: float) -> float:
        """x moved to the nearest point at least ``margin`` from every gap edge (x itself if it is
        already safe)."""
        for a, b in self.gaps:
            lo, hi = a - margin, b + margin
            if lo < x < hi:
                return lo if x - lo <= hi - x else hi
        return x

    # ------------------------------------------------------------------ smoothed profile (trunk)
    def _bridged(self, x: float) -> float:
        """Profile with gaps bridged linearly (edge to edge)."""
        s = self.strip_at(x)
        if s is not None:
            return s.height(x)
        for a, b in self.gaps:
            if a <= x <= b:
                za, zb = self._bridged_edge(a, -1), self._bridged_edge(b, +1)
                return za + (zb - za) * (x - a) / (b - a)
        return 0.0

    def _bridged_edge(self, x: float, side: int) -> float:
        s = self.strip_at(x + side * 1e-9)
        return s.height(x) if s is not None else 0.0

    def _integral(self, a: float, b: float) -> float:
        """∫_a^b of the bridged profile (exact: it is piecewise linear between the breakpoints)."""
        points = [a, b] + [p for s in self.strips for p in (s.x0, s.x1) if a < p < b]
        points = sorted(points)
        total = 0.0
        for lo, hi in zip(points[:-1], points[1:]):
            if hi > lo:  # linear on [lo, hi]: the trapezoid rule is exact
                eps = 1e-9 * (hi - lo)
                total += 0.5 * (self._bridged(lo + eps) + self._bridged(hi - eps)) * (hi - lo)
        return total

    def smooth_height(self, x: float) -> float:
        """Mean of the bridged profile over [x − w/2, x + w/2] (w = ``smoothing``)."""
        w = self.smoothing
        if w <= 0.0:
            return self._bridged(x)
        return self._integral(x - 0.5 * w, x + 0.5 * w) / w

    def smooth_slope(self, x: float) -> float:
        """d/dx of :meth:`smooth_height`: (p(x + w/2) − p(x − w/2)) / w."""
        w = self.smoothing
        if w <= 0.0:
            return self.slope(x)
        return (self._bridged(x + 0.5 * w) - self._bridged(x - 0.5 * w)) / w

    # ------------------------------------------------------------------ drawing
    def profile(self, x_min: float, x_max: float) -> tuple[np.ndarray, np.ndarray]:
        """(x, z) polyline of the surface for plotting (gaps drawn down to the hole bottom)."""
        xs, zs = [x_min], [self.height(x_min)]
        for s in self.strips:
            if s.x1 < x_min or s.x0 > x_max:
                continue
            a, b = max(s.x0, x_min), min(s.x1, x_max)
            if zs[-1] == self._bottom:  # climbing out of a gap
                xs.append(a)
                zs.append(self._bottom)
            xs += [a, b]
            zs += [s.height(a), s.height(b)]
            if b < x_max and self.strip_at(b + 1e-9) is None:
                xs.append(b)
                zs.append(self._bottom)
        xs.append(x_max)
        zs.append(self.height(x_max))
        return np.array(xs), np.array(zs)


def build_course(segments, x_start: float = 0.5, width: float = 3.0, friction: float = 1.0,
                 smoothing: float = 0.75) -> Course:
    """Build a :class:`Course` from ``segments`` (see the module docstring) starting at
    ``x_start``. ``smoothing``: window of the trunk terrain (m; about HyQ's hip-to-hip length)."""
    x, z = float(x_start), 0.0
    strips = [Strip(-FAR, x, 0.0, 0.0)]
    gaps = []
    for seg in segments:
        kind = seg[0]
        if kind == "flat":
            length = float(seg[1])
            strips.append(Strip(x, x + length, z, z))
            x += length
        elif kind == "slope":
            length, angle = float(seg[1]), float(seg[2])
            z1 = z + length * math.tan(angle)
            strips.append(Strip(x, x + length, z, z1))
            x, z = x + length, z1
        elif kind == "step":
            z += float(seg[1])
        elif kind == "gap":
            length = float(seg[1])
            gaps.append((x, x + length))
            x += length
        else:
            raise ValueError(f"course segment: unknown kind '{kind}' (flat, slope, step, gap)")
        if seg[0] in ("flat", "slope", "gap") and not float(seg[1]) > 0.0:
            raise ValueError(f"course segment {seg}: length must be > 0")
    strips.append(Strip(x, x + FAR, z, z))
    strips = [s for s in strips if s.x1 > s.x0]
    return Course(strips, gaps, width, friction, smoothing)


def ramp_course(angle_deg: float = 15.0, up: float = 1.6, top: float = 1.2, down: float = 1.6,
                x_start: float = 0.8, **kwargs) -> Course:
    """Up a ramp, along a plateau, down a ramp of the same slope (Fig. 8 climbs such a ramp)."""
    a = math.radians(angle_deg)
    return build_course([("slope", up, a), ("flat", top), ("slope", down, -a)], x_start, **kwargs)


def gap_course(gap: float = 0.22, step: float = 0.07, x_start: float = 0.7, **kwargs) -> Course:
    """A gap followed by a step up (Fig. 7, left: "crossing a 22 cm gap with a 7 cm step")."""
    return build_course([("gap", gap), ("step", step)], x_start, **kwargs)


class CoursePlanner(GaitPlanner):
    """A :class:`GaitPlanner` that keeps footholds out of the course's gaps: a Raibert target
    within ``gap_margin`` of a gap is moved along x to the nearest safe point and dropped on the
    terrain there (the planner of Fahmi et al. optimises footholds on the terrain map, Sect. V-G;
    this is the simplest stand-in)."""

    course: Course
    gap_margin: float = 0.06

    @classmethod
    def on_course(cls, robot, schedule, command, course: Course, gap_margin: float = 0.06,
                  **options) -> "CoursePlanner":
        """The planner for ``robot`` on ``course``: exact terrain for footholds and normals, the
        smoothed :attr:`Course.trunk_terrain` for the trunk reference."""
        planner = cls.for_robot(robot, schedule, command, course.terrain, **options)
        planner.course = course
        planner.gap_margin = float(gap_margin)
        # the trunk follows the smoothed course; at the start (level ground) both agree, so the
        # CoM height offset computed at construction is unchanged
        planner.trunk.terrain = course.trunk_terrain
        planner.adjusted = 0
        return planner

    def touchdown_target(self, leg, t_touchdown, com_velocity=None, t_now=None) -> Foothold:
        fh = super().touchdown_target(leg, t_touchdown, com_velocity, t_now)
        course = getattr(self, "course", None)
        if course is None or not course.gaps:
            return fh
        x = course.safe_x(float(fh.point[0]), self.gap_margin)
        if x == fh.point[0]:
            return fh
        self.adjusted += 1
        point = np.array([x, fh.point[1], self.terrain.height(x, fh.point[1])])
        normal = self.terrain.normal(x, fh.point[1])
        radius = float(np.linalg.norm(fh.position - fh.point))
        return Foothold(point, normal, point + radius * normal)
