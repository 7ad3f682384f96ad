"""Dynamic CoM reference for walking: the linear inverted pendulum and its divergent component.

The CoM ``c`` (horizontal, 2-D) of the linear inverted pendulum at a constant height z0 (Kajita et
al. 2003) moves as ``c̈ = ω² (c - p)``, ``ω = sqrt(g / z0)``, with ``p`` the ZMP (the CoP). Its
divergent component of motion (the capture point, Englsberger et al. 2015) ``ξ = c + ċ / ω``
splits this into an unstable and a stable first-order system:

    ξ̇ = ω (ξ - p)   (eq. 2 of Englsberger et al. 2015),        ċ = ω (ξ - c).

Shape of the reference: the ZMP is piecewise linear in time through knots (t_i, p_i),
i = 0..K, and held at p_K after t_K -- for walking, constant at a sole's centre in single support
and moving from one sole to the next over the double support (the caller builds the knots).
The DCM is integrated backward in closed form from rest at the end, ξ(t_K) = p_K; on segment i,
with slope s_i = (p_{i+1} - p_i) / (t_{i+1} - t_i),

    ξ(t) = p(t) + s_i / ω + E_i exp(ω (t - t_{i+1})),      E_i = ξ_{i+1} - p_{i+1} - s_i / ω,

and the CoM forward from c(t_0) = c0, continuous at every knot,

    c(t) = p(t) + (E_i / 2) exp(ω (t - t_{i+1})) + D_i exp(-ω (t - t_i)),

after t_K ``c = p_K + (c(t_K) - p_K) exp(-ω (t - t_K))``. ``ċ`` is the derivative of the same
expression and ``c̈ = ω² (c - p)``. ξ, c, ċ = ω (ξ - c) and c̈ are continuous at the knots; the
jerk steps where the ZMP slope does.

With ``dcm0`` the first ZMP knot is replaced by the one that starts the DCM where it is
(ξ(t_0) = dcm0): a robot at rest (dcm0 = c0) then starts with zero reference velocity, and a
re-plan keeps the reference DCM continuous. The replaced knot is ``plan.zmp_knots[0]``; it is the
caller's to check that it lies in the support.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from ..validation import finite_array, nonnegative, positive

__all__ = ["DCMPlan", "capture_point", "lipm_frequency", "predicted_dcm"]


def lipm_frequency(com_height: float, gravity: float = 9.81) -> float:
    """ω = sqrt(g / z0) [1/s], the natural frequency of the linear inverted pendulum at CoM height
    z0 (Kajita et al. 2003)."""
    return math.sqrt(positive(gravity, "gravity") / positive(com_height, "com_height"))


def capture_point(com, com_velocity, omega) -> np.ndarray:
    """ξ = c + ċ / ω, the DCM (capture point) of Englsberger et al. 2015, eq. 1, horizontal part.

    ``com`` and ``com_velocity`` are 2- or 3-vectors (the first two coordinates are used)."""
    omega = positive(omega, "omega")
    c = np.asarray(com, dtype=float)[..., :2]
    v = np.asarray(com_velocity, dtype=float)[..., :2]
    return c + v / omega


def predicted_dcm(dcm, zmp, omega, horizon) -> np.ndarray:
    """ξ after ``horizon`` seconds with the ZMP held at ``zmp``: the solution of ξ̇ = ω (ξ - p)
    (Englsberger et al. 2015, eq. 2), ``p + exp(ω T) (ξ - p)``."""
    omega = positive(omega, "omega")
    horizon = nonnegative(horizon, "horizon")
    p = np.asarray(zmp, dtype=float)[..., :2]
    xi = np.asarray(dcm, dtype=float)[..., :2]
    return p + math.exp(omega * horizon) * (xi - p)


def _is_scalar(t) -> bool:
    """``t`` is one time (a Python or numpy number, a 0-d array), not an array of them."""
    return type(t) is float or np.ndim(t) == 0


class DCMPlan:
    """LIPM CoM and DCM reference for a piecewise-linear ZMP (see the module docstring).

    ``knot_times`` (K+1,) strictly increasing (K = 0: one knot, a constant ZMP), ``zmp_knots``
    (K+1, 2), ``com0`` (2,) the CoM at ``knot_times[0]``; ``dcm0`` (2,), optional, the DCM to
    start from: it replaces ``zmp_knots[solve_knot]`` (default the first; a later knot keeps the
    first ZMP where it is, e.g. continuous with the ZMP commanded before a re-plan). Times before
    the first knot give the values at it.

    Evaluation (:meth:`zmp`, :meth:`dcm`, :meth:`com`) takes a scalar time, giving (2,) arrays, or
    N times, giving (N, 2) arrays; each segment's constants are computed here, so a call is one
    search and a few operations on 2-vectors.
    """

    def __init__(self, omega: float, knot_times, zmp_knots, com0, dcm0=None,
                 solve_knot: int = 0):
        self.omega = w = positive(omega, "omega")
        times = finite_array(knot_times, "knot_times")
        if times.ndim != 1 or times.size == 0:
            raise ValueError(f"knot_times: expected a 1-D array of at least one time, got shape "
                             f"{times.shape}")
        steps = np.diff(times)
        if np.any(steps <= 0.0):
            i = int(np.argmax(steps <= 0.0))
            raise ValueError(f"knot_times: must be strictly increasing, got {times[i]!r} then "
                             f"{times[i + 1]!r} at index {i + 1}")
        n = times.size
        zmp = finite_array(zmp_knots, "zmp_knots", shape=(n, 2)).copy()
        c0 = finite_array(com0, "com0", shape=(2,))
        K = n - 1

        slope = np.zeros((n, 2))          # row K: the constant tail after t_K
        decay = np.exp(-w * steps)        # exp(-ω (t_{i+1} - t_i)), in (0, 1)

        def backward(z):
            """DCM at the knots of ZMP knots ``z``, at rest at the end (ξ_K = p_K), and the
            segments' slopes."""
            s = np.zeros((n, 2))
            s[:K] = np.diff(z, axis=0) / steps[:, None]
            x = np.empty((n, 2))
            x[K] = z[K]
            for i in range(K - 1, -1, -1):
                x[i] = z[i] + s[i] / w + decay[i] * (x[i + 1] - z[i + 1] - s[i] / w)
            return x, s

        if dcm0 is not None:
            target = finite_array(dcm0, "dcm0", shape=(2,))
            if isinstance(solve_knot, bool) or not isinstance(solve_knot, (int, np.integer)) \
                    or not 0 <= solve_knot <= K:
                raise ValueError(f"solve_knot: expected an integer in [0, {K}], got "
                                 f"{solve_knot!r}")
            # ξ_0 is affine in the solved knot, with the same coefficient on x and y
            zmp[solve_knot] = 0.0
            base = backward(zmp)[0][0]
            zmp[solve_knot] = 1.0
            coefficient = backward(zmp)[0][0] - base
            zmp[solve_knot] = (target - base) / coefficient
        xi, slope = backward(zmp)
        if dcm0 is not None:
            xi[0] = target  # the same up to rounding

        # Per-segment constants; segment K is the tail [t_K, inf) with s = E = 0.
        gain = np.zeros((n, 2))
        gain[:K] = xi[1:] - zmp[1:] - slope[:K] / w       # E_i
        # Forward pass: D_i from the CoM at t_i, c(t_i) = p_i + (E_i / 2) decay_i + D_i.
        offset = np.empty((n, 2))
        c = c0
        for i in range(K):
            offset[i] = c - zmp[i] - 0.5 * gain[i] * decay[i]
            c = zmp[i + 1] + 0.5 * gain[i] + offset[i] * decay[i]
        offset[K] = c - zmp[K]

        for arr in (times, zmp):
            arr.flags.writeable = False
        self.knot_times = times
        self.zmp_knots = zmp
        self.com0 = c0
        self.end_time = float(times[K])
        self._start = times
        self._stop = np.append(times[1:], np.inf)
        # the same as Python floats, for the one-time lookups of the control loop (_scalar)
        self._start_list, self._stop_list = self._start.tolist(), self._stop.tolist()
        self._slope = slope
        self._gain = gain
        self._offset = offset
        self._dcm_shift = slope / w                       # s_i / ω

    @property
    def start_time(self) -> float:
        """t_0, the first knot."""
        return float(self.knot_times[0])

    def _scalar(self, t: float):
        """Segment index, ZMP, exp(ω (t - t_{i+1})) and exp(-ω (t - t_i)) at one time (the
        control loop's case: no array machinery)."""
        starts = self._start_list
        t = max(float(t), starts[0])
        i = bisect.bisect_right(starts, t) - 1  # (numpy's searchsorted, side="right")
        start = starts[i]
        p = self.zmp_knots[i] + self._slope[i] * (t - start)
        stop = self._stop_list[i]
        rise = math.exp(self.omega * (t - stop)) if stop != math.inf else 0.0
        fall = math.exp(-self.omega * (t - start))
        return i, p, rise, fall

    def _locate(self, t):
        """Segment index and, per time, the ZMP, exp(ω (t - t_{i+1})) and exp(-ω (t - t_i))."""
        t = np.maximum(np.asarray(t, dtype=float), self._start[0])
        i = np.searchsorted(self._start, t, side="right") - 1
        tt = t[..., None]
        p = self.zmp_knots[i] + self._slope[i] * (tt - self._start[i][..., None])
        rise = np.exp(self.omega * (tt - self._stop[i][..., None]))
        fall = np.exp(-self.omega * (tt - self._start[i][..., None]))
        return i, p, rise, fall

    def zmp(self, t) -> np.ndarray:
        """The ZMP reference p(t)."""
        t = np.maximum(np.asarray(t, dtype=float), self._start[0])
        i = np.searchsorted(self._start, t, side="right") - 1
        return self.zmp_knots[i] + self._slope[i] * (t[..., None] - self._start[i][..., None])

    def dcm(self, t) -> tuple[np.ndarray, np.ndarray]:
        """(ξ, ξ̇) at time ``t``: ξ = p + s_i / ω + E_i exp(ω (t - t_{i+1})), ξ̇ = ω (ξ - p)."""
        i, p, rise, _ = self._scalar(t) if _is_scalar(t) else self._locate(t)
        away = self._dcm_shift[i] + self._gain[i] * rise
        return p + away, self.omega * away

    def com(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(c, ċ, c̈) at time ``t``: c = p + (E_i / 2) exp(ω (t - t_{i+1})) + D_i exp(-ω (t - t_i)),
        c̈ = ω² (c - p)."""
        i, p, rise, fall = self._scalar(t) if _is_scalar(t) else self._locate(t)
        half, off = 0.5 * self._gain[i] * rise, self._offset[i] * fall
        w = self.omega
        return p + half + off, self._slope[i] + w * (half - off), w * w * (half + off)
