"""Figures of the quadruped scenarios in the style of Fahmi et al. 2019 (Sect. V,
Figs. 2-8): PNGs drawn from gait-run logs (headless pyplot of :mod:`wholebody.report.plots`).

Each function takes what the scenario measured (runs, logs, series, shaded intervals) and a path,
draws, saves and returns the path; none of them measures or judges anything.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from .plots import plt, save_figure, time_series_figure

def crawl_tracking_figure(path: Path, runs: dict, title: str) -> Path:
    """Fig. 5 style: ‖e_x‖ and ‖e_θ‖ of every run (name -> GaitRun) on the shared time axis."""
    t = next(iter(runs.values())).log["t"]
    n = min(len(r.log["t"]) for r in runs.values())
    panels = [("linear trunk error (Fig. 5 top)", "||e_x|| (m)",
               {k: np.linalg.norm(r.log["com_error"][:n], axis=1) for k, r in runs.items()}),
              ("angular trunk error (Fig. 5 bottom)", "||e_theta|| (rad)",
               {k: np.linalg.norm(r.log["orientation_error"][:n], axis=1)
                for k, r in runs.items()})]
    return time_series_figure(path, t[:n], panels, title)


def friction_mismatch_figure(path: Path, robot_name: str, runs: dict, stance_speed: dict,
                             floor_mu: float, controller_mu: float) -> Path:
    """Sect. V-B: the largest stance contact-point speed (``stance_speed``: name -> per-cycle
    series, impact excluded) and the CoM error of every run (name -> GaitRun)."""
    n = min(len(r.log["t"]) for r in runs.values())
    t = next(iter(runs.values())).log["t"][:n]
    first = ("mismatch", "mismatch, no stance task")
    rest = [k for k in runs if k.startswith(("corrected", "reference"))]
    panels = [
        (f"floor mu {floor_mu}, WBC mu {controller_mu}: stance task on/off (eq. 32)",
         "slip speed (m/s)", {k: np.minimum(stance_speed[k], 1.0) for k in first}),
        ("WBC mu corrected (plain pyramid with either regulariser, inscribed pyramid); "
         "matched-floor reference", "slip speed (m/s)",
         {k: stance_speed[k] for k in rest}),
        ("CoM tracking error", "||e_x|| (m)",
         {k: np.minimum(np.linalg.norm(r.log["com_error"][:n], axis=1), 0.1)
          for k, r in runs.items()}),
    ]
    return time_series_figure(path, t, panels, f"{robot_name} crawl on a slippery floor (Sect. V-B): "
                                               "largest contact-point speed of the stance feet")


def weak_joint_figure(path: Path, robot_name: str, runs: dict, joint_index: dict, joints: list[str],
                      limit: float, contact: str, speed: float, swing) -> Path:
    """Fig. 3 style: the weak joint's applied torque with its limit, then HFE and HAA, every run
    (name -> GaitRun; ``joints`` = HAA, HFE, KFE names, ``joint_index`` name -> torque index);
    ``swing`` intervals of the leg shaded."""
    sims = {k: r.sim.log.arrays() for k, r in runs.items()}
    n = min(len(s["t"]) for s in sims.values())
    t = sims["nominal"]["t"][:n]
    kfe = joints[2]
    series = {k: s["tau_applied"][:n, joint_index[kfe]] for k, s in sims.items()}
    series[f"+{limit:g} Nm"] = np.full(n, limit)
    panels = [(f"{kfe} torque applied in the twin", "tau (Nm)", series)]
    for jn in (joints[1], joints[0]):
        panels.append((f"{jn} torque", "tau (Nm)",
                       {k: s["tau_applied"][:n, joint_index[jn]] for k, s in sims.items()}))
    return time_series_figure(path, t, panels, f"{robot_name} crawl {speed} m/s, {kfe} torque limited "
                              f"in the WBC (Fig. 3; shaded: {contact} swing)", shaded=swing)


def joint_limit_figure(path: Path, robot_name: str, reference, shown: dict, leg: int, q_index: int,
                       limit: float, joint: str, contact: str, low_alpha: float, shaded) -> Path:
    """Fig. 2 style: the foot's X, Y, Z (the planner's reference of ``reference``, the simulator's of
    every ``shown`` run), the joint (configuration index ``q_index``) against the controller's
    ``limit``, the trunk orientation error; ``shaded`` intervals (slack active)."""
    n = min(len(x.log["t"]) for x in (reference, *shown.values()))
    t = reference.log["t"][:n]
    panels = []
    for axis, name in enumerate("XYZ"):
        series = {"reference": reference.log["foot_ref"][:n, leg, axis]}
        series.update({k: x.log["feet"][:n, leg, axis] for k, x in shown.items()})
        panels.append((f"{contact} {name}", f"{name.lower()} (m)", series))
    sim_t = reference.sim.log.arrays()["t"]
    k = np.clip(np.searchsorted(sim_t, t), 0, len(sim_t) - 1)
    joint_series = {name: x.sim.log.arrays()["q"][k, q_index] for name, x in shown.items()}
    joint_series["controller limit"] = np.full(n, limit)
    panels.append((f"{joint} position", "q (rad)", joint_series))
    panels.append(("trunk orientation error", "||e_theta|| (rad)",
                   {name: np.linalg.norm(x.log["orientation_error"][:n], axis=1)
                    for name, x in shown.items()}))
    return time_series_figure(path, t, panels, f"{robot_name} crawl, {joint} limit changed in the WBC "
                              f"(Fig. 2; shaded: slack active, alpha={low_alpha:g})",
                              shaded=shaded)


def passivity_figure(path: Path, storage: dict, balance: dict, title: str, tolerance: float,
                     shaded) -> Path:
    """Sect. III: the storage function's parts (eq. 23), its rate against the supply and the margin
    against the predicted dissipation (eq. 31); ``shaded``: the intervals whose violation exceeds
    ``tolerance`` (W)."""
    tb = balance["t"]
    margin = balance["supply"] - balance["Vdot"]
    V0 = storage["V_gravity"][0]
    panels = [
        ("storage function V (eq. 23)", "J",
         {"V_com,K (position)": storage["V_position"],
          "V_com,K (orientation)": storage["V_orientation"],
          "V_com,g = m g dz": storage["V_gravity"] - V0,
          "V_sw (Lambda K_sw)": storage["V_swing"]}),
        ("rate vs supply (eq. 31)", "W",
         {"dV/dt": _smooth(balance["Vdot"]), "supply dq_j^T tau": _smooth(balance["supply"])}),
        (f"margin supply - dV/dt vs predicted dissipation (grey: violations > {tolerance:.0f} W)",
         "W",
         {"margin": _smooth(margin), "dissipation (eq. 31)": balance["dissipation"]}),
    ]
    n = len(tb)
    panels = [(a, b, {k: (v[:n] if len(v) > n else v) for k, v in s.items()}) for a, b, s in panels]
    return time_series_figure(path, tb, panels, title, shaded=shaded)


def _smooth(x: np.ndarray, n: int = 5) -> np.ndarray:
    """Centred moving average over n samples (display only)."""
    x = np.nan_to_num(x)
    return np.convolve(x, np.ones(n) / n, mode="same")


def regularization_figure(path: Path, robot_name: str, weights, force_normal: dict, sweep: dict, gait: str,
                          other_weight: float) -> Path:
    """Sect. V-D: GRF angle (from the vertical and from the knee direction) and mean joint torques
    against the KFE weight (log axis); the force-normal scheme as horizontal lines."""
    fn, s = force_normal, sweep
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 5.6))
    ax1.semilogx(weights, s["grf_angle_from_vertical_deg"], "o-", label="from vertical, torque")
    ax1.semilogx(weights, s["grf_angle_to_knee_deg"], "s--", label="from knee direction, torque")
    ax1.axhline(fn["grf_angle_from_vertical_deg"], color="k", lw=0.8,
                label="from vertical, force-normal")
    ax1.set_ylabel("GRF angle (deg)")
    ax1.set_title("simulator contact forces, mean over the feet", fontsize=9)
    ax2.semilogx(weights, s["mean_abs_tau_kfe_Nm"], "o-", label="KFE, torque")
    ax2.semilogx(weights, s["mean_abs_tau_hfe_Nm"], "s-", label="HFE, torque")
    ax2.axhline(fn["mean_abs_tau_kfe_Nm"], color="k", lw=0.8, label="KFE, force-normal")
    ax2.set_ylabel("mean |tau| (Nm)")
    ax2.set_xlabel("KFE weight of R_tau (other joints: %g)" % other_weight)
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"{robot_name} {gait}: torque regularisation (Sect. V-D, footnote 16)", fontsize=10)
    return save_figure(fig, path)


def unstable_foothold_figure(path: Path, robot_name: str, contact: str, disturbed, reference,
                             sim: dict, leg: int, gait: str, depth: float, release: float,
                             window: float) -> Path:
    """Fig. 6 style: CoM x, y, z (reference and simulator, stone rolling and still), the disturbed
    foot's height and normal force (``sim``: the disturbed run's simulator log, ``leg`` its contact
    index); the window [release, release + window] shaded."""
    t = disturbed.log["t"]
    com, ref = disturbed.log["com"], disturbed.log["com_ref"]
    fig, axes = plt.subplots(5, 1, sharex=True, figsize=(8, 9))
    for k, name in enumerate("xyz"):
        ax = axes[k]
        ax.plot(t, ref[:, k], "k--", linewidth=1.0, label="desired")
        ax.plot(t, com[:, k], color="tab:blue", linewidth=1.0, label="actual (stone rolls)")
        tr = reference.log["t"]
        ax.plot(tr, reference.log["com"][:, k], color="tab:green", linewidth=0.8, alpha=0.6,
                label="actual (stone still)")
        ax.set_ylabel(f"CoM {name} (m)", fontsize=8)
    ax = axes[3]
    ax.plot(t, disturbed.log["feet"][:, leg, 2], color="tab:orange", label=f"{contact} height")
    ax.set_ylabel(f"{contact} z (m)", fontsize=8)
    ax = axes[4]
    ax.plot(sim["t"], sim["contact_wrenches"][:, leg, 2], color="tab:red", linewidth=0.8,
            label=f"{contact} normal force (simulator)")
    ax.set_ylabel(f"{contact} f_z (N)", fontsize=8)
    ax.set_xlabel("time (s)")
    for ax in axes:
        ax.axvspan(release, release + window, color="tab:red", alpha=0.12, zorder=0)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    fig.suptitle(f"{robot_name} {gait}: a {100 * depth:.0f} cm stone rolls away under "
                 f"{contact} at {release} s (cf. Fig. 6; red: disturbance window)", fontsize=10)
    return save_figure(fig, path)


def ramp_figure(path: Path, robot_name: str, t, desired, actual, com, course, gait: str, speed: float,
                angle_deg: float, band: float) -> Path:
    """Fig. 8 style: roll and pitch, desired vs actual (± ``band`` around the desired), and the
    course height under the CoM with the CoM height."""
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6.5))
    for ax, k, name in ((axes[0], 0, "roll"), (axes[1], 1, "pitch")):
        ax.plot(t, desired[:, k], "k--", linewidth=1.0, label="desired")
        ax.plot(t, actual[:, k], color="tab:blue", linewidth=1.0, label="actual (simulator)")
        ax.fill_between(t, desired[:, k] - band, desired[:, k] + band,
                        color="0.9", zorder=0, label=f"±{band:g} rad")
        ax.set_ylabel(f"{name} (rad)", fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper right", ncol=3)
    axes[2].plot(t, [course.height(x, 0.0) for x in com[:, 0]], color="0.4",
                 label="terrain under the CoM")
    axes[2].plot(t, com[:, 2], color="tab:green", label="CoM height")
    axes[2].set_ylabel("z (m)", fontsize=8)
    axes[2].set_xlabel("time (s)")
    axes[2].grid(True, alpha=0.3)
    axes[2].legend(fontsize=7)
    fig.suptitle(f"{robot_name} {gait} {speed} m/s over a {angle_deg:.0f} deg ramp: roll and "
                 "pitch tracking (Fig. 8)", fontsize=10)
    return save_figure(fig, path)


def course_side_view(path: Path, robot, gait_run, course, title: str, snapshots: int = 6) -> Path:
    """Fig. 7 style side view: the course, the CoM path, the feet paths and stick-figure snapshots
    of the robot, all from the simulator. A leg is drawn from its foot up two joints of the
    kinematic tree (knee, hip); left legs solid, right legs dashed (side of the foot in the base
    frame of the reference posture)."""
    sim_log = gait_run.sim.log
    qs = np.asarray(sim_log.q)
    ts = np.asarray(sim_log.t)
    L = gait_run.log
    model, data = robot.model, robot.model.createData()
    legs = _leg_chains(robot, data, gait_run.controller.planner.legs)
    x_lo = float(min(L["feet"][:, :, 0].min(), 0.0)) - 0.3
    x_hi = float(L["feet"][:, :, 0].max()) + 0.3
    fig, ax = plt.subplots(figsize=(10, 3.8))
    xs, zs = course.profile(x_lo, x_hi)
    surface = [course.height(x) for x in np.linspace(x_lo, x_hi, 400) if not course.in_gap(x)]
    z_lo = min(surface) - 0.25  # holes are drawn down to here
    ax.fill_between(xs, np.maximum(zs, z_lo), z_lo, color="0.85")
    ax.plot(xs, zs, color="0.3", linewidth=1.0)
    ax.plot(L["com"][:, 0], L["com"][:, 2], color="tab:green", linewidth=1.0, label="CoM")
    colors = ("tab:blue", "tab:orange", "tab:purple", "tab:red")
    for i, (name, *_) in enumerate(legs):
        ax.plot(L["feet"][:, i, 0], L["feet"][:, i, 2], color=colors[i % len(colors)],
                linewidth=0.6, alpha=0.7, label=name)
    times = np.linspace(ts[0] + 1.0, ts[-1], snapshots)
    for k, tk in enumerate(times):
        q = qs[min(int(np.searchsorted(ts, tk)), len(qs) - 1)]
        pin.framesForwardKinematics(model, data, q)
        shade = 0.15 + 0.6 * k / max(1, snapshots - 1)
        hips = []
        for _, foot, knee, hip, left in legs:
            pts = np.array([data.oMi[hip].translation, data.oMi[knee].translation,
                            data.oMf[foot].translation])
            hips.append(pts[0])
            ax.plot(pts[:, 0], pts[:, 2], "-" if left else "--", color=str(1 - shade),
                    linewidth=1.2)
        hips = np.array(hips)
        ax.plot([hips[:, 0].min(), hips[:, 0].max()],
                [hips[np.argmin(hips[:, 0]), 2], hips[np.argmax(hips[:, 0]), 2]],
                color=str(1 - shade), linewidth=3.0, solid_capstyle="round")
        ax.annotate(f"{tk:.0f} s", (hips[:, 0].mean(), hips[:, 2].max() + 0.06), fontsize=7,
                    ha="center", color=str(1 - shade))
    ax.set_aspect("equal")
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(z_lo, float(L["com"][:, 2].max()) + 0.2)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.legend(fontsize=6, loc="upper left", ncol=5)
    ax.set_title(title, fontsize=9)
    return save_figure(fig, path)


def _leg_chains(robot, data, names) -> list[tuple[str, int, int, int, bool]]:
    """Per contact of ``names`` (the log's foot order): (name, foot frame id, knee joint id = the
    foot's parent joint, hip joint id = the knee's parent, whether the foot is on the left of the
    base in the reference posture)."""
    model = robot.model
    pin.framesForwardKinematics(model, data, robot.q_ref)
    base = data.oMi[1]
    chains = []
    for name in names:
        foot = robot.contact(name).frame_id
        knee = model.frames[foot].parentJoint
        left = bool(base.actInv(data.oMf[foot]).translation[1] > 0.0)
        chains.append((name, foot, knee, model.parents[knee], left))
    return chains


def steer_figure(path: Path, t, velocity, yaw_rate, command, valid, reference, yaw, heading,
                 path_xy, reference_xy, parts, title: str) -> Path:
    """The ``steer`` scenario: commanded vs measured gait-period means of the heading-frame
    velocity (forward, lateral; dotted: the CoM reference's) and of the yaw rate, the heading, and a top view of the CoM path
    against the reference's. ``valid``: the samples whose mean window lies inside the run;
    ``parts``: (name, start, end) of the command schedule, marked on the time axes."""
    fig = plt.figure(figsize=(12, 7.5))
    grid = fig.add_gridspec(3, 2, width_ratios=(1.4, 1.0))
    axes = [fig.add_subplot(grid[k, 0]) for k in range(3)]
    top = fig.add_subplot(grid[:, 1])
    tv = np.where(valid, t, np.nan)
    for k, (name, colour) in enumerate((("forward", "tab:blue"), ("lateral", "tab:orange"))):
        axes[0].plot(t, command[:, k], "--", color=colour,
                     linewidth=1.0, label=f"{name} commanded")
        axes[0].plot(tv, reference[:, k], ":", color=colour, linewidth=1.0,
                     label=f"{name} CoM reference")
        axes[0].plot(tv, velocity[:, k], color=colour, linewidth=1.2, label=f"{name} measured")
    axes[0].set_ylabel("m/s", fontsize=8)
    axes[0].set_title("heading-frame CoM velocity (gait-period means)", fontsize=9)
    axes[1].plot(t, command[:, 2], "k--", linewidth=1.0, label="commanded")
    axes[1].plot(tv, yaw_rate, color="tab:green", linewidth=1.2, label="measured")
    axes[1].set_ylabel("rad/s", fontsize=8)
    axes[1].set_title("yaw rate (gait-period means)", fontsize=9)
    axes[2].plot(t, np.degrees(heading), "k--", linewidth=1.0, label="commanded")
    axes[2].plot(t, np.degrees(yaw), color="tab:red", linewidth=1.2, label="measured (base)")
    axes[2].set_ylabel("deg", fontsize=8)
    axes[2].set_title("heading", fontsize=9)
    axes[2].set_xlabel("time (s)")
    for ax in axes:
        for name, start, end in parts:
            ax.axvline(start, color="0.6", linewidth=0.6, linestyle=":")
            ax.text(0.5 * (start + end), 1.0, name, transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=7, color="0.4")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, ncol=2, loc="best")
    top.plot(reference_xy[:, 0], reference_xy[:, 1], "k--", linewidth=1.0, label="CoM reference")
    top.plot(path_xy[:, 0], path_xy[:, 1], color="tab:blue", linewidth=1.2, label="CoM measured")
    for name, start, _ in parts:
        k = min(int(np.searchsorted(t, start)), len(t) - 1)
        top.plot(path_xy[k, 0], path_xy[k, 1], "o", color="tab:blue", markersize=3)
        top.annotate(name, path_xy[k], fontsize=7, color="0.3", xytext=(3, 3),
                     textcoords="offset points")
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.set_title("top view", fontsize=9)
    top.grid(True, alpha=0.3)
    top.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)
