"""``joint-limit``: a joint limit that the swing motion runs into, softened swing tasks (Fahmi et
al. 2019, Sect. IV-B eq. 33, Sect. V-A, Fig. 2; joint limits as acceleration bounds, eqs. 16-18).

The paper "artificially incremented the lower limit of the LH-HFE joint" in the WBC: when the limit
is hit, the acceleration bound of eq. 18 stops the joint, which stays clamped at the limit, while the
swing task's slacks absorb the conflict; the foot tracking suffers mainly in X and Z (the HFE acts in
the sagittal plane), not in Y. One slack per direction keeps Y unaffected; a single slack per foot
"couples the three directions causing tracking errors also in the Y direction".

Here the limit is raised **in the controller only**: :func:`controller_joint_limits` replaces the
robot's ``q_min``/``q_max`` arrays (read by
:class:`~wholebody.tasks.limits.JointAccelerationLimits`, eq. 18 with Δt = 10 dt) for the duration of
the runs, while the MuJoCo twin is built from the Pinocchio model's own limits
(``model.lowerPositionLimit``), so the simulated joint keeps its real range — the raised limit is a
controller-side constraint, as in the paper's simulation. The scenario records the twin's joint range
to show it.

Runs, all at the same constant crawl speed, for two slack weights α of eq. 33, each set relative to
the trunk wrench task (:func:`~wholebody.control.passive.relative_slack_weight`: α = ratio · max(Q)
· m², ratio 1 weighing a foot acceleration error as the same acceleration error of the robot's CoM):
``slack_ratio`` (default 1e-4, α ≈ 0.75 on HyQ) and, for comparison, ``high_slack_ratio`` (default
1, α ≈ 7.5e3 on HyQ, close to the PassiveWBC default 1e4 and to the paper's "high weight"):
``nominal`` (real limits, per-direction slacks),
then the changed limit with ``swing_slack`` = ``per-direction`` (one slack per direction: the
weighted least-squares term α‖J q̈ − b‖²) and ``single`` (one slack per foot: |J q̈ − b|_∞ ≤ ε);
plus one run with ``none`` (hard swing equality, eq. 11; a failed QP is flagged, ``ok`` False, and
holds the previous torque).

Measured on the simulator: the joint's position against the changed limit, the foot's position
(foot frame) against the planner's reference during the leg's swing phases, per axis, relative to
the nominal run of the same α; the trunk orientation error; falls. The controller's swing-task
residual |J q̈ + J̇ v − v̇_d| (the slack) shades the figure where it is active.

Which task gives way is set by α against the trunk-wrench weight Q (eq. 7a): the base is a free
variable of the QP, so a swing foot can keep its reference by moving the trunk, and tilting the
trunk is cheap (its rotational inertia over the leg length squared is far below its mass). At
ratio 1 the foot error barely changes and the trunk tilts to keep the foot on its reference (the
hard swing task is feasible for the same reason); at the default ratio 1e-4 the trunk is not
disturbed and the foot error grows instead, as in Fig. 2, the single slack spreading it over X, Y
and Z (the numbers are in docs/results.md).

Success: for both ratios the per-direction run solves every cycle without falling and the joint
reaches the changed limit (within ``at_limit``) without going more than ``overshoot`` beyond it;
at ``slack_ratio`` the trunk's angular RMS error grows by at most ``trunk_tolerance``. The
direction claims are measured per ratio and reported in ``claims``.
"""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path

import numpy as np

from ..control.passive import relative_slack_weight
from ..report.locomotion_figures import joint_limit_figure
from ..robot import FREE_FLYER_NQ
from ..robots.roles import contact_roles, foot_of_joint, leg_joints
from .base import TIME_SPAN, Parameter, Scenario, ScenarioResult
from .gait_measures import intervals, outcome
from .locomotion import (CRAWL_SPEED, GAIT_SHAPE, WBC_GAINS, check_joint, check_positive,
                         check_quadruped, run_gait, steady_command, wbc_gains)

