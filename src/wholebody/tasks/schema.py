"""What a task hands to its compiled kernel, declared once on the task class.

A task class with a compiled counterpart names its kernel (``kernel = "com"``) and declares its
parameters as a typed schema (``params``): each :class:`Param` has a name, a size in the robot's
or the task's own units (:class:`Size`) and a form (a vector, a diagonal gain that a scalar fills,
a rotation, a matrix). From the schema the native cycle (:mod:`wholebody.cycle`) derives where each
parameter goes in the flat parameter array and sends that layout to C++ by name; the kernel
registered under the same name (src/wholebody/native/hierarchy_cycle.cpp) checks it receives
exactly the parameters and sizes it expects. Nobody writes an offset by hand.

Besides its parameters a kernel gets the task's *selection*: named lists of integers fixed for a
layout (the active contacts it applies to, the CoM axes or frame rows it keeps, a frame's index,
a flag such as the posture's base rows), from :meth:`KernelTask.selection`. The number of rows is
:meth:`KernelTask.row_count` (the kernel counts them too; the compiled program checks they agree).

The values come from the task object every cycle (the attribute of the same name, or ``get``):
a controller keeps changing them on the task as before. The native cycle copies them with its
compiled packer (:meth:`Param.source`); :meth:`Param.assigner` is the reference for what a value
means and writes the values the packer leaves to it.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from typing import Any, Callable, Protocol, Sequence

import numpy as np

#: what a :class:`Size` may count: a fixed number, the robot's nq / na / nv, the task's contacts,
#: the sum of their wrench dimensions, the entries of its ``rows`` selection, or the entries of
#: the auxiliary variables it uses (:meth:`KernelTask.auxiliary`)
UNITS = ("", "nq", "na", "nv", "contact", "contact_dim", "rows", "auxiliary")
#: how a value becomes the parameter's entries: ``vector`` as is (a scalar fills every entry),
#: ``diagonal`` a gain given as a number or one value per entry (a matrix is refused),
#: ``matrix`` a full matrix (row-major), ``flag`` a bool as 0/1
FORMS = ("vector", "diagonal", "matrix", "flag")


@dataclass(frozen=True)
class Size:
    """``k`` entries per ``per`` (:data:`UNITS`; "" = exactly ``k``)."""

    k: int = 1
    per: str = ""

    def __post_init__(self):
        if self.per not in UNITS:
            raise ValueError(f"Size.per: expected one of {UNITS}, got {self.per!r}")

    def resolve(self, layout: "LayoutContext") -> int:
        return self.k * layout.count(self.per)


class LayoutContext:
    """What sizes and selections are resolved against: the robot, the active contacts a task
    applies to (in lambda order), the task's own ``rows`` selection and the auxiliary columns of
    the variables it uses."""

    def __init__(self, robot, contacts: Sequence[str] = (), rows: Sequence[int] = (),
                 auxiliary: Sequence[int] = ()):
        self.robot, self.contacts, self.rows = robot, tuple(contacts), tuple(rows)
        self.auxiliary = tuple(auxiliary)
        self._counts: dict[str, int] | None = None

    def count(self, unit: str) -> int:
        """How many of ``unit`` (:data:`UNITS`) the layout has (counted on first use: a task's
        checks ask every cycle)."""
        if self._counts is None:
            robot = self.robot
            self._counts = {"": 1, "nq": robot.nq, "na": robot.na, "nv": robot.nv,
                            "contact": len(self.contacts), "rows": len(self.rows),
                            "auxiliary": len(self.auxiliary),
                            "contact_dim": sum(robot.contact(n).dim for n in self.contacts)}
        return self._counts[unit]


class CycleState(Protocol):
    """The state a parameter value may read (first-use references: hold where first seen):
    :class:`wholebody.cycle.HierarchyCycle` provides it."""

    com: np.ndarray

    def frame_placement(self, frame: str) -> tuple[np.ndarray, np.ndarray]: ...
    def contact_frame_position(self, contact: str) -> np.ndarray: ...
    def joint_positions(self, joints: Sequence[str]) -> np.ndarray: ...


@dataclass(frozen=True)
class Param:
    """One parameter of a task's kernel: ``name`` (the kernel looks it up by this name),
    ``size``, ``form`` (:data:`FORMS`) and ``get`` (task, layout, state) -> value (default: the
    task's attribute ``attribute``, a dotted path through objects the task holds such as
    ``"impedance.K_x"``, read by the compiled packer without a Python call; default ``name``).

    ``mapping`` (a per-contact vector with a ``get``): the task's attribute that holds the value
    per contact (contact name -> k values, e.g. the surface normals). ``get`` stays the reference;
    the compiled packer reads the mapping itself — the layout's contacts' entries stacked,
    ``default`` for a contact it lacks — and takes ``get``'s value instead where that is not
    possible (an entry missing without a default, an entry that is not a float64 vector of k
    values, a mapping that is not a dict). So ``get`` must give that same stacking whenever it
    applies."""

    name: str
    size: Size
    form: str = "vector"
    get: Callable[[Any, LayoutContext, CycleState], Any] | None = None
    mapping: str | None = None
    default: tuple[float, ...] | None = None
    attribute: str | None = None

    def __post_init__(self):
        if self.form not in FORMS:
            raise ValueError(f"Param.form: expected one of {FORMS}, got {self.form!r}")
        if self.attribute is not None and (self.get is not None
                                           or not all(self.attribute.split("."))):
            raise ValueError(f"Param {self.name!r}: attribute is a dotted path of names, read "
                             f"instead of a get (got {self.attribute!r})")
        if self.mapping is not None and (self.get is None or self.form != "vector"
                                         or self.size.per != "contact"):
            raise ValueError(f"Param {self.name!r}: a mapping is read per contact into a vector, "
                             "with get as its reference")
        if self.default is not None and (self.mapping is None
                                         or len(self.default) != self.size.k):
            raise ValueError(f"Param {self.name!r}: default needs a mapping and {self.size.k} "
                             "values")

    def assigner(self, task, view: np.ndarray) -> Callable[[Any], None]:
        """A function that writes a value of this parameter into ``view`` (its entries). A value
        of another shape is a ValueError naming the task's field and the forms the kernel takes
        (a matrix for a ``diagonal`` gain among them: it cannot broadcast into the entries)."""
        name, form = self.name, self.form
        if form == "flag":
            def assign(value):
                view[0] = bool(value)
            return assign

        def refuse(value):
            raise ValueError(f"task '{task.name}': field '{name}' has shape {np.shape(value)}; "
                             f"the native cycle takes {'a scalar or ' if form != 'matrix' else ''}"
                             f"{view.shape[0]} values (use engine='python' for other forms)")
        if form == "matrix":
            def assign(value):
                try:
                    view[:] = np.ravel(value)
                except (ValueError, TypeError):
                    refuse(value)
        else:
            def assign(value):
                try:
                    view[:] = value
                except (ValueError, TypeError):
                    refuse(value)
        return assign

    def writer(self, task, view: np.ndarray, layout: LayoutContext,
               state: CycleState) -> Callable[[], None]:
        """A function that writes the task's current value into ``view`` (:meth:`assigner`)."""
        assign, get = self.assigner(task, view), self.get
        if get is None:
            read = operator.attrgetter(self.attribute or self.name)
            return lambda: assign(read(task))
        return lambda: assign(get(task, layout, state))

    def source(self, task, view: np.ndarray, layout: LayoutContext, state: CycleState) -> tuple:
        """This parameter of ``task`` as a source of the compiled packer
        (``wholebody._hierarchy_cycle.ParameterPacker``, which writes the common values itself and
        hands the others to :meth:`assigner`'s function)."""
        mapping = None
        if self.mapping is not None:  # (attribute, the keys in order, k, default or None)
            mapping = (self.mapping, tuple(layout.contacts), self.size.k,
                       None if self.default is None else np.array(self.default, dtype=float))
        name = (None if self.get is not None else self.name if self.attribute is None
                else tuple(self.attribute.split(".")))
        return (task, name, self.get, layout, state, view, self.form, self.assigner(task, view),
                mapping)


