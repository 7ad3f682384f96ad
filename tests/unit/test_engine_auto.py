"""``engine="auto"``, the default of every controller: the compiled cycle where it is built and
supports the configuration, else the Python reference with one logged warning. The evidence for
"native" is the compiled cycle's own object behind the controller and torques equal to the
reference's."""

import logging
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import wholebody

from conftest import native_cycle_or_skip
from wholebody.control.balance import MomentumBalance
from wholebody.control.passive import PassiveWBC
from wholebody.cycle import warn_python_fallback
from wholebody.estimation import KinematicInertialEKF


def planner(robot):
    return SimpleNamespace(legs=robot.contact_names)


def test_passive_wbc_defaults_to_the_compiled_cycle(robots, rng, plan_for):
    native_cycle_or_skip("_hierarchy_cycle")
    module = native_cycle_or_skip("_passive_references")
    robot = robots["hyq"]
    auto = PassiveWBC(robot, planner=planner(robot))
    python = PassiveWBC(robot, planner=planner(robot), engine="python")
    assert auto.engine == "native" and auto._stack_cycle.native
    assert isinstance(auto._references, module.PassiveReferences)
    q = robot.q_ref.copy()
    q[7:] += rng.normal(scale=0.02, size=robot.na)
    v = rng.normal(scale=0.05, size=robot.nv)
    robot.update(q, v)
    plan = plan_for(robot, rng, (True, False, True, True))
    a, b = auto.cycle(q, v, plan), python.cycle(q, v, plan)
    assert a.ok and b.ok
    np.testing.assert_allclose(a.tau, b.tau, atol=1e-6)


def test_single_slack_runs_on_the_native_engine(robots, caplog):
    """The single swing slack (an auxiliary variable per swing foot): engine "auto" runs the
    stack of tasks on the compiled hierarchy cycle, no warning."""
    native_cycle_or_skip("_hierarchy_cycle")
    robot = robots["hyq"]
    warn_python_fallback.cache_clear()
    with caplog.at_level(logging.WARNING, logger="wholebody.cycle"):
        wbc = PassiveWBC(robot, planner=planner(robot), swing_slack="single")
    assert wbc.engine == "native" and wbc._stack_cycle.native
    assert not [r for r in caplog.records if "runs the Python engine" in r.message]


def test_momentum_balance_defaults_to_the_compiled_cycle(robots):
    native_cycle_or_skip("_hierarchy_cycle")
    ctrl = MomentumBalance(robots["talos14"], gains="pd")
    assert ctrl.cycle is not None and ctrl.cycle.engine_name == "native"


def test_estimator_defaults_to_the_compiled_cycle(robots):
    module = native_cycle_or_skip("_estimator")
    ekf = KinematicInertialEKF(robots["hyq"])
    assert ekf.engine == "native" and isinstance(ekf._native, module.Estimator)
    assert KinematicInertialEKF(robots["hyq"], engine="python")._native is None


def test_estimator_without_the_compiled_cycle(robots, monkeypatch, caplog):
    monkeypatch.setitem(sys.modules, "wholebody._estimator", None)  # import fails
    monkeypatch.delattr(wholebody, "_estimator", raising=False)
    with pytest.raises(ValueError, match="engine: 'native' needs the compiled estimator"):
        KinematicInertialEKF(robots["hyq"], engine="native")
    warn_python_fallback.cache_clear()
    with caplog.at_level(logging.WARNING, logger="wholebody.cycle"):
        ekf = KinematicInertialEKF(robots["hyq"])
    assert ekf.engine == "python" and ekf._native is None
    assert any("wholebody._estimator" in r.message for r in caplog.records)
    with pytest.raises(ValueError, match="engine: expected one of"):
        KinematicInertialEKF(robots["hyq"], engine="fast")
