"""Real-robot conditions (``--set realism``): the torque lag against its closed-form step response,
the controller fed the estimate (not the twin's state), the ``robot`` level's twin mismatched, the
parameter on every scenario that simulates; closed loop under each level (slow)."""

import math

import numpy as np
import pytest

import wholebody as wb
from wholebody.scenarios import SCENARIOS
from wholebody.scenarios.conditions import LEVELS, RobotConditions, robot_mismatch
from wholebody.scenarios.loop import run_closed_loop
from wholebody.sim.mismatch import Mismatch
from wholebody.sim.simulator import Simulator


@pytest.fixture(scope="module")
def talos14():
    return wb.load_robot("talos14")


def test_torque_lag_follows_the_first_order_step_response(talos14):
    """Commanded 0, then a step to tau: the applied torque after k steps is
    tau (1 - exp(-2 pi f k dt)) (the first-order lag's step response, sampled)."""
    f = 40.0
    sim = Simulator(talos14, mismatch=Mismatch(torque_bandwidth=f))
    tau = np.linspace(-5.0, 5.0, talos14.na)
    sim.step(np.zeros(talos14.na))
    for _ in range(30):
        sim.step(tau)
    applied = sim.log.tau_applied[1:]
    k = np.arange(len(applied))  # applied[k] is the torque of the (k+1)-th step of the command
    expected = tau[None, :] * (1.0 - np.exp(-2.0 * math.pi * f * (k + 1) * sim.dt))[:, None]
    np.testing.assert_allclose(applied, expected, atol=1e-12)
    assert Mismatch().lag_gain(sim.dt) == 1.0  # ideal by default


def test_the_controller_reads_the_estimate(talos14):
    """Under 'sensors' the closed loop hands the controller the estimator's state: equal to the
    conditions' estimate at each cycle, and not the twin's state (the sensors are noisy)."""
    conditions = RobotConditions(talos14, "sensors", seed=3)
    sim = Simulator(talos14, observers=[conditions])
    seen, truth = [], []
    standing = wb.control.StandingController(talos14)

    class Recorder:
        def compute(self, q, v, t):
            seen.append((q.copy(), v.copy(), conditions.controller_state(sim)))
            truth.append(sim.state())
            return standing.compute(*sim.state(), t)

    run_closed_loop(sim, Recorder(), 0.02)
    assert len(seen) == 20
    for (q, v, (q_hat, v_hat)), (q_true, v_true) in zip(seen, truth):
        np.testing.assert_array_equal(q, q_hat)
        np.testing.assert_array_equal(v, v_hat)
    assert max(np.abs(v - v_true).max() for (q, v, _), (_, v_true) in zip(seen, truth)) > 1e-6


def test_robot_level_mismatches_the_twin(talos14):
    """Under 'robot' the simulator takes the conditions' mismatch: its links' masses differ from
    the controller's model (±5 %), torques are late and lagged; 'sensors' keeps the exact twin."""
    robot_level = Simulator(talos14, observers=[RobotConditions(talos14, "robot")])
    sensors_level = Simulator(talos14, observers=[RobotConditions(talos14, "sensors")])
    assert robot_level.mismatch == robot_mismatch(talos14)
    assert robot_level.mismatch.torque_delay == 1 and robot_level.mismatch.torque_bandwidth > 0
    assert sensors_level.mismatch == Mismatch()
    masses = robot_level.model.body_mass[1:]
    exact = sensors_level.model.body_mass[1:]
    moved = np.abs(masses / np.where(exact > 0, exact, 1.0) - 1.0)[exact > 0]
    assert moved.max() > 0.01 and moved.max() <= 0.05 + 1e-9


def test_every_simulating_scenario_takes_realism():
    """Every scenario that declares its simulations has the realism parameter, with its levels;
    a bad level is refused naming the parameter."""
    simulating = [s for s in SCENARIOS.values() if s.simulations is not None]
    assert simulating
    for scenario in simulating:
        realism = [p for p in scenario.parameters if p.name == "realism"]
        assert len(realism) == 1 and realism[0].default == "exact", scenario.name
        assert tuple(realism[0].choices) == LEVELS
    with pytest.raises(ValueError, match="realism"):
        simulating[0].resolve({"realism": "perfect"})


@pytest.mark.slow
@pytest.mark.parametrize("level", ["sensors", "robot"])
def test_push_survived_under_real_conditions(talos14, level):
    """talos14's PD balance survives the default push reading the estimate, and on the
    mismatched, lagged twin: the scenario's own verdict, and the run records its level."""
    result = SCENARIOS["push"].run(talos14, "pd", {"realism": level})
    assert result.realism == level
    assert result.success, result.metrics
    assert result.metrics["failed_cycles"] == 0
