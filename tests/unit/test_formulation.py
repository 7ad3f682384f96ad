"""Tasks, torque elimination and the whole-body solve on real robot models, checked against the
equations of motion (eq. 1), the contact constraint (eq. 2), Pinocchio's centroidal dynamics, and
the full formulation as an independent route to the same answer."""

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from wholebody.formulation import Formulation, Solution, Stack
from wholebody.solvers import SolverSettings
from wholebody.tasks import (CenterOfPressure, CoMTask, ContactConstraint, ForceRegularizer,
                             FrameTask, FrictionCone, FullDynamics, JointAccelerationLimits,
                             MomentumForce, MomentumPD, NewtonEuler, NormalForceBounds,
                             PostureTask, TorqueLimits, momentum_map)
from wholebody.variables import Variables

PRESETS = ("talos14", "talos", "hyq")

#: DAQP at a small ε (eq. 5), where the solution barely moves from the exact hierarchy
DAQP_TIGHT = SolverSettings(regularization=1e-8, backend="daqp")


def standard_stack(robot, full=False, pin_everything=False):
    """Herzog et al. 2016 Table 2 (humanoids) / its point-foot analogue (HyQ)."""
    contact_rows = [ContactConstraint(), FrictionCone(robot.friction), JointAccelerationLimits()]
    if robot.contacts[0].spec.type == "rectangle":
        contact_rows.append(CenterOfPressure(weight=1e4))
    else:
        contact_rows.append(NormalForceBounds(f_min=5.0))
    last = [MomentumPD(), PostureTask(weight=0.1, base_kp=10.0 if pin_everything else 0.0,
                                      base_kd=5.0 if pin_everything else 0.0),
            ForceRegularizer(weight=1e-2 if pin_everything else 1e-4)]
    return Stack([[FullDynamics() if full else NewtonEuler(), TorqueLimits()], contact_rows, last])


def selection(robot):
    S_T = np.zeros((robot.nv, robot.na))
    S_T[6:] = np.eye(robot.na)
    return S_T


def check_physics(robot, sol: Solution, variables, contact_tol=None):
    J = robot.stacked_contact_jacobian(variables.contacts)
    eom = robot.M @ sol.qdd + robot.h - selection(robot) @ sol.tau - J.T @ sol.lam
    lo, hi = robot.torque_bounds()
    assert np.all(np.isfinite(sol.tau))
    assert np.all(sol.tau >= lo - 1e-6) and np.all(sol.tau <= hi + 1e-6)
    if contact_tol is not None:
        np.testing.assert_allclose(J @ sol.qdd + robot.stacked_contact_drift(variables.contacts), 0,
                                   atol=contact_tol)
    return np.abs(eom).max()


def nominal_state(robot, rng, scale=0.2):
    """The reference posture with small random joint offsets and velocities (feet near the ground)."""
    q = robot.q_ref.copy()
    q[7:] += rng.normal(scale=0.02, size=robot.na)
    q[7:] = np.clip(q[7:], robot.q_min + 0.05, robot.q_max - 0.05)
    v = rng.normal(scale=scale, size=robot.nv)
    return q, v


@pytest.mark.parametrize("name", PRESETS)
def test_solution_satisfies_dynamics_contacts_and_limits(robots, name, rng):
    robot = robots[name]
    for _ in range(3):
        robot.update(*nominal_state(robot, rng))
        variables = Variables(robot)
        sol = Formulation(robot).solve(standard_stack(robot), variables, settings=DAQP_TIGHT)
        assert sol.ok, sol.status
        assert check_physics(robot, sol, variables, contact_tol=1e-6) < 1e-8
        assert sol.timings["total"] > 0 and len(sol.tasks) == len(standard_stack(robot).tasks())


@pytest.mark.parametrize("name", PRESETS)
def test_reduced_equals_full(robots, name, rng):
    """Eliminating tau with eq. 14 gives the same (qdd, lambda, tau) as keeping all of eq. 1 —
    compared on a stack whose last level determines every variable (so the regulariser, which acts
    on different vectors in the two formulations, cannot pick different points)."""
    robot = robots[name]
    robot.update(*nominal_state(robot, rng))
    variables = Variables(robot)
    reduced = Formulation(robot, reduced=True).solve(
        standard_stack(robot, pin_everything=True), variables, settings=DAQP_TIGHT)
    full = Formulation(robot, reduced=False).solve(
        standard_stack(robot, full=True, pin_everything=True), variables, settings=DAQP_TIGHT)
    assert reduced.ok and full.ok
    for a, b in ((reduced.qdd, full.qdd), (reduced.lam, full.lam), (reduced.tau, full.tau)):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5 * (1 + np.abs(b).max()))
    assert check_physics(robot, full, variables) < 1e-6


