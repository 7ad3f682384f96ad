"""Swing-foot trajectories: lift-off position to touchdown position with a clearance apex.

The swing task of Fahmi et al. 2019 (eqs. 5-6 and 11-12) tracks a desired swing-foot
position ``x_sw,d``, velocity ``v_sw,d`` and feed-forward acceleration ``v̇_sw,ff``; this module
produces all three.

Shape: the horizontal coordinates follow a quintic (minimum-jerk) blend from ``p0`` to ``p1`` over
the whole swing; the height follows two quintic blends, ``z0 -> z_apex`` over the first half and
``z_apex -> z1`` over the second, with ``z_apex = max(z0, z1) + clearance``. Every blend starts and
ends with zero velocity and acceleration, so the trajectory is C2 (continuous acceleration; the jerk
jumps at mid-swing), starts and lands with zero velocity and acceleration, and its highest point is
exactly ``z_apex``, reached at mid-swing (each half is monotone in z).

A target below the floor (a touchdown pressed into it) meets the floor before the swing's end,
where the horizontal blend is not yet complete: with ``floor`` given, the horizontal move is
stretched so that the foot is over the target when its descent passes the floor's height (the
blend's shape and timing unchanged; it lands on its footstep, not short of it).
"""

from __future__ import annotations

import numpy as np

from .blend import quintic_blend

__all__ = ["SwingTrajectory", "quintic_blend", "swing_trajectory"]

_blend_scalar = quintic_blend  # the scalar form, still imported by planning.trunk


