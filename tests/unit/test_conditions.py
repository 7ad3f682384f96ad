"""Real-robot conditions (``--set realism``): the torque lag against its closed-form step response,
the controller fed the estimate (not the twin's state), the ``robot`` level's twin mismatched, the
parameter on every scenario, a scenario's mismatch on top of the level's, one estimator per
simulation; closed loop under each level (slow)."""

import math

import numpy as np
import pytest

import wholebody as wb
from wholebody.scenarios import SCENARIOS
from wholebody.scenarios.conditions import (LEVELS, RobotConditions, job_observers,
                                            robot_mismatch)
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


def test_every_scenario_takes_realism():
    """Every registered scenario declares its simulations and so has the realism parameter,
    with its levels; a bad level is refused naming the parameter."""
    for scenario in SCENARIOS.values():
        assert scenario.simulations is not None, scenario.name
        realism = [p for p in scenario.parameters if p.name == "realism"]
        assert len(realism) == 1 and realism[0].default == "exact", scenario.name
        assert tuple(realism[0].choices) == LEVELS, scenario.name
    with pytest.raises(ValueError, match="realism"):
        next(iter(SCENARIOS.values())).resolve({"realism": "perfect"})


class _Brings:
    """An observer that brings a mismatch, as the ``robot`` level's conditions do."""

    def __init__(self, mismatch):
        self.mismatch = mismatch

    def start(self, sim):
        pass

    def step(self, sim):
        pass

    def controller_result(self, sim, result):
        pass


def _links(sim):
    return sim.model.body_mass[1:].copy(), sim.model.body_ipos[1:].copy()


def test_a_scenario_mismatch_goes_on_top_of_the_robot_level(talos14):
    """A scenario's own mismatch under the robot level: each link's mass is the nominal one
    times both perturbations' factors and its CoM moved by both offsets, as measured on twins
    built with each mismatch alone."""
    own = Mismatch(mass_noise=0.1, com_offset=0.01, seed=7)
    level = RobotConditions(talos14, "robot")
    nominal_mass, nominal_com = _links(Simulator(talos14))
    own_mass, own_com = _links(Simulator(talos14, mismatch=own))
    level_mass, level_com = _links(Simulator(talos14, observers=[level]))
    both_mass, both_com = _links(Simulator(talos14, mismatch=own, observers=[level]))
    heavy = nominal_mass > 0
    np.testing.assert_allclose(both_mass[heavy] / nominal_mass[heavy],
                               own_mass[heavy] / nominal_mass[heavy]
                               * level_mass[heavy] / nominal_mass[heavy], rtol=1e-9)
    np.testing.assert_allclose(both_com[heavy] - nominal_com[heavy],
                               (own_com - nominal_com)[heavy] + (level_com - nominal_com)[heavy],
                               atol=1e-12)
    assert not np.allclose(both_mass, own_mass) and not np.allclose(both_mass, level_mass)


def test_combined_actuators_delay_add_and_the_slower_lag_stays(talos14):
    """Delays of 2 and 1 steps: a torque step arrives after 3 steps, then follows the slower
    (40 Hz, not 50 Hz) lag's step response tau (1 - exp(-2 pi f k dt))."""
    sim = Simulator(talos14, mismatch=Mismatch(torque_delay=2, torque_bandwidth=40.0),
                    observers=[_Brings(Mismatch(torque_delay=1, torque_bandwidth=50.0))])
    tau = np.linspace(-5.0, 5.0, talos14.na)
    for _ in range(30):
        sim.step(tau)
    applied = sim.log.tau_applied
    np.testing.assert_array_equal(applied[:3], 0.0)
    k = np.arange(len(applied) - 3)
    expected = tau[None, :] * (1.0 - np.exp(-2.0 * math.pi * 40.0 * (k + 1) * sim.dt))[:, None]
    np.testing.assert_allclose(applied[3:], expected, atol=1e-12)


def test_combined_torque_noises_add_their_variances(talos14):
    """Independent noises of 3 and 4 Nm on a zero command: the applied torque's spread is
    sqrt(3² + 4²) = 5 Nm (sample standard deviation over 500 steps x every joint, within 5 %)."""
    sim = Simulator(talos14, mismatch=Mismatch(torque_noise=3.0, seed=1),
                    observers=[_Brings(Mismatch(torque_noise=4.0, seed=2))])
    for _ in range(500):
        sim.step(np.zeros(talos14.na))
    assert np.std(sim.log.tau_applied) == pytest.approx(5.0, rel=0.05)


def test_each_simulation_gets_its_own_estimator(talos14):
    """One conditions observer watching two simulations side by side: each estimate follows its
    own twin (the second started 0.5 m aside), and the second's estimates equal those of a
    conditions observer that watched it alone (the same seed: no state carried over)."""
    shared = RobotConditions(talos14, "sensors", seed=2)
    first = Simulator(talos14, observers=[shared])
    for _ in range(20):
        first.step(np.zeros(talos14.na))
    q0 = talos14.q_ref.copy()
    q0[0] += 0.5
    second = Simulator(talos14, observers=[shared])
    second.reset(q0)
    alone = RobotConditions(talos14, "sensors", seed=2)
    single = Simulator(talos14, observers=[alone])
    single.reset(q0)
    for _ in range(20):
        for sim in (first, second, single):
            sim.step(np.zeros(talos14.na))
        np.testing.assert_array_equal(shared.controller_state(second)[0],
                                      alone.controller_state(single)[0])
    assert abs(shared.controller_state(first)[0][0] - first.state()[0][0]) < 0.05
    assert abs(shared.controller_state(second)[0][0] - second.state()[0][0]) < 0.05


