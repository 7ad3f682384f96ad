"""Ten steps forward on every humanoid we have, on the walking controller's defaults: which walk,
how far, and the controller's time per cycle. Prints the table of docs/results.md ("Walking and
stepping").

Each robot: :class:`~wholebody.control.Walking` with ``WalkingConfig.for_robot`` in the MuJoCo twin
(one deterministic run); standing 0.5 s, then forward at 0.4 m/s x sqrt(h / h_talos14) (the
speed ramped in over 1 s) until ten steps have touched down, then a zero command and 3 s to stop
(40 s at most). Fallen: :func:`~wholebody.scenarios.measures.fallen`. The robots: the presets
talos14, talos, romeo and G1, iCub, Alexander as docs/robots.md describes them (the descriptions
of tests/conftest.py). Times per cycle are the controller's wall time (native engine when built):
run with ``OPENBLAS_NUM_THREADS=1`` on an otherwise idle machine and ``--jobs 1`` for timings worth
quoting.

    OPENBLAS_NUM_THREADS=1 python benchmarks/walking.py [--jobs 2] [--robots talos14,g1]
"""

from __future__ import annotations

import argparse
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

import wholebody as wb
from wholebody.control import Walking
from wholebody.robots.reference import humanoid_length_ratio
from wholebody.scenarios.walking_runs import simulate, timing_ms, torque_steps

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from conftest import (ICUB_RIGHT_LEG_INERTIAS, alexander_description,  # noqa: E402
                      g1_description, icub_description)

ROBOTS = {"talos14": "talos14", "talos": "talos", "romeo": "romeo",
          "g1": lambda: g1_description(armature=0.02),
          "icub": lambda: icub_description(inertia_overrides=ICUB_RIGHT_LEG_INERTIAS),
          "alexander": alexander_description}
STEPS, SETTLE, LONGEST = 10, 3.0, 40.0


def walk(name: str) -> dict:
    source = ROBOTS[name]
    robot = wb.load_robot(source() if callable(source) else source)
    speed = 0.4 * math.sqrt(humanoid_length_ratio(robot))
    ctrl = Walking(robot)
    stop = {"at": None, "now": 0.0}

    def landed() -> int:
        return sum(1 for s in ctrl.steps if np.isfinite(s.touchdown))

    def command(t: float):
        stop["now"] = t
        if stop["at"] is None and landed() >= STEPS:
            stop["at"] = t
        if t < 0.5 or stop["at"] is not None:
            return (0.0, 0.0, 0.0)
        return (min(1.0, t - 0.5) * speed, 0.0, 0.0)

    run = simulate(robot, ctrl, LONGEST, command=command,
                   until=lambda: stop["at"] is not None and stop["now"] > stop["at"] + SETTLE)
    base = run.a["base_position"]
    k = len(base) - 1
    first = next((s.lift_off for s in ctrl.steps), None)
    distance = float(base[k, 0] - base[0, 0])
    moving = (stop["at"] - first) if stop["at"] is not None and first is not None else None
    _, at_switch = torque_steps(run)
    cycle = timing_ms(ctrl.cycle_times)
    return {"robot": name, "mass_kg": round(robot.mass, 1), "command_mps": round(speed, 3),
            "fell_at_s": run.fell_at, "steps": landed(), "distance_m": round(distance, 3),
            "speed_mps": round(distance / moving, 3) if moving else None,
            "failed_cycles": run.failed_cycles,
            "standing_at_end": ctrl.phase.kind == "stand" and not run.fallen,
            "torque_step_at_switch_Nm": round(at_switch or 0.0, 1),
            "step_limit_m": round(ctrl.limits.forward, 3),
            "cycle_median_ms": round(cycle["median_ms"], 3),
            "cycle_p99_ms": round(cycle["p99_ms"], 3)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--robots", default=",".join(ROBOTS))
    args = parser.parse_args()
    names = [n.strip() for n in args.robots.split(",") if n.strip()]
    unknown = sorted(set(names) - set(ROBOTS))
    if unknown:
        parser.error(f"--robots: unknown {unknown}; known: {', '.join(ROBOTS)}")
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(walk, names))
    print("| robot | command | walks 10 steps | distance, speed | failed cycles | stands at the end "
          "| largest torque step at a switch | step limit | cycle median / p99 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        walked = r["steps"] >= STEPS and r["fell_at_s"] is None
        fell = "" if r["fell_at_s"] is None else f"falls at {r['fell_at_s']:.2f} s after "
        print(f"| {r['robot']} ({r['mass_kg']} kg) | {r['command_mps']} m/s | "
              f"{'yes' if walked else 'no: ' + fell + str(r['steps']) + ' steps'} | "
              f"{r['distance_m']} m, {r['speed_mps']} m/s | {r['failed_cycles']} | "
              f"{'yes' if r['standing_at_end'] else 'no'} | {r['torque_step_at_switch_Nm']} Nm | "
              f"{r['step_limit_m']} m | {r['cycle_median_ms']} / {r['cycle_p99_ms']} ms |")


if __name__ == "__main__":
    main()
