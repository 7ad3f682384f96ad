"""Per-cycle time of hierarchical inverse dynamics: robot update + task rows + solve + tau.

Herzog et al. 2016 Sect. 5.1: Table 2 on the 14-DoF biped (max 0.9 ms), Table 1 on a 25-DoF
humanoid (max 3 ms), and the reduced formulation ~40 % faster than the full one (Fig. 5).
This script measures the same on `talos14` (Table 2) and `talos` (Table 1, double and single
support) over a moving state, reduced vs full, per method/backend, and prints median, p95, p99, max
with the breakdown. It is a benchmark, not a test: nothing here fails on time.

Two engines (``wholebody.cycle.HierarchyCycle``): ``native`` — rigid-body terms and task rows
compiled, then the compiled cascade — and ``python`` — ``Robot.update`` + ``Formulation.solve``
(task rows in numpy, then the same compiled cascade). Same levels, same solutions
(tests/test_cycle.py).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_wbc.py [--cycles 2000] [--quick] [--passes 5]
                                                          [--engines native,python]

This machine is shared: the same code runs up to ~1.8x slower in some minutes than in others, and
single cycles stall for milliseconds when the host takes the core. Each case therefore also
times a fixed reference workload after every cycle (a matrix product and a Cholesky factor at
the cascade's sizes, a short Python loop: no wholebody code), whose median says how fast the
machine was during that case, and ``--passes N`` runs the states N times: the
first pass is what a single run sees, the per-cycle best of the N passes estimates the
uncontended time (a host stall rarely hits the same cycle twice).
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time  # noqa: E402

import numpy as np  # noqa: E402

import wholebody as wb  # noqa: E402
from wholebody.control.stacks import table1_stack, table2_stack  # noqa: E402
from wholebody.cycle import HierarchyCycle  # noqa: E402
from wholebody.solvers import SolverSettings  # noqa: E402
from wholebody.variables import Variables  # noqa: E402


def moving_states(robot, cycles: int, dt: float = 1e-3):
    """A smooth joint motion around the reference posture (q, v per cycle):
    :meth:`wholebody.Robot.smooth_motion`."""
    return robot.smooth_motion(cycles, dt)


_REFERENCE = np.random.default_rng(0).standard_normal((50, 44))


def reference_workload() -> float:
    """Seconds for a fixed workload of the cascade's kind (a 44 × 50 by 50 × 44 product and its
    Cholesky factor, a 300-step Python loop): the machine's speed at this moment."""
    t0 = time.perf_counter()
    np.linalg.cholesky(_REFERENCE.T @ _REFERENCE)
    sum(range(300))
    return time.perf_counter() - t0


def stats(samples_s) -> str:
    us = np.asarray(samples_s) * 1e6
    return (f"median {np.median(us):7.0f}  p95 {np.percentile(us, 95):7.0f}  "
            f"p99 {np.percentile(us, 99):7.0f}  max {us.max():7.0f} µs")


