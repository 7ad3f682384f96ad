"""Terrain for planning: a height map z = height(x, y) and its unit normal.

Fahmi et al. 2019 describe the terrain to the controller by its inclination: the friction
cones use the terrain normal under each foot (Sect. V-G and footnote 17), and the planner places the
footholds and the trunk on it (the robot climbs ramps in Figs. 4, 7, 8). A :class:`Terrain` is the
planning view of that: a height callable and, optionally, an exact normal callable; without one the
normal comes from central differences of the height.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

HeightFn = Callable[[float, float], float]
NormalFn = Callable[[float, float], "np.ndarray"]


class Terrain:
    """A terrain given by ``height(x, y)`` [m] and optionally ``normal(x, y)`` (any positive
    multiple of the upward normal; it is normalized). Default: flat ground at z = 0.

    ``step`` [m] is the finite-difference step used when ``normal`` is not given and for the
    curvature term of :meth:`second_derivative`.
    """

    def __init__(self, height: HeightFn | None = None, normal: NormalFn | None = None,
                 step: float = 1e-4):
        self._flat_z = 0.0 if height is None else None
        self._height = height
        self._normal = normal
        self.step = float(step)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def flat(cls, z: float = 0.0) -> "Terrain":
        """Level ground at height ``z``."""
        terrain = cls()
        terrain._flat_z = float(z)
        return terrain

    @classmethod
    def plane(cls, normal, point=(0.0, 0.0, 0.0)) -> "Terrain":
        """The plane through ``point`` with upward normal ``normal`` (n_z > 0), e.g. a ramp of slope
        angle a climbing along +x: ``normal = (-sin a, 0, cos a)``."""
        n = np.asarray(normal, dtype=float).reshape(3)
        n = n / np.linalg.norm(n)
        if n[2] <= 0.0:
            raise ValueError(f"normal: a height map needs an upward normal (n_z > 0), got {normal}")
        p = np.asarray(point, dtype=float).reshape(3)
        gx, gy = -n[0] / n[2], -n[1] / n[2]
        unit = n.copy()
        return cls(height=lambda x, y: p[2] + gx * (x - p[0]) + gy * (y - p[1]),
                   normal=lambda x, y: unit)

    # ------------------------------------------------------------------ queries
    @property
    def is_flat(self) -> bool:
        """True for level ground (constant height, normal = +z)."""
        return self._flat_z is not None

    def height(self, x: float, y: float) -> float:
        if self._flat_z is not None:
            return self._flat_z
        return float(self._height(x, y))

    def gradient(self, x: float, y: float) -> np.ndarray:
        """(dz/dx, dz/dy) at (x, y)."""
        if self._flat_z is not None:
            return np.zeros(2)
        if self._normal is not None:
            n = np.asarray(self._normal(x, y), dtype=float)
            return np.array([-n[0] / n[2], -n[1] / n[2]])
        h = self.step
        return np.array([(self.height(x + h, y) - self.height(x - h, y)) / (2 * h),
                         (self.height(x, y + h) - self.height(x, y - h)) / (2 * h)])

    def normal(self, x: float, y: float) -> np.ndarray:
        """Unit upward normal at (x, y)."""
        if self._flat_z is not None:
            return np.array([0.0, 0.0, 1.0])
        if self._normal is not None:
            n = np.asarray(self._normal(x, y), dtype=float).reshape(3)
        else:
            gx, gy = self.gradient(x, y)
            n = np.array([-gx, -gy, 1.0])
        return n / np.linalg.norm(n)

    def project(self, x: float, y: float) -> np.ndarray:
        """The terrain point (x, y, height(x, y))."""
        return np.array([x, y, self.height(x, y)])

    def second_derivative(self, x: float, y: float, d) -> float:
        """d^T H d, the curvature of the height along the horizontal vector ``d`` (H the Hessian of
        the height), by central differences; 0 on flat ground."""
        if self._flat_z is not None:
            return 0.0
        d = np.asarray(d, dtype=float)
        norm = float(np.hypot(d[0], d[1]))
        if norm == 0.0:
            return 0.0
        e = 100.0 * self.step  # 1 cm by default: a smaller stencil would amplify rounding
        ux, uy = d[0] / norm * e, d[1] / norm * e
        h0 = self.height(x, y)
        second = (self.height(x + ux, y + uy) - 2.0 * h0 + self.height(x - ux, y - uy)) / (e * e)
        return second * norm * norm
