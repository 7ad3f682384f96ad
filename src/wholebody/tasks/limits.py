"""Actuation and joint limits as inequality rows."""

from __future__ import annotations

import numpy as np

from ..robot import FREE_FLYER_NQ, FREE_FLYER_NV
from .base import Task, TaskRows


class TorqueLimits(Task):
    """tau_min(q) <= tau <= tau_max(q) (Herzog et al. 2016 eq. 16; Fahmi et al. 2019 eq. 15).

    Bounds default to the robot's (joint-dependent) limits, recomputed every cycle; ``scale``
    shrinks them (a margin), ``upper_override`` replaces named joints' bound (e.g. a weak knee).
    """

    kind = "ineq"

    def __init__(self, name=None, weight=1.0, scale: float = 1.0,
                 upper_override: dict[str, float] | None = None):
        super().__init__(name, weight)
        self.scale = scale
        self.upper_override = dict(upper_override or {})

    def bounds(self, robot) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = robot.torque_bounds()
        lo, hi = lo * self.scale, hi * self.scale
        for joint, value in self.upper_override.items():
            if joint not in robot.joint_names:
                raise ValueError(f"upper_override: unknown joint '{joint}'")
            i = robot.joint_names.index(joint)
            hi[i], lo[i] = min(hi[i], value), max(lo[i], -value)
        return lo, hi

    def rows(self, robot, variables):
        lo, hi = self.bounds(robot)
        return TaskRows(qdd=None, lam=None, tau=robot.joint_selection[:, FREE_FLYER_NV:],
                        lower=lo, upper=hi,
                        tau_identity=True)


class JointAccelerationLimits(Task):
    """Joint position limits turned into joint-acceleration bounds.

    ``mode="braking"`` (Fahmi et al. 2019, eqs. 17-18): the acceleration that brings the joint from
    (q, qdot) exactly to the limit in ``horizon`` seconds (``10 dt`` in the paper) at constant
    acceleration: qdd_max = 2 (q_max - q - horizon qdot) / horizon^2, and likewise for q_min.
    (The paper prints a leading minus sign; with it the upper bound would be negative far from the
    limit, so it is read as the kinematic formula above.)

    ``mode="tanh"`` (Herzog et al. 2016, Sect. 2.1, "qdd bounds proportional to tanh of the distance
    to the limit"): qdd_max = a_max tanh(k (q_max - q)), qdd_min = a_max tanh(k (q_min - q)), i.e.
    +-a_max far from the limits, zero at the limit, pushing back beyond it.
    """

    kind = "ineq"
    MODES = ("braking", "tanh")

    def __init__(self, name=None, weight=1.0, mode: str = "braking", horizon: float = 0.01,
                 a_max: float = 200.0, steepness: float = 10.0):
        super().__init__(name, weight)
        if mode not in self.MODES:
            raise ValueError(f"mode: expected one of {self.MODES}, got '{mode}'")
        self.mode, self.horizon, self.a_max, self.steepness = mode, horizon, a_max, steepness

    def bounds(self, robot) -> tuple[np.ndarray, np.ndarray]:
        q = robot.q[FREE_FLYER_NQ:]
        qd = robot.v[FREE_FLYER_NV:]
        if self.mode == "braking":
            h = self.horizon
            return (2.0 * (robot.q_min - q - h * qd) / h ** 2,
                    2.0 * (robot.q_max - q - h * qd) / h ** 2)
        k = self.steepness
        return self.a_max * np.tanh(k * (robot.q_min - q)), self.a_max * np.tanh(k * (robot.q_max - q))

    def rows(self, robot, variables):
        lo, hi = self.bounds(robot)
        return TaskRows(qdd=robot.joint_selection, lam=None, tau=None, lower=lo, upper=hi)
