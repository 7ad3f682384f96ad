"""``trot-push``: a quadruped trotting forward is pushed mid-stride and trots on, the trunk
impedance and the friction cones of the passive WBC doing the work (Fahmi et al. 2019, eqs. 4 and
13; the footholds stay the planner's Raibert targets, which do not react to the push unless
``feedback_gain`` is set).

The robot stands for 1 s, its forward command (``speed``: HyQ's 0.4 m/s trot, Froude-scaled, as
``steer``) ramps in over one gait period, and it trots for ``settle`` gait periods from the gait's
start. ``phase`` gait periods later (a share of the period from a lift-off of the first diagonal;
0.25, the default, is the middle of the other diagonal's stance) a half-sine force of
``push_duration`` centred on that instant pushes the trunk at its centre of mass, giving the robot
the velocity change ``dv`` (impulse m dv). It comes along ``angle`` as in the ``push`` scenario:
the force points along (-cos angle, -sin angle) in the world, so 0 pushes the front backwards, 90
the left side toward -y, 180 the back forwards. The run ends ``after`` gait periods after the push.

Measured on the simulator over the time after the push's start: the largest horizontal CoM
deviation from its reference and trunk orientation error, the recovery time (the push's end to
when the CoM deviation is back, for good, under twice the largest it had over the gait period
before the push), failed cycles, the distance the CoM covers along the commanded heading against
the commanded ``speed`` x that time, the heading error (base yaw minus the commanded heading), the
largest stance-foot slip, and the shares of the cycles from the push to the fall (if any) with a
joint torque at its limit and with a foot force on its friction pyramid (eq. 13).

Survived (walked on): no fall, no failed cycle, the distance covered after the push at least 80 %
of the commanded one, and the heading error at the end within 5 deg. With ``bisect`` the largest
survived ``dv`` per angle of ``angles`` is searched between ``bisect_low`` and ``bisect_high``
(each step one simulation).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..control.passive import ENGINES
from ..planning.trunk import CommandPhase, CommandSchedule
from ..report.plots import grouped_bar_figure, time_series_figure
from ..sim.disturbance import Push
from ..sim.simulator import SimulationDiverged
from ..tasks.contact import friction_faces
from .base import TIME_SPAN, Parameter, Scenario, ScenarioResult
from .gait_measures import outcome
from .locomotion import (GAIT_SHAPE, REGULARIZATION, TROT_SPEED, WBC_GAINS, PaperSpeed,
                         check_gait, check_quadruped, make_schedule, run_gait, wbc_gains)
from .pushes import (bisect_dv, check_bisection, peak_force_for, push_angles, push_direction,
                     push_series, series_parameters, series_simulations)

logger = logging.getLogger(__name__)

#: the robot stands this long before its gait starts (s)
GAIT_START = 1.0
#: walked on: the CoM covers this share of the commanded distance after the push, and the
#: heading error at the end is within this (deg)
DISTANCE_SHARE = 0.8
MAX_HEADING_ERROR_DEG = 5.0
#: recovered: the CoM deviation under this many times its largest over the period before the push
RECOVERY_FACTOR = 2.0
#: a torque within this share of its range from a limit counts as at the limit; a foot force
#: within this share of mu f_n of a face of its friction pyramid as on it
AT_LIMIT_SHARE = 1e-3

PARAMETERS = (
    Parameter("speed", PaperSpeed(TROT_SPEED), "forward trotting speed (m/s)", low=0.0,
              low_open=True, high=5.0),
    Parameter("dv", PaperSpeed(0.3), "the push's velocity change (m/s): impulse m dv, peak force "
              "0.5 pi m dv / push_duration", low=0.0, low_open=True, high=5.0),
    Parameter("angle", 90.0, "direction of the push (deg), as push's: the force along (-cos, "
              "-sin); 0 = on the front, backwards; 90 = on the left side; 180 = on the back, "
              "forwards", low=-360.0, high=360.0),
    Parameter("phase", 0.25, "when the push is centred, in gait periods after the settle "
              "(0.25: the middle of a diagonal's stance)", low=0.0, high=1.0, high_open=True),
    Parameter("settle", 4.0, "gait periods trotted before the push (the first ramps the speed "
              "in)", low=2.0, high=100.0),
    Parameter("after", 4.0, "gait periods trotted after the push (the distance window)",
              low=1.0, high=100.0),
    Parameter("push_duration", 0.1, "duration of the push (s)", **TIME_SPAN),
    *series_parameters(0.0, PaperSpeed(1.2)),
    Parameter("feedback_gain", 0.0, "Raibert foothold feedback k (s): footholds moved by k times "
              "the CoM velocity error (0: the planner's default, no reaction)", low=0.0,
              high=10.0),
    Parameter("engine", "auto", "passive WBC engine: native, python or auto", choices=ENGINES),
    REGULARIZATION,
    *WBC_GAINS,
    *GAIT_SHAPE,
)


def timing(robot, params: dict) -> dict:
    """The gait ``period``, the push's centre ``push_time`` and the run's ``end`` (s)."""
    period = make_schedule(robot, "trot", GAIT_START, params).period
    push_time = GAIT_START + (params["settle"] + params["phase"]) * period
    return {"period": period, "push_time": push_time,
            "end": push_time + params["after"] * period}


def command_schedule(robot, params: dict) -> CommandSchedule:
    """Forward at ``speed`` from the gait's start, ramped in over one gait period."""
    t = timing(robot, params)
    return CommandSchedule.from_phases(
        [CommandPhase("forward", t["end"] - GAIT_START, params["speed"])], GAIT_START,
        t["period"])