def test_a_pool_worker_makes_the_level_conditions(talos14):
    """In a pool's worker (no observers shipped) a run gets the realism level's own conditions,
    none for exact; in the scenario's process the observers it was given."""
    made = job_observers(talos14, {"realism": "robot"})
    assert len(made) == 1 and made[0].level == "robot"
    assert made[0].mismatch == robot_mismatch(talos14)
    assert job_observers(talos14, {"realism": "exact"}) == ()
    given = (object(),)
    assert job_observers(talos14, {"realism": "robot"}, given) == given


@pytest.mark.slow
def test_passivity_under_sensors_reads_the_estimate(monkeypatch):
    """passivity (2 s of crawl) under 'sensors': the passive WBC is handed the conditions'
    estimate at every cycle, and it differs from the twin's state it estimates."""
    from wholebody.control.passive import PassiveWBC

    read, handed = [], []
    estimate = RobotConditions.controller_state

    def recorded_estimate(self, sim):
        q, v = estimate(self, sim)
        read.append((q.copy(), sim.state()[0]))
        return q, v
    compute = PassiveWBC.compute

    def recorded_compute(self, q, v, t=0.0):
        handed.append(np.array(q, copy=True))
        return compute(self, q, v, t)
    monkeypatch.setattr(RobotConditions, "controller_state", recorded_estimate)
    monkeypatch.setattr(PassiveWBC, "compute", recorded_compute)
    hyq = wb.load_robot("hyq")
    result = SCENARIOS["passivity"].run(hyq, "passive", {"realism": "sensors", "duration": "2"})
    assert result.realism == "sensors"
    assert len(read) == len(handed) == 500  # 2 s of the 250 Hz WBC
    for (q_hat, _), q in zip(read, handed):
        np.testing.assert_array_equal(q, q_hat)
    errors = np.array([np.abs(q_hat[:3] - q_true[:3]).max() for q_hat, q_true in read])
    assert errors.max() > 1e-4  # the estimate, not the truth
    assert errors.max() < 0.05  # of the same robot


@pytest.mark.slow
@pytest.mark.parametrize("level", ["sensors", "robot"])
def test_push_survived_under_real_conditions(talos14, level):
    """talos14's PD balance survives the default push reading the estimate, and on the
    mismatched, lagged twin: the scenario's own verdict, and the run records its level."""
    result = SCENARIOS["push"].run(talos14, "pd", {"realism": level})
    assert result.realism == level
    assert result.success, result.metrics
    assert result.metrics["failed_cycles"] == 0



def test_balance_measures_are_the_twins_not_the_estimates(talos14):
    """Under 'sensors' the controller's robot holds the estimate; the measures read the twin: a
    push trial's CoG error and momentum are Pinocchio's CoM and centroidal momentum of the
    simulator's own logged state, cycle by cycle, against one reference (the estimate's CoM
    differs from the twin's by more than the tolerance), and the balance monitor's CoG is the
    twin's while the robot holds another state."""
    from types import SimpleNamespace

    import pinocchio as pin

    from wholebody.control.balance import MomentumBalance
    from wholebody.scenarios.measures import BalanceMonitor
    from wholebody.scenarios.push import with_peak_force
    from wholebody.scenarios.pushes import push_trial

    params = with_peak_force(talos14, SCENARIOS["push"].validate(
        talos14, {"duration": "0.35", "start": "0.05", "push_duration": "0.05"}))
    conditions = RobotConditions(talos14, "sensors", seed=2)
    balance = MomentumBalance(talos14, gains="pd")
    trial = push_trial(talos14, "pd", params, observers=[conditions], balance=balance)
    log = trial.log.arrays()
    data = talos14.model.createData()
    references = []
    for k in range(len(trial.cog_error)):
        pin.computeCentroidalMomentum(talos14.model, data, log["q"][k], log["v"][k])
        references.append(data.com[0] - trial.cog_error[k])
        np.testing.assert_allclose(trial.momentum[k], data.hg.vector, atol=1e-12)
    np.testing.assert_allclose(references, np.tile(references[0], (len(references), 1)),
                               atol=1e-12)
    # the CoM of the last estimate the controller read is not the twin's of that cycle
    assert np.abs(balance.com - (references[0] + trial.cog_error[-1])).max() > 1e-6
    # the balance monitor on a robot whose cache holds another state
    sim = Simulator(talos14)
    ctrl = SimpleNamespace(cop_margin=0.1, com_ref=np.zeros(3), h_ref=np.zeros(6))
    monitor = BalanceMonitor(talos14, sim, ctrl)
    q, v = sim.state()
    elsewhere = q.copy()
    elsewhere[0] += 0.05
    talos14.update(elsewhere, v)
    monitor(0.0, SimpleNamespace(forces={}, qdd=np.zeros(talos14.nv)))
    expected = pin.centerOfMass(talos14.model, talos14.model.createData(), q)
    np.testing.assert_allclose(monitor.arrays()["com"][0], expected, atol=1e-12)
    assert abs(talos14.com[0] - expected[0] - 0.05) < 1e-9  # the robot still holds its state
