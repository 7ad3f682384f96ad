"""Registered scenarios: each experiment of the papers as a function returning a log and metrics."""

from __future__ import annotations

from .base import Parameter, Scenario, ScenarioResult
from .push import SCENARIO as _PUSH
from .push_series import SCENARIO as _PUSH_SERIES
from .single_support import SCENARIO as _SINGLE_SUPPORT
from .stand import SCENARIO as _STAND

SCENARIOS: dict[str, Scenario] = {s.name: s for s in (_STAND, _PUSH, _PUSH_SERIES, _SINGLE_SUPPORT)}


class UnknownScenarioError(ValueError):
    pass


def get_scenario(name: str) -> Scenario:
    if name not in SCENARIOS:
        raise UnknownScenarioError(f"unknown scenario '{name}'; scenarios: {', '.join(SCENARIOS)}")
    return SCENARIOS[name]


__all__ = ["Parameter", "Scenario", "ScenarioResult", "SCENARIOS", "get_scenario",
           "UnknownScenarioError"]
