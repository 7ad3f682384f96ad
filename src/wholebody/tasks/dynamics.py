"""Equations of motion as tasks (Herzog et al. 2016, eqs. 1 and 13)."""

from __future__ import annotations

import numpy as np

from ..robot import FREE_FLYER_NV
from .base import Task, TaskRows


class NewtonEuler(Task):
    """The 6 floating-base rows of the dynamics: M_l qdd + h_l = J_{c,l}^T lambda (eq. 13).

    The only dynamics constraint of the reduced formulation: tau is eliminated with eq. 14.
    """

    kernel = "newton_euler"

    def row_count(self, layout):
        return 6

    def rows(self, robot, variables):
        n = FREE_FLYER_NV
        J = robot.stacked_contact_jacobian(variables.contacts)
        return TaskRows(qdd=robot.M[:n], lam=-J[:, :n].T, tau=None, target=-robot.h[:n])


class FullDynamics(Task):
    """All nv rows of M qdd + h = S^T tau + J_c^T lambda (eq. 1), for the full formulation."""

    kernel = "full_dynamics"

    def row_count(self, layout):
        return layout.robot.nv

    def rows(self, robot, variables):
        J = robot.stacked_contact_jacobian(variables.contacts)
        selection = np.zeros((robot.nv, robot.na))
        selection[FREE_FLYER_NV:] = np.eye(robot.na)
        return TaskRows(qdd=robot.M, lam=-J.T, tau=-selection, target=-robot.h)
