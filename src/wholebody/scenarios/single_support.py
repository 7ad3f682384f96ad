"""``single-support``: contact switching, pushes and leg swinging on one foot (Herzog et al. 2016
Sect. 5.4, Table 4, Fig. 11).

Torques from the hierarchy only (no joint PD); momentum task PD (eq. 22) or LQR (eqs. 23-24). The
controller is :class:`~wholebody.control.contact_switch.ContactSwitch` (CoG shift, unloading,
single support lifting the other sole, leg swinging); this scenario adds pushes in single support
with the foot held up (``push_forces``, half-sine; the paper: up to 150 N, 4.5-5.8 Ns) and a push
at the hip from the front during the leg swinging (Fig. 11: knee tracking error, linear momentum,
push force, stance CoP). The swinging joints are the hip and knee flexion joints of the swing leg
tracking 0.25 Hz sines.

Success: every cycle solved, the foot lifted (and never touching the floor again), the CoG back within 5 mm of its reference within
``recovery_time`` after every push and at the end, the stance sole flat (< 2 deg) and in place
(< 1 cm), and no cycle-to-cycle torque change above ``max_torque_jump`` outside the push windows
and the first :data:`SETTLE_TIME` s (reported apart): the twin places the robot with its soles
touching the floor at zero penetration, it sinks onto its soft contacts' equilibrium (a fraction
of a millimetre) and the controller's answer to that sink, with PD gains the largest
cycle-to-cycle change of every humanoid's run, is not a phase switch. All of these are measured on the simulator (its state,
sole poses and contact wrenches).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..control.contact_switch import ContactSwitch, ContactSwitchConfig, Timeline
from ..report.balance_figures import fig11, single_support_figure
from ..robot import FREE_FLYER_NQ, FREE_FLYER_NV
from ..robots.roles import BIPED_ROLES, biped_soles, leg_joints, pitch_joints
from ..sim.simulator import Simulator
from .base import (COP_MARGIN, PD_PARAMETERS, POSTURE_PARAMETERS, Q_ANGULAR,
                   SWING_FOOT_PARAMETERS, TIME_SPAN, Parameter, Scenario, ScenarioResult,
                   duration_parameter, momentum_gains, paper_q_notes, task_gains)
from .loop import run_closed_loop
from .measures import (RECOVERY_WINDOW_S, Thresholds, TwinCentroidal, cog_recovery, cop_in_sole,
                       sole_slip, tilt_deg)
from .pushes import LOCATIONS, HumanoidScaled, location_of, make_push

log = logging.getLogger(__name__)

#: the start of a run while the twin's contacts settle (s), not counted in the torque continuity
SETTLE_TIME = 0.05

PARAMETERS = (
    Parameter("stance", "left", "the sole kept, by role (the other is lifted)",
              choices=BIPED_ROLES),
    Parameter("shift_time", 2.0, "duration of the CoG shift (s)",
              **TIME_SPAN),
    Parameter("swing_bend", -1.0, "the shift lowers the CoG by this fraction of the drop that "
                                  "keeps the swing leg's standing bend (0: the standing CoG "
                                  "height; larger fractions keep the swing leg bent and cost lift "
                                  "where the swing ankle limits it; -1: the fraction that keeps "
                                  "the legs farthest from their joint limits in the shifted and "
                                  "lifted poses); lower still when no pose inside the joint "
                                  "limits has the CoG there",
              low=0.0, high=1.0, special=(-1.0,)),
    Parameter("unload_time", 0.5, "duration of the unloading (s)",
              **TIME_SPAN),
    Parameter("lift_time", 1.0, "duration of the swing-foot lift (s)",
              **TIME_SPAN),
    Parameter("lift", HumanoidScaled(0.10, "m", height_power=1), "swing-foot lift height (m)",
              low=0.0, low_open=True, high=0.5 * Parameter.H),
    Parameter("push_forces", HumanoidScaled(150.0, "N", mass_power=1, listed=True),
              "comma-separated peak forces (N) of the pushes in single support with the foot held "
              "up ('' or 0: none); default the paper's 150 N on talos14, the same velocity change "
              "on any robot",
              low=0.0, items=float),
    Parameter("push_location", "front", f"their push point: {', '.join(LOCATIONS)}",
              choices=tuple(LOCATIONS)),
    Parameter("push_duration", 0.06, "their duration (s); 150 N x 0.06 s half-sine = 5.7 Ns "
                                     "on talos14 (the paper: 4.5-5.8 Ns)",
              **TIME_SPAN),
    Parameter("push_start", 1.0, "first push, seconds after the lift ends",
              low=0.0, high=Parameter.MAX_TIME),
    Parameter("push_interval", 3.0, "time between pushes (s)",
              **TIME_SPAN),
    Parameter("sine_time", 8.0, "duration of the joint-space leg swinging (s); 0: none",
              low=0.0, high=Parameter.MAX_TIME),
    Parameter("sine_frequency", 0.25, "frequency of the hip and knee sines (Hz)",
              low=0.0, low_open=True, high=5.0),
    Parameter("hip_amplitude", 0.2, "hip flexion amplitude (rad; positive = thigh up)",
              low=-np.pi / 2, high=np.pi / 2),
    Parameter("knee_amplitude", 0.3, "knee flexion amplitude (rad; positive = more bent)",
              low=-np.pi / 2, high=np.pi / 2),
    Parameter("sine_ramp", 1.0, "the amplitude ramps in over this time (s)",
              low=0.0, high=Parameter.MAX_TIME),
    Parameter("sine_joints", "", "hip and knee flexion joints of the swing leg (default: its "
                                 "first two joints with a lateral axis)"),
    Parameter("sine_kp", 100.0, "joint tracking stiffness (1/s^2)", low=0.0),
    Parameter("sine_kd", 20.0, "joint tracking damping (1/s)", low=0.0),
    Parameter("sine_push_force", HumanoidScaled(150.0, "N", mass_power=1),
              "peak force of the push during the swinging (N; 0: none)",
              low=0.0),
    Parameter("sine_push_location", "hip-front", "its push point", choices=tuple(LOCATIONS)),
    Parameter("sine_push_duration", 0.06, "its duration (s)",
              **TIME_SPAN),
    Parameter("sine_push_at", 3.0, "its time, seconds after the swinging starts",
              low=0.0, high=Parameter.MAX_TIME),
    Parameter("settle", 1.0, "simulated time after the last phase (s)",
              low=0.0, high=Parameter.MAX_TIME),
    duration_parameter(0.0, "simulated time (s); 0: until the end of all phases",
                       low_open=False),
    Parameter("recovery_time", RECOVERY_WINDOW_S, "a push is recovered if the CoG is back "
                                    "within 5 mm (on talos14, times h / h_talos14) of its "
                                    "reference this long after it (s)",
              **TIME_SPAN),
    Q_ANGULAR,
    *PD_PARAMETERS,
    *POSTURE_PARAMETERS,
    *SWING_FOOT_PARAMETERS,
    COP_MARGIN,
    Parameter("lqr_blend", True, "LQR: blend the gains during the unloading (Sect. 3.2 remark); "
                                 "false: switch them at the contact switch"),
    Parameter("max_torque_jump", HumanoidScaled(10.0, "Nm", mass_power=1, height_power=1),
              "largest cycle-to-cycle torque change counted as continuous, outside pushes (Nm)",
              low=0.0, low_open=True),
)

def parse_forces(text) -> list[float]:
    """Comma-separated peak forces; '' and zeros mean no push."""
    try:
        values = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--set push_forces: expected comma-separated numbers, got '{text}'") \
            from None
    if any(v < 0 or not np.isfinite(v) for v in values):
        raise ValueError("--set push_forces: peak forces must be >= 0")
    return [v for v in values if v > 0]


def stance_and_swing(robot, params: dict) -> tuple[str, str]:
    """The contact names of the (stance, swing) soles for ``--set stance`` (a role)."""
    left, right = biped_soles(robot)
    return (left, right) if params["stance"] == "left" else (right, left)


def sine_joints(robot, swing_contact: str, text: str) -> tuple[tuple[str, str], tuple[int, int]]:
    """The hip and knee flexion joints of the swing leg (default: its first two joints whose axes
    are lateral, :func:`~wholebody.robots.roles.pitch_joints`) and the signs that make a positive
    amplitude lift the thigh and bend the knee: (-s_hip, s_knee), s the sign of the joint axis
    along the base's y (a rotation about +y pitches the thigh down and bends a knee backwards)."""
    flexion = dict(pitch_joints(robot, swing_contact))
    if text:
        joints = tuple(j.strip() for j in text.split(",") if j.strip())
    else:
        joints = tuple(flexion)[:2]
    missing = [j for j in joints if j not in robot.joint_names]
    if len(joints) != 2 or missing or any(j not in flexion for j in joints):
        raise ValueError(f"--set sine_joints: expected the swing leg's hip and knee flexion joints "
                         f"of robot '{robot.name}' (its lateral-axis joints: "
                         f"{', '.join(flexion) or 'none'}), got {list(joints)}"
                         + (f" (unknown: {missing})" if missing else ""))
    return joints, (-int(flexion[joints[0]]), int(flexion[joints[1]]))


