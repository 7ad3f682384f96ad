"""``robust-push``: push recovery with a mismatched twin (robustness; Herzog et al. 2016 Sect. 5.2.2
protocol).

The controller (:class:`~wholebody.control.balance.MomentumBalance`, Table 2, PD eq. 22 or LQR
eqs. 23-24, no joint PD) keeps the nominal Pinocchio model; the simulated robot differs from it
(:class:`~wholebody.sim.mismatch.Mismatch`, simulator side only): every link mass and inertia scaled
by a factor in [1 - mass_noise, 1 + mass_noise], every link CoM moved by ``com_offset`` in a random
direction, the torques applied ``torque_delay`` steps (ms) late with Gaussian noise. Each seed is one
draw of that robot. The push is ``fraction`` (70 %) of the nominal largest peak force survived on the
exact twin, per location and controller (half-sine, 0.1 s, measured on talos14: ``NOMINAL``; on
another robot the same velocity change, the force times m / m_talos14).

Everything judged is measured on the simulator: the CoG is the simulated (mismatched) robot's own
CoM (:class:`~wholebody.sim.true_com.TrueCoM`, from the MuJoCo model), not the controller's estimate, and the feet are the
simulator's sole poses. Because the controller regulates its own (wrong) CoM estimate, the true CoG
settles at a static offset from the reference; the push error is measured from the true CoG before
the push (``pre-push``), and the static offset is reported separately.
Survived: feet flat and in place from the push on (tilt < 2 deg; slip < 1 cm from where the feet were
when pushed — the slip while settling on the mismatch is reported separately) and the true CoG back
within 5 mm of its pre-push position within 3 s of the end of the push.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..control.balance import MomentumBalance
from ..report.balance_figures import robust_push_location_figure, robust_push_summary_figure
from ..robot import Robot
from ..robots import load_robot, reference
from ..sim.mismatch import Mismatch
from ..sim.simulator import Simulator
from ..sim.true_com import TrueCoM
from ..sweep.executors import ordered, scenario_executor
from .base import (COP_MARGIN, ENGINE, INTEGRAL_LIMIT, PD_PARAMETERS, POSTURE_PARAMETERS,
                   Q_INTEGRAL, TIME_SPAN, Parameter, Scenario, ScenarioResult, duration_parameter,
                   parse_list)
from .conditions import job_observers
from .loop import run_closed_loop
from .measures import Thresholds, sole_slip, tilt_deg
from .pushes import (ANGULAR_WEIGHT, FIXED_PUSH, LOCATIONS, HumanoidScaled, check_locations,
                     check_push, controller_options, ignored_option_notes, make_push)

log = logging.getLogger(__name__)

#: Largest peak force (N) survived on the exact twin (front/back/left/right above the hip, 0.1 s
#: half-sine), measured with ``push`` in 10 N steps up to the first failure (LQR with
#: q_angular=10, this scenario's default).
#: The LQR values were measured with the paper's LQR (``q_integral=0``) and serve with integral
#: action too.
NOMINAL = {
    "pd": {"front": 190.0, "back": 180.0, "left": 250.0, "right": 260.0},
    "lqr": {"front": 190.0, "back": 180.0, "left": 310.0, "right": 310.0},
}
#: The same with the paper's single momentum weight (``--set angular_weight=1e4``), with the same
#: protocol as ``NOMINAL`` (``push``, 10 N steps up to the first failure, LQR with q_angular=10,
#: engine native). PD's first failures are foot slips with the CoG recovered; the LQR left/right
#: values include pushes survived with a few failed solver cycles, which ``push`` does not count
#: as failures.
NOMINAL_SINGLE_MOMENTUM_WEIGHT = {
    "pd": {"front": 150.0, "back": 130.0, "left": 210.0, "right": 200.0},
    "lqr": {"front": 100.0, "back": 220.0, "left": 330.0, "right": 330.0},
}

PARAMETERS = (
    Parameter("locations", "front,back,left,right", "comma-separated push points "
                                                    f"({', '.join(LOCATIONS)})",
              choices=tuple(LOCATIONS), items=str),
    Parameter("nominal_force", 0.0, "largest survived peak force on the exact twin (N); 0: the "
                                    "default per location and controller measured on talos14 "
                                    "(NOMINAL), times m / m_talos14", low=0.0),
    Parameter("fraction", 0.7, "the push is this fraction of the nominal force",
              low=0.0, low_open=True, high=10.0),
    Parameter("push_duration", 0.1, "push duration (s)",
              **TIME_SPAN),
    Parameter("seeds", 5, "number of mismatch draws per location", low=1, high=1000),
    Parameter("first_seed", 0, "seed of the first draw", low=0, high=2 ** 32 - 1),
    Parameter("mass_noise", 0.1, "link mass/inertia factor drawn in [1 - x, 1 + x]",
              low=0.0, high=1.0, high_open=True),
    Parameter("com_offset", HumanoidScaled(0.01, "m", height_power=1),
              "link CoM displacement (m), random direction",
              low=0.0, high=0.1 * Parameter.H),
    Parameter("torque_delay", "1,2", "torque delay in steps of 1 ms, cycled over the seeds",
              low=0, high=1000, items=int),
    Parameter("torque_noise", 1.0, "std of the Gaussian torque noise (Nm)", low=0.0),
    Parameter("start", 1.0, "time of the push (s); before it the robot settles on the mismatch",
              low=0.0, high=Parameter.MAX_TIME),
    duration_parameter(4.5, "simulated time per run (s)"),
    Parameter("baseline", True, "also run every mismatch draw without a push, to tell push "
                                "failures from the mismatch alone"),
    Parameter("q_angular", 10.0, "LQR weight on angular momentum (the nominal LQR forces were "
                                 "measured with 10; eq. 26 uses 0.1)", low=0.0, low_open=True),
    ANGULAR_WEIGHT,
    replace(Q_INTEGRAL, help=Q_INTEGRAL.help + ". NOMINAL was measured without it"),
    INTEGRAL_LIMIT,
    *PD_PARAMETERS,
    *POSTURE_PARAMETERS,
    COP_MARGIN,
    ENGINE,
    Parameter("workers", 1, "processes for the independent runs: 1 this process, N a local pool "
                            "of N, 0 one per core; same metrics", low=0, high=1024),
)

def nominal_force(controller: str, location: str, params: dict, robot) -> float:
    """The nominal largest survived peak force on ``robot``: ``--set nominal_force`` or the
    default measured on talos14 (``NOMINAL``; ``NOMINAL_SINGLE_MOMENTUM_WEIGHT`` with
    ``angular_weight=1e4``) times m / m_talos14, the same velocity change on any robot (exactly
    the measured force on talos14)."""
    if params["nominal_force"] > 0:
        return float(params["nominal_force"])
    table = (NOMINAL_SINGLE_MOMENTUM_WEIGHT if params.get("angular_weight") == 1e4 else NOMINAL)
    try:
        return table[controller][location] * reference.humanoid_mass_ratio(robot)
    except KeyError:
        raise ValueError(f"no measured nominal force for {controller} at '{location}' (known: "
                         f"{', '.join(NOMINAL.get(controller, {}))}); pass --set nominal_force=N"
                         ) from None


def mismatch_for(params: dict, i: int) -> Mismatch:
    """The i-th mismatch draw (seed ``first_seed + i``, delays cycled)."""
    delays = parse_list(params["torque_delay"], int, "torque_delay")
    return Mismatch(mass_noise=params["mass_noise"], com_offset=params["com_offset"],
                    torque_delay=delays[i % len(delays)], torque_noise=params["torque_noise"],
                    seed=int(params["first_seed"]) + i)


def validate(robot, params: dict) -> None:
    locations = parse_list(params["locations"], str, "locations")
    check_locations(locations)
    for controller in NOMINAL:  # every location has a nominal force, or --set nominal_force
        for location in locations:
            nominal_force(controller, location, params, robot)
    if not 0 < params["fraction"]:
        raise ValueError("--set fraction: must be > 0")
    if params["seeds"] < 1:
        raise ValueError("--set seeds: must be >= 1")
    if not params["start"] + params["push_duration"] < params["duration"]:
        raise ValueError("--set start/duration: the push must end before the run does")
    mismatch_for(params, 0)  # checks the mismatch values
    check_push(robot, {**FIXED_PUSH, "location": "front", "peak_force": 1.0,
                       "start": params["start"], "push_duration": params["push_duration"]})


def one_run(robot, controller: str, location: str, force: float, mismatch: Mismatch,
            params: dict, observers=None) -> dict:
    """One push on one mismatched twin; returns the metrics and the time series. ``observers``
    watch it (None: :func:`~wholebody.scenarios.conditions.job_observers`); under
    ``realism=robot`` the draw is on top of that level's twin (:meth:`Mismatch.on_top_of`)."""
    push = make_push({"location": location, "peak_force": force, "start": params["start"],
                      "push_duration": params["push_duration"]}, robot)
    ctrl = MomentumBalance(robot, gains=controller, **controller_options(controller, params))
    sim = Simulator(robot, mismatch=mismatch, record=False,
                    observers=job_observers(robot, params, observers), label=controller)
    sim.add_push(push)
    true_com = TrueCoM(sim)
    start_feet = sim.contact_frame_poses()
    t, com, model_com, tilt, slip, settle_slip, force_log = [], [], [], [], [], [], []
    feet_at_push = {n: pose[0] for n, pose in start_feet.items()}

    def observe(time, result):
        t.append(time)
        com.append(true_com())
        model_com.append(ctrl.com)  # the controller's estimate (nominal model)
        poses = sim.contact_frame_poses()
        tilt.append(max(tilt_deg(R) for _, R in poses.values()))
        if time < push.start:  # feet "in place" is judged from where they are when pushed
            feet_at_push.update({n: pose[0] for n, pose in poses.items()})
        slip.append(max(sole_slip(poses[n][0], feet_at_push[n]) for n in poses))
        settle_slip.append(max(sole_slip(poses[n][0], start_feet[n][0]) for n in poses))
        force_log.append(push.magnitude(time))

    failures = run_closed_loop(sim, ctrl, params["duration"], on_result=observe)
    t, com, model_com, tilt = np.array(t), np.array(com), np.array(model_com), np.array(tilt)
    before = (t >= push.start - 0.2) & (t < push.start)
    pre = com[before].mean(axis=0)
    err = np.linalg.norm(com - pre, axis=1)
    thresholds = Thresholds.for_robot(robot)  # the nominal robot's, as the controller's model
    recovered, recovery = thresholds.cog_recovered(t, err, push.start + push.duration)
    metrics = {
        "seed": mismatch.seed,
        "torque_delay_ms": sim.mismatch.torque_delay * sim.dt * 1e3,
        "true_mass_kg": true_com.mass,
        "peak_force_N": force,
        "impulse_Ns": push.impulse,
        "delta_v_mps": push.impulse / true_com.mass,
        "max_cog_error_m": float(err[t >= push.start].max()),
        "max_horizontal_cog_error_m": float(np.linalg.norm((com - pre)[t >= push.start, :2],
                                                           axis=1).max()),
        "final_vertical_cog_error_m": float((com - pre)[-1, 2]),
        "final_cog_error_m": float(err[-1]),
        "cog_recovery_time_s": recovery,
        "static_cog_offset_m": float(np.linalg.norm(pre - ctrl.com_ref)),
        "final_true_vs_reference_m": float(np.linalg.norm(com[-1] - ctrl.com_ref)),
        "final_model_vs_reference_m": float(np.linalg.norm(model_com[-1] - ctrl.com_ref)),
        "max_foot_tilt_deg": float(tilt[t >= push.start].max()),
        "max_foot_slip_m": float(max(slip)),
        "max_foot_tilt_before_push_deg": float(tilt[t < push.start].max()),
        "foot_slip_before_push_m": float(settle_slip[int(np.searchsorted(t, push.start)) - 1]),
        "max_foot_slip_from_start_m": float(max(settle_slip)),
        "failed_cycles": failures,
    }
    metrics["survived"] = bool(recovered and thresholds.feet_in_place(
        metrics["max_foot_tilt_deg"], metrics["max_foot_slip_m"]))
    return {"metrics": metrics, "t": t, "cog_error": com - pre, "push": np.array(force_log),
            "tilt": tilt}


