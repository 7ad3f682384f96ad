"""The passive WBC walks every quadruped preset on its defaults: the gait, speeds, trunk gains and
force bounds derived from the robot (its roles, standing height, mass and inertia), never from
HyQ's absolute numbers. Short runs in the twin: a crawl and a trot, judged by the simulator
(no fall, every cycle solved, the robot went forward about as commanded)."""

import numpy as np
import pytest

import wholebody as wb
from wholebody.planning.trunk import VelocityCommand
from wholebody.robots.reference import froude_ratio
from wholebody.scenarios import get_scenario
from wholebody.scenarios.locomotion import run_gait

pytestmark = pytest.mark.slow

DURATION = 5.0  # s: 1 s standing, then the gait


CASES = [(name, gait) for name in ("go1", "go2", "a1", "solo12", "anymal_c")
         for gait in ("crawl", "trot")]


@pytest.mark.parametrize("name, gait", CASES)
def test_passive_wbc_walks_every_quadruped_preset(name, gait):
    robot = wb.load_robot(name)
    speed = 0.1 * froude_ratio(robot)  # the paper's 0.1 m/s on HyQ, Froude-scaled
    # as the scenarios do: from a third of the speed at the gait start to all of it 2 s later
    command = VelocityCommand.speed_ramp(speed / 3, speed, 1.0, 3.0)
    run = run_gait(robot, "passive", gait, command, DURATION)
    assert not run.fell and run.failures == 0, (name, gait, run.failures)
    # the base went forward, as far as commanded within a quarter (the gait starts at 1 s)
    expected = (speed * 2 / 3) * 2.0 + speed * (DURATION - 3.0)
    assert run.distance == pytest.approx(expected, rel=0.25), run.distance
    tracking = run.tracking(t_from=1.0)
    # trunk errors small against the robot's size: mm-level CoM, a few degrees of tilt
    assert tracking["linear_max_m"] < 0.1 * robot.q_ref[2], tracking
    assert tracking["angular_max_rad"] < 0.35, tracking


@pytest.mark.parametrize("name", [name for name, gait in CASES if gait == "trot"])
def test_every_quadruped_preset_trots_over_the_ramp(name):
    """Fig. 8's course in proportion to the robot (15° up, a plateau, 15° down; lengths times
    h / h_HyQ, speed Froude-scaled), on the robot's defaults: across it without a fall or a failed
    cycle, the simulator's roll and pitch within the paper's 0.2 rad of the reference, every foot
    past the course's end."""
    robot = wb.load_robot(name)
    result = get_scenario("ramp").run(robot, "passive", {})
    m = result.metrics
    assert result.success and not m["fell"] and m["failed_cycles"] == 0, m
    assert m["roll_error_max_rad"] < 0.2 and m["pitch_error_max_rad"] < 0.2, m
    assert min(m["final_feet_x_m"]) > m["course_end_x_m"], m
    assert -m["desired_pitch_range_rad"][0] > 0.15  # the reference did pitch with the slopes


def test_two_joint_legs_crawl():
    """ODRI's 8-DoF Solo (hip and knee flexion only, stance rows linearly dependent): the passive
    WBC crawls it on its defaults, no fall, every cycle solved, about as far as commanded; its
    trunk cannot sway sideways (no hip abduction), so the CoM error is larger than on the
    presets but stays a fraction of the standing height."""
    from conftest import solo8_description

    robot = wb.load_robot(solo8_description())
    speed = 0.1 * froude_ratio(robot)
    command = VelocityCommand.speed_ramp(speed / 3, speed, 1.0, 3.0)
    run = run_gait(robot, "passive", "crawl", command, DURATION)
    assert not run.fell and run.failures == 0, run.failures
    expected = (speed * 2 / 3) * 2.0 + speed * (DURATION - 3.0)
    assert run.distance == pytest.approx(expected, rel=0.25), run.distance
    assert run.tracking(t_from=1.0)["linear_max_m"] < 0.3 * robot.q_ref[2]


