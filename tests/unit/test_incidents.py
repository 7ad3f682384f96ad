"""The incident log: what first went wrong in a run, checked against the simulator's own log of
joint positions and the Pinocchio model's limits, and against the controller results the closed
loop saw; and it reaches summary.json through Scenario.run."""

from __future__ import annotations

import numpy as np
import pytest

from wholebody.guard import Outcome
from wholebody.formulation import Solution
from wholebody.scenarios import get_scenario
from wholebody.scenarios.base import ScenarioResult
from wholebody.scenarios.loop import run_closed_loop
from wholebody.sim.incidents import IncidentLog
from wholebody.sim.simulator import Simulator


class ConstantTorque:
    """A controller that sends ``tau`` every cycle; the cycles listed in ``failing`` (0-based)
    are reported as held with the status 'stub failure'."""

    def __init__(self, tau, failing=(), clipping=()):
        self.tau, self.failing, self.cycle, self.times = np.asarray(tau, float), set(failing), 0, []
        self.clipping = set(clipping)

    def compute(self, q, v, t=0.0):
        outcome = Outcome.HELD if self.cycle in self.failing else Outcome.SOLVED
        if self.cycle in self.clipping:
            outcome = Outcome.CLIPPED
        self.cycle += 1
        self.times.append(t)
        return Solution(qdd=np.zeros(0), lam=np.zeros(0), tau=self.tau, forces={},
                        outcome=outcome, status="stub failure" if outcome is Outcome.HELD
                        else "solved", level_costs=np.zeros(0))


def _first_limit_times(sim, robot) -> dict[tuple[str, str], float]:
    """(joint, side) -> first logged time at which the joint's position was at or beyond the
    model's limit on that side (Pinocchio convention, the robot's own model)."""
    t, q = np.asarray(sim.log.t), np.asarray(sim.log.q)[:, robot.model.nq - robot.na:]
    lower = robot.model.lowerPositionLimit[-robot.na:]
    upper = robot.model.upperPositionLimit[-robot.na:]
    out = {}
    for j, name in enumerate(robot.joint_names):
        for side, hit in (("lower", q[:, j] <= lower[j]), ("upper", q[:, j] >= upper[j])):
            if hit.any():
                out[(name, side)] = float(t[np.argmax(hit)])
    return out


def _limit_incidents(log) -> dict[tuple[str, str], float]:
    out = {}
    for x in log.incidents:
        if x.what.startswith("joint "):
            name, side = x.what.split()[1], x.what.split()[4]
            assert (name, side) not in out, "each joint and side is reported once"
            out[(name, side)] = x.t
    return out


@pytest.mark.parametrize("compiled", [True, False])
def test_joint_limits_are_reported_when_the_logged_state_first_reaches_them(robots, monkeypatch,
                                                                             compiled):
    """HyQ pushed by half its torque limits on every joint for 0.4 s: its joints run into their
    ranges. Every (joint, side) whose logged position reached the model's limit is reported, at
    that step's time, and nothing else; with the per-step test compiled and in Python."""
    from wholebody.sim import incidents
    if compiled:
        from conftest import native_cycle_or_skip
        native_cycle_or_skip("_sim_reads")
    else:
        monkeypatch.setattr(incidents, "_sim_reads", None)
    robot = robots["hyq"]
    log = IncidentLog()
    sim = Simulator(robot, observers=[log])
    tau = 0.5 * robot.torque_limits.upper(robot.q_ref[7:])
    run_closed_loop(sim, ConstantTorque(tau), 0.4, control_period=0.004)
    expected = _first_limit_times(sim, robot)
    assert len(expected) >= 4  # the check below compares something
    assert _limit_incidents(log) == expected
    assert all(x.run == "" for x in log.incidents)


def test_a_joint_that_starts_on_a_limit_is_left_out(robots):
    """A posture on a limit (talos's closed grippers, which then touch it on and off) is not an
    incident, on that side; the other side still is."""
    robot = robots["hyq"]
    joint = robot.joint_names.index("lf_kfe_joint")
    lower = robot.model.lowerPositionLimit[7 + joint]
    upper = robot.model.upperPositionLimit[7 + joint]
    q = robot.q_ref.copy()
    q[7 + joint] = upper
    log = IncidentLog()
    sim = Simulator(robot, observers=[log])
    sim.reset(q)
    adr = sim.model.jnt_qposadr[sim.model.joint("lf_kfe_joint").id]
    for value in (upper, upper - 0.1, upper):
        sim.data.qpos[adr] = value
        log.step(sim)
    assert log.incidents == []
    sim.data.qpos[adr] = lower
    log.step(sim)
    assert [x.what for x in log.incidents] == [
        f"joint lf_kfe_joint at its lower position limit ({lower:.3f})"]


def test_the_first_failed_cycle_is_reported_once_with_its_status(robots):
    robot = robots["hyq"]
    hold = np.zeros(robot.na)  # 0.05 s: the robot only starts to sag
    log = IncidentLog()
    sim = Simulator(robot, observers=[log], label="stub")
    controller = ConstantTorque(hold, failing=(3, 4, 9))
    run_closed_loop(sim, controller, 0.05, control_period=0.004)
    failures = [x for x in log.incidents if "controller" in x.what]
    assert len(failures) == 1
    assert failures[0].t == controller.times[3]
    assert failures[0].what == "first failed controller cycle (held): stub failure"
    assert failures[0].as_dict() == {"t": round(controller.times[3], 4), "what": failures[0].what,
                                     "run": "stub"}
    sim.reset()  # a reset starts the run over
    assert log.incidents == []
    run_closed_loop(sim, ConstantTorque(hold), 0.05, control_period=0.004)
    assert log.incidents == []


def test_a_clipped_cycle_does_not_hide_the_first_held_one(robots):
    """Clipped at cycle 2, held from cycle 6: both are reported, each once, in time order."""
    robot = robots["hyq"]
    log = IncidentLog()
    sim = Simulator(robot, observers=[log], label="stub")
    controller = ConstantTorque(np.zeros(robot.na), failing=(6, 7), clipping=(2, 3, 8))
    run_closed_loop(sim, controller, 0.05, control_period=0.004)
    failures = [x for x in log.incidents if "controller" in x.what]
    assert [(x.what.split(":")[0], x.t) for x in failures] == [
        ("first failed controller cycle (clipped)", controller.times[2]),
        ("first failed controller cycle (held)", controller.times[6])]


def test_runs_are_kept_apart_by_label(robots):
    robot = robots["hyq"]
    log = IncidentLog()
    for label, failing in (("first", (2,)), ("second", (5,))):
        sim = Simulator(robot, observers=[log], label=label)
        run_closed_loop(sim, ConstantTorque(np.zeros(robot.na), failing), 0.05,
                        control_period=0.004)
    assert [(x.run, round(x.t, 3)) for x in log.incidents] == [("first", 0.008), ("second", 0.02)]


def test_scenario_run_puts_the_incidents_into_its_summary(robots):
    """A scenario that declares its simulations is watched: a short stand has an (empty) incident
    list in its summary; a result nobody watched has no such key."""
    result = get_scenario("stand").run(robots["hyq"], overrides={"duration": "0.2"})
    assert result.incidents == [] and result.summary()["incidents"] == []
    assert "incidents" not in ScenarioResult("stand", "hyq", "standing", True, {}, {}).summary()
