"""``trot-push`` without a closed loop: the push as the simulator applies it (its impulse from the
logged force series, its direction against the ``push`` scenario's, its point at the trunk's
centre of mass in MuJoCo), the push's timing against the trot schedule, and the checks (exit 2
before simulating)."""

from __future__ import annotations

import numpy as np
import pytest

import wholebody as wb
from wholebody.cli import main
from wholebody.scenarios import get_scenario
from wholebody.scenarios.locomotion import make_schedule
from wholebody.scenarios.pushes import make_push
from wholebody.scenarios.trot_push import (GAIT_START, on_cone_share, recovery_time, timing,
                                           trunk_push)
from wholebody.sim.simulator import Simulator


@pytest.fixture(scope="module")
def hyq():
    return wb.load_robot("hyq")


def pushed(robot, push, steps: int):
    """The twin under ``push`` for ``steps`` steps of zero torque: (log arrays, the pushes'
    points and the trunk body's CoM per step)."""
    sim = Simulator(robot)
    sim.add_push(push)
    body = sim.twin.joint_bodies[robot.model.names[1]]
    points = []
    for _ in range(steps):
        com = sim.data.xipos[body].copy()  # the state the step applies the push in
        sim.step(np.zeros(robot.na))
        if sim.active_pushes:
            (point, _), = sim.active_pushes
            points.append((point, com))
    return sim.log.arrays(), points


@pytest.mark.parametrize("dv,angle", [(0.3, 90.0), (0.45, 0.0), (0.2, 225.0)])
def test_the_pulse_gives_mass_times_dv(hyq, dv, angle):
    """The force the simulator applied, integrated over time, is m dv along the push's
    direction, and it acts at the trunk body's centre of mass (MuJoCo's xipos)."""
    push = trunk_push(hyq, dv, angle, centre=0.1, duration=0.1)
    a, points = pushed(hyq, push, 250)
    impulse = np.trapezoid(a["push_force"], a["t"], axis=0)
    mass = sum(inertia.mass for inertia in hyq.model.inertias)
    np.testing.assert_allclose(impulse, mass * dv * np.array(
        [-np.cos(np.radians(angle)), -np.sin(np.radians(angle)), 0.0]), atol=1e-3 * mass * dv)
    assert np.abs(a["push_force"][a["t"] < 0.05 - 1e-9]).max() == 0.0  # centred on 0.1 s
    assert np.abs(a["push_force"][a["t"] > 0.15 + 1e-9]).max() == 0.0
    for point, com in points:
        np.testing.assert_allclose(point, com, atol=1e-9)


def test_angle_convention_is_the_push_scenarios(hyq):
    """90 deg pushes the left side toward -y, as ``push --set location=angle`` does; every angle's
    force points where that scenario's does."""
    for angle in (0.0, 90.0, 180.0, 270.0, -45.0):
        ours = trunk_push(hyq, 0.3, angle, 1.0, 0.1).unit_direction
        theirs = make_push({"location": "angle", "angle": angle, "height": 0.0,
                            "peak_force": 1.0, "start": 0.0, "push_duration": 0.1},
                           hyq).unit_direction
        np.testing.assert_allclose(ours, theirs, atol=1e-12)
    np.testing.assert_allclose(trunk_push(hyq, 0.3, 90.0, 1.0, 0.1).unit_direction, [0, -1, 0],
                               atol=1e-12)


def test_default_push_comes_in_the_middle_of_a_diagonal_stance(hyq):
    """The trot schedule itself: at the push's centre one diagonal pair stands, as long since
    its touchdown as until its lift-off."""
    params = get_scenario("trot-push").validate(hyq, {})
    t = timing(hyq, params)["push_time"]
    schedule = make_schedule(hyq, "trot", GAIT_START, params)
    standing = schedule.stance_legs(t)
    assert len(standing) == 2
    for leg in standing:
        since, until = t - schedule.last_touchdown(leg, t), schedule.next_liftoff(leg, t) - t
        assert since == pytest.approx(until, abs=1e-9)
        assert since == pytest.approx(0.25 * schedule.period, abs=1e-9)


def test_recovery_time_and_cone_share_on_made_up_series():
    t = np.arange(0.0, 2.0, 0.01)
    deviation = np.where((t > 0.5) & (t < 1.2), 1.0, 0.1)
    assert recovery_time(t, deviation, 0.5, 0.6) == pytest.approx(0.6, abs=0.011)
    assert recovery_time(t, np.full_like(t, 0.1), 0.5, 0.6) == 0.0
    assert recovery_time(t, np.ones_like(t), 0.5, 0.6) is None
    # two feet; the first on the pyramid's face |f_x| = mu f_z in half the cycles
    mu, n = 0.7, 10
    forces = np.zeros((n, 6))
    forces[:, 2] = forces[:, 5] = 100.0
    forces[::2, 0] = mu * 100.0
    forces[1::2, 0] = 0.5 * mu * 100.0
    stance = np.ones((n, 2), dtype=bool)
    assert on_cone_share(forces, stance, mu) == pytest.approx(0.5)
    stance[:, 0] = False  # a swinging foot's force does not count
    assert on_cone_share(forces, stance, mu) == 0.0


@pytest.mark.parametrize("sets,needle", [
    (["angle=400"], "--set angle: expected a finite number in [-360, 360], got '400'"),
    (["angles=0,90,720"], "--set angles: expected a finite number in [-360, 360], got item '720'"),
    (["dv=0"], "--set dv: expected a finite number in (0, 5], got '0'"),
    (["dv=-0.3"], "--set dv: expected a finite number in (0, 5], got '-0.3'"),
    (["phase=1"], "--set phase: expected a finite number in [0, 1), got '1'"),
    (["phase=-0.1"], "--set phase: expected a finite number in [0, 1), got '-0.1'"),
    (["settle=1"], "--set settle: expected a finite number in [2, 100], got '1'"),
    (["push_duration=0.9"], "--set push_duration: 0.9 s is longer than the gait period"),
    (["bisect=true", "bisect_low=0.5", "bisect_high=0.4"],
     "--set bisect_low (0.5) must be below bisect_high (0.4)"),
])
def test_bad_input_exit_2_before_simulating(sets, needle, capsys, no_simulation, tmp_path):
    argv = ["run", "trot-push", *[a for s in sets for a in ("--set", s)],
            "--out", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("wholebody: error: ") and needle in err, err
    assert not (tmp_path / "out").exists()


def test_a_biped_is_refused(capsys, no_simulation):
    assert main(["run", "trot-push", "--robot", "talos14"]) == 2
    assert "trot-push" in capsys.readouterr().err
