"""``steer``: a quadruped follows a velocity-command schedule -- forward, a turn, a side-step, a
stop -- under the passive WBC (Fahmi et al. 2019), and how well it tracks the command is measured.

The command (:class:`~wholebody.planning.trunk.CommandSchedule`, heading-frame forward and lateral
speed and yaw rate) drives the gait planner: the trunk reference integrates it (the heading is the
integral of the yaw rate) and the Raibert footholds place each foot where its hip will be at
mid-stance under the commanded twist (the hip offsets rotated by the heading, their velocity
including the yaw rate's). After the robot has stood for 1 s and the gait has started:

* ``forward``: the forward ``speed``, held for ``forward_cycles`` gait periods;
* ``turn``: a heading change of ``turn`` degrees at ``yaw_rate``, walking on at ``turn_speed`` x
  the forward speed;
* ``side``: a side-step at ``lateral`` m/s (heading-frame, positive to the left) for
  ``side_cycles`` gait periods;
* ``stop``: a zero command for ``stop_cycles`` periods (the gait keeps stepping in place).

Each part ramps its command in linearly over ``ramp`` gait periods, so the heading changes by
exactly ``yaw_rate`` x the turn's duration, reached when the next part's ramp ends.

Defaults are robot-relative: on a trot, the forward speed is HyQ's ``0.4 m/s`` Froude-scaled
(times sqrt(h / h_HyQ)), the turn at half that speed and ``0.5 rad/s`` x sqrt(h_HyQ / h), the
side-step at 0.3 x the forward speed; on a crawl the same motion per gait period (the trot's
speeds and rates times the trot's period over the crawl's).

Measured on the simulator, in the robot's heading frame: the gait-period mean of the CoM velocity
and of the yaw rate against the command's mean over the same window; per part the RMS of the
velocity error (the norm of its forward/lateral error over the commanded speed) and of the yaw-rate
error, over the part after its ramp; the heading error (the base's yaw against the commanded
heading) at the end of the turn, at the end of the run and its largest; distance; failed cycles;
fall; the largest stance slip.

Success: no fall, every WBC cycle solved, heading error at the end of the turn and at the end
within 5 deg, and every moving part's velocity error RMS (and the turn's yaw-rate error RMS) within
10 % of its command.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..control.passive import ENGINES
from ..planning.gait import CRAWL_PERIOD, TROT_PERIOD
from ..planning.trunk import CommandPhase, CommandSchedule
from ..report.locomotion_figures import steer_figure
from ..robots.reference import froude_ratio
from .base import Parameter, Scenario, ScenarioResult
from .gait_measures import outcome
from .locomotion import (CRITICALLY_DAMPED_WBC_GAINS, GAIT_SHAPE, PAPER_BASE_HEIGHT,
                         REGULARIZATION, TROT_SPEED, check_gait, check_quadruped, make_schedule,
                         run_gait, wbc_gains)

#: the robot stands this long before its gait starts (s)
GAIT_START = 1.0
#: success thresholds: heading error (deg) and velocity / yaw-rate error RMS over the command
MAX_HEADING_ERROR_DEG = 5.0
MAX_VELOCITY_ERROR_SHARE = 0.10
#: the trot's default speeds on HyQ, Froude-scaled on any other robot
TROT_YAW_RATE = 0.5       # rad/s
SIDE_SHARE = 0.3          # lateral speed over the forward speed
PARTS = ("forward", "turn", "side", "stop")


GAIT_CHOICE = Parameter("gait", "trot", "trot or crawl", choices=("trot", "crawl"))

PARAMETERS = (
    GAIT_CHOICE,
    Parameter("speed", 0.0, f"forward speed (m/s; 0: {TROT_SPEED:g} sqrt(h / "
              f"{PAPER_BASE_HEIGHT:.3g}) on a trot, times {TROT_PERIOD:g}/{CRAWL_PERIOD:g} on a "
              "crawl)", low=0.0, low_open=True, high=5.0, special=(0.0,)),
    Parameter("forward_cycles", 4.0, "forward part's length in gait periods (its ramp included)",
              low=0.0, low_open=True, high=200.0),
    Parameter("turn", 90.0, "heading change of the turn (deg, positive to the left)",
              low=-360.0, high=360.0, low_open=False),
    Parameter("yaw_rate", 0.0, f"yaw rate of the turn (rad/s; 0: {TROT_YAW_RATE:g} sqrt("
              f"{PAPER_BASE_HEIGHT:.3g} / h) on a trot, times {TROT_PERIOD:g}/{CRAWL_PERIOD:g} on "
              "a crawl)", low=0.0, low_open=True, high=10.0, special=(0.0,)),
    Parameter("turn_speed", 0.5, "forward speed during the turn, as a share of speed",
              low=0.0, high=1.0),
    Parameter("lateral", 0.0, f"side-step speed (m/s, positive to the left; 0: {SIDE_SHARE:g} x "
              "speed)", low=-5.0, high=5.0),
    Parameter("side_cycles", 4.0, "side-step's length in gait periods (0: no side-step)",
              low=0.0, high=200.0),
    Parameter("stop_cycles", 3.0, "zero command at the end, in gait periods", low=0.0,
              low_open=True, high=200.0),
    Parameter("ramp", 1.0, "each part's command ramps in over this many gait periods", low=0.0,
              high=10.0),
    Parameter("engine", "auto", "passive WBC engine: native, python or auto", choices=ENGINES),
    REGULARIZATION,
    *CRITICALLY_DAMPED_WBC_GAINS,
    *GAIT_SHAPE,
)


def gait_period(robot, params: dict) -> float:
    return make_schedule(robot, params["gait"], GAIT_START, params).period


def resolved_command(robot, params: dict) -> dict:
    """The command's speeds and rates with the gait's defaults filled in (the 0 of ``speed``,
    ``yaw_rate`` and ``lateral``)."""
    share = 1.0 if params["gait"] == "trot" else TROT_PERIOD / CRAWL_PERIOD
    speed = params["speed"] or share * TROT_SPEED * froude_ratio(robot)
    rate = params["yaw_rate"] or share * TROT_YAW_RATE / froude_ratio(robot)
    lateral = params["lateral"] or SIDE_SHARE * speed
    return {"speed": speed, "yaw_rate": rate, "lateral": lateral,
            "turn_speed": params["turn_speed"] * speed}


def command_schedule(robot, params: dict) -> CommandSchedule:
    """The schedule of the module docstring: forward, turn, side-step, stop."""
    period = gait_period(robot, params)
    c = resolved_command(robot, params)
    ramp = params["ramp"] * period
    turn = math.radians(params["turn"])
    phases = [CommandPhase("forward", params["forward_cycles"] * period, c["speed"])]
    if turn != 0.0:
        # ramps in and out of the turn are linear and equally long: the heading changes by the
        # rate times the part's duration, whatever the ramp
        phases.append(CommandPhase("turn", abs(turn) / c["yaw_rate"], c["turn_speed"], 0.0,
                                   math.copysign(c["yaw_rate"], turn)))
    if params["side_cycles"] > 0:
        phases.append(CommandPhase("side", params["side_cycles"] * period, 0.0, c["lateral"]))
    phases.append(CommandPhase("stop", params["stop_cycles"] * period))
    return CommandSchedule.from_phases(phases, GAIT_START, ramp)


def validate(robot, params: dict) -> None:
    check_gait(params)
    check_quadruped(robot, "the steer scenario", params["gait"])
    period = gait_period(robot, params)
    ramp = params["ramp"] * period
    c = resolved_command(robot, params)
    for name, cycles in (("forward_cycles", params["forward_cycles"]),
                         ("side_cycles", params["side_cycles"]),
                         ("stop_cycles", params["stop_cycles"])):
        if 0.0 < cycles * period < ramp:
            raise ValueError(f"--set {name}: {cycles:g} gait periods are shorter than the ramp "
                             f"({params['ramp']:g} periods)")
    turn = math.radians(abs(params["turn"]))
    if turn > 0.0 and turn / c["yaw_rate"] < ramp:
        raise ValueError(f"--set turn: {params['turn']:g} deg at {c['yaw_rate']:.3g} rad/s lasts "
                         f"{turn / c['yaw_rate']:.2f} s, shorter than the ramp ({ramp:.2f} s): "
                         "a larger turn, a smaller yaw_rate or a shorter ramp")
    end = command_schedule(robot, params).end
    if end > Parameter.MAX_TIME:
        raise ValueError(f"the command schedule lasts {end:.0f} s, more than "
                         f"{Parameter.MAX_TIME:g} s: fewer --set cycles or a larger --set yaw_rate")


# ---------------------------------------------------------------------- measures
def period_mean(t: np.ndarray, x: np.ndarray, window: float):
    """(mask, mean): the mean of ``x`` (samples along axis 0) over [t - window/2, t + window/2]
    at every sample whose window lies inside the log, from the cumulative trapezoid integral."""
    dt = np.diff(t)
    integral = np.concatenate([np.zeros((1,) + x.shape[1:]),
                               np.cumsum(0.5 * (x[1:] + x[:-1]) * dt.reshape(-1, *([1] * (
                                   x.ndim - 1))), axis=0)])
    lo, hi = t - 0.5 * window, t + 0.5 * window
    mask = (lo >= t[0]) & (hi <= t[-1])
    at = lambda s: np.stack([np.interp(s, t, integral[:, k]) for k in range(  # noqa: E731
        integral.shape[1])], axis=1) if integral.ndim > 1 else np.interp(s, t, integral)
    return mask, (at(hi) - at(lo)) / window


def heading_frame_mean(t: np.ndarray, xy: np.ndarray, yaw: np.ndarray, window: float):
    """(velocity (n, 2), yaw rate (n,)): the mean over [t - window/2, t + window/2] of the
    horizontal velocity of ``xy`` -- its displacement over the window's length -- in the frame of
    the window's mean heading, and of the yaw rate (``yaw`` unwrapped)."""
    at = lambda x, s: np.interp(s, t, x)  # noqa: E731
    hi, lo = t + 0.5 * window, t - 0.5 * window
    v = np.stack([(at(xy[:, k], hi) - at(xy[:, k], lo)) / window for k in range(2)], axis=1)
    mid = 0.5 * (at(yaw, hi) + at(yaw, lo))
    c, s = np.cos(mid), np.sin(mid)
    return (np.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]], axis=1),
            (at(yaw, hi) - at(yaw, lo)) / window)