def run_case(robot, make_stack, contacts, reduced: bool, method: str, backend: str, cycles: int,
             fallback: str | None = None, passes: int = 1, engine: str = "python"):
    """Per-cycle times (update, rows, solve, total, of which in the QP backends) as arrays of
    shape (passes, cycles, 5), the number of failed cycles, the mean number of level QPs per
    cycle and the reference workload's times (:func:`reference_workload`, one after each
    cycle), for one HierarchyCycle engine."""
    cycle = HierarchyCycle(robot, make_stack(full=not reduced), reduced=reduced, engine=engine,
                           settings=SolverSettings(method=method, backend=backend,
                                                   fallback_backend=fallback))
    variables = Variables(robot, contacts)
    states = list(moving_states(robot, cycles))
    times = np.empty((passes, cycles, 5))
    reference = np.empty((passes, cycles))
    failures = 0
    qps = 0
    for p in range(passes):
        for i, (q, v) in enumerate(states):
            t0 = time.perf_counter()
            sol = cycle.solve(q, v, variables)
            t1 = time.perf_counter()
            failures += (not sol.ok) and p == 0
            qps += sol.timings["qps"] if p == 0 else 0
            times[p, i] = (sol.timings["update"], sol.timings["rows"], sol.timings["solve"],
                           t1 - t0, sol.timings["qp"])
            reference[p, i] = reference_workload()
    return times, failures, qps / cycles, reference


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=2000)
    parser.add_argument("--quick", action="store_true",
                        help="the controllers' default only (daqp cascade, quadprog fallback)")
    parser.add_argument("--passes", type=int, default=1,
                        help="run the states that many times, keep each cycle's fastest pass")
    parser.add_argument("--engines", default="native,python",
                        help="comma-separated HierarchyCycle engines (native, python)")
    parser.add_argument("--with-proxsuite", action="store_true",
                        help="also the ProxQP cascade (slow: up to 10k iterations and retries per QP)")
    args = parser.parse_args()
    # (method, backend, fallback backend): without a fallback a backend failure is counted as a
    # failed cycle; "daqp+quadprog" is the controllers' default (a level QP DAQP fails on is
    # solved again by quadprog, see solve_hierarchy's fallback_backend)
    combos = [("cascade", "daqp", "quadprog")] if args.quick else [
        ("cascade", "quadprog", None), ("cascade", "daqp", None), ("cascade", "daqp", "quadprog"),
        ("daqp", "daqp", None)]
    if args.with_proxsuite:
        combos.append(("cascade", "proxsuite", None))
    talos14, talos = wb.load_robot("talos14"), wb.load_robot("talos")
    cases = [
        ("talos14 Table 2 double support", talos14,
         lambda full: table2_stack(talos14, full=full), None),
        ("talos Table 1 double support", talos,
         lambda full: table1_stack(talos, talos.contact_names, full=full), None),
        ("talos Table 1 single support", talos,
         lambda full: table1_stack(talos, ["left_sole"], ["right_sole_link"], full=full),
         ["left_sole"]),
    ]
    print(f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}, {args.cycles} cycles, "
          f"{args.passes} pass(es), load average {os.getloadavg()[0]:.1f}")
    for title, robot, make_stack, contacts in cases:
        print(f"\n== {title}")
        medians = {}
        for engine in args.engines.split(","):
            for method, backend, fallback in combos:
                name = backend if fallback is None else f"{backend}+{fallback}"
                for reduced in (True, False):
                    label = f"{engine} {method}/{name} {'reduced' if reduced else 'full   '}"
                    try:
                        times, fails, qps, reference = run_case(
                            robot, make_stack, contacts, reduced, method, backend, args.cycles,
                            fallback, args.passes, engine)
                    except Exception as exc:  # a benchmark reports, it does not stop
                        print(f"{label}: error {exc}")
                        continue
                    best = times.min(axis=0)  # each cycle's fastest pass
                    upd, rows, solve, total, qp = best.T
                    medians[(engine, method, name, reduced)] = np.median(total)
                    if args.passes > 1:
                        print(f"{label:44} total {stats(times[0, :, 3])}  (first pass)")
                        label = f"  each cycle's best of {args.passes} passes"
                    print(f"{label:44} total {stats(total)}  failed {fails}")
                    in_qps = ("all levels in one QP" if np.isnan(qp).all() else
                              f"in QP backends {np.nanmedian(qp) * 1e6:4.0f}, {qps:.2f} QPs/cycle")
                    print(f"{'':44} update {np.median(upd) * 1e6:5.0f}  rows "
                          f"{np.median(rows) * 1e6:5.0f}  solve {np.median(solve) * 1e6:5.0f} "
                          f"({in_qps}) µs (medians); reference workload "
                          f"{np.median(reference) * 1e6:.0f} µs")
        for key in medians:
            engine, method, name, reduced = key
            full = medians.get((engine, method, name, False))
            if reduced and full:
                r = medians[key]
                print(f"reduced vs full ({engine} {method}/{name}): {100 * (1 - r / full):+.0f} % "
                      f"time (median ratio {r / full:.2f})")
            python = medians.get(("python", method, name, reduced))
            if engine == "native" and python:
                print(f"native vs python ({method}/{name} {'reduced' if reduced else 'full'}): "
                      f"median ratio {medians[key] / python:.2f}")


if __name__ == "__main__":
    main()
