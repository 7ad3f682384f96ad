"""How the priority levels are solved, in one object: :class:`SolverSettings`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from numbers import Real

from .backends import BACKENDS

#: the methods of :func:`~wholebody.solvers.hierarchy.solve_hierarchy`
METHODS = ("cascade", "daqp", "weighted")


@dataclass(frozen=True)
class SolverSettings:
    """The solver of a stack's levels (Herzog et al. 2016, Sect. 2: the cascade of eqs. 8-11).

    ``method``: ``"cascade"`` (one QP per level, the reference), ``"daqp"`` (DAQP's hierarchical
    mode) or ``"weighted"`` (``[hard, objective]`` in one QP, Fahmi et al. 2019, eq. 7).
    ``backend``: the QP solver (``quadprog``, ``daqp``, ``proxsuite``); ``fallback_backend``: the
    one that solves again what ``backend`` failed on (None: none; equal to ``backend`` it is
    stored as None, there being nothing else to try). ``regularization``: ε of eq. 5, finite and
    > 0 (not used by method ``"daqp"``). ``backend_options``: ``backend``'s settings, e.g. DAQP's
    ``{"primal_tol": 1e-7}``, given as a mapping of names to numbers and stored as sorted
    ``(name, value)`` pairs, so that the settings are hashable (a control loop keeps what it
    built for them). ``analytic_first_level``: level 1 solved in closed form (Sect. 2.4, eq. 17;
    cascade only): None = when level 1 holds only dynamics and torque limits, True = required.
    ``weighted_fallback`` (method ``"weighted"``): where the single QP has no solution (the hard
    level infeasible, or the backend failed), the levels' cascade result (True, recorded in the
    solution's ``method`` and ``warnings``) or the failure itself (False: for a controller that
    holds its previous torque rather than take the cascade's compromise of the hard rows).

    A bad value raises ValueError naming the field and the value.
    """

    method: str = "cascade"
    backend: str = "daqp"
    fallback_backend: str | None = "quadprog"
    regularization: float = 1e-6
    backend_options: tuple[tuple[str, float], ...] = ()
    analytic_first_level: bool | None = None
    weighted_fallback: bool = True

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"method: expected one of {METHODS}, got {self.method!r}")
        for name, or_none in (("backend", ""), ("fallback_backend", " or None")):
            value = getattr(self, name)
            if not (isinstance(value, str) and value in BACKENDS) and not (or_none and value is None):
                raise ValueError(f"{name}: expected one of {sorted(BACKENDS)}{or_none}, "
                                 f"got {value!r}")
        if self.fallback_backend == self.backend:
            object.__setattr__(self, "fallback_backend", None)
        eps = self.regularization
        if isinstance(eps, bool) or not isinstance(eps, Real) or not (math.isfinite(eps) and eps > 0):
            raise ValueError(f"regularization: expected a finite number > 0, got {eps!r}")
        object.__setattr__(self, "regularization", float(eps))
        object.__setattr__(self, "backend_options", _options(self.backend_options))
        analytic = self.analytic_first_level
        if analytic is not None:
            if analytic not in (True, False):
                raise ValueError(f"analytic_first_level: expected None, True or False, got "
                                 f"{analytic!r}")
            object.__setattr__(self, "analytic_first_level", bool(analytic))
        if self.weighted_fallback not in (True, False):
            raise ValueError(f"weighted_fallback: expected True or False, got "
                             f"{self.weighted_fallback!r}")
        object.__setattr__(self, "weighted_fallback", bool(self.weighted_fallback))

    @property
    def options(self) -> dict:
        """``backend_options`` as a new dict (the keyword arguments of the backend)."""
        return dict(self.backend_options)


def _options(given) -> tuple:
    """``backend_options`` (a mapping, its (name, value) pairs, or None for none) → sorted
    pairs."""
    if given is None:
        return ()
    try:
        pairs = dict(given.items() if isinstance(given, Mapping) else given)
    except (TypeError, ValueError):
        raise ValueError(f"backend_options: expected a mapping of names to numbers, got "
                         f"{given!r}") from None
    for key, value in pairs.items():
        if not isinstance(key, str) or not isinstance(value, Real):
            raise ValueError(f"backend_options: expected a mapping of names to numbers, got "
                             f"{key!r}: {value!r}")
    return tuple(sorted(pairs.items()))


def settings_or_default(settings: SolverSettings | None,
                        default: SolverSettings | None = None) -> SolverSettings:
    """``settings``, or ``default`` (``SolverSettings()``) for None; ValueError for anything
    else."""
    if settings is None:
        return default if default is not None else DEFAULT
    if not isinstance(settings, SolverSettings):
        raise ValueError(f"settings: expected a SolverSettings or None, got {settings!r}")
    return settings


#: ``SolverSettings()``, the settings of a whole-body controller when none are given
DEFAULT = SolverSettings()
#: the robot-free solver's settings when none are given (:func:`~wholebody.solvers.solve_hierarchy`,
#: :class:`~wholebody.solvers.hierarchy.BoundCascade`): quadprog without a fallback, ε = 1e-4
HIERARCHY_DEFAULT = SolverSettings(backend="quadprog", fallback_backend=None, regularization=1e-4)
