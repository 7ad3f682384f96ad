"""``push``: one push on the standing humanoid under momentum balance (Herzog et al. 2016 Sect. 5.2.2).

The push is a half-sine force applied at one of the paper's 7 points (front, right, back, left on
the torso above the hip; front, right, left at the hip) or along any ``angle`` and ``height``
(:mod:`~wholebody.scenarios.pushes`).
"Survived": the feet stay flat and in place (tilt < 2 deg, slip < 1 cm) and the CoG
returns within 5 mm of its reference within 3 s after the push.
"""

from __future__ import annotations

from pathlib import Path

from ..report.balance_figures import push_figure
from .base import (COP_MARGIN, ENGINE, INTEGRAL_LIMIT, PD_PARAMETERS, POSTURE_PARAMETERS,
                   Q_ANGULAR, Q_INTEGRAL, TIME_SPAN, Parameter, Scenario, ScenarioResult,
                   duration_parameter, paper_q_notes)
from .measures import RECORD_TAIL_S, Thresholds
from .pushes import (ANGULAR_WEIGHT, LOCATIONS, Q_ORIENTATION, HumanoidScaled, check_push,
                     ignored_option_notes, peak_force_for, push_trial)

PARAMETERS = (
    Parameter("location", "front", f"push point: {', '.join(LOCATIONS)} (or 'angle')",
              choices=(*LOCATIONS, "angle")),
    Parameter("angle", 0.0, "with location=angle: force direction in the horizontal plane (deg, "
                            "0 = pushing backwards from the front)", low=-180.0, high=180.0),
    Parameter("height", HumanoidScaled(0.1, "m", height_power=1), "with location=angle: height "
              "of the point above the base (m)", low=-Parameter.H, high=Parameter.H),
    Parameter("peak_force", HumanoidScaled(100.0, "N", mass_power=1), "peak of the half-sine "
              "force (N; 100 N on talos14, the same velocity change on any robot)", low=0.0),
    Parameter("dv", 0.0, "the push as the velocity change it gives the robot (m/s): impulse "
                         "m dv, the peak force 0.5 pi m dv / push_duration (0: peak_force)",
              low=0.0, high=5.0),
    Parameter("push_duration", 0.1, "duration of the push (s), 0.05-0.15 in the paper",
              **TIME_SPAN),
    Parameter("start", 0.5, "time of the push (s)", low=0.0, high=Parameter.MAX_TIME),
    duration_parameter(4.0),
    Q_ANGULAR,
    ANGULAR_WEIGHT,
    Q_INTEGRAL,
    INTEGRAL_LIMIT,
    Q_ORIENTATION,
    *PD_PARAMETERS,
    *POSTURE_PARAMETERS,
    COP_MARGIN,
    ENGINE,
)


def validate(robot, params: dict) -> None:
    """:func:`check_push`, and the push over :data:`~.measures.RECORD_TAIL_S` before the run
    ends (else a push that never came would count as a push survived)."""
    check_push(robot, params)
    end = params["start"] + params["push_duration"]
    if end + RECORD_TAIL_S > params["duration"]:
        raise ValueError(f"--set start: the push ends at {end:g} s, less than {RECORD_TAIL_S:g} s "
                         f"before the run does (duration {params['duration']:g} s)")


def with_peak_force(robot, params: dict) -> dict:
    """``params`` with ``peak_force`` from ``dv`` when it is set: a half-sine of peak F over T
    carries the impulse 2 F T / pi, which is m dv."""
    if params["dv"] <= 0.0:
        return params
    return {**params, "peak_force": peak_force_for(robot.mass, params["dv"],
                                                   params["push_duration"])}


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    params = with_peak_force(robot, params)
    trial = push_trial(robot, controller, params, progress, observers)
    push = trial.push
    notes = [Thresholds.for_robot(robot).push_criteria()]
    notes += ignored_option_notes(controller, params)
    notes += paper_q_notes(robot, controller, params)
    result = ScenarioResult("push", robot.name, controller, trial.success, trial.metrics, params,
                            notes, log=trial.log)
    if out_dir is not None:
        arrays = trial.log.arrays()
        result.figures = [str(push_figure(
            Path(out_dir) / "push.png", arrays["t"], arrays["push_force"], trial.cog_error,
            trial.momentum, title=f"push {params['location']} {push.peak_force:.0f} N — "
                                  f"{robot.name}, {controller} momentum gains",
            shaded=[(push.start, push.start + push.duration)]))]
    return result


SCENARIO = Scenario(
    name="push",
    summary="one half-sine push on the standing humanoid under momentum balance (Table 2, no "
            "joint PD); success = feet flat and in place, CoG back within 5 mm within 3 s",
    parameters=PARAMETERS,
    controllers=("lqr", "pd"),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
    simulations=1,
)
