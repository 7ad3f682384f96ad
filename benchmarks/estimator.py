"""Per-cycle time of the kinematic-inertial EKF (``wholebody.estimation``; target: median <= 50 µs).

Sensor readings are recorded at 1 kHz from closed-loop runs in the twin (hyq trotting under the
passive WBC, talos14 standing under the standing controller), then replayed through a fresh filter:
one cycle = forward kinematics of the measured joints + IMU prediction + kinematic update + the
estimate in Pinocchio's conventions. A benchmark, not a test.

    OPENBLAS_NUM_THREADS=1 python benchmarks/estimator.py [--seconds 2] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time  # noqa: E402

import numpy as np  # noqa: E402

import wholebody as wb  # noqa: E402
from wholebody.control.standing import StandingController  # noqa: E402
from wholebody.estimation import EstimatorNoise, KinematicInertialEKF  # noqa: E402
from wholebody.planning.trunk import VelocityCommand  # noqa: E402
from wholebody.scenarios.locomotion import run_gait  # noqa: E402
from wholebody.scenarios.loop import run_closed_loop  # noqa: E402
from wholebody.sim.sensors import Sensors, SensorSpec  # noqa: E402
from wholebody.sim.simulator import Simulator  # noqa: E402


class Recorder:
    """A simulator observer keeping every step's sensor readings."""

    def __init__(self, robot):
        self.sensors = Sensors(robot, SensorSpec(), np.random.default_rng(0))
        self.readings = []

    def start(self, sim):
        self.readings = [self.sensors.read(sim)]

    def step(self, sim):
        if sim.t > self.readings[-1].t:
            self.readings.append(self.sensors.read(sim))

    def controller_result(self, sim, result):
        pass


def record(name: str, seconds: float):
    robot = wb.load_robot(name)
    recorder = Recorder(robot)
    if name == "hyq":
        run_gait(robot, "passive", "trot", VelocityCommand.speed_ramp(0.3, 0.3, 1.0, 2.0),
                 seconds, observers=[recorder])
    else:
        sim = Simulator(robot, observers=[recorder], record=False)
        run_closed_loop(sim, StandingController(robot), seconds)
    return robot, recorder.readings


def time_cycles(robot, readings) -> np.ndarray:
    ekf = KinematicInertialEKF(robot, EstimatorNoise.for_sensors(SensorSpec()))
    ekf.reset(readings[0], np.zeros(3))
    times = np.empty(len(readings) - 1)
    for i, reading in enumerate(readings[1:]):
        start = time.perf_counter()
        ekf.update(reading)
        times[i] = time.perf_counter() - start
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated seconds recorded")
    parser.add_argument("--repeat", type=int, default=3, help="replays; the fastest median kept")
    args = parser.parse_args()
    for name in ("hyq", "talos14"):
        robot, readings = record(name, args.seconds)
        runs = [time_cycles(robot, readings) for _ in range(args.repeat)]
        best = min(runs, key=np.median)
        print(f"{name:8s} ({len(robot.contact_names)} contacts, state {15 + 3 * len(robot.contact_names)}):"
              f" {len(best)} cycles, median {np.median(best) * 1e6:6.1f} µs, "
              f"p99 {np.percentile(best, 99) * 1e6:6.1f} µs")


if __name__ == "__main__":
    main()
