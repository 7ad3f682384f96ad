"""What the walking scenarios (``walk``, ``push-step``, ``walk-push``) share: one closed-loop run
of :class:`~wholebody.control.walking.Walking` in the twin with its per-cycle record, the
measures taken from it, a velocity-command schedule, the pushes, and the figures."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Callable

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
from matplotlib.patches import Polygon  # noqa: E402

from ..control.walking import SupportPolygon, Walking, WalkingConfig  # noqa: E402
from ..report.plots import save_figure  # noqa: E402
from ..robots.roles import biped_soles  # noqa: E402
from ..sim.disturbance import Push  # noqa: E402
from ..sim.simulator import Simulator  # noqa: E402
from .base import Parameter, check_engine  # noqa: E402
from .loop import run_closed_loop  # noqa: E402
from .measures import Thresholds, fallen, tilt_deg  # noqa: E402
from .pushes import make_push, peak_force_for  # noqa: E402

#: a sole counts in the measured support while it carries this share of the weight
SUPPORT_FORCE_SHARE = 0.05
#: torque changes within this many cycles of a phase change count as at a contact switch
SWITCH_CYCLES = 2
#: standing at the start of a command schedule and the forward speed's ramp (s)
STAND_TIME, RAMP_TIME = 1.0, 1.0
#: a walk covers at least this share of the commanded displacement
DISTANCE_SHARE = 0.8
#: first controller cycles left out of the timing statistics
TIMING_WARMUP = 50
RECORDED = ("t", "base_position", "yaw", "com", "com_ref", "dcm", "dcm_ref", "zmp", "tau",
            "command")


@dataclass
class WalkRun:
    """The record of one run: per-cycle arrays (``a``), the soles' poses (``poses``: sole ->
    (positions (N, 3), rotations (N, 3, 3))), the phase kind of each cycle, the controller, the
    pushes applied, failed cycles and the fall."""

    ctrl: Walking
    sim: Simulator
    a: dict = field(default_factory=dict)
    poses: dict = field(default_factory=dict)
    kinds: list = field(default_factory=list)
    pushes: list = field(default_factory=list)
    failed_cycles: int = 0
    fell_at: float | None = None

    @property
    def fallen(self) -> bool:
        return self.fell_at is not None

    @property
    def end(self) -> float:
        return float(self.a["t"][-1])


def base_yaw_tilt(q) -> tuple[float, float]:
    """(yaw, tilt in deg) of the base of configuration ``q`` (quaternion x, y, z, w)."""
    x, y, z, w = q[3:7]
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    return float(math.atan2(R[1, 0], R[0, 0])), float(tilt_deg(R))


def sole_outline(robot, sole: str, p, R) -> np.ndarray:
    """The corners (x, y) of ``sole``'s rectangle at position ``p``, rotation ``R``."""
    hx, hy = np.asarray(robot.contact(sole).spec.half_size, dtype=float)
    corners = np.array([[hx, hy, 0.0], [hx, -hy, 0.0], [-hx, -hy, 0.0], [-hx, hy, 0.0]])
    return (np.asarray(p) + corners @ np.asarray(R).T)[:, :2]


