"""Per-cycle time of the kinematic-inertial EKF (``wholebody.estimation``; target: median <= 50 µs).

Sensor readings are recorded at 1 kHz from closed-loop runs in the twin (hyq trotting under the
passive WBC, talos14 standing under the standing controller), then replayed through a fresh filter:
one cycle = forward kinematics of the measured joints + the rest test + IMU prediction + kinematic
update (+ the rest update) + the estimate in Pinocchio's conventions, with the filter's default
engine (the compiled ``wholebody._estimator`` where it is built). A benchmark, not a test.

``--python``: the Python engine (the reference) too, on the same readings, cycle by cycle
alternating with the default one.

``--against REV``: the estimator as it was at git revision REV (``estimation/ekf.py`` and
``kinematics.py`` read with ``git show``) timed on the same readings, cycle by cycle alternating
with the current one, so that both see the same load on a shared machine.

    OPENBLAS_NUM_THREADS=1 python benchmarks/estimator.py [--seconds 2] [--repeat 3] [--python]
        [--against REV]
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import importlib  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

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


def estimator_at(revision: str, folder: Path):
    """The ``wholebody.estimation`` filter class as at git ``revision``, loaded as a package
    ``estimation_at_revision`` beside the current one (its ``..`` imports point to wholebody)."""
    root = Path(__file__).resolve().parent.parent
    package = folder / "estimation_at_revision"
    package.mkdir()
    for name in ("ekf.py", "kinematics.py"):
        text = subprocess.run(["git", "show", f"{revision}:src/wholebody/estimation/{name}"],
                              cwd=root, check=True, capture_output=True, text=True).stdout
        (package / name).write_text(text.replace("from ..", "from wholebody."))
    (package / "__init__.py").write_text("")
    sys.path.insert(0, str(folder))
    module = importlib.import_module("estimation_at_revision.ekf")
    return module.KinematicInertialEKF, module.EstimatorNoise


def time_cycles(robot, readings, filters) -> list[np.ndarray]:
    """Per-cycle times of each of ``filters`` (functions of the robot making a filter) on
    ``readings``, the filters taking turns at every reading."""
    ekfs = [make(robot) for make in filters]
    for ekf in ekfs:
        ekf.reset(readings[0], np.zeros(3))
    times = np.empty((len(ekfs), len(readings) - 1))
    for i, reading in enumerate(readings[1:]):
        for k, ekf in enumerate(ekfs):
            start = time.perf_counter()
            ekf.update(reading)
            times[k, i] = time.perf_counter() - start
    return list(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated seconds recorded")
    parser.add_argument("--repeat", type=int, default=3,
                        help="replays; the median of their medians is reported")
    parser.add_argument("--python", action="store_true",
                        help="also time the Python engine, interleaved")
    parser.add_argument("--against", default=None, metavar="REV",
                        help="also time the estimator of git revision REV, interleaved")
    args = parser.parse_args()

    def current(**options):
        return lambda robot: KinematicInertialEKF(
            robot, EstimatorNoise.for_sensors(SensorSpec()), **options)

    default_engine = KinematicInertialEKF(wb.load_robot("hyq")).engine
    filters = [(default_engine, current())]
    if args.python:
        filters.append(("python", current(engine="python")))
    with tempfile.TemporaryDirectory() as folder:
        if args.against:
            cls, noise = estimator_at(args.against, Path(folder))
            filters.append((args.against,
                            lambda robot: cls(robot, noise.for_sensors(SensorSpec()))))
        for name in ("hyq", "talos14"):
            robot, readings = record(name, args.seconds)
            runs = [time_cycles(robot, readings, [f for _, f in filters])
                    for _ in range(args.repeat)]
            for k, (label, _) in enumerate(filters):
                medians = [np.median(run[k]) * 1e6 for run in runs]
                p99 = np.median([np.percentile(run[k], 99) * 1e6 for run in runs])
                print(f"{name:8s} ({len(robot.contact_names)} contacts, state "
                      f"{current()(robot).size}) {label:10s}: {len(runs[0][k])} "
                      f"cycles, median {np.median(medians):6.1f} µs (runs "
                      f"{', '.join(f'{m:.1f}' for m in medians)}), p99 {p99:6.1f} µs",
                      flush=True)


if __name__ == "__main__":
    main()
