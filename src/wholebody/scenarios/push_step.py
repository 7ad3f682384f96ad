"""``push-step``: a push on the standing humanoid that the capture-point controller
(:class:`~wholebody.control.walking.Walking`) recovers by stepping (N-step capturability).

The robot stands under the controller; at ``start`` a half-sine push of ``push_duration`` gives it
the velocity change ``dv`` (impulse m dv, peak force 0.5 pi m dv / push_duration). It comes along
``angle`` in the horizontal plane and is applied ``height`` above the base frame, as the ``push``
scenario's ``location=angle``: the force points along (-cos angle, -sin angle), so 0 deg pushes
the front backwards (toward -x), 90 deg the left side toward -y, 180 deg the back forwards. When
the capture point leaves the soles' support, the controller steps (``stepping=false``: it never
steps, the feet-flat balance alone).

Measured on the simulator: the steps taken (times, landing points relative to the start soles),
the capture point's largest distance outside the support of the soles in contact, failed cycles,
the largest torque change between cycles, and falls (:func:`~wholebody.scenarios.measures.fallen`;
the run stops there).

Survived: no fall, the controller standing again at the end and the base within 10 % of its
initial height. Success = survived. A series (``angles``) pushes along each angle; with
``bisect`` it searches, per angle, the strongest survived ``dv`` between ``bisect_low`` and
``bisect_high`` (each trial a full simulation; success: every angle survived some push).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..control.walking import Walking, WalkingConfig
from ..report.plots import grouped_bar_figure, save_figure
from ..robots.roles import biped_soles
from .base import (COP_MARGIN, ENGINE, TIME_SPAN, Parameter, Scenario,
                   ScenarioResult, check_engine, duration_parameter)
from .pushes import (FroudeScaled, bisect_dv, check_bisection, push_angles, push_series,
                     series_parameters, series_simulations)
from .walking_runs import (WalkRun, capture_point_outside_support,
                           draw_torque_steps, push_of, shade_swings, simulate, step_rows,
                           torque_jumps, walking_figure)

#: standing again: the base within this share of its initial height at the end
HEIGHT_TOLERANCE = 0.1


PARAMETERS = (
    Parameter("dv", FroudeScaled(0.6, "m/s", height_power=0.5),
              "the push's velocity change (m/s): impulse m dv, peak force 0.5 pi m dv / "
              "push_duration", low=0.0, low_open=True, high=5.0),
    Parameter("angle", 0.0, "direction of the push in the horizontal plane (deg): the force "
                            "along (-cos, -sin); 0 = on the front, backwards; 90 = on the left "
                            "side; 180 = on the back, forwards", low=-360.0, high=360.0),
    Parameter("height", 0.0, "height of the push point above the base frame (m)",
              low=-Parameter.H, high=Parameter.H),
    Parameter("push_duration", 0.1, "duration of the push (s)", **TIME_SPAN),
    Parameter("start", 1.0, "time of the push (s)", low=0.0, high=Parameter.MAX_TIME),
    duration_parameter(5.0, "simulated time per push (s)"),
    Parameter("stepping", True, "recover by stepping (false: feet-flat balance only)"),
    *series_parameters(FroudeScaled(0.2, "m/s", height_power=0.5),
                       FroudeScaled(1.5, "m/s", height_power=0.5)),
    COP_MARGIN,
    ENGINE,
)


def validate(robot, params: dict) -> None:
    check_engine(params)
    biped_soles(robot)  # ValueError unless two rectangular soles
    WalkingConfig.for_robot(robot, cop_margin=params["cop_margin"])
    for angle in push_angles(params):
        push_of(robot, params, params["dv"], angle)
    if params["start"] + params["push_duration"] >= params["duration"]:
        raise ValueError(f"--set duration: {params['duration']:g} s ends before the push does "
                         f"(start {params['start']:g} s + push_duration "
                         f"{params['push_duration']:g} s)")
    check_bisection(params)


def trial(robot, params: dict, dv: float, angle: float, progress: bool = False,
          observers=()) -> tuple[dict, WalkRun]:
    """One push of ``dv`` along ``angle`` on the standing robot: its metrics and the run."""
    ctrl = Walking(robot, WalkingConfig.for_robot(robot, stepping=bool(params["stepping"]),
                                                  cop_margin=params["cop_margin"]),
                   engine=params["engine"])
    push = push_of(robot, params, dv, angle)
    run = simulate(robot, ctrl, params["duration"], push=lambda run, t: push,
                   progress=progress, observers=observers,
                   label=f"dv {dv:.3g} m/s, {angle:g} deg")
    z = run.a["base_position"][:, 2]
    standing = ctrl.phase.kind == "stand"
    height_ok = abs(z[-1] - z[0]) <= HEIGHT_TOLERANCE * z[0]
    cp = run.a["cp_distance"] = capture_point_outside_support(robot, run)
    metrics = {
        "dv_mps": dv, "angle_deg": angle, "peak_force_N": push.peak_force,
        "impulse_Ns": push.impulse,
        "survived": bool(not run.fallen and standing and height_ok), "fallen": run.fallen,
        "fell_at_s": run.fell_at, "standing_at_end": standing,
        "final_base_height_change": float(z[-1] / z[0] - 1.0),
        "steps_taken": len(ctrl.steps), "steps": step_rows(run),
        "max_capture_point_distance_from_support_m": float(np.nanmax(cp))
        if np.isfinite(cp).any() else None,
        "failed_cycles": run.failed_cycles,
        "max_torque_step_Nm": float(torque_jumps(run.a["tau"]).max()),
    }
    return metrics, run


def bisection(robot, params: dict, angle: float, progress: bool, observers) -> dict:
    """The strongest survived dv along ``angle`` between ``bisect_low`` and ``bisect_high``
    (:func:`~.pushes.bisect_dv`)."""
    return bisect_dv(
        lambda dv: trial(robot, params, dv, angle, progress, observers)[0]["survived"],
        float(params["bisect_low"]), float(params["bisect_high"]), int(params["bisect_steps"]))


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    angle_list = push_angles(params)
    notes = [f"survived = no fall, standing again at the end, the base within "
             f"{HEIGHT_TOLERANCE:.0%} of its initial height; angle 0 pushes the front "
             f"backwards, 90 the left side"]
    series = push_series(params, lambda a: bisection(robot, params, a, progress, observers),
                         lambda dv, a: trial(robot, params, dv, a, progress, observers))
    single = series.single()
    result = ScenarioResult("push-step", robot.name, controller, bool(series.success),
                            series.metrics, params, notes,
                            log=single[1].sim.log if single else None)
    if out_dir is not None:
        if single:
            only, run_ = single
            path = push_step_figure(
                Path(out_dir) / "push_step.png", robot, run_,
                title=f"push-step — {robot.name}, dv {params['dv']:.2f} m/s at "
                      f"{angle_list[0]:g} deg, stepping {'on' if params['stepping'] else 'off'}: "
                      f"{'survived' if only['survived'] else 'not survived'}")
        else:
            name, label = (("push_step_bisection.png", "strongest survived dv (cm/s)")
                           if params["bisect"] else
                           ("push_step_series.png",
                            "max capture-point distance outside the support (cm)"))
            path = grouped_bar_figure(
                Path(out_dir) / name, [f"{a:g} deg" for a in angle_list],
                {label: series.bar_values("max_capture_point_distance_from_support_m")},
                title=f"push-step — {robot.name}", ylabel=label)
        result.figures = [str(path)]
    return result


def push_step_figure(path: Path, robot, run: WalkRun, title: str) -> Path:
    """Top view (soles, CoM, DCM, ZMP command, the push) and time series (push force and base
    height, the capture point's distance outside the support, torque steps)."""
    a, t = run.a, run.a["t"]
    fig, axes = walking_figure(robot, run,
                               "top view (start soles solid, landed soles dashed, push arrow)")
    force = np.linalg.norm(run.sim.log.arrays()["push_force"], axis=1)[:len(t)]
    axes[0].plot(t[:len(force)], force, color="tab:green", label="push |F| (N)")
    axes[0].set_ylabel("N", fontsize=8)
    twin = axes[0].twinx()
    twin.plot(t, a["base_position"][:, 2], color="k", linewidth=0.8, label="base height (m)")
    twin.set_ylabel("base height (m)", fontsize=8)
    axes[0].set_title("push force and base height", fontsize=9)
    axes[1].plot(t, 100 * a["cp_distance"])
    axes[1].set_ylabel("cm", fontsize=8)
    axes[1].set_title("capture point outside the support of the soles in contact", fontsize=9)
    draw_torque_steps(axes[2], run)
    for ax in axes:
        shade_swings(ax, run)
        ax.grid(True, alpha=0.3)
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


SCENARIO = Scenario(
    name="push-step",
    summary="a push on the standing humanoid recovered by stepping (capture-point controller); "
            "optionally a series of angles with a bisection of the strongest survived dv; "
            "success = no fall, standing again at the end",
    parameters=PARAMETERS,
    controllers=("dcm",),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
    simulations=series_simulations,
)
