"""``push-series``: the push protocol of Herzog et al. 2016 Sect. 5.2.2 (Table 3, Figs. 6-7).

7 points (front, right, back, left above the hip; front, right, left at the hip) x pushes of
increasing peak force, once with PD momentum gains (eq. 22) and once with LQR gains (eq. 24); for
each controller and point, the strongest push survived (Table 3) and, optionally, the largest
survivable peak force by bisection. Pushes are reported as impulse and as Δv = impulse / mass, since
talos14 (~90 kg) is heavier than the paper's 51 kg biped (9.5 Ns there is ≈ 0.19 m/s).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..report.balance_figures import push_series_figure
from ..robot import Robot
from ..robots import load_robot
from ..sweep.executors import ordered, scenario_executor
from .base import (COP_MARGIN, ENGINE, INTEGRAL_LIMIT, PD_PARAMETERS, POSTURE_PARAMETERS,
                   Q_ANGULAR, Q_INTEGRAL, TIME_SPAN, Parameter, Scenario, ScenarioResult,
                   duration_parameter, parse_list)
from .conditions import job_observers
from .pushes import (ANGULAR_WEIGHT, CONTROLLER_PARAMETERS, FIXED_PUSH, LOCATIONS, Q_ORIENTATION,
                     HumanoidScaled, check_locations, check_push, push_trial)

PARAMETERS = (
    Parameter("locations", ",".join(LOCATIONS), "comma-separated push points",
              choices=tuple(LOCATIONS), items=str),
    Parameter("forces", HumanoidScaled((60.0, 100.0, 140.0, 180.0), "N", mass_power=1,
                                       listed=True),
              "comma-separated peak forces (N), increasing (talos14's, the same velocity changes "
              "on any robot)", low=0.0, low_open=True, items=float),
    Parameter("push_duration", 0.1, "duration of each push (s)",
              **TIME_SPAN),
    duration_parameter(3.5, "simulated time per push (s)"),
    Q_ANGULAR,
    ANGULAR_WEIGHT,
    Q_INTEGRAL,
    INTEGRAL_LIMIT,
    Q_ORIENTATION,
    *PD_PARAMETERS,
    *POSTURE_PARAMETERS,
    COP_MARGIN,
    Parameter("bisection", False, "also find the largest survivable peak force per point"),
    Parameter("bisection_steps", 5, "bisection iterations (each one simulated push)",
              low=1, high=30),
    ENGINE,
    Parameter("workers", 1, "processes for the independent pushes (and the points' bisections): "
                            "1 this process, N a local pool of N, 0 one per core; same metrics",
              low=0, high=1024),
)
CONTROLLERS = ("pd", "lqr")


def simulation_count(params: dict) -> int:
    """The pushes one run simulates: every point and force with each controller, and the
    bisections' steps."""
    points = len(CONTROLLERS) * len(parse_list(params["locations"], str, "locations"))
    forces = len(parse_list(params["forces"], float, "forces"))
    return points * (forces + (int(params["bisection_steps"]) if params["bisection"] else 0))


def validate(robot, params: dict) -> None:
    check_locations(parse_list(params["locations"], str, "locations"))
    forces = parse_list(params["forces"], float, "forces")
    if any(f <= 0 for f in forces):
        raise ValueError("--set forces: peak forces must be > 0")
    check_push(robot, {**FIXED_PUSH, "location": "front", "peak_force": forces[0], "start": 0.5,
                       "push_duration": params["push_duration"]})


def _one(robot, controller, location, force, params, observers=None):
    """One push trial: (survived, metrics); ``observers`` watch it (None: those of
    :func:`~wholebody.scenarios.conditions.job_observers`)."""
    p = {**FIXED_PUSH, "location": location, "peak_force": force,
         "push_duration": params["push_duration"], "start": 0.5, "duration": params["duration"],
         **{option.name: params[option.name] for option in CONTROLLER_PARAMETERS}}
    trial = push_trial(robot, controller, p,
                       observers=job_observers(robot, params, observers))
    return trial.success, trial.metrics


def _robot(robot):
    """The robot of a job: itself in this process, rebuilt from its description in a worker."""
    return robot if isinstance(robot, Robot) else load_robot(robot)


def _trial_job(job):
    """One push of a job ``(robot, controller, location, force, params, observers)``."""
    robot, c, loc, f, params, observers = job
    return _one(_robot(robot), c, loc, f, params, observers)


