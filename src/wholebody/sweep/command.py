"""``wholebody sweep SCENARIO --robot R --grid key=v1,v2 ...``: many independent runs, one table.

Exit codes: 0 every run executed (``success`` in the table says which met the scenario's
criterion: a failed criterion is a result of a sweep, not an error); 1 at least one run raised
(its ``error`` column says what); 2 bad usage (unknown scenario, robot, controller or parameter, a
value out of range, bad ``--grid`` syntax, an output directory that cannot be written, Ray
missing or unreachable), always found before anything is simulated; 130 interrupted (Ctrl-C),
with the runs done by then written and ``"interrupted": true`` in sweep.json.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..interrupts import EXIT_TERMINATED, Terminated, sigterm_raises
from .executors import add_executor_options

EXIT_OK, EXIT_RUN_RAISED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``sweep`` subcommand on the CLI's subparsers."""
    p = sub.add_parser("sweep", help="run a scenario over a parameter grid (serially, on a local "
                                     "process pool or on Ray) into one table",
                       description="Run SCENARIO once per point of the --grid product (x "
                                   "--repeat) and write DIR/sweep.csv, sweep.json and sweep.png.")
    p.add_argument("scenario", help="scenario name (see `wholebody scenarios`)")
    p.add_argument("--robot", help="preset name or path to a robot .toml (default: the scenario's)")
    p.add_argument("--controller", help="controller variant (default: the scenario's first)")
    p.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="a swept parameter and its values (repeatable: the runs are the product; "
                        "separate the values with ';' if they contain commas)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a parameter fixed for every run (repeatable)")
    p.add_argument("--repeat", type=int, default=1, metavar="N",
                   help="run every grid point N times (default 1)")
    add_executor_options(p)
    p.add_argument("--metric", help="also plot this metric's mean (a column of sweep.csv)")
    p.add_argument("--out", help="output directory, checked to be writable before the runs "
                                 "(default: results/sweep-SCENARIO-ROBOT)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=command)
    return p


def _usage_error(message) -> int:
    print(f"wholebody: error: {message}", file=sys.stderr)
    return EXIT_USAGE


class _Progress:
    """A tqdm bar on stderr (runs done, failed criterion, raised), or nothing."""

    def __init__(self, total: int, enabled: bool):
        self.bar = None
        self.failed = self.raised = 0
        if enabled:
            from tqdm import tqdm
            self.bar = tqdm(total=total, desc="runs", unit="run", file=sys.stderr, leave=False)

    def update(self, row: dict) -> None:
        self.raised += row["error"] is not None
        self.failed += row["error"] is None and not row["success"]
        if self.bar is not None:
            self.bar.set_postfix(failed=self.failed, raised=self.raised, refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _write(out_dir: Path, header: dict, rows: list[dict], grid_keys: list[str],
           metric: str | None) -> list[Path]:
    from . import table

    paths = [table.write_csv(out_dir / "sweep.csv", rows, grid_keys),
             table.write_json(out_dir / "sweep.json", header, rows)]
    title = (f"{header['scenario']} on {header['robot']} ({header['controller']}), "
             f"{len(rows)} of {header['runs']} runs")
    paths.append(table.write_figure(out_dir / "sweep.png", rows, grid_keys, title, metric))
    return paths


def command(args) -> int:
    """``wholebody sweep``: validate everything, run, write the table."""
    from ..outputs import OutputInUse, claim_output, prepare_output
    from ..robots.check import load_fit_robot
    from ..scenarios import get_scenario
    from .executors import make_executor
    from ..scenarios.base import parse_sets
    from .grid import expand, parse_grid, robot_reference
    from .table import FILES

    try:  # every usage error surfaces here, before anything runs
        scenario = get_scenario(args.scenario)
        sets = parse_sets(args.set)
        grid = parse_grid(args.grid)
        controller = args.controller or scenario.controllers[0]
        robot_name = args.robot or scenario.default_robot
        scenario.resolve(sets)
        robot = load_fit_robot(robot_name)
        runs = expand(scenario, robot, robot_reference(robot_name), controller, grid, sets,
                      args.repeat)
    except (ValueError, OSError) as exc:
        return _usage_error(exc)
    try:  # Ray missing or unreachable: found before the output directory is made
        executor = make_executor(args.serial, args.workers, args.ray)
    except (ImportError, ConnectionError, ValueError) as exc:
        return _usage_error(exc)
    out_dir = (Path(args.out) if args.out else
               Path("results") / f"sweep-{scenario.name}-{robot.name}")
    try:
        if out_dir.exists() and not out_dir.is_dir():
            raise NotADirectoryError(0, "not a directory")
        lock = claim_output(out_dir)
        prepare_output(out_dir, stale=FILES)
    except OutputInUse as exc:
        executor.close()
        return _usage_error(f"--out {out_dir}: {exc.strerror}")
    except OSError as exc:
        executor.close()
        return _usage_error(f"--out {out_dir}: cannot write there ({exc.strerror or exc})")
    with lock:  # the output folder is this sweep's until it is over
        return _sweep(args, scenario, robot, controller, grid, sets, runs, executor, out_dir)


def _sweep(args, scenario, robot, controller, grid, sets, runs, executor, out_dir) -> int:
    """Run the sweep's ``runs`` on ``executor`` and write the table in ``out_dir``."""
    from .table import metric_names
    from .worker import run_one

    header = {"scenario": scenario.name, "robot": robot.name, "controller": controller,
              "grid": grid, "set": sets, "repeat": args.repeat, "runs": len(runs),
              "executor": executor.describe()}
    progress = _Progress(len(runs), not args.no_progress and sys.stderr.isatty())
    rows: list[dict] = []
    start = time.perf_counter()
    interrupted = False
    terminated = False
    try:
        with sigterm_raises(), executor:  # stopping, the executor stops its workers
            for _, row in executor.map(run_one, runs):
                rows.append(row)
                progress.update(row)
    except (KeyboardInterrupt, Terminated) as exc:
        interrupted, terminated = True, isinstance(exc, Terminated)
    finally:
        progress.close()
    elapsed = time.perf_counter() - start
    raised = [r for r in rows if r["error"] is not None]
    header.update({"completed": len(rows), "succeeded": sum(bool(r["success"]) for r in rows),
                   "raised": len(raised), "interrupted": interrupted,
                   "wall_time_s": round(elapsed, 3)})
    try:
        paths = _write(out_dir, header, rows, list(grid), args.metric)
    except OSError as exc:
        print(f"wholebody: could not write the table in {out_dir}: {exc.strerror or exc}",
              file=sys.stderr)
        return (EXIT_TERMINATED if terminated else EXIT_INTERRUPTED) if interrupted \
            else EXIT_RUN_RAISED
    written = ", ".join(str(p) for p in paths)
    if args.metric is not None and rows and args.metric not in metric_names(rows):
        print(f"wholebody: note: --metric {args.metric}: no run has that metric; metrics: "
              f"{', '.join(metric_names(rows))}", file=sys.stderr)
    if interrupted:
        how = "SIGTERM" if terminated else "Ctrl-C"
        print(f"sweep {scenario.name} on {robot.name}: INTERRUPTED ({how}) after {elapsed:.1f} "
              f"s, {len(rows)} of {len(runs)} runs done; wrote {written} (interrupted: true)",
              file=sys.stderr)
        return EXIT_TERMINATED if terminated else EXIT_INTERRUPTED
    print(f"sweep {scenario.name} on {robot.name} ({controller}): {len(runs)} runs in "
          f"{elapsed:.1f} s ({executor.describe()}): {header['succeeded']} succeeded, "
          f"{len(rows) - header['succeeded'] - len(raised)} failed the criterion, "
          f"{len(raised)} raised")
    for row in raised:
        print(f"  run {row['index']} ({' '.join(f'{k}={v}' for k, v in row['grid'].items())} "
              f"repeat={row['repeat']}): {row['error']}")
    print(f"wrote {written}")
    return EXIT_RUN_RAISED if raised else EXIT_OK
