"""``agility``: one quadruped through the agility course of the library's own targets, each part
a run of an existing scenario on its Froude-scaled defaults, judged by that scenario.

The paper's experiments (Fahmi et al. 2019) stop at a 0.15 m/s crawl, a ramp and a gap; its
conclusion names stairs and faster gaits as the next step. The parts, every speed and size in
proportion to the robot's standing base height h (HyQ's 0.599 m the reference):

- ``top-speed``: ``crawl --set gait=trot``, the speed ramped from 0 to Froude ``froude``
  (v = sqrt(froude g h)) over 10 s and held 1 s; met: no fall, no failed cycle, the distance
  walked, and the CoM's velocity over the hold within 10 % of the command
  (``hold_velocity_error_share``);
- ``steer``: ``steer`` (trot): forward, a 90 deg turn, a side-step, a stop; met: its own success
  (no fall or failed cycle, heading error <= 5 deg, every part's velocity error <= 10 %);
- ``stairs-crawl``, ``stairs-trot``: ``ramp --set course=stairs``, 5 steps up and down;
- ``rough``: ``ramp --set course=rough --set gait=trot``, +-5 cm cells; met: the ramp scenario's
  success (no fall, every cycle solved, every foot past the course);
- ``push``: ``trot-push --set angles=90,270``: a 0.3 m/s lateral push from each side while
  trotting; met: trotted on after both.

Every part runs on its scenario's defaults (``steer``'s CoM loop critically damped, the others'
the paper's gains). A part whose simulation diverged counts as missed (``diverged`` in its metrics). Each part writes its own
``summary.json`` and figures under ``OUT/<part>/``.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

from ..sim.incidents import IncidentLog
from ..sim.simulator import SimulationDiverged
from .base import Parameter, Scenario, ScenarioResult
from .conditions import RobotConditions

log = logging.getLogger(__name__)

GRAVITY = 9.81
#: the top-speed part: the velocity error over the hold, as a share of the command, to meet it
MAX_HOLD_VELOCITY_ERROR_SHARE = 0.1
#: the top-speed part: the trot's speed ramp (s, after 1 s of standing) and the run's duration
TOP_SPEED_RAMP_S, TOP_SPEED_DURATION_S = 10.0, 12.0

#: part -> (scenario, controller, --set pairs other than the realism ones)
PARTS = {
    "top-speed": ("crawl", "passive", {"gait": "trot", "speed_start": "0",
                                       "ramp_time": f"{TOP_SPEED_RAMP_S:g}",
                                       "duration": f"{TOP_SPEED_DURATION_S:g}"}),
    "steer": ("steer", "passive", {}),
    "stairs-crawl": ("ramp", "passive", {"course": "stairs", "gait": "crawl"}),
    "stairs-trot": ("ramp", "passive", {"course": "stairs", "gait": "trot"}),
    "rough": ("ramp", "passive", {"course": "rough", "gait": "trot"}),
    "push": ("trot-push", "passive", {"angles": "90,270"}),
}

PARAMETERS = (
    Parameter("parts", ",".join(PARTS), "the parts to run, comma-separated",
              choices=tuple(PARTS), items=str),
    Parameter("froude", 0.5, "top-speed: the Froude number v^2 / (g h) of the speed reached",
              low=0.0, high=2.0, low_open=True),
)


def froude_speed(robot, froude: float) -> float:
    """The speed of Froude number ``froude`` on ``robot``: sqrt(froude g h), h its standing base
    height."""
    return math.sqrt(froude * GRAVITY * float(robot.q_ref[2]))


def part_overrides(name: str, robot, params: dict) -> dict[str, str]:
    """The ``--set`` pairs of part ``name`` on ``robot``: its own, the top speed from ``froude``,
    and the realism level passed down."""
    overrides = dict(PARTS[name][2])
    if name == "top-speed":
        overrides["speed_end"] = f"{froude_speed(robot, params['froude']):.4g}"
    if params["realism"] != "exact":
        overrides["realism"] = params["realism"]
        overrides["ground_map"] = str(params["ground_map"]).lower()
    return overrides


def command_line(scenario: str, robot, controller: str, overrides: dict[str, str]) -> str:
    return " ".join(["wholebody", "run", scenario, "--robot", robot.name, "--controller",
                     controller, *(f"--set {k}={v}" for k, v in overrides.items())])


def met(name: str, success: bool, metrics: dict) -> bool:
    """Whether part ``name`` meets its target (the module docstring) from its run's outcome."""
    if name == "top-speed":
        passive = metrics.get("passive", {})
        share = passive.get("hold_velocity_error_share")
        return bool(success and share is not None and share <= MAX_HOLD_VELOCITY_ERROR_SHARE)
    return bool(success)


