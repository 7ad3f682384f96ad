"""PassiveWBC (Fahmi et al. 2019): the one-QP controller checked against the equations of motion,
its constraints, an independent formulation (the two-level stack of the hierarchical core), the
slack identity of eq. 33, and in closed loop in the MuJoCo twin."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
import quadprog

from conftest import native_cycle_or_skip

from wholebody.control.passive import STANCE_RANK_TOLERANCE, PassiveWBC, SwingGains
from wholebody.formulation import Formulation
from wholebody.guard import Outcome
from wholebody.solvers import SolverSettings
from wholebody.tasks.contact import friction_faces


def standing_state(robot, rng, noise=0.02):
    q = robot.q_ref.copy()
    q[7:] += rng.normal(scale=noise, size=robot.na)
    v = rng.normal(scale=0.05, size=robot.nv)
    return q, v


STANCE_SETS = [(True, True, True, True), (False, True, True, True), (True, False, False, True)]


@pytest.mark.parametrize("stance", STANCE_SETS)
def test_solution_satisfies_dynamics_and_constraints(robots, rng, stance, plan_for):
    """Eq. 1 (all n+6 rows, via RNEA), eq. 10/32 on stance feet, friction pyramid + normal bounds
    (eqs. 13-14), torque limits (eq. 15) and joint-acceleration bounds (eq. 18)."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names), mu=0.6, engine="python")
    for _ in range(3):
        robot.update(*standing_state(robot, rng))
        sol = wbc.solve(plan_for(robot, rng, stance))
        assert sol.ok, sol.status
        J = robot.stacked_contact_jacobian()
        generalized = np.concatenate([np.zeros(6), sol.tau]) + J.T @ sol.lam
        rnea = pin.rnea(robot.model, robot.model.createData(), robot.q, robot.v, sol.qdd)
        np.testing.assert_allclose(rnea, generalized, atol=1e-6)
        lo, hi = robot.torque_bounds()
        assert np.all(sol.tau <= hi + 1e-9) and np.all(sol.tau >= lo - 1e-9)
        qlo, qhi = wbc.joint_limits.bounds(robot)
        assert np.all(sol.qdd[6:] <= qhi + 1e-6) and np.all(sol.qdd[6:] >= qlo - 1e-6)
        for i, name in enumerate(robot.contact_names):
            f = sol.lam[3 * i:3 * i + 3]
            if not stance[i]:
                np.testing.assert_allclose(f, 0.0, atol=1e-9)
                continue
            assert np.all(friction_faces(np.array([0, 0, 1.0]), 0.6) @ f <= 1e-6)
            assert wbc.f_min - 1e-6 <= f[2] <= wbc.f_max + 1e-6
            acc = robot.contact_jacobians[name] @ sol.qdd + robot.contact_drifts[name]
            point = robot.contact_point(name)
            expected = (wbc.K_st * (wbc._anchors[i] - point)
                        - wbc.D_st * robot.contact_jacobians[name] @ robot.v)
            np.testing.assert_allclose(acc, expected, atol=1e-6)


@pytest.mark.parametrize("stance", STANCE_SETS)
@pytest.mark.parametrize("options", [{}, {"regularization": "torque",
                                          "torque_weights": np.tile([1e-4, 1e-4, 1e-2], 4)},
                                     {"regularization": "force-parallel", "tangential_weight": 1.0},
                                     {"regularization": "force-normal"},
                                     {"swing_slack": "none"}])