@pytest.mark.parametrize("gait", ["crawl", "trot"])
def test_legs_of_five_joints_walk(gait):
    """IIT Centauro's legs (five joints each, wheels locked as spheres): the stance and swing
    tasks leave two joints per leg free, which the posture regulariser holds; the passive WBC
    walks it on its defaults, no fall, every cycle solved, about as far as commanded."""
    from conftest import centauro_description

    robot = wb.load_robot(centauro_description())
    speed = 0.1 * froude_ratio(robot)
    command = VelocityCommand.speed_ramp(speed / 3, speed, 1.0, 3.0)
    run = run_gait(robot, "passive", gait, command, DURATION)
    assert not run.fell and run.failures == 0, run.failures
    expected = (speed * 2 / 3) * 2.0 + speed * (DURATION - 3.0)
    assert run.distance == pytest.approx(expected, rel=0.25), run.distance
    assert run.tracking(t_from=1.0)["linear_max_m"] < 0.1 * robot.q_ref[2]


@pytest.mark.parametrize("angle", [12.0, 15.0])
def test_legs_of_five_joints_trot_over_the_ramp(angle):
    """IIT Centauro on the ramp, on its defaults: a level trunk (its splayed legs move less from
    their posture than under a trunk parallel to the slope) and swings no higher than its legs
    reach take it up, across and down without a fall or a failed cycle, roll and pitch within
    the paper's 0.2 rad, every foot past the course's end."""
    from conftest import centauro_description

    robot = wb.load_robot(centauro_description())
    result = get_scenario("ramp").run(robot, "passive", {"angle": angle})
    m = result.metrics
    assert result.success and not m["fell"] and m["failed_cycles"] == 0, m
    assert m["terrain_alignment"] == 0.0
    assert m["roll_error_max_rad"] < 0.2 and m["pitch_error_max_rad"] < 0.2, m
    assert min(m["final_feet_x_m"]) > m["course_end_x_m"], m


def _trot_mean_roll(robot, controller, command, duration, options):
    """(|mean roll| of the simulator's base after 3 s, its final yaw) of a trot that must neither
    fall nor fail a cycle."""
    import pinocchio as pin

    rolls = []

    def on_cycle(t, result, controller_, sim):
        if t > 3.0:
            q = sim.state()[0]
            R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
            rolls.append(np.arctan2(R[2, 1], R[2, 2]))

    run = run_gait(robot, controller, "trot", command, duration, on_cycle=on_cycle,
                   controller_options=options)
    assert not run.fell and run.failures == 0, (options, run.failures)
    yaw = pin.rpy.matrixToRpy(pin.Quaternion(run.sim.state()[0][3:7]).toRotationMatrix())[2]
    return abs(np.mean(rolls)), yaw


@pytest.mark.parametrize("controller", ["passive", "quasi-static"])
def test_a_narrow_robot_trots_without_a_steady_roll(controller):
    """ANYmal B stands narrow (tan ψ 0.55 against HyQ's 0.87): with unit trunk weights the pitch
    asks cancelled the roll moment its diagonal feet can make and it trotted rolled to one side;
    with the robot-relative pitch weight its mean roll (the simulator's base, 3-6 s) stays small,
    and nothing else changed between the two runs."""
    from conftest import anymal_b_description

    robot = wb.load_robot(anymal_b_description())
    command = VelocityCommand.speed_ramp(0.0, 0.1 * froude_ratio(robot), 1.0, 2.0)
    mean_roll = {label: _trot_mean_roll(robot, controller, command, 6.0, {"Q": Q})[0]
                 for label, Q in (("robot-relative", None), ("unit", (1.0,) * 6))}
    assert mean_roll["robot-relative"] < 0.02 and mean_roll["unit"] > 0.03, mean_roll


def test_the_trunk_weights_turn_with_the_heading(monkeypatch):
    """ANYmal B trotting while it turns 2.1 rad (0.3 rad/s): its pitch weight acts about the trunk
    reference's heading axes, so the mean roll (the simulator's base, after 3 s) stays small; the
    same weights left in world axes, which once the robot has turned weigh its roll instead, let it
    trot rolled to one side."""
    import wholebody.control.passive_stack as passive_stack
    from conftest import anymal_b_description

    robot = wb.load_robot(anymal_b_description())
    command = VelocityCommand.constant(0.1 * froude_ratio(robot), 0.0, 0.3)
    heading, yaw = _trot_mean_roll(robot, "passive", command, 8.0, {})
    assert abs(yaw) > 1.5  # it did turn
    task = passive_stack.TrunkWrenchTask
    monkeypatch.setattr(passive_stack, "TrunkWrenchTask",
                        lambda *args, **kwargs: task(*args, **{**kwargs, "heading": False}))
    world, _ = _trot_mean_roll(robot, "passive", command, 8.0, {})
    assert heading < 0.03 and world > 0.06, (heading, world)


