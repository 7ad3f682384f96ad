"""Smooth 0 -> 1 blends and minimum-jerk moves between waypoints.

:func:`quintic_blend` is the minimum-jerk (quintic) blend used for every smooth reference in the
package: swing feet (Fahmi et al. 2019, eqs. 5-6), CoG shifts, gain and amplitude ramps and moving
supports (Herzog et al. 2016, Sects. 5.2.3-5.4). Its velocity and acceleration vanish at both ends,
so a reference built from it (and fed forward) starts and stops without a step in the commanded
acceleration.
"""

from __future__ import annotations

import numpy as np


def quintic_blend(u, duration: float = 1.0):
    """s(u) = 10u^3 - 15u^4 + 6u^5 and its first two derivatives.

    ``u`` is clipped to [0, 1] (outside it the blend is held: s' = s'' = 0). The derivatives are in
    ``u``, or, with ``duration`` T (u = t / T), in time: ds/dt = s'(u) / T, d2s/dt2 = s''(u) / T^2.
    Scalar in, floats out; array in, arrays of the same shape out.
    """
    if np.ndim(u) == 0:
        u = min(max(float(u), 0.0), 1.0)
    else:
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    v = 1.0 - u
    s = u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
    ds = 30.0 * u * u * v * v
    dds = 60.0 * u * v * (1.0 - 2.0 * u)
    if duration != 1.0:
        ds, dds = ds / duration, dds / duration ** 2
    return s, ds, dds


def smoothstep(u: float) -> float:
    """The cubic blend 3u^2 - 2u^3 on u clipped to [0, 1] (its acceleration steps at both ends)."""
    u = min(max(u, 0.0), 1.0)
    return u * u * (3.0 - 2.0 * u)


class WaypointMotion:
    """Back-to-back quintic moves between waypoints of a coordinate vector, from ``start``.

    ``__call__(t)`` gives the vector, ``rate(t)`` and ``acceleration(t)`` its derivatives.
    """

    def __init__(self, waypoints, move_time: float, start: float):
        self.waypoints = np.asarray(waypoints, dtype=float)
        self.move_time, self.start = float(move_time), float(start)

    @property
    def end(self) -> float:
        return self.start + self.move_time * (len(self.waypoints) - 1)

    def _terms(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w, T = self.waypoints, self.move_time
        k = int(np.clip(np.floor((t - self.start) / T), 0, len(w) - 2))
        s = (t - self.start - k * T) / T
        p, dp, ddp = quintic_blend(s)
        delta = w[k + 1] - w[k]
        return w[k] + p * delta, dp / T * delta, ddp / T ** 2 * delta

    def __call__(self, t: float) -> np.ndarray:
        return self._terms(t)[0]

    def rate(self, t: float) -> np.ndarray:
        return self._terms(t)[1]

    def acceleration(self, t: float) -> np.ndarray:
        return self._terms(t)[2]
