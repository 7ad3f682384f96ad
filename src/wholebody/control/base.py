"""What every controller returns, and the loop shared by the quadruped controllers."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..guard import Outcome


@dataclass
class ControlResult:
    """Joint torques plus what the controller assumed (contact forces) and what happened.

    ``tau`` is finite and within the torque limits whatever happened (made by
    :func:`wholebody.guard.guard_torque`); ``outcome`` (:class:`~wholebody.guard.Outcome`) says
    what happened and ``status`` why; ``ok`` is True for a solved outcome.
    """

    tau: np.ndarray
    contact_forces: dict[str, np.ndarray] = field(default_factory=dict)
    outcome: Outcome = Outcome.SOLVED
    status: str = "solved"

    @property
    def ok(self) -> bool:
        return self.outcome.ok


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

