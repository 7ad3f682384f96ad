"""Every controller is a :class:`~wholebody.control.Controller`: ``compute(q, v, t)`` returns a
:class:`~wholebody.formulation.Solution` whose torque is finite and within the robot's limits."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

import wholebody as wb
import wholebody.control as control
from wholebody.control import Controller
from wholebody.formulation import Solution

#: the controllers built from a robot alone, and the preset each is for
BUILT_FROM_A_ROBOT = {"StandingController": "hyq", "MomentumBalance": "talos14",
                      "Walking": "talos14", "PassiveWBC": "hyq",
                      "QuasiStaticController": "hyq"}


def test_every_exported_controller_class_is_a_controller():
    """Every class of ``wholebody.control`` with a ``compute`` method satisfies the protocol,
    and the protocol is not vacuous (a class without ``compute`` does not)."""
    classes = [c for _, c in inspect.getmembers(control, inspect.isclass)
               if c is not Controller and "compute" in dir(c)]
    assert {"ContactSwitch", "Stepping", *BUILT_FROM_A_ROBOT} <= {c.__name__ for c in classes}
    for cls in classes:
        assert issubclass(cls, Controller), cls.__name__
    assert not issubclass(control.WalkingConfig, Controller)


@pytest.mark.parametrize("name", sorted(BUILT_FROM_A_ROBOT))
def test_compute_returns_a_solution_within_the_limits(name):
    robot = wb.load_robot(BUILT_FROM_A_ROBOT[name])
    result = getattr(control, name)(robot).compute(robot.q_ref, np.zeros(robot.nv), 0.0)
    assert isinstance(result, Solution)
    lower, upper = robot.torque_bounds(robot.q_ref)
    assert np.all(np.isfinite(result.tau)) and result.ok
    assert np.all(result.tau >= lower - 1e-9) and np.all(result.tau <= upper + 1e-9)
    assert set(result.forces) <= set(robot.contact_names)