log = logging.getLogger(__name__)

PARAMETERS = (
    Parameter("joint", "", "the joint whose limit is changed in the controller (empty: the "
                           "left-hind hip flexion, the second joint of that leg; Fig. 2: LH HFE)"),
    Parameter("side", "lower", "which of its limits is changed: lower or upper",
              choices=("lower", "upper")),
    Parameter("limit", -0.85, "the changed limit in the controller (rad), inside the real range",
              low=-np.pi, high=np.pi),
    CRAWL_SPEED,
    Parameter("duration", 8.5, "simulated time per run (s); the crawl starts at 1 s",
              **TIME_SPAN),
    Parameter("slack_ratio", 1e-4, "slack weight alpha of eq. 33 relative to the trunk task: "
                                   "alpha = ratio * max(Q) * mass^2", low=0.0, low_open=True),
    Parameter("high_slack_ratio", 1.0, "a higher ratio, run for comparison (1: alpha ~ the "
                                       "PassiveWBC default 1e4 on HyQ)", low=0.0, low_open=True),
    Parameter("trunk_tolerance", 0.005, "allowed increase of the trunk angular RMS error at "
                                        "slack_ratio (rad)", low=0.0, low_open=True, high=1.0),
    Parameter("at_limit", 0.01, "joint within this of the raised limit counts as 'at the limit' (rad)",
              low=0.0, low_open=True, high=np.pi),
    Parameter("overshoot", 0.02, "allowed excursion beyond the raised limit (rad)",
              low=0.0, low_open=True, high=np.pi),
    Parameter("slack_active", 0.5, "swing residual (m/s^2) above which the slack is 'active' "
                                   "(figure shading, time counts)", low=0.0, low_open=True),
    *WBC_GAINS,
    *GAIT_SHAPE,
)


@contextlib.contextmanager
def controller_joint_limits(robot, joint: str, lower: float | None = None,
                            upper: float | None = None):
    """Within the block, ``robot.q_min``/``q_max`` (the controller's joint limits, eq. 18) have
    ``joint``'s bounds replaced; the Pinocchio model (from which the twin is built) is untouched.
    The original arrays are restored on exit."""
    if joint not in robot.joint_names:
        raise ValueError(f"unknown joint '{joint}'; joints: {', '.join(robot.joint_names)}")
    i = robot.joint_names.index(joint)
    saved = robot.q_min, robot.q_max
    q_min, q_max = robot.q_min.copy(), robot.q_max.copy()
    if lower is not None and np.isfinite(lower):
        q_min[i] = lower
    if upper is not None and np.isfinite(upper):
        q_max[i] = upper
    if not q_min[i] < q_max[i]:
        raise ValueError(f"{joint}: limits would be empty ({q_min[i]} >= {q_max[i]})")
    robot.q_min, robot.q_max = q_min, q_max
    try:
        yield q_min[i], q_max[i]
    finally:
        robot.q_min, robot.q_max = saved


def limited_joint(robot, joint: str) -> str:
    """``joint``, or for "" the hip flexion (second joint) of the left-hind leg."""
    return joint or leg_joints(robot, contact_roles(robot)["left-hind"])[1]


def validate(robot, params: dict) -> None:
    check_quadruped(robot, "joint-limit")
    joint = limited_joint(robot, params["joint"])
    check_joint(robot, joint)
    if foot_of_joint(robot, joint) is None:
        raise ValueError(f"--set joint: '{joint}' is not a joint of a leg with a foot contact")
    i = robot.joint_names.index(joint)
    if params["side"] not in ("lower", "upper"):
        raise ValueError(f"--set side: expected lower or upper, got '{params['side']}'")
    if not robot.q_min[i] < params["limit"] < robot.q_max[i]:
        raise ValueError(f"--set limit: must lie inside the real range [{robot.q_min[i]:.3f}, "
                         f"{robot.q_max[i]:.3f}] of {joint}, got {params['limit']}")
    check_positive(params, ("speed", "duration", "at_limit", "overshoot", "slack_active",
                            "slack_ratio", "high_slack_ratio", "trunk_tolerance"))


