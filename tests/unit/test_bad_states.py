"""States a controller should not meet, through both engines: joints beyond their limits (the
engines agree on every well-posed one), a plan evaluated at an absurd time, a velocity whose
square overflows, and failed cycles in a row (said in the status, then recovery without reset).
Every expectation is checked against evidence of its own: the joint really is outside its range,
"ill-posed" is the harness's definition (benchmarks/fuzz.py), a recovered cycle satisfies the
equations of motion (Pinocchio's RNEA), the integral is compared with its value before."""

import copy
import logging
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import native_cycle_or_skip

from wholebody.control.balance import MomentumBalance
from wholebody.control.passive import PLAN_ARRAYS, PassiveWBC
from wholebody.guard import Outcome

native_cycle_or_skip("_passive_references")
native_cycle_or_skip("_hierarchy_cycle")

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import fuzz  # noqa: E402

OVERFLOWING_SPEED = 1e155  # its square, 1e310, overflows a double


@pytest.fixture(autouse=True)
def quiet():
    logging.getLogger("wholebody").setLevel(logging.ERROR)
    yield
    logging.getLogger("wholebody").setLevel(logging.WARNING)


def beyond_states(robot, n, seed=3):
    """``n`` near-upright states of the fuzz harness, each with one joint beyond its range."""
    states = []
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        q, v = fuzz.sample_state(robot, "near-upright", rng)
        q[7:] = fuzz.joint_beyond_limit(robot, q[7:], rng)
        plan = None
        if all(c.dim == 3 for c in robot.contacts):  # as fuzz.make_state
            robot.update(q, v)
            plan = fuzz.sample_plan(robot, rng)
        states.append((q, v, plan))
    return states


# ------------------------------------------------------------------ joints beyond their limits
@pytest.mark.parametrize("robot_name,controller", [("talos14", "pd"), ("talos14", "lqr"),
                                                   ("hyq", "passive")])
def test_engines_agree_beyond_the_joint_limits(robots, robot_name, controller):
    """With one joint outside its range, the engines' torques agree to 1e-6 Nm and on ``ok`` on
    every state that is well-posed (the harness's definition: a 1e-12 relative change of (q, v)
    moves neither engine's torque by more than 1e-7 Nm) — or, rarely (docs/results.md counts),
    the torque is not determined by double-precision rows: the same cascade on each engine's
    level arrays gives that engine's torque, and a 1e-13 change of the arrays moves it."""
    robot = robots[robot_name]
    runners = [fuzz.Runner(robot, controller, engine) for engine in ("python", "native")]
    well_posed = 0
    states = beyond_states(robot, 40)
    for index, (q, v, plan) in enumerate(states):
        outside = (q[7:] > robot.q_max) | (q[7:] < robot.q_min)
        assert outside.sum() == 1  # the state is what the test is about
        results = [r.run(q, v, plan) for r in runners]
        taus = {(r.controller, r.engine): (np.asarray(s.tau, float), s.ok, fuzz.outcome_key(s))
                for r, s in zip(runners, results)}
        diff = float(np.abs(results[0].tau - results[1].tau).max())
        if diff <= fuzz.DISAGREE_SMALL and results[0].ok == results[1].ok:
            well_posed += 1
            continue
        sensitivity = fuzz.sensitivity(runners, q, v, plan, index, taus)
        if sensitivity > fuzz.ILL_POSED:
            continue
        # well-posed by (q, v): then the engines differ only through their rows' round-off,
        # and a change of the rows below it moves the torque as far (fuzz.row_sensitivity)
        assert controller in ("pd", "lqr"), (index, diff)
        r = fuzz.row_sensitivity(robot, controller, q, v)
        assert max(r["reproduce"].values()) < 1e-9 and r["moves"][0] > fuzz.ILL_POSED, (
            f"state {index}: the engines differ by {diff:.3g} Nm (ok {results[0].ok} / "
            f"{results[1].ok}) on a well-posed state: {r}")
    assert well_posed >= len(states) // 2


