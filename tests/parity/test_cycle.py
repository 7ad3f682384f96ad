"""HierarchyCycle (src/wholebody/cycle.py + native/hierarchy_cycle.cpp): the compiled rigid-body terms
and task rows against the Python reference — ``robot.update(q, v)`` + ``Formulation.levels`` — row
for row on random states, for the stacks of Tables 1, 2 and 4 and for every compiled task kind;
the torques of both engines against each other and against the equations of motion built with
Pinocchio directly; parameter changes between cycles, contact switching, boundary errors, failed
solves and the per-task diagnostics.

The native engine keeps its first-use references (MomentumPD.com_ref, CoMTask.position, FrameTask
pose, ContactConstraint anchors, JointTrajectoryTask.position) on the task objects as the Python
tasks do, so each engine gets its own, identically built stack; the references are compared too.
"""

import copy

import numpy as np
import pinocchio as pin
import pytest
from conftest import torque_tolerance

from wholebody.control.stacks import table1_stack, table2_stack, table4_stack
from wholebody.cycle import HierarchyCycle, kernel_tasks, native_available, python_tasks
from wholebody.formulation import Formulation, Stack
from wholebody.solvers import SolverSettings
from wholebody.tasks import (CenterOfPressure, CoMTask, ContactConstraint, ForceRegularizer,
                             FrameTask, FrictionCone, FullDynamics, JointAccelerationLimits,
                             JointTrajectoryTask, MomentumForce, MomentumPD, NewtonEuler,
                             NormalForceBounds, PostureTask, SlackedFrameTask, TorqueLimits)
from wholebody.tasks.base import Task, TaskRows
from wholebody.tasks.regularization import (AccelerationRegularizer, AccelerationTarget,
                                             AuxiliaryRegularizer, ContactTorqueRegularizer,
                                             TangentialForceRegularizer)
from wholebody.tasks.wrench import TrunkWrenchTask
from wholebody.variables import Variables

#: quadprog without a fallback: the settings the engines are compared with
QUADPROG = SolverSettings(backend="quadprog", fallback_backend=None)

native = pytest.mark.skipif(not native_available(),
                            reason="wholebody._hierarchy_cycle not built (no C++ compiler)")

ENGINES = [pytest.param("native", marks=native), "python"]
LEVEL_FIELDS = ("B", "b", "w", "C", "lower", "upper", "v")


# ---------------------------------------------------------------------------- helpers
def snapshot(levels):
    """Copies of every level's arrays (the cycles' levels are views refilled by the next call)."""
    return [{f: np.array(getattr(level, f), dtype=float) for f in LEVEL_FIELDS} for level in levels]


def assert_levels_equal(native_levels, reference, where=""):
    """Same number of levels, same shapes, same ±inf entries, the same weights (copied, exact);
    the other finite entries equal up to round-off: rtol 1e-9 and atol 1e-8 — for the matrices
    times the row's largest entry (the contact-force columns carry the scale m g ~ 900), for the
    vectors absolute (N, Nm, rad/s²; round-off here is ~1e-12)."""
    assert len(native_levels) == len(reference), where
    for rank, (a, b) in enumerate(zip(native_levels, reference), start=1):
        for f in LEVEL_FIELDS:
            x, y = a[f], b[f]
            msg = f"{where}: level {rank} field {f}"
            assert x.shape == y.shape, f"{msg}: shape {x.shape} != {y.shape}"
            assert not np.isnan(x).any(), msg
            inf = np.isinf(y)
            np.testing.assert_array_equal(x[inf], y[inf], err_msg=f"{msg} (±inf entries)")
            assert np.isfinite(x[~inf]).all(), f"{msg}: native has ±inf where the reference has not"
            if f in ("w", "v"):  # the tasks' weights, copied: no arithmetic, no round-off
                np.testing.assert_array_equal(x, y, err_msg=msg)
                continue
            if x.ndim == 2:
                atol = 1e-8 * np.maximum(1.0, np.abs(y).max(axis=1, initial=0.0))[:, None]
                atol = np.broadcast_to(atol, y.shape)[~inf]
            else:
                atol = 1e-8
            xf, yf = x[~inf], y[~inf]
            np.testing.assert_array_less(np.abs(xf - yf), atol + 1e-9 * np.abs(yf), err_msg=msg)


def first_use_refs(task):
    """The references a task sets on first use (None until then)."""
    refs = {a: getattr(task, a) for a in ("com_ref", "position", "rotation") if hasattr(task, a)}
    if isinstance(task, ContactConstraint):
        refs["anchors"] = dict(task.anchors)
    return refs


def assert_same_refs(stack_native, stack_python, where=""):
    """The first-use references of two identically built stacks are set (after a solve) and equal;
    returns how many were compared (so that a caller can assert the check was not vacuous)."""
    n_set = 0
    for tn, tp in zip(stack_native.tasks(), stack_python.tasks()):
        assert tn.name == tp.name
        rn, rp = first_use_refs(tn), first_use_refs(tp)
        assert rn.keys() == rp.keys()
        for key in rn:
            a, b = rn[key], rp[key]
            msg = f"{where}: task '{tn.name}'.{key}"
            if isinstance(a, dict):
                assert a.keys() == b.keys(), msg
                for c in a:
                    np.testing.assert_allclose(a[c], b[c], atol=1e-10, rtol=0, err_msg=f"{msg}[{c}]")
                n_set += bool(a)
            else:
                assert a is not None and b is not None, f"{msg}: not set ({a} vs {b})"
                np.testing.assert_allclose(a, b, atol=1e-10, rtol=0, err_msg=msg)
                n_set += 1
    return n_set


def n_first_use_refs(stack) -> int:
    """How many first-use references a stack's tasks set (anchors: one per task using them)."""
    return sum(isinstance(t, MomentumPD) + isinstance(t, (CoMTask, JointTrajectoryTask))
               + 2 * isinstance(t, FrameTask)
               + (isinstance(t, ContactConstraint) and bool(t.kp or t.kd)) for t in stack.tasks())


def compare_on_states(robot, stack_native, stack_python, variables, states, reduced=True,
                      where="", cycle=None):
    """Solve every state with the native cycle and compare its levels with the Python reference
    (robot.update + a separate Formulation); returns the cycle and the last (native, reference)
    snapshots."""
    cycle = cycle or HierarchyCycle(robot, stack_native, reduced=reduced, engine="native")
    assert cycle.native
    formulation = Formulation(robot, reduced=reduced)
    for i, (q, v) in enumerate(states):
        cycle.solve(q, v, variables)
        got = snapshot(cycle.levels)
        robot.update(q, v)
        ref = snapshot(formulation.levels(stack_python, variables)[0])
        assert_levels_equal(got, ref, f"{where} state {i}")
    return cycle, got, ref


def random_states(robot, rng, n):
    return [robot.random_state(rng) for _ in range(n)]


def moving_states(robot, n, dt=0.05):
    """A smooth joint motion around the reference posture (Robot.smooth_motion, as in
    benchmarks/bench_wbc.py), sampled every ``dt``: feet near the ground, moderate velocities —
    states a controller actually sees."""
    return robot.smooth_motion(n, dt)


# ---------------------------------------------------------------------------- stacks
def set_lqr_gains(stack, rng, n_lambda):
    """Random LQR gains (n_lambda x 9, n_lambda) on the 'momentum' MomentumForce task."""
    task = stack.find("momentum")
    assert isinstance(task, MomentumForce)
    task.K = rng.normal(scale=50.0, size=(n_lambda, 9))
    task.k = rng.normal(scale=200.0, size=n_lambda)


TABLE_CASES = {
    # name: (robot, builder(robot, full), active contacts or None for all)
    "table2": ("talos14", lambda r, full: table2_stack(r, full=full), None),
    "table2-lqr": ("talos14", lambda r, full: table2_stack(r, lqr=True, full=full), None),
    "table1-double": ("talos", lambda r, full: table1_stack(r, r.contact_names, full=full), None),
    "table1-single": ("talos", lambda r, full: table1_stack(r, ["left_sole"], ["right_sole_link"],
                                                            full=full), ["left_sole"]),
    "table4": ("talos14", lambda r, full: table4_stack(r, ["left_sole"], ["right_sole_link"],
                                                       full=full), ["left_sole"]),
    "table4-lqr": ("talos14", lambda r, full: table4_stack(r, ["left_sole"], ["right_sole_link"],
                                                           lqr=True, full=full), ["left_sole"]),
}


def table_pair(robots, case, full, seed=7):
    """(robot, native stack, python stack, variables) for a TABLE_CASES entry, LQR gains equal."""
    name, build, contacts = TABLE_CASES[case]
    robot = robots[name]
    variables = Variables(robot, contacts)
    stacks = build(robot, full), build(robot, full)
    if "lqr" in case:
        for s in stacks:
            set_lqr_gains(s, np.random.default_rng(seed), variables.n_lambda)
    return robot, stacks[0], stacks[1], variables


