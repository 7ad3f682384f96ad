"""``weak-joint``: an artificial torque limit on one knee and the load redistribution it causes
(Fahmi et al. 2019, Sect. V-C, Fig. 3; torque limits of eq. 15).

The paper lowers the LF-KFE torque limit to 26 Nm in the WBC during a typical crawl: the KFE torque
is clamped at the limit, the HFE (and HAA) of the same leg take more load, and the trunk motion is
not affected.

Passive-WBC crawls at the same constant speed, same planner, same twin: ``nominal`` (the robot's
limits τ(q)), one with the paper's ``limit`` (26 Nm) and one per value of ``sweep``
(``torque_limit_override={joint: limit}``, i.e. |τ_joint| ≤ limit as a hard row of eq. 15). The
simulator keeps the real actuator limits: the weakness is the controller's knowledge, as in the
paper.

Measured on the simulator's own log: the torque it was sent and applied on the weak joint (must stay
within the limit), the amount it had to saturate to the real actuator limits
(``Simulator.last_clipped``), the leg's joint torques over its stance phases (mean |τ|), the trunk
tracking errors, the foot's MuJoCo contact-force direction. Also counted: cycles where the QP's own
eq. 19 torque left the limits and was clipped after the solve (a violated hard row, not a held
limit). A failed QP holds the previous torque (clipped to the limits), so a held limit alone does not
mean the robot coped: falls and failed cycles are reported next to it.

Success (at ``limit``): the nominal run and the limited run walk (no fall, every cycle solved); the
weak joint's sent and applied torques stay within the limit and nothing is clipped after a solve;
the leg's HFE and HAA carry more load than nominally; the trunk RMS errors grow by at most
``trunk_tolerance`` (m, rad). The same claims are reported for every ``sweep`` limit.

The stance (``knee_flexion``): every knee angle of the standing posture times this factor, the hip
flexion re-solved to keep each foot under the base (:func:`stance_posture`); every run starts from
it. How much the weak knee must carry is set by the posture: :func:`static_knee_torque` (a linear
program, independent of the controller) gives the smallest |τ| on the knee that any static force
distribution allows on each of the crawl's three-foot supports (friction pyramid, other joints
within their limits); the summary reports its worst support for the stance and for the standing
posture. On HyQ the standing posture (knee_flexion 1, shank 44° from vertical, steeper than the
friction pyramid allows a GRF to follow) needs 43 Nm: at 26 Nm the limit holds but the leg folds and
the robot falls. The default 0.8 (shank 36°) needs 14 Nm and walks at 26 Nm (docs/results.md).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

import pinocchio as pin

from ..guard import Outcome
from ..planning.planner import GaitPlanner
from ..robot import FREE_FLYER_NQ, FREE_FLYER_NV
from ..report.locomotion_figures import weak_joint_figure
from ..robots.roles import contact_roles, foot_of_joint, leg_joints, pitch_joints
from .base import Parameter, Scenario, ScenarioResult
from .gait_measures import intervals, outcome
from .locomotion import (CRAWL_SPEED, GAIT_SHAPE, RUN_DURATION, WBC_GAINS, check_joint,
                         check_positive, check_quadruped, gait_options, make_schedule,
                         parse_positive_floats, run_gait, steady_command, wbc_gains)

log = logging.getLogger(__name__)

PARAMETERS = (
    Parameter("joint", "", "the weakened joint (its leg's HAA/HFE are compared; empty: the "
                           "left-front knee)"),
    Parameter("limit", 26.0, "its torque limit in the WBC (Nm), symmetric", low=0.0, low_open=True),
    Parameter("knee_flexion", 0.8, "the stance: every knee angle of the standing posture times "
                                   "this, hips re-solved to keep the feet under the base (1: the "
                                   "robot's standing posture; below 1: a taller stance)",
              low=0.0, low_open=True, high=1.0),
    CRAWL_SPEED,
    RUN_DURATION,
    Parameter("sweep", "40,60", "further limits (Nm) run for comparison, comma-separated",
              low=0.0, low_open=True, items=float),
    Parameter("trunk_tolerance", 0.005, "allowed increase of the trunk RMS errors (m, rad)",
              low=0.0, low_open=True, high=1.0),
    *WBC_GAINS,
    *GAIT_SHAPE,
)


#: the labels of a leg's three joints, base first (hip abduction, hip flexion, knee flexion)
LEG_JOINT_LABELS = ("HAA", "HFE", "KFE")


def weakened_joint(robot, joint: str) -> str:
    """``joint``, or for "" the knee (last joint) of the left-front leg (Fig. 3: LF KFE)."""
    return joint or leg_joints(robot, contact_roles(robot)["left-front"])[-1]


def weak_leg(robot, joint: str) -> tuple[tuple[str, ...], str]:
    """(the three joints HAA/HFE/KFE of the leg that ``joint`` belongs to, base first, and its foot
    contact); ValueError naming ``--set joint`` unless it is a joint of a three-joint leg."""
    foot = foot_of_joint(robot, joint)
    joints = leg_joints(robot, foot) if foot is not None else ()
    if len(joints) == len(LEG_JOINT_LABELS):
        return joints, foot
    raise ValueError(f"--set joint: '{joint}' is not a joint of a three-joint leg (hip "
                     f"abduction, hip flexion, knee) with a foot contact; joints: "
                     f"{', '.join(robot.joint_names)}")


def stance_posture(robot, knee_flexion: float) -> np.ndarray:
    """The standing posture ``robot.q_ref`` with every leg's knee angle times ``knee_flexion``
    (1: the posture itself; below 1: straighter legs, a taller stance) and its hip flexion re-solved
    so that the foot stays at the same fore-aft position under the base; resting on the ground.
    Knee and hip flexion are a leg's last and first sagittal joints
    (:func:`~wholebody.robots.roles.pitch_joints`)."""
    q = robot.q_ref.copy()
    if knee_flexion == 1.0:
        return q
    model, data = robot.model, robot.model.createData()

    def foot_x(q, frame):
        pin.framesForwardKinematics(model, data, q)
        base = data.oMi[1]
        return float(base.actInv(data.oMf[frame]).translation[0])

    for contact in robot.contacts:
        sagittal = pitch_joints(robot, contact.name)
        if len(sagittal) < 2:
            raise ValueError(f"knee_flexion: the leg of '{contact.name}' has no hip and knee "
                             "flexion joints")
        hip, knee = (FREE_FLYER_NQ + robot.joint_names.index(j) for j, _ in
                     (sagittal[0], sagittal[-1]))
        x0 = foot_x(q, contact.frame_id)
        q[knee] *= knee_flexion
        for _ in range(20):  # Newton on the hip angle, numerical derivative
            r = foot_x(q, contact.frame_id) - x0
            if abs(r) < 1e-9:
                break
            q[hip] += 1e-6
            d = (foot_x(q, contact.frame_id) - x0 - r) / 1e-6
            q[hip] -= 1e-6 + r / d
    return robot.rest_on_ground(q)


def shank_angle_deg(robot, q, contact: str) -> float:
    """Angle of the knee-to-foot segment of ``contact``'s leg from the vertical (deg) at ``q``."""
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, q)
    knee = model.getJointId(leg_joints(robot, contact)[-1])
    d = data.oMf[robot.contact(contact).frame_id].translation - data.oMi[knee].translation
    return float(np.degrees(np.arctan2(np.linalg.norm(d[:2]), -d[2])))


