"""``walk-push``: the humanoid walking forward is pushed in the middle of a single support and
walks on (:class:`~wholebody.control.walking.Walking`: DCM feedback, step adjustment).

The ``walk`` scenario's forward part (1 s standing, the speed ramped in over 1 s) runs for
``push_step + steps_after`` step periods, then a zero command and ``settle`` s to stop. When the
``push_step``-th step has swung for ``push_phase`` of its single support, a half-sine push of
``push_duration`` gives the robot the velocity change ``dv`` along ``angle`` (the ``push``
scenario's convention: 0 pushes the front backwards, 90 the left side toward -y, 180 the back
forwards), ``height`` above the base frame. One run per angle of ``angles``.

Recovered (per angle): the ``walk`` scenario's success (no fall, every cycle solved, no sole
slipping while it stands, at least 80 % of the commanded displacement). Success: every angle
recovered.
"""

from __future__ import annotations

from pathlib import Path


from ..control.walking import Walking
from ..report.plots import grouped_bar_figure
from .base import (COP_MARGIN, ENGINE, TIME_SPAN, Parameter, Scenario, ScenarioResult,
                   parse_list)
from .pushes import FroudeScaled
from .walking_runs import (command_at, config, push_of, schedule, simulate, step_period,
                           validate_walk, walk_figure, walk_metrics, walked)

PARAMETERS = (
    Parameter("speed", FroudeScaled(0.4, "m/s", height_power=0.5),
              "forward walking speed (m/s)", low=0.0, low_open=True, high=5.0),
    Parameter("dv", FroudeScaled(0.2, "m/s", height_power=0.5),
              "the push's velocity change (m/s): impulse m dv", low=0.0, low_open=True,
              high=5.0),
    Parameter("angles", "0,90,180,270", "push directions (deg), one run each: 0 = on the front, "
                                        "backwards; 90 = on the left side; 180 = on the back",
              low=-360.0, high=360.0, items=float),
    Parameter("push_step", 6, "the step during whose single support the push comes (1 = the "
                              "first)", low=1, high=100),
    Parameter("push_phase", 0.5, "when in that single support (share of it)", low=0.0,
              high=1.0, high_open=True),
    Parameter("steps_after", 8, "step periods of walking after the pushed step", low=1,
              high=100),
    Parameter("push_duration", 0.1, "duration of the push (s)", **TIME_SPAN),
    Parameter("height", 0.0, "height of the push point above the base frame (m)",
              low=-Parameter.H, high=Parameter.H),
    Parameter("settle", 2.0, "time with a zero command at the end (s)", low=0.0,
              high=Parameter.MAX_TIME),
    COP_MARGIN,
    ENGINE,
)


def angles(params: dict) -> list[float]:
    return parse_list(str(params["angles"]), float, "angles")


def walk_params(params: dict) -> dict:
    """The ``walk`` schedule's parameters: forward only, for the pushed and the later steps."""
    return {**params, "steps": params["push_step"] + params["steps_after"], "turn": 0.0,
            "side_distance": 0.0, "yaw_rate": 1.0, "lateral": 1.0}


def validate(robot, params: dict) -> None:
    validate_walk(robot, walk_params(params))
    if not angles(params):
        raise ValueError("--set angles: give at least one angle")
    for angle in angles(params):
        push_of(robot, {**params, "start": 0.0}, params["dv"], angle)


def trial(robot, params: dict, angle: float, progress: bool = False, observers=()):
    """One walk pushed along ``angle``: (metrics, run)."""
    wp = walk_params(params)
    walking = config(robot, wp)
    parts = schedule(robot, wp, walking)
    ctrl = Walking(robot, walking, engine=params["engine"])

    def push(run, t):
        ph = ctrl.phase
        if (len(ctrl.steps) == params["push_step"] and ph.kind == "single"
                and t >= ph.start + params["push_phase"] * (ph.end - ph.start)):
            return push_of(robot, params, params["dv"], angle, start=t)
        return None

    run = simulate(robot, ctrl, parts[-1].end, command=lambda t: command_at(parts, t),
                   push=push, progress=progress, observers=observers,
                   label=f"push {angle:g} deg")
    metrics = walk_metrics(robot, wp, parts, run, walking)
    metrics = {"angle_deg": angle, "dv_mps": params["dv"],
               "pushed_at_s": run.pushes[0].start if run.pushes else None,
               "recovered": walked(robot, metrics) and bool(run.pushes), **metrics}
    return metrics, run, parts


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    trials = {f"{a:g}": trial(robot, params, a, progress, observers) for a in angles(params)}
    per_angle = {k: m for k, (m, _, _) in trials.items()}
    success = all(m["recovered"] for m in per_angle.values())
    metrics = {"angles": per_angle,
               "recovered": [k for k, m in per_angle.items() if m["recovered"]],
               "not_recovered": [k for k, m in per_angle.items() if not m["recovered"]]}
    notes = ["recovered = no fall, no failed cycle, soles not slipping while they stand, net "
             "displacement >= 80 % of the commanded; angle 0 pushes the front backwards, 90 the "
             "left side"]
    for k, m in per_angle.items():
        if m["pushed_at_s"] is None:
            notes.append(f"{k} deg: the run ended before step {params['push_step']} was pushed")
    first = next(iter(trials.values()))
    result = ScenarioResult("walk-push", robot.name, controller, bool(success), metrics, params,
                            notes, log=first[1].sim.log if len(trials) == 1 else None)
    if out_dir is not None:
        if len(trials) == 1:
            m, run_, parts = first
            path = walk_figure(Path(out_dir) / "walk_push.png", robot, run_, parts,
                               step_period(robot, walk_params(params)),
                               title=f"walk-push — {robot.name}, dv {params['dv']:.2f} m/s at "
                                     f"{m['angle_deg']:g} deg: "
                                     f"{'recovered' if m['recovered'] else 'not recovered'}")
        else:
            path = grouped_bar_figure(
                Path(out_dir) / "walk_push.png", [f"{k} deg" for k in per_angle],
                {"net displacement / commanded (%)":
                 [100 * (m["displacement_ratio"] or 0.0) for m in per_angle.values()],
                 "steps": [float(m["steps"]) for m in per_angle.values()]},
                title=f"walk-push — {robot.name}, dv {params['dv']:.2f} m/s "
                      f"(recovered: {', '.join(metrics['recovered']) or 'none'})",
                ylabel="")
        result.figures = [str(path)]
    return result


SCENARIO = Scenario(
    name="walk-push",
    summary="a push in the middle of a single support while walking (capture-point controller), "
            "one run per angle; success = every run walks on without a fall",
    parameters=PARAMETERS,
    controllers=("dcm",),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
    simulations=lambda params, controller: len(angles(params)),
)
