"""Who solves the level QPs on the states a closed loop visits: every control cycle of the chosen
scenarios counted by outcome, with the level QPs handed to a backend and those DAQP did not
solve (the fuzz harness's count, :func:`fuzz.daqp_failures`). A tool, not a test.

    OPENBLAS_NUM_THREADS=1 python benchmarks/closed_loop_qps.py [push:pd push:lqr ...]
        [--set key=value ...] [--json OUT]

A run is ``SCENARIO:CONTROLLER``; the default list is every momentum-balance scenario of Herzog
et al. 2016 on its default robot, both engines for push. Each scenario's closed loop is observed
by wrapping ``run_closed_loop`` where the scenario modules use it (the scenarios are unchanged).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fuzz  # noqa: E402

from wholebody.robots import load_robot  # noqa: E402
from wholebody.scenarios import get_scenario  # noqa: E402
from wholebody.scenarios import loop  # noqa: E402

RUNS = ("push:pd", "push:lqr", "push:pd:native", "push:lqr:native", "squat:pd", "platform:pd",
        "platform:lqr", "tilt-board:pd", "tilt-board:lqr", "single-support:pd",
        "single-support:lqr", "stepping:pd")
#: the scenario modules that call run_closed_loop
MODULES = ("pushes", "platform", "single_support", "squat", "stand", "stepping", "tilt_board",
           "locomotion", "robust_push")


def observe(run: str, sets: dict[str, str]) -> dict:
    """Run ``SCENARIO:CONTROLLER[:ENGINE]`` and count its control cycles."""
    name, controller, *engine = run.split(":")
    counts = Counter()

    def counting(sim, ctrl, duration, control_period=None, progress=False, on_result=None):
        def seen(t, result):
            counts[fuzz.outcome_key(result)] += 1
            counts["level QPs"] += int(getattr(result, "timings", {}).get("qps", 0))
            counts["DAQP failed"] += fuzz.daqp_failures(result)
            if on_result is not None:
                on_result(t, result)
        return loop.run_closed_loop(sim, ctrl, duration, control_period, progress, seen)

    originals = {}
    for module in MODULES:
        m = importlib.import_module(f"wholebody.scenarios.{module}")
        if hasattr(m, "run_closed_loop"):
            originals[m] = m.run_closed_loop
            m.run_closed_loop = counting
    try:
        scenario = get_scenario(name)
        overrides = dict(sets, **({"engine": engine[0]} if engine else {}))
        result = scenario.run(load_robot(scenario.default_robot), controller, overrides)
    finally:
        for m, original in originals.items():
            m.run_closed_loop = original
    return {"run": run, "success": bool(result.success), **counts}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="*", default=list(RUNS), help="SCENARIO:CONTROLLER[:ENGINE]")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--json", metavar="OUT")
    args = parser.parse_args(argv)
    logging.getLogger("wholebody").setLevel(logging.ERROR)
    sets = dict(pair.split("=", 1) for pair in args.set)
    rows = []
    print(f"{'run':<24} {'success':>7} {'cycles':>7} {'level QPs':>9} {'by DAQP':>8}  outcomes")
    for run in args.runs:
        row = observe(run, sets)
        rows.append(row)
        outcomes = {k: v for k, v in row.items()
                    if k not in ("run", "success", "level QPs", "DAQP failed")}
        qps = row.get("level QPs", 0)
        share = f"{1 - row.get('DAQP failed', 0) / qps:.2%}" if qps else "-"
        print(f"{run:<24} {str(row['success']):>7} {sum(outcomes.values()):>7} {qps:>9} "
              f"{share:>8}  {' '.join(f'{k} {v}' for k, v in outcomes.items())}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
