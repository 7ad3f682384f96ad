"""``ramp``: HyQ over terrain courses (Fahmi et al. 2019, seed 001, Sects. V-G and V-H, Figs. 7-8).

* ``course=ramp`` (default): trot up a ramp (default 15°), along a plateau and down again. The
  paper's Fig. 8 shows roll and pitch tracking "while climbing up a ramp with a trotting gait" and
  states that "the orientation error is always below 0.2 rad" (Sect. V-H). We measure the roll and
  pitch errors (desired minus actual ZYX Euler angles, the actual ones from the simulator) over the
  whole course.
* ``course=gap``: crawl across a 22 cm gap followed by a 7 cm step (Fig. 7, left column). The
  paper's footholds come from an optimiser on an online terrain map (Sect. V-G, ref. [4]); our
  planner's Raibert targets do land in the gap, so :class:`~wholebody.scenarios.courses.CoursePlanner`
  moves any target within 6 cm of the gap to the nearest safe point (reported: how many were moved).

The simulator sees the course as boxes (a real hole under the gap, no floor plane) and the planner
the same course as a height map with exact per-strip normals for the friction cones (footnote 17);
the trunk reference follows the course smoothed over the hip-to-hip length
(:mod:`~wholebody.scenarios.courses`).

Success: no fall, every WBC cycle solved, the whole robot past the course (simulator feet), and for
the ramp, roll and pitch errors below 0.2 rad throughout; for the gap, no foot ever below the
surface it should stand on (simulator foot heights) — i.e. nothing stepped into the hole.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..planning.trunk import VelocityCommand
from .base import Parameter, Scenario, ScenarioResult
from .courses import Course, CoursePlanner, gap_course, ramp_course
from .locomotion import make_schedule, run_gait

log = logging.getLogger(__name__)

COURSES = ("ramp", "gap")
ERROR_LIMIT = 0.2  # rad, Sect. V-H
DEFAULTS = {"ramp": {"gait": "trot", "speed": 0.15}, "gap": {"gait": "crawl", "speed": 0.1}}

PARAMETERS = (
    Parameter("course", "ramp", "ramp (trot up and down a ramp, Fig. 8) or gap (crawl across a "
                                "gap with a step, Fig. 7)"),
    Parameter("angle", 15.0, "ramp slope (deg)"),
    Parameter("gap", 0.22, "gap width (m), course=gap"),
    Parameter("step", 0.07, "step height after the gap (m), course=gap"),
    Parameter("gait", "auto", "crawl or trot (auto: trot on the ramp, crawl across the gap)"),
    Parameter("speed", 0.0, "forward speed (m/s) after a 2 s ramp-up (0: 0.15 ramp, 0.1 gap)"),
    Parameter("duration", 0.0, "simulated time (s) (0: long enough to cross the course)"),
)


def resolve(params: dict) -> dict:
    """Parameters with the per-course defaults filled in."""
    p = dict(params)
    d = DEFAULTS[p["course"]]
    if p["gait"] == "auto":
        p["gait"] = d["gait"]
    if p["speed"] <= 0.0:
        p["speed"] = d["speed"]
    return p


def build(params: dict) -> Course:
    if params["course"] == "ramp":
        return ramp_course(params["angle"], up=1.4, top=1.0, down=1.4)
    return gap_course(params["gap"], params["step"])


def course_end(course: Course) -> float:
    """x of the last feature of the course (start of the final level strip)."""
    return course.strips[-1].x0


def validate(robot, params: dict) -> None:
    if any(c.spec.type != "point" for c in robot.contacts) or len(robot.contacts) != 4:
        raise ValueError(f"robot '{robot.name}': the ramp scenario needs a quadruped with point "
                         "feet (hyq)")
    if params["course"] not in COURSES:
        raise ValueError(f"--set course: expected one of {COURSES}, got '{params['course']}'")
    if params["gait"] not in ("auto", "crawl", "trot"):
        raise ValueError(f"--set gait: expected auto, crawl or trot, got '{params['gait']}'")
    if not 0.0 < params["angle"] < 35.0:
        raise ValueError(f"--set angle: expected a slope in (0, 35) deg, got {params['angle']}")
    if not (0.0 < params["gap"] < 0.4 and -0.15 < params["step"] < 0.15):
        raise ValueError("--set gap/step: expected 0 < gap < 0.4 m and |step| < 0.15 m")


class _Recorder:
    """Per WBC cycle: desired and simulator (actual) roll/pitch/yaw."""

    def __init__(self):
        self.desired, self.actual = [], []

    def __call__(self, t, result, ctrl, sim):
        q, _ = sim.state()
        R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
        self.actual.append(pin.rpy.matrixToRpy(R))
        self.desired.append(pin.rpy.matrixToRpy(np.asarray(ctrl.last_plan.trunk.rotation)))


def crossing(robot, params: dict, progress: bool = False):
    """Run one course; returns (run, course, recorder, planner)."""
    p = resolve(params)
    course = build(p)
    end = course_end(course)
    duration = p["duration"]
    if duration <= 0.0:  # the hind feet (~0.4 m behind the CoM) past the end, plus margin
        duration = 3.0 + (end + 0.6) / p["speed"] + 2.0
    command = VelocityCommand.speed_ramp(0.0, p["speed"], 1.0, 3.0)
    planner = CoursePlanner.on_course(robot, make_schedule(p["gait"], 1.0), command, course)
    rec = _Recorder()
    run = run_gait(robot, "passive", duration=duration, environment=course.environment,
                   planner=planner, on_cycle=rec, progress=progress)
    return run, course, rec, planner, p, duration


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool) -> ScenarioResult:
    gait_run, course, rec, planner, p, duration = crossing(robot, params, progress)
    L = gait_run.log
    t = L["t"]
    desired, actual = np.array(rec.desired), np.array(rec.actual)
    err = desired - actual
    err[:, 2] = (err[:, 2] + np.pi) % (2 * np.pi) - np.pi
    after = t >= 1.0
    end = course_end(course)
    feet = L["feet"]  # simulator foot-frame positions
    com = L["com"]
    radius = robot.contacts[0].spec.radius
    # where the robot is on the course: over a slope, or elsewhere
    on_slope = np.array([abs(course.slope(x)) > 1e-6 or abs(course.smooth_slope(x)) > 1e-6
                         for x in com[:, 0]])
    final_feet_x = feet[-1, :, 0]
    crossed = bool(np.all(final_feet_x > end + 0.05))
    metrics = {
        "course": p["course"], "gait": p["gait"], "speed_mps": p["speed"],
        "duration_s": duration, "fell": gait_run.fell, "failed_cycles": int(gait_run.failures),
        "distance_m": gait_run.distance, "course_end_x_m": end,
        "final_feet_x_m": final_feet_x, "crossed": crossed,
        "roll_error_max_rad": float(np.abs(err[after, 0]).max()),
        "pitch_error_max_rad": float(np.abs(err[after, 1]).max()),
        "roll_error_rms_rad": float(np.sqrt(np.mean(err[after, 0] ** 2))),
        "pitch_error_rms_rad": float(np.sqrt(np.mean(err[after, 1] ** 2))),
        "pitch_error_mean_rad": float(np.mean(err[after, 1])),
        "desired_pitch_range_rad": [float(desired[:, 1].min()), float(desired[:, 1].max())],
        **gait_run.tracking(1.0),
        "max_stance_slip_m": float(gait_run.stance_slip().max()),
    }
    if np.any(on_slope & after):
        sel = on_slope & after
        metrics["on_slopes"] = {"roll_error_max_rad": float(np.abs(err[sel, 0]).max()),
                                "pitch_error_max_rad": float(np.abs(err[sel, 1]).max())}
    sat = (L["tau"] >= L["tau_max"] - 1e-6) | (L["tau"] <= L["tau_min"] + 1e-6)
    metrics["cycles_at_torque_limit"] = int(np.any(sat, axis=1).sum())
    notes = []
    success = (not gait_run.fell) and gait_run.failures == 0 and crossed
    if p["course"] == "ramp":
        below = bool(metrics["roll_error_max_rad"] < ERROR_LIMIT
                     and metrics["pitch_error_max_rad"] < ERROR_LIMIT)
        metrics["claim"] = {"paper": "roll and pitch errors always below 0.2 rad (Sect. V-H)",
                            "holds": below}
        success &= below
        notes.append(f"{p['gait']} at {p['speed']} m/s over a {p['angle']:.0f} deg ramp up, "
                     f"plateau, ramp down: max |roll error| {metrics['roll_error_max_rad']:.3f} rad, "
                     f"max |pitch error| {metrics['pitch_error_max_rad']:.3f} rad (paper: < 0.2); "
                     f"mean pitch error {metrics['pitch_error_mean_rad']:+.3f} rad")
    else:
        # nothing in the hole: every foot, whenever it is over the gap, stays above the surface
        # level of the gap's edges (a foot that stepped in would be well below)
        gap_x0, gap_x1 = course.gaps[0]
        over = (feet[:, :, 0] > gap_x0) & (feet[:, :, 0] < gap_x1)
        z_edge = min(course.height(gap_x0 - 1e-6, 0.0), course.height(gap_x1 + 1e-6, 0.0))
        lowest = float(feet[:, :, 2][over].min()) if np.any(over) else float("nan")
        in_hole = bool(np.any(over) and lowest < z_edge + radius - 0.01)
        # stance feet on the far side must stand on the step (simulator height)
        metrics["gap"] = {"x0_m": gap_x0, "x1_m": gap_x1, "footholds_moved": int(planner.adjusted),
                          "lowest_foot_over_gap_m": lowest, "foot_entered_hole": in_hole,
                          "final_feet_z_m": feet[-1, :, 2]}
        success &= not in_hole
        notes.append(f"crawl across a {p['gap'] * 100:.0f} cm gap with a {p['step'] * 100:.0f} cm "
                     f"step at {p['speed']} m/s: {planner.adjusted} Raibert footholds fell within "
                     f"{planner.gap_margin * 100:.0f} cm of the gap and were moved to the nearest "
                     f"safe point; lowest foot over the gap {lowest:.3f} m (edges at "
                     f"{z_edge:.2f} m); crossed: {crossed}")
    figures = []
    if out_dir is not None:
        out_dir = Path(out_dir)
        if p["course"] == "ramp":
            figures.append(str(_ramp_figure(out_dir / "ramp_roll_pitch.png", t, desired, actual,
                                            com, course, p)))
        figures.append(str(_side_view(out_dir / f"{p['course']}_side_view.png", robot, gait_run,
                                      course, p)))
    return ScenarioResult("ramp", robot.name, controller, success, metrics, p, notes,
                          figures=figures)


def _ramp_figure(path: Path, t, desired, actual, com, course: Course, p: dict) -> Path:
    """Fig. 8 style: roll and pitch, desired vs actual, and the course under the CoM."""
    from ..report.plots import plt, save_figure  # the headless (Agg) pyplot
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6.5))
    for ax, k, name in ((axes[0], 0, "roll"), (axes[1], 1, "pitch")):
        ax.plot(t, desired[:, k], "k--", linewidth=1.0, label="desired")
        ax.plot(t, actual[:, k], color="tab:blue", linewidth=1.0, label="actual (simulator)")
        ax.fill_between(t, desired[:, k] - ERROR_LIMIT, desired[:, k] + ERROR_LIMIT,
                        color="0.9", zorder=0, label="±0.2 rad")
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
    fig.suptitle(f"HyQ {p['gait']} {p['speed']} m/s over a {p['angle']:.0f} deg ramp: roll and "
                 "pitch tracking (Fig. 8)", fontsize=10)
    return save_figure(fig, path)


LEG_JOINTS = {"lf": ("lf_hfe_joint", "lf_kfe_joint"), "rf": ("rf_hfe_joint", "rf_kfe_joint"),
              "lh": ("lh_hfe_joint", "lh_kfe_joint"), "rh": ("rh_hfe_joint", "rh_kfe_joint")}


def _side_view(path: Path, robot, gait_run, course: Course, p: dict, snapshots: int = 6) -> Path:
    """Fig. 7 style side view: the course, the CoM path, the feet paths and stick-figure
    snapshots of the robot (left legs solid, right legs dashed), all from the simulator."""
    from ..report.plots import plt, save_figure  # the headless (Agg) pyplot
    sim_log = gait_run.sim.log
    qs = np.asarray(sim_log.q)
    ts = np.asarray(sim_log.t)
    L = gait_run.log
    model, data = robot.model, robot.model.createData()
    x_lo = float(min(L["feet"][:, :, 0].min(), 0.0)) - 0.3
    x_hi = float(L["feet"][:, :, 0].max()) + 0.3
    fig, ax = plt.subplots(figsize=(10, 3.8))
    xs, zs = course.profile(x_lo, x_hi)
    surface = [course.height(x) for x in np.linspace(x_lo, x_hi, 400) if not course.in_gap(x)]
    z_lo = min(surface) - 0.25  # holes are drawn down to here
    ax.fill_between(xs, np.maximum(zs, z_lo), z_lo, color="0.85")
    ax.plot(xs, zs, color="0.3", linewidth=1.0)
    ax.plot(L["com"][:, 0], L["com"][:, 2], color="tab:green", linewidth=1.0, label="CoM")
    colors = {"lf": "tab:blue", "rf": "tab:orange", "lh": "tab:purple", "rh": "tab:red"}
    for i, leg in enumerate(("lf", "rf", "lh", "rh")):
        ax.plot(L["feet"][:, i, 0], L["feet"][:, i, 2], color=colors[leg], linewidth=0.6,
                alpha=0.7, label=f"{leg.upper()} foot")
    jid = {n: model.getJointId(n) for pair in LEG_JOINTS.values() for n in pair}
    fid = {leg: robot.contact(f"{leg}_foot").frame_id for leg in LEG_JOINTS}
    times = np.linspace(ts[0] + 1.0, ts[-1], snapshots)
    for k, tk in enumerate(times):
        q = qs[min(int(np.searchsorted(ts, tk)), len(qs) - 1)]
        pin.framesForwardKinematics(model, data, q)
        shade = 0.15 + 0.6 * k / max(1, snapshots - 1)
        hips = []
        for leg, (hfe, kfe) in LEG_JOINTS.items():
            pts = np.array([data.oMi[jid[hfe]].translation, data.oMi[jid[kfe]].translation,
                            data.oMf[fid[leg]].translation])
            hips.append(pts[0])
            ax.plot(pts[:, 0], pts[:, 2], "-" if leg[0] == "l" else "--", color=str(1 - shade),
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
    what = (f"{p['angle']:.0f} deg ramp" if p["course"] == "ramp" else
            f"{p['gap'] * 100:.0f} cm gap + {p['step'] * 100:.0f} cm step")
    ax.set_title(f"HyQ {p['gait']} {p['speed']} m/s across a {what} (simulator; cf. Fig. 7)",
                 fontsize=9)
    return save_figure(fig, path)


SCENARIO = Scenario(
    name="ramp",
    summary="Sects. V-G/V-H, Figs. 7-8: HyQ trots up and down a 15 deg ramp (roll/pitch error < "
            "0.2 rad) or, with course=gap, crawls across a 22 cm gap with a 7 cm step; success = "
            "no fall, course crossed, every cycle solved, the criterion of the course",
    parameters=PARAMETERS,
    controllers=("passive",),
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
)
