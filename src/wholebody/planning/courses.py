"""Terrain courses for the quadruped experiments: one description -> the planner's terrain
(Fahmi et al. 2019, Sect. V-G, Figs. 7-8).

A course is a sequence of segments along +x (the walking direction), starting at ``x_start`` on
level ground at z = 0 and continuing level after the last segment:

* ``("flat", length)`` — level ground at the current height;
* ``("slope", length, angle)`` — a ramp of horizontal length ``length`` rising with slope ``angle``
  (rad; negative: descending);
* ``("step", height)`` — a vertical step of ``height`` (m; negative: down) at the current x;
* ``("gap", length)`` — a hole (nothing underneath; the ground after it continues at the current
  height, so a step after a gap is ``("gap", 0.22), ("step", 0.07)``);
* ``("rough", length, amplitude, cell, seed)`` — rough ground: a :class:`HeightField` of cells
  about ``cell`` wide across the course's whole width, each a level top at the current height
  plus a height uniform in [−amplitude, amplitude] (``numpy.random.default_rng(seed)``).

Stairs are steps and flats (:func:`stairs_course`).

:func:`build_course` turns it into a :class:`Course` with

* ``strips`` (one planar surface strip each) and ``gaps``, from which the simulator's boxes are
  built (:func:`wholebody.scenarios.locomotion.course_environment`);
* a :class:`~wholebody.planning.terrain.Terrain` with the exact height (gaps ``GAP_DEPTH`` below the
  lowest surface) and exact per-strip normals, for the footholds and friction cones (footnote 17:
  the real terrain normal under each foot);
* a smoothed ``trunk_terrain`` for the trunk reference: the course profile with gaps bridged
  and rough ground at its strip's level (its cells' mean is about that level),
  averaged over a window of the robot's hip-to-hip length, so that the desired trunk pitch is the
  slope of the line between the terrain under the hind and the front hips (a kink of the course
  does not become a jump of the desired pitch) and its height the mean terrain height under the
  body;
* :meth:`Course.safe_point` moves a foothold out of a gap and away from every edge where the
  surface jumps (a riser, a field cell's side; used by :class:`CoursePlanner`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .footholds import Foothold
from .planner import GaitPlanner
from .swing import SwingTrajectory
from .terrain import Terrain

GAP_DEPTH = 1.0  # planner's view of a hole: this far below the lowest surface (m)
FAR = 50.0  # the level ground before/after the course extends this far (m)


@dataclass(frozen=True, eq=False)
class HeightField:
    """Rough ground over x in [x0, x0 + nx cx], y in [y0, y0 + ny cy]: cell (i, j) is a level top
    ``heights[i, j]`` above its strip's level. Outside the y range the nearest cell is taken (the
    field covers the course's width, beyond which the simulator has no ground)."""

    x0: float
    y0: float
    cx: float
    cy: float
    heights: np.ndarray

    @classmethod
    def random(cls, x0: float, length: float, width: float, amplitude: float, cell: float,
               seed: int) -> "HeightField":
        """Cells about ``cell`` wide (a whole number of them over ``length`` and ``width``), heights
        uniform in [−amplitude, amplitude] from ``numpy.random.default_rng(seed)``."""
        if not (amplitude >= 0.0 and cell > 0.0):
            raise ValueError(f"rough: amplitude must be >= 0 and cell > 0, got {amplitude}, {cell}")
        nx, ny = max(1, round(length / cell)), max(1, round(width / cell))
        heights = np.random.default_rng(int(seed)).uniform(-amplitude, amplitude, (nx, ny))
        return cls(float(x0), -0.5 * width, length / nx, width / ny, heights)

    def cell(self, x: float, y: float) -> tuple[int, int]:
        """Indices of the cell under (x, y) (clamped to the field)."""
        nx, ny = self.heights.shape
        return (min(max(int(math.floor((x - self.x0) / self.cx)), 0), nx - 1),
                min(max(int(math.floor((y - self.y0) / self.cy)), 0), ny - 1))

    def offset(self, x: float, y: float) -> float:
        return float(self.heights[self.cell(x, y)])

    def inside(self, x: float, y: float, margin: float) -> tuple[float, float]:
        """(x, y) moved to the nearest point at least ``margin`` inside its cell's sides (the
        cell's centre if it is narrower than 2 ``margin``)."""
        i, j = self.cell(x, y)
        out = []
        for v, lo, size in ((x, self.x0 + i * self.cx, self.cx), (y, self.y0 + j * self.cy,
                                                                   self.cy)):
            m = min(margin, 0.5 * size)
            out.append(min(max(v, lo + m), lo + size - m))
        return out[0], out[1]

    def highest(self, a, b) -> float:
        """The highest cell top under the segment from (x, y) ``a`` to ``b`` (sampled at least
        every quarter cell)."""
        length = float(np.hypot(b[0] - a[0], b[1] - a[1]))
        n = 2 + int(4.0 * length / min(self.cx, self.cy))
        return max(self.offset(a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]))
                   for s in np.linspace(0.0, 1.0, n))


