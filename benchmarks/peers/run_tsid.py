"""TSID's side of the peer comparison: InverseDynamicsFormulationAccForce + SolverHQuadProgFast
(constraints at priority 0, weighted tasks at priority 1: one weighted QP) with the case's tasks.
Runs in TSID's own venv (setup.sh):

    $PEERS_DIR/tsid-venv/bin/python benchmarks/peers/run_tsid.py CASE [--all]

The model is the case's URDF reduced with Pinocchio's buildReducedModel (joints locked at the
posture angles of the states file), with the armature and the torque limits of the states file.
Per state: computeProblemData(t, q, v) (robot terms, task and contact rows), solve, torques.
"""

from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import tsid  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cases  # noqa: E402


def load(case_name):
    case = cases.CASES[case_name]
    data = dict(np.load(cases.states_path(case_name)))
    model = pin.buildModelFromUrdf(str(data["urdf"]), pin.JointModelFreeFlyer())
    locked = [str(n) for n in data["locked_names"]]
    if locked:
        q_full = pin.neutral(model)
        for name, angle in zip(locked, data["locked_angles"]):
            q_full[model.joints[model.getJointId(name)].idx_q] = angle
        model = pin.buildReducedModel(model, [model.getJointId(n) for n in locked], q_full)
    names = [str(n) for n in data["joint_names"]]
    assert list(model.names)[2:] == names, (list(model.names)[2:], names)
    model.armature[6:] = data["armature"]
    robot = tsid.RobotWrapper(model, tsid.RootJointType.FLOATING_BASE_SYSTEM, False)
    return case, data, model, robot


