"""The velocity-command schedule: the trunk reference's heading and path against an ODE
integration of the command, the Raibert footholds under a turning command against their formula,
and the ``steer`` scenario's schedule and parameter checks (no simulation)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import wholebody as wb
from wholebody.planning import CommandPhase, CommandSchedule, GaitPlanner, TrunkReference, trot
from wholebody.scenarios import get_scenario
from wholebody.scenarios.steer import command_schedule, period_mean


@pytest.fixture(scope="module")
def hyq():
    return wb.load_robot("hyq")


def schedule_example() -> CommandSchedule:
    return CommandSchedule.from_phases(
        [CommandPhase("forward", 2.0, 0.4), CommandPhase("turn", 3.0, 0.2, 0.05, 0.5),
         CommandPhase("side", 2.0, 0.0, -0.12), CommandPhase("stop", 1.5)], start=1.0, ramp=0.8)


def integrate(cmd: CommandSchedule, com0, yaw0: float, t0: float, t_end: float) -> np.ndarray:
    """x, y, yaw from dp/dt = R(yaw) v(t), dyaw/dt = yaw_rate(t) after t0 -- scipy, piece by
    piece between the keyframes, with the command read from its keyframes by np.interp."""
    keys = np.asarray(cmd.times)
    table = np.asarray(cmd.commands)

    def command(t):
        return [np.interp(t, keys, table[:, k]) for k in range(3)]

    def f(t, s):
        u0, u1, w = command(t)
        c, sn = math.cos(s[2]), math.sin(s[2])
        return [c * u0 - sn * u1, sn * u0 + c * u1, w]

    cuts = sorted({t0, t_end} | {float(b) for b in keys if t0 < b < t_end})
    s = np.array([com0[0], com0[1], yaw0], dtype=float)
    for a, b in zip(cuts[:-1], cuts[1:]):
        s = solve_ivp(f, (a, b), s, rtol=1e-11, atol=1e-12).y[:, -1]
    return s


def test_schedule_keyframes_ramps_and_heading_change():
    cmd = schedule_example()
    assert [p[0] for p in cmd.phases] == ["forward", "turn", "side", "stop"]
    np.testing.assert_allclose(cmd.command(0.5), [0, 0, 0])
    np.testing.assert_allclose(cmd.command(1.4), [0.2, 0, 0])           # half-way up the ramp
    np.testing.assert_allclose(cmd.command(2.5), [0.4, 0, 0])
    np.testing.assert_allclose(cmd.command(3.4), [0.3, 0.025, 0.25])    # ramping into the turn
    np.testing.assert_allclose(cmd.rate(3.4), [-0.25, 0.0625, 0.625])
    np.testing.assert_allclose(cmd.command(20.0), [0, 0, 0])
    # linear ramps in and out of the turn: the heading changes by the rate times its duration
    assert cmd.heading_change(0.0, 20.0) == pytest.approx(0.5 * 3.0)
    with pytest.raises(ValueError, match="duration"):
        CommandPhase("turn", 0.0, yaw_rate=0.5)


@pytest.mark.parametrize("t0", [0.0, 1.0, 3.3])
def test_trunk_reference_integrates_a_schedule_with_a_ramped_yaw_rate(t0):
    cmd = schedule_example()
    com0, yaw0 = np.array([0.2, -0.1, 0.55]), 0.4
    tr = TrunkReference(cmd, com0, yaw0, t0=t0)
    for t_end in (0.7, 3.5, 4.1, 6.3, 7.9, 9.4, 12.0):
        if t_end <= t0:
            continue
        x, y, yaw = integrate(cmd, com0, yaw0, t0, t_end)
        s = tr.evaluate(t_end)
        np.testing.assert_allclose(s.position, [x, y, 0.55], atol=1e-8)
        assert s.yaw == pytest.approx(yaw, abs=1e-9)
    # angular and linear rates: finite differences of the heading and of the path, also inside
    # the ramps of the yaw rate (where the angular acceleration is not zero)
    d = 1e-5
    for t in (3.4, 5.0, 6.4, 8.6):
        if t - d <= t0:
            continue
        s = tr.evaluate(t)
        assert s.angular_velocity[2] == pytest.approx(
            (tr.heading(t + d) - tr.heading(t - d)) / (2 * d), abs=1e-7)
        assert s.angular_acceleration[2] == pytest.approx(
            (tr.evaluate(t + d).angular_velocity[2] - tr.evaluate(t - d).angular_velocity[2])
            / (2 * d), abs=1e-6)
        dp = (tr.evaluate(t + d).position - tr.evaluate(t - d).position) / (2 * d)
        np.testing.assert_allclose(s.velocity, dp, atol=1e-7)
        dv = (tr.evaluate(t + d).velocity - tr.evaluate(t - d).velocity) / (2 * d)
        np.testing.assert_allclose(s.acceleration, dv, atol=1e-6)


def test_turning_footholds_follow_the_raibert_law_with_the_yaw_rate(hyq):
    """The touchdown target of every leg during a turn: hip = CoM + R(psi) r, its velocity the
    CoM's plus omega x R(psi) r, target = hip + velocity T_stance / 2, with the CoM and heading at
    touchdown from the ODE integration, not from the planner's closed form."""
    cmd = CommandSchedule.from_phases([CommandPhase("turn", 5.0, 0.2, 0.05, 0.5)], start=1.0,
                                      ramp=0.8)
    planner = GaitPlanner.for_robot(hyq, trot(0.8, start=1.0), cmd, start_shift=False)
    tr = planner.trunk
    com0 = tr.com0
    offsets = planner.footprint.feet_from_com()
    for i, leg in enumerate(planner.legs):
        for t_td in (1.5, 2.3, 3.9):  # in the ramp, just after it, steady turning
            x, y, psi = integrate(cmd, com0, tr.yaw0, tr.t0, t_td)
            u0, u1, w = cmd.command(t_td)
            R = np.array([[math.cos(psi), -math.sin(psi)], [math.sin(psi), math.cos(psi)]])
            r = R @ offsets[i]
            hip = np.array([x, y]) + r
            v_hip = R @ np.array([u0, u1]) + w * np.array([-r[1], r[0]])
            expected = hip + v_hip * 0.5 * planner.schedule.stance_duration(i)
            got = planner.touchdown_target(leg, t_td).point[:2]
            np.testing.assert_allclose(got, expected, atol=1e-8, err_msg=f"{leg} at {t_td}")
            if t_td < 1.8 + 0.8:
                continue
            # steady turning: the hip passes over the foot at mid-stance, to second order in the
            # half stance (ignoring the yaw rate would miss by |r| w T/2, 4.5 cm here)
            half = 0.5 * planner.schedule.stance_duration(i)
            xm, ym, psim = integrate(cmd, com0, tr.yaw0, tr.t0, t_td + half)
            Rm = np.array([[math.cos(psim), -math.sin(psim)], [math.sin(psim), math.cos(psim)]])
            mid_hip = np.array([xm, ym]) + Rm @ offsets[i]
            bound = (np.linalg.norm(offsets[i]) * w * w + math.hypot(u0, u1) * abs(w)) * half ** 2
            assert np.linalg.norm(got - mid_hip) <= bound