@dataclass(frozen=True)
class Strip:
    """A planar surface strip across the course: from (x0, z0) to (x1, z1); with a ``field``,
    rough ground whose cells are offset from that level."""

    x0: float
    x1: float
    z0: float
    z1: float
    field: HeightField | None = None

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
        lowest = [min(s.z0, s.z1) + (0.0 if s.field is None else float(s.field.heights.min()))
                  for s in self.strips]
        self._bottom = min(lowest) - GAP_DEPTH
        self.terrain = Terrain(height=self.height,
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
        """Exact course height at (x, y) (uniform across y except on rough ground)."""
        s = self.strip_at(x)
        if s is None:
            return self._bottom
        return s.height(x) if s.field is None else s.height(x) + s.field.offset(x, y)

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

    @property
    def edges(self) -> list[float]:
        """x of every edge across the course where the surface jumps: a step's riser, the ends
        of rough ground (not the gaps' edges, see :attr:`gaps`)."""
        out = []
        for a, b in zip(self.strips[:-1], self.strips[1:]):
            if a.x1 == b.x0 and (a.z1 != b.z0 or a.field is not None or b.field is not None):
                out.append(a.x1)
        return out

    def jumps_between(self, a, b) -> bool:
        """Whether the surface jumps under the segment from (x, y) ``a`` to ``b``: a riser or
        an end of rough ground (:attr:`edges`) between them, or rough ground under them."""
        lo, hi = sorted((float(a[0]), float(b[0])))
        return (any(lo <= e <= hi for e in self.edges)
                or any(s.field is not None and s.x0 < hi and s.x1 > lo for s in self.strips))

    def safe_x(self, x: float, margin: float) -> float:
        """x moved to the nearest point at least ``margin`` from every gap and every
        :attr:`edges` (x itself if it is already safe)."""
        spans = sorted([(a - margin, b + margin) for a, b in self.gaps]
                       + [(e - margin, e + margin) for e in self.edges])
        merged = []
        for lo, hi in spans:
            if merged and lo <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], hi)
            else:
                merged.append([lo, hi])
        for lo, hi in merged:
            if lo < x < hi:
                return lo if x - lo <= hi - x else hi
        return x

    def safe_point(self, x: float, y: float, margin: float) -> tuple[float, float]:
        """(x, y) moved to the nearest point at least ``margin`` from gaps and edges along x
        (:meth:`safe_x`) and, on rough ground, from its cell's sides."""
        x = self.safe_x(x, margin)
        s = self.strip_at(x)
        if s is not None and s.field is not None:
            x, y = s.field.inside(x, y, margin)
        return x, y

    def edge_distance(self, x: float, y: float = 0.0) -> float:
        """Horizontal distance from (x, y) to the nearest gap edge, :attr:`edges` or, on rough
        ground, side of its cell (inf on a course without any)."""
        xs = [e for g in self.gaps for e in g] + self.edges
        d = min((abs(x - e) for e in xs), default=math.inf)
        s = self.strip_at(x)
        if s is not None and s.field is not None:
            f = s.field
            for v, lo, size in ((x, f.x0, f.cx), (y, f.y0, f.cy)):
                u = (v - lo) / size
                d = min(d, abs(u - round(u)) * size)
        return d

    def highest(self, a, b) -> float:
        """The highest point of the exact course under the segment from (x, y) ``a`` to ``b``
        (gaps excluded; a strip's height at the ends of its part of the segment)."""
        lo, hi = sorted((float(a[0]), float(b[0])))
        top = -math.inf
        for s in self.strips:
            if s.x1 < lo or s.x0 > hi:
                continue
            u, v = max(s.x0, lo), min(s.x1, hi)
            z = max(s.height(u), s.height(v))
            if s.field is not None:
                span = b[0] - a[0]
                pa = a if span == 0 else [u, a[1] + (u - a[0]) / span * (b[1] - a[1])]
                pb = b if span == 0 else [v, a[1] + (v - a[0]) / span * (b[1] - a[1])]
                z += s.field.highest(pa, pb)
            top = max(top, z)
        return top

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
            if s.field is None:
                xs += [a, b]
                zs += [s.height(a), s.height(b)]
            else:  # rough ground: its cells along y = 0
                cuts = s.field.x0 + s.field.cx * np.arange(s.field.heights.shape[0] + 1)
                cuts = [a, *(c for c in cuts if a < c < b), b]
                for u, v in zip(cuts[:-1], cuts[1:]):
                    z = self.height(0.5 * (u + v), 0.0)
                    xs += [u, v]
                    zs += [z, z]
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
        elif kind == "rough":
            length, amplitude, cell, seed = float(seg[1]), float(seg[2]), float(seg[3]), seg[4]
            field = HeightField.random(x, length, width, amplitude, cell, seed)
            strips.append(Strip(x, x + length, z, z, field))
            x += length
        else:
            raise ValueError(f"course segment: unknown kind '{kind}' (flat, slope, step, gap, "
                             "rough)")
        if seg[0] in ("flat", "slope", "gap", "rough") and not float(seg[1]) > 0.0:
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