def static_knee_torque(robot, q, joint: str, supports, mu: float | None = None) -> list[dict]:
    """The smallest |τ| of ``joint`` that any static contact force distribution allows, by linear
    programming (scipy ``linprog``; independent of the controller).

    At the posture ``q`` (leg Jacobians and gravity torques), for each support in ``supports``
    (``(contacts in stance, CoM horizontal offset from its position at q)``): the stance forces F
    balance gravity about the shifted CoM (Σ F = m g, Σ (p_i − c) × F_i = 0), lie in the friction
    pyramid μ (``mu`` None: the robot's) with F_z ≥ 0, every other joint's torque
    τ = g(q) − J_jᵀ F within its limit; minimise t with −t ≤ τ_joint ≤ t. Returns one
    ``{"stance", "min_abs_tau_Nm"}`` per support (``None``: infeasible)."""
    from scipy.optimize import linprog

    robot.update(q, np.zeros(robot.nv))
    mu = robot.friction if mu is None else float(mu)
    gravity = robot.h[FREE_FLYER_NV:].copy()
    limits = robot.torque_limits.upper(q[FREE_FLYER_NQ:])
    j = robot.joint_names.index(joint)
    weight = robot.mass * float(np.linalg.norm(robot.model.gravity.linear))
    out = []
    for stance, offset in supports:
        stance = list(stance)
        n = 3 * len(stance)
        Jt = np.vstack([robot.contact_jacobians[c][:3, FREE_FLYER_NV:] for c in stance]).T
        c = robot.com.copy()
        c[:2] += offset
        rel = np.array([robot.contact_points[robot.contact_names.index(s)] - c for s in stance])
        A_eq = np.zeros((6, n + 1))
        for i, r in enumerate(rel):
            A_eq[:3, 3 * i:3 * i + 3] = np.eye(3)
            A_eq[3:, 3 * i:3 * i + 3] = pin.skew(r)
        b_eq = np.array([0.0, 0.0, weight, 0.0, 0.0, 0.0])
        rows = []
        for i in range(len(stance)):
            for axis in (0, 1):
                for sign in (1.0, -1.0):
                    row = np.zeros(n + 1)
                    row[3 * i + axis], row[3 * i + 2] = sign, -mu
                    rows.append((row, 0.0))
        for k in range(robot.na):
            if k == j:
                continue
            rows.append((np.append(-Jt[k], 0.0), limits[k] - gravity[k]))  # τ_k ≤ limit
            rows.append((np.append(Jt[k], 0.0), limits[k] + gravity[k]))  # −τ_k ≤ limit
        rows.append((np.append(-Jt[j], -1.0), -gravity[j]))  # τ_j ≤ t
        rows.append((np.append(Jt[j], -1.0), gravity[j]))  # −τ_j ≤ t
        A_ub = np.array([r for r, _ in rows])
        b_ub = np.array([b for _, b in rows])
        cost = np.zeros(n + 1)
        cost[-1] = 1.0
        res = linprog(cost, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq,
                      bounds=[(None, None), (None, None), (0.0, None)] * len(stance) + [(0.0, None)])
        out.append({"stance": stance, "min_abs_tau_Nm": float(res.fun) if res.status == 0 else None})
    return out


