"""placo's side of the peer comparison: its DynamicsSolver (one weighted QP, eiquadprog) with the
case's tasks. Runs in placo's own venv (setup.sh):

    $PEERS_DIR/placo-venv/bin/python benchmarks/peers/run_placo.py CASE [--all]

The model is the case's URDF, with the locked joints of the preset made fixed at their posture
angles (cases.reduced_urdf, what Pinocchio's buildReducedModel does), the armature as rotor
inertia, the torque limits of the states file. Per state: the state is set, kinematics updated,
the QP built and solved (``solve(False)``: no integration, the next state is set anyway).
"""

from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import placo  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cases  # noqa: E402


def load(case_name):
    case = cases.CASES[case_name]
    data = dict(np.load(cases.states_path(case_name)))
    urdf = str(data["urdf"])
    locked = dict(zip([str(n) for n in data["locked_names"]], data["locked_angles"]))
    text = cases.reduced_urdf(urdf, locked)
    robot = placo.RobotWrapper(os.path.dirname(urdf), placo.Flags.ignore_collisions, text)
    names = [str(n) for n in data["joint_names"]]
    assert list(robot.joint_names()) == names, (list(robot.joint_names()), names)
    for j, a, t in zip(names, data["armature"], data["tau_max"]):
        robot.set_rotor_inertia(j, float(a))
        robot.set_gear_ratio(j, 1.0)
        robot.set_torque_limit(j, float(t))
    return case, data, robot


def build(case, data, robot):
    mass = float(data["mass"])
    frames = [str(f) for f in data["placement_frames"]]
    pose = {f: data["placements"][i] for i, f in enumerate(frames)}
    solver = placo.DynamicsSolver(robot)
    solver.mask_fbase(False)
    solver.torque_cost = 0.0          # wholebody has no torque cost
    solver.problem.regularization = 1e-6   # wholebody's epsilon
    solver.enable_torque_limits(True)
    solver.enable_velocity_limits(False)
    if case["joint_limits"]:
        solver.dt = cases.JOINT_LIMIT_DT
        solver.enable_joint_limits(True)
    else:
        solver.enable_joint_limits(False)
    described = []
    reg = [t for t in case["tasks"] if t["kind"] == "force_regularizer"][0]
    w_reg = cases.quadratic_weight(reg, mass)
    for c in case["contacts"]:
        f = c["frame"]
        if c["type"] == "point":
            task = solver.add_position_task(f, pose[f][:3, 3])
            task.configure(f, "hard", 1.0)
            task.kp, task.kd = 0.0, 0.0
            contact = solver.add_unilateral_point_contact(task)
            contact.mu = case["mu"]
            contact.weight_forces = w_reg
            described.append(f"{f}: unilateral point contact, friction pyramid mu {case['mu']}")
        else:
            task = solver.add_frame_task(f, pose[f])
            task.configure(f, "hard", 1.0, 1.0)
            for sub in (task.position(), task.orientation()):
                sub.kp, sub.kd = 0.0, 0.0
            contact = solver.add_planar_contact(task)
            shrink = 1.0 - case.get("cop_margin", 0.0)
            hx, hy = c["half_size"]
            contact.length, contact.width = 2 * hx * shrink, 2 * hy * shrink
            contact.mu = case["mu"]
            contact.weight_forces = w_reg
            contact.weight_moments = w_reg / max(hx, hy) ** 2
            described.append(f"{f}: planar contact (CoP in {shrink:g} x sole, pyramid mu "
                             f"{case['mu']}, no yaw-moment bound)")
    for t in case["tasks"]:
        w = cases.quadratic_weight(t, mass)
        if t["kind"] == "com":
            task = solver.add_com_task(data["com_ref"])
            task.configure("com", "soft", w)
            task.kp, task.kd = t["kp"], t["kd"]
        elif t["kind"] == "orientation":
            task = solver.add_orientation_task(t["frame"], pose[t["frame"]][:3, :3])
            task.configure(t["frame"], "soft", w)
            task.kp, task.kd = t["kp"], t["kd"]
        elif t["kind"] == "posture":
            task = solver.add_joints_task()
            names = [str(n) for n in data["joint_names"]]
            q_ref = data["q_ref"]
            task.set_joints({n: float(q_ref[7 + k]) for k, n in enumerate(names)})
            task.configure("posture", "soft", w)
            task.kp, task.kd = t["kp"], t["kd"]
            if t["base"]:
                base = str(data["base_frame"])
                btask = solver.add_frame_task(base, pose[base])
                btask.configure("posture base", "soft", w, w)
                for sub in (btask.position(), btask.orientation()):
                    sub.kp, sub.kd = t["kp"], t["kd"]
        elif t["kind"] == "angular_momentum":
            described.append("angular momentum: no such task in placo's DynamicsSolver (omitted)")
            continue
        elif t["kind"] == "force_regularizer":
            continue  # on the contacts (weight_forces)
    extra = ["torque limits"] + (["joint limits (qdd bounds, dt %g)" % cases.JOINT_LIMIT_DT]
                                 if case["joint_limits"] else [])
    return solver, described + extra


def main():
    case_name = sys.argv[1]
    case, data, robot = load(case_name)
    # the model matches wholebody's: mass matrix at the reference posture
    robot.state.q = data["q_ref"].copy()
    robot.state.qd = np.zeros(robot.model.nv)
    robot.update_kinematics()
    dM = np.abs(robot.mass_matrix() - data["M_ref"]).max()
    solver, described = build(case, data, robot)
    solved = ("weighted QP: hard [dynamics, " + ", ".join(described) + "] + soft ["
              + cases.describe(case) + f"]; pinocchio {pin.__version__}, |M - M_wholebody| {dM:.0e}")
    print(f"# placo: {solved}", file=sys.stderr)
    Q, V = data["q"], data["v"]
    model = robot.model
    pdata = model.createData()

    def solve_one(i):
        t0 = time.perf_counter()
        robot.state.q = Q[i]
        robot.state.qd = V[i]
        robot.update_kinematics()
        res = solver.solve(False)
        tau = res.tau[6:]
        dt = time.perf_counter() - t0
        return dt, np.array(tau), np.array(res.qdd), bool(res.success)

    def acceleration_of_com(i, qdd):
        pin.centerOfMass(model, pdata, Q[i], V[i], qdd)
        return pdata.acom[0].copy()

    cases.serve(solve_one, acceleration_of_com, len(Q), solved)


if __name__ == "__main__":
    main()