def hyq_stack(robot, full=False):
    """Every task kind on HyQ's point feet, with non-default parameters: contact subsets in
    non-model order, a non-vertical friction normal, per-joint gain vectors, vector weights."""
    na = robot.na
    q_ref = robot.q_ref.copy()
    q_ref[:3] += [0.02, -0.01, 0.03]
    quat = np.array([0.05, -0.03, 0.02, 1.0])
    q_ref[3:7] = quat / np.linalg.norm(quat)
    q_ref[7:] += np.linspace(-0.1, 0.1, na)
    P = np.diag([40.0, 45.0, 50.0, 5.0, 6.0, 7.0])
    P[0, 1] = P[1, 0] = 3.0
    D = np.diag([12.0, 13.0, 14.0, 4.0, 5.0, 6.0])
    D[3, 5] = 1.5
    momentum = MomentumPD(P=P, D=D, name="momentum pd", weight=np.array([1.0, 1.0, 1.0, 0.1, 0.1, 0.1]))
    momentum.h_ref = np.array([1.0, -2.0, 0.5, 0.3, -0.2, 0.1])
    momentum.hdot_ref = np.array([0.5, 0.0, -1.0, 0.0, 0.2, 0.0])
    return Stack([
        [FullDynamics(name="dynamics") if full else NewtonEuler(name="newton-euler"),
         TorqueLimits(name="torque limits", scale=0.9, upper_override={"lf_kfe_joint": 10.0})],
        [ContactConstraint(name="contacts", kp=50.0, kd=5.0),
         FrictionCone(0.7, name="friction", normals={"lf_foot": [0.1, 0.0, 1.0]}),
         NormalForceBounds(f_min=5.0, f_max=500.0, name="normal bounds",
                           contacts=("rh_foot", "lf_foot", "lh_foot"),
                           normals={"lh_foot": [0.0, -0.2, 1.0]}),
         JointAccelerationLimits(name="qdd limits tanh", mode="tanh", a_max=150.0, steepness=8.0)],
        [JointAccelerationLimits(name="qdd limits braking", mode="braking", horizon=0.02, weight=2.0),
         CoMTask(kp=np.array([80.0, 0.0, 120.0]), kd=15.0, name="com xz", axes="xz",
                 weight=np.array([1.0, 3.0])),
         FrameTask("trunk", kp=np.array([100.0, 90.0, 80.0, 70.0, 60.0, 50.0]), kd=20.0,
                   name="trunk 6d", mask="6d"),
         FrameTask("lf_foot", kp=200.0, kd=30.0, name="lf position", mask="position"),
         FrameTask("trunk_imu", kp=30.0, kd=np.full(6, 7.0), name="imu orientation",
                   mask="orientation"),
         momentum,
         ContactConstraint(name="contacts as an independent set", kp=20.0, kd=2.0,
                           rank_tolerance=1e-3, contacts=("rh_foot", "lf_foot"), weight=0.5)],
        [PostureTask(kp=np.linspace(20.0, 80.0, na), kd=np.linspace(5.0, 15.0, na), name="posture base",
                     weight=0.1, q_ref=q_ref, base_kp=30.0, base_kd=8.0),
         PostureTask(kp=np.linspace(60.0, 10.0, na), kd=6.0, name="posture joints", weight=0.05),
         JointTrajectoryTask(["rh_kfe_joint", "lf_haa_joint"], kp=np.array([150.0, 90.0]), kd=25.0,
                             name="joint trajectory"),
         MomentumForce(K=np.random.default_rng(3).normal(scale=20.0, size=(6, 9)),
                       k=np.array([5.0, -3.0, 400.0, 2.0, 1.0, 380.0]), name="momentum force",
                       weight=1e-2, contacts=("rh_foot", "lf_foot")),
         ForceRegularizer(name="force regularizer", weight=1e-3, contacts=("lh_foot", "rf_foot"),
                          targets={"rf_foot": np.array([3.0, -4.0, 210.0])}),
         AccelerationRegularizer(name="qdd regularizer", weight=1e-4)],
    ])


def talos_stack(robot, full=False):
    """Rectangle feet: CoP with a margin, torsional friction, stance anchors with a 6D kd, a
    target wrench for one sole, a base-damping-only posture."""
    return Stack([
        [FullDynamics(name="dynamics") if full else NewtonEuler(name="newton-euler"),
         TorqueLimits(name="torque limits", upper_override={"leg_left_4_joint": 50.0})],
        [ContactConstraint(name="contacts", kp=30.0, kd=3.0),
         CenterOfPressure(name="cop", weight=1e4, margin=0.1),
         FrictionCone(0.6, name="friction torsion", torsion=True,
                      normals={"right_sole": [0.0, 0.1, 1.0]}),
         NormalForceBounds(f_min=10.0, name="normal bounds", contacts=("right_sole",)),
         JointAccelerationLimits(name="qdd limits")],
        [MomentumPD(name="momentum", weight=np.array([1e4] * 3 + [1e-4] * 3)),
         PostureTask(kp=50.0, kd=14.0, name="posture", weight=0.1, base_kp=0.0, base_kd=5.0),
         AccelerationTarget(np.linspace(-2.0, 3.0, robot.nv), name="qdd target", weight=1e-3),
         ForceRegularizer(name="force regularizer", weight=1e-4,
                          targets={"left_sole": np.array([1.0, 2.0, 450.0, 0.5, -0.5, 0.1])})],
    ])


def passive_stack_kinds(robot, variant=0):
    """The passive controller's tasks (Fahmi et al. 2019) on HyQ's point feet with non-default
    parameters: a trunk wrench with a tilted, turned reference, an external wrench and per-row
    weights (variant 0: with the feed-forward, about the heading frame; 1: neither), the
    contact-force torques and the leaning tangential forces on contact subsets in non-model
    order; a swing foot's and the trunk's frame tasks within slacks (auxiliary variables) costed
    on the second level in the other order."""
    from wholebody.planning.trunk import TrunkState
    from wholebody.tasks.wrench import TrunkImpedance
    impedance = TrunkImpedance(K_x=[2000.0, 1800.0, 2500.0], D_x=400.0,
                               K_theta=[900.0, 1000.0, 1100.0], D_theta=200.0,
                               feedforward=variant == 0)
    impedance.external_wrench = np.array([5.0, -3.0, 20.0, 1.0, -2.0, 0.5])
    wrench = TrunkWrenchTask(impedance, name="trunk wrench",
                             weight=np.array([1.0, 1.0, 1.0, 1.0, 1.4, 1.0]),
                             contacts=("rh_foot", "lf_foot", "lh_foot"), heading=variant == 0)
    yaw, pitch = 0.7, 0.1
    rotation = pin.rpy.rpyToMatrix(0.0, pitch, yaw)
    wrench.reference = TrunkState(np.array([0.05, -0.02, 0.6]), np.array([0.1, 0.0, -0.05]),
                                  np.array([0.3, -0.2, 0.1]), rotation, np.array([0.0, 0.1, 0.3]),
                                  np.array([0.5, -0.4, 1.0]))
    lean = np.array([60.0, -40.0, 800.0]) if variant == 0 else None
    return Stack([
        [NewtonEuler(name="newton-euler"), ContactConstraint(name="contacts", kp=200.0, kd=30.0),
         FrictionCone(0.7, name="friction"), TorqueLimits(name="torque limits"),
         SlackedFrameTask("lf_foot", "slack a", kp=2000.0, kd=20.0, mask="position",
                          name="swing within a slack"),
         SlackedFrameTask("trunk", "slack b", kp=np.linspace(50.0, 100.0, 6), kd=10.0,
                          name="trunk within a slack")],
        [wrench,
         AuxiliaryRegularizer(["slack b", "slack a"], name="slack costs",
                              weight=np.array([3.0, 100.0])),
         ContactTorqueRegularizer(name="contact torques", weight=np.linspace(0.01, 0.1, robot.na),
                                  contacts=("lh_foot", "rf_foot")),
         TangentialForceRegularizer(name="tangential", weight=0.03,
                                    contacts=("rf_foot", "lf_foot", "rh_foot"),
                                    normals={"lf_foot": [0.1, 0.0, 1.0],
                                             "rh_foot": [0.0, -0.3, 1.0]},
                                    lean=lean, mu=0.05 if variant == 0 else np.inf),
         AccelerationRegularizer(name="qdd regularizer", weight=1e-2)],
    ])


# ---------------------------------------------------------------------------- 1. rigid-body terms
@native
@pytest.mark.parametrize("name", ["talos14", "talos", "hyq"])
def test_terms_equal_robot_update(robots, name, rng):
    """M, h, CoM, its velocity and Jacobian, centroidal momentum and matrix, Adot_G v, the contact
    points and drifts of the compiled update equal Robot.update's (Pinocchio's Python bindings on the URDF
    model; the compiled cycle rebuilds the model from arrays); the points are the sole origins /
    sphere bottoms, checked against the frame placements."""
    robot = robots[name]
    cycle = HierarchyCycle(robot, Stack([[NewtonEuler(), TorqueLimits()], [AccelerationRegularizer()]]),
                           engine="native")
    for _ in range(5):
        q, v = robot.random_state(rng)
        cycle.solve(q, v)
        terms = cycle.engine.terms()
        robot.update(q, v)
        expected = {"M": robot.M, "h": robot.h, "com": robot.com, "vcom": robot.vcom,
                    "h_G": robot.h_G, "A_G": robot.A_G, "A_G_dot_v": robot.A_G_dot_v,
                    "J_com": robot.J_com, "points": robot.contact_points,
                    "contact_drifts": robot.stacked_contact_drift(robot.contact_names)}
        assert set(terms) == set(expected)
        for key, value in expected.items():
            assert terms[key].shape == np.shape(value), key
            scale = max(1.0, np.abs(value).max())
            np.testing.assert_allclose(terms[key], value, rtol=0, atol=1e-9 * scale, err_msg=key)
        np.testing.assert_array_equal(terms["M"], terms["M"].T)  # symmetric, both triangles
        for key in ("com", "vcom", "h_G"):
            np.testing.assert_allclose(getattr(cycle, key), expected[key], rtol=0, atol=1e-9)
        # independent: the points are the contact frames' origins, minus the radius along world z
        for i, c in enumerate(robot.contacts):
            origin = robot.data.oMf[c.frame_id].translation
            drop = c.spec.radius if c.dim == 3 else 0.0
            np.testing.assert_allclose(terms["points"][i], origin - [0.0, 0.0, drop], atol=1e-9)
    if name == "hyq":
        assert all(c.dim == 3 and c.spec.radius > 0 for c in robot.contacts)


