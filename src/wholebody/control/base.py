"""What every controller is (:class:`Controller`), and the loop shared by the quadruped
controllers."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from ..guard import Outcome

if TYPE_CHECKING:
    from ..formulation import Solution

log = logging.getLogger(__name__)


@runtime_checkable
class Controller(Protocol):
    """What every controller is: ``compute(q, v, t)`` turns the robot's state (Pinocchio's
    conventions) at time ``t`` into a :class:`~wholebody.formulation.Solution`, whose ``tau`` is
    finite and within the torque limits whatever happened (:func:`wholebody.guard.guard_torque`)
    and whose ``outcome`` and ``status`` say what happened."""

    def compute(self, q: np.ndarray, v: np.ndarray, t: float) -> "Solution": ...


class PlannedController:
    """A controller driven by a gait planner: ``compute(q, v, t)`` updates the robot's cycle
    cache, asks ``self.planner`` for the plan at ``t`` (with the measured foot-frame positions
    and CoM velocity, for the footholds' Raibert feedback) and returns ``self.solve(plan)``.
    Subclasses set ``robot`` and ``planner`` and define ``solve``."""

    def compute(self, q, v, t: float = 0.0):
        """Torques for the state (q, v) (Pinocchio convention) at time ``t``."""
        robot = self.robot
        robot.update(q, v)
        feet = np.array([robot.data.oMf[robot.contact(n).frame_id].translation
                         for n in self.planner.legs])
        return self.solve(self.planner.update(t, feet=feet, com_velocity=robot.vcom))



class FailureStreak:
    """The failed cycles in a row of one controller (``who`` names it in the log): :meth:`note`
    appends "(N failed cycle(s) in a row)" to the status of a ``HELD`` solution — as PassiveWBC
    does — logs one warning when a streak starts and one when the controller solves again, and
    ends the streak on the first solution that is not ``HELD``. Nothing else is kept: the next
    sane state is solved as if the streak had not happened."""

    def __init__(self, who: str):
        self.who = who
        self.count = 0  # length of the current streak of HELD cycles

    def note(self, solution):
        """``solution`` with its status extended when it is ``HELD``; the streak counted."""
        if solution.outcome is Outcome.HELD:
            self.count += 1
            if self.count == 1:
                log.warning("%s: %s", self.who, solution.status)
            solution.status = f"{solution.status} ({self.count} failed cycle(s) in a row)"
        elif self.count:
            log.warning("%s: solved again after %d failed cycles", self.who, self.count)
            self.count = 0
        return solution