def crawl_supports(robot, q, contact: str, speed: float, period_from: float = 2.0,
                   step: float = 0.02, shape: dict | None = None
                   ) -> list[tuple[tuple[str, ...], np.ndarray]]:
    """The three-foot supports of the crawl planned from ``q`` that include ``contact``, sampled
    every ``step`` s over one gait period from ``period_from`` s: (stance contacts, the planned
    CoM's horizontal offset from the stance feet's centroid minus that offset at ``q``), for
    :func:`static_knee_torque`."""
    planner = GaitPlanner.for_robot(robot, make_schedule(robot, "crawl", 1.0, shape),
                                    steady_command(speed), q=q, t0=0.0,
                                    **gait_options(robot, shape))
    legs = list(planner.legs)
    robot.update(q, np.zeros(robot.nv))
    at_q = {name: robot.contact_points[robot.contact_names.index(name)][:2] for name in legs}
    com_q = robot.com[:2].copy()
    out = []
    for t in np.arange(0.0, period_from + planner.schedule.period, step):
        plan = planner.update(t)
        if t < period_from:
            continue
        stance = [leg for leg, on in zip(legs, plan.contact) if on]
        if len(stance) != 3 or contact not in stance:
            continue
        feet = np.asarray(plan.foot_position, float).reshape(len(legs), 3)[:, :2]
        planned = np.asarray(plan.trunk.position, float)[:2] - feet[[legs.index(s) for s in stance]].mean(0)
        posture = com_q - np.mean([at_q[s] for s in stance], axis=0)
        out.append((tuple(stance), planned - posture))
    return out


