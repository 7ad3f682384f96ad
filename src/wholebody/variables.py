"""The "full" variables of one control cycle, y = [qdd, lambda, tau, aux] (Herzog et al. 2016,
eq. 3-4).

``lambda`` stacks the forces of the *active* contacts in the order given: 3 entries for a point
contact (force), 6 for a rectangle (wrench [f; tau] about the contact frame, world axes).
``aux`` stacks the auxiliary variables some tasks declare (:meth:`Task.auxiliary`), by name, in
the order given: e.g. the one slack per swing foot of Fahmi et al. 2019's ∞-norm swing task
(:class:`~wholebody.tasks.motion.SlackedFrameTask`). They are the last columns of the reduced
x = [qdd, lambda, aux] too.
"""

from __future__ import annotations

from typing import Mapping, Sequence

from .robot import Robot


class Variables:
    """Sizes and slices of y = [qdd (nv), lambda (sum of contact dims), tau (na), aux] for a
    contact set and a set of named auxiliary variables (name -> size; None: none)."""

    def __init__(self, robot: Robot, active_contacts: Sequence[str] | None = None,
                 auxiliary: Mapping[str, int] | None = None):
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
        #: each auxiliary variable's entries among the n_aux auxiliary columns
        self.auxiliary_slices: dict[str, slice] = {}
        start = 0
        for name, size in dict(auxiliary or {}).items():
            if not isinstance(name, str):
                raise ValueError(f"auxiliary: names must be strings, got {name!r}")
            if isinstance(size, bool) or not isinstance(size, int) or size < 1:
                raise ValueError(f"auxiliary[{name!r}]: expected a size >= 1, got {size!r}")
            self.auxiliary_slices[name] = slice(start, start + size)
            start += size
        #: (name, size) of the auxiliary variables, in column order
        self.auxiliary: tuple[tuple[str, int], ...] = tuple(
            (n, s.stop - s.start) for n, s in self.auxiliary_slices.items())
        self.n_aux = start

    def auxiliary_columns(self, names: Sequence[str], who: str) -> list[int]:
        """The auxiliary columns (0 = the first auxiliary one) of the variables ``names``, in
        order; a name the variables lack is a ValueError naming ``who`` (the task)."""
        columns = []
        for name in names:
            entries = self.auxiliary_slices.get(name)
            if entries is None:
                raise ValueError(f"{who}: no auxiliary variable named {name!r} among "
                                 f"{[n for n, _ in self.auxiliary]}")
            columns.extend(range(entries.start, entries.stop))
        return columns

    @property
    def n_full(self) -> int:
        """Size of y."""
        return self.nv + self.n_lambda + self.na + self.n_aux

    def __repr__(self) -> str:
        aux = f", auxiliary={dict(self.auxiliary)}" if self.auxiliary else ""
        return f"Variables(nv={self.nv}, contacts={list(self.contacts)}, na={self.na}{aux})"
