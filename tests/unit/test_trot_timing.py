"""The trot's timing law (:func:`wholebody.planning.gait.stride_capped`): the period shortens with
the commanded speed so that a stance foot's travel relative to its hip stays within a cap, and is
the fixed period below the speed where that period reaches the cap. Expected values come from the
law's formula (T = min(T0, L / (duty v))) and from the fixed-period schedule."""

import math

import numpy as np
import pytest

from wholebody.planning.gait import stride_capped, trot
from wholebody.planning.planner import GaitPlanner
from wholebody.planning.trunk import VelocityCommand
from wholebody.scenarios.locomotion import MAX_STRIDE, TROT_SPEED, make_schedule, paper_length

T0, DUTY, L = 0.8, 0.5, 0.2  # period (s), duty factor, stride cap (m)
V_CAP = L / (DUTY * T0)  # the speed where the fixed period's stance travel reaches L


def constant(v):
    return lambda t: v


def test_below_the_cap_every_event_is_the_fixed_period_s():
    fixed = trot(T0, DUTY, start=1.0)
    timed = stride_capped(fixed, constant(0.9 * V_CAP), L)
    for leg in fixed.legs:
        for k in range(30):
            assert timed.liftoff_time(leg, k) == fixed.liftoff_time(leg, k)
            assert timed.touchdown_time(leg, k) == fixed.touchdown_time(leg, k)
        for t in np.linspace(0.0, 20.0, 701):
            assert timed.stance_duration(leg, t) == fixed.stance_duration(leg)
            assert timed.in_swing(leg, t) == fixed.in_swing(leg, t)
    assert timed.period_of(15.0) == T0


@pytest.mark.parametrize("v", [1.5 * V_CAP, 3.0 * V_CAP, 6.0 * V_CAP])
def test_above_the_cap_the_stance_travel_is_the_cap(v):
    timed = stride_capped(trot(T0, DUTY, start=1.0), constant(v), L)
    period = L / (DUTY * v)
    for leg in timed.legs:
        for k in range(1, 10):
            lo, td = timed.liftoff_time(leg, k), timed.touchdown_time(leg, k)
            assert td - lo == pytest.approx((1.0 - DUTY) * period, rel=1e-12)
            assert timed.liftoff_time(leg, k + 1) - lo == pytest.approx(period, rel=1e-12)
            assert v * timed.stance_duration(leg, td) == pytest.approx(L, rel=1e-12)
    assert timed.max_swing_legs() == 2


def test_the_shortest_period_is_kept():
    timed = stride_capped(trot(T0, DUTY), constant(100.0), L, min_period=0.1)
    assert timed.period_of(5.0) == 0.1


def test_phase_is_continuous_where_the_period_changes_during_a_ramp():
    command = VelocityCommand.speed_ramp(0.0, 4.0 * V_CAP, 1.0, 9.0)
    speed = lambda t: command.velocity(t)[0]  # noqa: E731
    timed = stride_capped(trot(T0, DUTY, start=1.0), speed, L)
    boundaries = [timed.cycle_time(k) for k in range(40)]
    periods = np.diff(boundaries)
    assert periods[0] == T0 and periods[-1] == pytest.approx(L / (DUTY * 4.0 * V_CAP))
    assert np.all(np.diff(periods) <= 1e-12)  # the speed only rises: the period only shortens
    for k, (b, T) in enumerate(zip(boundaries, periods)):
        # each cycle's period is the law at the larger speed of its two ends
        v = max(speed(b), speed(b + min(T0, L / (DUTY * speed(b))) if speed(b) > 0 else b + T0))
        assert T == pytest.approx(min(T0, L / (DUTY * v)) if v > 0 else T0, rel=1e-12)
        for eps in (1e-7, 1e-9):  # the cycle count is continuous across each boundary
            assert timed.cycles(b + eps) - timed.cycles(b - eps) == pytest.approx(
                eps / T + eps / (periods[k - 1] if k else T0), rel=1e-3)
        assert timed.cycles(b) == pytest.approx(k, abs=1e-12)
    for c in np.linspace(-2.0, 35.0, 400):
        assert timed.cycles(timed.cycle_time(c)) == pytest.approx(c, abs=1e-9)
    # the legs' contact state agrees with the events, and the swings tile the timeline
    t = np.arange(0.0, boundaries[-1], 0.001)
    for leg in timed.legs:
        swings = timed.swings(0.0, boundaries[-1], [leg])
        for a, b in zip(swings[:-1], swings[1:]):
            assert b.liftoff > a.touchdown
            mid = 0.5 * (a.touchdown + b.liftoff)
            assert timed.in_stance(leg, mid)
            assert timed.stance_duration(leg, mid) == pytest.approx(b.liftoff - a.touchdown)
        flags = np.array([timed.in_swing(leg, x) for x in t])
        inside = np.zeros_like(flags)
        for s in swings:
            inside |= (t >= s.liftoff) & (t < s.touchdown)
        assert np.array_equal(flags, inside)


@pytest.fixture(scope="module")
def hyq(robots):
    return robots["hyq"]


def test_default_trot_on_hyq_keeps_its_period_at_the_trot_speed(hyq):
    fixed = make_schedule(hyq, "trot", 1.0)
    timed = make_schedule(hyq, "trot", 1.0, command=VelocityCommand.speed_ramp(0.0, TROT_SPEED,
                                                                               1.0, 3.0))
    assert timed.period_at is not None
    assert [timed.liftoff_time(0, k) for k in range(40)] == [fixed.liftoff_time(0, k)
                                                              for k in range(40)]
    # and with the stride cap off, no law at all
    assert make_schedule(hyq, "trot", 1.0, {"max_stride": 0.0},
                         VelocityCommand.constant(2.0)).period_at is None


def test_the_raibert_foothold_uses_the_shortened_stance(hyq):
    v = 1.5
    command = VelocityCommand.constant(v)
    schedule = make_schedule(hyq, "trot", 1.0, command=command)
    cap = paper_length(MAX_STRIDE).value(hyq)
    planner = GaitPlanner.for_robot(hyq, schedule, command)
    t_td = schedule.touchdown_time(0, 5)
    hip, _ = planner.hip(0, t_td)
    target = planner.touchdown_target(0, t_td).position
    # half the stance travel ahead of the hip, the stance travel being the cap
    assert target[0] - hip[0] == pytest.approx(0.5 * cap, rel=1e-9)
    assert math.isclose(schedule.stance_duration(0, t_td) * v, cap, rel_tol=1e-9)
