"""A longer closed-loop run keeps more memory only for its logs: the crawl's simulator log (1 kHz)
and gait log (250 Hz) grow by about 8 bytes per number per row, and nothing else grows with the
simulated time."""

import logging
import tracemalloc

import numpy as np
import pytest

from wholebody.scenarios.locomotion import run_gait, steady_command

pytestmark = pytest.mark.slow


@pytest.fixture(autouse=True)
def _quiet():
    logging.disable(logging.WARNING)
    yield
    logging.disable(logging.NOTSET)


def _crawl(robot, duration: float) -> tuple[int, int, int, int]:
    """(memory kept by the run while its result lives, bytes held by its logs, numbers per step
    of the simulator log, numbers per cycle of the gait log)."""
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        run = run_gait(robot, "passive", "crawl", steady_command(0.1), duration)
        kept = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert not run.fell and run.failures == 0
    gait_bytes = sum(a.nbytes for a in run.log.values())
    sim_numbers = sum(int(np.prod(a.shape[1:])) for k, a in run.sim.log.arrays().items()
                      if k != "contact_names")
    gait_numbers = sum(int(np.prod(a.shape[1:])) for a in run.log.values())
    return kept, run.sim.log.nbytes + gait_bytes, sim_numbers, gait_numbers


def test_only_the_logs_grow_with_the_simulated_time(robots):
    robot = robots["hyq"]
    short, long = 2.0, 6.0
    kept_short, logs_short, _, _ = _crawl(robot, short)
    kept_long, logs_long, sim_numbers, gait_numbers = _crawl(robot, long)
    # the logs: 8 bytes per number, at most one unfilled chunk per series (twice the rows)
    per_second = 8 * (sim_numbers * 1000 + gait_numbers * 250)
    assert logs_long <= 2 * per_second * long
    # everything else the run keeps does not grow with its duration
    others_growth = (kept_long - logs_long) - (kept_short - logs_short)
    assert others_growth < 0.1 * per_second * (long - short), (others_growth, per_second)