def test_matches_two_level_stack(robots, rng, stance, options, plan_for):
    """The dedicated assembly and the generic Formulation (two levels, method="weighted", DAQP)
    solve the same problem: same torques."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names), engine="python", **options)
    robot.update(*standing_state(robot, rng))
    plan = plan_for(robot, rng, stance)
    if options.get("swing_slack") == "none":  # a hard swing task must be reachable: small targets
        plan.foot_position = np.array([robot.data.oMf[robot.contact(n).frame_id].translation
                                       for n in robot.contact_names])
    sol = wbc.solve(plan)
    stack, variables = wbc.as_stack(plan)
    ref = Formulation(robot).solve(stack, variables, settings=SolverSettings(
        method="weighted", backend="daqp", regularization=1e-12, fallback_backend=None))
    assert sol.ok and ref.ok, (sol.status, ref.status)
    scale = np.abs(sol.tau).max()
    np.testing.assert_allclose(sol.tau, ref.tau, atol=1e-6 * scale)
    np.testing.assert_allclose(sol.qdd, ref.qdd, atol=1e-6 * max(1.0, np.abs(sol.qdd).max()))


def test_slack_per_direction_is_weighted_least_squares(rng):
    """Eq. 33 with one slack per row, min c(x) + α‖ε‖² s.t. −ε ≤ Ax − b ≤ ε, ε ≥ 0 (solved as a QP
    over [x, ε] with quadprog), has the same minimiser as c(x) + α‖Ax − b‖² (solved by lstsq):
    the identity PassiveWBC uses to add no variables."""
    for _ in range(20):
        n, k, m = 6, 3, 4
        C, d = rng.normal(size=(m, n)), rng.normal(size=m)
        A, b = rng.normal(size=(k, n)), rng.normal(size=k)
        alpha = 10.0 ** rng.uniform(-1, 3)
        # least squares: min ‖Cx − d‖² + α‖Ax − b‖² + 1e-6‖x‖²
        stacked = np.vstack([C, np.sqrt(alpha) * A, 1e-3 * np.eye(n)])
        x_ls = np.linalg.lstsq(stacked, np.concatenate([d, np.sqrt(alpha) * b, np.zeros(n)]),
                               rcond=None)[0]
        # explicit slacks: variables [x, eps]
        H = np.zeros((n + k, n + k))
        H[:n, :n] = 2 * (C.T @ C + 1e-6 * np.eye(n))
        H[n:, n:] = 2 * alpha * np.eye(k)
        g = np.concatenate([2 * C.T @ d, np.zeros(k)])  # quadprog maximises gᵀx − ½xᵀHx
        # constraints Gᵀ z >= h:  eps − (Ax − b) >= 0,  eps + (Ax − b) >= 0,  eps >= 0
        G = np.vstack([np.hstack([-A, np.eye(k)]), np.hstack([A, np.eye(k)]),
                       np.hstack([np.zeros((k, n)), np.eye(k)])])
        h = np.concatenate([-b, b, np.zeros(k)])
        z = quadprog.solve_qp(H, g, G.T, h)[0]
        np.testing.assert_allclose(z[:n], x_ls, atol=1e-6)
        np.testing.assert_allclose(z[n:], np.abs(A @ x_ls - b), atol=1e-6)


@pytest.mark.parametrize("engine", ["python", "native"])
def test_single_slack_couples_directions(robots, rng, plan_for, engine):
    """With one slack per swing foot the violation is bounded in the ∞-norm: the largest residual
    direction sets ε and every direction's residual is within it. The residual of eq. 12
    (J q̈ + J̇ v − v̇_d, eq. 6's v̇_d) from the robot's frame terms, not the controller's rows."""
    if engine == "native":
        native_cycle_or_skip("_hierarchy_cycle")
    robot = robots["hyq"]
    state = standing_state(robot, rng)
    robot.update(*state)
    plan = plan_for(robot, rng, (False, True, True, True))
    plan.foot_position[0, 0] += 0.5  # unreachable along x in one step: conflicts with limits
    wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names),
                     swing_slack="single", engine=engine)
    sol = wbc.cycle(*state, plan)
    assert sol.ok, sol.status
    assert set(sol.auxiliary) == {f"slack {robot.contact_names[0]}"}
    slack = float(sol.auxiliary[f"slack {robot.contact_names[0]}"][0])
    robot.update(*state)
    frame = robot.contact(robot.contact_names[0]).frame
    J = robot.frame_jacobian(frame)[:3]
    position = robot.frame_placement(frame)[0]
    desired = (wbc.swing.K * (plan.foot_position[0] - position)
               + wbc.swing.D * (plan.foot_velocity[0] - J @ robot.v) + plan.foot_acceleration[0])
    residual = J @ sol.qdd + robot.frame_drift(frame)[:3] - desired
    assert slack > 1e-3
    assert np.all(np.abs(residual) <= slack + 1e-6)
    assert np.abs(residual).max() == pytest.approx(slack, rel=1e-4)  # ε = the ∞-norm