def test_period_mean_is_the_window_average():
    t = np.linspace(0.0, 4.0, 4001)
    x = np.stack([np.sin(2 * math.pi * t / 0.8), t], axis=1)  # a gait-periodic wobble and a ramp
    mask, mean = period_mean(t, x, 0.8)
    assert not mask[0] and not mask[-1] and mask[2000]
    np.testing.assert_allclose(mean[mask, 0], 0.0, atol=1e-5)   # a whole period averages out
    np.testing.assert_allclose(mean[mask, 1], t[mask], atol=1e-9)


def test_steer_schedule_turns_by_the_commanded_angle(hyq):
    params = get_scenario("steer").validate(hyq, {"turn": "-60"})
    cmd = command_schedule(hyq, params)
    assert [p[0] for p in cmd.phases] == ["forward", "turn", "side", "stop"]
    assert math.degrees(cmd.heading_change(0.0, cmd.end)) == pytest.approx(-60.0)
    # HyQ's defaults: a trot at 0.4 m/s, a turn at 0.5 rad/s at half of it, a side-step at 0.3 x
    turn = [p for p in cmd.phases if p[0] == "turn"][0]
    np.testing.assert_allclose(cmd.command(turn[2] - 0.01), [0.2, 0.0, -0.5], atol=1e-12)
    side = [p for p in cmd.phases if p[0] == "side"][0]
    np.testing.assert_allclose(cmd.command(side[2] - 0.01), [0.0, 0.12, 0.0], atol=1e-12)


def test_steer_defaults_scale_with_the_robot(hyq):
    go1 = wb.load_robot("go1")
    scale = math.sqrt(go1.q_ref[2] / hyq.q_ref[2])
    params = get_scenario("steer").validate(go1, {})
    cmd = command_schedule(go1, params)
    turn = [p for p in cmd.phases if p[0] == "turn"][0]
    np.testing.assert_allclose(cmd.command(turn[2] - 0.01),
                               [0.2 * scale, 0.0, 0.5 / scale], rtol=1e-9)


@pytest.mark.parametrize("overrides, name", [
    ({"gait": "gallop"}, "gait"), ({"turn": "720"}, "turn"), ({"speed": "-1"}, "speed"),
    ({"forward_cycles": "0.5"}, "forward_cycles"), ({"turn": "5"}, "turn"),
    ({"yaw_rate": "nan"}, "yaw_rate")])
def test_steer_refuses_bad_settings_naming_them(hyq, overrides, name):
    with pytest.raises(ValueError, match=name):
        get_scenario("steer").validate(hyq, overrides)
