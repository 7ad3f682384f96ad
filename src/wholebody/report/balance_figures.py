"""Figures of the humanoid scenarios (Herzog et al. 2016 Figs. 5-11): pushes, push series, robust
pushes, moving supports, squat, single support, stepping timing, standing."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .plots import grouped_bar_figure, save_figure, time_series_figure  # noqa: E402


def _short(contact: str) -> str:
    """One-letter label of a contact (L, R)."""
    return contact.split("_")[0][0].upper()


def push_figure(path: Path, t, push_force, cog_error, momentum, title: str, shaded=()) -> Path:
    """One push (Sect. 5.2.2): push force, CoG error, linear and angular momentum."""
    return time_series_figure(
        path, t,
        [("push force", "N", {"|F|": np.linalg.norm(push_force, axis=1)}),
         ("CoG error", "cm", {a: 100 * cog_error[:, i] for i, a in enumerate("xyz")}),
         ("linear momentum", "N s", {a: momentum[:, i] for i, a in enumerate("xyz")}),
         ("angular momentum", "N m s", {a: momentum[:, 3 + i] for i, a in enumerate("xyz")})],
        title=title, shaded=shaded)


def push_series_figure(path: Path, trials, locations, controllers, robot_name: str) -> Path:
    """Fig. 6 style: peak force vs max CoG error and max angular momentum, per controller.
    ``trials``: (controller, location, force, survived, metrics) tuples."""
    fig, axes = plt.subplots(4, 1, figsize=(7, 10), sharex=True)
    for row, (key, label, scale) in enumerate((("max_cog_error_m", "max CoG error (cm)", 100.0),
                                              ("max_angular_momentum_Nms", "max ang. mom. (N m s)",
                                               1.0))):
        for col, c in enumerate(controllers):
            ax = axes[2 * row + col]
            for loc in locations:
                pts = [(t[2], scale * t[4][key], t[3]) for t in trials if t[0] == c and t[1] == loc]
                ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=loc, markersize=4)
                fell = [p for p in pts if not p[2]]
                if fell:
                    ax.plot([p[0] for p in fell], [p[1] for p in fell], "kx", markersize=8)
            ax.set_ylabel(label, fontsize=8)
            ax.set_title(f"{c.upper()} momentum gains (x = fell)", fontsize=9)
            ax.grid(True, alpha=0.3)
            ax.set_yscale("log")
    axes[0].legend(fontsize=7, ncol=4)
    axes[-1].set_xlabel("peak force (N)")
    fig.suptitle(f"push series — {robot_name}", fontsize=10)
    return save_figure(fig, path)


def robust_push_location_figure(path: Path, runs: list[dict], title: str, shaded=()) -> Path:
    """The mismatch draws of one push point: push force, true CoG error (horizontal, vertical),
    largest foot tilt. ``runs``: dicts with "t", "push", "cog_error", "tilt" and "metrics"."""
    seed = lambda r: f"seed {r['metrics']['seed']}"  # noqa: E731
    return time_series_figure(
        path, runs[0]["t"],
        [("push force", "N", {"|F|": runs[0]["push"]}),
         ("true CoG error from its pre-push position (horizontal norm, clipped at 5 cm)", "cm",
          {seed(r) + ("" if r["metrics"]["survived"] else " (failed)"):
           np.minimum(100 * np.linalg.norm(r["cog_error"][:, :2], axis=1), 5.0) for r in runs}),
         ("true CoG error, vertical (clipped at ±5 cm)", "cm",
          {seed(r): np.clip(100 * r["cog_error"][:, 2], -5, 5) for r in runs}),
         ("largest foot tilt (simulator; 2 deg = failure; clipped at 10)", "deg",
          {seed(r): np.minimum(r["tilt"], 10.0) for r in runs})],
        title=title, shaded=shaded)


def robust_push_summary_figure(path: Path, locations, per_location: dict, title: str) -> Path:
    """Success rate, the survivors' max CoG error and the peak force per push point."""
    return grouped_bar_figure(
        path, locations,
        {"success rate (%)": [100 * per_location[loc]["success_rate"] for loc in locations],
         "max CoG error of the survivors (mm)": [
             np.nan_to_num(1000 * per_location[loc]["survivors_max_cog_error_m"])
             for loc in locations],
         "peak force (N / 10)": [per_location[loc]["peak_force_N"] / 10 for loc in locations]},
        title=title)


