"""Accuracy of the kinematic-inertial EKF run open-loop beside closed-loop runs in the twin that
read the exact state: talos14 standing (standing controller) and hyq trotting at 0.3 m/s after 1 s
of standing (passive WBC); default sensors (``SensorSpec()``) and exact ones. A measurement, not a
test.

    python benchmarks/estimator_accuracy.py [--seconds 5] [--seed 1]
"""

from __future__ import annotations

import argparse

import numpy as np
import pinocchio as pin

import wholebody as wb
from wholebody.control.standing import StandingController
from wholebody.estimation import TwinEstimation
from wholebody.planning.trunk import VelocityCommand
from wholebody.scenarios.locomotion import run_gait
from wholebody.scenarios.loop import run_closed_loop
from wholebody.sim.sensors import SensorSpec
from wholebody.sim.simulator import Simulator


def errors(log: dict) -> dict:
    q_true, q_hat, v_true, v_hat = log["q_true"], log["q_hat"], log["v_true"], log["v_hat"]
    velocity = np.sqrt(np.mean(np.sum((v_hat[:, :3] - v_true[:, :3]) ** 2, axis=1)))
    angles = [np.linalg.norm(pin.log3(pin.Quaternion(a[6], *a[3:6]).toRotationMatrix().T
                                      @ pin.Quaternion(b[6], *b[3:6]).toRotationMatrix()))
              for a, b in zip(q_true, q_hat)]
    path = np.sum(np.linalg.norm(np.diff(q_true[:, :2], axis=0), axis=1))
    final = q_hat[-1, :3] - q_true[-1, :3]
    return {"velocity_rms": velocity, "orientation_max": max(angles), "path": path,
            "horizontal_error": np.linalg.norm(final[:2]), "vertical_error": abs(final[2])}


def run(name: str, spec: SensorSpec, seconds: float, seed: int) -> dict:
    robot = wb.load_robot(name)
    estimation = TwinEstimation.for_robot(robot, spec, seed=seed)
    if name == "hyq":
        run_gait(robot, "passive", "trot", VelocityCommand.speed_ramp(0.3, 0.3, 1.0, 2.0),
                 seconds, observers=[estimation])
    else:
        sim = Simulator(robot, observers=[estimation], record=False)
        run_closed_loop(sim, StandingController(robot), seconds)
    return errors(estimation.log.arrays())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    for name in ("talos14", "hyq"):
        for label, spec in (("default sensors", SensorSpec()), ("exact sensors", SensorSpec.exact())):
            e = run(name, spec, args.seconds, args.seed)
            drift = (f"{100 * e['horizontal_error'] / e['path']:.2f} % of {e['path']:.2f} m"
                     if e["path"] > 0.1 else f"{1e3 * e['horizontal_error']:.2f} mm")
            print(f"{name:8s} {label:16s}: velocity RMS {1e3 * e['velocity_rms']:.2f} mm/s, "
                  f"orientation max {1e3 * e['orientation_max']:.2f} mrad, horizontal drift "
                  f"{drift}, height error {1e3 * e['vertical_error']:.1f} mm")


if __name__ == "__main__":
    main()