def test_failure_is_a_value(robots, rng, plan_for):
    """An infeasible QP (normal force floor above the robot's weight share, hard constraints) returns
    ok=False with a finite torque within limits and the reason."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names), f_min=1500.0,
                     f_max=2000.0, torque_limit_override={"lf_kfe_joint": 1.0})
    robot.update(*standing_state(robot, rng))
    sol = wbc.solve(plan_for(robot, rng, (True, True, True, True)))
    assert not sol.ok and "daqp" in sol.status
    assert "(1 failed cycle(s) in a row)" in sol.status
    again = wbc.solve(plan_for(robot, rng, (True, True, True, True)))
    assert not again.ok and "(2 failed cycle(s) in a row)" in again.status
    lo, hi = robot.torque_bounds()
    hi[robot.joint_names.index("lf_kfe_joint")] = 1.0
    assert np.all(np.isfinite(sol.tau)) and np.all(sol.tau <= hi) and np.all(sol.tau >= lo)


NAN = float("nan")


@pytest.mark.parametrize("field,kwargs", [
    ("swing_slack", {"swing_slack": "two"}),
    ("regularization", {"regularization": "l1"}),
    ("f_max", {"f_min": 10.0, "f_max": 5.0}),
    ("f_min", {"f_min": -1.0}),
    ("mu", {"mu": NAN}), ("mu", {"mu": -0.5}), ("mu", {"mu": 0.0}),
    ("control_period", {"control_period": 0.0}), ("control_period", {"control_period": NAN}),
    ("control_period", {"control_period": -0.004}),
    ("K_st", {"K_st": NAN}), ("D_st", {"D_st": -1.0}),
    ("R_qdd", {"R_qdd": -1.0}), ("R_force", {"R_force": 0.0}),
    ("slack_weight", {"slack_weight": float("inf")}), ("tangential_weight", {"tangential_weight": -1.0}),
    ("Q", {"Q": (1.0, 1.0, NAN, 1.0, 1.0, 1.0)}), ("Q", {"Q": -1.0}),
    ("torque_weights", {"torque_weights": -1e-4}),
    ("torque_limit_override.lf_kfe_joint", {"torque_limit_override": {"lf_kfe_joint": NAN}}),
    ("torque_limit_override.lf_kfe_joint", {"torque_limit_override": {"lf_kfe_joint": -5.0}}),
    ("unknown joint", {"torque_limit_override": {"knee": 5.0}}),
])
def test_bad_options_name_the_field(robots, field, kwargs):
    """Every number of PassiveConfig is checked when the controller is built: NaN friction used to
    drop the friction cone, a zero control period the joint-limit braking, a NaN override the torque
    limit itself; the error names the field."""
    with pytest.raises(ValueError, match=field):
        PassiveWBC(robots["hyq"], planner=SimpleNamespace(legs=robots["hyq"].contact_names),
                   **kwargs)


def test_swing_gains_checked():
    with pytest.raises(ValueError, match="swing.K"):
        SwingGains(K=NAN)
    with pytest.raises(ValueError, match="swing.D"):
        SwingGains(D=-1.0)


@pytest.mark.parametrize("engine", ["python", "native"])
def test_one_absurd_velocity_sample_does_not_wind_up_the_stance_anchors(robots, engine):
    """Standing still, one state sample with every velocity at 300 (a sensor glitch) moves the
    stance anchors by at most the feet's radius, so the cycles after it solve again without
    reset() (it once wound the slip up by 1.2 m and every later cycle was held)."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, engine=engine)
    q, v = robot.q_ref, np.zeros(robot.nv)
    for k in range(10):
        assert wbc.compute(q, v, 0.004 * k).ok
    wbc.compute(q, np.full(robot.nv, 300.0), 0.04)
    after = [wbc.compute(q, v, 0.044 + 0.004 * k).ok for k in range(50)]
    assert all(after[5:]), after


