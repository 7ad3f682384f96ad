"""The "full" variables of one control cycle, y = [qdd, lambda, tau] (Herzog et al. 2016, eq. 3-4).

``lambda`` stacks the forces of the *active* contacts in the order given: 3 entries for a point
contact (force), 6 for a rectangle (wrench [f; tau] about the contact frame, world axes).
"""

from __future__ import annotations

from typing import Sequence

from .robot import Robot


class Variables:
    """Sizes and slices of y = [qdd (nv), lambda (sum of contact dims), tau (na)] for a contact set."""

    def __init__(self, robot: Robot, active_contacts: Sequence[str] | None = None):
        names = robot.contact_names if active_contacts is None else tuple(active_contacts)
        for n in names:
            robot.contact(n)  # ValueError naming an unknown contact
        if len(set(names)) != len(names):
            raise ValueError(f"active_contacts: duplicate names in {list(names)}")
        self.robot = robot
        self.contacts = tuple(names)
        self.nv, self.na = robot.nv, robot.na
        self.lambda_slices: dict[str, slice] = {}
        start = 0
        for n in names:
            dim = robot.contact(n).dim
            self.lambda_slices[n] = slice(start, start + dim)
            start += dim
        self.n_lambda = start

    @property
    def n_full(self) -> int:
        """Size of y."""
        return self.nv + self.n_lambda + self.na

    def __repr__(self) -> str:
        return f"Variables(nv={self.nv}, contacts={list(self.contacts)}, na={self.na})"
