"""Actuation and joint limits as inequality rows."""

from __future__ import annotations

import numpy as np

from ..robot import FREE_FLYER_NV
from .base import Task, TaskRows, checked_attribute, choice_rule, scalar_rule
from .schema import flag, scalar, vector


def _overrides(value, field) -> dict[str, float]:
    """joint name -> a torque cap >= 0 (inf allowed)."""
    rule = scalar_rule(low=0.0, allow_inf=True)
    out = {}
    for joint, cap in dict(value or {}).items():
        if not isinstance(joint, str):
            raise ValueError(f"{field}: expected joint names as keys, got {joint!r}")
        out[joint] = rule(cap, f"{field}[{joint!r}]")
    return out


class TorqueLimits(Task):
    """tau_min(q) <= tau <= tau_max(q) (Herzog et al. 2016 eq. 16; Fahmi et al. 2019 eq. 15).

    Bounds default to the robot's (joint-dependent) limits, recomputed every cycle; ``scale``
    shrinks them (a margin), ``upper_override`` replaces named joints' bound (e.g. a weak knee).
    Checked on every assignment: ``scale`` in (0, 1] (above 1 it would exceed the robot's limits),
    ``upper_override`` values >= 0 (inf allowed: no cap; a NaN cap would be ignored by the min).
    """

    kind = "ineq"
    scale = checked_attribute(scalar_rule(low=0.0, high=1.0, low_open=True),
                              "Factor on the robot's torque bounds, in (0, 1].")
    upper_override = checked_attribute(
        lambda value, field, obj: _overrides(value, field), "joint name -> torque cap (Nm) >= 0.")

    kernel = "torque_limits"
    params = (scalar("scale"), vector("cap", 1, "na", get=lambda t, layout, state: t.caps(layout.robot)))

    def __init__(self, name=None, weight=1.0, scale: float = 1.0,
                 upper_override: dict[str, float] | None = None):
        super().__init__(name, weight)
        self.scale = scale
        self.upper_override = upper_override

    def caps(self, robot) -> np.ndarray:
        """Per joint the cap of ``upper_override`` (inf where none; inf alone if none)."""
        if not self.upper_override:
            return np.inf
        cap = np.full(robot.na, np.inf)
        for joint, value in self.upper_override.items():
            if joint not in robot.joint_names:
                raise ValueError(f"upper_override: unknown joint '{joint}'")
            i = robot.joint_names.index(joint)
            cap[i] = min(cap[i], value)
        return cap

    def row_count(self, layout):
        return layout.robot.na

    def bounds(self, robot, q=None) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) torque bounds at configuration ``q`` (default: the robot's cached
        state)."""
        lo, hi = robot.torque_bounds(q)  # (new arrays)
        if self.scale != 1.0:  # (x * 1.0 is x: the common case skips two products)
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

    ``horizon`` (s), ``a_max`` (rad/s^2) and ``steepness`` (1/rad) must be finite and > 0, checked
    at construction and on every assignment: horizon = 0 would make the bounds +-inf (braking
    silently off), a negative one would flip their sign.
    """

    kind = "ineq"
    MODES = ("braking", "tanh")
    mode = checked_attribute(choice_rule(MODES), "'braking' or 'tanh'.")
    horizon = checked_attribute(scalar_rule(low=0.0, low_open=True), "Braking horizon (s), > 0.")
    a_max = checked_attribute(scalar_rule(low=0.0, low_open=True), "tanh amplitude (rad/s^2), > 0.")
    steepness = checked_attribute(scalar_rule(low=0.0, low_open=True), "tanh slope (1/rad), > 0.")

    kernel = "joint_acceleration_limits"
    params = (flag("tanh", get=lambda t, layout, state: t.mode == "tanh"), scalar("horizon"),
              scalar("a_max"), scalar("steepness"))

    def row_count(self, layout):
        return layout.robot.na

    def __init__(self, name=None, weight=1.0, mode: str = "braking", horizon: float = 0.01,
                 a_max: float = 200.0, steepness: float = 10.0):
        super().__init__(name, weight)
        self.mode, self.horizon, self.a_max, self.steepness = mode, horizon, a_max, steepness

    def bounds(self, robot) -> tuple[np.ndarray, np.ndarray]:
        q = robot.joint_angles(robot.q)
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
