"""SolverSettings: the solver of a stack's levels as one frozen object (Herzog et al. 2016,
Sect. 2). Bad values are refused naming the field; equal settings are one key (a control loop's
compiled cascade is built once for them); and each setting reaches the QP backend it names —
observed at the backends themselves (counted calls, the keyword arguments DAQP receives, DAQP's
own iteration-limit status), not through the code under test."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import wholebody as wb
import wholebody.cycle as cycle_mod
from wholebody.control.balance import MomentumBalance
from wholebody.control.stacks import table2_stack
from wholebody.cycle import HierarchyCycle, native_available
from wholebody.formulation import Formulation, Stack
from wholebody.guard import Outcome
from wholebody.solvers import SolverSettings, backends, compiled_cascade
from wholebody.tasks import CoMTask, NewtonEuler
from wholebody.variables import Variables

native = pytest.mark.skipif(not native_available(),
                            reason="wholebody._hierarchy_cycle not built (no C++ compiler)")


@pytest.mark.parametrize("field, value", [
    ("method", "magic"),
    ("method", None),
    ("backend", "cplex"),
    ("backend", None),
    ("fallback_backend", "cplex"),
    ("regularization", 0.0),
    ("regularization", -1e-6),
    ("regularization", math.nan),
    ("regularization", math.inf),
    ("regularization", "1e-6"),
    ("regularization", True),
    ("backend_options", 3.0),
    ("backend_options", {"primal_tol": "tight"}),
    ("backend_options", {"primal_start": np.zeros(3)}),
    ("backend_options", {1: 1e-7}),
    ("analytic_first_level", "yes"),
    ("weighted_fallback", "yes"),
    ("weighted_fallback", None),
])
def test_a_bad_field_is_a_value_error_naming_it(field, value):
    with pytest.raises(ValueError, match=rf"^{field}: ") as caught:
        SolverSettings(**{field: value})
    assert "got" in str(caught.value)


def test_defaults_are_the_whole_body_solver():
    s = SolverSettings()
    assert (s.method, s.backend, s.fallback_backend, s.regularization, s.backend_options,
            s.analytic_first_level) == ("cascade", "daqp", "quadprog", 1e-6, (), None)
    assert wb.SolverSettings is SolverSettings


def test_a_fallback_equal_to_the_backend_is_no_fallback():
    """Nothing else to try: stored as None, so both spellings are the same settings."""
    assert SolverSettings(backend="quadprog").fallback_backend is None
    assert SolverSettings(backend="quadprog") == SolverSettings(backend="quadprog",
                                                                fallback_backend=None)


def test_settings_are_frozen_hashable_and_own_their_options():
    options = {"primal_tol": 1e-7, "iter_limit": 50}
    a = SolverSettings(backend_options=options)
    b = SolverSettings(backend_options={"iter_limit": 50, "primal_tol": 1e-7})
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    assert a.options == options and a.options is not a.options  # a fresh dict each time
    options["primal_tol"] = 1.0  # the caller's dict is not held
    assert a.options["primal_tol"] == 1e-7
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.backend = "quadprog"
    assert a != SolverSettings(backend_options={"primal_tol": 1e-8, "iter_limit": 50})
    assert dataclasses.replace(a, regularization=1e-5).regularization == 1e-5


def test_settings_of_another_type_are_refused_by_the_callers(robots):
    robot = robots["talos14"]
    with pytest.raises(ValueError, match="settings: expected a SolverSettings or None, got 'quadprog'"):
        HierarchyCycle(robot, table2_stack(robot), engine="python", settings="quadprog")
    with pytest.raises(ValueError, match="settings: expected a SolverSettings"):
        MomentumBalance(robot, engine="python", settings={"backend": "quadprog"})
    robot.update(robot.q_ref, np.zeros(robot.nv))
    with pytest.raises(ValueError, match="settings: expected a SolverSettings"):
        Formulation(robot).solve(table2_stack(robot), Variables(robot), "weighted")


def test_a_closed_form_level_one_is_refused_where_level_one_does_not_allow_it(robots):
    """Sect. 2.4: level 1 in closed form needs level 1 to be the dynamics (and torque limits)."""
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    stack = Stack([[NewtonEuler(), CoMTask(kp=10.0, kd=6.0)]])
    forced = SolverSettings(analytic_first_level=True)
    with pytest.raises(ValueError, match="analytic_first_level: True"):
        Formulation(robot).solve(stack, Variables(robot), forced)
    with pytest.raises(ValueError, match="analytic_first_level: True"):
        HierarchyCycle(robot, stack, engine="python", settings=forced)
    assert Formulation(robot).solve(stack, Variables(robot), SolverSettings()).ok


def qp_states(robot, stack, count: int = 2):
    """States of a smooth motion on which the cascade of ``stack`` solves a level QP (on most,
    every level has its closed-form solution and no backend is called)."""
    formulation, variables, found = Formulation(robot), Variables(robot), []
    for q, v in robot.smooth_motion(40, 0.05):
        robot.update(q, v)
        if formulation.solve(stack, variables, diagnostics=False).timings["qps"]:
            found.append((q, v))
            if len(found) == count:
                return found
    pytest.fail("no state of the motion needs a level QP")


def counting(monkeypatch, name: str) -> list:
    """Replace the backend ``name`` by itself, counting its calls."""
    calls, solve = [], backends.BACKENDS[name]
    monkeypatch.setitem(backends.BACKENDS, name,
                        lambda *a, **k: calls.append(k) or solve(*a, **k))
    return calls


@pytest.mark.parametrize("engine", [pytest.param("native", marks=native), "python"])
def test_the_backend_named_is_the_one_called(robots, monkeypatch, engine):
    robot = robots["talos14"]
    stack = table2_stack(robot)
    states = qp_states(robot, stack)
    quadprog, daqp = counting(monkeypatch, "quadprog"), counting(monkeypatch, "daqp")
    cycle = HierarchyCycle(robot, stack, engine=engine,
                           settings=SolverSettings(backend="quadprog", fallback_backend=None))
    for q, v in states:
        assert cycle.solve(q, v).ok
    assert len(quadprog) >= len(states) and not daqp
    quadprog.clear()
    controller = MomentumBalance(robot, engine=engine,
                                 settings=SolverSettings(backend="quadprog", fallback_backend=None))
    assert controller.settings.backend == "quadprog"
    if engine == "native":
        assert controller.cycle.settings is controller.settings
    # the default: DAQP (in the compiled run or through the adapter), quadprog never asked
    cycle.settings = SolverSettings()
    for q, v in states:
        assert cycle.solve(q, v).timings["qps"]
    assert not quadprog


def test_backend_options_reach_daqp(robots, monkeypatch):
    """DAQP's ``primal_tol`` arrives in daqp.solve's keyword arguments (the level QPs solved
    through the Python adapter; the stock settings otherwise)."""
    import daqp
    robot = robots["talos14"]
    stack = table2_stack(robot)
    states = qp_states(robot, stack, 1)
    monkeypatch.setattr(compiled_cascade, "_daqp_in_cascade", lambda backend, opts: None)
    received, solve = [], daqp.solve
    monkeypatch.setattr(daqp, "solve", lambda *a, **k: received.append(k) or solve(*a, **k))
    formulation, variables = Formulation(robot), Variables(robot)
    robot.update(*states[0])
    assert formulation.solve(stack, variables, SolverSettings(backend_options={"primal_tol": 1e-7})).ok
    assert received and all(k.get("primal_tol") == 1e-7 for k in received)
    received.clear()
    assert formulation.solve(stack, variables, SolverSettings()).ok
    assert received and all(k.get("primal_tol") != 1e-7 for k in received)


@native
def test_an_iteration_limit_reaches_the_compiled_daqp(robots):
    """``iter_limit`` 1 for the DAQP that the compiled cascade calls itself: DAQP reports its
    iteration limit and quadprog, the fallback, solves (outcome FALLBACK)."""
    robot = robots["talos14"]
    stack = table2_stack(robot)
    (q, v), = qp_states(robot, stack, 1)
    cycle = HierarchyCycle(robot, stack, engine="native",
                           settings=SolverSettings(backend_options={"iter_limit": 1}))
    limited = cycle.solve(q, v)
    assert limited.ok and limited.outcome is Outcome.FALLBACK
    assert "iteration limit" in limited.status and "quadprog after daqp" in limited.status
    cycle.settings = SolverSettings()
    assert "iteration limit" not in cycle.solve(q, v).status


@native
def test_equal_settings_share_the_compiled_cascade(robots, monkeypatch):
    """HierarchyCycle keeps one compiled cascade per program for its settings: given settings
    equal to the current ones (another object, options in another order) it keeps it; other
    settings build a new one. Counted at the construction of BoundCascade."""
    built = []

    class Counted(cycle_mod.BoundCascade):
        def __init__(self, *args, **kwargs):
            built.append(args[1])
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(cycle_mod, "BoundCascade", Counted)
    robot = robots["talos14"]
    variables = Variables(robot)
    states = robot.smooth_motion(6, 0.05)
    first = SolverSettings(backend_options={"primal_tol": 1e-8, "iter_limit": 500})
    cycle = HierarchyCycle(robot, table2_stack(robot), engine="native", settings=first)
    cycle.solve(*states[0], variables)
    program = cycle._program
    bound = program._bound
    assert len(built) == 1 and built[0] is first and isinstance(bound, Counted)
    for q, v in states[1:3]:
        cycle.settings = SolverSettings(backend_options={"iter_limit": 500, "primal_tol": 1e-8})
        cycle.solve(q, v, variables)
    assert len(built) == 1 and cycle._program is program and program._bound is bound
    cycle.settings = dataclasses.replace(first, regularization=1e-5)
    cycle.solve(*states[3], variables)
    assert len(built) == 2 and program._bound is not bound
    assert built[1].regularization == 1e-5