@pytest.mark.parametrize("name", PRESETS)
def test_analytic_first_level_matches_qp(robots, name, rng):
    """Sect. 2.4: the analytic level 1 (no QP) reaches the same solution as solving level 1."""
    robot = robots[name]
    robot.update(*nominal_state(robot, rng))
    variables = Variables(robot)
    f = Formulation(robot)
    stack = standard_stack(robot, pin_everything=True)
    analytic = f.solve(stack, variables, settings=replace(DAQP_TIGHT, analytic_first_level=True))
    qp = f.solve(stack, variables, settings=replace(DAQP_TIGHT, analytic_first_level=False))
    np.testing.assert_allclose(analytic.tau, qp.tau, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(analytic.level_costs, qp.level_costs, rtol=1e-4, atol=1e-8)
    assert check_physics(robot, analytic, variables) < 1e-8


def test_single_support_contacts(robots, rng):
    """With one active contact (Table 4), the swing foot follows its frame task and the stance
    contact carries the robot."""
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    variables = Variables(robot, ["left_sole"])
    swing = FrameTask("right_sole_link", kp=100.0, kd=20.0, mask="position")
    pos, _ = robot.frame_placement("right_sole_link")
    swing.position = pos + np.array([0.0, 0.0, 0.05])
    stack = Stack([[NewtonEuler(), TorqueLimits()],
                   [ContactConstraint(), CenterOfPressure(), FrictionCone(0.8)],
                   [MomentumPD(), swing, PostureTask(weight=0.1), ForceRegularizer(weight=1e-4)]])
    sol = Formulation(robot).solve(stack, variables)
    assert sol.ok and set(sol.forces) == {"left_sole"}
    assert check_physics(robot, sol, variables, contact_tol=1e-4) < 1e-8
    assert sol.forces["left_sole"][2] > 0.5 * robot.mass * 9.81


def test_friction_cone_rows_match_geometry(robots):
    """A force inside the cone (by angle) satisfies the rows, one outside violates them."""
    robot = robots["hyq"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    variables = Variables(robot, ["lf_foot"])
    normal = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    rows = FrictionCone(0.5, normals={"lf_foot": normal}).rows(robot, variables)
    t = np.cross(normal, [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    inside = 100 * normal + 30 * t  # tangential/normal = 0.3 < 0.5 / sqrt(2)... inside the pyramid
    outside = 100 * normal + 80 * t
    assert np.all(rows.lam @ inside <= rows.upper)
    assert np.any(rows.lam @ outside > rows.upper)


def test_friction_cone_torsion_bounds_the_yaw_moment_by_the_corner_friction(robots):
    """torsion=True: with the CoP at the centre of a flat sole and no tangential force, the yaw
    moment may reach what friction at the corners under equal loads gives — mu f_n/4 times the
    corners' distances summed over the directions of a rigid rotation, here mu f_n (X + Y) for
    a square pyramid (each corner's tangential force mu f_n/4 along both sole axes) — and not
    beyond; without torsion the yaw moment is free (the papers' 4 rows)."""
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    variables = Variables(robot, ["left_sole"])
    mu, fn = 0.6, 400.0
    R = robot.data.oMf[robot.contact("left_sole").frame_id].rotation
    hx, hy = robot.contact("left_sole").spec.half_size
    # corners at (±hx, ±hy): the square pyramid's corner force (±mu, ±mu) fn/4 that turns about
    # the normal gives x fy - y fx = mu fn/4 (hx + hy) per corner
    moment = 4 * (mu * fn / 4) * (hx + hy)
    normal = R[:, 2]
    with_torsion = FrictionCone(mu, normals={"left_sole": normal}, torsion=True).rows(robot, variables)
    plain = FrictionCone(mu, normals={"left_sole": normal}).rows(robot, variables)
    assert with_torsion.lam.shape[0] == 12 and plain.lam.shape[0] == 4
    for scale, holds in ((0.99, True), (1.01, False), (-0.99, True), (-1.01, False)):
        wrench = np.concatenate([fn * normal, scale * moment * normal])
        assert bool(np.all(with_torsion.lam @ wrench <= with_torsion.upper)) == holds
        assert np.all(plain.lam @ wrench <= plain.upper)


def test_center_of_pressure_rows_match_geometry(robots):
    """A vertical force applied at a point of the sole gives a wrench about the sole frame whose CoP
    rows hold iff the point lies in the rectangle."""
    robot = robots["talos14"]
    q = robot.q_ref.copy()
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.05, -0.1, 0.7)).coeffs()  # tilted, yawed
    robot.update(q, np.zeros(robot.nv))
    variables = Variables(robot, ["left_sole"])
    rows = CenterOfPressure().rows(robot, variables)
    c = robot.contact("left_sole")
    placement = robot.data.oMf[c.frame_id]
    hx, hy = c.spec.half_size
    force = placement.rotation @ np.array([10.0, -5.0, 300.0])
    for local, inside in (((0.9 * hx, -0.9 * hy), True), ((1.1 * hx, 0.0), False),
                          ((0.0, -1.1 * hy), False), ((-0.5 * hx, 0.5 * hy), True)):
        p = placement.act(np.array([local[0], local[1], 0.0]))
        wrench = np.concatenate([force, np.cross(p - placement.translation, force)])
        assert np.all(rows.lam @ wrench <= 1e-9) == inside, local


def test_momentum_map_matches_centroidal_dynamics(robots, rng):
    """Eq. 21: for (qdd, lambda) satisfying Newton-Euler, Pinocchio's momentum rate
    A_G qdd + Adot_G v equals G lambda + [m g; 0]."""
    for name in PRESETS:
        robot = robots[name]
        robot.update(*nominal_state(robot, rng))
        variables = Variables(robot)
        sol = Formulation(robot).solve(standard_stack(robot), variables)
        rate = robot.A_G @ sol.qdd + robot.A_G_dot_v
        G = momentum_map(robot, variables.contacts)
        gravity = np.concatenate([robot.mass * robot.model.gravity.linear, np.zeros(3)])
        np.testing.assert_allclose(rate, G @ sol.lam + gravity, atol=1e-6 * robot.mass)


def test_momentum_force_task_reaches_lqr_law(robots):
    """Eq. 24 as the only objective: the momentum produced equals G (k - K s)."""
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    variables = Variables(robot)
    K = np.zeros((12, 9))
    K[2, 2] = K[8, 2] = 1000.0  # vertical force feedback on CoM height
    k = np.zeros(12)
    k[2] = k[8] = robot.mass * 9.81 / 2 + 1000.0 * robot.com[2] - 50.0
    task = MomentumForce(K, k)
    stack = Stack([[NewtonEuler(), TorqueLimits()], [ContactConstraint()],
                   [task], [PostureTask(weight=0.1)]])
    sol = Formulation(robot).solve(stack, variables)
    G = momentum_map(robot, variables.contacts)
    state = np.concatenate([robot.com, robot.h_G])
    np.testing.assert_allclose(G @ sol.lam, G @ (k - K @ state), atol=1e-4)
    assert sum(f[2] for f in sol.forces.values()) == pytest.approx(robot.mass * 9.81 - 100.0, abs=1e-3)


def test_com_task_tracks(robots):
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    com = CoMTask(kp=100.0, kd=20.0)
    com.position = robot.com + np.array([0.02, 0.0, -0.03])
    stack = Stack([[NewtonEuler(), TorqueLimits()], [ContactConstraint(), CenterOfPressure()],
                   [com], [PostureTask(weight=0.1), ForceRegularizer(weight=1e-4)]])
    errors = {}
    for eps in (1e-4, 1e-6, 1e-8):
        sol = Formulation(robot).solve(stack, Variables(robot),
                                       settings=SolverSettings(regularization=eps))
        acc = robot.J_com @ sol.qdd + robot.com_drift
        errors[eps] = np.abs(acc - [2.0, 0.0, -3.0]).max()
    # the eps ||x||^2 of eq. 5 trades the task off by O(eps): ~4 % at the paper's 1e-4
    assert errors[1e-8] < 1e-5 and errors[1e-6] < 2e-3
    assert errors[1e-6] < errors[1e-4] / 30


def test_stack_table_lists_ranks_and_rows(robots):
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    text = standard_stack(robot).table(robot, Variables(robot))
    assert "6 eq" in text and "NewtonEuler" in text
    assert "14 ineq" in text and "TorqueLimits" in text
    assert "12 eq" in text and "ContactConstraint" in text
    assert "8 ineq" in text and "CenterOfPressure" in text


def test_torque_limits_bind_and_are_respected(robots):
    """A tight torque limit is met exactly while the contacts still hold."""
    robot = robots["hyq"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    variables = Variables(robot)
    stack = Stack([[NewtonEuler(), TorqueLimits(upper_override={"lf_kfe_joint": 26.0})],
                   [ContactConstraint(), FrictionCone(0.7), NormalForceBounds(f_min=1.0)],
                   [MomentumPD(), PostureTask(weight=0.1), ForceRegularizer(weight=1e-4)]])
    sol = Formulation(robot).solve(stack, variables)
    kfe = robot.joint_names.index("lf_kfe_joint")
    assert sol.ok and abs(sol.tau[kfe]) <= 26.0 + 1e-6
    check_physics(robot, sol, variables, contact_tol=1e-4)
    unconstrained = Formulation(robot).solve(Stack([[NewtonEuler(), TorqueLimits()]] +
                                                   stack.levels[1:]), variables)
    assert abs(unconstrained.tau[kfe]) > 26.0  # the limit was really binding


def test_failure_is_a_flagged_safe_torque(robots, monkeypatch):
    """A backend failure never raises: the solution is flagged and its torque finite, in limits."""
    import wholebody.formulation as formulation
    from wholebody.solvers.hierarchy import HierarchySolution

    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    stack = standard_stack(robot)
    f = Formulation(robot)
    n = f.size(Variables(robot))

    def failing(levels, **kwargs):
        return HierarchySolution(x=np.full(n, 1e6), costs=np.zeros(len(levels)), eq_residuals=[],
                                 ineq_violations=[], status="backend failed: test", ok=False,
                                 timings={}, method="cascade", levels_solved=0,
                                 nullspace_dims=np.zeros(0, int), warnings=())

    monkeypatch.setattr(formulation, "solve_hierarchy", failing)
    sol = f.solve(stack, Variables(robot))
    lo, hi = robot.torque_bounds()
    assert not sol.ok and "backend failed" in sol.status
    assert np.all(np.isfinite(sol.tau)) and np.all(sol.tau >= lo) and np.all(sol.tau <= hi)


def test_bad_task_input_is_named(robots):
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    with pytest.raises(ValueError, match="not active"):
        FrictionCone(0.5, contacts=["right_sole"]).rows(robot, Variables(robot, ["left_sole"]))
    with pytest.raises(ValueError, match="active_contacts"):
        Variables(robot, ["left_sole", "left_sole"])
    with pytest.raises(ValueError, match="contact"):
        Variables(robot, ["nose"])
    com = CoMTask()
    com.position = np.array([np.nan, 0.0, 1.0])
    with pytest.raises(ValueError, match="level 2"):
        Formulation(robot).solve(Stack([[NewtonEuler()], [com]]), Variables(robot))
    with pytest.raises(ValueError, match="reduced"):
        Formulation(robot).solve(Stack([[FullDynamics()]]), Variables(robot))


@pytest.mark.parametrize("name", PRESETS)
def test_backends_agree_on_robots(robots, name, rng):
    """Goldfarb-Idnani (quadprog, the paper's solver) and DAQP give the same whole-body solution."""
    robot = robots[name]
    robot.update(*nominal_state(robot, rng))
    variables = Variables(robot)
    f = Formulation(robot)
    a = f.solve(standard_stack(robot), variables, settings=SolverSettings(backend="quadprog"))
    b = f.solve(standard_stack(robot), variables, settings=SolverSettings(backend="daqp"))
    assert a.ok and b.ok
    np.testing.assert_allclose(a.level_costs, b.level_costs, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(a.tau, b.tau, rtol=1e-4, atol=1e-3)


def test_task_whose_rows_change_shape_is_replanned(robots):
    """The preallocated layout follows a task whose row count changes (0 -> 1 -> 2 rows)."""
    from wholebody.tasks import Task, TaskRows

    class Toggle(Task):
        def __init__(self):
            super().__init__("toggle")
            self.joints = []

        def rows(self, robot, variables):
            A = np.zeros((len(self.joints), robot.nv))
            A[np.arange(len(self.joints)), [6 + j for j in self.joints]] = 1.0
            return TaskRows(qdd=A, lam=None, tau=None, target=np.full(len(self.joints), 3.0))

    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    toggle = Toggle()
    stack = Stack([[NewtonEuler(), TorqueLimits()], [toggle], [PostureTask(weight=0.1)]])
    f, variables = Formulation(robot), Variables(robot)
    assert f.solve(stack, variables).ok
    for joints in ([0], [0, 1]):
        toggle.joints = joints
        sol = f.solve(stack, variables)
        assert sol.ok
        np.testing.assert_allclose(sol.qdd[[6 + j for j in joints]], 3.0, atol=1e-4)  # eps
        assert [t.rows for t in sol.tasks if t.name == "toggle"] == [len(joints)]