def simulate(robot, ctrl: Walking, duration: float,
             command: Callable[[float], np.ndarray] | None = None,
             push: Callable[[WalkRun, float], Push | None] | None = None, progress: bool = False,
             observers=(), label: str = "", until: Callable[[], bool] | None = None) -> WalkRun:
    """Run ``ctrl`` for ``duration`` s in the twin, fed ``command(t)`` (forward, lateral, yaw
    rate) when given; ``push(run, t)`` may return a push to apply from then on (asked each cycle
    until it does). Stops at a fall (:func:`~wholebody.scenarios.measures.fallen`) or when
    ``until()`` says so."""
    sim = Simulator(robot, observers=observers, label=label)
    run = WalkRun(ctrl, sim)
    rec = {k: [] for k in RECORDED}
    run.poses = {s: ([], []) for s in ctrl.soles}
    h0 = float(robot.q_ref[2])
    pin_data = robot.model.createData()

    def compute(q, v, t):
        if command is not None:
            ctrl.set_command(*command(t))
        if push is not None and not run.pushes:
            p = push(run, t)
            if p is not None:
                sim.add_push(p)
                run.pushes.append(p)
        return ctrl.compute(q, v, t)

    def observe(t, sol):
        q, v = sim.state()
        # the simulator's CoM and its velocity through the exact model (the numbers of
        # Robot.update's, without its other terms; on data of its own, the robot untouched)
        com = pin.centerOfMass(robot.model, pin_data, q, v).copy()
        vcom = pin_data.vcom[0].copy()
        yaw, tilt = base_yaw_tilt(q)
        dcm = com[:2] + vcom[:2] / ctrl.omega
        frames = sim.contact_frame_poses()
        for key, value in (("t", t), ("base_position", q[:3].copy()), ("yaw", yaw),
                           ("com", com), ("com_ref", np.array(ctrl.com_ref)),
                           ("dcm", dcm), ("dcm_ref", np.array(ctrl.dcm_ref)),
                           ("zmp", np.array(ctrl.zmp_command)),
                           ("tau", np.array(sol.tau, dtype=float)),
                           ("command", ctrl.command.copy())):
            rec[key].append(value)
        run.kinds.append(ctrl.phase.kind)
        for s in ctrl.soles:
            run.poses[s][0].append(frames[s][0])
            run.poses[s][1].append(frames[s][1])
        if run.fell_at is None and fallen(tilt, q[2], h0):
            run.fell_at = t

    def stop() -> bool:
        return run.fallen or (until is not None and until())

    run.failed_cycles = run_closed_loop(sim, SimpleNamespace(compute=compute), duration,
                                        progress=progress, on_result=observe, until=stop)
    run.a = {k: np.asarray(v, dtype=float) for k, v in rec.items()}
    run.poses = {s: (np.asarray(p), np.asarray(R)) for s, (p, R) in run.poses.items()}
    return run


def capture_point_outside_support(robot, run: WalkRun) -> np.ndarray:
    """Per recorded cycle, how far the measured capture point is outside the support polygon of
    the soles that carry SUPPORT_FORCE_SHARE of the weight in the twin (the log's contact
    wrenches of the same cycles), NaN while none does."""
    wrenches = np.asarray(run.sim.log.contact_wrenches)
    columns = {s: robot.contact_names.index(s) for s in run.ctrl.soles}
    threshold = SUPPORT_FORCE_SHARE * robot.mass * 9.81
    out = np.full(len(run.a["t"]), math.nan)
    for k in range(min(len(wrenches), len(out))):  # a fall ends the run before its last step
        loaded = [s for s, i in columns.items() if wrenches[k, i, 2] > threshold]
        if loaded:
            support = SupportPolygon(np.vstack([
                sole_outline(robot, s, run.poses[s][0][k], run.poses[s][1][k]) for s in loaded]))
            dcm = run.a["dcm"][k]
            out[k] = float(np.linalg.norm(dcm - support.project(dcm)))
    return out


def stance_intervals(steps, sole: str, end: float) -> list[tuple[float, float]]:
    """(touchdown, next lift-off) of every stance of ``sole`` (from 0, to ``end``)."""
    out, start = [], 0.0
    for s in steps:
        if s.contact != sole:
            continue
        out.append((start, s.lift_off))
        start = s.touchdown if np.isfinite(s.touchdown) else math.inf
    if start < end:
        out.append((start, end))
    return out


def sole_measures(run: WalkRun) -> tuple[float, float, dict | None]:
    """(largest horizontal slip of a sole within one stance, largest tilt of a sole in contact,
    where that slip was), from the soles' poses in the twin."""
    t = run.a["t"]
    slip, tilt, where = 0.0, 0.0, None
    for sole, (p, R) in run.poses.items():
        for a, b in stance_intervals(run.ctrl.steps, sole, run.end + 1.0):
            mask = (t >= a) & (t < b)
            if not mask.any():
                continue
            moved = float(np.linalg.norm(p[mask, :2] - p[mask][0, :2], axis=1).max())
            if moved > slip:
                slip, where = moved, {"sole": sole, "from_s": float(t[mask][0]),
                                      "to_s": float(t[mask][-1])}
            cos = np.clip(R[mask][:, 2, 2], -1.0, 1.0)
            tilt = max(tilt, float(np.degrees(np.arccos(cos)).max()))
    return slip, tilt, where