def limit_run(robot, joint: str, lower, upper, slack: str, speed: float, duration: float,
              slack_weight: float = 1e4, progress: bool = False, gains: dict | None = None,
              shape: dict | None = None, observers=()):
    """One crawl with ``joint``'s limits replaced in the controller (None: real limits);
    ``gains``: the controller's gains (:func:`~wholebody.scenarios.locomotion.wbc_gains`);
    ``shape``: the gait's step height and period
    (:data:`~wholebody.scenarios.locomotion.GAIT_SHAPE`); ``observers`` watch the simulation.

    Returns the :class:`GaitRun` with two extra per-cycle arrays in its log: ``foot_ref`` (legs, 3)
    the planner's foot references and ``swing_residual`` (legs,) the swing-task residuals."""
    command = steady_command(speed)
    refs, residuals = [], []
    legs = None

    def record(t, result, ctrl, sim):
        nonlocal legs
        legs = legs or list(ctrl.planner.legs)
        refs.append(np.array(ctrl.last_plan.foot_position, dtype=float).reshape(len(legs), 3))
        res = np.zeros(len(legs))
        for report in result.tasks:
            if report.name.startswith("swing "):
                res[legs.index(report.name[6:])] = report.error
        residuals.append(res)

    ctx = (controller_joint_limits(robot, joint, lower, upper)
           if lower is not None or upper is not None else contextlib.nullcontext())
    with ctx:
        r = run_gait(robot, "passive", "crawl", command, duration,
                     controller_options={"swing_slack": slack, "slack_weight": slack_weight},
                     on_cycle=record, progress=progress, gains=gains, shape=shape,
                     observers=observers)
    r.log["foot_ref"] = np.array(refs)
    r.log["swing_residual"] = np.array(residuals)
    return r


def swing_tracking(run, leg: int, t_from: float = 1.0) -> dict:
    """RMS and max of (reference − simulator foot position) per axis over the leg's swing cycles."""
    L = run.log
    swing = ~L["stance"][:, leg].astype(bool) & (L["t"] >= t_from)
    err = L["foot_ref"][swing, leg] - L["feet"][swing, leg]
    if not swing.any():
        return {"rms_m": [0.0, 0.0, 0.0], "max_m": [0.0, 0.0, 0.0]}
    return {"rms_m": np.sqrt(np.mean(err ** 2, axis=0)), "max_m": np.abs(err).max(axis=0)}