@pytest.mark.parametrize("engine", ["python", "native"])
def test_torques_within_limits_under_an_impossible_wrench(robots, rng, plan_for, engine):
    """A 3000 N downward external wrench estimate on a weak knee: whatever the QP does, the torque
    that leaves the controller is finite and within the limits it enforces (the robot's, lowered on
    the weak joint), and a solution reported solved satisfies eq. 19 (RNEA) with that torque."""
    robot = robots["hyq"]
    knee = robot.joint_names.index("lf_kfe_joint")
    wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names), engine=engine,
                     torque_limit_override={"lf_kfe_joint": 20.0})
    wbc.impedance.external_wrench = np.array([0.0, 0.0, -3000.0, 0.0, 0.0, 0.0])
    for k in range(6):
        q, v = standing_state(robot, rng)
        robot.update(q, v)
        lo, hi = robot.torque_bounds()  # eq. 15: they depend on q
        hi[knee], lo[knee] = min(hi[knee], 20.0), max(lo[knee], -20.0)
        sol = wbc.cycle(q, v, plan_for(robot, rng, STANCE_SETS[k % len(STANCE_SETS)]))
        assert np.all(np.isfinite(sol.tau)) and np.all(sol.tau <= hi + 1e-9), sol.status
        assert np.all(sol.tau >= lo - 1e-9), sol.status
        if sol.ok:
            J = robot.stacked_contact_jacobian()
            rnea = pin.rnea(robot.model, robot.model.createData(), q, v, sol.qdd)
            np.testing.assert_allclose(rnea[6:] - J[:, 6:].T @ sol.lam, sol.tau, atol=1e-6)
        else:
            assert sol.outcome is Outcome.HELD and sol.status


def _stance_motion(robot, q, base_velocity, slip=None):
    """The generalized velocity with the base at ``base_velocity`` (6,) and the joint rates under
    which every foot's material contact point moves at ``slip`` (n, 3; default: all still, the
    feet roll without slipping)."""
    robot.update(q, np.zeros(robot.nv))
    J = robot.stacked_contact_jacobian()
    target = np.zeros(J.shape[0]) if slip is None else np.asarray(slip, dtype=float).ravel()
    joints = np.linalg.solve(J[:, 6:], target - J[:, :6] @ base_velocity)  # one 3-DoF leg a foot
    return np.concatenate([base_velocity, joints])


@pytest.mark.parametrize("engine", ["python", "native"])
def test_stance_task_ignores_rolling_and_opposes_slip(robots, rng, plan_for, engine):
    """Eq. 32 is active only when a foot slips (Fahmi et al. 2019, Sect. IV): the trunk moves over
    four feet that roll without slipping, so the bottoms of the foot spheres travel (checked), and
    the QP's stance rows demand no foot acceleration; then one foot slides at u and the demand on
    it is the stance task's K_st (-slip) - D_st u, with the slip integrated from the motion fed in."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names), engine=engine)
    dt, q = wbc.control_period, robot.q_ref.copy()
    robot.update(q, np.zeros(robot.nv))
    plan = plan_for(robot, rng, (True,) * 4, swing_noise=(0.0, 0.0, 0.0))
    bottoms0 = robot.contact_points.copy()
    forward = np.array([0.15, 0.0, 0.0, 0.0, 0.0, 0.0])  # trunk forward, m/s

    def step(q, v):
        sol = wbc.cycle(q, v, plan)
        robot.update(q, v)
        acc = robot.stacked_contact_jacobian() @ sol.qdd + robot.stacked_contact_drift()
        assert sol.ok, sol.status
        return pin.integrate(robot.model, q, v * dt), acc.reshape(-1, 3)

    for _ in range(150):  # 0.6 s, the trunk 9 cm ahead
        q, acc = step(q, _stance_motion(robot, q, forward))
        np.testing.assert_allclose(acc, 0.0, atol=1e-6)
    robot.update(q, np.zeros(robot.nv))
    rolled = np.linalg.norm(robot.contact_points - bottoms0, axis=1)
    assert np.all(rolled > 2e-3), rolled  # a touchdown anchor would demand K_st * rolled

    u = np.zeros((4, 3))
    u[0] = (0.05, -0.02, 0.0)  # the first foot slides (m/s)
    for k in range(1, 26):
        q, acc = step(q, _stance_motion(robot, q, np.zeros(6), u))
        expected = -wbc.K_st * k * dt * u - wbc.D_st * u
        np.testing.assert_allclose(acc, expected, atol=1e-6)
        assert acc[0] @ u[0] < 0.0  # against the slip


def test_point_feet_required(robots):
    with pytest.raises(ValueError, match="point contacts"):
        PassiveWBC(robots["talos14"])


@pytest.mark.slow  # closed loop in the twin
@pytest.mark.parametrize("controller", ["passive", "quasi-static"])
def test_crawl_in_the_twin(robots, controller):
    """Closed loop, 250 Hz WBC / 1 kHz twin: HyQ crawls forward without falling or slipping; the
    distance and the trunk pose are the simulator's."""
    from wholebody.planning.trunk import VelocityCommand
    from wholebody.scenarios.locomotion import run_gait
    robot = robots["hyq"]
    # a ramp from 0.04 m/s as in the paper (a step from rest to 0.1 m/s makes the planner's sway
    # leave the support triangle in the first cycle, a planner limitation: one foot then slips 8 mm)
    run = run_gait(robot, controller, "crawl", VelocityCommand.speed_ramp(0.04, 0.1, 1.0, 3.0),
                   duration=5.0)
    assert not run.fell and run.failures == 0
    assert 0.15 < run.distance < 0.4  # 0.14 m on the ramp + 0.2 m at 0.1 m/s commanded
    q, _ = run.sim.state()
    R = pin.Quaternion(q[3:7]).toRotationMatrix()
    assert abs(np.arctan2(R[1, 0], R[0, 0])) < 0.05  # heading kept
    assert run.stance_slip().max() < 0.005
    assert run.tracking(1.0)["linear_max_m"] < 0.02