def torque_jumps(tau: np.ndarray) -> np.ndarray:
    """The largest change of any joint torque from the cycle before (N m; 0 at the first)."""
    if len(tau) < 2:
        return np.zeros(len(tau))
    return np.r_[0.0, np.abs(np.diff(tau, axis=0)).max(axis=1)]


def torque_steps(run: WalkRun) -> tuple[float, float | None]:
    """(largest cycle-to-cycle torque change, the largest within SWITCH_CYCLES of a phase
    change, None without one), N m."""
    jumps = torque_jumps(run.a["tau"])
    if jumps.size == 0:
        return 0.0, None
    kinds = run.kinds
    changes = np.flatnonzero([a != b for a, b in zip(kinds[:-1], kinds[1:])]) + 1
    near = np.zeros(len(jumps), bool)
    for k in changes:
        near[max(k - SWITCH_CYCLES, 1):k + SWITCH_CYCLES + 1] = True
    return float(jumps.max()), (float(jumps[near].max()) if near.any() else None)


def timing_ms(cycle_times) -> dict:
    """Median and 99th percentile of the controller's cycle times (ms), warm-up left out."""
    x = 1e3 * np.asarray(cycle_times[TIMING_WARMUP:])
    if x.size == 0:
        return {"median_ms": None, "p99_ms": None}
    return {"median_ms": float(np.median(x)), "p99_ms": float(np.percentile(x, 99))}


def step_rows(run: WalkRun) -> list[dict]:
    """Each step taken: sole, lift-off and touchdown times, recovery or not, the planned footstep
    and the adjusted target (world x, y and yaw), where the sole landed in the twin (world x, y)
    and that relative to where it started."""
    t, rows = run.a["t"], []
    for s in run.ctrl.steps:
        row = {"contact": s.contact, "lift_off_s": float(s.lift_off),
               "touchdown_s": float(s.touchdown) if np.isfinite(s.touchdown) else None,
               "recovery": bool(s.recovery),
               "planned_xy_m": [float(x) for x in s.planned[:2]],
               "target_xy_m": [float(x) for x in s.target[:2]], "yaw_rad": float(s.yaw),
               "landed_xy_m": None, "landing_from_start_xy_m": None}
        if np.isfinite(s.touchdown):
            k = min(int(np.searchsorted(t, s.touchdown)), len(t) - 1)
            landed = run.poses[s.contact][0][k, :2]
            row["landed_xy_m"] = landed.tolist()
            row["landing_from_start_xy_m"] = (landed - run.poses[s.contact][0][0, :2]).tolist()
        rows.append(row)
    return rows


def walking_figure(robot, run: WalkRun, top_title: str):
    """A walking run's figure: the top view (:func:`draw_top_view`, titled ``top_title``) on the
    left, three time-series axes on the right → (figure, the three axes)."""
    fig = plt.figure(figsize=(13, 7.5))
    grid = fig.add_gridspec(3, 2, width_ratios=(1.1, 1.0))
    draw_top_view(fig.add_subplot(grid[:, 0]), robot, run, top_title)
    return fig, [fig.add_subplot(grid[i, 1]) for i in range(3)]


