"""Deliberate mismatch between the controller's model and the simulated robot (simulator side only).

Robustness is shown by controlling, with the nominal Pinocchio model, a simulated robot whose link
masses, centres of mass, actuation (delay, noise) and joint friction differ from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Mismatch:
    """Options applied when building and stepping the twin. Defaults: an exact twin.

    mass_scale      every link mass and inertia multiplied by this factor
    mass_noise      each link additionally scaled by a factor drawn uniformly in [1 - x, 1 + x]
    com_offset      each link CoM moved by this distance (m) in a random direction
    torque_delay    commanded torques applied this many simulation steps late
    torque_noise    Gaussian noise (std, Nm) added to every applied torque
    joint_damping   viscous friction (Nm s/rad) on every actuated joint
    torque_bandwidth  the actuators' torque tracking as a first-order lag of this cut-off
                    frequency (Hz), exactly discretised at the simulator's step; 0: ideal
    seed            seed of the random draws above
    """

    mass_scale: float = 1.0
    mass_noise: float = 0.0
    com_offset: float = 0.0
    torque_delay: int = 0
    torque_noise: float = 0.0
    joint_damping: float = 0.0
    torque_bandwidth: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.mass_scale > 0:
            raise ValueError(f"mismatch.mass_scale must be > 0, got {self.mass_scale}")
        if not 0 <= self.mass_noise < 1:
            raise ValueError(f"mismatch.mass_noise must be in [0, 1), got {self.mass_noise}")
        for name in ("com_offset", "torque_noise", "joint_damping", "torque_bandwidth"):
            if getattr(self, name) < 0:
                raise ValueError(f"mismatch.{name} must be >= 0, got {getattr(self, name)}")
        if self.torque_delay < 0 or int(self.torque_delay) != self.torque_delay:
            raise ValueError("mismatch.torque_delay must be a whole number of steps >= 0")

    def lag_gain(self, dt: float) -> float:
        """The share of the remaining torque error the actuators close in one step of ``dt``:
        1 - exp(-2 pi f dt) (the exact discretisation of a first-order lag; 1 when ideal)."""
        if not self.torque_bandwidth:
            return 1.0
        return float(1.0 - np.exp(-2.0 * np.pi * self.torque_bandwidth * dt))

    def link_perturbations(self, n_links: int) -> tuple[np.ndarray, np.ndarray]:
        """Per-link (mass factor, CoM offset vector) drawn from ``seed``."""
        rng = np.random.default_rng(self.seed)
        factors = self.mass_scale * rng.uniform(1 - self.mass_noise, 1 + self.mass_noise, n_links)
        directions = rng.normal(size=(n_links, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        return factors, self.com_offset * directions