def test_force_parallel_regularization_spreads_friction_evenly(robots, plan_for):
    """A lateral trunk acceleration on four feet: with ``regularization="force-parallel"`` every
    stance force leans like the net force the QP returns (the same tangential-to-normal ratio on
    each foot, computed from the solution's own sum), so the most-loaded-in-friction foot needs
    less friction than with the paper's regulariser, which shares the tangential force equally."""
    robot = robots["hyq"]
    robot.update(robot.q_ref.copy(), np.zeros(robot.nv))
    rng = np.random.default_rng(4)
    ratios = {}
    for scheme in ("force-normal", "force-parallel"):
        wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names), mu=0.6,
                         regularization=scheme, engine="python")
        plan = plan_for(robot, rng, (True,) * 4)
        plan.trunk = replace(plan.trunk, position=robot.com.copy(), velocity=np.zeros(3),
                             acceleration=np.array([0.5, 2.0, 0.0]), angular_velocity=np.zeros(3),
                             rotation=pin.Quaternion(robot.q[3:7]).toRotationMatrix())
        sol = wbc.solve(plan)
        assert sol.ok, sol.status
        F = sol.lam.reshape(-1, 3)
        net = F.sum(axis=0)
        ratios[scheme] = np.hypot(F[:, 0], F[:, 1]) / F[:, 2]
        if scheme == "force-parallel":
            np.testing.assert_allclose(ratios[scheme], np.hypot(*net[:2]) / net[2], atol=0.01)
    assert ratios["force-parallel"].max() < ratios["force-normal"].max() - 0.02


@pytest.mark.parametrize("engine", ["python", "native"])
def test_dependent_stance_rows_are_met_in_the_least_squares_sense(rng, plan_for, engine):
    """ODRI's 8-DoF Solo (two joints per leg): its stance rows are linearly dependent, so the
    stance task's targets are generally inconsistent. The controller still solves: the dynamics
    hold (RNEA), and the stance feet's accelerations are the least-squares part of the target
    (J_s J_s⁺ b_s, by numpy's lstsq on the rows the test builds), with the hand-assembled QP
    (engine "python") and with the stack of tasks, whose stance task takes an independent set of
    its rows (engine "native")."""
    from conftest import solo8_description

    import wholebody as wb
    from wholebody.cycle import native_available
    solo = wb.load_robot(solo8_description())
    planner = SimpleNamespace(legs=solo.contact_names)
    if engine == "native" and not native_available():
        pytest.skip("the native engine needs the compiled wholebody._hierarchy_cycle")
    wbc = PassiveWBC(solo, planner=planner, engine=engine)
    assert wbc.dependent_stance
    solved = 0
    for stance in [(True,) * 4, (False, True, True, True)]:
        for _ in range(3):
            q, v = standing_state(solo, rng, noise=0.05)
            sol = wbc.cycle(q, v, plan_for(solo, rng, stance, swing_noise=(0.005, 0.05, 0.2)))
            assert sol.ok, sol.status
            solved += 1
            solo.update(q, v)
            J = solo.stacked_contact_jacobian()
            rnea = pin.rnea(solo.model, solo.model.createData(), solo.q, solo.v, sol.qdd)
            np.testing.assert_allclose(rnea, np.concatenate([np.zeros(6), sol.tau]) + J.T @ sol.lam,
                                       atol=1e-6)
            rows = np.repeat(np.array(stance), 3)
            Js = J[rows]
            points = solo.contact_points[rows[::3]]
            target = (-solo.stacked_contact_drift()[rows]
                      + wbc.K_st * (wbc._anchors[rows[::3]] - points).ravel() - wbc.D_st * Js @ solo.v)
            # lstsq truncates the singular values the controller treats as zero
            reachable = Js @ np.linalg.lstsq(Js, target, rcond=STANCE_RANK_TOLERANCE)[0]
            assert np.linalg.norm(Js @ sol.qdd - reachable) < 1e-6 * max(1.0, np.linalg.norm(target))
            if all(stance):
                assert np.linalg.matrix_rank(Js, tol=1e-9) < Js.shape[0]
                assert np.linalg.norm(target - reachable) > 1e-4  # an inconsistent target
    assert solved == 6


