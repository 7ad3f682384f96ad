"""First closed loop: the contact-consistent standing controller keeps every preset standing for 5 s
in the twin (base drift < 1 cm, no fall), and the simulator's contact forces carry the weight."""

import numpy as np
import pytest

from wholebody.control import StandingController
from wholebody.scenarios import get_scenario
from wholebody.sim.simulator import Simulator


@pytest.mark.parametrize("name", ["talos14", "talos", "hyq"])
def test_stands_five_seconds(robots, name):
    robot = robots[name]
    result = get_scenario("stand").run(robot, overrides={"duration": "5.0"})
    log = result.log.arrays()
    base = log["q"][:, :3]
    assert log["t"][-1] == pytest.approx(5.0 - 1e-3)
    drift = np.linalg.norm(base - base[0], axis=1).max()
    assert drift < 0.01, drift
    assert base[:, 2].min() > 0.9 * base[0, 2]  # did not fall or sag
    # after settling, the floor carries the weight (simulator's own contact forces)
    normal = log["contact_wrenches"][1000:, :, 2].sum(axis=1)
    np.testing.assert_allclose(normal, robot.mass * 9.81, rtol=0.01)
    assert np.all(log["contact_wrenches"][1000:, :, 2] > 0)  # every foot loaded
    assert result.success and result.metrics["base_drift_max_m"] == pytest.approx(drift)


def test_naive_gravity_compensation_is_not_contact_consistent(robots):
    """Compensating only the joint rows (tau = h_u) is wrong for a robot on its feet: the contact-
    consistent torques differ by J_{c,u}^T lambda, which carries the weight (docs/architecture.md)."""
    robot = robots["talos14"]
    ctrl = StandingController(robot, kp=0.0, kd=0.0)
    q = robot.q_ref
    res = ctrl.compute(q, np.zeros(robot.nv))
    robot.update(q, np.zeros(robot.nv))
    naive = robot.h[6:]
    knee = robot.joint_names.index("leg_left_4_joint")
    assert abs(res.tau[knee] - naive[knee]) > 20.0
    # the contact-consistent solution balances the floating-base rows exactly
    J = robot.stacked_contact_jacobian()
    lam = np.concatenate([res.contact_forces[n] for n in robot.contact_names])
    np.testing.assert_allclose(J[:, :6].T @ lam, robot.h[:6], atol=1e-8)
    assert sum(res.contact_forces[n][2] for n in robot.contact_names) == pytest.approx(
        robot.mass * 9.81, rel=1e-9)


def test_standing_controller_in_twin_holds_without_pd_drift(robots):
    """With PD only on the joints and exact gravity compensation, the twin barely moves in 1 s."""
    robot = robots["hyq"]
    sim = Simulator(robot)
    ctrl = StandingController(robot)
    for _ in range(1000):
        sim.step(ctrl.compute(*sim.state()).tau)
    q, v = sim.state()
    assert np.linalg.norm(q[:3] - robot.q_ref[:3]) < 2e-3
    assert np.abs(v).max() < 1e-2
