"""Tasks and constraints as affine rows over the full variables y = [qdd, lambda, tau].

Herzog et al. 2016, eqs. 3-4: every control objective and physical constraint of a cycle is an
affine function of (qdd, lambda, tau). A task fills :class:`TaskRows` from the robot's cycle cache:
an equality ``A y ≈ target`` (weighted least squares) or an inequality ``lower <= A y <= upper``,
with ``A`` given as its three column blocks (any may be None = zero). Gains, references and weights
are plain attributes: change them every cycle without rebuilding the stack.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot import Robot
from ..variables import Variables


@dataclass
class TaskRows:
    """Rows of one task over y = [qdd (nv), lambda (n_lambda), tau (na)]."""

    qdd: np.ndarray | None
    lam: np.ndarray | None
    tau: np.ndarray | None
    target: np.ndarray | None = None  # equality rows: A y ≈ target
    lower: np.ndarray | None = None  # inequality rows: lower <= A y <= upper
    upper: np.ndarray | None = None
    tau_identity: bool = False  # tau block is the identity (lets the formulation skip a product)

    @property
    def m(self) -> int:
        for block in (self.qdd, self.lam, self.tau):
            if block is not None:
                return block.shape[0]
        return 0

    @property
    def is_equality(self) -> bool:
        return self.target is not None


class Task:
    """Base class: a named equality (``kind = "eq"``) or inequality (``kind = "ineq"``) task."""

    kind = "eq"

    def __init__(self, name: str | None = None, weight: float | np.ndarray = 1.0):
        self.name = name or type(self).__name__
        self.weight = weight

    def rows(self, robot: Robot, variables: Variables) -> TaskRows:  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


def contact_subset(variables: Variables, contacts) -> tuple[str, ...]:
    """The active contacts a task applies to (default: all active ones); unknown names are errors."""
    if contacts is None:
        return variables.contacts
    missing = [c for c in contacts if c not in variables.lambda_slices]
    if missing:
        raise ValueError(f"contacts: {missing} are not active (active: {list(variables.contacts)})")
    return tuple(contacts)


def pd_acceleration(kp, kd, position_error, velocity_error, feedforward=0.0) -> np.ndarray:
    """Desired acceleration of a PD law: a = a_ff + Kp e + Kd ė (diagonal or full gains)."""
    def apply(gain, vec):
        gain = np.asarray(gain, dtype=float)
        return gain @ vec if gain.ndim == 2 else gain * vec
    return feedforward + apply(kp, position_error) + apply(kd, velocity_error)
