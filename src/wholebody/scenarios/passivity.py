"""``passivity``: the storage function of the passive WBC measured along a closed-loop run
(Fahmi et al. 2019, Sect. III, eqs. 20-31).

The paper proves passivity of the controller under Assumption 1 (stance feet do not move) and
Assumption 2 (the QP achieves the motion tasks; no feed-forward terms) by showing that the storage
function V = V_com + V_sw (eq. 23) satisfies eq. 31,

    V̇ = Δq̇_jᵀ τ − Δv_comᵀ D_com Δv_com − Δv_swᵀ D_sw Δv_sw  ≤  Δq̇_jᵀ τ.

This scenario runs HyQ with the feed-forward terms off (W_ff of eq. 4 via
``TrunkImpedance(feedforward=False)``, and v̇_sw,ff of eq. 6 zeroed in the plan the controller sees,
:class:`~wholebody.control.passivity.SwingFeedForwardOff`) and measures, every WBC cycle, on the
simulator's state (:class:`~wholebody.control.passivity.StorageMeter`):

* V_com = ½ Δxᵀ K_x Δx + ½ Δθᵀ K_θ Δθ + m g Δz — the CoM/trunk impedance potential plus the
  gravity potential whose gradient is ∇V_com,g = m g (eq. 4, footnote 6; as a function of the
  error, so that V̇ = Δv_comᵀ ∇V_com as in eq. 24 and footnote 11). Δθ = log3(R_d Rᵀ); for the
  isotropic K_θ of Sect. V, d/dt ½|Δθ|² = Δθᵀ Δω exactly.
* V_sw: footnote 10 says the analysis uses the force-level swing task (eq. 5); ours is at the
  acceleration level (eq. 6), where K_sw, D_sw "have no physical meaning". The acceleration task is
  the force-level impedance F = Λ(K_sw Δx + D_sw Δv) with Λ = (J M⁻¹ Jᵀ)⁻¹ the foot's
  operational-space inertia, so we use V_sw = ½ Δx_swᵀ Λ K_sw Δx_sw (energy units, Λ evaluated at
  each sample) and D_sw,eff = Λ D_sw in the dissipation term. (½ K_sw |Δx|² without Λ is in m²/s²,
  not J; its size is reported too.) V_sw only exists while a foot swings: V jumps at lift-off and
  touchdown, so intervals with a contact switch are counted separately.
* q̇_j,d: the joint velocities of the generalized velocity that realises the desired CoM velocity,
  the desired trunk angular velocity, zero stance-foot velocity (Assumption 1, v_st,d = 0) and the
  planner's swing-foot velocities — the unique solution of [J_com; S_ω; J_feet] ν_d = [ẋ_com,d;
  ω_d; v_feet,d] (18 equations, 18 unknowns for HyQ). With it, eq. 27a holds identically.
* supply Δq̇_jᵀ τ: τ and q̇_j from the simulator log at 1 kHz (the torque actually applied), q̇_j,d
  interpolated between WBC cycles; integrated over each WBC interval as τᵀ(q̇_j,d Δt − Δq_j).

Per WBC interval the measured rate V̇ (finite difference of V) is compared with the supply; the
margin s − V̇ is compared with the dissipation that eq. 31 predicts. A check of the measurement
itself: the finite-difference V̇ must agree with the analytic rate Δv_comᵀ∇V_com + Δv_swᵀ∇V_sw.

Success = no fall, every WBC cycle solved, and that self-check. Whether V̇ ≤ Δq̇ᵀτ holds is the
measurement, reported in ``metrics`` and ``notes``, never asserted.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..control.passive import SwingGains
from ..control.passivity import StorageMeter, SwingFeedForwardOff
from ..planning.planner import GaitPlanner
from ..report.locomotion_figures import passivity_figure
from ..tasks.wrench import TrunkImpedance
from .base import Parameter, Scenario, ScenarioResult
from .gait_measures import intervals, outcome
from .locomotion import (DURATION, GAIT, GAIT_SHAPE, WBC_GAINS, PaperSpeed, check_gait,
                         check_quadruped, gait_options, make_schedule, ramped_command, run_gait,
                         wbc_gains)

log = logging.getLogger(__name__)

TOLERANCE = 1.0  # W: violations smaller than this are reported apart (finite differences, 4 ms)
NEAR_SWITCH = 0.05  # s: "right after a lift-off or touchdown"

PARAMETERS = (
    GAIT,
    Parameter("speed", PaperSpeed(0.1), "forward speed after the ramp-up (m/s)", low=0.0, high=5.0),
    DURATION,
    Parameter("feedforward", False, "keep the feed-forward terms on (Assumption 2 needs them off)"),
    *WBC_GAINS,
    *GAIT_SHAPE,
)


def energy_balance(storage: dict, sim_log: dict, nq_base: int = 7, nv_base: int = 6) -> dict:
    """Per WBC interval k: V̇_k = ΔV / Δt, supply s_k = (1/Δt) Σ τᵀ(q̇_j,d dt − Δq_j) over the
    simulator steps of the interval (q̇_j,d linearly interpolated), the analytic rate and the
    dissipation averaged over the interval, and whether the contact set switched."""
    t = storage["t"]
    V = (storage["V_position"] + storage["V_orientation"] + storage["V_gravity"]
         + storage["V_swing"])
    ts, qs, taus = sim_log["t"], sim_log["q"], sim_log["tau_applied"]
    idx = np.searchsorted(ts, t - 1e-9)
    n = len(t) - 1
    supply = np.full(n, np.nan)
    for k in range(n):
        j0, j1 = idx[k], idx[k + 1]
        if j1 >= len(ts):
            break
        dt_k = ts[j1] - ts[j0]
        w = ((ts[j0:j1] - ts[j0]) / max(dt_k, 1e-12))[:, None]
        qd_des = (1.0 - w) * storage["qd_des"][k] + w * storage["qd_des"][k + 1]
        dq = qs[j0 + 1:j1 + 1, nq_base:] - qs[j0:j1, nq_base:]
        step = np.diff(ts[j0:j1 + 1])[:, None]
        supply[k] = float(np.sum(taus[j0:j1] * (qd_des * step - dq))) / dt_k
    dt = np.diff(t)
    Vdot = np.diff(V) / dt
    switched = np.any(storage["stance"][1:] != storage["stance"][:-1], axis=1)
    since = np.full(n, np.inf)  # time from the last contact switch (lift-off or touchdown)
    last = -np.inf
    for k in range(n):
        if switched[k]:
            last = t[k + 1]
        since[k] = t[k] - last
    avg = lambda x: 0.5 * (x[1:] + x[:-1])  # noqa: E731
    return {"t": t[:-1], "dt": dt, "V": V, "Vdot": Vdot, "supply": supply,
            "rate_analytic": avg(storage["rate_analytic"]),
            "dissipation": avg(storage["dissipation"]), "switched": switched,
            "since_switch": since}


def summarize(balance: dict, t_from: float = 0.0) -> dict:
    """Where V̇ ≤ Δq̇ᵀτ holds and by what margin (intervals from ``t_from``, valid supply)."""
    sel = (balance["t"] >= t_from) & np.isfinite(balance["supply"])
    smooth = sel & ~balance["switched"]
    margin = balance["supply"] - balance["Vdot"]
    out = {}
    for name, mask in (("no_switch", smooth), ("all", sel)):
        m = margin[mask]
        if m.size == 0:
            continue
        worst = int(np.argmin(m))
        out[name] = {
            "intervals": int(m.size),
            "fraction_holds": float(np.mean(m >= 0.0)),
            "median_margin_W": float(np.median(m)),
            "worst_violation_W": float(max(0.0, -m[worst])),
            "worst_violation_t": float(balance["t"][mask][worst]),
            "violation_energy_J": float(np.sum(np.maximum(0.0, -m) * balance["dt"][mask])),
            "fraction_holds_within_1W": float(np.mean(m >= -TOLERANCE)),
        }
    # where the violations beyond the tolerance are: right after a contact switch or elsewhere
    bad = smooth & (margin < -TOLERANCE)
    near = bad & (balance["since_switch"] <= NEAR_SWITCH)
    out["violations_beyond_1W"] = {
        "count": int(bad.sum()),
        "within_50ms_after_contact_switch": int(near.sum()),
        "worst_elsewhere_W": float(max(0.0, -margin[bad & ~near].min())) if np.any(bad & ~near)
        else 0.0}
    # eq. 31: margin = dissipation exactly; how far from it
    resid = (margin - balance["dissipation"])[smooth]
    scale = np.sqrt(np.mean(balance["supply"][smooth] ** 2)) if np.any(smooth) else np.nan
    out["eq31_residual_rms_W"] = float(np.sqrt(np.mean(resid ** 2))) if resid.size else np.nan
    out["supply_rms_W"] = float(scale)
    out["Vdot_rms_W"] = float(np.sqrt(np.mean(balance["Vdot"][smooth] ** 2)))
    out["dissipation_median_W"] = float(np.median(balance["dissipation"][smooth]))
    # the integral form over the whole window (switch jumps included)
    k0 = int(np.argmax(sel))
    k1 = int(np.nonzero(sel)[0][-1])
    dV = float(balance["V"][k1 + 1] - balance["V"][k0])
    work = float(np.sum(balance["supply"][k0:k1 + 1] * balance["dt"][k0:k1 + 1]))
    out["integral"] = {"delta_V_J": dV, "supply_J": work, "holds": bool(dV <= work)}
    # self-check of the measurement: finite-difference V̇ vs analytic rate (no switches)
    diff = (balance["Vdot"] - balance["rate_analytic"])[smooth]
    ref = np.sqrt(np.mean(balance["rate_analytic"][smooth] ** 2))
    out["rate_check_rel_rms"] = float(np.sqrt(np.mean(diff ** 2)) / max(ref, 1e-9))
    return out


def validate(robot, params: dict) -> None:
    check_gait(params)
    check_quadruped(robot, "the passivity scenario", params["gait"])
    if not 2.0 <= params["duration"]:
        raise ValueError("--set duration: need at least 2 s")


def measure(robot, gait: str = "crawl", speed: float = 0.1, duration: float = 10.0,
            feedforward: bool = False, progress: bool = False, gains: dict | None = None,
            shape: dict | None = None, observers=()):
    """Run the gait and return (run, storage arrays, energy balance); ``gains``: the controller's
    gains (:func:`~wholebody.scenarios.locomotion.wbc_gains`); ``shape``: the gait's step height
    and period (:data:`~wholebody.scenarios.locomotion.GAIT_SHAPE`); ``observers`` watch the
    simulation."""
    planner = GaitPlanner.for_robot(robot, make_schedule(robot, gait, 1.0, shape),
                                    ramped_command(speed), **gait_options(robot, shape))
    if not feedforward:
        planner = SwingFeedForwardOff(planner)
    gains = gains or {}
    impedance = TrunkImpedance.for_robot(robot, feedforward=feedforward,
                                         **gains.get("impedance", {}))
    swing = SwingGains(*gains["swing"]) if "swing" in gains else SwingGains()
    meter = StorageMeter(robot, impedance, swing.K, swing.D)
    run = run_gait(robot, "passive", duration=duration, planner=planner, progress=progress,
                   controller_options={"impedance": impedance, "swing": swing},
                   on_cycle=meter, gains=gains or None, observers=observers)
    storage = meter.log.arrays()
    balance = energy_balance(storage, run.sim.log.arrays())
    return run, storage, balance


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool,
        observers=()) -> ScenarioResult:
    gait_run, storage, balance = measure(robot, params["gait"], params["speed"],
                                         params["duration"], params["feedforward"], progress,
                                         wbc_gains(params), params, observers)
    stats = summarize(balance, t_from=0.5)
    we = storage["wrench_error"]
    metrics = {
        **outcome(gait_run), **gait_run.tracking(1.0),
        "passivity": stats,
        "storage": {"V_position_max_J": float(storage["V_position"].max()),
                    "V_orientation_max_J": float(storage["V_orientation"].max()),
                    "V_gravity_range_J": [float(storage["V_gravity"].min()),
                                          float(storage["V_gravity"].max())],
                    "V_swing_max_J": float(storage["V_swing"].max()),
                    "V_swing_raw_max_m2s2": float(storage["V_swing_raw"].max())},
        "assumption2_wrench_error_N": {"median": float(np.nanmedian(we)),
                                       "p95": float(np.nanpercentile(we, 95)),
                                       "max": float(np.nanmax(we))},
        "qd_des_solve_residual_max": float(storage["solve_residual"].max()),
    }
    ns = stats.get("no_switch", {})
    al = stats.get("all", {})
    notes = [
        f"V̇ ≤ Δq̇ᵀτ holds in {100 * ns.get('fraction_holds', np.nan):.1f} % of "
        f"{ns.get('intervals', 0)} WBC intervals without a contact switch "
        f"({100 * al.get('fraction_holds', np.nan):.1f} % of all {al.get('intervals', 0)}); "
        f"worst violation {ns.get('worst_violation_W', np.nan):.1f} W at "
        f"t = {ns.get('worst_violation_t', np.nan):.2f} s (all intervals: "
        f"{al.get('worst_violation_W', np.nan):.1f} W); median margin "
        f"{ns.get('median_margin_W', np.nan):.1f} W",
        f"violations beyond {TOLERANCE:.0f} W: {stats['violations_beyond_1W']['count']}, of which "
        f"{stats['violations_beyond_1W']['within_50ms_after_contact_switch']} within "
        f"{1000 * NEAR_SWITCH:.0f} ms after a lift-off/touchdown (impacts and swing-set changes: "
        f"Assumption 1 and the QP's instant re-distribution); worst elsewhere "
        f"{stats['violations_beyond_1W']['worst_elsewhere_W']:.1f} W",
        f"eq. 31 predicts margin = dissipation (median {stats['dissipation_median_W']:.2f} W); "
        f"measured residual RMS {stats['eq31_residual_rms_W']:.1f} W against a supply RMS of "
        f"{stats['supply_rms_W']:.1f} W and V̇ RMS {stats['Vdot_rms_W']:.1f} W",
        f"integral form over the run: ΔV = {stats['integral']['delta_V_J']:.2f} J vs supplied "
        f"{stats['integral']['supply_J']:.2f} J ({'holds' if stats['integral']['holds'] else 'fails'})",
        f"Assumption 2 (QP achieves the trunk wrench): |W_com − W_com,d| median "
        f"{metrics['assumption2_wrench_error_N']['median']:.3g}, p95 "
        f"{metrics['assumption2_wrench_error_N']['p95']:.3g}, max "
        f"{metrics['assumption2_wrench_error_N']['max']:.3g} (N, Nm mixed norm)",
        "V_sw uses Λ K_sw (the force-level equivalent of the acceleration-level swing task, "
        "footnote 10); q̇_j,d from [J_com; S_ω; J_feet] ν_d = [ẋ_com,d; ω_d; v_feet,d]",
    ]
    if metrics["assumption2_wrench_error_N"]["median"] > 1.0:
        notes.append("Assumption 2 does not hold in this run: the QP does not realise W_com,d "
                     "(with two feet on the ground, as in a trot, no contact force makes a moment "
                     "about the line through them), so eqs. 22b-31 do not apply and V̇ ≤ Δq̇ᵀτ "
                     "is not expected to hold")
    check_ok = stats["rate_check_rel_rms"] < 0.1
    if not check_ok:
        notes.append(f"measurement self-check failed: finite-difference V̇ vs analytic rate "
                     f"relative RMS {stats['rate_check_rel_rms']:.3f}")
    success = (not gait_run.fell) and gait_run.failures == 0 and check_ok
    figures = []
    if out_dir is not None:
        margin = balance["supply"] - balance["Vdot"]
        violations = intervals(balance["t"], (margin < -TOLERANCE) & ~balance["switched"])
        title = (f"{robot.name} {params['gait']} {params['speed']:.3g} m/s, feed-forward "
                 f"{'on' if params['feedforward'] else 'off'} (Assumption 2)")
        figures.append(str(passivity_figure(Path(out_dir) / "passivity.png", storage, balance,
                                            title, TOLERANCE, violations)))
    return ScenarioResult("passivity", robot.name, controller, success, metrics, params, notes,
                          figures=figures)


SCENARIO = Scenario(
    name="passivity",
    summary="Sect. III / eqs. 23-31: storage function V of the passive WBC and its rate against "
            "the supply dq_j^T tau over a HyQ run with the feed-forward terms off (Assumption 2); "
            "success = no fall, every cycle solved, V measurement self-consistent",
    parameters=PARAMETERS,
    controllers=("passive",),
    default_robot="hyq",
    run_function=run,
    validate_function=validate,
    simulations=1,
)
