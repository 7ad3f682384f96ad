"""The one place torques leave the library: every controller's :class:`~wholebody.formulation.Solution`
is made by :func:`guard_torque`, which returns a finite torque within the limits the controller
enforces, and the outcome of the cycle as an :class:`Outcome` with a human-readable reason.
"""

from __future__ import annotations

import enum
import logging

import numpy as np

log = logging.getLogger(__name__)

#: a torque beyond a limit by more than this share of the limit's magnitude (and by more than this
#: many Nm for a limit under 1 Nm) is out of the limits: the solvers' primal tolerances are below
#: it, so only a wrong problem or a wrong solution gets there. Within it the torque is the
#: solver's optimum, clipped onto the limit (a 300 N m knee 2e-5 N m over is not a failed cycle)
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
        return self in _SUCCESSES


#: the outcomes that are successes (a module tuple: reading an Enum member from its class is slow,
#: and ``ok`` runs every cycle)
_SUCCESSES = (Outcome.SOLVED, Outcome.FALLBACK)


def guard_torque(tau: np.ndarray, lower: np.ndarray, upper: np.ndarray, outcome: Outcome,
                 reason: str, excess: float | None = None) -> tuple[np.ndarray, Outcome, str]:
    """(τ, outcome, reason) with τ finite and inside [lower, upper].

    A torque of a successful cycle is clipped to the limits; if it left them by more than
    ``LIMIT_TOLERANCE`` relative to the bound (more than a solver's tolerance) the outcome
    becomes ``CLIPPED``; the torque of a failed cycle (``HELD``) is clipped as well. A
    torque with a non-finite entry is no torque at all: replaced by zero (clipped), ``HELD``.
    Limits with a NaN (a bug upstream: robot files and constructors validate them) give zero
    torque, ``HELD``. ``excess``: max(τ − upper, lower − τ), NaN if anything is not finite,
    where the caller computed it already (the compiled cycle does)."""
    if outcome in _SUCCESSES:  # the common case first: one pass, NaN anywhere makes ``excess`` NaN
        if excess is None:
            excess = _max(_larger(np.subtract(tau, upper), np.subtract(lower, tau)))
        if excess <= 0.0:
            return tau, outcome, reason
        if excess <= LIMIT_TOLERANCE or _within_tolerance(tau, lower, upper):
            return np.clip(tau, lower, upper), outcome, reason  # still the optimum
    if np.isnan(np.add.reduce(lower) + np.add.reduce(upper)):
        return np.zeros(np.shape(tau)), Outcome.HELD, f"{reason}; torque limits not finite: zero torque"
    if not np.isfinite(np.add.reduce(tau)):
        tau = np.zeros(np.shape(tau))
        outcome, reason = Outcome.HELD, f"{reason}; non-finite torque replaced by zero"
    elif outcome in _SUCCESSES:
        joint = int(np.argmax(np.maximum(np.subtract(tau, upper), np.subtract(lower, tau))))
        reason = (f"torque {excess:.3g} Nm outside limits after solve (joint {joint}); "
                  f"clipped")
        log.debug(reason)
        outcome = Outcome.CLIPPED
    return np.clip(tau, lower, upper), outcome, reason


def _within_tolerance(tau, lower, upper) -> bool:
    """Every entry of ``tau`` within ``LIMIT_TOLERANCE`` x max(1, |bound|) of its bounds (NaN:
    not within)."""
    scale_hi = np.maximum(1.0, np.abs(upper))
    scale_lo = np.maximum(1.0, np.abs(lower))
    worst = _max(_larger(np.subtract(tau, upper) / scale_hi, np.subtract(lower, tau) / scale_lo))
    return bool(worst <= LIMIT_TOLERANCE)