def draw_top_view(ax, robot, run: WalkRun, title: str) -> None:
    """Top view: the start soles (solid) and every landed sole (dashed) as in the twin, the ZMP
    command, the DCM reference and the measured DCM and CoM, the pushes as arrows."""
    a, t = run.a, run.a["t"]
    first = robot.contact_names[0]
    soles = [(s, p[0], R[0], True) for s, (p, R) in run.poses.items()]
    for s in run.ctrl.steps:
        if np.isfinite(s.touchdown):
            k = min(int(np.searchsorted(t, s.touchdown)), len(t) - 1)
            soles.append((s.contact, run.poses[s.contact][0][k], run.poses[s.contact][1][k],
                          False))
    for sole, p, R, start in soles:
        ax.add_patch(Polygon(sole_outline(robot, sole, p, R), closed=True, fill=False,
                             edgecolor="tab:blue" if sole == first else "tab:red",
                             linewidth=1.2 if start else 0.8, linestyle="-" if start else "--"))
    ax.plot(a["zmp"][:, 0], a["zmp"][:, 1], color="0.6", linewidth=0.7, label="ZMP command")
    ax.plot(a["dcm_ref"][:, 0], a["dcm_ref"][:, 1], "--", color="tab:purple", linewidth=0.8,
            label="DCM reference")
    ax.plot(a["dcm"][:, 0], a["dcm"][:, 1], color="tab:purple", linewidth=0.8, label="DCM")
    ax.plot(a["com"][:, 0], a["com"][:, 1], color="k", linewidth=1.0, label="CoM")
    span = float(np.ptp(np.vstack([a["com"][:, :2], a["dcm"]]), axis=0).max()) or 0.1
    for push in run.pushes:
        k = min(int(np.searchsorted(t, push.start)), len(t) - 1)
        d = np.asarray(push.direction, dtype=float)[:2]
        ax.annotate("", xy=a["com"][k, :2], xytext=a["com"][k, :2] - 0.3 * span * d,
                    arrowprops={"arrowstyle": "->", "color": "tab:green", "linewidth": 1.5})
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_title(title, fontsize=9)


def draw_torque_steps(ax, run: WalkRun) -> None:
    """The largest torque change between cycles over time (the swings shaded by the caller)."""
    ax.plot(run.a["t"], torque_jumps(run.a["tau"]), linewidth=0.8)
    ax.set_ylabel("N m", fontsize=8)
    ax.set_title("largest torque change between cycles (swings shaded)", fontsize=9)
    ax.set_xlabel("time (s)")


def shade_swings(ax, run: WalkRun) -> None:
    """Shade every swing (lift-off to touchdown) on a time axis."""
    for s in run.ctrl.steps:
        end = s.touchdown if np.isfinite(s.touchdown) else run.end
        ax.axvspan(s.lift_off, end, color="0.9", zorder=0)


# ---------------------------------------------------------------------- walking on a command
@dataclass(frozen=True)
class Part:
    """A part of the command schedule: (forward, lateral, yaw rate) moving linearly from
    ``begin`` to ``finish`` over [start, end)."""

    name: str
    start: float
    end: float
    begin: tuple[float, float, float]
    finish: tuple[float, float, float]

    def command(self, t: float) -> np.ndarray:
        s = min(max((t - self.start) / (self.end - self.start), 0.0), 1.0)
        return (1.0 - s) * np.asarray(self.begin) + s * np.asarray(self.finish)


def step_period(robot, params: dict, walking: WalkingConfig | None = None) -> float:
    """A step's duration with the walking settings of ``params`` (``walking``: those settings,
    when already made with :func:`config`: they take a search over the robot's stances)."""
    c = config(robot, params) if walking is None else walking
    return c.single_support + c.double_support


def schedule(robot, params: dict, walking: WalkingConfig | None = None) -> list[Part]:
    """The command schedule, in order; the last part is the settling (zero command).
    ``walking``: as in :func:`step_period`."""
    period = step_period(robot, params, walking)
    parts, t = [Part("stand", 0.0, STAND_TIME, (0, 0, 0), (0, 0, 0))], STAND_TIME
    v = params["speed"]

    def add(name, duration, begin, finish=None):
        nonlocal t
        parts.append(Part(name, t, t + duration, begin, begin if finish is None else finish))
        t += duration

    if params["steps"] > 0:
        add("ramp", RAMP_TIME, (0.0, 0.0, 0.0), (v, 0.0, 0.0))
        add("forward", params["steps"] * period, (v, 0.0, 0.0))
    def whole_periods(amount: float, rate: float) -> tuple[float, float]:
        """(duration, rate): ``amount`` at the rate nearest ``rate`` that takes a whole number
        of step periods (the controller reads its command once a step)."""
        duration = max(1, round(abs(amount) / rate / period)) * period
        return duration, math.copysign(abs(amount) / duration, amount)

    if params["turn"] != 0:
        duration, rate = whole_periods(math.radians(params["turn"]), params["yaw_rate"])
        add("turn", duration, (0.5 * v, 0.0, rate))
    if params["side_distance"] != 0:
        duration, lateral = whole_periods(params["side_distance"], params["lateral"])
        add("side", duration, (0.0, lateral, 0.0))
    add("settle", params["settle"], (0.0, 0.0, 0.0))
    return parts


