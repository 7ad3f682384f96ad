"""Interleaved A/B timing of two source trees of wholebody (not a test).

Both trees are imported in one process under different package names (``wb_a``, ``wb_b``: symlinks
made in a temporary folder) and solve the same moving states alternately, so both see the same load
on a shared machine. Prints each one's percentiles and the median of the paired per-cycle ratios.
Each tree needs its compiled modules built in place (``pip install -e`` there).

    python benchmarks/bench_ab.py A/src/wholebody B/src/wholebody --case t2|t1 \
        [--backend daqp|quadprog] [--full] [--fallback quadprog|none] [--cycles 2000]
"""
import argparse
import importlib
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ["OPENBLAS_NUM_THREADS"] = "1"
import numpy as np  # noqa: E402

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("a", type=Path, help="first package folder (…/src/wholebody)")
parser.add_argument("b", type=Path, help="second package folder (…/src/wholebody)")
parser.add_argument("--case", choices=("t2", "t1"), default="t1",
                    help="t2: talos14 Table 2; t1: talos Table 1")
parser.add_argument("--backend", default="daqp")
parser.add_argument("--full", action="store_true", help="full formulation (default: reduced)")
parser.add_argument("--fallback", default="quadprog", help="fallback backend or 'none'")
parser.add_argument("--cycles", type=int, default=2000)
args = parser.parse_args()
fallback = None if args.fallback == "none" else args.fallback
reduced = not args.full

links = Path(tempfile.mkdtemp(prefix="wholebody-ab-"))
for tag, tree in (("wb_a", args.a), ("wb_b", args.b)):
    if not (tree / "__init__.py").exists():
        parser.error(f"{tree} is not a wholebody package folder (no __init__.py)")
    (links / tag).symlink_to(tree.resolve(), target_is_directory=True)
sys.path.insert(0, str(links))

versions = {}
for tag in ("wb_a", "wb_b"):
    wb = importlib.import_module(tag)
    stacks = importlib.import_module(tag + ".control.stacks")
    formulation = importlib.import_module(tag + ".formulation")
    variables = importlib.import_module(tag + ".variables")
    robot = wb.load_robot("talos14" if args.case == "t2" else "talos")
    stack = (stacks.table2_stack(robot, full=not reduced) if args.case == "t2"
             else stacks.table1_stack(robot, robot.contact_names, full=not reduced))
    solver = ({"settings": wb.SolverSettings(backend=args.backend, fallback_backend=fallback)}
              if hasattr(wb, "SolverSettings") else  # a tree from before SolverSettings
              {"backend": args.backend, "fallback_backend": fallback})
    versions[tag] = (robot, stack, formulation.Formulation(robot, reduced=reduced),
                     variables.Variables(robot), solver)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_wbc import moving_states  # noqa: E402

states = list(moving_states(versions["wb_a"][0], args.cycles))
times = {k: np.zeros((args.cycles, 4)) for k in versions}
failures = {k: 0 for k in versions}
order = list(versions)
for i, (q, v) in enumerate(states):
    for tag in (order if i % 2 == 0 else order[::-1]):
        robot, stack, form, var, solver = versions[tag]
        t0 = time.perf_counter()
        robot.update(q, v)
        t1 = time.perf_counter()
        sol = form.solve(stack, var, diagnostics=False, **solver)
        t2 = time.perf_counter()
        times[tag][i] = (t1 - t0, sol.timings["rows"], sol.timings["solve"], t2 - t0)
        failures[tag] += not sol.ok

label = (f"{args.case} cascade/{args.backend}{'+' + fallback if fallback else ''} "
         f"{'reduced' if reduced else 'full'}")
for tag in versions:
    t = times[tag] * 1e6
    total = t[:, 3]
    print(f"{label:34} {tag[3:]:2} median {np.median(total):6.0f} p95 {np.percentile(total, 95):6.0f} "
          f"p99 {np.percentile(total, 99):6.0f} max {total.max():7.0f} | update "
          f"{np.median(t[:, 0]):4.0f} rows {np.median(t[:, 1]):4.0f} solve {np.median(t[:, 2]):5.0f}"
          f" µs | failed {failures[tag]}")
ratio = times["wb_b"][:, 3] / times["wb_a"][:, 3]
print(f"{label:34} b/a: median of paired ratios {np.median(ratio):.2f}, ratio of medians "
      f"{np.median(times['wb_b'][:, 3]) / np.median(times['wb_a'][:, 3]):.2f}   "
      f"load {os.getloadavg()[0]:.1f}")