# ------------------------------------------------------------------ PassiveWBC, infeasible QP
@pytest.mark.parametrize("engine", ["python", "native"])
def test_passive_infeasible_hard_level_is_held_not_compromised(robots, engine):
    """A wild state of the fuzz harness (seed 0, index 5596) whose QP has no solution: the same
    QP assembled by hand (tests/passive_oracle.py) is infeasible to DAQP. Both engines hold the
    previous torque, naming the weighted QP, rather than return the cascade's least-squares
    compromise of the hard rows, which breaks the floating-base dynamics by 6e-3 N (a
    solution reported solved that the equations of motion refute)."""
    from types import SimpleNamespace

    from passive_oracle import hand_assembled
    robot = robots["hyq"]
    q, v, plan = fuzz.make_state(robot, "wild", 0, 5596)
    ctrl = PassiveWBC(robot, planner=SimpleNamespace(legs=robot.contact_names), engine=engine)
    sol = ctrl.cycle(q, v, plan)
    robot.update(q, v)
    assert not hand_assembled(ctrl, plan).ok  # the evidence: DAQP on the hand-assembled QP
    assert sol.outcome is Outcome.HELD and "hard level infeasible" in sol.status
    lo, hi = robot.torque_bounds(q)
    assert np.all(np.isfinite(sol.tau)) and np.all(sol.tau >= lo) and np.all(sol.tau <= hi)


# ------------------------------------------------------------------ PassiveWBC at t = 1e300
@pytest.mark.parametrize("engine", ["python", "native"])
def test_passive_plan_at_an_absurd_time_is_held(robots, engine):
    """t = 1e300 makes the planner's trunk reference NaN: both engines return the previous
    torque, HELD, naming the plan's field; the next cycle with a sane plan is solved (checked
    with RNEA)."""
    robot = robots["hyq"]
    ctrl = PassiveWBC(robot, engine=engine)
    q, v = robot.q_ref, np.zeros(robot.nv)
    first = ctrl.compute(q, v, 0.0)
    assert first.ok
    sane_plan = copy.deepcopy(ctrl.last_plan)
    held = ctrl.compute(q, v, 1e300)
    assert held.outcome is Outcome.HELD
    assert "plan: trunk.position is not finite" in held.status
    assert "(1 failed cycle(s) in a row)" in held.status
    lo, hi = robot.torque_bounds(q)
    np.testing.assert_array_equal(held.tau, np.clip(first.tau, lo, hi))
    again = ctrl.cycle(q, v, sane_plan)  # (the planner itself refuses to go back in time)
    assert again.ok and again.outcome is Outcome.SOLVED
    dyn = fuzz.DynamicsCheck(robot)
    assert max(dyn.residuals(q, v, again)) < 1e-6 * dyn.weight


def test_passive_engines_agree_at_an_absurd_time(robots):
    robot = robots["hyq"]
    q, v = robot.q_ref, np.zeros(robot.nv)
    out = []
    for engine in ("python", "native"):
        ctrl = PassiveWBC(robot, engine=engine)
        ctrl.compute(q, v, 0.0)
        out.append(ctrl.compute(q, v, 1e300))
    for other in out[1:]:
        assert other.status == out[0].status
        np.testing.assert_allclose(other.tau, out[0].tau, atol=1e-9)