def validate(robot, params: dict) -> None:
    check_quadruped(robot, "weak-joint")
    joint = weakened_joint(robot, params["joint"])
    check_joint(robot, joint)
    weak_leg(robot, joint)
    parse_positive_floats(params["sweep"], "sweep", allow_empty=True)
    check_positive(params, ("limit", "speed", "duration", "trunk_tolerance", "knee_flexion"))


def post_solve_clipped(solution) -> bool:
    """True for a cycle whose QP was solved but whose eq. 19 torque left the controller's limits by
    more than the solver's tolerance and was clipped by the output guard
    (:func:`~wholebody.guard.guard_torque` reports it as ``Outcome.CLIPPED``, reason
    "torque … Nm outside limits after solve; clipped"). Failed cycles (``HELD``: the previous torque,
    clipped as well) are counted as failed cycles, not here."""
    return solution.outcome is Outcome.CLIPPED


def weak_joint_runs(robot, joint: str, limits, speed: float, duration: float,
                    progress: bool = False, q0=None, controller_options: dict | None = None,
                    gains: dict | None = None, shape: dict | None = None,
                    observers=()) -> dict:
    """The nominal crawl and one crawl per torque limit of ``joint`` (see module docstring), from
    the configuration ``q0`` (default: the standing posture): name -> :class:`GaitRun`, each with
    ``post_solve_clips`` (cycles counted by :func:`post_solve_clipped`) and ``sim_saturation_max``
    (largest torque the simulator had to cut to the real actuator limits). ``controller_options``
    are passed to every run's controller; ``observers`` watch every run."""
    command = steady_command(speed)
    setups = [("nominal", {})] + [(f"limit {lim:g} Nm", {"torque_limit_override": {joint: lim}})
                                  for lim in limits]
    runs = {}
    for name, options in setups:
        seen = []
        runs[name] = run_gait(robot, "passive", "crawl", command, duration,
                              controller_options={**(controller_options or {}), **options},
                              progress=progress, q0=q0, gains=gains, shape=shape,
                              observers=observers,
                              on_cycle=lambda t, res, ctrl, sim, c=seen: c.append(
                                  (post_solve_clipped(res), float(np.abs(sim.last_clipped).max()))))
        runs[name].post_solve_clips = int(sum(c for c, _ in seen))
        runs[name].sim_saturation_max = float(max((s for _, s in seen), default=0.0))
    return runs


def leg_load(run, robot, joints: list[str], contact: str, t_from: float = 1.0,
             t_until: float = np.inf) -> dict:
    """Mean and peak |τ| of ``joints`` over the stance phases of ``contact`` (t_from ≤ t < t_until),
    from the torques the simulator applied, and the mean angle of the foot's measured contact force
    from the vertical."""
    sim = run.sim.log.arrays()
    t = sim["t"]
    leg = list(run.controller.planner.legs).index(contact)
    k = np.clip(np.searchsorted(run.log["t"], t, side="right") - 1, 0, len(run.log["t"]) - 1)
    stance = run.log["stance"][k, leg].astype(bool) & (t >= t_from) & (t < t_until)
    idx = [robot.joint_names.index(j) for j in joints]
    tau = np.abs(sim["tau_applied"][stance][:, idx])
    ci = robot.contact_names.index(contact)
    f = sim["contact_wrenches"][stance, ci, :3]
    loaded = f[:, 2] > 20.0
    angle = np.degrees(np.arctan2(np.linalg.norm(f[loaded, :2], axis=1), f[loaded, 2]))
    return {"mean_abs_tau_Nm": dict(zip(joints, tau.mean(axis=0))),
            "peak_abs_tau_Nm": dict(zip(joints, tau.max(axis=0))),
            "grf_angle_from_vertical_mean_deg": float(angle.mean()) if loaded.any() else None,
            "stance_time_s": float(stance.sum() * run.sim.dt)}


