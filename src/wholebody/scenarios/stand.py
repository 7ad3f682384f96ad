"""``stand``: the robot stands on flat ground in the twin under the baseline standing controller."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from ..control.standing import DEFAULT_DAMPING_RATIO, DEFAULT_FREQUENCY_HZ, StandingController
from ..report.balance_figures import stand_figure
from ..sim.environment import Environment
from ..sim.simulator import Simulator
from .base import Parameter, Scenario, ScenarioResult, duration_parameter
from .loop import run_closed_loop
from .measures import fallen, sole_slip, tilt_deg

PARAMETERS = (
    duration_parameter(5.0),
    Parameter("frequency_hz", DEFAULT_FREQUENCY_HZ, "natural frequency of each joint's PD (Hz): "
              "kp = (2 pi f)^2 M_ii, M_ii the joint's inertia at the reference posture",
              low=0.0, low_open=True, high=30.0),
    Parameter("damping_ratio", DEFAULT_DAMPING_RATIO, "damping ratio of each joint's PD: "
              "kd = 2 zeta (2 pi f) M_ii", low=0.0, high=10.0),
    Parameter("kp", -1.0, "joint stiffness of the PD, every joint (Nm/rad) (-1: from "
              "frequency_hz)", low=0.0, special=(-1.0,)),
    Parameter("kd", -1.0, "joint damping of the PD, every joint (Nm s/rad) (-1: from "
              "frequency_hz and damping_ratio)", low=0.0, special=(-1.0,)),
    Parameter("friction", 1.0, "floor friction coefficient", low=0.0, low_open=True, high=10.0),
    Parameter("drift_tolerance", 0.01 * Parameter.H, "largest base drift counted as success (m)",
              low=0.0, low_open=True, high=Parameter.H),
)


def standing_metrics(arrays: dict, robot) -> dict:
    """Base drift and tilt, foot slip, and contact forces of a logged standing run."""
    q = arrays["q"]
    base = q[:, :3]
    drift = np.linalg.norm(base - base[0], axis=1)
    tilt = np.array([tilt_deg(pin.Quaternion(qi[6], *qi[3:6]).toRotationMatrix()) for qi in q])
    wrenches = arrays["contact_wrenches"]
    return {
        "base_drift_max_m": float(drift.max()),
        "base_drift_final_m": float(drift[-1]),
        "base_tilt_max_deg": float(tilt.max()),
        "base_height_min_m": float(base[:, 2].min()),
        "normal_force_mean_N": {n: float(wrenches[:, i, 2].mean())
                                for i, n in enumerate(robot.contact_names)},
        "normal_force_min_N": {n: float(wrenches[:, i, 2].min())
                               for i, n in enumerate(robot.contact_names)},
    }


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    sim = Simulator(robot, Environment(floor_friction=params["friction"]), observers=observers)
    ctrl = StandingController(robot, kp=None if params["kp"] == -1.0 else params["kp"],
                              kd=None if params["kd"] == -1.0 else params["kd"],
                              frequency_hz=params["frequency_hz"],
                              damping_ratio=params["damping_ratio"])
    start_sites = {n: p for n, (p, _) in sim.contact_frame_poses().items()}
    slip = {n: 0.0 for n in robot.contact_names}
    force_error = []

    def observe(t, result):
        for n, (p, _) in sim.contact_frame_poses().items():
            slip[n] = max(slip[n], float(sole_slip(p, start_sites[n])))
        if t > 0.5:  # after settling: the controller's contact forces vs the simulator's
            measured = sim.contact_wrenches()
            force_error.append(max(np.linalg.norm(result.contact_forces[n][:3] - measured[n][:3])
                                   for n in robot.contact_names))

    failures = run_closed_loop(sim, ctrl, params["duration"], progress=progress, on_result=observe)
    arrays = sim.log.arrays()
    metrics = standing_metrics(arrays, robot)
    metrics["foot_slip_max_m"] = max(slip.values())
    metrics["contact_force_prediction_error_max_N"] = float(max(force_error, default=0.0))
    metrics["torque_saturated_cycles"] = failures
    metrics["simulated_s"] = float(arrays["t"][-1] + sim.dt)
    fell = fallen(metrics["base_tilt_max_deg"], metrics["base_height_min_m"], robot.q_ref[2])
    metrics["fell"] = bool(fell)
    success = (not fell) and metrics["base_drift_max_m"] < params["drift_tolerance"]
    result = ScenarioResult("stand", robot.name, controller, success, metrics, params,
                            log=sim.log)
    if out_dir is not None:
        result.figures = [str(stand_figure(Path(out_dir) / "stand.png", arrays, robot.joint_names,
                                           robot.contact_names, title=f"stand — {robot.name}"))]
    return result


SCENARIO = Scenario(
    name="stand",
    summary="stand still on flat ground for `duration` s with contact-consistent gravity "
            "compensation + joint PD; success = no fall and base drift < drift_tolerance",
    parameters=PARAMETERS,
    controllers=("standing",),
    default_robot="talos14",
    run_function=run,
    simulations=1,
)