def balance_figure(monitor, path: Path, title: str, imu: bool = True, shaded=(),
                   extra=()) -> Path:
    """Figs. 8-10 style from a :class:`~wholebody.scenarios.measures.BalanceMonitor`: CoG error,
    momentum, (extra panels), (platform IMU), predicted vs measured CoPs."""
    a = monitor.arrays()
    t = a["t"]
    panels = [("CoG error", "cm", {c: 100 * a["cog_error"][:, i] for i, c in enumerate("xyz")}),
              ("linear momentum - reference", "N s",
               {c: a["dh"][:, i] for i, c in enumerate("xyz")}),
              ("angular momentum - reference", "N m s",
               {c: a["dh"][:, 3 + i] for i, c in enumerate("xyz")})]
    panels += list(extra)
    if imu:
        acc, omega = monitor.support_imu()
        panels += [("platform angular velocity", "rad/s",
                    {c: omega[:, i] for i, c in enumerate("xyz")}),
                   ("platform linear acceleration (under the soles)", "m/s²",
                    {c: acc[:, i] for i, c in enumerate("xyz")})]
    for axis, c in enumerate("xy"):
        series = {}
        for j, n in enumerate(monitor.names):
            series[f"{_short(n)} predicted"] = 100 * a["cop_pred"][:, j, axis]
            series[f"{_short(n)} measured"] = 100 * a["cop_meas"][:, j, axis]
        panels.append((f"CoP {c} in the sole (bound ±{100 * monitor.bound[n][axis]:.1f} cm)",
                       "cm", series))
    return time_series_figure(path, t, panels, title=title, shaded=shaded)


def squat_figure(path: Path, monitor, velocities, joint: str, joint_index: int, bound_x: float,
                 title: str) -> Path:
    """Fig. 10 style: CoG vertical position and velocity, forward position (desired vs actual),
    the most deviating joint, CoP x (grey: a CoP constraint active). ``velocities``: (N, 2, 3)
    of (actual, desired) CoG velocities."""
    a = monitor.arrays()
    t, com, ref = a["t"], a["com"], a["com_ref"]
    edges = np.flatnonzero(np.diff(np.r_[0, a["active"].astype(int), 0]))
    shaded = [(t[s], t[min(e, len(t) - 1)]) for s, e in zip(edges[::2], edges[1::2])]
    cop = {}
    for j, n in enumerate(monitor.names):
        cop[f"{_short(n)} predicted"] = 100 * a["cop_pred"][:, j, 0]
        cop[f"{_short(n)} measured"] = 100 * a["cop_meas"][:, j, 0]
    return time_series_figure(
        path, t,
        [("CoG vertical position", "cm", {"desired": 100 * ref[:, 2], "actual": 100 * com[:, 2]}),
         ("CoG vertical velocity", "cm/s", {"desired": 100 * velocities[:, 1, 2],
                                            "actual": 100 * velocities[:, 0, 2]}),
         ("CoG forward position", "cm", {"desired": 100 * ref[:, 0], "actual": 100 * com[:, 0]}),
         ("joint deviation from the posture", "rad", {joint: a["joints"][:, joint_index]}),
         (f"CoP x in the sole (admissible ±{100 * bound_x:.1f} cm; grey: a CoP constraint "
          f"active)", "cm", cop)],
        title=title, shaded=shaded)


