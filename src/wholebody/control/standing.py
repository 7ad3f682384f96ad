"""Baseline standing controller: contact-consistent gravity compensation plus joint PD.

Not a whole-body controller — it proves the closed loop. With all contacts held and q̈ = 0, the
floating-base rows of the dynamics (Herzog et al. 2016, eq. 13) fix the contact forces up to the
internal forces: ``h_b = J_{c,b}^T lambda``. The least-norm lambda is used, and the actuated rows
(eq. 14) give the compensating torques ``tau_g = h_u - J_{c,u}^T lambda``. Compensating only the
joint rows (``tau = h_u``) ignores that the contacts carry the robot and makes Talos fall in the twin.
"""

from __future__ import annotations

import numpy as np

from ..guard import Outcome, guard_torque
from ..robot import FREE_FLYER_NV, Robot
from ..tasks.base import check_gain
from ..validation import finite_array
from .base import ControlResult


class StandingController:
    """tau = h_u - J_{c,u}^T lambda + Kp (q_ref - q) - Kd qdot, saturated to the torque limits
    (outcome ``CLIPPED`` when saturated).

    ``kp``, ``kd``: a number or one per joint, finite and >= 0; ``q_ref``: a finite nq vector
    (default the robot's reference posture). Checked at construction (ValueError naming the
    argument and the bad value)."""

    def __init__(self, robot: Robot, kp: float | np.ndarray = 1000.0,
                 kd: float | np.ndarray = 30.0, q_ref: np.ndarray | None = None):
        self.robot = robot
        self.kp = np.broadcast_to(check_gain(kp, "kp", robot.na, matrix=False), robot.na).copy()
        self.kd = np.broadcast_to(check_gain(kd, "kd", robot.na, matrix=False), robot.na).copy()
        q_ref = robot.q_ref if q_ref is None else finite_array(q_ref, "q_ref", shape=(robot.nq,))
        self.q_joint_ref = q_ref[7:].copy()

    def compute(self, q, v, t: float = 0.0) -> ControlResult:
        robot = self.robot
        robot.update(q, v)
        J = robot.stacked_contact_jacobian()
        h = robot.h
        n = FREE_FLYER_NV
        # least-norm contact forces balancing the floating-base rows: J_b^T lambda = h_b
        lam, *_ = np.linalg.lstsq(J[:, :n].T, h[:n], rcond=None)
        tau = h[n:] - J[:, n:].T @ lam
        tau += self.kp * (self.q_joint_ref - robot.q[7:]) - self.kd * robot.v[n:]
        tau, outcome, status = guard_torque(tau, *robot.torque_bounds(), Outcome.SOLVED, "solved")
        forces, start = {}, 0
        for c in robot.contacts:
            forces[c.name] = lam[start:start + c.dim]
            start += c.dim
        return ControlResult(tau, forces, outcome, status)
