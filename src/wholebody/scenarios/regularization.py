"""``regularization``: the two force-regularisation schemes of the passive WBC (Fahmi et al. 2019,
Sect. V-D, footnote 16; the ‖u‖²_R term of eq. 7a).

* ``force-normal``: the tangential components of each stance force are penalised, so the ground
  reaction forces stay close to the cone normals (robustness to a wrong friction estimate);
* ``torque``: the joint torques produced by the contact forces are penalised with per-joint weights,
  R_F = J_st,j R_τ J_st,jᵀ (footnote 16). The paper: "If we gradually increase the weight of the
  Knee Flexion-Extension (KFE) joints, [...] the GRFs are no longer vertical. Indeed the GRFs start
  to point toward the knee axis in order to reduce its torque command." (video only, no numbers).

The robot stands on all four feet (or crawls, ``--set gait=crawl``) once with ``force-normal`` and
then with ``torque`` for each KFE weight of the sweep (the other joints keep ``other_weight``). The
internal forces (those that leave the trunk wrench unchanged) are what the regulariser selects.

Measured on the simulator over the last ``window`` seconds of each run, averaged over the stance
feet: the angle of the MuJoCo contact force from the vertical, the mean |τ| it applied to the KFE
(and HFE) joints, and the angle between the contact force and the foot-to-knee-axis direction (the
GRF "pointing toward the knee": 0 deg when its line of action passes through the knee axis, which
zeroes the knee torque the force causes).

Success: every cycle solved, no fall; over the torque-scheme sweep the mean GRF angle from the
vertical grows and the mean |τ_KFE| drops from the smallest to the largest KFE weight; the
force-normal scheme gives a GRF angle no larger than the torque scheme's at the largest weight.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..report.locomotion_figures import regularization_figure
from ..robots.roles import joint_axis, leg_joints
from .base import TIME_SPAN, Parameter, Scenario, ScenarioResult
from .locomotion import (GAIT_SHAPE, WBC_GAINS, PaperSpeed, check_gait, check_quadruped,
                         parse_positive_floats, run_gait, steady_command, wbc_gains)

log = logging.getLogger(__name__)

PARAMETERS = (
    Parameter("kfe_weights", "1e-4,1e-3,1e-2,3e-2,1e-1,1", "comma-separated KFE weights of R_tau",
              low=0.0, low_open=True, items=float),
    Parameter("other_weight", 1e-4, "R_tau weight of the HAA and HFE joints",
              low=0.0, low_open=True),
    Parameter("gait", "stand", "stand or crawl", choices=("stand", "crawl")),
    Parameter("speed", PaperSpeed(0.11), "crawl speed (m/s) when gait=crawl", low=0.0, high=5.0),
    Parameter("duration", 2.0, "simulated time per run (s)",
              **TIME_SPAN),
    Parameter("window", 0.5, "averaging window at the end of each run (s)",
              **TIME_SPAN),
    *WBC_GAINS,
    *GAIT_SHAPE,
)


def validate(robot, params: dict) -> None:
    check_quadruped(robot, "regularization")
    if any(len(leg_joints(robot, foot)) < 2 for foot in robot.contact_names):
        raise ValueError(f"robot '{robot.name}': a leg with fewer than two joints has no hip "
                         f"flexion and knee to compare")
    parse_positive_floats(params["kfe_weights"], "kfe_weights")
    check_gait(params, ("stand", "crawl"))
    if not (params["other_weight"] > 0 and params["duration"] > params["window"] > 0):
        raise ValueError("--set other_weight > 0 and duration > window > 0 required")


def knee_joints(robot, contact: str) -> tuple[str, str]:
    """(hip flexion, knee): the last two joints of ``contact``'s leg."""
    hfe, kfe = leg_joints(robot, contact)[-2:]
    return hfe, kfe


def grf_measures(run, robot, window: float) -> dict:
    """Simulator-side averages over the last ``window`` s: per stance foot, the contact force's angle
    from the vertical, its angle to the foot->knee-axis direction, and |τ| on HFE and KFE."""
    sim = run.sim.log.arrays()
    t, q = sim["t"], sim["q"]
    sel = np.flatnonzero(t >= t[-1] - window)
    data = robot.model.createData()
    angles, to_knee, tau_kfe, tau_hfe = [], [], [], []
    for k in sel[::10]:
        pin.forwardKinematics(robot.model, data, q[k])
        pin.updateFramePlacements(robot.model, data)
        for ci, name in enumerate(robot.contact_names):
            f = sim["contact_wrenches"][k, ci, :3]
            if f[2] < 20.0:
                continue
            hfe, kfe = knee_joints(robot, name)
            jid = robot.model.getJointId(kfe)
            knee = data.oMi[jid]
            axis = knee.rotation @ joint_axis(robot, kfe)
            foot = data.oMf[robot.contact(name).frame_id].translation
            lever = knee.translation - foot
            lever -= axis * (axis @ lever)  # foot -> knee axis, perpendicular to the axis
            fp = f - axis * (axis @ f)  # force in the plane normal to the knee axis
            angles.append(np.degrees(np.arctan2(np.linalg.norm(f[:2]), f[2])))
            to_knee.append(np.degrees(np.arccos(np.clip(
                fp @ lever / (np.linalg.norm(fp) * np.linalg.norm(lever)), -1.0, 1.0))))
            tau_kfe.append(abs(sim["tau_applied"][k, robot.joint_names.index(kfe)]))
            tau_hfe.append(abs(sim["tau_applied"][k, robot.joint_names.index(hfe)]))
    return {"grf_angle_from_vertical_deg": float(np.mean(angles)),
            "grf_angle_to_knee_deg": float(np.mean(to_knee)),
            "mean_abs_tau_kfe_Nm": float(np.mean(tau_kfe)),
            "mean_abs_tau_hfe_Nm": float(np.mean(tau_hfe))}


