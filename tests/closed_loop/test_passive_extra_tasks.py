"""A task of the user's own in the passive WBC's QP (``extra_tasks``), in closed loop in the
MuJoCo twin: HyQ crawls with a cap on every foot's normal force, measured by the simulator."""

from conftest import ForceCap, native_cycle_or_skip

from wholebody.planning.trunk import VelocityCommand
from wholebody.scenarios.locomotion import run_gait


def peak_normal_force(run, after: float = 1.0) -> float:
    """The largest normal force the twin measured at any foot after ``after`` s."""
    log = run.sim.log.arrays()
    return float(log["contact_wrenches"][log["t"] > after, :, 2].max())


def test_crawl_with_a_force_cap(robots):
    """A hard cap of 0.55 m g on each foot's normal force (the default crawl's feet reach about
    0.63 m g): the crawl goes on (no fall, no failed cycle, the same distance) and the twin's
    measured forces stay within 1 % of the cap, while the plain controller's exceed it by 10 %;
    the trunk pays for it (its wrench is not fully met) but stays within a centimetre."""
    native_cycle_or_skip("_hierarchy_cycle")
    robot = robots["hyq"]
    cap = 0.55 * robot.mass * 9.81
    command = VelocityCommand.speed_ramp(0.0, 0.2, 1.0, 2.0)
    capped = run_gait(robot, "passive", "crawl", command, duration=5.0,
                      controller_options={"extra_tasks": {"hard": [ForceCap(cap)]}})
    plain = run_gait(robot, "passive", "crawl", command, duration=5.0)
    assert capped.controller.engine == "native"
    for run in (capped, plain):
        assert not run.fell and run.failures == 0
    assert abs(capped.distance - plain.distance) < 0.05 * plain.distance
    assert peak_normal_force(capped) <= 1.01 * cap
    assert peak_normal_force(plain) > 1.1 * cap
    linear = capped.tracking(1.0)["linear_rms_m"]
    assert plain.tracking(1.0)["linear_rms_m"] < linear < 0.01
