"""MomentumBalance (Herzog et al. 2016 Table 2, no joint PD) in closed loop in the twin."""

import numpy as np
import pytest

from wholebody.control.balance import MomentumBalance
from wholebody.sim.disturbance import Push
from wholebody.sim.simulator import Simulator


def run(robot, controller, steps, push=None):
    sim = Simulator(robot)
    if push is not None:
        sim.add_push(push)
    com_error, failures = [], 0
    for _ in range(steps):
        q, v = sim.state()
        sol = controller.compute(q, v, sim.t)
        failures += not sol.ok
        com_error.append(robot.com - controller.com_ref)
        sim.step(sol.tau)
    return np.array(com_error), failures


@pytest.mark.parametrize("gains", ["pd", "lqr"])
def test_balance_holds_still(robots, gains):
    robot = robots["talos14"]
    err, failures = run(robot, MomentumBalance(robot, gains=gains), 1000)
    assert failures == 0 and np.abs(err).max() < 1e-3


def test_pd_balance_recovers_from_a_push(robots):
    """A 100 N half-sine push of 0.1 s (6.4 Ns, Δv = 0.07 m/s on 90 kg) from the front above the
    hip: the CoG moves a few mm and returns within 5 mm (Sect. 5.2.2's recovery criterion)."""
    robot = robots["talos14"]
    push = Push("torso_2_link", (-1.0, 0.0, 0.0), 100.0, start=0.2, duration=0.1,
                offset=(0.1, 0.0, 0.1))
    err, failures = run(robot, MomentumBalance(robot, gains="pd"), 2500, push)
    assert failures == 0
    assert 1e-3 < np.abs(err[:, 0]).max() < 0.05  # the push did move the CoG
    assert np.linalg.norm(err[-1]) < 5e-3
