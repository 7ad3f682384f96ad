"""``single-support``: contact switching to one foot (Herzog et al. 2016 Sect. 5.4, Table 4).

Three phases, torques from the hierarchy only (no joint PD), PD momentum task (eq. 22):
1. shift: the CoG reference moves (smoothstep) over the stance sole, Table 2 hierarchy;
2. unload: a force regulariser drives the leaving sole's wrench from its value at the start of the
   phase to zero (a ramp of the target, not of the weight: ramping the weight over six decades gave
   torque jumps of 30 Nm per cycle);
3. single support: the contact is removed, the Table 4 hierarchy takes over with a swing-foot task
   lifting the sole by ``lift`` metres.
Success: every cycle solved, the foot lifted, the CoG within 5 mm of its reference at the end, the
stance sole flat (< 2 deg) and in place (< 1 cm), and no torque jump above ``max_torque_jump``.
Not yet here: pushes in single support and the joint-space sine tracking of Fig. 11.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..control.stacks import table2_stack, table4_stack
from ..formulation import Formulation
from ..report.plots import time_series_figure
from ..sim.simulator import Simulator
from ..tasks import ForceRegularizer
from ..variables import Variables
from .base import Parameter, Scenario, ScenarioResult
from .loop import run_closed_loop

PARAMETERS = (
    Parameter("stance", "left_sole", "contact kept (the other sole is lifted)"),
    Parameter("shift_time", 2.0, "duration of the CoG shift (s)"),
    Parameter("unload_time", 0.5, "duration of the unloading (s)"),
    Parameter("lift_time", 1.0, "duration of the swing-foot lift (s)"),
    Parameter("lift", 0.10, "swing-foot lift height (m)"),
    Parameter("duration", 6.0, "simulated time (s)"),
    Parameter("max_torque_jump", 10.0, "largest cycle-to-cycle torque change counted as "
                                       "continuous (Nm)"),
)


def smoothstep(s: float) -> float:
    s = min(max(s, 0.0), 1.0)
    return s * s * (3.0 - 2.0 * s)


class ContactSwitch:
    """Double support -> unloading -> single support, as a ``compute(q, v, t)`` controller."""

    def __init__(self, robot, stance: str, params: dict):
        swing_contact = next(n for n in robot.contact_names if n != stance)
        self.robot, self.p = robot, params
        self.swing_frame = robot.contact(swing_contact).spec.frame
        self.formulation = Formulation(robot)
        self.double, self.double_vars = table2_stack(robot), Variables(robot)
        self.unload = ForceRegularizer(name="unload", contacts=[swing_contact], weight=0.0)
        self.double.levels[2].append(self.unload)
        self.single = table4_stack(robot, [stance], [self.swing_frame])
        self.single_vars = Variables(robot, [stance])
        self.swing = self.single.find(f"swing {self.swing_frame}")
        self.swing_contact = swing_contact
        robot.update(robot.q_ref, np.zeros(robot.nv))
        self.com_start = robot.com.copy()
        stance_pos = robot.frame_placement(robot.contact(stance).spec.frame)[0]
        self.com_target = np.array([stance_pos[0], stance_pos[1], self.com_start[2]])
        self.unload_start: np.ndarray | None = None
        self.lift_start: np.ndarray | None = None
        self.last = None

    @property
    def switch_time(self) -> float:
        return self.p["shift_time"] + self.p["unload_time"]

    def com_ref(self, t: float) -> np.ndarray:
        return self.com_start + smoothstep(t / self.p["shift_time"]) * (self.com_target -
                                                                       self.com_start)

    def compute(self, q, v, t: float):
        robot, p = self.robot, self.p
        robot.update(q, v)
        if t < self.switch_time:
            self.double.find("momentum").com_ref = self.com_ref(t)
            if t >= p["shift_time"]:
                if self.unload_start is None:
                    self.unload_start = self.last.forces[self.swing_contact].copy()
                self.unload.weight = 1.0
                s = smoothstep((t - p["shift_time"]) / p["unload_time"])
                self.unload.targets[self.swing_contact] = (1.0 - s) * self.unload_start
            sol = self.formulation.solve(self.double, self.double_vars, diagnostics=False)
        else:
            if self.lift_start is None:
                self.lift_start, rotation = robot.frame_placement(self.swing_frame)
                self.swing.rotation = rotation
            self.single.find("momentum").com_ref = self.com_target
            s = smoothstep((t - self.switch_time) / p["lift_time"])
            self.swing.position = self.lift_start + np.array([0.0, 0.0, p["lift"] * s])
            sol = self.formulation.solve(self.single, self.single_vars, diagnostics=False)
        self.last = sol
        return sol


def validate(robot, params: dict) -> None:
    if params["stance"] not in robot.contact_names or len(robot.contact_names) != 2 or any(
            c.spec.type != "rectangle" for c in robot.contacts):
        raise ValueError(f"--set stance: '{params['stance']}' must be one of the two soles of a "
                         f"biped; robot '{robot.name}' has {list(robot.contact_names)}")


def run(robot, controller: str, params: dict, out_dir: Path | None, progress: bool) -> ScenarioResult:
    ctrl = ContactSwitch(robot, params["stance"], params)
    sim = Simulator(robot)
    stance_start = sim.contact_frame_poses()[params["stance"]]
    com_err, swing_z, tilt, slip, tau = [], [], [], [], []

    def observe(t, sol):
        com_err.append(robot.com - (ctrl.com_ref(t) if t < ctrl.switch_time else ctrl.com_target))
        poses = sim.contact_frame_poses()
        swing_z.append(poses[ctrl.swing_contact][0][2])
        p, R = poses[params["stance"]]
        tilt.append(np.degrees(np.arccos(np.clip(R[2, 2], -1.0, 1.0))))
        slip.append(np.linalg.norm((p - stance_start[0])[:2]))
        tau.append(sol.tau.copy())

    failures = run_closed_loop(sim, ctrl, params["duration"], progress=progress, on_result=observe)
    t = sim.log.arrays()["t"]
    com_err, tau = np.array(com_err), np.array(tau)
    jumps = np.abs(np.diff(tau, axis=0)).max(axis=1)
    k_switch = int(round(ctrl.switch_time / sim.dt))
    metrics = {
        "failed_cycles": failures,
        "swing_lift_m": float(swing_z[-1] - swing_z[0]),
        "final_cog_error_m": float(np.linalg.norm(com_err[-1])),
        "max_cog_error_m": float(np.linalg.norm(com_err, axis=1).max()),
        "max_stance_tilt_deg": float(max(tilt)),
        "max_stance_slip_m": float(max(slip)),
        "max_torque_jump_Nm": float(jumps.max()),
        "torque_jump_at_switch_Nm": float(jumps[max(0, k_switch - 2):k_switch + 2].max()),
        "unloaded_force_N": float(np.linalg.norm(ctrl.unload_start[:3])) if ctrl.unload_start
        is not None else None,
    }
    success = (failures == 0 and metrics["swing_lift_m"] > 0.8 * params["lift"]
               and metrics["final_cog_error_m"] < 5e-3 and metrics["max_stance_tilt_deg"] < 2.0
               and metrics["max_stance_slip_m"] < 0.01
               and metrics["max_torque_jump_Nm"] < params["max_torque_jump"])
    result = ScenarioResult("single-support", robot.name, controller, success, metrics, params,
                            log=sim.log)
    if out_dir is not None:
        wrenches = sim.log.arrays()["contact_wrenches"]
        result.figures = [str(time_series_figure(
            Path(out_dir) / "single_support.png", t,
            [("CoG error", "mm", {a: 1000 * com_err[:, i] for i, a in enumerate("xyz")}),
             ("normal forces (simulator)", "N",
              {n: wrenches[:, i, 2] for i, n in enumerate(robot.contact_names)}),
             ("swing sole height", "cm", {"z": 100 * (np.array(swing_z) - swing_z[0])}),
             ("largest cycle-to-cycle torque change", "Nm", {"max |Δτ|": np.r_[0.0, jumps]})],
            title=f"single support — {robot.name}",
            shaded=[(params["shift_time"], ctrl.switch_time)]))]
    return result


SCENARIO = Scenario(
    name="single-support",
    summary="Sect. 5.4 contact switching: CoG shift, unloading, Table 4 single support lifting "
            "the other sole (PD momentum task); success = lifted, balanced, torques continuous",
    parameters=PARAMETERS,
    controllers=("pd",),
    default_robot="talos14",
    run_function=run,
    validate_function=validate,
)
