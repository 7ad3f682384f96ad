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

On the HyQ preset the nominal LF-KFE torque of this crawl is well above 26 Nm, so at the paper's
limit the limit itself holds and HFE/HAA do take more load, but the front-left leg folds and the
robot falls (docs/results.md). The paper does not give its nominal knee torque; see the summary
notes.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..guard import Outcome
from ..report.locomotion_figures import weak_joint_figure
from ..robots.roles import contact_roles, foot_of_joint, leg_joints
from .base import Parameter, Scenario, ScenarioResult
from .gait_measures import intervals, outcome
from .locomotion import (CRAWL_SPEED, RUN_DURATION, check_joint, check_positive, check_quadruped,
                         parse_positive_floats, run_gait, steady_command)

log = logging.getLogger(__name__)

PARAMETERS = (
    Parameter("joint", "", "the weakened joint (its leg's HAA/HFE are compared; empty: the "
                           "left-front knee)"),
    Parameter("limit", 26.0, "its torque limit in the WBC (Nm), symmetric", low=0.0, low_open=True),
    CRAWL_SPEED,
    RUN_DURATION,
    Parameter("sweep", "40,60", "further limits (Nm) run for comparison, comma-separated",
              low=0.0, low_open=True, items=float),
    Parameter("trunk_tolerance", 0.005, "allowed increase of the trunk RMS errors (m, rad)",
              low=0.0, low_open=True, high=1.0),
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


def validate(robot, params: dict) -> None:
    check_quadruped(robot, "weak-joint")
    joint = weakened_joint(robot, params["joint"])
    check_joint(robot, joint)
    weak_leg(robot, joint)
    parse_positive_floats(params["sweep"], "sweep", allow_empty=True)
    check_positive(params, ("limit", "speed", "duration", "trunk_tolerance"))


def weak_joint_runs(robot, joint: str, limits, speed: float, duration: float,
                    progress: bool = False) -> dict:
    """The nominal crawl and one crawl per torque limit of ``joint`` (see module docstring):
    name -> :class:`GaitRun`, each with ``post_solve_clips`` (cycles whose eq. 19 torque left the
    limits and was clipped after the solve) and ``sim_saturation_max`` (largest torque the simulator
    had to cut to the real actuator limits)."""
    command = steady_command(speed)
    setups = [("nominal", {})] + [(f"limit {lim:g} Nm", {"torque_limit_override": {joint: lim}})
                                  for lim in limits]
    runs = {}
    for name, options in setups:
        seen = []
        runs[name] = run_gait(robot, "passive", "crawl", command, duration,
                              controller_options=options, progress=progress,
                              on_cycle=lambda t, res, ctrl, sim, c=seen: c.append(
                                  (res.outcome is Outcome.CLIPPED,
                                   float(np.abs(sim.last_clipped).max()))))
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


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool) -> ScenarioResult:
    p = params
    joint, limit = weakened_joint(robot, p["joint"]), p["limit"]
    joints, contact = weak_leg(robot, joint)
    sweep = parse_positive_floats(p["sweep"], "sweep", allow_empty=True)
    limits = [limit] + [x for x in sweep if x != limit]
    runs = weak_joint_runs(robot, joint, limits, p["speed"], p["duration"], progress)
    j = robot.joint_names.index(joint)
    metrics = {}
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
    notes = [f"{joint} nominal: peak {nom[f'{joint}_max_abs_applied_Nm']:.1f} Nm, mean over the "
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
            Path(out_dir) / "weak_joint.png", runs,
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
)