def part_names(params: dict) -> list[str]:
    return [n.strip() for n in params["parts"].split(",") if n.strip()]


def simulation_count(params: dict) -> int:
    """The simulations of the selected parts, as their scenarios declare them."""
    from . import get_scenario

    total = 0
    for name in part_names(params):
        scenario_name, controller, overrides = PARTS[name]
        scenario = get_scenario(scenario_name)
        total += scenario.simulation_count(scenario.resolve(overrides), controller)
    return total


def run_part(name: str, robot, params: dict, out_dir: Path | None, progress: bool,
             observers=()) -> dict:
    """One part: its scenario run (into ``out_dir/<name>``) and whether it met its target.
    ``observers`` (the replay recorder, the live view) watch its simulations; each part makes its
    own real-robot conditions and incident log from its parameters, as a run of its own would."""
    from . import get_scenario

    scenario_name, controller, _ = PARTS[name]
    overrides = part_overrides(name, robot, params)
    row = {"command": command_line(scenario_name, robot, controller, overrides)}
    passed = tuple(o for o in observers if not isinstance(o, (RobotConditions, IncidentLog)))
    try:
        result = get_scenario(scenario_name).run(
            robot, controller, overrides, out_dir=None if out_dir is None else Path(out_dir) / name,
            progress=progress, observers=passed)
    except SimulationDiverged as exc:
        log.info("agility %s on %s: %s", name, robot.name, exc)
        return {**row, "met": False, "success": False, "diverged": str(exc)}
    return {**row, "met": met(name, result.success, result.metrics), "success": result.success,
            "metrics": result.metrics, "wall_time_s": result.wall_time_s}


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    parts = {name: run_part(name, robot, params, out_dir, progress, observers)
             for name in part_names(params)}
    notes = [f"{name}: {'met' if p['met'] else 'missed'} ({p['command']})"
             for name, p in parts.items()]
    metrics = {"parts": parts, "met": sum(p["met"] for p in parts.values()),
               "top_speed_mps": froude_speed(robot, params["froude"]), "base_height_m":
               float(robot.q_ref[2])}
    return ScenarioResult("agility", robot.name, controller,
                          all(p["met"] for p in parts.values()), metrics, params, notes)


def validate(robot, params: dict) -> None:
    """ValueError unless ``robot`` is a quadruped, some part is given and every part's own
    scenario accepts its parameters on ``robot`` (all checked before anything is simulated)."""
    from . import get_scenario

    names = part_names(params)
    if not names:
        raise ValueError("--set parts: no part given; parts: " + ", ".join(PARTS))
    if len(robot.contact_names) != 4:
        raise ValueError(f"robot '{robot.name}': the agility course is for quadrupeds (four "
                         f"feet); it has {len(robot.contact_names)} contacts")
    for name in names:
        scenario_name, _, _ = PARTS[name]
        try:
            get_scenario(scenario_name).validate(robot, part_overrides(name, robot, params))
        except ValueError as exc:
            raise ValueError(f"--set parts: part '{name}' ({scenario_name}): {exc}") from None


SCENARIO = Scenario(
    name="agility",
    summary="a quadruped through the library's agility targets, each part a run of an existing "
            "scenario on Froude-scaled defaults: trot to Froude 0.5, steer, stairs (crawl, trot), "
            "rough ground, lateral pushes while trotting; success = every part met",
    parameters=PARAMETERS,
    controllers=("passive",),
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
    simulations=lambda params, controller: simulation_count(params),
)
