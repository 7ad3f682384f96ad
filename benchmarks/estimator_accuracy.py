"""Accuracy of the kinematic-inertial EKF run open-loop beside closed-loop runs in the twin that
read the exact state. A measurement, not a test.

Default: talos14 standing (standing controller) and hyq trotting at 0.3 m/s after 1 s of standing
(passive WBC), ``--seconds`` each, with default sensors (``SensorSpec()``) and exact ones.
``--distance D``: every quadruped preset trotting D m (0.3 m/s on HyQ, Froude-scaled on the
others), HyQ crawling D m (the crawl's default speed), every humanoid preset standing D s and
walking D m (``control.Walking`` at 0.4 m/s on talos14, Froude-scaled on the others, ramped in
over 1 s); default sensors (``--exact`` adds exact ones). The orientation error is split into
tilt (roll and pitch, which gravity observes) and heading (yaw, which only the stance feet's
anchors hold). ``--rest-update``: the filter with its zero angular-rate update (off by default);
``--gyro-bias-walk``: the default sensors with that gyro bias random walk (rad/s per sqrt(s));
``--noise NAME=VALUE``: a term of the filter's ``EstimatorNoise`` (repeatable).

    python benchmarks/estimator_accuracy.py [--seconds 5] [--seed 1]
    python benchmarks/estimator_accuracy.py --distance 10 [--robots hyq go1 ...] [--exact]
        [--rest-update] [--gyro-bias-walk W] [--noise kinematics_noise=0.001 ...]
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import fields

import numpy as np
import pinocchio as pin

import wholebody as wb
from wholebody.control import Walking
from wholebody.control.standing import StandingController
from wholebody.estimation import EstimatorNoise, TwinEstimation
from wholebody.planning.trunk import VelocityCommand
from wholebody.robots.reference import froude_ratio, humanoid_length_ratio
from wholebody.scenarios.locomotion import CRAWL_SPEED, run_gait
from wholebody.scenarios.loop import run_closed_loop
from wholebody.scenarios.walking_runs import simulate
from wholebody.sim.sensors import SensorSpec
from wholebody.sim.simulator import Simulator

QUADRUPEDS = ("hyq", "go1", "go2", "a1", "anymal_c", "solo12")
HUMANOIDS = ("talos14", "talos", "romeo")
TROT_SPEED_ON_HYQ = 0.3  # m/s
WALK_SPEED = 0.4  # m/s, the walk scenario's on talos14; another humanoid's times sqrt(h / h_talos14)
GAIT_START = 1.0  # s of standing before the gait


def _rotation(q: np.ndarray) -> np.ndarray:
    return pin.Quaternion(q[6], *q[3:6]).toRotationMatrix()


def errors(log: dict) -> dict:
    q_true, q_hat, v_true, v_hat = log["q_true"], log["q_hat"], log["v_true"], log["v_hat"]
    velocity = np.sqrt(np.mean(np.sum((v_hat[:, :3] - v_true[:, :3]) ** 2, axis=1)))
    angles, tilts, headings = [], [], []
    for a, b in zip(q_true, q_hat):
        Ra, Rb = _rotation(a), _rotation(b)
        angles.append(np.linalg.norm(pin.log3(Ra.T @ Rb)))
        tilts.append(math.acos(min(1.0, Ra[2] @ Rb[2])))  # the base's vertical, world axes
        headings.append(abs(pin.rpy.matrixToRpy(Ra.T @ Rb)[2]))
    path = np.sum(np.linalg.norm(np.diff(q_true[:, :2], axis=0), axis=1))  # with the sway
    distance = np.linalg.norm(q_true[-1, :2] - q_true[0, :2])  # from start to end
    final = q_hat[-1, :3] - q_true[-1, :3]
    return {"velocity_rms": velocity, "orientation_max": max(angles), "tilt_max": max(tilts),
            "heading_max": max(headings), "heading_end": headings[-1], "path": path,
            "distance": distance, "horizontal_error": np.linalg.norm(final[:2]),
            "vertical_error": abs(final[2]), "position_error": np.linalg.norm(final),
            "duration": log["t"][-1]}


def run(name: str, spec: SensorSpec, seconds: float, seed: int, gait: str | None = "trot",
        speed: float = TROT_SPEED_ON_HYQ, rest_update: bool = False, noise=None) -> dict:
    """The filter beside ``name`` walking ``gait`` at ``speed`` (m/s, from GAIT_START on) under
    the passive WBC (a quadruped) or ``control.Walking`` (``gait`` "walk"), or standing (``gait``
    None) under the standing controller, ``seconds``."""
    robot = wb.load_robot(name)
    estimation = TwinEstimation.for_robot(robot, spec, seed=seed, rest_update=rest_update,
                                          **(noise or {}))
    fell = False
    if gait == "walk":
        def command(t):
            return np.array([speed * min(max(t - GAIT_START, 0.0), 1.0), 0.0, 0.0])

        fell = simulate(robot, Walking(robot), seconds, command=command,
                        observers=[estimation]).fallen
    elif gait is not None:
        gait_run = run_gait(robot, "passive", gait,
                            VelocityCommand.speed_ramp(speed, speed, GAIT_START, GAIT_START + 1.0),
                            seconds, observers=[estimation])
        fell = gait_run.fell
    else:
        sim = Simulator(robot, observers=[estimation], record=False)
        run_closed_loop(sim, StandingController(robot), seconds)
    return {**errors(estimation.log.arrays()), "fell": fell}


def line(label: str, e: dict) -> str:
    if e["distance"] > 0.1:
        drift = (f"{100 * e['horizontal_error'] / e['distance']:.2f} % (3D "
                 f"{100 * e['position_error'] / e['distance']:.2f} %) of {e['distance']:.2f} m "
                 f"(path {e['path']:.2f} m)")
    else:
        drift = f"{1e3 * e['horizontal_error']:.2f} mm"
    return (f"{label}: {e['duration']:.1f} s, velocity RMS {1e3 * e['velocity_rms']:.2f} mm/s, "
            f"orientation max {1e3 * e['orientation_max']:.2f} mrad (tilt "
            f"{1e3 * e['tilt_max']:.2f}, heading {1e3 * e['heading_max']:.2f}, at the end "
            f"{1e3 * e['heading_end']:.2f}), horizontal drift {drift}, height error "
            f"{1e3 * e['vertical_error']:.1f} mm{', FELL' if e['fell'] else ''}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--distance", type=float, default=None,
                        help="walk this many metres (talos14 stands this many seconds)")
    parser.add_argument("--robots", nargs="+", default=None,
                        help="with --distance: these presets only (default: hyq crawl, every "
                             "quadruped's trot, every humanoid standing and walking)")
    parser.add_argument("--exact", action="store_true", help="with --distance: exact sensors too")
    parser.add_argument("--rest-update", action="store_true",
                        help="the filter with its zero angular-rate update at rest")
    parser.add_argument("--gyro-bias-walk", type=float, default=None, metavar="W",
                        help="the default sensors' gyro bias random walk (rad/s per sqrt(s))")
    parser.add_argument("--noise", action="append", default=[], metavar="NAME=VALUE",
                        help="a term of the filter's EstimatorNoise (repeatable)")
    args = parser.parse_args()
    rest = args.rest_update
    noise = {}
    terms = {f.name for f in fields(EstimatorNoise)} - {"rest_update"}
    for item in args.noise:
        name, _, value = item.partition("=")
        try:
            noise[name] = float(value)
        except ValueError:
            parser.error(f"--noise {item!r}: expected NAME=NUMBER")
        if name not in terms:
            parser.error(f"--noise {item!r}: NAME is one of {', '.join(sorted(terms))}")
    try:
        EstimatorNoise(**noise)
    except ValueError as exc:
        parser.error(f"--noise: {exc}")
    default = SensorSpec()
    if args.gyro_bias_walk is not None:
        if not (math.isfinite(args.gyro_bias_walk) and args.gyro_bias_walk >= 0):
            parser.error(f"--gyro-bias-walk must be a finite number >= 0, got "
                         f"{args.gyro_bias_walk}")
        default = SensorSpec(gyro_bias_walk=args.gyro_bias_walk)
    if args.distance is None:
        for name in ("talos14", "hyq"):
            for label, spec in (("default sensors", default),
                                ("exact sensors", SensorSpec.exact())):
                e = run(name, spec, args.seconds, args.seed, None if name == "talos14" else "trot",
                        rest_update=rest, noise=noise)
                print(line(f"{name:8s} {label:16s}", e), flush=True)
        return
    if not (math.isfinite(args.distance) and args.distance > 0):
        parser.error(f"--distance must be a finite number > 0, got {args.distance}")
    specs = [("default sensors", default)]
    if args.exact:
        specs.append(("exact sensors", SensorSpec.exact()))
    runs = [("hyq", "crawl", CRAWL_SPEED.default.value(wb.load_robot("hyq")))]
    runs += [(name, "trot", TROT_SPEED_ON_HYQ * froude_ratio(wb.load_robot(name)))
             for name in QUADRUPEDS]
    for name in HUMANOIDS:
        speed = WALK_SPEED * math.sqrt(humanoid_length_ratio(wb.load_robot(name)))
        runs += [(name, None, 0.0), (name, "walk", speed)]
    if args.robots:
        runs = [r for r in runs if r[0] in args.robots]
    for name, gait, speed in runs:
        # the commanded time for the distance, and 10 % for the gait's own start
        seconds = args.distance if gait is None else GAIT_START + 1.1 * args.distance / speed
        if gait == "walk":
            seconds += 0.5  # the ramp
        for label, spec in specs:
            start = time.perf_counter()
            e = run(name, spec, seconds, args.seed, gait, speed, rest, noise)
            what = "standing" if gait is None else f"{gait} {speed:.3f} m/s"
            print(line(f"{name:8s} {what:16s} {label:16s}", e)
                  + f" [{time.perf_counter() - start:.0f} s wall]", flush=True)


if __name__ == "__main__":
    main()