def test_posture_regularizer_damps_the_legs_null_space(rng, plan_for):
    """Legs of five joints on point feet: with every foot held, the joints still have a null space
    of the stance rows (computed here with scipy). At the posture with a joint velocity inside
    it, the posture regulariser adds −2ζω q̇ to the joints' acceleration along it: the solution's
    q̈ there, with the regulariser minus without (posture_frequency=0, where nothing opposes the
    motion), is −2ζω per unit of q̇."""
    from conftest import centauro_description
    from scipy.linalg import null_space

    import wholebody as wb
    robot = wb.load_robot(centauro_description())
    robot.update(robot.q_ref.copy(), np.zeros(robot.nv))
    J = robot.stacked_contact_jacobian()
    N = null_space(J[:, 6:])  # joint motions that move no foot with the base still
    assert N.shape[1] == robot.na - J.shape[0] > 0
    v = np.zeros(robot.nv)
    v[6:] = N @ rng.normal(size=N.shape[1])
    v[6:] *= 0.5 / np.linalg.norm(v[6:])
    robot.update(robot.q_ref.copy(), v)
    plan = plan_for(robot, rng, (True,) * 4)
    plan.trunk.position, plan.trunk.velocity = robot.com.copy(), robot.vcom.copy()
    along = {}
    for omega in (0.0, None):
        wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names),
                         posture_frequency=omega, engine="python")
        sol = wbc.solve(plan)
        assert sol.ok, sol.status
        along[omega] = (N.T @ sol.qdd[6:]) @ (N.T @ v[6:]) / (v[6:] @ v[6:])
    damping = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names)).posture_D
    assert along[None] - along[0.0] == pytest.approx(-damping, rel=0.05)


def test_posture_regularizer_leaves_three_joint_legs_alone(robots, rng, plan_for):
    """On HyQ (three joints per leg, every joint determined by its foot's task) the posture
    regulariser is off: the same torques as with posture_frequency=0, away from the posture."""
    robot = robots["hyq"]
    robot.update(*standing_state(robot, rng, noise=0.1))
    plan = plan_for(robot, rng, (True, False, True, True))
    taus = [PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names),
                       posture_frequency=omega, engine="python").solve(plan).tau
            for omega in (None, 0.0)]
    np.testing.assert_array_equal(taus[0], taus[1])


