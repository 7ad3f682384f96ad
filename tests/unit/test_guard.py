"""The torque guard (wholebody.guard): what leaves the library is finite and within the limits, and
the outcome says what happened."""

import numpy as np
import pytest

from wholebody.guard import LIMIT_TOLERANCE, Outcome, guard_torque

LO, HI = np.array([-10.0, -5.0, -1.0]), np.array([10.0, 5.0, 1.0])


@pytest.mark.parametrize("outcome", [Outcome.SOLVED, Outcome.FALLBACK])
def test_solved_torque_inside_passes_unchanged(outcome):
    tau = np.array([9.0, -5.0, 0.0])
    out, got, reason = guard_torque(tau, LO, HI, outcome, "optimal")
    assert out is tau and got is outcome and reason == "optimal" and got.ok


def test_solved_torque_within_the_solver_tolerance_is_clipped_silently():
    tau = np.array([9.0, -5.0 - 0.5 * LIMIT_TOLERANCE, 0.0])
    out, got, reason = guard_torque(tau, LO, HI, Outcome.SOLVED, "optimal")
    np.testing.assert_array_equal(out, [9.0, -5.0, 0.0])
    assert got is Outcome.SOLVED and reason == "optimal"


def test_tolerance_is_relative_to_the_limit():
    """A 300 N m limit left by 1e-4 N m (3e-7 of it) is the solver's tolerance, not a failed
    cycle; 1e-3 N m (3e-6 of it) is."""
    lo, hi = np.array([-300.0, -1.0]), np.array([300.0, 1.0])
    out, got, _ = guard_torque(np.array([300.0 + 1e-4, 0.0]), lo, hi, Outcome.SOLVED, "optimal")
    assert got is Outcome.SOLVED and out[0] == 300.0
    out, got, reason = guard_torque(np.array([300.0 + 1e-3, 0.0]), lo, hi, Outcome.SOLVED, "")
    assert got is Outcome.CLIPPED and out[0] == 300.0 and "(joint 0)" in reason
    _, got, _ = guard_torque(np.array([0.0, -1.0 - 5e-6]), lo, hi, Outcome.SOLVED, "")
    assert got is Outcome.CLIPPED  # a small limit: the absolute tolerance


def test_solved_torque_outside_is_clipped_and_flagged():
    out, got, reason = guard_torque(np.array([12.0, 0.0, -3.0]), LO, HI, Outcome.SOLVED, "optimal")
    np.testing.assert_array_equal(out, [10.0, 0.0, -1.0])
    assert got is Outcome.CLIPPED and not got.ok and "2 Nm outside limits" in reason


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("outcome", [Outcome.SOLVED, Outcome.HELD])
def test_non_finite_torque_is_zero_and_held(bad, outcome):
    out, got, reason = guard_torque(np.array([1.0, bad, 0.5]), LO, HI, outcome, "why")
    np.testing.assert_array_equal(out, np.zeros(3))
    assert got is Outcome.HELD and reason.startswith("why") and "non-finite" in reason


def test_held_torque_is_clipped_keeping_the_reason():
    out, got, reason = guard_torque(np.array([-20.0, 1.0, 2.0]), LO, HI, Outcome.HELD, "infeasible")
    np.testing.assert_array_equal(out, [-10.0, 1.0, 1.0])
    assert got is Outcome.HELD and reason == "infeasible"


def test_non_finite_limits_give_zero_torque():
    out, got, reason = guard_torque(np.array([1.0, 1.0, 1.0]), LO, np.array([10.0, np.nan, 1.0]),
                                    Outcome.SOLVED, "optimal")
    np.testing.assert_array_equal(out, np.zeros(3))
    assert got is Outcome.HELD and "limits not finite" in reason


def test_outcome_values_are_stable_names():
    assert [o.value for o in Outcome] == ["solved", "solved-with-fallback", "clipped", "held"]
    assert [o.ok for o in Outcome] == [True, True, False, False]


def test_standing_controller_saturation_is_clipped_outcome(robots):
    """StandingController's torque leaves through the guard: a posture error far beyond what the
    limits allow saturates, the outcome says CLIPPED, the torque is at the limits."""
    from wholebody.control.standing import StandingController

    robot = robots["talos14"]
    q = robot.q_ref.copy()
    q[7:] += 0.5
    result = StandingController(robot).compute(q, np.zeros(robot.nv))
    lo, hi = robot.torque_bounds()
    assert result.outcome is Outcome.CLIPPED and not result.ok
    assert np.all(result.tau >= lo) and np.all(result.tau <= hi)
    assert np.any(np.isclose(result.tau, hi) | np.isclose(result.tau, lo))
    calm = StandingController(robot, kp=0.0, kd=0.0).compute(robot.q_ref, np.zeros(robot.nv))
    assert calm.outcome is Outcome.SOLVED and calm.ok
