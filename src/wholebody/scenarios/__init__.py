"""Registered scenarios: each experiment of the papers as a function returning a log and metrics.

Every module of this package that defines ``SCENARIO`` (a :class:`Scenario`) or ``SCENARIOS`` (a
tuple of them) is registered under the scenario's name; adding an experiment is adding a module.
"""

from __future__ import annotations

import importlib
import pkgutil

from .base import Parameter, Scenario, ScenarioResult


def _discover() -> dict[str, Scenario]:
    found: dict[str, Scenario] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        entries = getattr(module, "SCENARIOS", ())
        if hasattr(module, "SCENARIO"):
            entries = (module.SCENARIO, *entries)
        for scenario in entries:
            if scenario.name in found:
                raise RuntimeError(f"scenario '{scenario.name}' is defined twice "
                                   f"(second time in {module.__name__})")
            found[scenario.name] = scenario
    return found


SCENARIOS: dict[str, Scenario] = _discover()


class UnknownScenarioError(ValueError):
    pass


def get_scenario(name: str) -> Scenario:
    if name not in SCENARIOS:
        raise UnknownScenarioError(f"unknown scenario '{name}'; scenarios: {', '.join(SCENARIOS)}")
    return SCENARIOS[name]


__all__ = ["Parameter", "Scenario", "ScenarioResult", "SCENARIOS", "get_scenario",
           "UnknownScenarioError"]