def config(robot, params: dict) -> ContactSwitchConfig:
    """The :class:`ContactSwitchConfig` of the scenario parameters (the swing leg's hip and knee
    flexion joints and their Talos flexion signs: hip positive = thigh up, knee positive = more
    bent)."""
    _, swing = stance_and_swing(robot, params)
    joints, signs = sine_joints(robot, swing, params.get("sine_joints", ""))
    return ContactSwitchConfig(
        shift_time=params["shift_time"], unload_time=params["unload_time"],
        lift_time=params["lift_time"], lift=params["lift"],
        push_forces=tuple(parse_forces(params["push_forces"])), push_start=params["push_start"],
        push_interval=params["push_interval"], sine_time=params["sine_time"],
        sine_frequency=params["sine_frequency"],
        sine_amplitudes=(signs[0] * params["hip_amplitude"], signs[1] * params["knee_amplitude"]),
        sine_ramp=params["sine_ramp"], sine_joints=joints, held_joints=leg_joints(robot, swing),
        sine_kp=params["sine_kp"], sine_kd=params["sine_kd"],
        sine_push_force=params["sine_push_force"], sine_push_at=params["sine_push_at"],
        settle=params["settle"], q_angular=params["q_angular"], lqr_blend=params["lqr_blend"],
        swing_bend=None if params["swing_bend"] < 0.0 else params["swing_bend"],
        **task_gains(params))