def _bisection_job(job):
    """The largest survived peak force of one point: ``steps`` sequential pushes, bisecting
    [0, ``high``]; job ``(robot, controller, location, high, steps, params, observers)``."""
    robot, c, loc, high, steps, params, observers = job
    robot = _robot(robot)
    lo, hi = 0.0, high
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        ok, _ = _one(robot, c, loc, mid, params, observers)
        lo, hi = (mid, hi) if ok else (lo, mid)
    return lo


def _map(executor, function, jobs, progress: bool, desc: str) -> list:
    """``function`` over ``jobs`` on ``executor``, results in job order, with a progress bar."""
    with tqdm(total=len(jobs), disable=not progress, desc=desc, leave=False) as bar:
        return ordered(executor, function, jobs, progress=lambda i, r: bar.update(1))


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    locations = parse_list(params["locations"], str, "locations")
    forces = sorted(parse_list(params["forces"], float, "forces"))
    jobs = [(c, loc, f) for c in CONTROLLERS for loc in locations for f in forces]
    with scenario_executor(params["workers"]) as executor:
        # the robot itself in this process; its (picklable) description for a pool's workers
        shipped = robot if params["workers"] == 1 else robot.description
        watched = observers if params["workers"] == 1 else None  # see job_observers
        results = _map(executor, _trial_job,
                       [(shipped, c, loc, f, params, watched) for c, loc, f in jobs],
                       progress, "pushes")
        trials = [(c, loc, f, survived, m)  # (controller, location, force, survived, metrics)
                  for (c, loc, f), (survived, m) in zip(jobs, results)]
        points = [(c, loc) for c in CONTROLLERS for loc in locations]
        if params["bisection"]:  # the points are independent, each bisection sequential
            lows = _map(executor, _bisection_job,
                        [(shipped, c, loc, forces[-1] * 2.0, int(params["bisection_steps"]),
                          params, watched) for c, loc in points], progress, "bisections")

    table = {}
    for c in CONTROLLERS:
        for loc in locations:
            survived = [t for t in trials if t[0] == c and t[1] == loc and t[3]]
            if survived:
                m = max(survived, key=lambda t: t[2])[4]
                table[f"{c}/{loc}"] = {k: m[k] for k in (
                    "peak_force_N", "impulse_Ns", "delta_v_mps", "max_cog_error_m",
                    "max_linear_momentum_Ns", "max_angular_momentum_Nms")}
            else:
                table[f"{c}/{loc}"] = None

    # the paper's claim: LQR's max CoG error <= PD's for the same pushes (both survived)
    pairs = []
    for loc in locations:
        for f in forces:
            pd = next(t for t in trials if t[:3] == ("pd", loc, f))
            lqr = next(t for t in trials if t[:3] == ("lqr", loc, f))
            if pd[3] and lqr[3]:
                pairs.append(lqr[4]["max_cog_error_m"] <= pd[4]["max_cog_error_m"])
    metrics = {
        "trials": len(trials),
        "survived": {c: sum(t[3] for t in trials if t[0] == c) for c in CONTROLLERS},
        "table3": table,
        "lqr_cog_error_le_pd_fraction": (float(np.mean(pairs)) if pairs else None),
        "pairs_survived_by_both": len(pairs),
    }
    notes = []
    if pairs and np.mean(pairs) < 1.0:
        notes.append(f"LQR's max CoG error <= PD's held in {np.mean(pairs):.0%} of the "
                     f"{len(pairs)} pushes both survived (the paper claims it throughout)")
    if not pairs:
        notes.append("no push was survived by both controllers: the LQR-vs-PD claim is untested")

    if params["bisection"]:
        largest = {}
        for (c, loc), lo in zip(points, lows):
            impulse = 2.0 / np.pi * lo * params["push_duration"]
            largest[f"{c}/{loc}"] = {"peak_force_N": lo, "impulse_Ns": impulse,
                                     "delta_v_mps": impulse / robot.mass}
        metrics["largest_survived"] = largest

    result = ScenarioResult("push-series", robot.name, "pd+lqr", True, metrics, params, notes)
    if out_dir is not None:
        result.figures = [str(push_series_figure(Path(out_dir) / "push_series.png", trials,
                                                 locations, CONTROLLERS, robot.name))]
    return result


SCENARIO = Scenario(
    name="push-series",
    summary="Sect. 5.2.2 protocol: 7 points x increasing pushes, PD and LQR momentum gains; "
            "Table 3 (strongest push survived per point), Fig. 6, optional bisection",
    parameters=PARAMETERS,
    controllers=("pd+lqr",),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
    simulations=lambda params, controller: simulation_count(params),
)