def command_at(parts: list[Part], t: float) -> np.ndarray:
    for part in parts:
        if t < part.end:
            return part.command(t)
    return np.zeros(3)


def commanded_path(parts: list[Part], dt: float = 1e-3) -> np.ndarray:
    """The command integrated along the commanded heading from the origin: (x, y, heading) at
    the end."""
    x = np.zeros(3)
    for t in np.arange(0.0, parts[-1].end, dt):
        vx, vy, wz = command_at(parts, t)
        c, s = math.cos(x[2]), math.sin(x[2])
        x += dt * np.array([c * vx - s * vy, s * vx + c * vy, wz])
    return x


def config(robot, params: dict) -> WalkingConfig:
    return WalkingConfig.for_robot(robot, cop_margin=params["cop_margin"])


def walk_metrics(robot, params: dict, parts: list[Part], run: WalkRun,
                 walking: WalkingConfig | None = None) -> dict:
    """Distance, speed, heading, side-step, tracking, slip, torque continuity and timing of a
    run of the command schedule ``parts`` (``walking``: as in :func:`step_period`)."""
    a, t, base = run.a, run.a["t"], run.a["base_position"]
    yaw = np.unwrap(a["yaw"])
    commanded_net = float(np.linalg.norm(commanded_path(parts)[:2]))
    net = float(np.linalg.norm(base[-1, :2] - base[0, :2]))
    by_name = {p.name: p for p in parts}
    period = step_period(robot, params, walking)

    def index(time):
        return min(int(np.searchsorted(t, time)), len(t) - 1)

    forward_speed = None
    if "forward" in by_name:
        fw = by_name["forward"]
        t0 = fw.start + period if fw.end - fw.start > period else fw.start
        i, j = index(t0), index(fw.end)
        if j > i:
            d = base[j, :2] - base[i, :2]
            forward_speed = float((math.cos(yaw[0]) * d[0] + math.sin(yaw[0]) * d[1])
                                  / (t[j] - t[i]))
    side = None
    if "side" in by_name:
        i = index(by_name["side"].start)
        d = base[-1, :2] - base[i, :2]
        side = float(-math.sin(yaw[i]) * d[0] + math.cos(yaw[i]) * d[1])
    com_err = np.linalg.norm(a["com"][:, :2] - a["com_ref"][:, :2], axis=1)
    dcm_err = np.linalg.norm(a["dcm"] - a["dcm_ref"], axis=1)
    slip, tilt, slip_stance = sole_measures(run)
    jump, jump_switch = torque_steps(run)
    return {
        "fallen": run.fallen,
        "fell_at_s": run.fell_at,
        "simulated_s": run.end,
        "failed_cycles": run.failed_cycles,
        "path_length_m": float(np.linalg.norm(np.diff(base[:, :2], axis=0), axis=1).sum()),
        "net_displacement_m": net,
        "commanded_net_displacement_m": commanded_net,
        "commanded_forward_distance_m": float(params["speed"] * (
            0.5 * RAMP_TIME + params["steps"] * period)) if params["steps"] > 0 else 0.0,
        "displacement_ratio": net / commanded_net if commanded_net > 0 else None,
        "mean_forward_speed_mps": forward_speed,
        "commanded_forward_speed_mps": params["speed"] if params["steps"] > 0 else None,
        "heading_change_deg": float(np.degrees(yaw[-1] - yaw[0])),
        "commanded_heading_change_deg": float(params["turn"]),
        "side_step_displacement_m": side,
        "commanded_side_step_m": float(params["side_distance"]),
        "com_tracking_rms_m": float(np.sqrt(np.mean(com_err ** 2))),
        "dcm_tracking_rms_m": float(np.sqrt(np.mean(dcm_err ** 2))),
        "max_dcm_error_m": float(dcm_err.max()),
        "steps": len(run.ctrl.steps),
        "recovery_steps": sum(bool(s.recovery) for s in run.ctrl.steps),
        "max_sole_slip_per_stance_m": slip,
        "max_slip_stance": slip_stance,
        "max_sole_tilt_in_contact_deg": tilt,
        "max_torque_step_Nm": jump,
        "max_torque_step_at_contact_switch_Nm": jump_switch,
        "standing_at_end": run.ctrl.phase.kind == "stand",
        "controller_cycle": timing_ms(run.ctrl.cycle_times),
        "footsteps": step_rows(run),
    }


