"""What the simulated robot stands on: floor friction, static boxes (ramps, steps), a moving platform.

These are options of the simulator only; controllers never see them (they get the terrain through
their own inputs, e.g. a friction coefficient or a surface normal).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

PoseFunction = Callable[[float], tuple[np.ndarray, np.ndarray]]
"""t -> (position (3), roll-pitch-yaw (3)) of a moving body."""


@dataclass
class Box:
    """A static box (a step, a block, or a ramp when tilted). ``rpy`` in radians."""

    center: tuple[float, float, float]
    half_size: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    friction: float | None = None  # None: the floor's

    @classmethod
    def ramp(cls, start_x: float, length: float, angle: float, width: float = 2.0,
             thickness: float = 0.1, y: float = 0.0, friction: float | None = None) -> "Box":
        """A ramp rising along +x with slope ``angle`` (rad), starting at ground level at ``start_x``."""
        c, s = np.cos(angle), np.sin(angle)
        # top surface passes through (start_x, 0); box centre is half a thickness below its middle
        cx = start_x + 0.5 * length * c + 0.5 * thickness * s
        cz = 0.5 * length * s - 0.5 * thickness * c
        return cls((cx, y, cz), (0.5 * length, 0.5 * width, 0.5 * thickness), (0.0, -angle, 0.0),
                   friction)


@dataclass
class Platform:
    """A board the robot stands on, moved by a prescribed pose trajectory (rolling platform, tilt board).

    ``motion(t)`` gives the pose of the board's top-centre relative to its initial pose (position
    offset, roll-pitch-yaw). The board is kinematic: its state is set from ``motion`` every step, so
    contacts see its true velocity.
    """

    half_size: tuple[float, float, float] = (0.5, 0.5, 0.02)
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)  # top-centre at t = 0
    motion: PoseFunction | None = None
    friction: float | None = None


@dataclass
class Environment:
    """Simulator-side world: a floor, boxes and an optional platform; friction per surface."""

    floor_friction: float = 1.0
    floor: bool = True
    boxes: list[Box] = field(default_factory=list)
    platform: Platform | None = None
    ground_height: float = 0.0

    def support_height(self) -> float:
        """Height of the surface the robot starts on (platform top if any, else the floor)."""
        if self.platform is not None:
            return float(self.platform.center[2])
        return self.ground_height