# ------------------------------------------------------------------ |v|² overflows
@pytest.mark.parametrize("engine", ["python", "native"])
@pytest.mark.parametrize("gains", ["pd", "lqr"])
@pytest.mark.parametrize("index", [0, 9])  # a base velocity, a joint velocity
def test_overflowing_velocity_is_a_flagged_value_naming_v(robots, engine, gains, index):
    """v with an entry of 1e155 (finite; its square is not): HELD, zero torque, the status names
    v; the next sane state is solved again without reset (its dynamics checked with RNEA)."""
    robot = robots["talos14"]
    ctrl = MomentumBalance(robot, gains=gains, engine=engine)
    q, v = robot.q_ref, np.zeros(robot.nv)
    bad = v.copy()
    bad[index] = OVERFLOWING_SPEED
    sol = ctrl.compute(q, bad, 0.0)
    assert sol.outcome is Outcome.HELD and not sol.ok
    assert sol.status.startswith("v: ") and "overflow" in sol.status
    assert np.all(sol.tau == 0.0)
    again = ctrl.compute(q, v, 0.002)
    assert again.ok
    dyn = fuzz.DynamicsCheck(robot)
    assert max(dyn.residuals(q, v, again)) < 1e-6 * dyn.weight


@pytest.mark.parametrize("engine", ["python", "native"])
def test_passive_overflowing_velocity_names_v(robots, engine):
    robot = robots["hyq"]
    ctrl = PassiveWBC(robot, engine=engine)
    v = np.zeros(robot.nv)
    v[8] = OVERFLOWING_SPEED
    sol = ctrl.compute(robot.q_ref, v, 0.0)
    assert sol.outcome is Outcome.HELD
    assert sol.status.startswith("v: ") and np.isfinite(sol.tau).all()


# ------------------------------------------------------------------ failed cycles in a row
@pytest.mark.parametrize("engine", ["python", "native"])
@pytest.mark.parametrize("gains", ["pd", "lqr"])
def test_momentum_balance_counts_failed_cycles_and_recovers(robots, engine, gains):
    robot = robots["talos14"]
    ctrl = MomentumBalance(robot, gains=gains, engine=engine)
    q, v = robot.q_ref, np.zeros(robot.nv)
    bad = v.copy()
    bad[0] = OVERFLOWING_SPEED
    reference = MomentumBalance(robot, gains=gains, engine=engine).compute(q, v, 0.0)
    for n in range(1, 4):
        sol = ctrl.compute(q, bad, 0.002 * n)
        assert sol.outcome is Outcome.HELD
        assert sol.status.endswith(f"({n} failed cycle(s) in a row)")
    sol = ctrl.compute(q, v, 0.01)
    assert sol.outcome is Outcome.SOLVED and "in a row" not in sol.status
    # the recovered cycle is the cycle of a controller that never failed
    np.testing.assert_allclose(sol.tau, reference.tau, atol=1e-9)
    sol = ctrl.compute(q, bad, 0.012)
    assert sol.status.endswith("(1 failed cycle(s) in a row)")  # a new streak


@pytest.mark.parametrize("engine", ["python", "native"])
def test_integral_does_not_wind_up_on_failed_cycles(robots, engine):
    """LQR with integral action: cycles that fail leave the CoG-error integral where it was; a
    huge time step is clamped to the anti-windup bound, never NaN."""
    robot = robots["talos14"]
    ctrl = MomentumBalance(robot, gains="lqr", engine=engine, q_integral=1e6)
    q, v = robot.q_ref.copy(), np.zeros(robot.nv)
    q[0] += 0.01  # a CoG error for the integral to integrate
    for k in range(5):
        assert ctrl.compute(q, v, 0.002 * k).ok
    before = ctrl.cog_integral.copy()
    assert np.any(before != 0.0)
    bad = v.copy()
    bad[0] = OVERFLOWING_SPEED
    for k in range(5, 200):
        assert ctrl.compute(q, bad, 0.002 * k).outcome is Outcome.HELD
    np.testing.assert_array_equal(ctrl.cog_integral, before)
    # a solve that fails at a sane state (the solver made to fail): no integration either
    solver = ctrl.cycle if ctrl.cycle is not None else ctrl.formulation
    names = ("solve", "solve_updated") if ctrl.cycle is not None else ("solve",)

    def failing(solve):
        def solve_and_fail(*args, **kwargs):
            sol = solve(*args, **kwargs)
            sol.outcome, sol.status = Outcome.HELD, "made to fail"
            return sol
        return solve_and_fail

    for name in names:
        setattr(solver, name, failing(getattr(solver, name)))
    for k in range(200, 300):
        assert ctrl.compute(q, v, 0.002 * k).outcome is Outcome.HELD
    np.testing.assert_array_equal(ctrl.cog_integral, before)
    for name in names:
        delattr(solver, name)  # the class's methods again
    assert ctrl.compute(q, v, 0.6).ok
    assert abs(ctrl.cog_integral[0]) > abs(before[0])  # integrating again (the error is in x)
    assert ctrl.compute(q, v, 1e300).ok  # dt = 1e300: clamped
    limit = ctrl.lqr.integral_limit
    assert np.all(np.isfinite(ctrl.cog_integral)) and np.all(np.abs(ctrl.cog_integral) <= limit)