def test_quasi_static_baseline_crawls_a_heavy_robot_inside_its_torque_limits():
    """IIT Centauro (117 kg) crawling at the crawl scenario's top speed: the baseline's static map
    needs some stance joints at their torque limits (the torques the simulator applies reach 95 %
    of a limit), and with the limits as rows of its force QP every cycle is solved inside them:
    none flagged, none the simulator had to clip, no fall."""
    from conftest import centauro_description

    robot = wb.load_robot(centauro_description())
    speed = 0.15 * froude_ratio(robot)
    command = VelocityCommand.speed_ramp(speed / 3, speed, 1.0, 3.0)
    used, clipped = [], []

    def on_cycle(t, result, controller, sim):
        used.append(np.max(np.abs(sim.data.ctrl) / robot.model.effortLimit[6:]))
        clipped.append(np.max(np.abs(sim.last_clipped)))

    run = run_gait(robot, "quasi-static", "crawl", command, DURATION, on_cycle=on_cycle)
    assert not run.fell and run.failures == 0, run.failures
    assert max(used) >= 0.95 and max(clipped[1:]) < 1e-6


def test_a_gait_run_stops_a_grace_period_after_the_fall():
    """Knees limited to 1 Nm cannot hold HyQ up: the run ends FALL_GRACE after the fall, and the
    simulator's own base state says the robot was up before the recorded fall time and down at it
    (base below half its standing height, or tilted by more than 45 degrees)."""
    from wholebody.scenarios.locomotion import FALL_GRACE
    from wholebody.scenarios.measures import FALL_HEIGHT_FRACTION

    robot = wb.load_robot("hyq")
    knees = [j for j in robot.joint_names if "kfe" in j]
    states = []
    run = run_gait(robot, "passive", "stand", duration=6.0,
                   controller_options={"torque_limit_override": dict.fromkeys(knees, 1.0)},
                   on_cycle=lambda t, r, c, sim: states.append((t, *sim.state()[0][:7])))
    assert run.fell and run.fell_at is not None
    t, z, qx, qy = np.array(states)[:, [0, 3, 4, 5]].T
    cos_tilt = 1.0 - 2.0 * (qx ** 2 + qy ** 2)  # R[2, 2] of the base quaternion (x, y, z, w)
    down = (z < FALL_HEIGHT_FRACTION * robot.q_ref[2]) | (cos_tilt < np.cos(np.radians(45.0)))
    assert down[np.searchsorted(t, run.fell_at)] and not down[t < run.fell_at].any()
    assert run.fell_at + FALL_GRACE <= run.sim.t < run.fell_at + FALL_GRACE + 0.01
    assert run.sim.t < 5.0  # stopped well before the 6 s asked


def test_the_gait_shape_parameters_reach_the_twin():
    """``crawl --set clearance=0.07 --set period=1.2`` on go1: in the twin, the swing feet rise
    to 7 cm above the floor (their spheres' bottoms, within 5 mm) instead of the default's
    4.5 cm (HyQ's 0.1 m in proportion), and each foot lifts off once per 1.2 s (1.69 s by
    default)."""
    robot = wb.load_robot("go1")
    params = get_scenario("crawl").validate(robot, {"clearance": "0.07", "period": "1.2"})
    default = get_scenario("crawl").validate(robot, {})
    radius = robot.contact(robot.contact_names[0]).spec.radius
    heights, lifts = {}, {}
    for label, p in (("set", params), ("default", default)):
        run = run_gait(robot, "passive", "crawl", VelocityCommand.constant(0.05), 5.0,
                       shape=p)
        assert not run.fell and run.failures == 0, label
        t, feet, stance = run.log["t"], run.log["feet"], run.log["stance"]
        heights[label] = float(feet[:, :, 2].max()) - radius
        first = np.flatnonzero(np.diff(stance[:, 0].astype(int)) == -1) + 1  # lift-offs, leg 0
        lifts[label] = np.diff(t[first])
    assert heights["set"] == pytest.approx(0.07, abs=5e-3), heights
    assert heights["default"] == pytest.approx(default["clearance"], abs=5e-3), heights
    np.testing.assert_allclose(lifts["set"], 1.2, atol=0.01)
    assert abs(lifts["default"].mean() - 1.2) > 0.3, lifts