def single_support_figure(path: Path, t, cog_error, wrenches, contact_names, push_force, swing_z,
                          torque_jumps, title: str, shaded=()) -> Path:
    """Sect. 5.4: CoG error, normal forces, push force, swing sole height, torque changes."""
    return time_series_figure(
        path, t,
        [("CoG error", "mm", {a: 1000 * cog_error[:, i] for i, a in enumerate("xyz")}),
         ("normal forces (simulator)", "N",
          {n: wrenches[:, i, 2] for i, n in enumerate(contact_names)}),
         ("push force", "N", {"|F|": np.linalg.norm(push_force, axis=1)}),
         ("swing sole height", "cm", {"z": 100 * (np.asarray(swing_z) - swing_z[0])}),
         ("largest cycle-to-cycle torque change", "Nm", {"max |Δτ|": torque_jumps})],
        title=title, shaded=shaded)


def fig11(path, t, jerr, h, push_force, cop, half_size, joints, title=""):
    """Fig. 11 of the paper: knee (and hip) tracking errors, linear momentum, push force, CoP."""
    return time_series_figure(path, t, [
        ("joint position tracking error", "deg",
         {joints[1]: np.degrees(jerr[:, 1]), joints[0]: np.degrees(jerr[:, 0])}),
        ("joint velocity tracking error", "deg/s",
         {joints[1]: np.degrees(jerr[:, 3]), joints[0]: np.degrees(jerr[:, 2])}),
        ("linear momentum", "N s", {a: h[:, i] for i, a in enumerate("xyz")}),
        ("push force", "N", {"|F|": np.linalg.norm(push_force, axis=1)}),
        ("stance CoP (sole frame, simulator)", "cm",
         {"x": 100 * cop[:, 0], "y": 100 * cop[:, 1],
          "heel/toe bound": np.full(len(t), -100 * half_size[0])}),
    ], title=title)


def stepping_timing_figure(path: Path, runs: dict, title: str) -> Path:
    """Fig. 5 style: controller time per cycle of each formulation, its maximum, the number of
    contacts; single support shaded. ``runs``: formulation -> dict with "_t", "_cycles", "_nc",
    "_phases" and "timing"."""
    any_run = next(iter(runs.values()))
    shaded = [(ph.start, ph.end) for ph in any_run["_phases"] if ph.kind == "single"]
    labels = {"reduced": "reduced (Sect. 2.3)", "full": "full EoM"}
    panels = [("controller time per cycle (update + rows + solve + τ)", "ms",
               {labels.get(k, k): 1e3 * r["_cycles"] for k, r in runs.items()}),
              ("per-formulation maximum (after warm-up)", "ms",
               {f"max {labels.get(k, k)}": np.full(len(r["_cycles"]),
                                                   r["timing"]["overall"].get("max_ms", np.nan))
                for k, r in runs.items()}),
              ("number of contacts c", "", {"c": any_run["_nc"]})]
    n = min(len(r["_t"]) for r in runs.values())
    for panel in panels:
        for key in panel[2]:
            panel[2][key] = panel[2][key][:n]
    return time_series_figure(path, any_run["_t"][:n], panels, title=title, shaded=shaded)


def stand_figure(path: Path, arrays: dict, joint_names, contact_names, title: str) -> Path:
    """Standing: base position change, simulator normal forces, the six largest joint torques."""
    t = arrays["t"]
    base = arrays["q"][:, :3]
    err = 1000 * (base - base[0])
    wrenches = arrays["contact_wrenches"]
    tau = arrays["tau_applied"]
    joint_panels = {joint_names[i]: tau[:, i] for i in np.argsort(-np.abs(tau).max(0))[:6]}
    return time_series_figure(
        path, t,
        [("base position change", "mm", {"x": err[:, 0], "y": err[:, 1], "z": err[:, 2]}),
         ("contact normal forces (simulator)", "N",
          {n: wrenches[:, i, 2] for i, n in enumerate(contact_names)}),
         ("largest joint torques", "Nm", joint_panels)],
        title=title)
