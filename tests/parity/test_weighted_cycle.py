"""HierarchyCycle with method "weighted" (engine "native"): the single weighted QP (Fahmi et al.
2019, eq. 7) assembled and, with DAQP, solved in C++ (``BoundWeighted``) gives the torques of the
Python reference (``weighted._solve_weighted`` on the same native level arrays)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import torque_tolerance

from wholebody.control.stacks import table1_stack, table2_stack
from wholebody.cycle import HierarchyCycle, native_available
from wholebody.formulation import Stack
from wholebody.solvers import SolverSettings
from wholebody.tasks import (CoMTask, ContactConstraint, ForceRegularizer, FrictionCone,
                             NewtonEuler, PostureTask, TorqueLimits)
from wholebody.variables import Variables

pytestmark = pytest.mark.skipif(not native_available(),
                                reason="wholebody._hierarchy_cycle not built (no C++ compiler)")


def as_weighted(stack: Stack) -> Stack:
    """The stack's levels 1-2 as the hard level, the rest as one weighted objective."""
    return Stack([stack.levels[0] + stack.levels[1], [t for lv in stack.levels[2:] for t in lv]])


def stance(robot) -> Stack:
    """A quadruped's stance: rigid point contacts with friction pyramids and torque limits hard;
    CoM and posture PD and a force regulariser weighted."""
    return Stack([
        [NewtonEuler(), TorqueLimits(), ContactConstraint(), FrictionCone(0.7)],
        [CoMTask(kp=100.0, kd=20.0, weight=1.0), PostureTask(kp=50.0, kd=14.0, weight=0.1),
         ForceRegularizer(weight=1e-2)],
    ])


CASES = {  # name: (robot, stack builder, whether the reference is well conditioned)
    "hyq-stance": ("hyq", stance, True),
    "table1-talos": ("talos", lambda r: as_weighted(table1_stack(r, r.contact_names)), True),
    # Table 2's objective weighs momentum rows by 1e4 against the force regulariser's 1e-4: H's
    # condition number ~1e16 at ε = 1e-6, and the reference's own torques move by up to ~1 Nm
    # when the base moves by 1e-13 m (torque_tolerance measures it per state); the level costs
    # still agree to 1e-7
    "table2-talos14": ("talos14", lambda r: as_weighted(table2_stack(r)), False),
}


@pytest.mark.parametrize("case", list(CASES))
def test_compiled_weighted_cycle_equals_python(robots, case, monkeypatch):
    """On a smooth motion near the reference posture, the compiled weighted QP (DAQP in C++)
    gives the Python reference's outcome, status, level costs (to 1e-7 relative) and torques (to
    1e-6 Nm) — for Table 2's ill-conditioned objective each within 100 times the reference's own
    sensitivity to a last-bit change of the state more (conftest.torque_tolerance) — and solves
    one QP per cycle."""
    import wholebody.solvers.compiled_cascade as cc
    name, build, well_conditioned = CASES[case]
    robot = robots[name]
    variables = Variables(robot)
    states = list(robot.smooth_motion(20, 0.05))
    settings = SolverSettings(method="weighted")
    compiled = HierarchyCycle(robot, build(robot), engine="native", settings=settings)
    solved = [compiled.solve(q, v, variables) for q, v in states]
    taus = [(s.tau.copy(), s.level_costs.copy()) for s in solved]
    assert all(s.timings["qps"] == 1 for s in solved)  # the compiled run's QP
    monkeypatch.setattr(cc.BoundWeighted, "available", False)
    monkeypatch.setattr(cc, "_WeightedRun", None)
    python = HierarchyCycle(robot, build(robot), engine="native", settings=settings)
    for i, ((q, v), a, (tau, costs)) in enumerate(zip(states, solved, taus)):
        b = python.solve(q, v, variables)
        where = f"{case} state {i}"
        assert b.timings["qps"] == 0, where  # the Python reference solved it
        assert a.ok and b.ok and (a.outcome, a.status) == (b.outcome, b.status), where
        tol, cost_tol = 1e-6, 1e-12
        if not well_conditioned:
            tol = torque_tolerance(lambda q, v: python.solve(q, v, variables).tau.copy(), q, v,
                                   robot.nq)
            cost_tol += torque_tolerance(
                lambda q, v: python.solve(q, v, variables).level_costs.copy(), q, v, robot.nq,
                atol=0.0)
        np.testing.assert_allclose(costs, b.level_costs, rtol=1e-7, atol=cost_tol, err_msg=where)
        np.testing.assert_allclose(tau, b.tau, rtol=0, atol=tol, err_msg=where)
