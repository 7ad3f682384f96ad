"""Controllers: each turns a robot state into joint torques (``compute(q, v, t)``)."""

from .base import ControlResult
from .standing import StandingController

__all__ = ["ControlResult", "StandingController"]
