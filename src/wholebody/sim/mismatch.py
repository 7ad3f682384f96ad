"""Deliberate mismatch between the controller's model and the simulated robot (simulator side only).

Robustness is shown by controlling, with the nominal Pinocchio model, a simulated robot whose link
masses, centres of mass, actuation (delay, noise) and joint friction differ from it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

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
    under           the mismatch this one is on top of (:meth:`on_top_of`), None: the model's
    """

    mass_scale: float = 1.0
    mass_noise: float = 0.0
    com_offset: float = 0.0
    torque_delay: int = 0
    torque_noise: float = 0.0
    joint_damping: float = 0.0
    torque_bandwidth: float = 0.0
    seed: int = 0
    under: "Mismatch | None" = None

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

    def on_top_of(self, base: "Mismatch") -> "Mismatch":
        """This mismatch applied to a robot that already differs from the model by ``base`` (a
        scenario's perturbation on a real robot's, e.g. under ``--set realism=robot``): link mass
        factors multiply and CoM offsets add, each drawn from its own seed; the delays add, the
        noises' variances add, the joint dampings add; of two torque lags the slower (lower
        cut-off) is kept. The torque noise is drawn from this mismatch's seed."""
        lags = [f for f in (self.torque_bandwidth, base.torque_bandwidth) if f]
        return replace(self, torque_delay=self.torque_delay + base.torque_delay,
                       torque_noise=float(np.hypot(self.torque_noise, base.torque_noise)),
                       joint_damping=self.joint_damping + base.joint_damping,
                       torque_bandwidth=min(lags, default=0.0), under=base)

    @property
    def moves_links(self) -> bool:
        """Whether any link's mass, inertia or CoM differs from the model's (here or under)."""
        return (self.mass_scale != 1.0 or bool(self.mass_noise) or bool(self.com_offset)
                or (self.under is not None and self.under.moves_links))

    def link_perturbations(self, n_links: int) -> tuple[np.ndarray, np.ndarray]:
        """Per-link (mass factor, CoM offset vector) drawn from ``seed``, composed with those of
        the mismatch ``under`` this one (factors multiplied, offsets added)."""
        rng = np.random.default_rng(self.seed)
        factors = self.mass_scale * rng.uniform(1 - self.mass_noise, 1 + self.mass_noise, n_links)
        directions = rng.normal(size=(n_links, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        offsets = self.com_offset * directions
        if self.under is not None:
            below, moved = self.under.link_perturbations(n_links)
            factors, offsets = factors * below, offsets + moved
        return factors, offsets