def torque_limits(params: dict) -> list[float]:
    """The knee's torque limits of the runs: ``limit``, then the ``sweep``'s others."""
    sweep = parse_positive_floats(params["sweep"], "sweep", allow_empty=True)
    return [params["limit"]] + [x for x in sweep if x != params["limit"]]


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    p = params
    joint, limit = weakened_joint(robot, p["joint"]), p["limit"]
    joints, contact = weak_leg(robot, joint)
    limits = torque_limits(p)
    q0 = stance_posture(robot, p["knee_flexion"])
    statics = {}
    for label, q in (("stance", q0), ("standing posture", robot.q_ref)):
        lp = [r["min_abs_tau_Nm"] for r in static_knee_torque(
            robot, q, joint, crawl_supports(robot, q, contact, p["speed"], shape=p))]
        statics[label] = {"shank_from_vertical_deg": shank_angle_deg(robot, q, contact),
                          "base_height_m": float(q[2]),
                          "static_min_abs_tau_Nm": max((x for x in lp if x is not None),
                                                       default=None),
                          "infeasible_supports": sum(x is None for x in lp)}
    runs = weak_joint_runs(robot, joint, limits, p["speed"], p["duration"], progress, q0=q0,
                           gains=wbc_gains(p), shape=p, observers=observers)
    j = robot.joint_names.index(joint)
    metrics = {"static_lp": statics}
    for name, r in runs.items():
        sim = r.sim.log.arrays()
        failed = np.flatnonzero(~r.log["ok"].astype(bool))
        until = float(r.log["t"][failed[0]]) if len(failed) else float(np.inf)
        metrics[name] = {
            **outcome(r), **r.tracking(t_from=1.0),
            f"{joint}_max_abs_sent_Nm": float(np.abs(sim["tau_command"][:, j]).max()),
            f"{joint}_max_abs_applied_Nm": float(np.abs(sim["tau_applied"][:, j]).max()),
            f"{joint}_time_at_or_above_{limit:g}Nm_s": float(
                np.sum(np.abs(sim["tau_applied"][:, j]) > limit - 0.1) * r.sim.dt),
            "post_solve_clipped_cycles": r.post_solve_clips,
            "simulator_saturation_max_Nm": r.sim_saturation_max,
            "first_failed_cycle_s": until if len(failed) else None,
            "leg_load_in_stance": leg_load(r, robot, joints, contact, t_until=until),
        }
    nom = metrics["nominal"]
    hfe, haa = joints[1], joints[0]
    load_n = nom["leg_load_in_stance"]
    claims_by_limit = {}
    for lim in limits:
        m = metrics[f"limit {lim:g} Nm"]
        load_w = m["leg_load_in_stance"]
        change = {jn: load_w["mean_abs_tau_Nm"][jn] - load_n["mean_abs_tau_Nm"][jn] for jn in joints}
        m["stance_mean_abs_tau_change_Nm"] = change
        m["trunk_rms_increase"] = {"linear_m": m["linear_rms_m"] - nom["linear_rms_m"],
                                   "angular_rad": m["angular_rms_rad"] - nom["angular_rms_rad"]}
        claims_by_limit[f"{lim:g} Nm"] = {
            "limit holds (sent and applied torque, no post-solve clip)": bool(
                m[f"{joint}_max_abs_sent_Nm"] <= lim + 1e-6
                and m[f"{joint}_max_abs_applied_Nm"] <= lim + 1e-6
                and m["post_solve_clipped_cycles"] == 0),
            "walks (no fall, every cycle solved)": bool(not m["fell"] and m["failed_cycles"] == 0),
            "HFE loaded more": bool(change[hfe] > 0),
            "HAA loaded more": bool(change[haa] > 0),
            "trunk unaffected": bool(
                m["trunk_rms_increase"]["linear_m"] <= p["trunk_tolerance"]
                and m["trunk_rms_increase"]["angular_rad"] <= p["trunk_tolerance"]),
            "limit active (nominal peak above it)": bool(nom[f"{joint}_max_abs_applied_Nm"] > lim),
        }
    metrics["claims"] = claims_by_limit
    head = claims_by_limit[f"{limit:g} Nm"]
    success = (not nom["fell"] and nom["failed_cycles"] == 0
               and all(v for k, v in head.items()))
    notes = [f"{label} (knee_flexion {1.0 if label != 'stance' else p['knee_flexion']:g}): "
             f"shank {st['shank_from_vertical_deg']:.1f} deg from vertical, base "
             f"{st['base_height_m']:.3f} m; static LP: the crawl's worst three-foot support "
             f"needs |tau| >= "
             + (f"{st['static_min_abs_tau_Nm']:.1f} Nm" if st["static_min_abs_tau_Nm"] is not None
                else "(infeasible)") + f" on {joint} (friction {robot.friction:g})"
             for label, st in statics.items()]
    notes += [f"{joint} nominal: peak {nom[f'{joint}_max_abs_applied_Nm']:.1f} Nm, mean over the "
              f"{contact} stance {load_n['mean_abs_tau_Nm'][joint]:.1f} Nm (the paper's nominal "
              "value is not given; its limit is 26 Nm)"]
    for lim in limits:
        m = metrics[f"limit {lim:g} Nm"]
        lw = m["leg_load_in_stance"]
        notes.append(
            f"limit {lim:g} Nm: fell={m['fell']}, failed cycles {m['failed_cycles']}"
            + (f" (first at {m['first_failed_cycle_s']:.2f} s; loads below up to then)"
               if m["first_failed_cycle_s"] is not None else "") + f", {joint} peak "
            f"sent {m[f'{joint}_max_abs_sent_Nm']:.2f} / applied {m[f'{joint}_max_abs_applied_Nm']:.2f}"
            " Nm; stance mean |tau| nominal -> limited: " + ", ".join(
                f"{label} {load_n['mean_abs_tau_Nm'][jn]:.1f} -> "
                f"{lw['mean_abs_tau_Nm'][jn]:.1f}" for label, jn in zip(LEG_JOINT_LABELS, joints))
            + f" Nm; trunk RMS linear {nom['linear_rms_m'] * 1e3:.2f} -> {m['linear_rms_m'] * 1e3:.2f}"
            f" mm, angular {nom['angular_rms_rad'] * 1e3:.2f} -> {m['angular_rms_rad'] * 1e3:.2f} "
            f"mrad; {contact} GRF angle from vertical {load_n['grf_angle_from_vertical_mean_deg']:.1f}"
            f" -> {lw['grf_angle_from_vertical_mean_deg']:.1f} deg")
    notes.append(f"paper (Sect. V-C, Fig. 3): at 26 Nm the KFE is clamped, HFE loaded more, trunk "
                 f"unaffected. Here at {limit:g} Nm: limit held "
                 f"{head['limit holds (sent and applied torque, no post-solve clip)']}, HFE loaded "
                 f"more {head['HFE loaded more']}, walks {head['walks (no fall, every cycle solved)']}"
                 f", trunk unaffected {head['trunk unaffected']}")
    figures = []
    if out_dir is not None:
        nominal = runs["nominal"]
        leg = list(nominal.controller.planner.legs).index(contact)
        swing = intervals(nominal.log["t"], ~nominal.log["stance"][:, leg].astype(bool)
                          & (nominal.log["t"] >= 1.0))
        figures.append(str(weak_joint_figure(
            Path(out_dir) / "weak_joint.png", robot.name, runs,
            {jn: robot.joint_names.index(jn) for jn in joints}, joints, limits[0], contact,
            p["speed"], swing)))
    return ScenarioResult("weak-joint", robot.name, controller, success, metrics, params, notes,
                          figures=figures)


SCENARIO = Scenario(
    name="weak-joint",
    summary="Sect. V-C / Fig. 3: HyQ crawl with the LF-KFE torque limit lowered to 26 Nm in the "
            "WBC: limit held, HFE/HAA take more load, trunk motion unaffected (vs nominal run)",
    parameters=PARAMETERS,
    controllers=("passive",),
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
    simulations=lambda params, controller: len(torque_limits(params)) + 1,
)
