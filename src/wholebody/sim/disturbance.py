"""External pushes: a force applied at a point of a robot body with a time profile."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PROFILES = ("half-sine", "constant")


@dataclass
class Push:
    """A push of peak ``peak_force`` (N) along ``direction`` (world), from ``start`` for ``duration`` s.

    ``frame`` is a Pinocchio frame of the robot; ``offset`` is the point of application in that frame.
    The half-sine profile has impulse ``2 / pi * peak_force * duration``.
    """

    frame: str
    direction: tuple[float, float, float]
    peak_force: float
    start: float
    duration: float
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    profile: str = "half-sine"

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ValueError(f"push.profile must be one of {PROFILES}, got '{self.profile}'")
        if not self.duration > 0:
            raise ValueError(f"push.duration must be > 0, got {self.duration}")
        d = np.asarray(self.direction, dtype=float)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
            raise ValueError(f"push.direction must be a non-zero 3-vector, got {self.direction}")

    @property
    def unit_direction(self) -> np.ndarray:
        d = np.asarray(self.direction, dtype=float)
        return d / np.linalg.norm(d)

    def magnitude(self, t: float) -> float:
        """Force magnitude at time t."""
        s = (t - self.start) / self.duration
        if s < 0.0 or s > 1.0:
            return 0.0
        if self.profile == "constant":
            return self.peak_force
        return self.peak_force * float(np.sin(np.pi * s))

    @property
    def impulse(self) -> float:
        factor = 2.0 / np.pi if self.profile == "half-sine" else 1.0
        return factor * self.peak_force * self.duration