class SwingTrajectory:
    """Swing of one foot from ``p0`` (lift-off, time ``t0``) to ``p1`` (touchdown, time
    ``t0 + duration``), rising ``clearance`` [m] above the higher endpoint at mid-swing.

    Positions are those of the foot frame (for a point foot of radius r on flat ground the frame is
    r above the ground). Before ``t0`` the foot is held at ``p0``, after touchdown at ``p1``.
    ``floor``: the height (between ``p1``'s and the apex) at which the foot is over ``p1``
    (module docstring; it then moves on by the blend's rest, horizontally, until touchdown);
    None: at the end.
    """

    def __init__(self, p0, p1, duration: float, clearance: float = 0.1, t0: float = 0.0,
                 floor: float | None = None):
        self.p0 = np.array(p0, dtype=float).reshape(3)
        self.p1 = np.array(p1, dtype=float).reshape(3)
        if not (np.all(np.isfinite(self.p0)) and np.all(np.isfinite(self.p1))):
            raise ValueError("p0, p1: swing endpoints must be finite 3-vectors")
        if not (np.isfinite(duration) and duration > 0.0):
            raise ValueError(f"duration: must be a positive finite time, got {duration}")
        if not (np.isfinite(clearance) and clearance >= 0.0):
            raise ValueError(f"clearance: must be a finite height >= 0, got {clearance}")
        self.duration = float(duration)
        self.clearance = float(clearance)
        self.t0 = float(t0)
        self.apex_height = max(self.p0[2], self.p1[2]) + self.clearance
        self._dxy = self.p1[:2] - self.p0[:2]
        self._rise = self.apex_height - self.p0[2]
        self._fall = self.p1[2] - self.apex_height
        #: share of the swing at which the foot passes ``floor`` (1 without one)
        self.floor_share = 1.0
        self._stretch = None  # the horizontal blend's value at floor_share, with a floor
        if floor is not None:
            if not (np.isfinite(floor) and self.p1[2] <= floor < self.apex_height):
                raise ValueError(f"floor: expected a height in [{self.p1[2]:.4g}, "
                                 f"{self.apex_height:.4g}) (touchdown to apex), got {floor!r}")
            self.floor_share = 0.5 * (1.0 + _descent_share(
                (self.apex_height - floor) / (self.apex_height - self.p1[2])))
            self._stretch = quintic_blend(self.floor_share)[0]
            self._dxy = self._dxy / self._stretch

    def with_landing_xy(self, xy) -> "SwingTrajectory":
        """The same swing (start, duration, heights, floor) landing at ``xy`` (x, y) instead:
        what the constructor gives for that target, without solving for the floor's share again
        (a step adjusted every control cycle)."""
        xy = np.asarray(xy, dtype=float).reshape(2)
        if not np.all(np.isfinite(xy)):
            raise ValueError(f"xy: the landing position must be finite, got {xy!r}")
        moved = object.__new__(SwingTrajectory)
        moved.__dict__.update(self.__dict__)
        moved.p0, moved.p1 = self.p0.copy(), self.p1.copy()
        moved.p1[:2] = xy
        moved._dxy = moved.p1[:2] - moved.p0[:2]
        if self._stretch is not None:
            moved._dxy = moved._dxy / self._stretch
        return moved

    @property
    def t1(self) -> float:
        """Touchdown time."""
        return self.t0 + self.duration

    def evaluate(self, t):
        """(position, velocity, acceleration) at time(s) ``t``: each (3,) for a scalar ``t``,
        (N, 3) for N times."""
        t_arr = np.asarray(t, dtype=float)
        scalar = t_arr.ndim == 0
        tau = np.atleast_1d((t_arr - self.t0) / self.duration)
        T = self.duration
        n = tau.shape[0]
        pos = np.empty((n, 3))
        vel = np.empty((n, 3))
        acc = np.empty((n, 3))
        s, ds, dds = quintic_blend(tau)
        pos[:, :2] = self.p0[:2] + np.outer(s, self._dxy)
        vel[:, :2] = np.outer(ds / T, self._dxy)
        acc[:, :2] = np.outer(dds / T**2, self._dxy)
        first = tau < 0.5
        sigma = np.where(first, 2.0 * tau, 2.0 * tau - 1.0)
        s, ds, dds = quintic_blend(sigma)
        base = np.where(first, self.p0[2], self.apex_height)
        delta = np.where(first, self._rise, self._fall)
        pos[:, 2] = base + delta * s
        vel[:, 2] = delta * ds * (2.0 / T)
        acc[:, 2] = delta * dds * (4.0 / T**2)
        if scalar:
            return pos[0], vel[0], acc[0]
        return pos, vel, acc

    def evaluate_into(self, t: float, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray) -> None:
        """Scalar-time evaluation written into three preallocated 3-vectors (for control loops)."""
        T = self.duration
        tau = min(max((t - self.t0) / T, 0.0), 1.0)
        s, ds, dds = quintic_blend(tau)
        pos[0] = self.p0[0] + s * self._dxy[0]
        pos[1] = self.p0[1] + s * self._dxy[1]
        vel[0] = ds / T * self._dxy[0]
        vel[1] = ds / T * self._dxy[1]
        acc[0] = dds / T**2 * self._dxy[0]
        acc[1] = dds / T**2 * self._dxy[1]
        if tau < 0.5:
            base, delta, sigma = self.p0[2], self._rise, 2.0 * tau
        else:
            base, delta, sigma = self.apex_height, self._fall, 2.0 * tau - 1.0
        s, ds, dds = quintic_blend(sigma)
        pos[2] = base + delta * s
        vel[2] = delta * ds * (2.0 / T)
        acc[2] = delta * dds * (4.0 / T**2)

    def position(self, t):
        return self.evaluate(t)[0]

    def velocity(self, t):
        return self.evaluate(t)[1]

    def acceleration(self, t):
        return self.evaluate(t)[2]


def _descent_share(fraction: float) -> float:
    """The share sigma of the descent's blend at which it has covered ``fraction`` of its
    height: the root in [0, 1] of 6 sigma^5 - 15 sigma^4 + 10 sigma^3 = fraction."""
    roots = np.roots([6.0, -15.0, 10.0, 0.0, 0.0, -float(fraction)])
    real = roots[np.abs(roots.imag) < 1e-9].real
    return float(np.clip(real[(real >= -1e-9) & (real <= 1.0 + 1e-9)], 0.0, 1.0).min())


def swing_trajectory(p0, p1, duration: float, t, clearance: float = 0.1):
    """Functional form: (position, velocity, acceleration) of the swing from ``p0`` at t = 0 to
    ``p1`` at t = ``duration`` (see :class:`SwingTrajectory`)."""
    return SwingTrajectory(p0, p1, duration, clearance).evaluate(t)
