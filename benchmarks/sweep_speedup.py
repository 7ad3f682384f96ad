"""Wall time of a 16-run sweep serially and on the local process pool, interleaved and repeated;
prints the medians and the ratio pool / serial (target on a 2-core machine: <= 0.6). A tool, not
a test.

    OPENBLAS_NUM_THREADS=1 python benchmarks/sweep_speedup.py [--repeats 3] [--workers N]
        [--duration 4.0] [--json OUT]

The sweep is ``push --robot talos14 --grid peak_force=<8 values> --grid location=front,back``
(``--duration`` s of simulated time per run). Each pool timing includes starting the pool (its
processes import wholebody). The rows of every timing are checked equal (wall time aside). The
load average is printed before and after: on a shared machine other work competes for the cores.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

from wholebody.robots import load_robot  # noqa: E402
from wholebody.scenarios import get_scenario  # noqa: E402
from wholebody.sweep import LocalPoolExecutor, SerialExecutor, expand, run_one  # noqa: E402

FORCES = ("60", "80", "100", "120", "140", "160", "180", "200")


def _timed(executor, runs) -> tuple[float, list]:
    """Wall time of the sweep, the sum of its runs' wall times, the rows without them."""
    start = time.perf_counter()
    with executor:
        rows = sorted((row for _, row in executor.map(run_one, runs)), key=lambda r: r["index"])
    return (time.perf_counter() - start, sum(r["wall_time_s"] for r in rows),
            [{k: v for k, v in r.items() if k != "wall_time_s"} for r in rows])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, default=None, help="default: one per core")
    parser.add_argument("--duration", default="4.0", help="simulated time per run (s)")
    parser.add_argument("--json", help="write the timings here")
    args = parser.parse_args()

    scenario, robot = get_scenario("push"), load_robot("talos14")
    runs = expand(scenario, robot, "talos14", "lqr",
                  {"peak_force": list(FORCES), "location": ["front", "back"]},
                  {"duration": args.duration})
    load_before = os.getloadavg()
    print(f"{len(runs)} runs of push on talos14 ({args.duration} s each), {os.cpu_count()} cores, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}; load average "
          f"{load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f}", flush=True)
    serial, pool, reference = [], [], None
    for k in range(args.repeats):
        for label, executor, times in (("serial", SerialExecutor(), serial),
                                       ("pool", LocalPoolExecutor(args.workers), pool)):
            name = executor.describe()
            elapsed, busy, rows = _timed(executor, runs)
            reference = reference or rows
            assert rows == reference, f"{label} rows differ from the first timing's"
            times.append(elapsed)
            print(f"  repeat {k + 1}: {label:<6} {elapsed:7.1f} s  (runs' own wall time "
                  f"{busy:.1f} s; {name}; load {os.getloadavg()[0]:.2f})", flush=True)
    s, p = statistics.median(serial), statistics.median(pool)
    load_after = os.getloadavg()
    print(f"median serial {s:.1f} s, median pool {p:.1f} s, ratio pool/serial {p / s:.2f} "
          f"(target <= 0.6); rows identical; load average after {load_after[0]:.2f} "
          f"{load_after[1]:.2f} {load_after[2]:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"runs": len(runs), "duration_s": float(args.duration), "serial_s": serial,
                       "pool_s": pool, "median_serial_s": s, "median_pool_s": p,
                       "ratio": p / s, "load_before": load_before, "load_after": load_after},
                      f, indent=2)


if __name__ == "__main__":
    main()
