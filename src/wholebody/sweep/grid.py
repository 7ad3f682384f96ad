"""A sweep's runs: ``--grid key=v1,v2`` (repeatable) x ``--repeat N`` over ``--set`` overrides.

Every run's parameters are checked with :meth:`Scenario.validate` by :func:`expand`, before
anything is simulated; each error names the ``--grid``/``--set`` field and the value.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class SweepRun:
    """One run of a sweep: what :func:`~wholebody.sweep.worker.run_one` needs, picklable."""

    index: int  # position in grid order (the table's row order)
    scenario: str
    robot: str  # preset name or absolute path of a robot .toml
    controller: str
    overrides: dict[str, str] = field(default_factory=dict)  # --set and this point's --grid
    grid: dict[str, str] = field(default_factory=dict)  # this point's --grid values (text)
    repeat: int = 0
    #: where the run writes its summary.json and figures (``wholebody report``); None: nowhere
    out_dir: str | None = None

    def label(self) -> str:
        """``peak_force=100 location=front repeat=0``: the run, for messages."""
        parts = [f"{k}={v}" for k, v in self.grid.items()]
        return " ".join(parts + [f"repeat={self.repeat}"])


def parse_grid(texts: list[str]) -> dict[str, list[str]]:
    """``--grid key=v1,v2,...`` texts as ``{key: [v1, v2, ...]}`` in the order given.

    Values are split on ``;`` if the text has one (for list parameters whose value has commas:
    ``--grid 'forces=100,200;150,250'``), else on ``,``. ValueError naming the field for a missing
    ``=``, an empty key or value, or a key given twice."""
    grid: dict[str, list[str]] = {}
    for text in texts:
        key, sep, values = text.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--grid expects key=v1,v2,..., got '{text}'")
        if key in grid:
            raise ValueError(f"--grid {key}: given twice")
        items = [v.strip() for v in values.split(";" if ";" in values else ",")]
        if not values.strip() or any(not v for v in items):
            raise ValueError(f"--grid {key}: empty value in '{values}' (expected {key}=v1,v2,...)")
        grid[key] = items
    return grid


def robot_reference(name_or_path: str) -> str:
    """A robot argument workers can load: a preset name as it is, a file as an absolute path."""
    path = Path(name_or_path).expanduser()
    return str(path.resolve()) if path.is_file() else str(name_or_path)


#: the most runs one sweep takes (the runs are listed before the first starts)
MAX_RUNS = 100_000


def expand(scenario, robot, robot_ref: str, controller: str, grid: dict[str, list[str]],
           sets: dict[str, str] | None = None, repeat: int = 1) -> list[SweepRun]:
    """The runs of ``grid`` (first key outermost, repeats innermost) on top of ``sets``, each
    validated with ``scenario.validate(robot, overrides)``; ValueError naming the field and value
    of the first invalid one (nothing is run)."""
    sets = dict(sets or {})
    if repeat < 1:
        raise ValueError(f"--repeat: expected a whole number >= 1, got {repeat}")
    count = repeat * math.prod(len(values) for values in grid.values())
    if count > MAX_RUNS:
        raise ValueError(f"--grid/--repeat: {count} runs, more than {MAX_RUNS} (each is a "
                         f"simulation; split the sweep)")
    if controller not in scenario.controllers:
        raise ValueError(f"scenario '{scenario.name}' has no controller '{controller}'; "
                         f"controllers: {', '.join(scenario.controllers)}")
    scenario.resolve(sets)  # the --set values alone first: their errors name --set
    known = {p.name for p in scenario.parameters}
    for key, values in grid.items():
        if key in sets:
            raise ValueError(f"--grid {key}: also given with --set {key}={sets[key]}")
        if key not in known:
            raise ValueError(f"--grid {key}: scenario '{scenario.name}' has no parameter '{key}'; "
                             f"parameters: {', '.join(sorted(known)) or 'none'}")
        for value in values:  # each value on its own first: the message names it
            try:
                scenario.resolve({**sets, key: value})
            except ValueError as exc:
                raise ValueError(f"--grid {key}={value}: {exc}") from None
    runs = []
    for point in itertools.product(*grid.values()):
        values = dict(zip(grid, point))
        overrides = {**sets, **values}
        for r in range(repeat):
            run = SweepRun(len(runs), scenario.name, robot_ref, controller, overrides, values, r)
            try:
                scenario.validate(robot, overrides)
            except ValueError as exc:
                where = " ".join(f"{k}={v}" for k, v in values.items()) or "the --set values"
                raise ValueError(f"--grid {where}: {exc}") from None
            runs.append(run)
    return runs
