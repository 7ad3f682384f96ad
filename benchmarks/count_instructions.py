"""Instructions per control cycle, counted by valgrind (callgrind): a noise-free A/B measure.

Wall-clock medians on a shared 2-core machine move by ±50 % with whatever else runs; instruction
counts do not (same binary, same inputs: the same count, loaded machine or not). This script runs
each case twice under ``valgrind --tool=callgrind`` with N and 3N cycles and reports
(count(3N) − count(N)) / 2N, so imports and set-up cancel. Instructions are not seconds (cache
misses and IPC differ between parts), but a change that removes instructions from a Python-bound
cycle removes time, and the split shows where the cycle goes.

Parts per case: ``update`` (Robot.update only), ``cycle`` (update + assembly + QP + τ; for the
passive WBC its Python engine) and, for the passive WBC, ``native`` (the whole cycle with
``engine="native"``: the QP as a stack of tasks through the compiled hierarchy cycle).

    python benchmarks/count_instructions.py [--cases passive-trot,table2] [--cycles 100]

Needs valgrind (Debian package ``valgrind``). A benchmark, not a test.
"""

from __future__ import annotations

import argparse
import os
import pickle
import re
import shutil
import subprocess
import sys
import tempfile

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

CASES = ("passive-crawl", "passive-trot", "table2", "table1")
PARTS = {"passive-crawl": ("update", "cycle", "native"),
         "passive-trot": ("update", "cycle", "native"),
         "table2": ("update", "cycle"), "table1": ("update", "cycle")}


# ---------------------------------------------------------------------------- worker (in valgrind)
def worker(case: str, part: str, cycles: int, data: str) -> None:
    import numpy as np

    import wholebody as wb
    if case.startswith("passive"):
        from types import SimpleNamespace

        from wholebody.control.passive import PassiveWBC
        states = pickle.load(open(data, "rb"))
        robot = wb.load_robot("hyq")
        wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names),
                         engine="native" if part == "native" else "python")
        for k in range(cycles):
            q, v, plan = states[k % len(states)]
            if part == "update":
                robot.update(q, v)
            else:
                wbc.cycle(q, v, plan)
        return
    from wholebody.control.stacks import table1_stack, table2_stack
    from wholebody.formulation import Formulation
    from wholebody.variables import Variables
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from bench_wbc import moving_states
    robot = wb.load_robot("talos14" if case == "table2" else "talos")
    stack = table2_stack(robot) if case == "table2" else table1_stack(robot, robot.contact_names)
    formulation, variables = Formulation(robot), Variables(robot, None)
    states = list(moving_states(robot, 200))
    for k in range(cycles):
        robot.update(*states[k % len(states)])
        if part == "cycle":
            formulation.solve(stack, variables, diagnostics=False)
    del np


# ---------------------------------------------------------------------------- parent
def record_passive(gait: str, path: str, cycles: int = 300) -> None:
    """Closed-loop HyQ states (after 1.6 s, so that legs swing)."""
    import wholebody as wb
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from bench_passive import record
    robot = wb.load_robot("hyq")
    states = record(robot, gait, 400 + cycles)[400:]
    with open(path, "wb") as f:
        pickle.dump(states, f)


def count(case: str, part: str, cycles: int, data: str) -> int:
    cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable,
           os.path.abspath(__file__), "--worker", case, part, str(cycles), data]
    err = subprocess.run(cmd, capture_output=True, text=True).stderr
    found = re.search(r"Collected\s*:\s*(\d+)", err)
    if found is None:
        raise RuntimeError(f"valgrind run failed:\n{err[-2000:]}")
    return int(found.group(1))


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        case, part, cycles, data = sys.argv[2:6]
        worker(case, part, int(cycles), data)
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {CASES}")
    parser.add_argument("--cycles", type=int, default=100, help="N (runs with N and 3N cycles)")
    args = parser.parse_args()
    cases = [c for c in args.cases.split(",") if c]
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        parser.error(f"--cases: unknown {unknown}; choose from {CASES}")
    if shutil.which("valgrind") is None:
        parser.error("valgrind not found (Debian: apt-get install valgrind)")
    n = args.cycles
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            data = os.path.join(tmp, f"{case}.pkl")
            if case.startswith("passive"):
                record_passive(case.split("-")[1], data)
            per_cycle = {}
            for part in PARTS[case]:
                per_cycle[part] = (count(case, part, 3 * n, data) - count(case, part, n, data)) / (2 * n)
            line = "  ".join(f"{p} {v / 1e3:7.0f}k" for p, v in per_cycle.items())
            rest = per_cycle["cycle"] - per_cycle["update"]
            print(f"{case:14s} instructions per cycle: {line}  (rows + solve + τ {rest / 1e3:.0f}k)",
                  flush=True)


if __name__ == "__main__":
    main()