def timeline(robot, params: dict) -> Timeline:
    """The phase times of a run with these parameters."""
    return Timeline.from_config(config(robot, params))


def validate(robot, params: dict) -> None:
    biped_soles(robot)  # ValueError unless a biped
    parse_forces(params["push_forces"])
    for key in ("push_location", "sine_push_location"):
        if params[key] not in LOCATIONS:
            raise ValueError(f"--set {key}: '{params[key]}' is not one of {', '.join(LOCATIONS)}")
    for key in ("shift_time", "unload_time", "lift_time", "push_duration", "sine_push_duration",
                "push_interval", "sine_frequency"):
        if not params[key] > 0:
            raise ValueError(f"--set {key}: must be > 0, got {params[key]}")
    if params["sine_time"] > 0:
        sine_joints(robot, stance_and_swing(robot, params)[1], params["sine_joints"])


def _push(robot, location: str, force: float, start: float, duration: float):
    return make_push({"location": location, "peak_force": force, "start": start,
                      "push_duration": duration}, robot)


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    stance, _ = stance_and_swing(robot, params)
    pd_gains = momentum_gains(controller, params) if controller == "pd" else {}
    ctrl = ContactSwitch(robot, stance, config(robot, params), gains=controller,
                         cop_margin=params["cop_margin"], **pd_gains)
    tl = ctrl.timeline
    duration = params["duration"] if params["duration"] > 0 else tl.end
    sim = Simulator(robot, observers=observers)
    pushes = [_push(robot, params["push_location"], f, t0, params["push_duration"])
              for t0, f in tl.pushes]
    if tl.sine_push is not None:
        pushes.append(_push(robot, params["sine_push_location"], params["sine_push_force"],
                            tl.sine_push, params["sine_push_duration"]))
    for push in pushes:
        sim.add_push(push)
    stance_start = sim.contact_frame_poses()[stance]
    com_err, swing_z, tilt, slip, tau, cop, h, jerr = [], [], [], [], [], [], [], []
    half_size = np.asarray(robot.contact(stance).spec.half_size)
    k_stance = robot.contact_names.index(stance)
    twin = TwinCentroidal(robot)

    def observe(t, sol):
        # the simulator's state through the (exact) model: the twin's CoG
        q, v = sim.state()
        com, _, h_G = twin.at(q, v)
        com_err.append(com - ctrl.com_ref(t))
        h.append(h_G)
        poses = sim.contact_frame_poses()
        swing_z.append(poses[ctrl.swing_contact][0][2])
        p, R = poses[stance]
        tilt.append(tilt_deg(R))
        slip.append(sole_slip(p, stance_start[0]))
        cop.append(cop_in_sole(sim.contact_wrenches_array()[k_stance], R, min_force=1.0)[0])
        tau.append(sol.tau.copy())
        if ctrl.sine_q0 is not None:
            qd, vd, _ = ctrl.joint_reference(t)
            j = np.array([robot.joint_names.index(n) for n in ctrl.joints])
            jerr.append(np.concatenate([q[FREE_FLYER_NQ + j] - qd, v[FREE_FLYER_NV + j] - vd]))
        else:
            jerr.append(np.full(4, np.nan))

    failures = run_closed_loop(sim, ctrl, duration, progress=progress, on_result=observe)
    t = sim.log.arrays()["t"]
    com_err, tau, cop, h, jerr = map(np.array, (com_err, tau, cop, h, jerr))
    err = np.linalg.norm(com_err, axis=1)
    jumps = np.r_[0.0, np.abs(np.diff(tau, axis=0)).max(axis=1)]
    in_push = np.zeros(len(t), dtype=bool)
    for push in pushes:  # the push and the 0.3 s after it: torques follow the impact
        in_push |= (t >= push.start) & (t <= push.start + push.duration + 0.3)
    settling = t < SETTLE_TIME

    def jump_near(t0):
        near = np.abs(t - t0) <= 0.02
        return float(jumps[near].max()) if near.any() else None

    # every push: the CoG back within the thresholds' tolerance within recovery_time
    thresholds = Thresholds.for_robot(robot)
    push_rows = []
    starts = sorted(p.start for p in pushes)
    for push in pushes:
        end = push.start + push.duration
        if end > t[-1]:
            continue
        # the recovery window ends at the next push (or recovery_time, or the end of the run)
        deadline = min([end + params["recovery_time"], t[-1]]
                       + [s for s in starts if s > push.start])
        window = (t >= push.start) & (t < deadline)
        recovery, last = cog_recovery(t, err, end, window, thresholds.cog_tolerance)
        recovered = bool(last is None or (last < deadline - 0.05 and deadline - end > 0.5))
        push_rows.append({
            "time_s": push.start, "location": location_of(push, robot), "peak_force_N": push.peak_force,
            "impulse_Ns": push.impulse, "delta_v_mps": push.impulse / robot.mass,
            "during_swinging": bool(tl.sine_start is not None and push.start >= tl.sine_start),
            "max_cog_error_m": float(err[window].max()),
            "recovery_time_s": recovery,
            "recovered": recovered,
            "max_linear_momentum_Ns": float(np.linalg.norm(h[window, :3], axis=1).max()),
            "max_cop_fraction": float(np.nanmax(np.abs(cop[window]) / half_size)),
        })
    wrenches = sim.log.arrays()["contact_wrenches"]
    k_swing = robot.contact_names.index(ctrl.swing_contact)
    lifted = t >= tl.switch + 0.5 * params["lift_time"]
    metrics = {
        "failed_cycles": failures,
        "swing_sole_max_normal_force_after_lift_N": float(wrenches[lifted, k_swing, 2].max())
        if lifted.any() else None,
        "swing_lift_m": float(swing_z[min(len(t), int(round(
            (tl.sine_start or tl.end) / sim.dt))) - 1] - swing_z[0]),
        "final_cog_error_m": float(err[-1]),
        "max_cog_error_m": float(err.max()),
        "max_cog_error_shift_m": float(err[t < tl.switch].max()),
        "max_stance_tilt_deg": float(max(tilt)),
        "max_stance_slip_m": float(max(slip)),
        "max_torque_jump_Nm": float(jumps.max()),
        "max_torque_jump_settling_Nm": float(jumps[settling].max()),
        "max_torque_jump_outside_pushes_Nm": float(jumps[~in_push & ~settling].max()),
        "torque_jump_at_unload_start_Nm": jump_near(tl.shift_end),
        "torque_jump_at_switch_Nm": jump_near(tl.switch),
        "torque_jump_at_swing_swap_Nm": jump_near(tl.sine_start) if tl.sine_start else None,
        "unloaded_force_N": float(np.linalg.norm(ctrl.unload_start[:3])) if ctrl.unload_start
        is not None else None,
        "pushes": push_rows,
        "pushes_recovered": sum(r["recovered"] for r in push_rows),
    }
    if controller == "lqr":
        g = ctrl.lqr.gains(robot, (stance,)) if ctrl.unload_start is not None else None
        metrics["lqr_slowest_pole_single_rad_s"] = (float(np.max(g.poles.real)) if g else None)
        metrics["lqr_slowest_pole_double_rad_s"] = float(np.max(
            ctrl.lqr.gains(robot, ctrl.double_contacts).poles.real))
    sine = (~np.isnan(jerr[:, 0])) if tl.sine_start is not None else np.zeros(len(t), bool)
    if sine.any():
        ramp_done = sine & (t >= tl.sine_start + params["sine_ramp"])
        quiet = ramp_done & ~in_push
        metrics["joint_tracking"] = {}
        for i, name in enumerate(("hip", "knee")):
            e, ev = jerr[:, i], jerr[:, 2 + i]
            metrics["joint_tracking"][name] = {
                "joint": ctrl.joints[i],
                "rms_error_rad": float(np.sqrt(np.mean(e[ramp_done] ** 2))),
                "max_error_rad": float(np.abs(e[ramp_done]).max()),
                "max_error_without_push_rad": float(np.abs(e[quiet]).max()) if quiet.any()
                else None,
                "max_error_push_rad": float(np.abs(e[ramp_done & in_push]).max())
                if (ramp_done & in_push).any() else None,
                "rms_velocity_error_rad_s": float(np.sqrt(np.mean(ev[ramp_done] ** 2))),
                "max_velocity_error_rad_s": float(np.abs(ev[ramp_done]).max()),
            }
    touched = bool(metrics["swing_sole_max_normal_force_after_lift_N"] or 0.0)
    success = (failures == 0 and metrics["swing_lift_m"] > 0.8 * params["lift"] and not touched
               and metrics["final_cog_error_m"] < thresholds.cog_tolerance
               and thresholds.feet_in_place(metrics["max_stance_tilt_deg"],
                                            metrics["max_stance_slip_m"])
               and all(r["recovered"] for r in push_rows)
               and metrics["max_torque_jump_outside_pushes_Nm"] < params["max_torque_jump"])
    notes = []
    notes += paper_q_notes(robot, controller, params)
    result = ScenarioResult("single-support", robot.name, controller, success, metrics, params,
                            notes, log=sim.log)
    if out_dir is not None:
        push_force = sim.log.arrays()["push_force"]
        shaded = [(params["shift_time"], tl.switch)] + [(p.start, p.start + p.duration)
                                                        for p in pushes]
        figures = [single_support_figure(
            Path(out_dir) / "single_support.png", t, com_err, wrenches, robot.contact_names,
            push_force, swing_z, jumps,
            title=f"single support — {robot.name}, {controller} momentum gains", shaded=shaded)]
        if sine.any():
            figures.append(fig11(Path(out_dir) / "joint_tracking.png", t[sine], jerr[sine],
                                 h[sine], push_force[sine], cop[sine], half_size, ctrl.joints,
                                 title=f"leg swinging in single support, pushed at the hip — "
                                       f"{robot.name}, {controller}"))
        result.figures = [str(f) for f in figures]
    return result


SCENARIO = Scenario(
    name="single-support",
    summary="Sect. 5.4: CoG shift, unloading, Table 4 single support lifting the other sole, "
            "pushes on one foot, hip/knee sine tracking pushed at the hip (Fig. 11); PD or LQR "
            "momentum gains (blended across the switch); success = lifted, pushes recovered, "
            "feet flat, torques continuous",
    parameters=PARAMETERS,
    controllers=("pd", "lqr"),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
    simulations=1,
)