def build(case, data, model, robot):
    mass = float(data["mass"])
    na, nv = model.nv - 6, model.nv
    frames = [str(f) for f in data["placement_frames"]]
    pose = {f: pin.SE3(data["placements"][i]) for i, f in enumerate(frames)}
    inv = tsid.InverseDynamicsFormulationAccForce("tsid", robot, False)
    inv.computeProblemData(0.0, data["q_ref"], np.zeros(nv))
    keep = []  # the Python objects TSID refers to
    described = []
    reg = [t for t in case["tasks"] if t["kind"] == "force_regularizer"][0]
    w_reg = cases.quadratic_weight(reg, mass)
    normal = np.array([0.0, 0.0, 1.0])
    for c in case["contacts"]:
        f = c["frame"]
        if c["type"] == "point":
            contact = tsid.ContactPoint(f, robot, f, normal, case["mu"], 0.0, 1e4)
            contact.useLocalFrame(False)
            contact.setRegularizationTaskWeightVector(np.ones(3))
            described.append(f"{f}: ContactPoint (4-facet cone mu {case['mu']})")
        else:
            shrink = 1.0 - case.get("cop_margin", 0.0)
            hx, hy = c["half_size"]
            hx, hy = hx * shrink, hy * shrink
            corners = np.array([[hx, hx, -hx, -hx], [hy, -hy, hy, -hy], [0.0, 0.0, 0.0, 0.0]])
            contact = tsid.Contact6d(f, robot, f, corners, normal, case["mu"], 0.0, 1e4)
            # the regulariser acts on the sole's wrench (row scales; TSID's default 1e-3 on the
            # normal force), scaled as wholebody's: 1 on forces, 1 / largest half-size on moments
            h = max(c["half_size"])
            contact.setRegularizationTaskWeightVector(np.array([1, 1, 1, 1 / h, 1 / h, 1 / h]))
            described.append(f"{f}: Contact6d (4 corner forces at {shrink:g} x sole, 4-facet "
                             f"cones mu {case['mu']})")
        contact.setKp(np.zeros(contact.n_motion))
        contact.setKd(np.zeros(contact.n_motion))
        contact.setReference(pose[f])
        inv.addRigidContact(contact, w_reg, 1.0, 0)  # motion as a constraint (priority 0)
        keep.append(contact)
    for t in case["tasks"]:
        w = cases.quadratic_weight(t, mass)
        if t["kind"] == "com":
            task = tsid.TaskComEquality("com", robot)
            task.setKp(t["kp"] * np.ones(3))
            task.setKd(t["kd"] * np.ones(3))
            sample = tsid.TrajectorySample(3)
            sample.value(data["com_ref"])
            sample.derivative(np.zeros(3))
            sample.second_derivative(np.zeros(3))
            task.setReference(sample)
            inv.addMotionTask(task, w, 1, 0.0)
            keep += [task, sample]
        elif t["kind"] == "orientation":
            task = tsid.TaskSE3Equality(t["frame"], robot, t["frame"])
            task.setKp(t["kp"] * np.ones(6))
            task.setKd(t["kd"] * np.ones(6))
            task.setMask(np.array([0, 0, 0, 1, 1, 1.0]))
            task.useLocalFrame(False)
            traj = tsid.TrajectorySE3Constant(t["frame"], pose[t["frame"]])
            task.setReference(traj.computeNext())
            inv.addMotionTask(task, w, 1, 0.0)
            keep += [task, traj]
        elif t["kind"] == "posture":
            task = tsid.TaskJointPosture("posture", robot)
            task.setKp(t["kp"] * np.ones(na))
            task.setKd(t["kd"] * np.ones(na))
            traj = tsid.TrajectoryEuclidianConstant("posture", data["q_ref"][7:])
            task.setReference(traj.computeNext())
            inv.addMotionTask(task, w, 1, 0.0)
            keep += [task, traj]
            if t["base"]:
                base = str(data["base_frame"])
                btask = tsid.TaskSE3Equality("posture base", robot, base)
                btask.setKp(t["kp"] * np.ones(6))
                btask.setKd(t["kd"] * np.ones(6))
                btraj = tsid.TrajectorySE3Constant("posture base", pose[base])
                btask.setReference(btraj.computeNext())
                inv.addMotionTask(btask, w, 1, 0.0)
                keep += [btask, btraj]
        elif t["kind"] == "angular_momentum":
            task = tsid.TaskAMEquality("angular momentum", robot)
            task.setKp(np.zeros(3))
            task.setKd(t["kd"] * np.ones(3))
            sample = tsid.TrajectorySample(3)
            task.setReference(sample)
            inv.addMotionTask(task, w, 1, 0.0)
            keep += [task, sample]
    bounds = tsid.TaskActuationBounds("torque limits", robot)
    bounds.setBounds(-data["tau_max"], data["tau_max"])
    inv.addActuationTask(bounds, 1.0, 0, 0.0)
    keep.append(bounds)
    extra = ["torque limits"]
    if case["joint_limits"]:
        limits = tsid.TaskJointPosVelAccBounds("joint limits", robot, cases.JOINT_LIMIT_DT, False)
        limits.setPositionBounds(data["q_min"], data["q_max"])
        limits.setVelocityBounds(1e3 * np.ones(na))
        limits.setAccelerationBounds(1e4 * np.ones(na))
        limits.setImposeBounds(True, False, False, False)
        inv.addMotionTask(limits, 1.0, 0, 0.0)
        keep.append(limits)
        extra.append(f"joint limits (qdd bounds, dt {cases.JOINT_LIMIT_DT:g})")
    solver = tsid.SolverHQuadProgFast("qp")
    solver.resize(inv.nVar, inv.nEq, inv.nIn)
    return inv, solver, keep, described + extra


def main():
    case_name = sys.argv[1]
    case, data, model, robot = load(case_name)
    inv, solver, keep, described = build(case, data, model, robot)
    rdata = inv.data()
    robot.computeAllTerms(rdata, data["q_ref"], np.zeros(model.nv))
    M = robot.mass(rdata)
    dM = np.abs(np.triu(M) + np.triu(M, 1).T - data["M_ref"]).max()
    solved = ("HQP: priority 0 [dynamics, " + ", ".join(described) + "] + priority 1 ["
              + cases.describe(case) + f"]; pinocchio {pin.__version__}, |M - M_wholebody| {dM:.0e}")
    print(f"# tsid: {solved}", file=sys.stderr)
    Q, V = data["q"], data["v"]
    pdata = model.createData()

    def solve_one(i):
        t0 = time.perf_counter()
        hqp = inv.computeProblemData(0.0, Q[i], V[i])
        sol = solver.solve(hqp)
        tau = inv.getActuatorForces(sol)
        qdd = inv.getAccelerations(sol)
        dt = time.perf_counter() - t0
        return dt, np.array(tau), np.array(qdd), sol.status == 0

    def acceleration_of_com(i, qdd):
        pin.centerOfMass(model, pdata, Q[i], V[i], qdd)
        return pdata.acom[0].copy()

    cases.serve(solve_one, acceleration_of_com, len(Q), solved)


if __name__ == "__main__":
    main()
