"""The one place torques leave the library: every controller's :class:`~wholebody.formulation.Solution`
is made by :func:`guard_torque`, which returns a finite torque within the limits the controller
enforces, and the outcome of the cycle as an :class:`Outcome` with a human-readable reason.
"""

from __future__ import annotations

import enum
import logging

import numpy as np

log = logging.getLogger(__name__)

#: a torque this far (Nm) beyond a limit is out of the limits: the solvers' primal tolerances are
#: far below it, so only a wrong problem or a wrong solution gets there
LIMIT_TOLERANCE = 1e-6

_larger, _max = np.maximum, np.maximum.reduce  # both propagate NaN (np.fmax would drop it)


class Outcome(enum.Enum):
    """What one control cycle achieved (``Solution.outcome``; ``Solution.status`` says why).

    ``SOLVED``: the solver's optimum. ``FALLBACK``: the optimum found by the fallback backend
    after the first one failed. ``CLIPPED``: a solution whose torque was outside the limits (or not
    finite) and was clipped to them. ``HELD``: no solution; the torque is the controller's safe
    fallback (the previous torque or the nonlinear effects, clipped to the limits). The first two
    are successes (``Solution.ok``)."""

    SOLVED = "solved"
    FALLBACK = "solved-with-fallback"
    CLIPPED = "clipped"
    HELD = "held"

    @property
    def ok(self) -> bool:
        return self in (Outcome.SOLVED, Outcome.FALLBACK)


def guard_torque(tau: np.ndarray, lower: np.ndarray, upper: np.ndarray, outcome: Outcome,
                 reason: str) -> tuple[np.ndarray, Outcome, str]:
    """(τ, outcome, reason) with τ finite and inside [lower, upper].

    A torque of a successful cycle is clipped to the limits; if it left them by more than
    ``LIMIT_TOLERANCE`` (more than a solver's tolerance) the outcome becomes ``CLIPPED``; the torque of a failed cycle (``HELD``) is clipped as well. A
    torque with a non-finite entry is no torque at all: replaced by zero (clipped), ``HELD``.
    Limits with a NaN (a bug upstream: robot files and constructors validate them) give zero
    torque, ``HELD``."""
    if outcome.ok:  # the common case first: one pass, NaN anywhere makes ``excess`` NaN
        excess = _max(_larger(np.subtract(tau, upper), np.subtract(lower, tau)))
        if excess <= 0.0:
            return tau, outcome, reason
        if excess <= LIMIT_TOLERANCE:  # the solver's tolerance: clipped, still the optimum
            return np.clip(tau, lower, upper), outcome, reason
    if np.isnan(np.add.reduce(lower) + np.add.reduce(upper)):
        return np.zeros(np.shape(tau)), Outcome.HELD, f"{reason}; torque limits not finite: zero torque"
    if not np.isfinite(np.add.reduce(tau)):
        tau = np.zeros(np.shape(tau))
        outcome, reason = Outcome.HELD, f"{reason}; non-finite torque replaced by zero"
    elif outcome.ok:
        reason = f"torque {excess:.3g} Nm outside limits after solve; clipped"
        log.debug(reason)
        outcome = Outcome.CLIPPED
    return np.clip(tau, lower, upper), outcome, reason
