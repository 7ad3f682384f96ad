"""``push``: one push on the standing humanoid under momentum balance (Herzog et al. 2016 Sect. 5.2.2).

The push is a half-sine force applied at one of the paper's 7 points (front, right, back, left on
the torso above the hip; front, right, left at the hip) or along any ``angle`` and ``height``.
"Survived" (issue criterion): the feet stay flat and in place (tilt < 2 deg, slip < 1 cm) and the CoG
returns within 5 mm of its reference within 3 s after the push.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..control.balance import MomentumBalance
from ..control.lqr import DEFAULT_INTEGRAL_LIMIT
from ..control.stacks import ANGULAR_MOMENTUM_WEIGHT
from ..report.plots import time_series_figure
from ..sim.disturbance import Push
from ..sim.simulator import Simulator
from .base import ENGINE, Parameter, Scenario, ScenarioResult, check_engine
from .loop import run_closed_loop

# location -> (frame, direction of the force, point of application in the frame)
TORSO_OFFSET, SURFACE = 0.1, 0.12
LOCATIONS = {
    "front": ("torso_2_link", (-1.0, 0.0, 0.0), (SURFACE, 0.0, TORSO_OFFSET)),
    "right": ("torso_2_link", (0.0, 1.0, 0.0), (0.0, -SURFACE, TORSO_OFFSET)),
    "back": ("torso_2_link", (1.0, 0.0, 0.0), (-SURFACE, 0.0, TORSO_OFFSET)),
    "left": ("torso_2_link", (0.0, -1.0, 0.0), (0.0, SURFACE, TORSO_OFFSET)),
    "hip-front": ("base_link", (-1.0, 0.0, 0.0), (SURFACE, 0.0, 0.0)),
    "hip-right": ("base_link", (0.0, 1.0, 0.0), (0.0, -SURFACE, 0.0)),
    "hip-left": ("base_link", (0.0, -1.0, 0.0), (0.0, SURFACE, 0.0)),
}

PARAMETERS = (
    Parameter("location", "front", f"push point: {', '.join(LOCATIONS)} (or 'angle')"),
    Parameter("angle", 0.0, "with location=angle: force direction in the horizontal plane (deg, "
                            "0 = pushing backwards from the front)"),
    Parameter("height", 0.1, "with location=angle: height of the point above the base (m)"),
    Parameter("peak_force", 100.0, "peak of the half-sine force (N)"),
    Parameter("push_duration", 0.1, "duration of the push (s), 0.05-0.15 in the paper"),
    Parameter("start", 0.5, "time of the push (s)"),
    Parameter("duration", 4.0, "simulated time (s)"),
    Parameter("q_angular", 0.1, "LQR weight on angular momentum (eq. 26 uses 0.1)"),
    Parameter("angular_weight", ANGULAR_MOMENTUM_WEIGHT,
              "weight of the momentum task's angular rows in Table 2 (1e4: the paper's single "
              "momentum weight, which lets the pelvis drift under model errors)"),
    Parameter("q_integral", 0.0, "LQR only: weight of the CoG-error integral (LQI; our extension, "
                                 "not the paper's); 0 = off, the paper's controller"),
    Parameter("integral_limit", DEFAULT_INTEGRAL_LIMIT,
              "LQR integral action: anti-windup clamp of each integral component (m s)"),
    ENGINE,
)


def controller_options(controller: str, params: dict) -> dict:
    """Keyword arguments of :class:`MomentumBalance` from the scenario parameters (``q_angular``,
    ``angular_weight``, ``engine``, and for LQR the integral action ``q_integral``/``integral_limit``;
    missing keys take the defaults above)."""
    defaults = {p.name: p.default for p in PARAMETERS}
    get = lambda key: params.get(key, defaults[key])  # noqa: E731
    opts = {"angular_weight": get("angular_weight"), "engine": get("engine")}
    if controller == "lqr":
        opts["Q"] = np.diag([30, 30, 50, .5, .5, .5] + [get("q_angular")] * 3)
        if get("q_integral") > 0:
            opts["q_integral"] = get("q_integral")
            opts["integral_limit"] = get("integral_limit")
    return opts


def make_push(params: dict) -> Push:
    location = params["location"]
    if location == "angle":
        a = np.radians(params["angle"])
        direction = (-np.cos(a), -np.sin(a), 0.0)
        offset = (SURFACE * np.cos(a), SURFACE * np.sin(a), params["height"])
        frame = "base_link"
    elif location in LOCATIONS:
        frame, direction, offset = LOCATIONS[location]
    else:
        raise ValueError(f"--set location: '{location}' is not one of {', '.join(LOCATIONS)}, angle")
    return Push(frame, direction, params["peak_force"], params["start"], params["push_duration"],
                offset=offset)


def validate(robot, params: dict) -> None:
    check_engine(params)
    push = make_push(params)
    if not robot.model.existFrame(push.frame):
        raise ValueError(f"robot '{robot.name}' has no frame '{push.frame}' to push at; the push "
                         f"scenario is for the Talos humanoids (talos14, talos)")
    if any(c.spec.type != "rectangle" for c in robot.contacts):
        raise ValueError(f"robot '{robot.name}': momentum balance needs rectangular soles")


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool) -> ScenarioResult:
    push = make_push(params)
    ctrl = MomentumBalance(robot, gains=controller, **controller_options(controller, params))
    sim = Simulator(robot)
    sim.add_push(push)
    start_feet = sim.contact_frame_poses()
    com, momentum, feet_tilt, feet_slip = [], [], [], []

    def observe(t, result):
        com.append(robot.com - ctrl.com_ref)
        momentum.append(robot.h_G.copy())
        poses = sim.contact_frame_poses()
        feet_tilt.append(max(np.degrees(np.arccos(np.clip(R[2, 2], -1, 1)))
                             for _, R in poses.values()))
        feet_slip.append(max(np.linalg.norm((poses[n][0] - start_feet[n][0])[:2]) for n in poses))

    failures = run_closed_loop(sim, ctrl, params["duration"], progress=progress, on_result=observe)
    arrays = sim.log.arrays()
    t = arrays["t"]
    com, momentum = np.array(com), np.array(momentum)
    err = np.linalg.norm(com, axis=1)
    push_end = push.start + push.duration
    deadline = push_end + 3.0
    after = t >= push_end
    outside = np.flatnonzero(after & (err > 5e-3))
    recovery = 0.0 if outside.size == 0 else float(t[outside[-1]] - push_end)
    recovered = bool(outside.size == 0 or t[outside[-1]] < min(deadline, t[-1] - 0.2))
    metrics = {
        "peak_force_N": push.peak_force,
        "impulse_Ns": push.impulse,
        "delta_v_mps": push.impulse / robot.mass,
        "max_cog_error_m": float(err.max()),
        "final_cog_error_m": float(err[-1]),
        "max_linear_momentum_Ns": float(np.linalg.norm(momentum[:, :3], axis=1).max()),
        "max_angular_momentum_Nms": float(np.linalg.norm(momentum[:, 3:], axis=1).max()),
        "cog_recovery_time_s": recovery,
        "max_foot_tilt_deg": float(max(feet_tilt)),
        "max_foot_slip_m": float(max(feet_slip)),
        "failed_cycles": failures,
    }
    success = (recovered and metrics["max_foot_tilt_deg"] < 2.0
               and metrics["max_foot_slip_m"] < 0.01)
    notes = []
    if controller != "lqr" and params.get("q_integral", 0.0) > 0:
        notes.append("q_integral is an LQR option; ignored with the PD gains")
    if controller == "lqr" and params["q_angular"] == 0.1:
        notes.append("eq. 26's Q weighs angular momentum by 0.1; on talos14 (heavy upper body) "
                     "this leaves the trunk rotation nearly undamped — try --set q_angular=10")
    result = ScenarioResult("push", robot.name, controller, success, metrics, params, notes,
                            log=sim.log)
    if out_dir is not None:
        shaded = [(push.start, push_end)]
        result.figures = [str(time_series_figure(
            Path(out_dir) / "push.png", t,
            [("push force", "N", {"|F|": np.linalg.norm(arrays["push_force"], axis=1)}),
             ("CoG error", "cm", {a: 100 * com[:, i] for i, a in enumerate("xyz")}),
             ("linear momentum", "N s", {a: momentum[:, i] for i, a in enumerate("xyz")}),
             ("angular momentum", "N m s", {a: momentum[:, 3 + i] for i, a in enumerate("xyz")})],
            title=f"push {params['location']} {push.peak_force:.0f} N — {robot.name}, "
                  f"{controller} momentum gains", shaded=shaded))]
    return result


SCENARIO = Scenario(
    name="push",
    summary="one half-sine push on the standing humanoid under momentum balance (Table 2, no "
            "joint PD); success = feet flat and in place, CoG back within 5 mm within 3 s",
    parameters=PARAMETERS,
    controllers=("lqr", "pd"),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
)