def scalar(name: str, get=None) -> Param:
    return Param(name, Size(1), "vector", get)


def vector(name: str, k: int = 1, per: str = "", get=None, mapping: str | None = None,
           default: tuple[float, ...] | None = None, attribute: str | None = None) -> Param:
    return Param(name, Size(k, per), "vector", get, mapping, default, attribute)


def diagonal(name: str, k: int = 1, per: str = "", get=None, attribute: str | None = None) -> Param:
    return Param(name, Size(k, per), "diagonal", get, attribute=attribute)


def matrix(name: str, k: int, per: str = "", get=None, attribute: str | None = None) -> Param:
    return Param(name, Size(k, per), "matrix", get, attribute=attribute)


def flag(name: str, get=None, attribute: str | None = None) -> Param:
    return Param(name, Size(1), "flag", get, attribute=attribute)


class KernelTask:
    """The compiled-kernel side of a task class (mixed into :class:`~wholebody.tasks.base.Task`).

    ``kernel``: the name of the compiled kernel (None: rows from Python only); ``params``: its
    schema; ``per_contact``: the task applies to a subset of the active contacts (its
    ``contacts`` attribute). A subclass that changes the rows must set ``kernel = None`` (or its
    own kernel): only the class that declares ``kernel`` runs it."""

    kernel: str | None = None
    params: tuple[Param, ...] = ()
    per_contact: bool = False

    @classmethod
    def has_kernel(cls) -> bool:
        return cls.__dict__.get("kernel") is not None

    def selection(self, robot) -> dict[str, list[int]]:
        """Named integer lists fixed for a layout (CoM axes, frame rows, joint indices, flags);
        ``rows`` also sizes parameters counted per row."""
        return {}

    def auxiliary(self) -> dict[str, int | None]:
        """The auxiliary variables the task's rows use, name -> size (None: declared by another
        task of the stack, e.g. a cost on a slack another task owns); see
        :class:`~wholebody.variables.Variables`."""
        return {}

    def layout_key(self) -> tuple:
        """What the row layout depends on besides the active contacts (hashable)."""
        return ()

    def row_count(self, layout: LayoutContext) -> int:  # pragma: no cover - per class
        raise NotImplementedError