@pytest.mark.parametrize("engine", ["python", "native"])
@pytest.mark.parametrize("name", ["talos14", "hyq"])
def test_terms_view_equals_pinocchio(robots, name, engine, rng):
    """The arrays of terms_view, rewritten by every update, equal Pinocchio's own functions at
    that state (a separate Data: frame placements, LOCAL_WORLD_ALIGNED frame Jacobians and
    classical accelerations, centerOfMass, computeCentroidalMomentum, ccrba's locked inertia)
    and the robot's torque bounds, on either engine; solve_updated after update gives solve's
    torques."""
    import pinocchio as pin

    if engine == "native" and not native_available():
        pytest.skip("the compiled extension is not built")
    robot = robots[name]
    stack = Stack([[NewtonEuler(), TorqueLimits()], [AccelerationRegularizer()]])
    cycle = HierarchyCycle(robot, stack, engine=engine)
    other = HierarchyCycle(robot, stack, engine=engine)
    view = cycle.terms_view()
    model, data = robot.model, robot.model.createData()
    LWA = pin.LOCAL_WORLD_ALIGNED
    for _ in range(4):
        q, v = robot.random_state(rng)
        cycle.update(q, v)
        assert cycle.terms_view() is view  # the same arrays, rewritten
        pin.forwardKinematics(model, data, q, v, np.zeros(robot.nv))
        pin.updateFramePlacements(model, data)
        pin.computeJointJacobians(model, data, q)
        np.testing.assert_array_equal(view.q, q)
        np.testing.assert_array_equal(view.v, v)
        np.testing.assert_allclose(view.nle, pin.nonLinearEffects(model, model.createData(), q, v),
                                   atol=1e-9)
        np.testing.assert_allclose(view.com, pin.centerOfMass(model, model.createData(), q),
                                   atol=1e-12)
        centroidal = model.createData()
        pin.computeCentroidalMomentum(model, centroidal, q, v)
        np.testing.assert_allclose(view.h_G, centroidal.hg.vector, atol=1e-9)
        np.testing.assert_allclose(view.vcom, centroidal.hg.linear / robot.mass, atol=1e-12)
        pin.ccrba(model, centroidal, q, v)
        np.testing.assert_allclose(view.Ig, centroidal.Ig.inertia, atol=1e-9)
        np.testing.assert_allclose(view.rotation, data.oMi[1].rotation, atol=1e-12)
        for i, c in enumerate(robot.contacts):
            origin = data.oMf[c.frame_id].translation
            J = pin.getFrameJacobian(model, data, c.frame_id, LWA)[:3]
            np.testing.assert_allclose(view.frame_positions[i], origin, atol=1e-12)
            np.testing.assert_allclose(view.frame_jacobians[i], J, atol=1e-12)
            np.testing.assert_allclose(view.frame_velocities[i], J @ v, atol=1e-9)
            np.testing.assert_allclose(
                view.frame_drifts[i],
                pin.getFrameClassicalAcceleration(model, data, c.frame_id, LWA).linear,
                atol=1e-9)
            drop = c.spec.radius if c.dim == 3 else 0.0
            np.testing.assert_allclose(view.points[i], origin - [0.0, 0.0, drop], atol=1e-12)
        np.testing.assert_allclose(view.tau_max, robot.torque_limits.upper(q[7:]), atol=1e-9)
        np.testing.assert_array_equal(cycle.solve_updated().tau, other.solve(q, v).tau)


@pytest.mark.parametrize("engine", ["python", "native"])
def test_update_misuse_is_named(robots, engine):
    """solve_updated before any update is an error that says what to call instead."""
    if engine == "native" and not native_available():
        pytest.skip("the compiled extension is not built")
    robot = robots["talos14"]
    cycle = HierarchyCycle(robot, Stack([[NewtonEuler()], [AccelerationRegularizer()]]),
                           engine=engine)
    with pytest.raises(RuntimeError, match="update"):
        cycle.solve_updated()


# ---------------------------------------------------------------------------- 2. Tables 1, 2, 4
@native
@pytest.mark.parametrize("full", [False, True], ids=["reduced", "full"])
@pytest.mark.parametrize("case", list(TABLE_CASES))
def test_table_levels_equal_formulation(robots, case, full):
    """Every level array (B, b, w, C, lower, upper, v) of the stacks of Tables 1, 2 and 4 equals the
    Python Formulation's on random states, in the reduced and the full formulation; the first-use
    references (momentum com_ref, CoM position, swing-foot pose) come out equal."""
    robot, s_native, s_python, variables = table_pair(robots, case, full)
    rng = np.random.default_rng(100 + list(TABLE_CASES).index(case))
    _, got, _ = compare_on_states(robot, s_native, s_python, variables,
                                  random_states(robot, rng, 5), reduced=not full,
                                  where=f"{case} {'full' if full else 'reduced'}")
    n = robot.nv + variables.n_lambda + (robot.na if full else 0)
    assert all(level["B"].shape[1] == n and level["C"].shape[1] == n for level in got)
    assert sum(level["B"].shape[0] + level["C"].shape[0] for level in got) > n
    assert assert_same_refs(s_native, s_python, case) == n_first_use_refs(s_native)


# ---------------------------------------------------------------------------- 3. every kind
def test_every_kind_is_exercised(robots):
    """The stacks compared in this file use every task class with a compiled kernel."""
    used = set()
    for case in TABLE_CASES:
        for full in (False, True):
            used |= {type(t) for t in table_pair(robots, case, full)[1].tasks()}
    for full in (False, True):
        used |= {type(t) for t in hyq_stack(robots["hyq"], full).tasks()}
        used |= {type(t) for t in talos_stack(robots["talos14"], full).tasks()}
    used |= {type(t) for t in passive_stack_kinds(robots["hyq"]).tasks()}
    assert used == set(kernel_tasks().values())
    assert not python_tasks(hyq_stack(robots["hyq"]))


@native
def test_every_kernel_is_registered_by_name():
    """The compiled registry and the Python task classes name the same kernels, and each kernel
    takes exactly the parameters its task's schema declares (a program built from every task's
    schema compiles: see the level comparisons above; a wrong name is refused below)."""
    from wholebody import _hierarchy_cycle
    assert set(_hierarchy_cycle.HierarchyCycle.kernels()) == set(kernel_tasks())


@native
@pytest.mark.parametrize("change", ["renamed", "resized", "missing", "unknown kernel", "bad axis"])
def test_compile_checks_the_layout_by_name(robots, change):
    """A slot whose parameters do not match its kernel's (a name, a size, one left out), that
    names no kernel, or that selects a CoM axis beyond z is refused at compile, the error naming
    the kernel and the parameter or selection."""
    robot = robots["talos14"]
    stack = Stack([[NewtonEuler()], [CoMTask(kp=10.0, kd=5.0)]])
    cycle = HierarchyCycle(robot, stack, engine="native")
    q, v = moving_states(robot, 1)[0]
    cycle.solve(q, v)
    sent = copy.deepcopy({k: v for k, v in cycle._program.description.items() if k != "buffers"})
    sent["buffers"] = cycle._program.description["buffers"]
    slot = next(s for s in sent["slots"] if s["kernel"] == "com")
    if change == "renamed":
        slot["params"]["stiffness"] = slot["params"].pop("kp")
        match = "kernel 'com'.*parameters"
    elif change == "resized":
        slot["params"]["kp"][1] = 1
        match = "kernel 'com': parameter 'kp' must be 3 values"
    elif change == "missing":
        del slot["params"]["kd"]
        match = "kernel 'com'.*parameters"
    elif change == "bad axis":
        slot["selection"]["rows"] = [0, 3]  # the CoM has three axes
        match = "kernel 'com': selection 'rows' has 3"
    else:
        slot["kernel"] = "cmo"
        match = "no kernel named 'cmo'"
    with pytest.raises(ValueError, match=match):
        cycle.engine.compile(sent)


@native
@pytest.mark.parametrize("full", [False, True], ids=["reduced", "full"])
@pytest.mark.parametrize("name", ["hyq", "talos14"])
def test_every_kind_levels_equal_formulation(robots, name, full):
    """Custom stacks with every task kind and non-default parameters (see hyq_stack, talos_stack):
    level arrays equal the Python Formulation's on random states; the ContactConstraint anchors
    and the other first-use references match."""
    robot = robots[name]
    build = hyq_stack if name == "hyq" else talos_stack
    s_native, s_python = build(robot, full), build(robot, full)
    variables = Variables(robot, robot.contact_names)
    rng = np.random.default_rng(200 + full)
    compare_on_states(robot, s_native, s_python, variables, random_states(robot, rng, 5),
                      reduced=not full, where=f"{name} {'full' if full else 'reduced'}")
    anchors = s_native.find("contacts").anchors
    assert set(anchors) == set(robot.contact_names)
    assert assert_same_refs(s_native, s_python, name) == n_first_use_refs(s_native) >= 2