def run_metrics(r, i: int, leg: int, lim_lo: float, lim_hi: float, p: dict) -> dict:
    """Simulator-side measures of one run (see module docstring)."""
    qs = r.sim.log.arrays()["q"][:, FREE_FLYER_NQ + i]
    beyond = float(max((lim_lo - qs).max(), (qs - lim_hi).max()))
    at = (np.abs(qs - lim_lo) < p["at_limit"]) | (np.abs(qs - lim_hi) < p["at_limit"])
    tr = swing_tracking(r, leg)
    res = r.log["swing_residual"][:, leg]
    period = float(np.median(np.diff(r.log["t"])))
    return {**outcome(r), **r.tracking(t_from=1.0),
            "joint_min_rad": float(qs.min()), "joint_max_rad": float(qs.max()),
            "beyond_controller_limit_max_rad": beyond,
            "time_at_limit_s": float(at.sum() * r.sim.dt),
            "swing_error_rms_xyz_m": np.asarray(tr["rms_m"]),
            "swing_error_max_xyz_m": np.asarray(tr["max_m"]),
            "slack_active_time_s": float(np.sum(res > p["slack_active"]) * period),
            "swing_residual_max": float(res.max())}


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    p = params
    joint = limited_joint(robot, p["joint"])
    i = robot.joint_names.index(joint)
    contact = foot_of_joint(robot, joint)
    lower = p["limit"] if p["side"] == "lower" else None
    upper = p["limit"] if p["side"] == "upper" else None
    real = (float(robot.q_min[i]), float(robot.q_max[i]))
    lim_lo = lower if lower is not None else -np.inf
    lim_hi = upper if upper is not None else np.inf
    alphas = {"low": relative_slack_weight(robot, p["slack_ratio"]),
              "high": relative_slack_weight(robot, p["high_slack_ratio"])}
    ratios = {"low": p["slack_ratio"], "high": p["high_slack_ratio"]}
    runs = {}
    for key, alpha in alphas.items():
        runs[(key, "nominal")] = limit_run(robot, joint, None, None, "per-direction", p["speed"],
                                           p["duration"], alpha, progress, wbc_gains(p), p,
                                           observers)
        for mode in ("per-direction", "single"):
            log.info("joint-limit: %s limit changed, swing_slack=%s, alpha=%g", joint, mode, alpha)
            runs[(key, mode)] = limit_run(robot, joint, lower, upper, mode, p["speed"],
                                          p["duration"], alpha, progress, wbc_gains(p), p,
                                          observers)
    runs[("hard", "none")] = limit_run(robot, joint, lower, upper, "none", p["speed"],
                                       p["duration"], alphas["high"], progress,
                                       wbc_gains(p), p, observers)
    some = runs[("high", "per-direction")]
    leg = list(some.controller.planner.legs).index(contact)
    sim_model = some.sim.model
    sim_range = sim_model.jnt_range[sim_model.joint(joint).id].tolist()
    metrics = {"controller_limits_rad": [lim_lo if lower is not None else real[0],
                                         lim_hi if upper is not None else real[1]],
               "real_limits_rad": list(real), "simulator_joint_range_rad": sim_range}
    claims, notes = {}, [f"{joint} limits in the controller {metrics['controller_limits_rad']}, "
                         f"in the twin {[round(x, 3) for x in sim_range]} (the real ones)"]
    fmt = lambda v: "/".join(f"{1e3 * x:.1f}" for x in v)  # noqa: E731
    for key, alpha in alphas.items():
        block = {name: run_metrics(runs[(key, name)], i, leg, lim_lo, lim_hi, p)
                 for name in ("nominal", "per-direction", "single")}
        nom = block["nominal"]
        for name in ("per-direction", "single"):
            m = block[name]
            m["swing_error_rms_increase_xyz_m"] = m["swing_error_rms_xyz_m"] - nom["swing_error_rms_xyz_m"]
            m["trunk_angular_rms_increase_rad"] = m["angular_rms_rad"] - nom["angular_rms_rad"]
        pd, single = block["per-direction"], block["single"]
        inc = pd["swing_error_rms_increase_xyz_m"]
        label = f"ratio={ratios[key]:g}"
        metrics[label] = block
        block["alpha"] = alpha
        claims[label] = {
            "slack absorbs the conflict (no failed cycle, no fall)":
                bool(pd["failed_cycles"] == 0 and not pd["fell"]),
            "joint clamped at the changed limit": bool(
                pd["time_at_limit_s"] > 0 and pd["beyond_controller_limit_max_rad"] <= p["overshoot"]),
            "foot error grows mainly in X and Z, not Y (per-direction)":
                bool(inc[0] > 2 * max(inc[1], 0.0) and inc[2] > 2 * max(inc[1], 0.0)
                     and max(inc[0], inc[2]) > 1e-3),
            "single slack couples error into Y": bool(
                single["swing_error_rms_increase_xyz_m"][1] > inc[1] + 1e-3),
            "trunk not disturbed (per-direction)": bool(
                pd["trunk_angular_rms_increase_rad"] <= p["trunk_tolerance"]),
        }
        for name in ("nominal", "per-direction", "single"):
            m = block[name]
            notes.append(
                f"{label} (alpha {alpha:.3g}), {name}: {joint} min {m['joint_min_rad']:.3f} rad (at the limit "
                f"{m['time_at_limit_s']:.2f} s), {contact} swing error RMS x/y/z "
                f"{fmt(m['swing_error_rms_xyz_m'])} mm, trunk angular RMS/max "
                f"{m['angular_rms_rad'] * 1e3:.1f}/{m['angular_max_rad'] * 1e3:.0f} mrad, failed "
                f"cycles {m['failed_cycles']}, fell={m['fell']}")
    for key, alpha in alphas.items():
        label = f"ratio={ratios[key]:g}"
        block = metrics[label]
        inc = block["per-direction"]["swing_error_rms_increase_xyz_m"]
        inc_s = block["single"]["swing_error_rms_increase_xyz_m"]
        notes.append(
            f"paper (Fig. 2, Sect. IV-B): foot error mainly in X and Z, single slack couples Y. "
            f"Here, {label} (alpha {alpha:.3g}): RMS increase x/y/z per-direction {fmt(inc)} mm, single "
            f"{fmt(inc_s)} mm, trunk angular RMS +"
            f"{block['per-direction']['trunk_angular_rms_increase_rad'] * 1e3:.1f} mrad"
            + (" -- the trunk, not the foot, gives way" if max(inc) < 1e-3 else ""))
    hard = run_metrics(runs[("hard", "none")], i, leg, lim_lo, lim_hi, p)
    metrics["hard swing task (none)"] = hard
    claims["hard swing task gives infeasible cycles"] = bool(hard["failed_cycles"] > 0)
    notes.append(f"hard swing task: failed cycles {hard['failed_cycles']}, fell={hard['fell']}, "
                 f"{joint} min {hard['joint_min_rad']:.3f}, trunk angular RMS/max "
                 f"{hard['angular_rms_rad'] * 1e3:.1f}/{hard['angular_max_rad'] * 1e3:.0f} mrad: the "
                 "floating base takes the swing task's conflict (feasible), the trunk pays")
    metrics["claims"] = claims
    success = (all(claims[f"ratio={r:g}"]["slack absorbs the conflict (no failed cycle, no fall)"]
                   and claims[f"ratio={r:g}"]["joint clamped at the changed limit"]
                   for r in ratios.values())
               and claims[f"ratio={ratios['low']:g}"]["trunk not disturbed (per-direction)"])
    figures = []
    if out_dir is not None:
        low = runs[("low", "per-direction")]
        shown = {f"per-direction, alpha={alphas['low']:.3g}": low,
                 f"single, alpha={alphas['low']:.3g}": runs[("low", "single")],
                 f"per-direction, alpha={alphas['high']:.3g}": runs[("high", "per-direction")]}
        n = min(len(x.log["t"]) for x in runs.values())
        active = low.log["swing_residual"][:n, leg] > p["slack_active"]
        figures.append(str(joint_limit_figure(
            Path(out_dir) / "joint_limit.png", robot.name, low, shown, leg, FREE_FLYER_NQ + i,
            lim_lo if np.isfinite(lim_lo) else lim_hi, joint, contact, alphas["low"],
            intervals(low.log["t"][:n], active))))
    return ScenarioResult("joint-limit", robot.name, controller, success, metrics, params, notes,
                          figures=figures)


SCENARIO = Scenario(
    name="joint-limit",
    summary="Sect. V-A / Fig. 2: LH-HFE lower limit raised in the WBC: the swing slacks absorb the "
            "conflict, the joint stays at the limit, foot error mainly in X and Z; per-direction vs "
            "single slack vs hard swing task",
    parameters=PARAMETERS,
    controllers=("passive",),
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
    simulations=7,
)
