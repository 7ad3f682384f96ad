"""Command line: ``wholebody robots | check-robot ROBOT | init-robot MODEL | scenarios |
run SCENARIO | sweep | report``.

Exit codes: 0 success; 1 the scenario ran but did not meet its success criterion; 2 bad usage
(unknown robot, scenario, controller or parameter; a parameter value outside its declared range;
malformed robot file; an output directory that cannot be written), always found before anything
is simulated; 130 interrupted (Ctrl-C), with a summary.json marked ``"interrupted": true``. A
simulation that diverges ends the run with exit 1 and a summary naming the time
(``metrics.diverged_at_s``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import sys
import time
from pathlib import Path

from . import __version__
from .interrupts import EXIT_TERMINATED, Terminated, sigterm_raises

EXIT_OK, EXIT_SCENARIO_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130

log = logging.getLogger("wholebody.cli")


def _usage_error(exc: Exception) -> int:
    print(f"wholebody: error: {exc}", file=sys.stderr)
    return EXIT_USAGE


def _cmd_robots(args) -> int:
    from .robots import load_robot, preset_names

    rows = [load_robot(name).summary() for name in preset_names()]
    if args.json:
        print(json.dumps(rows, indent=2))
        return EXIT_OK
    print(f"{'robot':<10} {'DoF':>4} {'mass (kg)':>10}  contacts")
    for r in rows:
        print(f"{r['name']:<10} {r['actuated_dof']:>4} {r['mass_kg']:>10.1f}  "
              f"{', '.join(r['contacts'])}")
    return EXIT_OK


def _cmd_check_robot(args) -> int:
    from .robots.check import check_robot

    _note_drafted(args.robot)
    report = check_robot(args.robot)
    if args.json:
        print(json.dumps(report.as_dict(), indent=2))
        return EXIT_OK if report.ok else EXIT_USAGE
    f = report.facts
    if f:
        print(f"{f['name']}: {f['actuated_dof']} actuated DoF, {f['mass_kg']:.2f} kg, base "
              f"{f['standing_base_height_m']:.3f} m above the floor standing, friction "
              f"{f['friction']:g}")
        margin = f.get("com_support_margin_m")  # none when the contacts span no support area
        support = ("no support polygon" if margin is None
                   else f"CoM {1000 * margin:.0f} mm inside the support polygon")
        print(f"  {support}; holding the posture takes "
              f"{100 * f['holding_torque_max_fraction_of_limit']:.0f} % of the nearest torque limit")
    for c in report.contacts:
        size = (f"radius {c['radius_m']:g} m" if c["type"] == "point"
                else f"{2 * c['half_size_m'][0]:g} x {2 * c['half_size_m'][1]:g} m")
        where = f", {round(1000 * c['height_above_floor_m'], 1) + 0.0:.1f} mm above the floor"
        tilt = f", tilted {c['tilt_deg']:.1f} deg" if "tilt_deg" in c else ""
        offset = (f" + [{', '.join(f'{x:g}' for x in c['offset_m'])}] m" if any(c["offset_m"])
                  else "")
        print(f"  contact {c['name']} ({c['role'] or 'no role'}): {c['type']} on frame "
              f"'{c['frame']}'{offset}, {size}{where}{tilt}; leg: "
              f"{', '.join(c['leg_joints']) or '-'}")
    for finding in report.findings:  # errors on stderr, the report on stdout
        print(f"  {finding.level}: {finding.topic}: {finding.message}" +
              (f"\n    fix: {finding.fix}" if finding.fix else ""),
              file=sys.stderr if finding.level == "error" else sys.stdout)
    if report.ok:
        print(f"{report.source}: OK")
        return EXIT_OK
    errors = sum(f.level == "error" for f in report.findings)
    print(f"wholebody: error: {report.source}: {errors} error(s) (above)", file=sys.stderr)
    return EXIT_USAGE


def _note_drafted(robot: str | None) -> None:
    """Say so when ``--robot``/``check-robot`` is given a model file instead of a description."""
    from .robots import is_model_file

    if robot and is_model_file(robot):
        print(f"note: {robot} is a model file, not a description: using the description "
              f"`wholebody init-robot {robot}` drafts (its guesses unchecked); write it to a "
              f"file with --out to check and edit it", file=sys.stderr)


def _cmd_init_robot(args) -> int:
    from .robots.description import DescriptionError
    from .robots.draft import draft_description

    model = Path(args.model)
    if not model.is_file():
        return _usage_error(ValueError(f"init-robot: model file not found: {model}"))
    out = Path(args.out) if args.out else None
    if out is not None and out.exists() and not args.force:
        return _usage_error(ValueError(f"init-robot: --out {out} exists; pass --force to "
                                       f"overwrite it"))
    started = time.perf_counter()
    try:
        draft = draft_description(model, args.name)
    except (DescriptionError, ValueError, OSError) as exc:
        return _usage_error(exc)
    if out is None:
        print(draft.text, end="")
    else:
        try:
            out.write_text(draft.text)
        except OSError as exc:
            return _usage_error(ValueError(f"init-robot: cannot write --out {out}: "
                                           f"{exc.strerror or exc}"))
    stream = sys.stderr if out is None else sys.stdout
    print(f"drafted '{draft.data['name']}' from {model} in {time.perf_counter() - started:.1f} s"
          + (f": wrote {out}" if out else ""), file=stream)
    print(f"  {len(draft.data['contacts'])} contact(s): "
          + ", ".join(f"{c['name']} ({c['type']} on {c['frame']})" for c in draft.data["contacts"]),
          file=stream)
    for note in draft.notes:
        print(f"  check: {note}", file=stream)
    print(f"  next: wholebody check-robot {out or 'FILE.toml'}", file=stream)
    return EXIT_OK


def _cmd_scenarios(args) -> int:
    from .scenarios import SCENARIOS
    from .scenarios.base import BASE_HEIGHT_LEGEND, RobotRelative

    if args.json:
        if args.name is not None and args.name not in SCENARIOS:
            return _usage_error(ValueError(f"unknown scenario '{args.name}'; scenarios: "
                                           f"{', '.join(SCENARIOS)}"))
        print(json.dumps({s.name: {"summary": s.summary, "controllers": list(s.controllers),
                                   "default_robot": s.default_robot,
                                   "parameters": {p.name: _parameter_json(p)
                                                  for p in s.parameters}}
                          for s in SCENARIOS.values()
                          if args.name in (None, s.name)}, indent=2))
        return EXIT_OK
    chosen = list(SCENARIOS.values())
    if args.name is not None:
        if args.name not in SCENARIOS:
            return _usage_error(ValueError(f"unknown scenario '{args.name}'; scenarios: "
                                           f"{', '.join(SCENARIOS)}"))
        chosen = [SCENARIOS[args.name]]
    relative = False
    for s in chosen:
        print(f"{s.name}  (robot {s.default_robot}; controllers: {', '.join(s.controllers)})")
        print(f"    {s.summary}")
        for p in s.parameters:
            setting = f"--set {p.name}={p.default_text()}"
            accepted = p.describe()
            print(f"    {setting:<32} {p.help}" + (f"; {accepted}" if accepted else ""))
            relative |= p.robot_relative or isinstance(p.default, RobotRelative)
    if relative:
        print(BASE_HEIGHT_LEGEND)
    return EXIT_OK


def _parameter_json(p) -> dict:
    """One parameter for ``scenarios --json``: default (a value, or for a robot-relative one its
    data, e.g. ``{"base_height": factor}``), help, and what it accepts."""
    from .scenarios.base import RobotRelative

    default = p.default.as_data() if isinstance(p.default, RobotRelative) else p.default
    out = {"default": default, "help": p.help, "type": p.kind.__name__}
    if p.items is not None:
        out["list"] = True  # comma-separated items of that type
    if p.numeric:  # "(0, 600]", "[0, 0.5 h]" (h: the robot's standing base height), and as data
        out["range"] = p.range_text()
        out["bounds"] = p.bounds()
    if p.choices:
        out["choices"] = list(p.choices)
    return out


def _print_metrics(metrics: dict, indent: int) -> None:
    """Metrics one per line; nested tables indented, floats to 4 significant digits."""
    pad = " " * indent
    for key, value in metrics.items():
        if isinstance(value, dict) and any(isinstance(v, dict) for v in value.values()):
            print(f"{pad}{key}:")
            _print_metrics(value, indent + 2)
            continue
        if isinstance(value, dict):
            value = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                              for k, v in value.items())
        elif isinstance(value, float):
            value = f"{value:.4g}"
        print(f"{pad}{key}: {value}")


def _report_cut_short(result, out_dir: Path, what: str, mark: str = "") -> None:
    """Write the summary of a run that ended early and say so on stderr (also if it cannot be
    written)."""
    try:
        written = f"wrote {result.write(out_dir)}{mark}"
    except OSError as exc:
        written = f"could not write {out_dir / 'summary.json'}: {exc.strerror or exc}"
    print(f"{result.scenario} on {result.robot} ({result.controller}): {what}; {written}",
          file=sys.stderr)


def _cmd_run(args) -> int:
    with contextlib.ExitStack() as held:  # the output directory's lock, until the run is over
        return _run(args, held)


def _run(args, held: contextlib.ExitStack) -> int:
    from .outputs import OutputInUse, claim_output, prepare_output
    from .robots.check import load_fit_robot
    from .scenarios import get_scenario
    from .scenarios.base import ScenarioResult, parse_sets
    from .sim.plant import PlantError, check_plant, plant_label, with_plant
    from .sim.simulator import SimulationDiverged

    try:  # every usage error surfaces here, before anything runs
        scenario = get_scenario(args.scenario)
        overrides = parse_sets(args.set)
        scenario.resolve(overrides)
        if args.controller and args.controller not in scenario.controllers:
            raise ValueError(f"scenario '{scenario.name}' has no controller '{args.controller}'; "
                             f"controllers: {', '.join(scenario.controllers)}")
        _note_drafted(args.robot)
        robot = load_fit_robot(args.robot or scenario.default_robot)
        if args.plant:
            robot = with_plant(robot, args.plant)
        check_plant(robot)  # the description's or --plant's file: mapped before anything runs
        params = scenario.validate(robot, overrides)
        _check_observed(args, scenario, params)
    except PlantError as exc:  # named as given: the flag, or the description's field
        return _usage_error(ValueError(f"--plant {args.plant}: {exc.reason}") if args.plant
                            else exc)
    except (ValueError, OSError) as exc:
        return _usage_error(exc)
    out_dir = Path(args.out) if args.out else Path("results") / f"{scenario.name}-{robot.name}"
    try:
        if out_dir.exists() and not out_dir.is_dir():
            raise NotADirectoryError(0, "not a directory")
        held.enter_context(claim_output(out_dir))
        prepare_output(out_dir, stale=("summary.json",))
    except OutputInUse as exc:
        return _usage_error(f"--out {out_dir}: {exc.strerror}")
    except OSError as exc:
        return _usage_error(f"--out {out_dir}: cannot write there ({exc.strerror or exc})")
    controller = args.controller or scenario.controllers[0]
    recorder, view = _observers(args, out_dir)
    observers = [o for o in (recorder, view) if o is not None]
    start = time.perf_counter()
    try:
        with sigterm_raises():
            result = scenario.run(robot, controller, overrides, out_dir,
                                  progress=not args.no_progress and sys.stderr.isatty(),
                                  **({"observers": observers} if observers else {}))
    except (KeyboardInterrupt, Terminated) as exc:
        elapsed = time.perf_counter() - start
        how = "SIGTERM" if isinstance(exc, Terminated) else "Ctrl-C"
        cut = ScenarioResult(scenario.name, robot.name, controller, False, {}, params,
                             [f"interrupted ({how}) after {elapsed:.1f} s of wall time; no "
                              f"metrics or figures"], wall_time_s=elapsed, interrupted=True,
                             plant=plant_label(robot))
        _report_cut_short(cut, out_dir, f"INTERRUPTED ({how}) after {elapsed:.1f} s",
                          " (interrupted: true)")
        return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
    except SimulationDiverged as exc:
        failed = ScenarioResult(scenario.name, robot.name, controller, False,
                                {"diverged_at_s": exc.t}, params, [str(exc)],
                                wall_time_s=time.perf_counter() - start,
                                plant=plant_label(robot))
        failed.incidents = exc.incidents
        _print_incidents(failed.incidents)
        _report_cut_short(failed, out_dir, f"FAILED: {exc}")
        _write_replay(recorder, f"{scenario.name} on {robot.name} ({controller}): diverged",
                      out_dir, failed.incidents)
        return EXIT_SCENARIO_FAILED
    except Exception as exc:  # an error in the scenario: the run still ends with its summary
        log.debug("the scenario raised", exc_info=True)
        error = f"{type(exc).__name__}: {exc}"
        failed = ScenarioResult(scenario.name, robot.name, controller, False, {}, params,
                                [f"the run ended with an error, no metrics: {error} (run with -v "
                                 f"for the traceback)"],
                                wall_time_s=time.perf_counter() - start, error=error,
                                plant=plant_label(robot))
        _report_cut_short(failed, out_dir, f"ERROR: {error}", " (completed: false)")
        return EXIT_SCENARIO_FAILED
    finally:
        if view is not None:
            view.close()
    status = "SUCCESS" if result.success else "FAILED"
    print(f"{scenario.name} on {robot.name} ({result.controller}): {status} "
          f"in {result.wall_time_s:.1f} s")
    print(f"  plant: {result.plant}")
    print(f"  realism: {result.realism}")
    metrics = dict(result.summary()["metrics"])
    claim = metrics.pop("claim", None)
    _print_metrics(metrics, indent=2)
    if isinstance(claim, dict) and "holds" in claim:
        print(_claim_verdict(claim))
    for note in result.notes:
        print(f"  note: {note}")
    if not result.success:
        _print_incidents(result.incidents)
    print(f"wrote {out_dir / 'summary.json'}" +
          (f" and {len(result.figures)} figure(s)" if result.figures else ""))
    _write_replay(recorder, f"{scenario.name} on {robot.name} ({controller}): {status}", out_dir,
                  result.incidents, result.summary())
    return EXIT_OK if result.success else EXIT_SCENARIO_FAILED


def _claim_verdict(claim: dict) -> str:
    """The paper's claim a run checks, as a verdict of its own (a run can succeed by its own
    criterion while the claim does not hold, or fail while it holds)."""
    numbers = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                        for k, v in claim.items() if k not in ("paper", "holds"))
    verdict = "HOLDS" if claim["holds"] else "DOES NOT HOLD"
    return (f"  paper's claim (a verdict of its own, not the run's success): {verdict}: "
            f"{claim.get('paper', '')}" + (f" ({numbers})" if numbers else ""))


#: how many of a failed run's first incidents the command line prints (summary.json has all)
PRINTED_INCIDENTS = 6


def _print_incidents(incidents) -> None:
    """The first incidents of a failed run, one per line (time, then what happened)."""
    if not incidents:
        return
    print("  first incidents in the twin:")
    several = len({x.get("run") for x in incidents}) > 1
    for x in incidents[:PRINTED_INCIDENTS]:
        run = f" [{x['run']}]" if several else ""
        print(f"    {x['t']:.3f} s{run}  {x['what']}")
    if len(incidents) > PRINTED_INCIDENTS:
        print(f"    ... {len(incidents) - PRINTED_INCIDENTS} more in summary.json")


def _check_observed(args, scenario, params: dict) -> None:
    """ValueError naming the flag if ``--replay``/``--view`` cannot watch this run: the scenario
    does not declare its simulations or runs too many, or (``--view``) no display."""
    from .report.replay import MAX_RUNS

    for flag in [f for f, on in (("--replay", args.replay), ("--view", args.view)) if on]:
        n = scenario.simulation_count(params, args.controller)
        if n is None:
            raise ValueError(f"scenario '{scenario.name}' does not declare how many simulations it "
                             f"runs; {flag} needs a single-run scenario")
        if n > MAX_RUNS:
            raise ValueError(f"scenario '{scenario.name}' runs {n} simulations; {flag} needs a "
                             f"single-run scenario (or a comparison of {MAX_RUNS}, shown side by "
                             f"side)")
    if args.view:
        from .sim.live_view import display_problem

        problem = display_problem()
        if problem:
            raise ValueError(f"--view: {problem}; run without --view (--replay writes a replay "
                             f"to open later)")


def _observers(args, out_dir: Path):
    """The replay recorder (``--replay``; an earlier replay.html removed) and the live view
    (``--view``), or None."""
    from .sim.live_view import LiveView
    from .sim.recorder import ReplayRecorder

    if args.replay:
        (out_dir / "replay.html").unlink(missing_ok=True)
    return (ReplayRecorder() if args.replay else None), (LiveView() if args.view else None)


def _write_replay(recorder, title: str, out_dir: Path, incidents=None, summary=None) -> None:
    """Write ``out_dir/replay.html`` from what ``recorder`` (``--replay``) saw, if anything, with
    the run's ``incidents`` and the footsteps its ``summary`` records (one list per recording)."""
    if recorder is None or not any(r.frames for r in recorder.recordings):
        return
    from .report.replay import summary_footsteps, write_replay

    footsteps = summary_footsteps(summary) if summary is not None else []
    if len(footsteps) != len(recorder.recordings):
        footsteps = None
    path = write_replay(out_dir / "replay.html", recorder.recordings, title, incidents,
                        footsteps)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wholebody",
        description="Whole-body control of torque-controlled legged robots, checked in a MuJoCo twin.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("robots", help="list the robot presets (DoF, mass, contacts)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_robots)

    p = sub.add_parser("check-robot", help="load and check a robot description: size, contacts "
                                           "and their roles, posture, limits (exit 2 on errors)")
    p.add_argument("robot", help="preset name, path to a robot .toml, or a .urdf/.xml model file "
                                 "(checked through the description init-robot drafts)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_check_robot)

    p = sub.add_parser("init-robot", help="draft a robot description (.toml) from a URDF or MJCF "
                                          "model file: feet, contacts, posture, limits")
    p.add_argument("model", help="the robot's URDF or MJCF (.xml) file")
    p.add_argument("--out", help="write the draft to this .toml file (default: print it)")
    p.add_argument("--name", help="the robot's name (default: the file's stem)")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.set_defaults(func=_cmd_init_robot)

    p = sub.add_parser("scenarios", help="list the scenarios and their parameters (or one: "
                                         "scenarios NAME)")
    p.add_argument("name", nargs="?", help="show this scenario only")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_scenarios)

    p = sub.add_parser("run", help="run a closed-loop scenario in the MuJoCo twin")
    p.add_argument("scenario", help="scenario name (see `wholebody scenarios`)")
    p.add_argument("--robot", help="preset name, path to a robot .toml, or a .urdf/.xml model "
                                   "file (run on the description init-robot drafts; default: "
                                   "the scenario's robot)")
    p.add_argument("--controller", help="controller variant (default: the scenario's first)")
    p.add_argument("--plant", metavar="FILE.xml",
                   help="simulate the robot's vendor MJCF instead of the exact twin (joints mapped "
                        "by name; the controller keeps its own model; overrides the "
                        "description's plant)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario parameter (repeatable)")
    p.add_argument("--out", help="output directory, created and checked to be writable before "
                                 "the run (default: results/SCENARIO-ROBOT)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--replay", action="store_true",
                   help="also write DIR/replay.html: a 3D replay that opens from disk")
    p.add_argument("--view", action="store_true",
                   help="watch the run live in MuJoCo's viewer (needs a display)")
    p.set_defaults(func=_cmd_run)

    from .sweep.command import add_parser as add_sweep_parser  # exit codes: sweep/command.py
    add_sweep_parser(sub)
    from .report.command import add_parser as add_report_parser  # exit codes: report/command.py
    add_report_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except KeyboardInterrupt:  # outside a run (a run writes its interrupted summary itself)
        print("wholebody: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # the reader went away (`wholebody scenarios | head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
