"""What every controller returns, and the loop shared by the quadruped controllers."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ControlResult:
    """Joint torques plus what the controller assumed (contact forces) and whether it succeeded.

    ``ok`` False means the controller could not do what was asked; ``tau`` is still finite and within
    the torque limits, and ``status`` says why.
    """

    tau: np.ndarray
    contact_forces: dict[str, np.ndarray] = field(default_factory=dict)
    ok: bool = True
    status: str = "ok"


class PlannedController:
    """A controller driven by a gait planner: ``compute(q, v, t)`` updates the robot's cycle
    cache, asks ``self.planner`` for the plan at ``t`` (with the measured foot-frame positions)
    and returns ``self.solve(plan)``. Subclasses set ``robot`` and ``planner`` and define
    ``solve``."""

    def compute(self, q, v, t: float = 0.0):
        """Torques for the state (q, v) (Pinocchio convention) at time ``t``."""
        robot = self.robot
        robot.update(q, v)
        feet = np.array([robot.data.oMf[robot.contact(n).frame_id].translation
                         for n in self.planner.legs])
        return self.solve(self.planner.update(t, feet=feet))

