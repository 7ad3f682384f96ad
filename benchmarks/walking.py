"""Closed-loop walking and push-recovery runs of :class:`~wholebody.control.Walking` in the MuJoCo
twin, printed as the table of docs/results.md ("Walking and stepping").

Each case is one deterministic simulation on the controller's defaults
(``WalkingConfig.for_robot``): a velocity command (forward, lateral, yaw rate, speeds in m/s on
talos14 times sqrt(h / h_talos14)) held from 0.5 s, then zero for the last 3 s; or a 0.1 s
half-sine push at the base (hip height) from 1 s along ``angle`` (the ``push`` scenario's
convention: 0 pushes the front toward -x, 90 the left side toward -y), 5 s in all. Fallen: the
base below 60 % of its standing height. The controller's wall time per cycle (native engine when
built) is timed here too: run with ``OPENBLAS_NUM_THREADS=1`` on an otherwise idle machine for
timings worth quoting.

    OPENBLAS_NUM_THREADS=1 python benchmarks/walking.py [--jobs 2]
"""

from __future__ import annotations

import argparse
import math
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pinocchio as pin

import wholebody as wb
from wholebody.control import Walking, WalkingConfig
from wholebody.robots.reference import humanoid_length_ratio
from wholebody.sim.disturbance import Push
from wholebody.sim.simulator import Simulator

WALKS = [("talos14", (0.4, 0.0, 0.0), 15.0), ("talos14", (0.1, 0.0, 0.3), 10.0),
         ("talos14", (0.0, 0.1, 0.0), 10.0), ("talos", (0.3, 0.0, 0.0), 10.0),
         ("romeo", (0.2, 0.0, 0.0), 10.0)]
PUSHES = [("talos14", dv, angle, True) for dv in (0.4, 0.5, 0.6) for angle in (0, 90, 180, 270)]
PUSHES += [("talos14", 0.5, 0, False), ("talos14", 0.5, 180, False)]


def _fallen(robot, q) -> bool:
    return q[2] < 0.6 * robot.q_ref[2]


def walk(case) -> dict:
    name, command, duration = case
    robot = wb.load_robot(name)
    scale = math.sqrt(humanoid_length_ratio(robot))
    ctrl, sim = Walking(robot), Simulator(robot)
    fails, fell = 0, False
    while sim.t < duration:
        q, v = sim.state()
        on = 0.5 < sim.t < duration - 3.0
        ramp = min(1.0, max(sim.t - 0.5, 0.0))  # 1 s ramp of the forward speed
        ctrl.set_command(*((ramp * command[0] * scale, command[1] * scale, command[2])
                           if on else (0.0, 0.0, 0.0)))
        sol = ctrl.compute(q, v, sim.t)
        fails += not sol.ok
        if _fallen(robot, q):
            fell = True
            break
        sim.step(sol.tau)
    yaw = pin.rpy.matrixToRpy(pin.Quaternion(q[3:7]).toRotationMatrix())[2]
    times = 1e3 * np.array(ctrl.cycle_times[50:])
    return {"case": f"walk {name} cmd {tuple(round(c * (scale if i < 2 else 1), 3) for i, c in enumerate(command))}",
            "fell": fell, "t_end": round(sim.t, 2), "steps": len(ctrl.steps),
            "base_xy": q[:2].round(3).tolist(), "yaw_deg": round(math.degrees(yaw), 1),
            "failed_cycles": fails, "standing": ctrl.phase.kind == "stand",
            "cycle_ms_median": round(float(np.median(times)), 3),
            "cycle_ms_p99": round(float(np.percentile(times, 99)), 3)}


def push(case) -> dict:
    name, dv, angle, stepping = case
    robot = wb.load_robot(name)
    ctrl = Walking(robot, WalkingConfig.for_robot(robot, stepping=stepping))
    sim = Simulator(robot)
    a, duration = math.radians(angle), 0.1
    peak = dv * robot.mass / (2.0 / math.pi * duration)
    sim.add_push(Push(robot.base_frame, (-math.cos(a), -math.sin(a), 0.0), peak, 1.0, duration))
    fell = False
    while sim.t < 5.0:
        q, v = sim.state()
        sol = ctrl.compute(q, v, sim.t)
        if _fallen(robot, q):
            fell = True
            break
        sim.step(sol.tau)
    return {"case": f"push {name} dv {dv} angle {angle} stepping {stepping}", "fell": fell,
            "t_end": round(sim.t, 2), "steps": len(ctrl.steps),
            "standing": ctrl.phase.kind == "stand",
            "landed": [s.target[:2].round(3).tolist() for s in ctrl.steps]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(walk, WALKS)) + list(pool.map(push, PUSHES))
    for row in rows:
        print(row)


if __name__ == "__main__":
    main()
