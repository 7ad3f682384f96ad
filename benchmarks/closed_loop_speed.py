"""How fast the closed loop runs: simulated time over wall time for a fixed list of scenario runs
on their defaults, and (``--profile``) where the wall time goes. A benchmark, not a test.

    OPENBLAS_NUM_THREADS=1 python benchmarks/closed_loop_speed.py [--repeats 3] [--runs push:pd,...]
        [--profile] [--top 25] [--metrics OUT.json] [--compare BEFORE.json]

Each run is ``SCENARIO[:CONTROLLER][@ROBOT][+key=value...]`` as ``wholebody run`` would do it
(``Scenario.run`` without an output directory: no figures, no summary file). Simulated time is
counted by a :class:`~wholebody.sim.simulator.SimObserver` (steps x dt over every simulation the
scenario makes); wall time is that of ``Scenario.run`` (the robot is loaded before). For each run
the median, the fastest and the slowest of ``--repeats`` runs are printed, the real-time factor
(simulated / wall) of the median, and where the median run's wall time went: ``physics`` (inside
MuJoCo's ``mj_step``, timed through a stand-in for the simulator's ``mujoco`` module), ``ctrl``
(from the end of a step to the controller's result reaching the observers: reading the state and
``compute``) and ``rest`` (the simulator's per-step work, the scenario's measures and logs); the
physics-only real-time factor (simulated / physics) bounds what any loop around it can reach. ``--profile`` adds one run under cProfile per scenario and prints
its top functions by cumulative and by own time. ``--metrics`` writes each run's summary metrics
(the first repeat's); ``--compare`` reads such a file and prints, per run, the largest difference
of any metric but the controller's own wall-clock times (absolute and relative), so that a change
meant to leave the results unchanged can be checked.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import cProfile  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import math  # noqa: E402
import pstats  # noqa: E402
import re  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import wholebody.sim.simulator as simulator_module  # noqa: E402
from wholebody.robots.check import load_fit_robot  # noqa: E402
from wholebody.scenarios import get_scenario  # noqa: E402
from wholebody.scenarios.base import _jsonable  # noqa: E402

RUNS = ("push:pd", "push:lqr", "stand", "crawl", "crawl+gait=trot", "walk")


class TimedPhysics:
    """Stands for the ``mujoco`` module in the simulator: every ``mj_step`` timed (``seconds``,
    and when the last one ended), everything else MuJoCo's."""

    def __init__(self, module):
        self._module = module
        self.seconds = 0.0
        self.last_end = None

    def __getattr__(self, name):
        return getattr(self._module, name)

    def mj_step(self, *args):
        start = time.perf_counter()
        self._module.mj_step(*args)
        self.last_end = time.perf_counter()
        self.seconds += self.last_end - start


class StepCounter:
    """A SimObserver that adds up the simulated time of every simulation it watches, and the wall
    time from the end of the last physics step to each controller result (``controller``)."""

    def __init__(self, physics: TimedPhysics):
        self.simulated = 0.0
        self.controller = 0.0
        self.physics = physics

    def start(self, sim) -> None:
        self.physics.last_end = None

    def step(self, sim) -> None:
        self.simulated += sim.dt

    def controller_result(self, sim, result) -> None:
        if self.physics.last_end is not None:
            self.controller += time.perf_counter() - self.physics.last_end


def parse_run(text: str) -> tuple[str, str | None, str | None, dict[str, str]]:
    """``SCENARIO[:CONTROLLER][@ROBOT][+key=value...]`` -> (scenario, controller, robot, sets)."""
    head, *sets = text.split("+")
    overrides = dict(s.split("=", 1) for s in sets)
    head, _, robot = head.partition("@")
    scenario, _, controller = head.partition(":")
    return scenario, controller or None, robot or None, overrides


def run_once(text: str, profile: cProfile.Profile | None = None):
    """(simulated s, wall s, metrics, physics s, controller s) of one run of ``text``."""
    name, controller, robot_name, overrides = parse_run(text)
    scenario = get_scenario(name)
    robot = load_fit_robot(robot_name or scenario.default_robot)
    physics = TimedPhysics(simulator_module.mujoco)
    counter = StepCounter(physics)
    simulator_module.mujoco = physics
    try:
        start = time.perf_counter()
        if profile is not None:
            profile.enable()
        result = scenario.run(robot, controller, overrides, None, False, observers=(counter,))
        if profile is not None:
            profile.disable()
        wall = time.perf_counter() - start
    finally:
        simulator_module.mujoco = physics._module
    return counter.simulated, wall, _jsonable(result.metrics), physics.seconds, counter.controller