def trunk_push(robot, dv: float, angle: float, centre: float, duration: float) -> Push:
    """The half-sine push of ``duration`` centred on ``centre`` giving ``robot`` the velocity
    change ``dv`` along ``angle`` (:func:`~.pushes.push_direction`), applied at the centre of
    mass of the body carrying the base frame (the trunk: no moment about it)."""
    model = robot.model
    frame = model.frames[model.getFrameId(robot.base_frame)]
    com = frame.placement.actInv(model.inertias[frame.parentJoint].lever)
    return Push(robot.base_frame, push_direction(angle), peak_force_for(robot.mass, dv, duration),
                centre - 0.5 * duration, duration, offset=tuple(float(x) for x in com))


def validate(robot, params: dict) -> None:
    check_gait({**params, "gait": "trot"})
    check_quadruped(robot, "the trot-push scenario", "trot")
    push_angles(params)
    t = timing(robot, params)
    if params["push_duration"] > t["period"]:
        raise ValueError(f"--set push_duration: {params['push_duration']:g} s is longer than the "
                         f"gait period ({t['period']:.3f} s)")
    if t["end"] > Parameter.MAX_TIME:
        raise ValueError(f"the run lasts {t['end']:.0f} s, more than {Parameter.MAX_TIME:g} s: "
                         "fewer --set settle or after periods")
    check_bisection(params)