@native
def test_dependent_contact_rows_equal_formulation(rng):
    """ODRI's 8-DoF Solo (two joints per leg, point feet): its contacts' rows are linearly
    dependent. With ``rank_tolerance`` the contact task's rows are an independent set, the rest
    zero: the native level arrays equal the Python Formulation's (some rows zero in both), and
    the torques of the two engines agree."""
    from conftest import solo8_description

    import wholebody as wb
    solo = wb.load_robot(solo8_description())

    def build():
        return Stack([[NewtonEuler(name="newton-euler"),
                       ContactConstraint(name="contacts", kp=50.0, kd=5.0, rank_tolerance=1e-4),
                       TorqueLimits(name="torque limits")],
                      [PostureTask(name="posture", kp=10.0, kd=2.0)]])
    variables = Variables(solo, solo.contact_names)
    s_native, s_python = build(), build()
    states = moving_states(solo, 4) + random_states(solo, rng, 3)
    cycle, got, ref = compare_on_states(solo, s_native, s_python, variables, states,
                                        where="solo8")
    J = solo.stacked_contact_jacobian()  # of the last state
    zero = ~ref[0]["B"].any(axis=1)
    assert 0 < zero.sum() == J.shape[0] - np.linalg.matrix_rank(J, tol=1e-4 * np.linalg.norm(J, 2))
    python = HierarchyCycle(solo, build(), engine="python")
    for q, v in states:
        a, b = cycle.solve(q, v, variables), python.solve(q, v, variables)
        assert a.ok and b.ok, (a.status, b.status)
        np.testing.assert_allclose(a.tau, b.tau, atol=1e-6, rtol=0)


@native
@pytest.mark.parametrize("variant", [0, 1], ids=["feedforward-heading", "plain"])
@pytest.mark.parametrize("full", [False, True], ids=["reduced", "full"])
def test_passive_kinds_levels_equal_formulation(robots, variant, full):
    """The passive controller's trunk wrench, contact-torque and tangential-force tasks (see
    passive_stack_kinds): level arrays equal the Python Formulation's on random states and on
    smooth motions, all stance feet active and only three; the trunk wrench's target is the
    impedance's wrench (rows about the heading frame rotate it: its norm with unit weights)."""
    robot = robots["hyq"]
    rng = np.random.default_rng(400 + 2 * variant + full)
    for contacts in (robot.contact_names, ("lf_foot", "rh_foot", "lh_foot")):
        s_native, s_python = (passive_stack_kinds(robot, variant) for _ in range(2))
        variables = Variables(robot, contacts, s_native.auxiliary())
        assert variables.auxiliary == (("slack a", 1), ("slack b", 1))
        if len(contacts) < len(robot.contact_names):  # the tasks on all active contacts
            for task in s_native.tasks() + s_python.tasks():
                if task.per_contact:
                    task.contacts = None
        states = random_states(robot, rng, 4) + moving_states(robot, 3)
        compare_on_states(robot, s_native, s_python, variables, states, reduced=not full,
                          where=f"passive kinds {variant} {contacts}")
        task = s_python.find("trunk wrench")
        q, v = states[-1]
        robot.update(q, v)
        wrench = task.impedance.wrench(robot, task.reference)
        target = task.rows(robot, variables).target
        for part in (slice(0, 3), slice(3, 6)):
            np.testing.assert_allclose(np.linalg.norm(target[part]), np.linalg.norm(wrench[part]),
                                       rtol=1e-12)
        if variant:
            np.testing.assert_array_equal(target, wrench)


@native
@pytest.mark.parametrize("mode", ["braking", "tanh"])
@pytest.mark.parametrize("name", ["hyq", "talos14"])
def test_joint_limit_rows_beyond_the_limits(robots, name, mode):
    """Joints outside their range (each joint by 0.01-0.5 rad, below or above, moving away or
    back): every level array of both engines — the joint-acceleration-limit rows among them —
    equal up to round-off, both engines' torques within the limits; with the tanh bounds a
    violated limit pushes back (upper bound below zero past the upper limit, lower bound above
    zero past the lower one)."""
    robot = robots[name]
    stacks = [Stack([[NewtonEuler(name="newton-euler"), TorqueLimits(name="torque limits")],
                     [ContactConstraint(name="contacts"),
                      JointAccelerationLimits(name="qdd limits", mode=mode)],
                     [PostureTask(name="posture", weight=0.1)]]) for _ in range(2)]
    variables = Variables(robot, robot.contact_names)
    rng = np.random.default_rng(31)
    states = []
    for k in range(6):
        q, v = robot.random_state(rng, velocity_scale=0.3)
        past = rng.uniform(0.01, 0.5, size=robot.na)
        above = rng.random(robot.na) < 0.5
        q[7:] = np.where(above, robot.q_max + past, robot.q_min - past)
        states.append((q, v))
    cycle, _, _ = compare_on_states(robot, stacks[0], stacks[1], variables, states,
                                    where=f"{name} {mode} beyond the limits")
    limits = stacks[1].find("qdd limits")
    python = HierarchyCycle(robot, stacks[1], engine="python")
    for q, v in states:
        a, b = cycle.solve(q, v, variables), python.solve(q, v, variables)
        lo, hi = robot.torque_bounds(q)
        assert np.all(np.abs(a.tau) <= hi + 1e-12) and np.all(np.abs(b.tau) <= hi + 1e-12)
        robot.update(q, v)
        qdd_lo, qdd_hi = limits.bounds(robot)
        above = q[7:] > robot.q_max
        if mode == "tanh":  # the tanh bounds do not depend on the velocity
            assert np.all(qdd_hi[above] < 0.0) and np.all(qdd_lo[~above] > 0.0)


