"""Every scenario on values drawn across its declared ranges: ``wholebody run`` ends with exit 0 or
1 and a complete summary, with 2 before anything is simulated (a refusal), or, when the run is
still simulating after :data:`BUDGET_S` simulated seconds (where this harness delivers what a
SIGTERM delivers, :class:`~wholebody.interrupts.Terminated`), with 143 and a summary marked
interrupted. Never an exception out of a scenario (a summary with an ``error``), never a
traceback, never a success without a complete summary; a value outside its range is refused
before the simulation starts.

Draws (seeded): each run sets one to three parameters of one scenario, cycling through the
scenarios. A number is drawn at a bound, just inside an open bound (tiny), uniformly, or
log-uniformly across its range (huge values where the range allows them), or at a special value;
lists get one to three such items, texts one of their choices. One draw in ten sets one value
outside its range instead. The budget keeps each run short, so tiny durations and early events
reach the code after the simulation, and long ones end through the interrupt path.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest

import wholebody as wb
from wholebody import cli
from wholebody.interrupts import Terminated
from wholebody.scenarios import SCENARIOS
from wholebody.scenarios.base import BaseHeight
from wholebody.sim.simulator import Simulator

pytestmark = pytest.mark.slow

#: simulated seconds a run may take (summed over its simulations) before the harness's SIGTERM
BUDGET_S = 0.4
DRAWS, CHUNKS = 200, 8
SEED = 20261206


@functools.cache
def _robot(name: str):
    return wb.load_robot(name)


def _resolved(bound, robot) -> float:
    return bound.value(robot) if isinstance(bound, BaseHeight) else float(bound)


def _number(p, robot, rng) -> float:
    """A value inside ``p``'s declared range."""
    low, high = _resolved(p.low, robot), _resolved(p.high, robot)
    low = low if math.isfinite(low) else -1e6
    high = high if math.isfinite(high) else 1e6
    span = high - low
    inside_low = low + (max(1e-9 * span, 1e-12) if p.low_open else 0.0)
    inside_high = high - (max(1e-9 * span, 1e-12) if p.high_open else 0.0)
    kind = rng.choice(["low", "high", "tiny", "uniform", "log"]
                      + (["special"] if p.special else []))
    if kind == "low":
        x = inside_low
    elif kind == "high":
        x = inside_high
    elif kind == "tiny":
        x = inside_low + 1e-6 * span
    elif kind == "uniform":
        x = rng.uniform(inside_low, inside_high)
    elif kind == "special":
        return float(rng.choice(p.special))
    else:
        floor = max(inside_low, 1e-6)
        x = 10.0 ** rng.uniform(math.log10(floor), math.log10(max(inside_high, floor)))
    if p.kind is int:
        x = float(min(max(math.ceil(x) if p.low_open else round(x), math.ceil(low)),
                      math.floor(high)))
    return min(max(x, inside_low), inside_high)


def _text(p, robot, rng, outside: bool = False) -> str | None:
    """``--set`` text for ``p``: inside its range, or outside it (None if it has no outside)."""
    if p.kind is bool:
        return None if outside else str(bool(rng.integers(2))).lower()
    if p.kind is str:
        if not p.choices:
            return None
        return "no-such-choice" if outside else str(rng.choice(p.choices))
    if outside:
        low, high = _resolved(p.low, robot), _resolved(p.high, robot)
        candidates = [x for x in (high + abs(high) + 1.0, low - abs(low) - 1.0,
                                  low if p.low_open else None, high if p.high_open else None)
                      if x is not None and math.isfinite(x) and x not in p.special]
        if not candidates:
            return None
        x = float(rng.choice(candidates))
        return str(int(x)) if p.kind is int and x == int(x) else repr(x)
    values = [_number(p, robot, rng) for _ in range(int(rng.integers(1, 4)) if p.items else 1)]
    return ",".join(str(int(x)) if p.kind is int else repr(float(x)) for x in values)


def _draws():
    rng = np.random.default_rng(SEED)
    names = sorted(SCENARIOS)
    for k in range(DRAWS):
        scenario = SCENARIOS[names[k % len(names)]]
        robot = _robot(scenario.default_robot)
        settable = [p for p in scenario.parameters
                    if p.name != "engine" and (p.kind is not str or p.choices)]
        chosen = rng.choice(len(settable), size=min(len(settable), int(rng.integers(1, 4))),
                            replace=False)
        wants_outside, outside = rng.random() < 0.1, False
        sets = {}
        for i, j in enumerate(chosen):
            text = _text(settable[j], robot, rng, outside=wants_outside and i == 0)
            if text is not None and settable[j].name == "workers" and not (wants_outside and i == 0):
                # one process: the budget below does not reach a pool's workers, which would
                # simulate their runs to the end (pools: test_sweep_closed_loop, test_signals)
                text = "1"
            if text is not None:
                sets[settable[j].name] = text
                outside = outside or (wants_outside and i == 0)
        yield k, scenario.name, sets, outside


@pytest.mark.parametrize("chunk", range(CHUNKS))
def test_values_across_the_declared_ranges_end_with_a_result(chunk, tmp_path, monkeypatch,
                                                             capsys):
    steps = {"n": 0}
    original_step = Simulator.step

    def step(self, *args, **kwargs):
        original_step(self, *args, **kwargs)
        steps["n"] += 1
        if steps["n"] * self.dt > BUDGET_S:
            raise Terminated()

    monkeypatch.setattr(Simulator, "step", step)
    failures = []
    for k, name, sets, outside in _draws():
        if k % CHUNKS != chunk:
            continue
        steps["n"] = 0
        out = tmp_path / f"run{k}"
        argv = ["run", name, "--no-progress", "--out", str(out)]
        for key, text in sets.items():
            argv += ["--set", f"{key}={text}"]
        try:
            code = cli.main(argv)
        except BaseException as exc:  # noqa: BLE001 (anything escaping the command is a defect)
            failures.append(f"{' '.join(argv)}: {type(exc).__name__}: {exc}")
            continue
        err = capsys.readouterr().err
        summary_path = out / "summary.json"
        summary = json.loads(summary_path.read_text()) if summary_path.exists() else None
        problem = None
        if "Traceback" in err:
            problem = "a traceback"
        elif outside and code != 2:
            problem = f"a value outside its range gave exit {code}"
        elif code == 2:
            if steps["n"]:
                problem = "refused after simulating"
        elif code in (0, 1):
            if summary is None or summary.get("completed") is not True or summary.get("error"):
                problem = f"exit {code} without a complete summary: {summary and summary.get('error')}"
            elif (code == 0) != bool(summary["success"]):
                problem = f"exit {code} but success {summary['success']}"
        elif code == 143:
            if summary is None or summary.get("interrupted") is not True:
                problem = "interrupted without a summary marked so"
        else:
            problem = f"exit {code}"
        if problem:
            failures.append(f"{' '.join(argv)}: {problem}; stderr: {err[-300:]}")
    assert not failures, "\n".join(failures)
