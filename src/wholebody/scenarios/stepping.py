"""``stepping``: the timing benchmark of Herzog et al. 2016 Sect. 5.1 (Table 1, Fig. 5).

The full humanoid (``talos``, 32 actuated DoF; the paper's Sarcos: 25) steps in place in the MuJoCo
twin under the Table 1 hierarchy (:func:`~wholebody.control.stacks.table1_stack`): (1) dynamics and
torque limits, (2) contact constraints, CoP, friction, joint acceleration limits, (3) CoG PD and
swing-foot PD, (4) posture, (5) GRF regulariser. The same motion is run twice, with the reduced
formulation of Sect. 2.3 (x = [qdd, lambda], Newton-Euler rows only, eq. 13/14) and with the full
one (y = [qdd, lambda, tau], all rows of eq. 1), and the controller's wall time per cycle
(``robot.update`` + task rows + hierarchical solve + tau) is recorded, as in Fig. 5.

The controller is :class:`~wholebody.control.stepping.Stepping` (its docstring lists the phases of
one step).

Success is measured on the simulator: every cycle solved, each swing sole lifted by >= 80 % of
``lift`` with zero normal force while up, both soles flat (< 2 deg) and in place (< 1 cm) whenever
in contact, and no fall (base height within 10 cm of its start, final CoG over the support polygon).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..control.stepping import Stepping, SteppingConfig
from ..report.balance_figures import stepping_timing_figure
from ..sim.simulator import Simulator
from .base import (COM_PARAMETERS, COP_MARGIN, ENGINE, POSTURE_PARAMETERS, SWING_FOOT_PARAMETERS,
                   TIME_SPAN, Parameter, Scenario, ScenarioResult, check_engine, task_gains)
from .loop import run_closed_loop
from .measures import Thresholds, TwinCentroidal, sole_slip, tilt_deg
from .pushes import HumanoidScaled

log = logging.getLogger(__name__)

PARAMETERS = (
    Parameter("steps", 2, "number of steps (alternating, the right sole lifted first)",
              low=1, high=100),
    Parameter("shift_time", 1.0, "duration of each CoG shift (s)",
              **TIME_SPAN),
    Parameter("unload_time", 0.3, "duration of the unloading (s)",
              **TIME_SPAN),
    Parameter("lift_time", 0.5, "duration of the lift and, again, of the lowering (s)",
              **TIME_SPAN),
    Parameter("reload_time", 0.3, "double support after touch-down before the next shift (s)",
              **TIME_SPAN),
    Parameter("preload", 0.1, "normal force ramped onto the touched-down sole during the reload, "
                              "as a fraction of the weight", low=0.0, high=1.0),
    Parameter("lift", HumanoidScaled(0.03, "m", height_power=1), "swing-foot lift height (m)",
              low=0.0, low_open=True, high=0.5 * Parameter.H),
    Parameter("touchdown_depth", HumanoidScaled(0.003, "m", height_power=1),
              "the lowered swing-foot target ends this far below its lift-off height (m)",
              low=0.0, high=0.1 * Parameter.H),
    Parameter("settle", 0.5, "simulated time after the final shift back to the middle (s)",
              low=0.0, high=Parameter.MAX_TIME),
    Parameter("contact_kd", 20.0, "damping of the contact velocities in the contact constraint "
                                  "(1/s; 0: eq. 2 as is)", low=0.0),
    *COM_PARAMETERS,
    *SWING_FOOT_PARAMETERS,
    *POSTURE_PARAMETERS,
    COP_MARGIN,
    Parameter("formulations", "reduced,full", "formulations to run, in this order",
              choices=("reduced", "full"), items=str),
    ENGINE,
    Parameter("timing_warmup", 50, "first cycles left out of the timing statistics (plans, "
                                   "caches)", low=0),
)


def config(robot, params: dict) -> SteppingConfig:
    """The :class:`SteppingConfig` of the scenario parameters (the left sole is the first stance,
    by the contact names)."""
    left, right = robot.contact_names[0], robot.contact_names[1]
    if "right" in left:
        left, right = right, left
    return SteppingConfig(
        stance_order=(left, right), steps=int(params["steps"]), shift_time=params["shift_time"],
        unload_time=params["unload_time"], lift_time=params["lift_time"],
        reload_time=params["reload_time"], preload=params["preload"], lift=params["lift"],
        touchdown_depth=params["touchdown_depth"], settle=params["settle"],
        contact_kd=params["contact_kd"], **task_gains(params))


def _stats(x: np.ndarray) -> dict:
    if x.size == 0:
        return {}
    ms = 1e3 * x
    return {"n": int(x.size), "median_ms": float(np.median(ms)), "mean_ms": float(ms.mean()),
            "p95_ms": float(np.percentile(ms, 95)), "p99_ms": float(np.percentile(ms, 99)),
            "max_ms": float(ms.max())}


def run_once(robot, params: dict, reduced: bool, progress: bool = False,
             observers=()) -> dict:
    """One closed-loop stepping run; returns measurements (simulator-based) and timings.
    ``observers`` watch it, labelled with the formulation."""
    ctrl = Stepping(robot, config(robot, params), reduced=reduced, engine=params["engine"],
                    cop_margin=params["cop_margin"])
    duration = ctrl.phases[-1].end
    sim = Simulator(robot, observers=observers, label="reduced" if reduced else "full")
    names = list(robot.contact_names)
    start_poses = sim.contact_frame_poses()
    base_z0 = sim.state()[0][2]
    swing_z = {n: [] for n in names}
    tilt = {n: [] for n in names}
    slip = {n: [] for n in names}
    base_z, com = [], []
    twin = TwinCentroidal(robot)

    def observe(t, sol):
        poses = sim.contact_frame_poses()
        for n in names:
            pos, R = poses[n]
            swing_z[n].append(pos[2] - start_poses[n][0][2])
            tilt[n].append(tilt_deg(R))
            slip[n].append(sole_slip(pos, start_poses[n][0]))
        q, v = sim.state()
        base_z.append(q[2])
        com.append(twin.at(q, v)[0])

    failures = run_closed_loop(sim, ctrl, duration, progress=progress, on_result=observe)
    t = sim.log.arrays()["t"]
    wrenches = sim.log.arrays()["contact_wrenches"]
    n = len(t)
    steps = []
    in_contact = {k: np.ones(n, bool) for k in names}
    for ph in ctrl.phases:
        if ph.kind != "single":
            continue
        window = (t >= ph.start) & (t < ph.end)
        in_contact[ph.swing] &= ~window
        up = (t >= ph.start + 0.5 * params["lift_time"]) & (t < ph.end - 0.5 * params["lift_time"])
        k = names.index(ph.swing)
        z = np.array(swing_z[ph.swing])
        steps.append({"swing": ph.swing, "t_lift_off": ph.start, "t_touch_down": ph.end,
                      "lift_m": float(z[window].max()),
                      "max_normal_force_while_up_N": float(wrenches[up, k, 2].max()),
                      "min_stance_normal_force_N": float(wrenches[window, names.index(ph.stance),
                                                                  2].min())})
    max_tilt = max(float(np.max(np.array(tilt[k])[in_contact[k]])) for k in names)
    max_slip = max(float(np.max(np.array(slip[k])[in_contact[k]])) for k in names)
    final_com_xy_err = float(np.linalg.norm(com[-1][:2] - ctrl.com_middle[:2]))
    base_drop = float(base_z0 - min(base_z))
    cycles = np.array(ctrl.cycle_times)
    warm = min(int(params["timing_warmup"]), len(cycles))
    nc = np.array(ctrl.n_contacts)
    keep = np.arange(len(cycles)) >= warm
    parts = {key: np.array([d.get(key, np.nan) for d in ctrl.timings])
             for key in ("rows", "solve", "total")}
    timing = {"overall": _stats(cycles[keep]),
              "double_support": _stats(cycles[keep & (nc == 2)]),
              "single_support": _stats(cycles[keep & (nc == 1)]),
              "breakdown_median_ms": {
                  "update_and_phase_logic": float(1e3 * np.median(cycles[keep]
                                                                  - parts["total"][keep])),
                  "rows": float(1e3 * np.median(parts["rows"][keep])),
                  "solve": float(1e3 * np.median(parts["solve"][keep])),
                  "recover_tau": float(1e3 * np.median((parts["total"] - parts["rows"]
                                                        - parts["solve"])[keep]))}}
    lifted_ok = all(s["lift_m"] > 0.8 * params["lift"] and s["max_normal_force_while_up_N"] == 0.0
                    for s in steps)
    th = Thresholds.for_robot(robot)
    success = bool(failures == 0 and lifted_ok and th.feet_in_place(max_tilt, max_slip)
                   and base_drop < th.max_base_drop and final_com_xy_err < th.step_cog_error
                   and len(steps) > 0)
    return {"formulation": "reduced" if reduced else "full", "success": success,
            "failed_cycles": failures, "steps": steps, "max_sole_tilt_in_contact_deg": max_tilt,
            "max_sole_slip_in_contact_m": max_slip, "max_base_drop_m": base_drop,
            "final_cog_xy_error_m": final_com_xy_err, "timing": timing,
            "_t": t, "_cycles": cycles, "_nc": nc, "_phases": ctrl.phases}


def formulations(params: dict) -> list[str]:
    """The formulations ``--set formulations`` asks for, in order."""
    return [k.strip() for k in str(params["formulations"]).split(",") if k.strip()]


def run(robot, controller: str, params: dict, out_dir: Path | None,
        progress: bool, observers=()) -> ScenarioResult:
    runs = {}
    for kind in formulations(params):
        log.info("stepping: %s formulation", kind)
        runs[kind] = run_once(robot, params, reduced=(kind == "reduced"), progress=progress,
                              observers=observers)
    metrics = {k: {key: val for key, val in r.items() if not key.startswith("_")}
               for k, r in runs.items()}
    if "reduced" in runs and "full" in runs:
        ratios = {}
        for part in ("overall", "double_support", "single_support"):
            a, b = runs["reduced"]["timing"][part], runs["full"]["timing"][part]
            if a and b:
                ratios[part] = {s: b[s] / a[s] for s in ("median_ms", "p95_ms", "p99_ms",
                                                         "max_ms")}
        metrics["ratio_full_over_reduced"] = ratios
        med = ratios.get("overall", {}).get("median_ms")
        metrics["reduced_faster_by_percent_median"] = (100.0 * (1.0 - 1.0 / med)) if med else None
        mx = ratios.get("overall", {}).get("max_ms")
        metrics["reduced_faster_by_percent_max"] = (100.0 * (1.0 - 1.0 / mx)) if mx else None
    success = all(r["success"] for r in runs.values())
    notes = [
        f"controller engine '{params['engine']}'; wall times on a shared 2-core machine: noisy, "
        "especially the tails (p99/max) — compare medians; not asserted by any test",
        "Herzog et al. 2016 (Sect. 5.1, Table 1, Fig. 5; C++/Eigen, Goldfarb-Idnani, i7-2600 3.4 GHz): "
        "peak ~1 ms for the 14-DoF biped, 5 ms (full) vs 3 ms (reduced) for the 25-DoF robot; the "
        "reduction is ~40 % faster; the maximum occurs in double support (c = 2)",
        f"robot {robot.name}: {robot.na} actuated DoF (the paper's Sarcos: 25); the reduction "
        f"removes {robot.na} equality rows and {robot.na} variables here",
    ]
    result = ScenarioResult("stepping", robot.name, controller, success, metrics, params, notes)
    if out_dir is not None and runs:
        result.figures = [str(stepping_timing_figure(
            Path(out_dir) / "fig5_timing.png", runs,
            title=f"stepping (Table 1) on {robot.name}: reduced vs full formulation, single "
                  f"support shaded"))]
    return result


def validate(robot, params: dict) -> None:
    if len(robot.contact_names) != 2 or any(c.spec.type != "rectangle" for c in robot.contacts):
        raise ValueError(f"stepping needs a biped with two soles; robot '{robot.name}' has "
                         f"{list(robot.contact_names)}")
    for key in ("shift_time", "unload_time", "lift_time", "reload_time"):
        if not params[key] > 0:
            raise ValueError(f"--set {key}: must be > 0, got {params[key]}")
    if int(params["steps"]) < 1:
        raise ValueError("--set steps: must be >= 1")
    check_engine(params)
    kinds = formulations(params)
    if not kinds or any(k not in ("reduced", "full") for k in kinds):
        raise ValueError(f"--set formulations: comma-separated 'reduced'/'full', got "
                         f"'{params['formulations']}'")


SCENARIO = Scenario(
    name="stepping",
    summary="Sect. 5.1 timing run (Table 1, Fig. 5): stepping in place on the full humanoid, "
            "reduced vs full formulation; per-cycle controller time, single support shaded",
    parameters=PARAMETERS,
    controllers=("pd",),
    default_robot="talos",
    run_function=run,
    validate_function=validate,
    simulations=lambda params, controller: len(formulations(params)),
)
