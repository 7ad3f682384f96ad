"""The QP of PassiveWBC (Fahmi et al. 2019, eq. 7), assembled by hand (tests/passive_oracle.py),
as solved through the DAQP adapter (solvers.backends.solve_daqp_qp, warm-started) against quadprog
(Goldfarb–Idnani) on the very same arrays: same optimum. Also the adapter alone on random QPs with
simple bounds, senses and warm starts, and its failure values, and the hand assembly's blocks."""

from types import SimpleNamespace

import numpy as np
import pytest
import quadprog

from wholebody.control.passive import PassiveConfig, PassiveWBC
from wholebody.solvers.backends import DAQP_EXIT, DAQP_SENSE_EQ, solve_daqp_qp

from passive_oracle import PassiveQP, hand_assembled


def quadprog_solve(H, g, A, upper, lower, sense):
    """min ½xᵀHx + gᵀx over DAQP's form (simple bounds on the first variables, then A's rows;
    sense 5 = equality) by quadprog: → (x, cost)."""
    n = H.shape[0]
    rows = np.vstack([np.eye(n)[:len(upper) - A.shape[0]], A])
    eq = sense == DAQP_SENSE_EQ
    lo = ~eq & np.isfinite(lower)
    up = ~eq & np.isfinite(upper)
    C = np.vstack([rows[eq], rows[lo], -rows[up]])
    b = np.concatenate([upper[eq], lower[lo], -upper[up]])
    x = quadprog.solve_qp(H, -g, C.T, b, int(eq.sum()))[0]
    return x, 0.5 * x @ H @ x + g @ x


STANCES = [(True, True, True, True), (False, True, True, True), (True, False, False, True),
           (True, True, False, True)]


@pytest.mark.parametrize("options", [{}, {"swing_slack": "none"}, {"swing_slack": "single"},
                                     {"regularization": "torque", "mu": 0.5, "f_min": 5.0},
                                     {"regularization": "force-normal", "mu": 0.4}])
def test_adapter_optimum_matches_quadprog(robots, rng, options, plan_for):
    """Cycle after cycle (so that DAQP is warm-started from the previous multipliers), the x the
    controller got through the adapter is quadprog's optimum of the same arrays."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names), engine="python", **options)
    for k in range(8):
        q = robot.q_ref.copy()
        q[7:] += rng.normal(scale=0.03, size=robot.na)
        robot.update(q, rng.normal(scale=0.05, size=robot.nv))
        plan = plan_for(robot, rng, STANCES[k % len(STANCES)], swing_noise=(0.005, 0.05, 0.2))
        sol = wbc.solve(plan)  # this cycle's stance anchors, W_d and torque bounds
        assert sol.ok, sol.status
        ref = hand_assembled(wbc, plan, None if k == 0 else qp)
        qp = ref.qp
        x_ref, cost_ref = quadprog_solve(qp.H, qp.g, qp.A, qp.upper, qp.lower, qp.sense)
        x = ref.x
        cost = 0.5 * x @ qp.H @ x + qp.g @ x
        assert cost == pytest.approx(cost_ref, rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(x, x_ref, atol=1e-7 * max(1.0, np.abs(x_ref).max()))
    assert qp.dual is not None  # the next cycle is warm-started


def test_adapter_random_qps_match_quadprog(rng):
    """Random strictly convex QPs with simple bounds, equality and two-sided rows: the adapter's
    optimum is quadprog's, cold and warm-started (from a neighbouring QP's multipliers)."""
    for _ in range(30):
        n, m = 8, 10
        L = rng.normal(size=(n, n))
        H = L @ L.T + 0.1 * np.eye(n)
        g, A = rng.normal(size=n), rng.normal(size=(m, n))
        x0 = rng.normal(size=n)  # a feasible point
        ax = A @ x0
        upper = np.concatenate([x0 + rng.uniform(0.1, 1.0, n), ax + rng.uniform(0.0, 1.0, m)])
        lower = np.concatenate([x0 - rng.uniform(0.1, 1.0, n), ax - rng.uniform(0.0, 1.0, m)])
        sense = np.zeros(n + m, dtype=np.int32)
        sense[n:n + 2] = DAQP_SENSE_EQ
        upper[n:n + 2] = lower[n:n + 2] = ax[:2]
        upper[n + 2], lower[n + 2] = np.inf, -np.inf  # a free row
        x_ref, _ = quadprog_solve(H, g, A, upper, lower, sense)
        cold = solve_daqp_qp(H, g, A, upper, lower, sense)
        assert cold.ok and cold.status == "optimal" and cold.flag in (1, 2)
        np.testing.assert_allclose(cold.x, x_ref, atol=1e-7)
        warm = solve_daqp_qp(H, g + 1e-3 * rng.normal(size=n), A, upper, lower, sense,
                             dual_start=cold.dual)
        again = solve_daqp_qp(H, g, A, upper, lower, sense, dual_start=warm.dual)
        assert again.ok
        np.testing.assert_allclose(again.x, x_ref, atol=1e-7)


def test_adapter_failure_is_a_value():
    """Infeasible rows: ok False, x and the warm start None, the status names DAQP's flag."""
    H, g = np.eye(2), np.zeros(2)
    A = np.array([[1.0, 0.0], [1.0, 0.0]])
    upper, lower = np.array([-1.0, np.inf]), np.array([-np.inf, 1.0])
    result = solve_daqp_qp(H, g, A, upper, lower, np.zeros(2, dtype=np.int32))
    assert not result.ok and result.x is None and result.dual is None
    assert result.flag not in (1, 2)
    assert result.status == f"daqp: {DAQP_EXIT[result.flag]} ({result.flag})"


