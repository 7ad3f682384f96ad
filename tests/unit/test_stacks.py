"""The hierarchies of Herzog et al. 2016 Tables 1, 2 and 4 build, print with the paper's row counts,
and solve to physically consistent torques."""

import numpy as np
import pytest

from wholebody.control.stacks import table1_stack, table2_stack, table4_stack
from wholebody.formulation import Formulation
from wholebody.variables import Variables


def _rows_of(table: str) -> list[tuple[str, str]]:
    """(rows, task) pairs of a printed stack."""
    out = []
    for line in table.splitlines()[2:-1]:
        parts = line[6:].split(None, 2)
        out.append((" ".join(parts[:2]), parts[2]))
    return out


def _physics_ok(robot, sol, variables):
    S_T = np.zeros((robot.nv, robot.na))
    S_T[6:] = np.eye(robot.na)
    J = robot.stacked_contact_jacobian(variables.contacts)
    eom = robot.M @ sol.qdd + robot.h - S_T @ sol.tau - J.T @ sol.lam
    lo, hi = robot.torque_bounds()
    return (np.abs(eom).max() < 1e-8 and np.all(sol.tau >= lo - 1e-6)
            and np.all(sol.tau <= hi + 1e-6))


def test_table2_on_talos14(robots):
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    variables = Variables(robot)
    stack = table2_stack(robot)
    rows = _rows_of(stack.table(robot, variables))
    # Table 2: 6 eq Newton-Euler, 2x14 ineq torque limits (two-sided rows), 2x6 eq contacts,
    # 2x4 ineq CoP, 2x(4+8) ineq friction (pyramid + the wrench cone's yaw-moment rows), 14 two-sided joint acceleration
    # limits, 6 eq momentum, 14+6 eq posture, 2x6 eq force regulariser
    expected = [("6 eq", "newton-euler"), ("14 ineq", "torque limits"), ("12 eq", "contacts"),
                ("8 ineq", "center of pressure"), ("24 ineq", "friction"),
                ("14 ineq", "joint acceleration limits"), ("6 eq", "momentum"),
                ("20 eq", "posture"), ("12 eq", "force regularizer")]
    assert rows == expected
    # torsion=False: the paper's pyramid only, 4 rows per sole
    plain = _rows_of(table2_stack(robot, torsion=False).table(robot, variables))
    assert plain == [r if r[1] != "friction" else ("8 ineq", "friction") for r in expected]
    with pytest.raises(TypeError, match="torsion"):
        table2_stack(robot, torsion="yes")
    sol = Formulation(robot).solve(stack, variables)
    assert sol.ok and _physics_ok(robot, sol, variables)
    # standing still at the reference: nothing to sacrifice, the feet carry the weight
    assert sum(f[2] for f in sol.forces.values()) == pytest.approx(robot.mass * 9.81, rel=1e-3)


@pytest.mark.parametrize("stance,swing", [(("left_sole", "right_sole"), ()),
                                          (("left_sole",), ("right_sole_link",))])
def test_table1_on_talos(robots, stance, swing):
    robot = robots["talos"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    variables = Variables(robot, stance)
    for full in (False, True):
        stack = table1_stack(robot, stance, swing, full=full)
        rows = _rows_of(stack.table(robot, variables))
        c = len(stance)
        expected_first = ("38 eq", "dynamics") if full else ("6 eq", "newton-euler")
        assert rows[0] == expected_first and rows[1] == ("32 ineq", "torque limits")
        assert ("%d eq" % (6 * c), "contacts") in rows and ("3 eq", "com") in rows
        assert (("6 eq", "swing right_sole_link") in rows) == bool(swing)
        assert ("38 eq", "posture") in rows
        sol = Formulation(robot, reduced=not full).solve(stack, variables)
        assert sol.ok and _physics_ok(robot, sol, variables)


def test_table4_single_support_with_lqr_placeholder(robots):
    """Table 4 builds with the PD momentum task; the LQR variant needs gains (a clear error)."""
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    variables = Variables(robot, ["left_sole"])
    stack = table4_stack(robot, ["left_sole"], ["right_sole_link"])
    rows = _rows_of(stack.table(robot, variables))
    assert rows[2:5] == [("4 ineq", "center of pressure"), ("12 ineq", "friction"),
                         ("14 ineq", "joint acceleration limits")]
    plain = _rows_of(table4_stack(robot, ["left_sole"], ["right_sole_link"], torsion=False)
                     .table(robot, variables))
    assert plain[3] == ("4 ineq", "friction")
    sol = Formulation(robot).solve(stack, variables)
    assert sol.ok and _physics_ok(robot, sol, variables)
    with pytest.raises(ValueError, match="gains K and k are not set"):
        Formulation(robot).solve(table4_stack(robot, ["left_sole"], lqr=True), variables)


@pytest.mark.slow  # closed loop in the twin
@pytest.mark.parametrize("name", ["talos14", "hyq"])
def test_table2_hierarchy_stands_in_twin(robots, name):
    """Closed loop in MuJoCo, the hierarchy's torques as the only command (no joint PD, as in the
    paper): the robot stands 2 s, base still, every cycle solved, the floor carries the weight."""
    from wholebody.sim.simulator import Simulator

    robot = robots[name]
    sim = Simulator(robot)
    stack, formulation, variables = table2_stack(robot), Formulation(robot), Variables(robot)
    q0, _ = sim.state()
    failures = 0
    for _ in range(2000):
        q, v = sim.state()
        robot.update(q, v)
        sol = formulation.solve(stack, variables, diagnostics=False)
        failures += not sol.ok
        sim.step(sol.tau)
    q, v = sim.state()
    assert failures == 0
    assert np.linalg.norm(q[:3] - q0[:3]) < 5e-3 and np.abs(v).max() < 0.05
    normal = sim.log.arrays()["contact_wrenches"][500:, :, 2].sum(axis=1)
    np.testing.assert_allclose(normal, robot.mass * 9.81, rtol=0.02)


def test_table2_momentum_rows_weights(robots):
    """Linear momentum rows 1e4, angular rows 1e-4 by default; one weight 1e4 on request."""
    robot = robots["talos14"]
    w = table2_stack(robot).find("momentum").weight
    np.testing.assert_array_equal(w, [1e4] * 3 + [1e-4] * 3)
    w = table2_stack(robot, lqr=True, angular_weight=1e4).find("momentum").weight
    np.testing.assert_array_equal(w, [1e4] * 6)


def test_table2_torques_are_determined_by_the_state(robots):
    """A change of the state at the level of rounding (1e-13 relative) must not move the torques
    by more than 1e-6 Nm: the hierarchy's solution is a function of its data."""
    robot = robots["talos14"]
    stack = table2_stack(robot)
    formulation, variables = Formulation(robot), Variables(robot)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(40):
        q, v = robot.random_state(rng, velocity_scale=0.1)
        q[:7], q[7:] = robot.q_ref[:7], robot.q_ref[7:] + 0.05 * rng.standard_normal(robot.na)
        q[7:] = np.clip(q[7:], robot.q_min, robot.q_max)
        robot.update(q, v)
        tau = formulation.solve(stack, variables, diagnostics=False).tau.copy()
        robot.update(q, v * (1.0 + 1e-13 * rng.standard_normal(robot.nv)))
        worst = max(worst, np.abs(formulation.solve(stack, variables, diagnostics=False).tau
                                  - tau).max())
    assert worst < 1e-6, f"torques moved by {worst:.3g} Nm"
