"""wholebody's side of the peer comparison: one HierarchyCycle (engine "native") per case.

    PYTHONPATH=src python benchmarks/peers/run_wholebody.py CASE VARIANT [--all]

VARIANT: "cascade" (the strict stack of the case: Table 2 for talos14, Table 1 for talos),
"weighted" (one hard level — dynamics, torque limits, contacts, friction/CoP, joint-acceleration
limits — and one weighted objective, method "weighted": one QP) or "2level" (the same two levels
solved by the compiled cascade: the hard level, then the objective in its solution set — the
weighted variant's solution whenever the hard level is feasible). Reads $PEERS_DIR/states/CASE.npz; see cases.serve for the
protocol on stdin.
"""

from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cases  # noqa: E402
import wholebody as wb  # noqa: E402
from wholebody.control.stacks import table1_stack, table2_stack  # noqa: E402
from wholebody.cycle import HierarchyCycle  # noqa: E402
from wholebody.formulation import Stack  # noqa: E402
from wholebody.solvers import SolverSettings  # noqa: E402
from wholebody.tasks import (CoMTask, ContactConstraint, ForceRegularizer, FrameTask,  # noqa: E402
                             FrictionCone, NewtonEuler, PostureTask, TorqueLimits)


def hyq_stack(robot, case, data):
    t = {task["kind"]: task for task in case["tasks"]}
    com = CoMTask(kp=t["com"]["kp"], kd=t["com"]["kd"], name="com", weight=t["com"]["weight"])
    com.position = data["com_ref"].copy()
    o = t["orientation"]
    trunk = FrameTask(o["frame"], kp=o["kp"], kd=o["kd"], name="trunk", weight=o["weight"],
                      mask="orientation")
    frames = list(data["placement_frames"])
    pose = data["placements"][frames.index(o["frame"])]
    trunk.position, trunk.rotation = pose[:3, 3].copy(), pose[:3, :3].copy()
    p = t["posture"]
    return Stack([
        [NewtonEuler(name="newton-euler"), TorqueLimits(name="torque limits"),
         ContactConstraint(name="contacts"), FrictionCone(case["mu"], name="friction")],
        [com, trunk, PostureTask(kp=p["kp"], kd=p["kd"], name="posture", weight=p["weight"]),
         ForceRegularizer(name="force regularizer", weight=t["force_regularizer"]["weight"])],
    ])


def build(case_name: str, variant: str, robot, data):
    case = cases.CASES[case_name]
    if case_name == "hyq":
        return hyq_stack(robot, case, data), "cascade" if variant == "2level" else "weighted"
    if case_name == "talos14":
        stack = table2_stack(robot)
        stack.find("momentum").com_ref = data["com_ref"].copy()
    else:
        stack = table1_stack(robot, robot.contact_names)
        stack.find("com").position = data["com_ref"].copy()
    if variant == "cascade":
        return stack, "cascade"
    # one hard level (the stack's levels 1-2) and one weighted objective (the rest), with the
    # case's weights (Table 2's level 3 keeps its own)
    if case_name == "talos":
        w = {t["kind"]: t["weight"] for t in case["tasks"]}
        stack.find("com").weight = w["com"]
        stack.find("posture").weight = w["posture"]
        stack.find("force regularizer").weight = w["force_regularizer"]
    return Stack([stack.levels[0] + stack.levels[1],
                  [t for level in stack.levels[2:] for t in level]]), \
        "cascade" if variant == "2level" else "weighted"


def describe(stack: Stack, method: str) -> list[str]:
    return [f"{method} (native engine): " + " > ".join(
        "[" + ", ".join(t.name for t in level) + "]" for level in stack.levels)]


def main():
    case_name, variant = sys.argv[1], sys.argv[2]
    data = dict(np.load(cases.states_path(case_name)))
    robot = wb.load_robot(cases.CASES[case_name]["preset"])
    assert list(robot.joint_names) == list(data["joint_names"])
    stack, method = build(case_name, variant, robot, data)
    cycle = HierarchyCycle(robot, stack, engine="native", settings=SolverSettings(method=method))
    Q, V = data["q"], data["v"]
    model, pdata = robot.model, robot.model.createData()
    solved = describe(stack, method)[0]
    print(f"# wholebody {variant}: {solved}", file=sys.stderr)

    def solve_one(i):
        t0 = time.perf_counter()
        sol = cycle.solve(Q[i], V[i])
        dt = time.perf_counter() - t0
        return dt, sol.tau.copy(), sol.qdd.copy(), bool(sol.ok)

    def acceleration_of_com(i, qdd):
        pin.centerOfMass(model, pdata, Q[i], V[i], qdd)
        return pdata.acom[0].copy()

    cases.serve(solve_one, acceleration_of_com, len(Q), solved)


if __name__ == "__main__":
    main()