def test_layout_blocks():
    """The row blocks of eq. 7: dynamics nv rows, 3 feet rows and 5 friction rows per foot (and 3
    paired rows per foot plus one slack variable per foot with single slacks)."""
    qp = PassiveQP(18, 4)
    assert (qp.n, qp.m, qp.r_feet, qp.r_fric) == (30, 18 + 12 + 20, 18, 30)
    single = PassiveQP(18, 4, single_slack=True)
    assert (single.n, single.m, single.r_single) == (34, 18 + 12 + 20 + 12, 50)
    assert single.A.shape == (62, 34) and single.upper.shape == (96,)


def test_config_and_overrides(robots):
    """PassiveWBC(robot, planner, config, **overrides): keywords override the configuration's
    fields; unknown keywords are refused by name."""
    robot = robots["hyq"]
    planner = SimpleNamespace(legs=robot.contact_names)
    config = PassiveConfig(mu=0.5, K_st=100.0, Q=2.0)
    wbc = PassiveWBC(robot, planner, config, K_st=0.0)
    assert wbc.config == PassiveConfig(mu=0.5, K_st=0.0, Q=(2.0,) * 6)
    assert (wbc.mu, wbc.K_st) == (0.5, 0.0)
    np.testing.assert_array_equal(wbc.Q, np.full(6, 2.0))
    assert config.K_st == 100.0  # the given configuration is not changed
    with pytest.raises(TypeError, match="K_sw"):
        PassiveWBC(robot, planner, K_sw=1.0)


def test_leaning_tangential_matches_the_rows_built_one_by_one(rng):
    """The vectorised regulariser of the QP equals the blocks Rᵀ R of
    tasks.contact.tangent_rows built foot by foot: tilted normals, a lean inside the cone, one
    steeper than mu (capped) and one that does not press into the ground (no lean)."""
    from wholebody.tasks.contact import tangent_rows
    qp = PassiveQP(nv=18, n_feet=4)
    normals = np.array([[0.0, 0.0, 1.0], [0.2, -0.1, 1.0], [-0.3, 0.0, 1.0], [0.0, 0.25, 1.0]])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    qp.set_friction(normals, 0.6, 0.0, 1000.0)
    stance = np.array([True, True, False, True])
    for lean in ([30.0, -20.0, 500.0], [400.0, 300.0, 200.0], [0.0, 10.0, -50.0]):
        lean = np.asarray(lean)
        got = qp.leaning_tangential(stance, lean, 0.6)
        want = np.zeros((12, 12))
        for i in np.flatnonzero(stance):
            rows = tangent_rows(normals[i], lean, 0.6)
            want[3 * i:3 * i + 3, 3 * i:3 * i + 3] = rows.T @ rows
        np.testing.assert_allclose(got, want, atol=1e-12)