def regularization_run(robot, scheme: str, weights: np.ndarray | None, params: dict,
                       progress: bool = False, observers=()):
    """One run with ``regularization=scheme`` (and ``torque_weights`` for the torque scheme),
    watched by ``observers``."""
    options = {"regularization": scheme}
    if weights is not None:
        options["torque_weights"] = weights
    command = steady_command(params["speed"]) if params["gait"] == "crawl" else None
    return run_gait(robot, "passive", params["gait"], command, params["duration"],
                    controller_options=options, progress=progress, gains=wbc_gains(params),
                    shape=params, observers=observers)


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    p = params
    kfe_weights = parse_positive_floats(p["kfe_weights"], "kfe_weights")
    knees = {knee_joints(robot, foot)[1] for foot in robot.contact_names}
    kfe = np.array([j in knees for j in robot.joint_names])
    runs, metrics = {}, {}
    runs["force-normal"] = regularization_run(robot, "force-normal", None, p, progress,
                                                observers)
    for w in kfe_weights:
        weights = np.where(kfe, w, p["other_weight"])
        runs[f"torque, w_kfe={w:g}"] = regularization_run(robot, "torque", weights, p, progress,
                                                                observers)
    for name, r in runs.items():
        metrics[name] = {"fell": r.fell, "failed_cycles": int(np.sum(~r.log["ok"].astype(bool))),
                         **grf_measures(r, robot, p["window"]), **r.tracking(t_from=0.5)}
    sweep = [metrics[f"torque, w_kfe={w:g}"] for w in kfe_weights]
    angle = [m["grf_angle_from_vertical_deg"] for m in sweep]
    tau = [m["mean_abs_tau_kfe_Nm"] for m in sweep]
    metrics["sweep"] = {"kfe_weight": kfe_weights, "grf_angle_from_vertical_deg": angle,
                        "mean_abs_tau_kfe_Nm": tau,
                        "grf_angle_to_knee_deg": [m["grf_angle_to_knee_deg"] for m in sweep],
                        "mean_abs_tau_hfe_Nm": [m["mean_abs_tau_hfe_Nm"] for m in sweep]}
    solved = all(not m["fell"] and m["failed_cycles"] == 0
                 for k, m in metrics.items() if k != "sweep")
    fn = metrics["force-normal"]
    metrics["claims"] = {
        "GRF angle grows with the KFE weight": bool(angle[-1] > angle[0]),
        "GRF angle monotone over the sweep (0.2 deg tolerance)":
            bool(np.all(np.diff(angle) > -0.2)),
        "KFE torque drops with the KFE weight": bool(tau[-1] < tau[0]),
        "force-normal keeps the GRFs closest to vertical":
            bool(fn["grf_angle_from_vertical_deg"] <= angle[-1]),
    }
    success = solved and angle[-1] > angle[0] and tau[-1] < tau[0] and \
        fn["grf_angle_from_vertical_deg"] <= angle[-1]
    notes = [f"force-normal: GRF {fn['grf_angle_from_vertical_deg']:.1f} deg from vertical, "
             f"|tau_KFE| {fn['mean_abs_tau_kfe_Nm']:.1f} Nm"]
    notes += [f"torque, w_KFE={w:g}: GRF {a:.1f} deg from vertical, {m['grf_angle_to_knee_deg']:.1f}"
              f" deg from the knee direction, |tau_KFE| {tq:.1f} Nm, |tau_HFE| "
              f"{m['mean_abs_tau_hfe_Nm']:.1f} Nm" for w, a, tq, m in zip(kfe_weights, angle, tau, sweep)]
    notes.append("paper (Sect. V-D, video only): as the KFE weight grows the GRFs leave the "
                 "vertical and point toward the knee axis to reduce its torque. Here: GRF angle "
                 f"{angle[0]:.1f} -> {angle[-1]:.1f} deg from vertical, "
                 f"{sweep[0]['grf_angle_to_knee_deg']:.1f} -> {sweep[-1]['grf_angle_to_knee_deg']:.1f}"
                 f" deg from the foot-knee direction, |tau_KFE| {tau[0]:.1f} -> {tau[-1]:.1f} Nm "
                 f"over KFE weights {kfe_weights[0]:g} -> {kfe_weights[-1]:g}")
    figures = []
    if out_dir is not None:
        figures.append(str(regularization_figure(
            Path(out_dir) / "regularization.png", robot.name, kfe_weights, metrics["force-normal"],
            metrics["sweep"], p["gait"], p["other_weight"])))
    return ScenarioResult("regularization", robot.name, controller, success, metrics, params,
                          notes, figures=figures)


SCENARIO = Scenario(
    name="regularization",
    summary="Sect. V-D: force-normal vs torque-minimising regularisation; GRF angle and KFE torque "
            "as the KFE weight of R_tau grows (HyQ standing or crawling)",
    parameters=PARAMETERS,
    controllers=("passive",),
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
    simulations=lambda params, controller: 1 + len(parse_positive_floats(params["kfe_weights"], "kfe_weights")),
)