def _numbers(value, prefix=""):
    """(key, float) for every number in a nested metrics dict/list."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _numbers(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _numbers(v, f"{prefix}[{i}]")
    elif isinstance(value, bool) or value is None:
        yield prefix, value
    elif isinstance(value, (int, float)):
        yield prefix, float(value)


#: metrics that are wall-clock times of the controller (they differ from run to run)
WALL_CLOCK = re.compile(r"cycle_time|controller_cycle|_us$|_ms$")


def compare(before: dict, after: dict) -> tuple[float, float, str, list[str]]:
    """(largest absolute difference, largest relative difference, its key, keys that differ in
    kind: missing, or booleans/None that changed) between two metrics dicts, leaving out the
    controller's wall-clock times (:data:`WALL_CLOCK`)."""
    a, b = ({k: v for k, v in _numbers(m) if not WALL_CLOCK.search(k)} for m in (before, after))
    worst_abs = worst_rel = 0.0
    worst_key = ""
    odd = sorted(set(a) ^ set(b))
    for key in set(a) & set(b):
        x, y = a[key], b[key]
        if not isinstance(x, float) or not isinstance(y, float):
            if x != y:
                odd.append(key)
            continue
        if math.isnan(x) and math.isnan(y):
            continue
        diff = abs(x - y)
        rel = diff / max(abs(x), abs(y), 1e-300) if diff else 0.0
        if diff > worst_abs:
            worst_abs = diff
        if rel > worst_rel:
            worst_rel, worst_key = rel, key
    return worst_abs, worst_rel, worst_key, odd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", default=",".join(RUNS), help="comma-separated runs")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--profile", action="store_true", help="one more run under cProfile")
    parser.add_argument("--top", type=int, default=25, help="functions listed by --profile")
    parser.add_argument("--metrics", help="write the runs' metrics (JSON) here")
    parser.add_argument("--compare", help="compare the metrics with those of this file")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    runs = [r for r in args.runs.split(",") if r]
    reference = json.loads(open(args.compare).read()) if args.compare else {}
    metrics = {}
    print(f"{'run':<22} {'sim s':>7} {'wall s median':>14} {'min':>7} {'max':>7} {'x real time':>12}"
          f" | {'physics':>7} {'ctrl':>5} {'rest':>5} {'x physics only':>15}")
    for text in runs:
        walls, parts, simulated = [], [], 0.0
        for k in range(args.repeats):
            simulated, wall, m, physics, controller = run_once(text)
            walls.append(wall)
            parts.append((wall, physics, controller))
            if k == 0:
                metrics[text] = m
        median = statistics.median(walls)
        wall, physics, controller = sorted(parts)[(len(parts) - 1) // 2]  # the median run's
        rest = wall - physics - controller
        print(f"{text:<22} {simulated:>7.2f} {median:>14.3f} {min(walls):>7.3f} {max(walls):>7.3f} "
              f"{simulated / median:>12.2f} | {physics / wall:>7.0%} {controller / wall:>5.0%} "
              f"{rest / wall:>5.0%} {simulated / physics:>15.1f}", flush=True)
        if text in reference:
            worst_abs, worst_rel, key, odd = compare(reference[text], metrics[text])
            print(f"    vs {args.compare}: max |diff| {worst_abs:.3g}, max relative {worst_rel:.3g}"
                  f"{f' ({key})' if key else ''}" + (f"; differ: {odd}" if odd else ""))
        if args.profile:
            profile = cProfile.Profile()
            run_once(text, profile)
            for order in ("cumulative", "tottime"):
                out = io.StringIO()
                pstats.Stats(profile, stream=out).strip_dirs().sort_stats(order).print_stats(
                    args.top)
                print(f"--- {text}: top {args.top} by {order}")
                print("\n".join(line for line in out.getvalue().splitlines()[4:] if line.strip()))
    if args.metrics:
        with open(args.metrics, "w") as f:
            json.dump(metrics, f, indent=1)


if __name__ == "__main__":
    main()
