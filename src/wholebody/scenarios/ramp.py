"""``ramp``: HyQ over terrain courses (Fahmi et al. 2019, Sects. V-G and V-H, Figs. 7-8).

* ``course=ramp`` (default): trot up a ramp (default 15°), along a plateau and down again. The
  paper's Fig. 8 shows roll and pitch tracking "while climbing up a ramp with a trotting gait" and
  states that "the orientation error is always below 0.2 rad" (Sect. V-H). We measure the roll and
  pitch errors (desired minus actual ZYX Euler angles, the actual ones from the simulator) over the
  whole course.
* ``course=gap``: crawl across a 22 cm gap followed by a 7 cm step (Fig. 7, left column). The
  paper's footholds come from an optimiser on an online terrain map (Sect. V-G, ref. [4]); our
  planner's Raibert targets do land in the gap, so :class:`~wholebody.planning.courses.CoursePlanner`
  moves any target within 6 cm of the gap to the nearest safe point (reported: how many were moved).
* ``course=stairs``: up ``steps`` steps of ``step_height`` (15 cm on HyQ), a landing, and down
  again; the same planner keeps footholds 6 cm off every riser. The paper's conclusion names
  stairs with slopes and gaps as the terrain of legged robots; it shows none.
* ``course=rough``: rough ground of ±5 cm on HyQ, a seeded grid of cells of random heights known
  to the planner as a height map (the paper's terrain map), footholds kept off the cells' sides.

The simulator sees the course as boxes (a real hole under the gap, no floor plane) and the planner
the same course as a height map with exact per-strip normals for the friction cones (footnote 17);
the trunk reference follows the course smoothed over the hip-to-hip length
(:mod:`~wholebody.planning.courses`), its attitude parallel to the slope (the paper's) or level,
whichever moves the robot's legs less from their posture on the ramp's slope
(:func:`~wholebody.planning.reach.terrain_alignment_for`; ``--set terrain_alignment`` to choose).

Success: no fall, every WBC cycle solved, the whole robot past the course (simulator feet), and for
the ramp, roll and pitch errors below 0.2 rad throughout; for the gap, no foot ever below the
surface it should stand on (simulator foot heights) — i.e. nothing stepped into the hole. Both
controllers run every course (``--controller quasi-static``: the baseline of Sect. V-E).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..planning.courses import (Course, CoursePlanner, gap_course, ramp_course, rough_course,
                                stairs_course)
from ..planning.reach import foot_lift, terrain_alignment_for
from ..report.locomotion_figures import course_side_view, ramp_figure
from .base import Parameter, Scenario, ScenarioResult
from .gait_measures import outcome
from .locomotion import (BASELINE_GAINS, CONTROLLERS, GAIT_SHAPE, WBC_GAINS, PaperSpeed,
                         check_quadruped, course_environment, gait_options, make_schedule,
                         paper_length, ramped_command, run_gait, wbc_gains)

log = logging.getLogger(__name__)

COURSES = ("ramp", "gap", "stairs", "rough")
AUTO = -1.0  # terrain_alignment: the one that moves the legs less (terrain_alignment_for)
ERROR_LIMIT = 0.2  # rad, Sect. V-H
DEFAULTS = {"ramp": {"gait": "trot", "speed": PaperSpeed(0.15)},
            "gap": {"gait": "crawl", "speed": PaperSpeed(0.1)},
            "stairs": {"gait": "crawl", "speed": PaperSpeed(0.1)},
            "rough": {"gait": "crawl", "speed": PaperSpeed(0.1)}}
#: footholds are kept this far from a gap, a riser or a rough cell's side (m on HyQ)
EDGE_MARGIN = paper_length(0.06)

PARAMETERS = (
    Parameter("course", "ramp", "ramp (trot up and down a ramp, Fig. 8), gap (crawl across a "
                                "gap with a step, Fig. 7), stairs (up, a landing, down) or rough "
                                "(a seeded field of cells of random heights)", choices=COURSES),
    Parameter("angle", 15.0, "ramp slope (deg)", low=0.0, high=35.0, low_open=True, high_open=True),
    Parameter("gap", paper_length(0.22), "gap width (m), course=gap",
              low=0.0, high=0.65 * Parameter.H, low_open=True, high_open=True),
    Parameter("step", paper_length(0.07), "step height after the gap (m), course=gap",
              low=-0.25 * Parameter.H, high=0.25 * Parameter.H, low_open=True, high_open=True),
    Parameter("steps", 5, "course=stairs: steps up (and as many down)", low=1, high=50),
    Parameter("step_height", paper_length(0.15), "course=stairs: rise of each step (m; at most "
              "what the legs reach, see validate)", low=0.0, high=0.5 * Parameter.H, low_open=True),
    Parameter("tread", paper_length(0.5), "course=stairs: tread of each step (m; longer than "
              "twice the footholds' 6 cm edge margin on HyQ)", low=0.0, high=5.0 * Parameter.H,
              low_open=True),
    Parameter("landing", paper_length(1.0), "course=stairs: length of the top tread (m)",
              low=0.0, high=10.0 * Parameter.H, low_open=True),
    Parameter("roughness", paper_length(0.05), "course=rough: cell heights uniform in "
              "[-roughness, roughness] (m)", low=0.0, high=0.25 * Parameter.H),
    Parameter("cell", paper_length(0.2), "course=rough: cell size (m; wider than twice the "
              "footholds' edge margin)", low=0.0, high=2.0 * Parameter.H, low_open=True),
    Parameter("rough_length", paper_length(3.0), "course=rough: length of the rough ground (m)",
              low=0.0, high=20.0 * Parameter.H, low_open=True),
    Parameter("seed", 0, "course=rough: seed of the cell heights", low=0, high=2 ** 32 - 1),
    Parameter("gait", "auto", "crawl or trot (auto: trot on the ramp, crawl on the other courses)",
              choices=("auto", "crawl", "trot")),
    Parameter("speed", 0.0, "forward speed (m/s) after a 2 s ramp-up (0: 0.15 ramp, 0.1 the "
              "others, times sqrt(h / 0.599))",
              low=0.01, high=5.0, special=(0.0,)),
    Parameter("terrain_alignment", AUTO, "how far the trunk's roll and pitch follow the course's "
              "inclination (1: parallel to the slope, as in Fig. 8; 0: level; -1: whichever of the "
              "two moves the legs less from their posture on the ramp's slope)",
              low=0.0, high=1.0, special=(AUTO,)),
    Parameter("duration", 0.0, "simulated time (s) (0: long enough to cross the course)",
              low=0.0, high=Parameter.MAX_TIME),
    *WBC_GAINS,
    *GAIT_SHAPE,
    *BASELINE_GAINS,
)


def resolve(params: dict, robot) -> dict:
    """Parameters with the per-course defaults filled in (the speed scaled to ``robot``)."""
    p = dict(params)
    d = DEFAULTS[p["course"]]
    if p["gait"] == "auto":
        p["gait"] = d["gait"]
    if p["speed"] <= 0.0:
        p["speed"] = d["speed"].value(robot)
    if p["terrain_alignment"] == AUTO:
        p["terrain_alignment"] = 1.0
        angle = None
        if p["course"] == "ramp":
            angle = p["angle"]
        elif p["course"] == "stairs":  # their mean slope, which the trunk follows
            angle = math.degrees(math.atan2(p["step_height"], p["tread"]))
        if angle is not None:
            p["terrain_alignment"], changes = terrain_alignment_for(robot, math.radians(angle))
            log.info("terrain_alignment %g: standing on %.3g deg up or down moves a leg joint by "
                     "up to %.3f of its range with the trunk parallel, %.3f level",
                     p["terrain_alignment"], angle, changes[1.0], changes[0.0])
    return p


def build(params: dict, robot) -> Course:
    """The course: a ramp 1.4 m up, 1 m flat, 1.4 m down on HyQ (in proportion on other robots,
    :func:`paper_length`), the gap, the stairs or the rough ground (their sizes parameters)."""
    course = params["course"]
    if course == "ramp":
        up, top = (paper_length(x).value(robot) for x in (1.4, 1.0))
        return ramp_course(params["angle"], up=up, top=top, down=up)
    # the trunk's window: HyQ's hip-to-hip length, in proportion (the ramp and gap keep 0.75 m)
    smoothing = paper_length(0.75).value(robot)
    if course == "stairs":
        return stairs_course(params["steps"], params["step_height"], params["tread"],
                             params["landing"], smoothing=smoothing)
    if course == "rough":
        return rough_course(params["rough_length"], params["roughness"], params["cell"],
                            params["seed"], smoothing=smoothing)
    return gap_course(params["gap"], params["step"])


def highest_step(robot) -> float:
    """The highest rise a stairs course takes on ``robot``: a riser is crossed at mid-swing with
    the trunk reference midway between the two treads (it follows the smoothed course), so the
    foot's bottom must rise half a step above its standing height: 2 (lift − r), with the lift the
    least :func:`~wholebody.planning.reach.foot_lift` of the legs and r the foot radius."""
    lift = min(foot_lift(robot, c.name, up_to=float(robot.q_ref[2])) for c in robot.contacts)
    radius = max(float(c.spec.radius) for c in robot.contacts)
    return 2.0 * (lift - radius)


def course_end(course: Course) -> float:
    """x of the last feature of the course (start of the final level strip)."""
    return course.strips[-1].x0


def validate(robot, params: dict) -> None:
    if params["course"] not in COURSES:
        raise ValueError(f"--set course: expected one of {COURSES}, got '{params['course']}'")
    if params["gait"] not in ("auto", "crawl", "trot"):
        raise ValueError(f"--set gait: expected auto, crawl or trot, got '{params['gait']}'")
    gait = DEFAULTS[params["course"]]["gait"] if params["gait"] == "auto" else params["gait"]
    check_quadruped(robot, "the ramp scenario", gait)
    margin = EDGE_MARGIN.value(robot)
    if params["course"] == "stairs":
        if params["tread"] <= 2.0 * margin:
            raise ValueError(f"--set tread: {params['tread']:g} m leaves no foothold "
                             f"{margin:.3g} m from both risers (needs > {2 * margin:.3g} m on "
                             f"{robot.name})")
        top = highest_step(robot)
        if params["step_height"] > top:
            raise ValueError(f"--set step_height: {params['step_height']:g} m is more than "
                             f"{robot.name}'s legs reach ({top:.3g} m: twice the foot lift above "
                             "standing, less the foot radius)")
    if params["course"] == "rough" and params["cell"] <= 2.0 * margin:
        raise ValueError(f"--set cell: {params['cell']:g} m leaves no foothold {margin:.3g} m from "
                         f"a cell's sides (needs > {2 * margin:.3g} m on {robot.name})")


def stance_edge_distances(log: dict, course: Course) -> np.ndarray:
    """Per stance phase after the first touchdown of each foot (the planner's contact flags), the
    simulator foot's horizontal distance to the nearest edge of ``course``
    (:meth:`Course.edge_distance`) at the middle of the stance."""
    stance, feet = log["stance"], log["feet"]
    out = []
    for leg in range(stance.shape[1]):
        s = np.concatenate([[0], stance[:, leg].astype(np.int8), [0]])
        starts, ends = np.flatnonzero(np.diff(s) == 1), np.flatnonzero(np.diff(s) == -1)
        for a, b in zip(starts[1:], ends[1:]):  # the first stance is the standing start
            x, y = feet[(a + b) // 2, leg, :2]
            out.append(course.edge_distance(float(x), float(y)))
    return np.array(out)


class _Recorder:
    """Per WBC cycle: desired and simulator (actual) roll/pitch/yaw."""

    def __init__(self):
        self.desired, self.actual = [], []

    def __call__(self, t, result, ctrl, sim):
        q, _ = sim.state()
        R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
        self.actual.append(pin.rpy.matrixToRpy(R))
        self.desired.append(pin.rpy.matrixToRpy(np.asarray(ctrl.last_plan.trunk.rotation)))


def crossing(robot, params: dict, progress: bool = False, observers=(),
             controller: str = "passive"):
    """Run one course; returns (run, course, recorder, planner, resolved parameters, duration)."""
    p = resolve(params, robot)
    course = build(p, robot)
    end = course_end(course)
    duration = p["duration"]
    if duration <= 0.0:  # the hind feet (~0.4 m behind the CoM) past the end, plus margin
        duration = 3.0 + (end + paper_length(0.6).value(robot)) / p["speed"] + 2.0
    planner = CoursePlanner.on_course(robot, make_schedule(robot, p["gait"], 1.0, p),
                                      ramped_command(p["speed"]), course,
                                      gap_margin=EDGE_MARGIN.value(robot),
                                      terrain_alignment=p["terrain_alignment"],
                                      **gait_options(robot, p))
    rec = _Recorder()
    run = run_gait(robot, controller, duration=duration, environment=course_environment(course),
                   planner=planner, on_cycle=rec, progress=progress, observers=observers,
                   gains=wbc_gains(p))
    return run, course, rec, planner, p, duration


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    gait_run, course, rec, planner, p, duration = crossing(robot, params, progress, observers,
                                                           controller)
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
        "terrain_alignment": p["terrain_alignment"], "duration_s": duration,
        **outcome(gait_run), "course_end_x_m": end,
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
        notes.append(f"{p['gait']} at {p['speed']:.3g} m/s over a {p['angle']:.0f} deg ramp up, "
                     f"plateau, ramp down: max |roll error| {metrics['roll_error_max_rad']:.3f} rad, "
                     f"max |pitch error| {metrics['pitch_error_max_rad']:.3f} rad (paper: < 0.2); "
                     f"mean pitch error {metrics['pitch_error_mean_rad']:+.3f} rad")
    elif p["course"] in ("stairs", "rough"):
        edges = stance_edge_distances(L, course)
        on_edge = int(np.sum(edges < radius))
        metrics[p["course"]] = {"footholds_moved": int(planner.adjusted),
                                "stances": int(edges.size),
                                "nearest_stance_to_an_edge_m": float(edges.min(initial=np.inf)),
                                "stances_over_an_edge": on_edge,
                                "final_feet_z_m": feet[-1, :, 2]}
        if p["course"] == "stairs":  # the trunk's linear error going up and going down
            risers = course.edges
            middle = 0.5 * (risers[p["steps"] - 1] + risers[p["steps"]])  # of the landing
            error = np.linalg.norm(L["com_error"], axis=1)
            for part, sel in (("up", (com[:, 0] >= risers[0]) & (com[:, 0] < middle)),
                              ("down", (com[:, 0] >= middle) & (com[:, 0] < risers[-1]))):
                metrics["stairs"][f"linear_rms_{part}_m"] = float(np.sqrt(np.mean(
                    error[sel] ** 2))) if np.any(sel) else float("nan")
        what = (f"{p['steps']} steps of {p['step_height'] * 100:.1f} cm (tread "
                f"{p['tread'] * 100:.0f} cm) up and down" if p["course"] == "stairs" else
                f"rough ground of +-{p['roughness'] * 100:.1f} cm (cells {p['cell'] * 100:.0f} cm, "
                f"seed {p['seed']})")
        nearest = metrics[p["course"]]["nearest_stance_to_an_edge_m"]
        notes.append(f"{p['gait']} at {p['speed']:.3g} m/s over {what}: {planner.adjusted} Raibert "
                     f"footholds within {planner.gap_margin * 100:.1f} cm of an edge moved; "
                     f"simulator stance feet at least {nearest * 100:.1f} cm from an edge "
                     f"({on_edge} of {edges.size} stances over one); crossed: {crossed}")
    else:
        # nothing in the hole: every foot, whenever it is over the gap, stays above the surface
        # level of the gap's edges (a foot that stepped in would be well below)
        gap_x0, gap_x1 = course.gaps[0]
        over = (feet[:, :, 0] > gap_x0) & (feet[:, :, 0] < gap_x1)
        z_edge = min(course.height(gap_x0 - 1e-6, 0.0), course.height(gap_x1 + 1e-6, 0.0))
        lowest = float(feet[:, :, 2][over].min()) if np.any(over) else float("nan")
        in_hole = bool(np.any(over) and lowest < z_edge + radius - 0.01)
        metrics["gap"] = {"x0_m": gap_x0, "x1_m": gap_x1, "footholds_moved": int(planner.adjusted),
                          "lowest_foot_over_gap_m": lowest, "foot_entered_hole": in_hole,
                          "final_feet_z_m": feet[-1, :, 2]}
        success &= not in_hole
        notes.append(f"crawl across a {p['gap'] * 100:.0f} cm gap with a {p['step'] * 100:.0f} cm "
                     f"step at {p['speed']:.3g} m/s: {planner.adjusted} Raibert footholds fell within "
                     f"{planner.gap_margin * 100:.0f} cm of the gap and were moved to the nearest "
                     f"safe point; lowest foot over the gap {lowest:.3f} m (edges at "
                     f"{z_edge:.2f} m); crossed: {crossed}")
    figures = []
    if out_dir is not None:
        out_dir = Path(out_dir)
        if p["course"] == "ramp":
            figures.append(str(ramp_figure(out_dir / "ramp_roll_pitch.png", robot.name, t, desired,
                                           actual, com, course, p["gait"], p["speed"], p["angle"],
                                           ERROR_LIMIT)))
        what = {"ramp": f"{p['angle']:.0f} deg ramp",
                "gap": f"{p['gap'] * 100:.0f} cm gap + {p['step'] * 100:.0f} cm step",
                "stairs": f"staircase ({p['steps']} steps of {p['step_height'] * 100:.1f} cm up "
                          "and down)",
                "rough": f"field of +-{p['roughness'] * 100:.1f} cm cells (seed {p['seed']}; "
                         "drawn along y = 0)"
                }[p["course"]]
        figures.append(str(course_side_view(
            out_dir / f"{p['course']}_side_view.png", robot, gait_run, course,
            f"{robot.name} {p['gait']} {p['speed']:.3g} m/s across a {what} (simulator; cf. Fig. 7)")))
    return ScenarioResult("ramp", robot.name, controller, success, metrics, p, notes,
                          figures=figures)


SCENARIO = Scenario(
    name="ramp",
    summary="Sects. V-G/V-H, Figs. 7-8: HyQ trots up and down a 15 deg ramp (roll/pitch error < "
            "0.2 rad) or, with course=gap, crawls across a 22 cm gap with a 7 cm step; "
            "course=stairs and course=rough: 15 cm steps, +-5 cm rough ground; success = no fall, "
            "course crossed, every cycle solved, the criterion of the course",
    parameters=PARAMETERS,
    controllers=CONTROLLERS,
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
    simulations=1,
)
