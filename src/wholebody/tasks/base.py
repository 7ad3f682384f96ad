"""Tasks and constraints as affine rows over the full variables y = [qdd, lambda, tau, aux].

Herzog et al. 2016, eqs. 3-4: every control objective and physical constraint of a cycle is an
affine function of (qdd, lambda, tau). A task fills :class:`TaskRows` from the robot's cycle cache:
an equality ``A y ≈ target`` (weighted least squares) or an inequality ``lower <= A y <= upper``,
with ``A`` given as its column blocks (any may be None = zero; ``aux`` only for a task that uses
auxiliary variables, :meth:`~wholebody.tasks.schema.KernelTask.auxiliary`). Gains, references and weights
are plain attributes: change them every cycle without rebuilding the stack.

Validated attributes. The parameters whose bad value would silently change a task's meaning (a
negative friction coefficient, a zero braking horizon, a negative gain or weight, ...) are
:class:`checked_attribute`\\ s: every assignment, in the constructor and after it
(``task.mu = -0.5``), runs the attribute's rule and raises a ValueError naming the field as
``<TaskClass>('<task name>').<attr>`` (``<TaskClass>.<attr>`` for an unnamed task) and the bad
value. Both engines (``Formulation`` and the native ``HierarchyCycle``, which packs the attributes
into its arrays) therefore only ever see valid values, and a cycle pays nothing: ``rows()`` reads
the stored value. Out of scope: arrays and dicts mutated in place (``task.kp[0] = -1``,
``task.normals["l"] = ...``) bypass the rules — assign a new object to have it checked.
References (positions, velocities, momentum targets, LQR gains K/k, force targets) are not checked
on assignment: any finite value is meaningful, and a NaN/inf ends at the formulation's boundary
check as a ValueError naming the task.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..robot import Robot
from ..validation import finite_array, number
from ..variables import Variables
from .schema import KernelTask


@dataclass
class TaskRows:
    """Rows of one task over y = [qdd (nv), lambda (n_lambda), tau (na), aux (n_aux)]."""

    qdd: np.ndarray | None
    lam: np.ndarray | None
    tau: np.ndarray | None
    target: np.ndarray | None = None  # equality rows: A y ≈ target
    lower: np.ndarray | None = None  # inequality rows: lower <= A y <= upper
    upper: np.ndarray | None = None
    tau_identity: bool = False  # tau block is the identity (lets the formulation skip a product)
    aux: np.ndarray | None = None  # over all n_aux auxiliary columns (Variables.auxiliary)

    @property
    def m(self) -> int:
        for block in (self.qdd, self.lam, self.tau, self.aux):
            if block is not None:
                return block.shape[0]
        return 0

    @property
    def is_equality(self) -> bool:
        return self.target is not None


# ------------------------------------------------------------------------- validated attributes
def field_name(obj, attr: str) -> str:
    """How errors name ``obj.attr``: ``FrictionCone('friction').mu``, or ``FrictionCone.mu`` when
    the object has no name of its own."""
    cls = type(obj).__name__
    name = obj.__dict__.get("name")
    if isinstance(name, str) and name != cls:
        return f"{cls}({name!r}).{attr}"
    return f"{cls}.{attr}"


#: A rule: (value, field name for errors, the object) -> the value to store, or ValueError.
Rule = Callable[[object, str, object], object]


class checked_attribute(property):
    """An attribute validated on every assignment: ``rule(value, field, obj)`` returns the value to
    store (e.g. a list turned into a float array) or raises a ValueError naming ``field``.

    A :class:`property` whose getter is C-level (``operator.attrgetter`` of the private slot
    ``_checked_<attr>`` in the instance's ``__dict__``), so a read in ``rows()`` costs about what
    a plain attribute does; the rule runs only on assignment. Arrays mutated in place are not
    seen (see the module docstring)."""

    def __init__(self, rule: Rule, doc: str | None = None):
        self.rule, self.doc = rule, doc
        super().__init__(None, None, None, doc)

    def __set_name__(self, owner, name: str) -> None:
        self.attr, slot, rule = name, f"_checked_{name}", self.rule

        def setter(obj, value):
            obj.__dict__[slot] = rule(value, field_name(obj, name), obj)
        super().__init__(operator.attrgetter(slot), setter, None, self.doc)
        self.__doc__ = self.doc


def _plain_float(value) -> float | None:
    """``value`` as a float if it is a Python/numpy real scalar (the fast path), else None."""
    return float(value) if isinstance(value, (float, int)) else None


def scalar_rule(*, low: float = -np.inf, high: float = np.inf, low_open: bool = False,
                high_open: bool = False, allow_inf: bool = False) -> Rule:
    """A finite float in the interval (``allow_inf``: +inf is also accepted, e.g. f_max)."""
    def rule(value, field, obj=None):
        if allow_inf and isinstance(value, float) and value == math.inf:
            return math.inf
        return number(value, field, low=low, high=high, low_open=low_open, high_open=high_open)
    return rule


def check_gain(value, field: str, size: int | None = None, matrix: bool = True,
               scalar_only: bool = False):
    """A PD gain: a finite number >= 0, ``size`` such numbers (per row), or (``matrix``) a
    ``size x size`` matrix whose symmetric part is positive semi-definite. ``size`` None: any
    size (not known before the robot is). Returns a float or a float array."""
    x = _plain_float(value)
    if x is not None and math.isfinite(x) and x >= 0.0:
        return x
    arr = finite_array(value, field)
    if arr.ndim == 0:
        return float(finite_array(value, field, nonnegative=True))
    n = size or "n"
    forms = "a number >= 0" if scalar_only else (
        f"a number >= 0, {n} numbers >= 0" + (f" or a {n}x{n} matrix" if matrix else ""))
    if not scalar_only and arr.ndim == 1 and (size is None or arr.shape == (size,)):
        return finite_array(arr, field, nonnegative=True)
    if (not scalar_only and matrix and arr.ndim == 2 and arr.shape[0] == arr.shape[1]
            and (size is None or arr.shape[0] == size)):
        sym = 0.5 * (arr + arr.T)
        eig_min = float(np.linalg.eigvalsh(sym).min()) if arr.size else 0.0
        if eig_min < -1e-12 * max(1.0, float(np.abs(arr).max()) if arr.size else 1.0):
            raise ValueError(f"{field}: a gain matrix must be positive semi-definite, got one "
                             f"whose symmetric part has the eigenvalue {eig_min:.6g}")
        return arr
    raise ValueError(f"{field}: expected {forms}, got shape {arr.shape}")


def gain_rule(size: int | None = None, matrix: bool = True, scalar_only: bool = False) -> Rule:
    """:func:`check_gain` as a rule."""
    return lambda value, field, obj=None: check_gain(value, field, size, matrix, scalar_only)


def check_weight(value, field: str, positive: bool = False):
    """A task weight: a finite number >= 0 or a vector of them (one per row); with ``positive``
    (inequality tasks, whose slacks the weight scales) > 0."""
    x = _plain_float(value)
    if x is not None and math.isfinite(x) and (x > 0.0 if positive else x >= 0.0):
        return x
    if (isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind == "f"
            and value.size <= 64):  # the fast path of per-row weights (numpy calls cost more)
        xs = value.tolist()
        low_ok = (lambda x: x > 0.0) if positive else (lambda x: x >= 0.0)
        if all(low_ok(x) and x < math.inf for x in xs):  # False for NaN
            return value
    arr = finite_array(value, field, nonnegative=True)
    if arr.ndim > 1:
        raise ValueError(f"{field}: expected a number or one number per row, got shape {arr.shape}")
    if positive and np.any(arr == 0.0):
        raise ValueError(f"{field}: an inequality task's weight must be > 0, got {value!r}")
    return float(arr) if arr.ndim == 0 else arr


def _weight_rule(value, field, obj):
    return check_weight(value, field, positive=getattr(obj, "kind", "eq") == "ineq")


def choice_rule(options: tuple) -> Rule:
    """One of ``options``."""
    def rule(value, field, obj=None):
        if not isinstance(value, str) or value not in options:
            raise ValueError(f"{field}: expected one of {options}, got {value!r}")
        return value
    return rule


def flag(value, field: str, obj=None) -> bool:
    """A bool (a string such as "no" would otherwise read as True)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{field}: expected True or False, got {value!r}")
    return bool(value)


def contact_list(value, field: str, obj=None) -> tuple[str, ...] | None:
    """None (all active contacts) or a list of contact names; an empty list means no contact (the
    task then has no rows). A bare string is an error (it would read as its characters)."""
    if value is None:
        return None
    if isinstance(value, str):
        raise ValueError(f"{field}: expected a list of contact names (None: all active contacts), "
                         f"got the string {value!r}")
    try:
        names = tuple(value)
    except TypeError:
        raise ValueError(f"{field}: expected a list of contact names (None: all active "
                         f"contacts), got {value!r}") from None
    bad = [n for n in names if not isinstance(n, str)]
    if bad:
        raise ValueError(f"{field}: expected contact names, got {bad[0]!r}")
    if len(set(names)) != len(names):
        raise ValueError(f"{field}: duplicate names in {list(names)}")
    return names


def vector_rule(size: int | None = None, optional: bool = False) -> Rule:
    """A finite 1-D float vector (of ``size`` entries if given; ``optional``: None allowed)."""
    def rule(value, field, obj=None):
        if optional and value is None:
            return None
        arr = finite_array(value, field)
        if arr.ndim != 1 or (size is not None and arr.size != size):
            raise ValueError(f"{field}: expected a vector of {size or 'any number of'} numbers, "
                             f"got shape {arr.shape}")
        return arr
    return rule


def normal_map(value, field: str, obj=None) -> dict:
    """contact name -> surface normal: finite, non-zero 3-vectors (None: none, world up)."""
    out = {}
    for name, n in dict(value or {}).items():
        entry = f"{field}[{name!r}]"
        arr = finite_array(n, entry, shape=(3,))
        if not np.linalg.norm(arr) > 0.0:
            raise ValueError(f"{entry}: a normal must be non-zero, got {n!r}")
        out[name] = arr
    return out


# ------------------------------------------------------------------------------------- tasks
class Task(KernelTask):
    """Base class: a named equality (``kind = "eq"``) or inequality (``kind = "ineq"``) task.

    ``weight``: a finite number >= 0 or one per row (> 0 for inequality tasks), checked on every
    assignment (see the module docstring)."""

    kind = "eq"
    weight = checked_attribute(_weight_rule, "Row weight(s): finite >= 0 (> 0 for inequalities).")

    def __init__(self, name: str | None = None, weight: float | np.ndarray = 1.0):
        self.name = name or type(self).__name__
        self.weight = weight

    def rows(self, robot: Robot, variables: Variables) -> TaskRows:  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


def contact_subset(variables: Variables, contacts) -> tuple[str, ...]:
    """The active contacts a task applies to: None means all active ones, an empty list none (the
    task has no rows); unknown or inactive names are errors."""
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
