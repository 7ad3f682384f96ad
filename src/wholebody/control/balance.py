"""Momentum-based balance with hierarchical inverse dynamics (Herzog et al. 2016, Sects. 3 and 5.2).

The hierarchy of Table 2 (double support): (1) Newton-Euler + torque limits, (2) contact
constraints, CoP, friction, joint acceleration limits, (3) momentum control + posture + GRF
regulariser. The momentum task is either the LQR force law projected into momentum space (eq. 24,
gains from :class:`~wholebody.control.lqr.MomentumLQR` with the cost of eq. 26) or the PD law on
the momentum rate (eq. 22). The hierarchy's torques are the only command: no joint PD.
"""

from __future__ import annotations

import numpy as np

from ..formulation import Formulation, Solution
from ..robot import Robot
from ..variables import Variables
from .lqr import MomentumLQR
from .stacks import table2_stack

GAINS = ("lqr", "pd")


class MomentumBalance:
    """Balance controller: ``compute(q, v, t) -> Solution`` (tau, contact forces, diagnostics).

    ``gains`` "lqr" (eq. 24, default) or "pd" (eq. 22 with diagonal ``P``/``D``). ``com_ref``
    defaults to the CoM of the reference posture. ``backend`` picks the QP solver of the cascade.
    """

    def __init__(self, robot: Robot, gains: str = "lqr", contacts=None, com_ref=None,
                 P=None, D=None, Q=None, R=None, backend: str = "daqp"):
        if gains not in GAINS:
            raise ValueError(f"gains: expected one of {GAINS}, got '{gains}'")
        self.robot = robot
        self.gains = gains
        self.contacts = tuple(contacts or robot.contact_names)
        self.variables = Variables(robot, self.contacts)
        self.stack = table2_stack(robot, self.contacts, lqr=(gains == "lqr"))
        self.momentum = self.stack.find("momentum")
        if gains == "pd":
            if P is not None:
                self.momentum.P = np.asarray(P, dtype=float)
            if D is not None:
                self.momentum.D = np.asarray(D, dtype=float)
        self.formulation = Formulation(robot)
        self.backend = backend
        if com_ref is None:
            robot.update(robot.q_ref, np.zeros(robot.nv))
            com_ref = robot.com.copy()
        self.com_ref = np.asarray(com_ref, dtype=float)
        self.h_ref = np.zeros(6)
        self.lqr = MomentumLQR(robot, self.contacts, Q=Q, R=R) if gains == "lqr" else None
        if self.lqr is not None:
            robot.update(robot.q_ref, np.zeros(robot.nv))
            self.lqr.gains(robot, self.contacts)  # gains at the reference pose (Sect. 3.2 remark)

    def compute(self, q, v, t: float = 0.0) -> Solution:
        """Torques for the state (q, v) in Pinocchio convention."""
        robot = self.robot
        robot.update(q, v)
        if self.lqr is not None:
            K, k = self.lqr.feedback(robot, self.com_ref, self.h_ref, contacts=self.contacts)
            self.momentum.K, self.momentum.k = K, k
        else:
            self.momentum.com_ref = self.com_ref
            self.momentum.h_ref = self.h_ref
        return self.formulation.solve(self.stack, self.variables, backend=self.backend,
                                      diagnostics=False)