def rms(error: np.ndarray) -> float:
    """Root mean square of scalars (n,) or of vectors' norms (n, k)."""
    e = np.asarray(error, dtype=float)
    return float(np.sqrt(np.mean(e ** 2 if e.ndim == 1 else np.sum(e ** 2, axis=1))))


def tracking(rec: dict, schedule: CommandSchedule, period: float, ramp: float) -> dict:
    """Per part: the RMS velocity and yaw-rate errors of the gait-period means (module docstring)
    against the command, and, to tell the planner's share from the controller's, those of the CoM
    reference against the command (``reference_*``: the crawl's sway turning with the heading
    moves it) and of the measured CoM against the reference (``to_reference_*``); the heading
    errors. ``rec``: per-cycle ``t``, ``com`` and ``com_ref`` (m), ``yaw`` and ``heading`` (rad,
    unwrapped: measured and commanded), ``command`` (forward, lateral, yaw rate)."""
    t, yaw = rec["t"], rec["yaw"]
    v_heading, rate = heading_frame_mean(t, rec["com"][:, :2], yaw, period)
    v_ref, _ = heading_frame_mean(t, rec["com_ref"][:, :2], rec["heading"], period)
    mask, cmd = period_mean(t, rec["command"], period)
    parts = {}
    for name, start, end in schedule.phases:
        sel = mask & (t >= start + ramp) & (t <= end)
        if not np.any(sel):
            continue
        target = schedule.command(end)
        err = v_heading[sel] - cmd[sel, :2]
        speed = float(np.hypot(target[0], target[1]))
        row = {"command": [float(x) for x in target],
               "forward_rms_mps": rms(err[:, 0]), "lateral_rms_mps": rms(err[:, 1]),
               "velocity_rms_mps": rms(err),
               "yaw_rate_rms": rms(rate[sel] - cmd[sel, 2]),
               "reference_velocity_rms_mps": rms(v_ref[sel] - cmd[sel, :2]),
               "to_reference_velocity_rms_mps": rms(v_heading[sel] - v_ref[sel]),
               "mean_velocity_mps": [float(x) for x in v_heading[sel].mean(axis=0)],
               "mean_yaw_rate": float(rate[sel].mean())}
        for key in ("velocity", "reference_velocity", "to_reference_velocity"):
            row[f"{key}_error_share"] = row[f"{key}_rms_mps"] / speed if speed > 0 else None
        row["yaw_rate_error_share"] = (row["yaw_rate_rms"] / abs(target[2])
                                       if target[2] != 0 else None)
        parts[name] = row
    heading_err = np.degrees(yaw - rec["heading"])
    out = {"parts": parts, "heading_error_max_deg": float(np.abs(heading_err).max()),
           "heading_error_final_deg": float(heading_err[-1])}
    turn = [p for p in schedule.phases if p[0] == "turn"]
    if turn:
        t_end = turn[0][2] + ramp  # the yaw rate is back to 0
        out["heading_error_end_of_turn_deg"] = float(np.interp(t_end, t, heading_err))
        out["commanded_heading_change_deg"] = float(np.degrees(rec["heading"][-1]
                                                               - rec["heading"][0]))
        out["heading_change_deg"] = float(np.degrees(yaw[-1] - yaw[0]))
    return {**out, "velocity_mean": (v_heading, rate, cmd, mask, v_ref)}