def walked(robot, metrics: dict) -> bool:
    """No fall, every cycle solved, no sole slipping while it stands, the distance covered."""
    return bool(not metrics["fallen"] and metrics["failed_cycles"] == 0
                and metrics["max_sole_slip_per_stance_m"] < Thresholds.for_robot(robot).max_slip
                and metrics["net_displacement_m"]
                >= DISTANCE_SHARE * metrics["commanded_net_displacement_m"])


def walk_figure(path: Path, robot, run: WalkRun, parts, period: float, title: str) -> Path:
    """Top view (soles, CoM, DCM, ZMP command) and time series (command and base velocity,
    tracking errors, torque steps)."""
    a, t = run.a, run.a["t"]
    fig, axes = walking_figure(robot, run, "top view (start soles solid, landed soles dashed)")
    dt = np.gradient(t)
    vel = np.gradient(a["base_position"][:, :2], axis=0) / dt[:, None]
    c, s = np.cos(a["yaw"]), np.sin(a["yaw"])
    window = max(1, int(round(period / max(np.median(dt), 1e-6))))  # over one step period
    smooth = lambda x: np.convolve(x, np.ones(window) / window, mode="same")  # noqa: E731
    axes[0].plot(t, a["command"][:, 0], label="forward cmd")
    axes[0].plot(t, a["command"][:, 1], label="lateral cmd")
    axes[0].plot(t, a["command"][:, 2], label="yaw rate cmd (rad/s)")
    axes[0].plot(t, smooth(c * vel[:, 0] + s * vel[:, 1]), "--", label="forward (step mean)")
    axes[0].plot(t, smooth(-s * vel[:, 0] + c * vel[:, 1]), "--", label="lateral (step mean)")
    axes[0].set_ylabel("m/s", fontsize=8)
    axes[0].set_title("command and base velocity (heading frame)", fontsize=9)
    axes[1].plot(t, 100 * np.linalg.norm(a["com"][:, :2] - a["com_ref"][:, :2], axis=1),
                 label="CoM")
    axes[1].plot(t, 100 * np.linalg.norm(a["dcm"] - a["dcm_ref"], axis=1), label="DCM")
    axes[1].set_ylabel("cm", fontsize=8)
    axes[1].set_title("horizontal tracking error", fontsize=9)
    draw_torque_steps(axes[2], run)
    for ax in axes:
        shade_swings(ax, run)
        for part in parts[1:]:
            ax.axvline(part.start, color="0.5", linewidth=0.5, linestyle=":")
        ax.grid(True, alpha=0.3)
    for ax in axes[:2]:
        ax.legend(fontsize=7, ncol=3, loc="best")
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def validate_walk(robot, params: dict) -> None:
    """The robot a biped, the settings valid, the schedule within the longest simulation."""
    check_engine(params)
    biped_soles(robot)  # ValueError unless two rectangular soles
    end = schedule(robot, params, config(robot, params))[-1].end
    if end > Parameter.MAX_TIME:
        raise ValueError(f"the command schedule lasts {end:.0f} s, more than "
                         f"{Parameter.MAX_TIME:g} s: fewer --set steps, a larger turn yaw_rate "
                         f"or lateral speed, or a shorter side_distance")


# ---------------------------------------------------------------------- pushes
def push_of(robot, params: dict, dv: float, angle: float, start: float | None = None):
    """The half-sine push giving ``dv`` along ``angle`` (see the module docstring), ``height``
    above the base, from ``start`` (default the ``start`` parameter)."""
    return make_push({"location": "angle", "angle": angle, "height": params["height"],
                      "peak_force": peak_force_for(robot.mass, dv, params["push_duration"]),
                      "start": params["start"] if start is None else start,
                      "push_duration": params["push_duration"]}, robot)
