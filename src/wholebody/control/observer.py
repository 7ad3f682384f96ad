"""External wrench at the centre of mass from the centroidal momentum: the W_ext of Fahmi et al.
2019, eq. 4 ("W_ext ... an estimate from a momentum-based observer").

The centroidal dynamics (Fahmi et al. 2019 eq. 2, Orin et al. 2013) read

    ḣ_G = W_c + W_g + W_ext,    h_G = [m ċ; L_G],  W_g = [0, 0, −m g, 0, 0, 0],

with W_c the contact wrench about the CoM. A first-order momentum observer (the generalised-
momentum residual of De Luca et al., here on the 6 centroidal coordinates) needs no acceleration:

    r(t) = K_O ( h_G(t) − h_G(t0) − ∫_{t0}^{t} (W_c + W_g + r) dt ),

so ṙ = K_O (W_ext − r): r follows W_ext with time constant 1/K_O. W_c is the wrench the controller
commanded for the interval just ended (the forces of its QP, not a measurement), so r also takes
up whatever the model gets wrong about that interval — mass and CoM errors, unmodelled joint
friction — which is what eq. 4 subtracts W_ext for.
"""

from __future__ import annotations

import numpy as np

from ..robot import GRAVITY


class MomentumObserver:
    """W_ext estimate (6,: force; moment about the CoM, world axes) from h_G and the commanded
    contact wrench. ``gain`` K_O (1/s); ``limit`` (6,) clips the estimate componentwise
    (default: none)."""

    def __init__(self, gain: float = 10.0, limit=None):
        if not gain > 0:
            raise ValueError(f"gain: must be > 0, got {gain}")
        self.gain = float(gain)
        self.limit = None if limit is None else np.broadcast_to(np.asarray(limit, float), 6).copy()
        self.reset()

    def reset(self) -> None:
        """Forget the history: the next :meth:`update` starts the integral."""
        self.estimate = np.zeros(6)
        self._h0: np.ndarray | None = None
        self._integral = np.zeros(6)

    def update(self, h_G: np.ndarray, contact_wrench: np.ndarray, mass: float,
               dt: float) -> np.ndarray:
        """Advance by ``dt`` (s): ``contact_wrench`` is what acted over the interval just ended,
        ``h_G`` the centroidal momentum now. Returns (and keeps in ``estimate``) r."""
        h_G = np.asarray(h_G, dtype=float)
        if self._h0 is None:  # the first sample only anchors the integral
            self._h0 = h_G.copy()
            return self.estimate
        self._integral += dt * (np.asarray(contact_wrench, dtype=float) + self.estimate)
        self._integral[2] -= dt * mass * GRAVITY
        r = self.gain * (h_G - self._h0 - self._integral)
        if self.limit is not None:
            r = np.clip(r, -self.limit, self.limit)
        self.estimate = r
        return r