def success_of(metrics: dict) -> tuple[bool, list[str]]:
    """Whether the run meets the module docstring's criteria, and each criterion missed."""
    misses = []
    if metrics["fell"]:
        misses.append(f"fell at {metrics.get('fell_at_s', float('nan')):.2f} s")
    if metrics["failed_cycles"]:
        misses.append(f"{metrics['failed_cycles']} failed WBC cycles")
    for key in ("heading_error_end_of_turn_deg", "heading_error_final_deg"):
        if key in metrics and not abs(metrics[key]) <= MAX_HEADING_ERROR_DEG:
            misses.append(f"{key.replace('_deg', '').replace('_', ' ')} {metrics[key]:+.1f} deg "
                          f"(limit {MAX_HEADING_ERROR_DEG:g})")
    for name, row in metrics["parts"].items():
        for key, what in (("velocity_error_share", "velocity"), ("yaw_rate_error_share",
                                                                 "yaw-rate")):
            share = row.get(key)
            if share is not None and not share <= MAX_VELOCITY_ERROR_SHARE:
                misses.append(f"{name}: {what} error RMS {100 * share:.0f} % of the command "
                              f"(limit {100 * MAX_VELOCITY_ERROR_SHARE:.0f} %)")
    return not misses, misses


# ---------------------------------------------------------------------- run
def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    schedule = command_schedule(robot, params)
    period = gait_period(robot, params)
    ramp = params["ramp"] * period
    rec = {k: [] for k in ("t", "com", "yaw", "command", "heading", "com_ref")}

    def on_cycle(t, result, ctrl, sim):
        q, _ = sim.state()
        R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
        rec["t"].append(t)
        rec["com"].append(robot.com.copy())
        rec["yaw"].append(math.atan2(R[1, 0], R[0, 0]))
        rec["command"].append(schedule.command(t))
        rec["heading"].append(ctrl.last_plan.trunk.yaw)
        rec["com_ref"].append(ctrl.last_plan.trunk.position[:2].copy())

    r = run_gait(robot, controller, params["gait"], schedule, schedule.end, progress=progress,
                 observers=observers, on_cycle=on_cycle,
                 controller_options={"engine": params["engine"],
                                     "regularization": params["regularization"]},
                 gains=wbc_gains(params), start=GAIT_START, shape=params)
    rec = {k: np.asarray(v, dtype=float) for k, v in rec.items()}
    rec["yaw"] = np.unwrap(rec["yaw"])
    # the commanded heading from the measured start, unwrapped like the measured yaw
    rec["heading"] = rec["yaw"][0] + np.unwrap(rec["heading"] - rec["heading"][0])
    measured = tracking(rec, schedule, period, ramp)
    v_heading, rate, cmd, mask, v_ref = measured.pop("velocity_mean")
    path = rec["com"][:, :2]
    commanded = rec["com_ref"]
    metrics = {**outcome(r), **measured, **r.tracking(t_from=GAIT_START),
               "path_length_m": float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()),
               "net_displacement_m": float(np.linalg.norm(path[-1] - path[0])),
               "commanded_net_displacement_m": float(np.linalg.norm(commanded[-1] - commanded[0])),
               "end_position_error_m": float(np.linalg.norm(path[-1] - commanded[-1])),
               "max_stance_slip_m": float(r.stance_slip().max()),
               "gait_period_s": period, "command": resolved_command(robot, params),
               "schedule": [{"part": n, "start_s": a, "end_s": b} for n, a, b in schedule.phases]}
    metrics.pop("distance_m", None)  # run_gait's x displacement: not a distance on a turn
    success, misses = success_of(metrics)
    c = metrics["command"]
    notes = [f"command: forward {c['speed']:.3g} m/s, turn {params['turn']:g} deg at "
             f"{c['yaw_rate']:.3g} rad/s walking {c['turn_speed']:.3g} m/s, side-step "
             f"{c['lateral']:.3g} m/s; gait period {period:.3f} s; parts: " + ", ".join(
                 f"{n} {a:.2f}-{b:.2f} s" for n, a, b in schedule.phases),
             f"success = no fall, no failed cycle, heading error <= {MAX_HEADING_ERROR_DEG:g} deg "
             f"(end of turn, end), velocity and yaw-rate error RMS <= "
             f"{100 * MAX_VELOCITY_ERROR_SHARE:.0f} % of the command per part"]
    notes += [f"missed: {m}" for m in misses]
    result = ScenarioResult("steer", robot.name, controller, success, metrics, params, notes)
    if out_dir is not None:
        result.figures = [str(steer_figure(
            Path(out_dir) / "steer.png", rec["t"], v_heading, rate, cmd, mask, v_ref, rec["yaw"],
            rec["heading"], path, commanded, schedule.phases,
            f"steer — {robot.name} {params['gait']}, "
            f"{'fell' if r.fell else 'no fall'}, {r.failures} failed cycles"))]
    return result


SCENARIO = Scenario(
    name="steer",
    summary="velocity-command schedule (forward, turn, side-step, stop) under the passive WBC; "
            "velocity/yaw-rate error RMS per part, heading error; success = no fall, no failed "
            "cycle, heading error <= 5 deg, velocity errors <= 10 % of the command",
    parameters=PARAMETERS,
    controllers=("passive",),
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
    simulations=1,
)