def test_quasi_static_baseline_holds_only_the_legs_null_space(rng, plan_for):
    """The quasi-static baseline on legs of five joints: what the posture hold adds to the static
    map's torques moves no foot force (it lies in each leg Jacobian's null space, checked with
    scipy) and pushes the joints back toward the posture; on HyQ's three-joint legs it adds
    nothing."""
    from conftest import centauro_description
    from scipy.linalg import null_space

    import wholebody as wb
    from wholebody.control.quasi_static import QuasiStaticController
    robot = wb.load_robot(centauro_description())
    q = robot.q_ref.copy()
    robot.update(q, np.zeros(robot.nv))
    J = robot.stacked_contact_jacobian()
    held = QuasiStaticController(robot, SimpleNamespace(legs=robot.contact_names))
    legs = [cols for _, cols in held._redundant_legs]
    assert len(legs) == 4
    # displace the first leg's joints inside its null space
    N0 = null_space(J[0:3, 6 + legs[0]])
    q[7 + legs[0]] += N0 @ np.array([0.05, -0.03])
    robot.update(q, np.zeros(robot.nv))
    plan = plan_for(robot, rng, (True,) * 4)
    free = QuasiStaticController(robot, SimpleNamespace(legs=robot.contact_names))
    free._redundant_legs = []
    added = held.solve(plan).tau - free.solve(plan).tau
    J = robot.stacked_contact_jacobian()
    for i, cols in enumerate(legs):
        Jl = J[3 * i:3 * i + 3, 6 + cols]
        np.testing.assert_allclose(Jl @ added[cols], 0.0, atol=1e-8 * max(1.0, np.abs(added).max()))
    displacement = pin.difference(robot.model, q, robot.q_ref)[6:]
    assert added[legs[0]] @ displacement[legs[0]] > 0.0
    hyq = wb.load_robot("hyq")
    assert QuasiStaticController(hyq, SimpleNamespace(legs=hyq.contact_names))._redundant_legs == []


def test_quasi_static_baseline_redistributes_forces_within_torque_limits(robots, rng, plan_for):
    """The static map τ = g − Jᵀ F is affine in F, so the baseline meets the stance legs' torque
    limits by redistributing the forces. One joint's limit set to 60 % of what the force QP asks of
    it without limits: the torque stays inside (solved, not clipped), the limit is active, the
    torque is the static map recomputed with Pinocchio's RNEA, and the forces stay in the
    pyramid. Limits no forces can meet (every joint at 0.1 Nm with the normal forces capped at
    0.01 N: the legs' own gravity torques are larger) are flagged and the torques still leave
    inside the limits."""
    from wholebody.control.quasi_static import QuasiStaticController
    robot = robots["hyq"]
    robot.update(*standing_state(robot, rng, noise=0.05))
    plan = plan_for(robot, rng, (True,) * 4)
    legs = SimpleNamespace(legs=robot.contact_names)
    free = QuasiStaticController(robot, legs).solve(plan)
    assert free.outcome is Outcome.SOLVED
    knee = int(np.argmax(np.abs(free.tau) / robot.model.effortLimit[6:]))
    name = robot.joint_names[knee]
    bound = 0.6 * abs(free.tau[knee])
    baseline = QuasiStaticController(robot, legs, torque_limit_override={name: bound})
    sol = baseline.solve(plan)
    assert sol.outcome is Outcome.SOLVED, sol.status
    assert abs(sol.tau[knee]) == pytest.approx(bound, rel=1e-6)  # active
    gravity = pin.rnea(robot.model, robot.model.createData(), robot.q, np.zeros(robot.nv),
                       np.zeros(robot.nv))
    J = robot.stacked_contact_jacobian()
    np.testing.assert_allclose(sol.tau, gravity[6:] - J[:, 6:].T @ sol.lam, atol=1e-8)
    assert np.all(np.abs(sol.tau) <= robot.model.effortLimit[6:] + 1e-9)
    for i in range(4):
        f = sol.lam[3 * i:3 * i + 3]
        assert np.all(friction_faces(np.array([0.0, 0.0, 1.0]), robot.friction) @ f <= 1e-9)
    # the same joint's limit met, the trunk wrench is matched less well than without it
    assert sol.level_costs[0] > free.level_costs[0]

    weak = QuasiStaticController(robot, legs, f_max=0.01,
                                 torque_limit_override={j: 0.1 for j in robot.joint_names})
    sol = weak.solve(plan)
    assert sol.outcome is Outcome.CLIPPED and "out of reach" in sol.status
    assert np.all(np.abs(sol.tau) <= 0.1)