# ---------------------------------------------------------------------------- 4. parameters
@native
def test_parameters_changed_between_cycles(robots, rng):
    """Gains, references, weights, targets and the torque-limit scale changed on both stacks between
    two solves at the same state: the arrays still equal the reference, and they changed exactly
    where the task definitions say (checked against the definitions, not the code)."""
    robot = robots["hyq"]
    s_native, s_python = hyq_stack(robot), hyq_stack(robot)
    variables = Variables(robot)
    q, v = robot.random_state(rng, velocity_scale=0.3)
    cycle, before, _ = compare_on_states(robot, s_native, s_python, variables, [(q, v)],
                                                  where="before")
    for stack in (s_native, s_python):
        stack.find("com xz").position = stack.find("com xz").position + [0.03, 0.5, -0.02]
        stack.find("posture joints").kp = 2.0 * stack.find("posture joints").kp
        stack.find("qdd regularizer").weight = 5e-3
        stack.find("force regularizer").targets = {"lh_foot": np.array([1.0, 2.0, 150.0])}
        stack.find("torque limits").scale = 0.5
        stack.find("friction").mu = 0.4
    _, after, _ = compare_on_states(robot, s_native, s_python, variables, [(q, v)], cycle=cycle,
                                    where="after")

    # level 1: the torque bounds (reduced: tau bounds - h_u) are the robot's times the scale, the
    # knee's capped at 10 Nm (upper_override); the Newton-Euler rows do not change
    robot.update(q, v)
    h_u = robot.h[6:]
    _, hi = robot.torque_bounds()
    cap = np.full(robot.na, np.inf)
    cap[robot.joint_names.index("lf_kfe_joint")] = 10.0
    for levels, scale in ((before, 0.9), (after, 0.5)):
        np.testing.assert_allclose(levels[0]["upper"] + h_u, np.minimum(scale * hi, cap), rtol=1e-12)
        np.testing.assert_allclose(levels[0]["lower"] + h_u, -np.minimum(scale * hi, cap), rtol=1e-12)
    assert 0.5 * hi[robot.joint_names.index("lf_kfe_joint")] > 10.0  # the cap is what binds
    np.testing.assert_array_equal(after[0]["B"], before[0]["B"])
    np.testing.assert_array_equal(after[0]["b"], before[0]["b"])
    # level 2: friction rows change (mu), the contact rows (equalities) do not
    assert not np.allclose(after[1]["C"], before[1]["C"])
    np.testing.assert_array_equal(after[1]["B"], before[1]["B"])
    np.testing.assert_array_equal(after[1]["b"], before[1]["b"])
    # level 3: the CoM rows x, z move by kp * delta (kp x = 80, kp z = 120); y is not a row
    delta_b = after[2]["b"] - before[2]["b"]
    np.testing.assert_allclose(delta_b[:2], [80.0 * 0.03, 120.0 * -0.02], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(delta_b[2:], 0.0, atol=1e-9)
    # level 4: joint posture rows (after the nv base-posture rows) double; the regularizer's weight
    # and the force targets change; nothing else
    nv, na = robot.nv, robot.na
    joint_rows = slice(nv, nv + na)
    np.testing.assert_allclose(after[3]["b"][joint_rows] - before[3]["b"][joint_rows],
                               np.linspace(60.0, 10.0, na) * (robot.q_ref[7:] - q[7:]), atol=1e-9)
    np.testing.assert_array_equal(before[3]["w"][-nv:], 1e-4)
    np.testing.assert_array_equal(after[3]["w"][-nv:], 5e-3)
    np.testing.assert_array_equal(after[3]["w"][:-nv], before[3]["w"][:-nv])
    changed_b = np.flatnonzero(after[3]["b"] != before[3]["b"])
    m = after[3]["b"].shape[0]
    # rows: base posture nv, joint posture na, trajectory 2, momentum force 6, regularizer 6, qdd nv
    reg = slice(nv + na + 2 + 6, nv + na + 2 + 6 + 6)
    assert set(changed_b) <= set(range(nv, nv + na)) | set(range(reg.start, reg.stop))
    np.testing.assert_allclose(before[3]["b"][reg], [0.0, 0.0, 0.0, 3.0, -4.0, 210.0], atol=1e-12)
    np.testing.assert_allclose(after[3]["b"][reg], [1.0, 2.0, 150.0, 0.0, 0.0, 0.0], atol=1e-12)
    assert m == nv + na + 2 + 6 + 6 + nv


# ---------------------------------------------------------------------------- 5. torques
def pinocchio_eom(robot, q, contacts):
    """M, and J_c (contacts' points, LOCAL_WORLD_ALIGNED) from Pinocchio directly, not Robot."""
    model = robot.model
    data = model.createData()
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    blocks = []
    for n in contacts:
        c = robot.contact(n)
        J = pin.getFrameJacobian(model, data, c.frame_id, pin.LOCAL_WORLD_ALIGNED)
        if c.dim == 3:  # the sphere bottom d = (0, 0, -r): J_lin - [d]x J_ang
            d = np.array([0.0, 0.0, -c.spec.radius])
            J = J[:3] - np.cross(d, J[3:].T).T
        blocks.append(J)
    return M, np.vstack(blocks)


TORQUE_CASES = {
    "table2-talos14": ("talos14", lambda r: table2_stack(r), None, True),
    "table2-talos14-full": ("talos14", lambda r: table2_stack(r, full=True), None, False),
    "table1-single-talos": ("talos", lambda r: table1_stack(r, ["left_sole"], ["right_sole_link"]),
                            ["left_sole"], True),
    "hyq": ("hyq", lambda r: hyq_stack(r), None, True),
}


@native
@pytest.mark.parametrize("case", list(TORQUE_CASES))
def test_torques_equal_python_and_satisfy_dynamics(robots, case):
    """On a smooth motion near the reference posture, the native cycle's tau, qdd and lambda equal
    the Python engine's, satisfy M qdd + h = S^T tau + J_c^T lambda (Pinocchio directly) and stay
    within the robot's torque limits.

    Both engines use quadprog without fallback: DAQP accepts a level's solution when it is within
    its tolerance, and inputs that differ in the last bits (the two engines round differently) can
    fall on either side of that boundary and give different — both valid — active sets. Quadprog's
    decisions do not sit on such a boundary for these problems, so equal inputs up to round-off
    give equal solutions up to round-off. (Not Table 4 here: on these states its level 3 conflicts
    at a cost ~1e11 and the cascade's x moves by up to 1e-2 when B, b are perturbed by 1e-14
    relative — in the Python engine alone — so no engine comparison at 1e-6 is meaningful there;
    its level arrays are compared in test_table_levels_equal_formulation.)"""
    name, build, contacts, reduced = TORQUE_CASES[case]
    robot = robots[name]
    variables = Variables(robot, contacts)
    # quadprog, no fallback: DAQP's tolerance-boundary acceptance could decide differently on the
    # bit-level-different inputs of the two engines (see the docstring)
    kw = dict(reduced=reduced, settings=QUADPROG)
    c_native = HierarchyCycle(robot, build(robot), engine="native", **kw)
    c_python = HierarchyCycle(robot, build(robot), engine="python", **kw)
    assert c_native.native and not c_python.native
    S_T = np.vstack([np.zeros((6, robot.na)), np.eye(robot.na)])
    for i, (q, v) in enumerate(moving_states(robot, 20)):
        a = c_native.solve(q, v, variables)
        b = c_python.solve(q, v, variables)
        where = f"{case} state {i}"
        assert a.ok and b.ok, (where, a.status, b.status)
        assert a.status == b.status, where
        np.testing.assert_allclose(a.tau, b.tau, rtol=0, atol=1e-6, err_msg=where)
        np.testing.assert_allclose(a.qdd, b.qdd, rtol=0, atol=1e-6, err_msg=where)
        np.testing.assert_allclose(a.lam, b.lam, rtol=0, atol=1e-6, err_msg=where)
        assert a.contacts == variables.contacts and list(a.forces) == list(variables.contacts)
        # equations of motion, from Pinocchio directly (h = rnea at zero acceleration)
        M, J = pinocchio_eom(robot, q, variables.contacts)
        h = pin.rnea(robot.model, robot.model.createData(), q, v, np.zeros(robot.nv))
        terms = [M @ a.qdd, h, S_T @ a.tau, J.T @ a.lam]
        residual = terms[0] + terms[1] - terms[2] - terms[3]
        scale = sum(np.linalg.norm(t) for t in terms)
        assert np.linalg.norm(residual) <= 1e-8 * scale, (where, np.linalg.norm(residual), scale)
        robot.update(q, v)
        lo, hi = robot.torque_bounds()
        assert np.all(a.tau >= lo - 1e-6) and np.all(a.tau <= hi + 1e-6), where


# ---------------------------------------------------------------------------- 6. contact switching
def switching_stack(robot):
    """Per-contact tasks on the active contacts (contacts=None), a swing-foot task on the right
    sole: valid in double and in single support."""
    return Stack([
        [NewtonEuler(name="newton-euler"), TorqueLimits(name="torque limits")],
        [ContactConstraint(name="contacts"), CenterOfPressure(name="cop", weight=1e4),
         FrictionCone(robot.friction, name="friction"), JointAccelerationLimits(name="qdd limits")],
        [MomentumPD(name="momentum", weight=np.array([1e4] * 3 + [1e-4] * 3)),
         FrameTask("right_sole_link", kp=100.0, kd=20.0, name="swing", weight=1e-2),
         PostureTask(name="posture", weight=0.1, kp=50.0, kd=14.0, base_kp=50.0, base_kd=14.0),
         ForceRegularizer(name="force regularizer", weight=1e-4)],
    ])


@native
def test_contact_switching(robots, rng):
    """One cycle object solving double, single, double, single support again (cached layouts
    reused): every cycle's arrays have the contact set's sizes and equal the Python reference;
    the solution's forces are those of the active contacts."""
    robot = robots["talos"]
    s_native, s_python = switching_stack(robot), switching_stack(robot)
    cycle = HierarchyCycle(robot, s_native, engine="native")
    double, single = Variables(robot, robot.contact_names), Variables(robot, ["left_sole"])
    states = moving_states(robot, 4, dt=0.1)
    for i, variables in enumerate([double, single, double, single]):
        q, v = states[i]
        compare_on_states(robot, s_native, s_python, variables, [(q, v)], cycle=cycle,
                          where=f"cycle {i} {variables.contacts}")
        n = robot.nv + 6 * len(variables.contacts)
        assert all(level.B.shape[1] == n and level.C.shape[1] == n for level in cycle.levels)
        # contact rows (6 per sole), CoP rows (4 per sole), friction rows (4 per sole)
        assert cycle.levels[1].B.shape[0] == 6 * len(variables.contacts)
        assert cycle.levels[1].C.shape[0] == 8 * len(variables.contacts) + robot.na
        sol = cycle.solve(q, v, variables)
        assert sol.lam.shape == (6 * len(variables.contacts),)
        assert sol.contacts == variables.contacts and list(sol.forces) == list(variables.contacts)


@pytest.mark.parametrize("engine", ENGINES)
def test_levels_are_the_last_cycles(robots, engine):
    """The documented meaning of HierarchyCycle.levels ("the solver levels of the last cycle") holds
    for the Python engine after a single-support solve too."""
    robot = robots["talos14"]
    cycle = HierarchyCycle(robot, switching_stack(robot), engine=engine)
    q, v = moving_states(robot, 1)[0]
    cycle.solve(q, v, Variables(robot, ["left_sole"]))
    n = robot.nv + 6
    assert [level.B.shape[1] for level in cycle.levels] == [n] * 3


# ---------------------------------------------------------------------------- 7. boundary errors
@pytest.mark.parametrize("engine", ENGINES)
def test_bad_state_raises_naming_the_field(robots, engine):
    """q/v with NaN or inf, of the wrong size, or with a non-unit base quaternion: ValueError naming
    the field; the cycle still solves a good state afterwards, as before the errors. A quaternion
    within the accepted 1e-3 of unit norm is accepted and gives the reference's arrays."""
    robot = robots["talos14"]
    cycle = HierarchyCycle(robot, table2_stack(robot), engine=engine, settings=QUADPROG)
    q, v = moving_states(robot, 1)[0]
    before = cycle.solve(q, v)
    bad_q, bad_v = q.copy(), v.copy()
    bad_q[9], bad_v[3] = np.nan, np.inf
    with pytest.raises(ValueError, match=r"^q: .*NaN"):
        cycle.solve(bad_q, v)
    with pytest.raises(ValueError, match=r"^v: .*NaN or inf"):
        cycle.solve(q, bad_v)
    with pytest.raises(ValueError, match=r"^q: .*21"):
        cycle.solve(q[:-1], v)
    with pytest.raises(ValueError, match=r"^v: .*20"):
        cycle.solve(q, np.r_[v, 0.0])
    unnormed = q.copy()
    unnormed[3:7] *= 1.1
    with pytest.raises(ValueError, match=r"^q: base quaternion"):
        cycle.solve(unnormed, v)
    after = cycle.solve(q, v)
    np.testing.assert_array_equal(after.tau, before.tau)
    # the accepted side of the quaternion check (|norm - 1| <= 1e-3): solved, and the native
    # arrays equal the reference's there too
    almost = q.copy()
    almost[3:7] *= 1.0009
    assert np.isfinite(cycle.solve(almost, v).tau).all()
    if engine == "native":
        compare_on_states(robot, table2_stack(robot), table2_stack(robot), Variables(robot),
                          [(almost, v)], where="quaternion norm 1.0009")


@native
def test_native_rejects_q_of_wrong_shape(robots):
    """A q with the right number of values in another shape is refused by both engines."""
    robot = robots["talos14"]
    cycle = HierarchyCycle(robot, table2_stack(robot), engine="native")
    q, v = moving_states(robot, 1)[0]
    with pytest.raises(ValueError, match=r"^q: "):
        HierarchyCycle(robot, table2_stack(robot), engine="python").solve(q.reshape(3, 7), v)
    with pytest.raises(ValueError, match=r"^q: "):
        cycle.solve(q.reshape(3, 7), v)


class SubclassedPosture(PostureTask):
    """A subclass may change the rows: it has no compiled kernel."""


class SlackedForceSum(Task):
    """A user's own inequality task with an auxiliary variable: |Σ f_z − m g| ≤ ε."""

    kind = "ineq"

    def auxiliary(self):
        return {"force slack": 1}

    def rows(self, robot, variables):
        A = np.zeros((2, variables.n_lambda))
        for sl in variables.lambda_slices.values():
            A[:, sl.start + 2] = 1.0
        aux = np.zeros((2, variables.n_aux))
        aux[:, variables.auxiliary_columns(["force slack"], self.name)[0]] = [-1.0, 1.0]
        weight = robot.mass * 9.81
        return TaskRows(qdd=None, lam=A, tau=None, aux=aux, lower=np.array([-np.inf, weight]),
                        upper=np.array([weight, np.inf]))


class ForceSum(Task):
    """A user's own task on the contact forces, without a kernel: their sum ≈ the weight."""

    def rows(self, robot, variables):
        A = np.zeros((3, variables.n_lambda))
        for sl in variables.lambda_slices.values():
            A[:, sl.start:sl.start + 3] = np.eye(3)
        return TaskRows(qdd=None, lam=A, tau=None, target=np.array([0.0, 0.0, robot.mass * 9.81]))


@pytest.mark.parametrize("extra", ["subclass", "own", "own with a slack"])
def test_python_task_in_a_native_stack(robots, extra):
    """A task without a compiled kernel (a subclass, a task only the Python engine has, one with
    an auxiliary variable that a compiled task costs) writes its rows from Python into the native
    program while every other task stays compiled: the level arrays and torques equal the Python
    reference on moving states."""
    robot = robots["talos14"]

    def build():
        stack = table2_stack(robot)
        if extra == "subclass":
            stack.levels[2][1] = SubclassedPosture(name="odd posture", weight=0.1, base_kp=50.0,
                                                   base_kd=14.0)
        elif extra == "own":
            stack.levels[2].append(ForceSum(name="odd force sum", weight=1e-4))
        else:
            stack.levels[1].append(SlackedForceSum(name="odd force sum"))
            stack.levels[2].append(AuxiliaryRegularizer(["force slack"], weight=1e-2))
        return stack

    stack = build()
    odd = "odd posture" if extra == "subclass" else "odd force sum"
    assert [t.name for t in python_tasks(stack)] == [odd]
    if not native_available():
        return
    cycle = HierarchyCycle(robot, stack, engine="auto", settings=QUADPROG)
    assert cycle.native
    reference = build()
    variables = Variables(robot, auxiliary=stack.auxiliary())
    compare_on_states(robot, stack, reference, variables, moving_states(robot, 4),
                      cycle=cycle, where=extra)
    q, v = moving_states(robot, 5)[-1]
    sol = cycle.solve(q, v)
    robot.update(q, v)
    ref = Formulation(robot).solve(reference, settings=QUADPROG)
    assert sol.ok and ref.ok
    np.testing.assert_allclose(sol.tau, ref.tau, atol=1e-6, rtol=0)


@native
def test_stack_edited_after_the_first_solve(robots):
    """Inserting a task on a frame the cycle has not seen, removing and replacing tasks after the
    first native solve: every cycle's level arrays equal the Python reference's for the stack as
    it is then (the program is rebuilt, the new frame added to the compiled model)."""
    robot = robots["talos14"]
    stacks = table2_stack(robot), table2_stack(robot)
    cycle = HierarchyCycle(robot, stacks[0], engine="native")
    states = iter(moving_states(robot, 8))
    frame = next(f.name for f in robot.model.frames if f.name.startswith("torso_2"))
    compare_on_states(robot, stacks[0], stacks[1], Variables(robot), [next(states)], cycle=cycle,
                      where="before")
    for stack in stacks:
        stack.insert(2, FrameTask(frame, kp=40.0, kd=12.0, mask="orientation", name="torso"))
    compare_on_states(robot, stacks[0], stacks[1], Variables(robot), [next(states), next(states)],
                      cycle=cycle, where="inserted")
    for stack in stacks:
        stack.replace("torso", CoMTask(kp=30.0, kd=10.0, axes="z", name="torso"))
    compare_on_states(robot, stacks[0], stacks[1], Variables(robot), [next(states)], cycle=cycle,
                      where="replaced")
    for stack in stacks:
        stack.remove("torso")
    compare_on_states(robot, stacks[0], stacks[1], Variables(robot), [next(states)], cycle=cycle,
                      where="removed")


class PostureAlike(SubclassedPosture):
    """A user's task class whose == compares by kind, not identity: any two are equal."""

    def __eq__(self, other):
        return isinstance(other, PostureAlike)

    __hash__ = Task.__hash__


@native
def test_tasks_swapped_in_the_level_lists(robots):
    """Edits straight on the levels' lists after the first solve, not through Stack's methods: a
    task put in another's place with the same layout and other gains, a task of a class whose ==
    calls any two of its tasks equal swapped for another of them, a level list replaced by an
    equal one. Every cycle's level arrays equal the Python reference's for the stack as it is
    then (the program follows the tasks, not what they compare equal to)."""
    robot = robots["talos14"]
    stacks = table2_stack(robot), table2_stack(robot)
    cycle = HierarchyCycle(robot, stacks[0], engine="native", settings=QUADPROG)
    states = iter(moving_states(robot, 6))

    def compare(where):
        compare_on_states(robot, stacks[0], stacks[1], Variables(robot), [next(states)],
                          cycle=cycle, where=where)

    compare("before")
    i, j = stacks[0].locate("posture")
    for stack in stacks:
        stack.levels[i][j] = PostureTask(kp=5.0, kd=1.0, name="posture", weight=0.3)
    compare("same layout, other gains")
    for kp in (7.0, 20.0):
        for stack in stacks:
            stack.levels[i][j] = PostureAlike(kp=kp, kd=2.0, name="posture", weight=0.3)
        compare(f"equal by its ==, kp {kp}")
    for stack in stacks:
        stack.levels[i] = list(stack.levels[i])
    compare("level list replaced")


def random_task(robot, rng, contacts):
    """One library task with a kernel and random (valid) parameters, or a Python-only one."""
    names = list(contacts)
    subset = tuple(rng.permutation(names)[:rng.integers(1, len(names) + 1)])
    frame = robot.model.frames[robot.contact(names[0]).frame_id].name
    joints = list(rng.permutation(robot.joint_names)[:rng.integers(1, 4)])
    w = float(rng.uniform(0.01, 2.0))
    make = [
        lambda: CoMTask(kp=rng.uniform(0, 100, 3), kd=float(rng.uniform(0, 20)), weight=w,
                        axes="".join(rng.permutation(list("xyz"))[:rng.integers(1, 4)])),
        lambda: FrameTask(frame, kp=float(rng.uniform(0, 100)), kd=rng.uniform(0, 20, 6), weight=w,
                          mask=str(rng.choice(["6d", "position", "orientation"]))),
        lambda: PostureTask(kp=rng.uniform(0, 60, robot.na), kd=float(rng.uniform(0, 10)), weight=w,
                            base_kp=float(rng.choice([0.0, 20.0])), base_kd=float(rng.uniform(0, 5))),
        lambda: MomentumPD(P=np.diag(rng.uniform(0, 50, 6)), D=np.diag(rng.uniform(0, 10, 6)), weight=w),
        lambda: ForceRegularizer(weight=w * 1e-3, contacts=subset),
        lambda: AccelerationRegularizer(weight=w * 1e-4),
        lambda: JointTrajectoryTask(joints, kp=float(rng.uniform(0, 100)), kd=5.0, weight=w),
        lambda: JointAccelerationLimits(mode=str(rng.choice(["braking", "tanh"])), horizon=0.05, weight=w),
        lambda: NormalForceBounds(f_min=float(rng.uniform(0, 5)), f_max=1e4, contacts=subset, weight=w),
        lambda: FrictionCone(float(rng.uniform(0.3, 1.0)), contacts=subset, weight=w,
                             torsion=bool(rng.integers(2))),
        lambda: CenterOfPressure(margin=float(rng.uniform(0, 0.3)), contacts=subset, weight=w),
        lambda: TangentialForceRegularizer(weight=w * 1e-4, contacts=subset),
        lambda: SubclassedPosture(kp=20.0, kd=5.0, weight=w),
        lambda: ContactConstraint(kp=float(rng.uniform(0, 100)), kd=float(rng.uniform(0, 20)),
                                  contacts=subset, weight=w,
                                  rank_tolerance=float(rng.choice([0.0, 1e-4]))),
        lambda: SlackedFrameTask(frame, str(rng.choice(["slack 0", "slack 1"])),  # may share one
                                 kp=float(rng.uniform(0, 100)), kd=5.0, weight=w,
                                 mask=str(rng.choice(["6d", "position", "orientation"]))),
    ]
    return make[rng.integers(len(make))]()


@native
@pytest.mark.parametrize("method", ["cascade", "weighted", "daqp"])
@pytest.mark.parametrize("seed", range(6))
def test_random_stacks_equal_python(robots, seed, method):
    """Stacks drawn at random (library tasks of every kind, Python-only ones among them, at random
    priorities below the dynamics and contacts) on random robots and contact sets: the native
    program's level arrays equal the Python reference's, and the torques agree to 1e-6 Nm when
    both solve, plus the reference's own sensitivity (conftest.torque_tolerance: random levels
    can conflict, and the cascade is then ill-conditioned)."""
    rng = np.random.default_rng(1000 + seed)
    robot = robots[["talos14", "hyq", "talos"][seed % 3]]
    contacts = tuple(rng.permutation(robot.contact_names)[:rng.integers(1, len(robot.contact_names) + 1)])
    n_levels = int(rng.integers(1, 4))

    def build(seed_tasks):
        r = np.random.default_rng(seed_tasks)
        levels = [[NewtonEuler(), TorqueLimits()], [ContactConstraint(), FrictionCone(0.8)]]
        levels += [[] for _ in range(n_levels)]
        for k in range(int(r.integers(2, 8))):
            levels[2 + int(r.integers(n_levels))].append(random_task(robot, r, contacts))
        for i, level in enumerate(levels):  # unique names for the diagnostics
            for j, task in enumerate(level):
                task.name = f"{type(task).__name__} {i}.{j}"
        levels = [level for level in levels if level]
        if method == "weighted":  # one hard level, one weighted objective
            levels = [levels[0] + levels[1], [t for level in levels[2:] for t in level]]
        return Stack([level for level in levels if level])

    stack, reference = build(seed), build(seed)
    variables = Variables(robot, contacts, stack.auxiliary())
    kwargs = dict(settings=SolverSettings(method=method, fallback_backend=None,
                                          backend="daqp" if method == "daqp" else "quadprog"))
    cycle = HierarchyCycle(robot, stack, engine="native", **kwargs)
    python = HierarchyCycle(robot, reference, engine="python", **kwargs)
    for q, v in moving_states(robot, 3):
        a, b = cycle.solve(q, v, variables), python.solve(q, v, variables)
        assert_levels_equal(snapshot(cycle.levels), snapshot(python.levels), f"seed {seed}")
        if a.ok and b.ok:
            tol = torque_tolerance(lambda q, v: python.solve(q, v, variables).tau, q, v, robot.nq)
            np.testing.assert_allclose(a.tau, b.tau, atol=tol, rtol=0)


def test_unknown_engine(robots):
    with pytest.raises(ValueError, match="engine: .*'fast'"):
        HierarchyCycle(robots["talos14"], table2_stack(robots["talos14"]), engine="fast")


@pytest.mark.parametrize("engine", ENGINES)
def test_task_producing_nan_names_the_task(robots, engine):
    """A NaN reference ends as a ValueError naming the task (in both engines); once the reference
    is finite again the cycle solves as the Python reference."""
    robot = robots["talos14"]
    stack = table1_stack(robot, robot.contact_names)
    cycle = HierarchyCycle(robot, stack, engine=engine)
    q, v = moving_states(robot, 1)[0]
    stack.find("com").position = np.array([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="task 'com'"):
        cycle.solve(q, v)
    stack.find("com").position = np.array([0.01, 0.0, 0.85])
    if engine == "native":
        reference = table1_stack(robot, robot.contact_names)
        reference.find("com").position = stack.find("com").position.copy()
        compare_on_states(robot, stack, reference, Variables(robot), [(q, v)], cycle=cycle,
                          where="after NaN")


class HugeRows(Task):
    """A user's task whose entries are finite but sum past the largest double (1e307 on every
    joint acceleration): rows no QP can use."""

    def rows(self, robot, variables):
        return TaskRows(qdd=np.full((2, robot.nv), 1e307), lam=None, tau=None,
                        target=np.zeros(2))


@pytest.mark.parametrize("engine", ENGINES)
def test_rows_whose_sum_overflows_are_refused_naming_the_task(robots, engine):
    """The check of the level arrays is a sum (one pass): rows whose finite entries sum past the
    largest double are refused as a NaN would be, by both engines alike (the compiled fill's
    check is the Python reference's), naming the task; the stack solves again without it."""
    robot = robots["talos14"]
    stack = table2_stack(robot)
    stack.levels[2].append(HugeRows(name="huge rows", weight=1e-12))
    cycle = HierarchyCycle(robot, stack, engine=engine)
    q, v = moving_states(robot, 1)[0]
    with np.errstate(over="ignore"), pytest.raises(ValueError,
                                                   match="task 'huge rows' produced NaN/inf rows"):
        cycle.solve(q, v)
    stack.remove("huge rows")
    assert cycle.solve(q, v).ok


@pytest.mark.parametrize("engine", ENGINES)
def test_independent_contact_rows_with_a_nan_name_the_task(robots, engine):
    """A contact task taking an independent set of its rows (``rank_tolerance``) with a NaN
    anchor: its rows stay NaN (no SVD hides them as dropped rows) and the cycle's check names
    the task, in both engines."""
    robot = robots["hyq"]
    stack = Stack([[NewtonEuler(name="newton-euler"),
                    ContactConstraint(name="contacts", kp=50.0, kd=5.0, rank_tolerance=1e-4)],
                   [PostureTask(name="posture", kp=10.0, kd=2.0)]])
    cycle = HierarchyCycle(robot, stack, engine=engine)
    q, v = moving_states(robot, 1)[0]
    assert cycle.solve(q, v).ok
    stack.find("contacts").anchors["lf_foot"] = np.array([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="task 'contacts'"):
        cycle.solve(q, v)


@native
def test_anchors_held_with_the_gains_off_are_unused(robots):
    """The stance task's anchors enter its rows only through its gains: with kp = kd = 0 the
    anchors it holds (read by the compiled packer from the task's dict, a NaN one among them)
    leave the native torques equal to the Python engine's; turned on, the gains pull towards
    the anchors held, in both engines."""
    robot = robots["hyq"]
    q, v = moving_states(robot, 2)[1]
    robot.update(q, v)
    feet = {n: robot.data.oMf[robot.contact(n).frame_id].translation.copy()
            for n in robot.contact_names}
    first = robot.contact_names[0]
    solutions = {}
    for engine in ("python", "native"):
        stack = Stack([[NewtonEuler(name="newton-euler"), ContactConstraint(name="contacts")],
                       [PostureTask(name="posture", kp=10.0, kd=2.0)]])
        contacts = stack.find("contacts")
        contacts.anchors = {n: p + np.array([0.004, -0.003, 0.0]) for n, p in feet.items()}
        contacts.anchors[first] = np.array([np.nan, 0.0, 0.0])
        cycle = HierarchyCycle(robot, stack, engine=engine)
        off = cycle.solve(q, v)
        contacts.anchors[first] = feet[first] + np.array([-0.002, 0.002, 0.001])
        contacts.kp, contacts.kd = 50.0, 5.0
        solutions[engine] = off, cycle.solve(q, v)
    (py_off, py_on), (nat_off, nat_on) = solutions["python"], solutions["native"]
    assert py_off.ok and nat_off.ok and py_on.ok and nat_on.ok
    np.testing.assert_allclose(nat_off.tau, py_off.tau, atol=1e-6)
    np.testing.assert_allclose(nat_on.tau, py_on.tau, atol=1e-6)
    assert np.abs(py_on.tau - py_off.tau).max() > 1e-3


@native
def test_matrix_gain_names_the_field(robots):
    """The native cycle takes scalar or per-joint gains: a matrix posture kp (which the Python
    engine accepts) is a ValueError naming the task and the field 'kp'."""
    robot = robots["talos14"]
    stack = table2_stack(robot)
    stack.find("posture").kp = 50.0 * np.eye(robot.na)
    cycle = HierarchyCycle(robot, stack, engine="native")
    q, v = moving_states(robot, 1)[0]
    with pytest.raises(ValueError, match=r"task 'posture': field 'kp'"):
        cycle.solve(q, v)


# ---------------------------------------------------------------------------- 8. failed solves
@native
@pytest.mark.parametrize("backend", ["quadprog", "daqp"])
def test_tiny_torque_limits_return_a_value(robots, backend):
    """Torque limits scaled to 1e-3 (the robot cannot hold itself): no exception; both engines
    report the same ok and, when failing, the same level (DAQP's flag on such a degenerate QP,
    "infeasible" or "cycling", depends on rounding); the torque is finite. Quadprog solves the cascade (tasks are
    sacrificed, ok): tau within the scaled limits up to the solver's feasibility tolerance (1e-6
    on rows whose values are ~|h_u| ~ 1e2 Nm, plus its relative margins). DAQP without fallback
    fails some level QPs: not ok, and tau clipped into the robot's limits."""
    robot = robots["talos14"]

    def build():
        stack = table2_stack(robot)
        stack.find("torque limits").scale = 1e-3
        return stack

    kw = dict(settings=SolverSettings(backend=backend, fallback_backend=None))
    c_native = HierarchyCycle(robot, build(), engine="native", **kw)
    c_python = HierarchyCycle(robot, build(), engine="python", **kw)
    oks = []
    for i, (q, v) in enumerate(moving_states(robot, 4)):
        a = c_native.solve(q, v)
        b = c_python.solve(q, v)
        assert (a.ok, a.status.split(":")[0]) == (b.ok, b.status.split(":")[0]), i
        oks.append(a.ok)
        assert np.isfinite(a.tau).all() and np.isfinite(a.qdd).all() and np.isfinite(a.lam).all()
        robot.update(q, v)
        lo, hi = robot.torque_bounds()
        assert np.all(a.tau >= lo) and np.all(a.tau <= hi)
        if a.ok:
            assert np.all(np.abs(a.tau) <= 1e-3 * hi + 1e-5), (i, np.abs(a.tau) - 1e-3 * hi)
        else:
            assert a.status  # the reason
    # quadprog solves every cycle (tau ~ 0 and a falling base satisfy the dynamics rows); DAQP
    # without fallback fails at least once, so both paths are exercised
    assert all(oks) if backend == "quadprog" else not all(oks)


# ---------------------------------------------------------------------------- 9. diagnostics
def eq_first(stack) -> bool:
    """Every level declares its equality tasks before its inequality tasks."""
    return all([t.kind for t in level] == sorted((t.kind for t in level), key=lambda k: k != "eq")
               for level in stack.levels)


@native
@pytest.mark.parametrize("name", ["talos14", "hyq"])
def test_diagnostics_equal_python(robots, name):
    """diagnostics=True: every task's report (level, kind, rows, error, active rows) equals the
    Python engine's, one report per task; where each level declares its equality tasks first (Table
    2) the lists are equal in order too (for the other order see the test below)."""
    robot = robots[name]
    build = table2_stack if name == "talos14" else hyq_stack
    kw = dict(settings=QUADPROG)
    c_native = HierarchyCycle(robot, build(robot), engine="native", **kw)
    c_python = HierarchyCycle(robot, build(robot), engine="python", **kw)
    names = [t.name for t in c_native.stack.tasks()]
    assert len(set(names)) == len(names)
    for i, (q, v) in enumerate(moving_states(robot, 5)):
        a = c_native.solve(q, v, diagnostics=True)
        b = c_python.solve(q, v, diagnostics=True)
        ra, rb = {t.name: t for t in a.tasks}, {t.name: t for t in b.tasks}
        assert len(ra) == len(a.tasks) == len(names) and ra.keys() == rb.keys() == set(names)
        for n in names:
            x, y = ra[n], rb[n]
            assert (x.level, x.kind, x.rows, x.active) == (y.level, y.kind, y.rows, y.active), (i, n)
            np.testing.assert_allclose(x.error, y.error, rtol=1e-6, atol=1e-8, err_msg=f"{i} {n}")
        if eq_first(c_native.stack):
            assert [t.name for t in a.tasks] == [t.name for t in b.tasks]
    assert any(t.error > 1e-3 for t in a.tasks)  # some task is traded off: errors are not all ~0
    assert c_native.solve(q, v).tasks == []  # only on request


@native
def test_diagnostics_in_declared_order(robots):
    """Reports follow the declared task order within a level, as Formulation's, also where an
    inequality task is declared before an equality task."""
    robot = robots["hyq"]
    assert not eq_first(hyq_stack(robot))  # level 3: braking limits (ineq) before the CoM task
    kw = dict(settings=QUADPROG)
    q, v = moving_states(robot, 1)[0]
    a = HierarchyCycle(robot, hyq_stack(robot), engine="native", **kw).solve(q, v, diagnostics=True)
    b = HierarchyCycle(robot, hyq_stack(robot), engine="python", **kw).solve(q, v, diagnostics=True)
    assert [t.name for t in a.tasks] == [t.name for t in b.tasks]


@native
def test_diagnostics_with_a_zero_row_task(robots):
    """A task without rows for these contacts (CoP rows of point feet) gets no report, as in
    Formulation."""
    robot = robots["hyq"]

    def build():
        return Stack([[NewtonEuler(), TorqueLimits()],
                      [ContactConstraint(), CenterOfPressure(name="cop"), FrictionCone(0.7)],
                      [PostureTask(), ForceRegularizer(weight=1e-3)]])

    kw = dict(settings=QUADPROG)
    q, v = moving_states(robot, 1)[0]
    a = HierarchyCycle(robot, build(), engine="native", **kw).solve(q, v, diagnostics=True)
    b = HierarchyCycle(robot, build(), engine="python", **kw).solve(q, v, diagnostics=True)
    assert [t.name for t in a.tasks] == [t.name for t in b.tasks]


@native
def test_solver_settings_changed_after_the_first_cycle_take_effect(robots):
    """The native cycle keeps its compiled cascade bound to the program's level arrays; settings
    given to the cycle afterwards (regularization, backend, backend options) are used from the
    next solve on — the same torques as a cycle built with them."""
    robot = robots["talos14"]
    variables = Variables(robot)
    q, v = next(iter(moving_states(robot, 3)))
    cycle = HierarchyCycle(robot, table2_stack(robot), engine="native")
    first = cycle.solve(q, v, variables)
    cycle.settings = SolverSettings(regularization=1e-3, backend="quadprog", fallback_backend=None)
    changed = cycle.solve(q, v, variables)
    fresh = HierarchyCycle(robot, table2_stack(robot), engine="native",
                           settings=cycle.settings).solve(q, v, variables)
    assert changed.ok and fresh.ok
    np.testing.assert_array_equal(changed.tau, fresh.tau)
    assert np.abs(changed.tau - first.tau).max() > 1e-3  # ε = 1e-3 trades the tasks off visibly
    # backend options too: an iteration limit of 1 makes DAQP fail, the fallback solves (on a
    # state whose cascade needs a level QP)
    cycle.settings = SolverSettings()
    q, v = next((q, v) for q, v in moving_states(robot, 400)
                if cycle.solve(q, v, variables).timings["qps"])
    cycle.settings = SolverSettings(backend_options={"iter_limit": 1})
    limited = cycle.solve(q, v, variables)
    assert limited.ok and "iteration limit" in limited.status
    cycle.settings = SolverSettings()
    assert "iteration limit" not in cycle.solve(q, v, variables).status


# ---------------------------------------------------------------------------- 7. unaligned joints
def unaligned_quadruped():
    """ANYmal C from example-robot-data: six of its twelve joints turn about -x (URDF axis
    "-1 0 0"), which Pinocchio models as JointModelRevoluteUnaligned. Point feet at the FOOT frames
    (the geometry's offset does not matter for the comparison)."""
    import wholebody as wb
    feet = ("LF", "RF", "LH", "RH")
    return wb.load_robot({
        "name": "anymal_c",
        "urdf": "erd:anymal_c_simple_description/urdf/anymal.urdf",
        "srdf": "erd:anymal_c_simple_description/srdf/anymal.srdf",
        "posture": "standing",
        "contacts": [{"name": f"{leg.lower()}_foot", "frame": f"{leg}_FOOT", "type": "point",
                      "radius": 0.03} for leg in feet],
    })


@native
def test_unaligned_joints_equal_python():
    """A model with joints about a negative axis: the compiled update's rigid-body terms equal
    Robot.update's, and a three-level stack gives the Python engine's torques, which satisfy the
    equations of motion computed here with Pinocchio's RNEA."""
    robot = unaligned_quadruped()
    kinds = {robot.model.joints[j].shortname() for j in range(1, robot.model.njoints)}
    assert "JointModelRevoluteUnaligned" in kinds

    def stack():
        return Stack([[NewtonEuler(), TorqueLimits()],
                      [ContactConstraint(), FrictionCone(0.8)],
                      [CoMTask(kp=50.0, kd=14.0), PostureTask(kp=30.0, kd=8.0, weight=0.1)]])

    native_cycle, python_cycle = (HierarchyCycle(robot, stack(), engine=e) for e in ("native", "python"))
    rng = np.random.default_rng(21)
    for _ in range(5):
        q, v = robot.random_state(rng)
        a, b = python_cycle.solve(q, v), native_cycle.solve(q, v)
        terms = native_cycle.engine.terms()
        robot.update(q, v)
        for key in ("M", "h", "com", "A_G"):
            value = getattr(robot, key)
            np.testing.assert_allclose(terms[key], value, rtol=0,
                                       atol=1e-9 * max(1.0, np.abs(value).max()), err_msg=key)
        assert a.ok == b.ok
        np.testing.assert_allclose(b.tau, a.tau, rtol=0, atol=1e-6)
        if not b.ok:
            continue
        model, data = robot.model, robot.model.createData()
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        rows = []
        for c in robot.contacts:  # the sphere's bottom: J_o - [d]x J_w with d = (0, 0, -r)
            J6 = pin.getFrameJacobian(model, data, c.frame_id, pin.LOCAL_WORLD_ALIGNED)
            rows.append(J6[:3] - pin.skew(np.array([0.0, 0.0, -c.spec.radius])) @ J6[3:])
        J = np.vstack(rows)
        eom = pin.rnea(model, data, q, v, b.qdd) - J.T @ b.lam
        np.testing.assert_allclose(eom[:6], 0.0, atol=1e-6 * robot.mass)
        np.testing.assert_allclose(eom[6:], b.tau, atol=1e-6 * robot.mass)


# ---------------------------------------------------------------------------- 9. checks in C++
@native
@pytest.mark.parametrize("bad", [np.nan, np.inf, -1.0])
def test_a_weight_mutated_in_place_names_the_task(robots, bad):
    """Weights are checked when assigned; one changed inside its array afterwards (NaN, inf,
    negative) is caught by the compiled fill's check and named, as the Python engine names it;
    a zero weight on an inequality task likewise (its slack would be free)."""
    robot = robots["talos14"]
    for name, zero_ok in (("com", True), ("friction", False)):
        stack = table1_stack(robot, robot.contact_names)
        task = stack.find(name)
        cycle = HierarchyCycle(robot, stack, engine="native")
        q, v = moving_states(robot, 1)[0]
        cycle.solve(q, v)
        slot = next(s for s in cycle._program.slots if s.task is task)
        m = slot.stop - slot.start
        task.weight = np.ones(m)
        cycle.solve(q, v)
        task.weight[1] = bad
        with pytest.raises(ValueError, match=f"task '{name}'"):
            cycle.solve(q, v)
        task.weight[1] = 0.0
        if zero_ok:
            assert cycle.solve(q, v).ok
        else:
            with pytest.raises(ValueError, match=f"task '{name}'"):
                cycle.solve(q, v)


@native
def test_recover_reports_how_far_the_torque_is_outside_its_limits(robots):
    """The compiled recover returns max(τ − τ_max, τ_min − τ) for the guard: equal to numpy's on
    solved states and on solutions scaled far outside the limits; NaN for a NaN solution."""
    robot = robots["talos14"]
    cycle = HierarchyCycle(robot, table2_stack(robot), engine="native")
    for q, v in moving_states(robot, 3):
        cycle.solve(q, v)
        program = cycle._program
        x = np.linalg.lstsq(program.levels[0].B, program.levels[0].b, rcond=None)[0]
        for scale in (1.0, 50.0):
            excess = cycle.engine.recover(program.id, scale * x)
            tau, lo, hi = program.tau, program.tau_lo, program.tau_hi
            assert excess == np.max(np.maximum(tau - hi, lo - tau))
        assert np.isnan(cycle.engine.recover(program.id, np.full_like(x, np.nan)))