def stairs_course(steps: int = 5, rise: float = 0.15, tread: float = 0.5, landing: float = 1.0,
                  x_start: float = 0.8, **kwargs) -> Course:
    """``steps`` steps of ``rise`` up, a ``landing`` (the top tread), ``steps`` down: risers up at
    ``x_start + k tread`` (k < steps), risers down at ``x_start + (steps - 1) tread + landing +
    k tread``, the ground level again after the last."""
    if int(steps) != steps or steps < 1:
        raise ValueError(f"steps: expected a whole number >= 1, got {steps}")
    steps = int(steps)
    up = [("step", rise), ("flat", tread)] * (steps - 1) + [("step", rise), ("flat", landing)]
    down = [("step", -rise), ("flat", tread)] * (steps - 1) + [("step", -rise)]
    return build_course(up + down, x_start, **kwargs)


def rough_course(length: float = 3.0, amplitude: float = 0.05, cell: float = 0.2, seed: int = 0,
                 x_start: float = 0.8, **kwargs) -> Course:
    """Rough ground of ``length`` (:class:`HeightField`, ±``amplitude``) between level ground."""
    return build_course([("rough", length, amplitude, cell, seed)], x_start, **kwargs)


class CoursePlanner(GaitPlanner):
    """A :class:`GaitPlanner` that keeps footholds out of the course's gaps and off its edges: a
    Raibert target within ``gap_margin`` of a gap, a riser or a rough cell's side is moved to the
    nearest safe point (:meth:`Course.safe_point`) and dropped on the terrain there (the planner
    of Fahmi et al. optimises footholds on the terrain map, Sect. V-G; this is the simplest
    stand-in). A swing's apex is ``clearance`` above the highest terrain under its path, not
    only above its ends (a cell between them may be higher)."""

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
        if course is None:
            return fh
        x, y = course.safe_point(float(fh.point[0]), float(fh.point[1]), self.gap_margin)
        if x == fh.point[0] and y == fh.point[1]:
            return fh
        self.adjusted += 1
        point = np.array([x, y, self.terrain.height(x, y)])
        normal = self.terrain.normal(x, y)
        radius = float(np.linalg.norm(fh.position - fh.point))
        return Foothold(point, normal, point + radius * normal)

    def swing_clearance(self, leg, p0, p1, swing, clearance: float | None = None) -> float:
        """The planner's clearance above the highest terrain under the path, capped by the leg's
        reach (:meth:`GaitPlanner.swing_clearance`); where the capped swing would meet an edge
        (a riser crossed before mid-swing, the foot still low, :meth:`Course.jumps_between`),
        raised in quarters of the foot radius until its sphere passes over the course, the reach
        cap yielding to the terrain. Over a slope the cap stands: a leg of little reach (IIT
        Centauro's) raised beyond it on a ramp drives its hip onto its limit."""
        course = getattr(self, "course", None)
        wanted = self.clearance if clearance is None else clearance
        if course is None:
            return super().swing_clearance(leg, p0, p1, swing, wanted)
        ends = max(course.height(p0[0], p0[1]), course.height(p1[0], p1[1]))
        wanted += max(0.0, course.highest(p0[:2], p1[:2]) - ends)
        c = super().swing_clearance(leg, p0, p1, swing, wanted)
        radius = float(self._radius[self.schedule.index(leg)])
        if not course.jumps_between(p0[:2], p1[:2]):
            return c  # a slope or level ground: the reach cap stands (the swing may graze it)
        while c < wanted and not self._passes(p0, p1, swing, c, radius):
            c = min(wanted, c + 0.25 * max(radius, 1e-3))
        return c

    def _passes(self, p0, p1, swing, clearance: float, radius: float,
                tolerance: float = 2e-3) -> bool:
        """Whether the swing with ``clearance`` keeps a foot of ``radius`` above the course: at 41
        times, the foot's bottom above the highest point of the course within ``radius`` of it
        (a square around it), ``tolerance`` allowed for a foot that lifts off pressed in."""
        trajectory = SwingTrajectory(p0, p1, swing.touchdown - swing.liftoff, clearance, 0.0)
        offsets = (-radius, 0.0, radius)
        for x, y, z in trajectory.evaluate(np.linspace(0.0, trajectory.duration, 41))[0]:
            under = max(self.course.height(x + dx, y + dy) for dx in offsets for dy in offsets)
            if z - radius < under - tolerance:
                return False
        return True