def _run_job(job) -> dict:
    """:func:`one_run` of a job ``(robot, controller, location, force, mismatch, params,
    observers)``; the robot itself in this process, its description in a pool's worker."""
    robot, controller, location, force, mismatch, params, observers = job
    robot = robot if isinstance(robot, Robot) else load_robot(robot)
    return one_run(robot, controller, location, force, mismatch, params, observers)


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    locations = parse_list(params["locations"], str, "locations")
    seeds = range(int(params["seeds"]))
    shipped = robot if params["workers"] == 1 else robot.description
    watched = observers if params["workers"] == 1 else None  # see job_observers
    nominal = {loc: nominal_force(controller, loc, params, robot) for loc in locations}
    jobs = [(shipped, controller, loc, params["fraction"] * nominal[loc], mismatch_for(params, i),
             params, watched) for loc in locations for i in seeds]
    if params["baseline"]:  # the same draws, no push (a zero-force push keeps the timeline)
        jobs += [(shipped, controller, locations[0], 0.0, mismatch_for(params, i), params,
                  watched) for i in seeds]
    with scenario_executor(params["workers"]) as executor, \
            tqdm(total=len(jobs), disable=not progress, desc="mismatch runs", leave=False) as bar:
        results = ordered(executor, _run_job, jobs, progress=lambda i, r: bar.update(1))
    pushed = len(locations) * len(seeds)
    runs: dict[str, list[dict]] = {loc: [] for loc in locations}
    for k, r in enumerate(results[:pushed]):
        loc, i = locations[k // len(seeds)], seeds[k % len(seeds)]
        log.info("robust-push %s %s seed %d: %s", controller, loc, i, r["metrics"]["survived"])
        runs[loc].append(r)
    baseline = {r["metrics"]["seed"]: r["metrics"] for r in results[pushed:]}

    per_location = {}
    for loc, rs in runs.items():
        ms = [r["metrics"] for r in rs]
        per_location[loc] = {
            "nominal_force_N": nominal[loc],
            "peak_force_N": ms[0]["peak_force_N"],
            "impulse_Ns": ms[0]["impulse_Ns"],
            "success_rate": float(np.mean([m["survived"] for m in ms])),
            "max_cog_error_m": float(max(m["max_cog_error_m"] for m in ms)),
            "mean_max_cog_error_m": float(np.mean([m["max_cog_error_m"] for m in ms])),
            "max_final_cog_error_m": float(max(m["final_cog_error_m"] for m in ms)),
            "max_static_cog_offset_m": float(max(m["static_cog_offset_m"] for m in ms)),
            "survivors_max_cog_error_m": float(max(
                [m["max_cog_error_m"] for m in ms if m["survived"]] or [np.nan])),
            "runs": ms,
        }
    all_runs = [m for v in per_location.values() for m in v["runs"]]
    rate = float(np.mean([m["survived"] for m in all_runs]))
    metrics = {
        "success_rate": rate,
        "runs": len(all_runs),
        "survived": int(sum(m["survived"] for m in all_runs)),
        "max_cog_error_m": float(max(m["max_cog_error_m"] for m in all_runs)),
        "max_final_cog_error_m": float(max(m["final_cog_error_m"] for m in all_runs)),
        "per_location": per_location,
    }
    if baseline:
        metrics["without_push"] = {
            "stands_rate": float(np.mean([m["survived"] for m in baseline.values()])),
            "runs": {str(k): {key: m[key] for key in (
                "survived", "true_mass_kg", "max_cog_error_m", "final_vertical_cog_error_m",
                "max_foot_tilt_deg", "max_foot_slip_m", "static_cog_offset_m")}
                for k, m in baseline.items()},
        }
    notes = ignored_option_notes(controller, params)
    if rate < 1.0:
        lost = [f"{loc} seed {m['seed']}" for loc, v in per_location.items() for m in v["runs"]
                if not m["survived"]]
        notes.append(f"not survived at {params['fraction']:.0%} of the nominal push: "
                     f"{', '.join(lost)}")
    standing_fails = [k for k, m in baseline.items() if not m["survived"]]
    if standing_fails:
        notes.append(f"without any push, the criterion already fails for seeds {standing_fails} "
                     f"(the mismatch alone)")
    result = ScenarioResult("robust-push", robot.name, controller, rate == 1.0, metrics, params,
                            notes)
    if out_dir is not None:
        mismatch = (f"mass ±{params['mass_noise']:.0%}, CoM {100 * params['com_offset']:.0f} cm, "
                    f"delay {params['torque_delay']} ms, noise {params['torque_noise']} Nm")
        figures = [robust_push_location_figure(
            Path(out_dir) / f"robust_push_{loc}.png", rs,
            title=f"robust push {loc}, {rs[0]['metrics']['peak_force_N']:.0f} N "
                  f"({params['fraction']:.0%} of nominal) — {robot.name}, {controller}, {mismatch}",
            shaded=[(params["start"], params["start"] + params["push_duration"])])
            for loc, rs in runs.items()]
        figures.append(robust_push_summary_figure(
            Path(out_dir) / "robust_push_summary.png", locations, per_location,
            title=f"robust push — {robot.name}, {controller}, {int(params['seeds'])} mismatch "
                  f"draws per point"))
        result.figures = [str(f) for f in figures]
    return result


SCENARIO = Scenario(
    name="robust-push",
    summary="push recovery at 70 % of the nominal largest push on mismatched twins (link masses "
            "±10 %, CoM offsets 1 cm, 1-2 ms torque delay, torque noise), several seeds; CoG "
            "measured on the simulated robot's own CoM",
    parameters=PARAMETERS,
    controllers=("pd", "lqr"),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
    simulations=lambda params, controller: (
        len(parse_list(params["locations"], str, "locations")) + bool(params["baseline"]))
    * int(params["seeds"]),
)