def other_hierarchy_controller(robot, kind):
    """ContactSwitch, Stepping or Walking on talos14, built as their scenarios build them."""
    from wholebody.scenarios import get_scenario
    if kind == "contact-switch":
        from wholebody.control.contact_switch import ContactSwitch
        from wholebody.scenarios import single_support
        params = get_scenario("single-support").validate(robot, {})
        stance, _ = single_support.stance_and_swing(robot, params)
        return ContactSwitch(robot, stance, single_support.config(robot, params), gains="pd")
    if kind == "stepping":
        from wholebody.control.stepping import Stepping
        from wholebody.scenarios import stepping
        return Stepping(robot, stepping.config(robot, get_scenario("stepping").validate(robot, {})))
    from wholebody.control.walking import Walking
    return Walking(robot)


@pytest.mark.parametrize("kind", ["contact-switch", "stepping", "walking"])
def test_other_hierarchy_controllers_count_failed_cycles(robots, kind):
    """The held cycles of the other hierarchy controllers say how many in a row; a sane state
    afterwards is solved (its dynamics checked with RNEA) and a new failure starts at 1."""
    robot = robots["talos14"]
    ctrl = other_hierarchy_controller(robot, kind)
    q, v = robot.q_ref, np.zeros(robot.nv)
    bad = v.copy()
    bad[0] = OVERFLOWING_SPEED
    assert ctrl.compute(q, v, 0.0).ok
    for n in range(1, 4):
        sol = ctrl.compute(q, bad, 0.002 * n)
        assert sol.outcome is Outcome.HELD and sol.status.startswith("v: ")
        assert sol.status.endswith(f"({n} failed cycle(s) in a row)")
    sol = ctrl.compute(q, v, 0.008)
    assert sol.ok and "in a row" not in sol.status
    dyn = fuzz.DynamicsCheck(robot)
    assert max(dyn.residuals(q, v, sol)) < 1e-6 * dyn.weight
    assert ctrl.compute(q, bad, 0.010).status.endswith("(1 failed cycle(s) in a row)")


@pytest.mark.parametrize("field", PLAN_ARRAYS)
def test_passive_nonfinite_plan_field_is_named_alike_by_every_engine(robots, field):
    """One NaN in one plan array: every engine holds the previous torque and names that field
    (the native engine's compiled references check the arrays themselves)."""
    robot = robots["hyq"]
    q, v = robot.q_ref, np.zeros(robot.nv)
    statuses = set()
    for engine in ("python", "native"):
        ctrl = PassiveWBC(robot, engine=engine)
        assert ctrl.compute(q, v, 0.0).ok
        plan = copy.deepcopy(ctrl.last_plan)
        owner, name = (plan.trunk, field[6:]) if field.startswith("trunk.") else (plan, field)
        getattr(owner, name).flat[-1] = np.nan
        held = ctrl.cycle(q, v, plan)
        assert held.outcome is Outcome.HELD
        assert f"plan: {field} is not finite" in held.status
        statuses.add(held.status)
    assert len(statuses) == 1
