"""HyQ trots at 1.5 m/s (Froude 0.38) in the MuJoCo twin with the stride-capped trot period: no
fall, every WBC cycle solved, the simulator's base within 10 % of the commanded speed, and the
stance phases as long as the timing law's formula asks (T_stance = max_stride / v)."""

import numpy as np
import pytest

from wholebody.planning.trunk import VelocityCommand
from wholebody.scenarios.gait_measures import stance_phases
from wholebody.scenarios.locomotion import MAX_STRIDE, paper_length, run_gait

SPEED = 1.5


@pytest.mark.slow
def test_hyq_trots_at_one_and_a_half_metres_per_second(robots):
    hyq = robots["hyq"]
    command = VelocityCommand.speed_ramp(0.0, SPEED, 1.0, 6.0)
    xs = []
    run = run_gait(hyq, "passive", "trot", command, 8.0,
                   on_cycle=lambda t, result, ctrl, sim: xs.append((t, sim.state()[0][0])))
    assert not run.fell and run.failures == 0
    t, x = np.array(xs).T
    late = t >= 6.5  # the speed held since 6 s
    speed = np.polyfit(t[late], x[late], 1)[0]
    assert abs(speed - SPEED) <= 0.1 * SPEED
    # the stances that began after the ramp last max_stride / v (within one 4 ms cycle)
    log = run.log
    stances = [(log["t"][b - 1] - log["t"][a] + 0.004) for _, a, b in
               stance_phases(log["t"], log["stance"]) if log["t"][a] > 6.0 and b < len(log["t"])]
    assert stances
    expected = paper_length(MAX_STRIDE).value(hyq) / SPEED
    assert np.allclose(stances, expected, atol=0.0041)
