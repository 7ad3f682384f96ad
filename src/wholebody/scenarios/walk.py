"""``walk``: the humanoid walks forward, turns, side-steps and stops under the capture-point
walking controller (:class:`~wholebody.control.walking.Walking`, Tables 2 and 4 of Herzog et al.
2016 with a DCM reference).

A velocity command schedule drives the controller: 1 s standing, the forward speed ramped in over
1 s and held for ``steps`` step periods, a turn by ``turn`` degrees at ``yaw_rate`` (walking on at
half the speed), a side-step of ``side_distance`` at ``lateral``, then a zero command and
``settle`` s to stop (``steps=0``, ``turn=0`` or ``side_distance=0`` leave a part out). The
controller reads its command at each touchdown, so the turn and the side-step last a whole number
of step periods, at the rate nearest ``yaw_rate`` (``lateral``) that makes them exact.

Everything is measured on the simulator: the base's path and heading, the CoM and the DCM against
the controller's references, each sole's slip while it stands (from its touchdown to its next
lift-off) and its tilt in contact, the torque changes between cycles (at the contact switches
apart), and falls (:func:`~wholebody.scenarios.measures.fallen`; the run stops there).

Success: no fall, every cycle solved, no sole slipping by 1 cm (talos14's, in proportion to the
standing height) while it stands, and a net displacement of at least 80 % of the commanded one
(the end point of the command integrated along the commanded heading).
"""

from __future__ import annotations

from pathlib import Path

from ..control.walking import Walking
from .base import COP_MARGIN, ENGINE, Parameter, Scenario, ScenarioResult
from .measures import Thresholds
from .pushes import FroudeScaled, HumanoidScaled
from .walking_runs import (DISTANCE_SHARE, command_at, config, schedule, simulate, step_period,
                           validate_walk, walk_figure, walk_metrics, walked)


PARAMETERS = (
    Parameter("speed", FroudeScaled(0.4, "m/s", height_power=0.5),
              "forward speed of the forward part (m/s)", low=0.0, low_open=True, high=5.0),
    Parameter("steps", 20, "length of the forward part at full speed, in step periods "
                           "(0: no forward part)", low=0, high=500),
    Parameter("turn", 90.0, "heading change of the turn (deg, positive to the left; 0: no turn)",
              low=-360.0, high=360.0),
    Parameter("yaw_rate", FroudeScaled(0.35, "rad/s", height_power=-0.5),
              "yaw rate of the turn (rad/s), walking on at half the speed", low=0.0,
              low_open=True, high=10.0),
    Parameter("side_distance", HumanoidScaled(1.0, "m", height_power=1),
              "distance of the side-step after the turn (m, positive to the left; 0: none)",
              low=-20 * Parameter.H, high=20 * Parameter.H),
    Parameter("lateral", FroudeScaled(0.12, "m/s", height_power=0.5),
              "side-step speed (m/s)", low=0.0, low_open=True, high=5.0),
    Parameter("settle", 2.0, "time with a zero command at the end (s)", low=0.0,
              high=Parameter.MAX_TIME),
    COP_MARGIN,
    ENGINE,
)


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    walking = config(robot, params)
    parts = schedule(robot, params, walking)
    ctrl = Walking(robot, walking, engine=params["engine"])
    run_ = simulate(robot, ctrl, parts[-1].end, command=lambda t: command_at(parts, t),
                    progress=progress, observers=observers, label=controller)
    metrics = walk_metrics(robot, params, parts, run_, walking)
    period = step_period(robot, params, walking)
    notes = [f"success = no fall, no failed cycle, sole slip per stance < "
             f"{1e3 * Thresholds.for_robot(robot).max_slip:.1f} mm, net displacement >= "
             f"{DISTANCE_SHARE:.0%} of the commanded "
             f"{metrics['commanded_net_displacement_m']:.2f} m",
             f"step period {period:.3f} s; schedule: " + ", ".join(
                 f"{p.name} {p.start:.2f}-{p.end:.2f} s" for p in parts)]
    if run_.fallen:
        notes.append(f"fell at t = {run_.fell_at:.2f} s; the run stopped there")
    result = ScenarioResult("walk", robot.name, controller, walked(robot, metrics), metrics,
                            params, notes, log=run_.sim.log)
    if out_dir is not None:
        result.figures = [str(walk_figure(
            Path(out_dir) / "walk.png", robot, run_, parts, period,
            title=f"walk — {robot.name}, {len(ctrl.steps)} steps, "
                  f"{'fell' if run_.fallen else 'no fall'}"))]
    return result


SCENARIO = Scenario(
    name="walk",
    summary="capture-point walking (Tables 2/4, DCM reference): forward, a turn, a side-step, "
            "stop; success = no fall, no failed cycle, soles not slipping while they stand, "
            "net displacement >= 80 % of the commanded",
    parameters=PARAMETERS,
    controllers=("dcm",),
    default_robot="talos14",
    run_function=run,
    validate_function=validate_walk,
    simulations=1,
)