@pytest.mark.parametrize("engine", ["python", "native"])
@pytest.mark.parametrize("gain", [0.0, 0.3])
def test_footholds_get_the_measured_com_velocity(robots, engine, gain):
    """The Raibert feedback of the footholds (``feedback_gain`` k) is fed the CoM velocity of the
    state the controller reads: a foot lifting off is sent to the feedback-free target plus k
    times the measured minus the commanded CoM velocity, the measured one from Pinocchio's CoM
    velocity at that state (not the controller's)."""
    from wholebody.planning import GaitPlanner, VelocityCommand, trot
    robot = robots["hyq"]
    command = VelocityCommand((0.2, 0.0), (0.2, 0.0), (0.0, 1.0))
    planner = GaitPlanner.for_robot(robot, trot(0.8, start=0.5, legs=robot.contact_names),
                                    command, feedback_gain=gain, start_shift=False)
    free = GaitPlanner.for_robot(robot, trot(0.8, start=0.5, legs=robot.contact_names),
                                 command, start_shift=False)
    wbc = PassiveWBC(robot, planner, engine=engine)
    q, v = robot.q_ref.copy(), np.zeros(robot.nv)
    v[:3] = (0.05, -0.3, 0.02)  # base linear velocity (local = world at q_ref's orientation)
    t = 0.5 + 1e-4  # just after the first diagonal's lift-off
    wbc.compute(q, v, t)
    plan = wbc.last_plan
    data = robot.model.createData()
    pin.centerOfMass(robot.model, data, q, v)
    measured = data.vcom[0][:2]
    _, v_ref, _, _, _ = free.trunk.nominal(t)
    swinging = [i for i, leg in enumerate(planner.legs) if not plan.contact[i]]
    assert len(swinging) == 2
    for i in swinging:
        base = free.touchdown_target(planner.legs[i], plan.touchdown_time[i]).position
        expected = base[:2] + gain * (measured - v_ref)
        np.testing.assert_allclose(plan.touchdown_position[i][:2], expected, atol=1e-9)


@pytest.mark.parametrize("engine", ["python", "native"])
def test_nonfinite_external_wrench_is_a_held_cycle(robots, engine):
    """An external-wrench estimate with a NaN makes W_d of eq. 4 NaN: the cycle is a held value
    (the previous torque, finite), not an exception, and the next cycle with a finite estimate
    solves again."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, engine=engine)
    q, v = robot.q_ref, np.zeros(robot.nv)
    first = wbc.compute(q, v, 0.0)
    wbc.impedance.external_wrench = np.array([0.0, 0.0, np.nan, 0.0, 0.0, 0.0])
    held = wbc.compute(q, v, 0.004)
    assert held.outcome is Outcome.HELD and "held" in held.status
    np.testing.assert_allclose(held.tau, first.tau, atol=1e-12)
    wbc.impedance.external_wrench = np.zeros(6)
    assert wbc.compute(q, v, 0.008).ok


def test_quasi_static_pyramid_follows_the_normals_and_mu_of_each_cycle(robots, rng, plan_for):
    """The baseline keeps the friction rows of the terrain normals it met; a new normal or a new
    friction coefficient between cycles gives the new pyramid (eq. 13): each stance foot's rows
    are the faces written from the normal and ``mu`` of that cycle, and its force lies inside
    them, on a ramp after flat ground and after ``mu`` changes."""
    from wholebody.control.quasi_static import QuasiStaticController
    robot = robots["hyq"]
    robot.update(*standing_state(robot, rng, noise=0.02))
    ctrl = QuasiStaticController(robot, SimpleNamespace(legs=robot.contact_names))
    ramp = (0.0, -np.sin(0.2), np.cos(0.2))
    for normal, mu in [((0.0, 0.0, 1.0), ctrl.mu), (ramp, ctrl.mu), (ramp, 0.3),
                       ((0.0, 0.0, 1.0), 0.3)]:
        ctrl.mu = mu
        plan = plan_for(robot, rng, (True,) * 4, normal=normal)
        sol = ctrl.solve(plan)
        assert sol.ok, sol.status
        unit = np.asarray(normal) / np.linalg.norm(normal)
        for i in range(4):
            faces = friction_faces(unit, mu)
            np.testing.assert_allclose(ctrl.A[5 * i:5 * i + 4, 3 * i:3 * i + 3], faces,
                                       atol=1e-12)
            np.testing.assert_allclose(ctrl.A[5 * i + 4, 3 * i:3 * i + 3], unit, atol=1e-12)
            assert np.all(faces @ sol.lam[3 * i:3 * i + 3] <= 1e-7)