# ---------------------------------------------------------------------- measures
def heading_error_deg(yaw: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Base yaw minus commanded heading (deg), both unwrapped from the same start."""
    yaw = np.unwrap(yaw)
    heading = yaw[0] + np.unwrap(heading - heading[0])
    return np.degrees(yaw - heading)


def recovery_time(t: np.ndarray, deviation: np.ndarray, level: float, since: float):
    """The time from ``since`` until ``deviation`` is under ``level`` for the rest of the record
    (s); None if it still is not at the end."""
    above = np.flatnonzero((t >= since) & (deviation >= level))
    if not len(above):
        return 0.0
    if above[-1] == len(t) - 1:
        return None
    return float(t[above[-1] + 1] - since)


def at_limit_share(tau, lo, hi) -> float:
    """The share of cycles in which some joint torque is at a limit."""
    tol = AT_LIMIT_SHARE * (hi - lo)
    return float(np.mean(np.any((tau >= hi - tol) | (tau <= lo + tol), axis=1))) if len(tau) \
        else 0.0


def on_cone_share(forces: np.ndarray, stance: np.ndarray, mu: float) -> float:
    """The share of cycles in which some stance foot's force (world axes, flat ground) is on a
    face of its friction pyramid (eq. 13): within :data:`AT_LIMIT_SHARE` of mu times the normal
    force."""
    f = forces.reshape(len(forces), -1, 3)
    faces = friction_faces(np.array([0.0, 0.0, 1.0]), mu)
    slack = -(f @ faces.T).max(axis=-1)  # >= 0 inside the pyramid
    on = stance.astype(bool) & (f[..., 2] > 0) & (slack <= AT_LIMIT_SHARE * mu * f[..., 2])
    return float(np.mean(np.any(on, axis=1))) if len(f) else 0.0


def trial(robot, params: dict, dv: float, angle: float, progress: bool = False,
          observers=()) -> tuple[dict, object]:
    """One trot pushed by ``dv`` along ``angle``: its metrics (module docstring) and the run."""
    t_ = timing(robot, params)
    period = t_["period"]
    push = trunk_push(robot, dv, angle, t_["push_time"], params["push_duration"])
    rec = {"yaw": [], "heading": []}

    def on_cycle(t, result, ctrl, sim):
        q, _ = sim.state()
        R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
        rec["yaw"].append(math.atan2(R[1, 0], R[0, 0]))
        rec["heading"].append(ctrl.last_plan.trunk.yaw)

    r = run_gait(robot, "passive", "trot", command_schedule(robot, params), t_["end"],
                 progress=progress, observers=observers, on_cycle=on_cycle,
                 controller_options={"engine": params["engine"],
                                     "regularization": params["regularization"]},
                 planner_options={"feedback_gain": params["feedback_gain"]},
                 gains=wbc_gains(params), start=GAIT_START, shape=params, pushes=(push,))
    metrics = {"dv_mps": dv, "angle_deg": angle, "peak_force_N": push.peak_force,
               "impulse_Ns": push.impulse, "push_start_s": push.start, "gait_period_s": period,
               **outcome(r), **after_push(r, push, rec, params["speed"], period)}
    metrics["survived"] = bool(
        not r.fell and r.failures == 0 and metrics["pushed"]
        and metrics["distance_share"] >= DISTANCE_SHARE
        and abs(metrics["heading_error_final_deg"]) <= MAX_HEADING_ERROR_DEG)
    return metrics, r


def after_push(r, push: Push, rec: dict, speed: float, period: float) -> dict:
    """The measures of the module docstring over the run ``r`` from ``push``'s start (``rec``:
    per-cycle measured ``yaw`` and commanded ``heading``); ``pushed`` False and no measures if
    the run ended before the push."""
    log = r.log
    t = log["t"]
    after = t >= push.start
    if not after.any():
        return {"pushed": False}
    before = (t >= push.start - period) & ~after
    up = after & (t < (r.fell_at if r.fell_at is not None else math.inf))  # not yet fallen
    heading_err = heading_error_deg(np.asarray(rec["yaw"]), np.asarray(rec["heading"]))
    deviation = np.linalg.norm(log["com_error"][:, :2], axis=1)
    level = RECOVERY_FACTOR * float(deviation[before].max()) if before.any() else 0.0
    heading = float(rec["heading"][int(np.argmax(after))])
    start = np.array([np.interp(push.start, t, log["com"][:, k]) for k in range(2)])
    covered = float(np.dot(log["com"][-1, :2] - start, (math.cos(heading), math.sin(heading))))
    commanded = speed * float(t[-1] - push.start)
    return {
        "pushed": True,
        "max_com_deviation_m": float(deviation[after].max()),
        "max_orientation_error_deg": float(np.degrees(np.linalg.norm(
            log["orientation_error"][after], axis=1).max())),
        "deviation_before_push_m": float(deviation[before].max()) if before.any() else None,
        "recovery_time_s": recovery_time(t, deviation, level, push.start + push.duration),
        "distance_after_push_m": covered, "commanded_distance_after_push_m": commanded,
        "distance_share": covered / commanded if commanded > 0 else 0.0,
        "heading_error_final_deg": float(heading_err[-1]),
        "heading_error_max_deg": float(np.abs(heading_err[after]).max()),
        "max_stance_slip_m": float(r.stance_slip().max()),
        "torque_at_limit_share_after_push": at_limit_share(
            log["tau"][up], log["tau_min"][up], log["tau_max"][up]),
        "friction_cone_share_after_push": on_cone_share(log["forces"][up], log["stance"][up],
                                                        r.controller.mu),
    }


def bisection(robot, params: dict, angle: float, progress: bool, observers) -> dict:
    """The strongest survived dv along ``angle`` between ``bisect_low`` and ``bisect_high``
    (:func:`~.pushes.bisect_dv`); a trial whose simulation diverged (a violent fall) counts as
    not survived and is listed in ``diverged_dv_mps``."""
    diverged = []

    def survives(dv: float) -> bool:
        try:
            return trial(robot, params, dv, angle, progress, observers)[0]["survived"]
        except SimulationDiverged as exc:
            logger.info("trot-push: dv %.3g m/s at %g deg: %s", dv, angle, exc)
            diverged.append(dv)
            return False

    found = bisect_dv(survives, float(params["bisect_low"]), float(params["bisect_high"]),
                      int(params["bisect_steps"]))
    return {**found, "diverged_dv_mps": diverged}


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    angle_list = push_angles(params)
    t_ = timing(robot, params)
    notes = [f"trot at {params['speed']:.3g} m/s, gait period {t_['period']:.3f} s; push centred "
             f"at {t_['push_time']:.2f} s, run to {t_['end']:.2f} s; survived = no fall, no "
             f"failed cycle, >= {100 * DISTANCE_SHARE:.0f} % of the commanded distance after the "
             f"push, heading error <= {MAX_HEADING_ERROR_DEG:g} deg at the end; angle 0 pushes the "
             "front backwards, 90 the left side"]
    series = push_series(params, lambda a: bisection(robot, params, a, progress, observers),
                         lambda dv, a: trial(robot, params, dv, a, progress, observers))
    single = series.single()
    result = ScenarioResult("trot-push", robot.name, controller, bool(series.success),
                            series.metrics, params, notes,
                            log=single[1].sim.log if single else None)
    if out_dir is not None:
        if single:
            m, r = single
            start = m["push_start_s"]
            path = trot_push_figure(Path(out_dir) / "trot_push.png", r.log,
                                    (start, start + params["push_duration"]),
                                    f"trot-push — {robot.name}, dv {m['dv_mps']:.2f} m/s at "
                                    f"{m['angle_deg']:g} deg: "
                                    f"{'walked on' if m['survived'] else 'did not walk on'}")
        else:
            label = ("strongest survived dv (cm/s)" if params["bisect"] else
                     "largest CoM deviation (cm)")
            path = grouped_bar_figure(Path(out_dir) / "trot_push.png",
                                      [f"{a:g} deg" for a in angle_list],
                                      {label: series.bar_values("max_com_deviation_m")},
                                      title=f"trot-push — {robot.name}", ylabel=label)
        result.figures = [str(path)]
    return result


def trot_push_figure(path: Path, log: dict, push: tuple[float, float], title: str) -> Path:
    """The CoM's deviation from its reference (x, y) and the trunk orientation error of one
    pushed trot (a gait-run log), the push's (start, end) shaded."""
    panels = [("CoM reference minus measured", "m",
               {"x": log["com_error"][:, 0], "y": log["com_error"][:, 1]}),
              ("trunk orientation error", "deg",
               {k: np.degrees(log["orientation_error"][:, i]) for i, k in
                enumerate(("roll", "pitch", "yaw"))})]
    return time_series_figure(path, log["t"], panels, title, shaded=[push])


SCENARIO = Scenario(
    name="trot-push",
    summary="a push at the trunk's CoM in the middle of a trot's diagonal stance (passive WBC); "
            "optionally a series of angles with a bisection of the strongest survived dv; "
            "success = no fall, no failed cycle, >= 80 % of the commanded distance after it, "
            "heading within 5 deg",
    parameters=PARAMETERS,
    controllers=("passive",),
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
    simulations=series_simulations,
)
