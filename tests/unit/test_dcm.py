"""The LIPM / DCM walking reference (:mod:`wholebody.planning.dcm`), checked against evidence of its
own: scipy's integration of the pendulum c̈ = ω² (c - p(t)) with the ZMP interpolated here,
finite differences of the closed forms, the analytic pendulum for a constant ZMP, and a re-plan
that must recover the ZMP it started from."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from wholebody.planning.dcm import (DCMPlan, capture_point, lipm_frequency, predicted_dcm)

OMEGA = lipm_frequency(0.85)          # ~3.4 1/s
DOUBLE, SINGLE = 0.1, 0.6


def _walk(steps: int = 6, t0: float = 0.0):
    """Knots of a straight walk: from between the feet onto the right sole, then ``steps`` steps of
    0.2 m (soles at y = ±0.1 m), ending between the last two soles."""
    soles = [np.array([0.2 * k, -0.1 if k % 2 == 0 else 0.1]) for k in range(steps + 1)]
    times, points = [t0], [np.array([0.0, 0.0])]
    t = t0
    for sole in soles[:-1]:
        t += DOUBLE
        times.append(t)
        points.append(sole)
        t += SINGLE
        times.append(t)
        points.append(sole)
    times.append(t + DOUBLE)
    points.append(0.5 * (soles[-2] + soles[-1]))
    return np.array(times), np.array(points)


def _zmp(times, points, t):
    """The ZMP reference interpolated independently of the module (held outside the knots)."""
    return np.array([np.interp(t, times, points[:, 0]), np.interp(t, times, points[:, 1])])


def _between_knots(times, per_segment: int = 7, tail: float = 1.0):
    """Times inside every segment (off the knots) and in the tail after the last knot."""
    grid = [np.linspace(a, b, per_segment + 2)[1:-1] for a, b in zip(times[:-1], times[1:])]
    grid.append(times[-1] + np.linspace(0.05, tail, per_segment))
    return np.concatenate(grid)


def test_lipm_frequency():
    assert lipm_frequency(0.85) ** 2 * 0.85 == pytest.approx(9.81)
    assert lipm_frequency(1.0, gravity=1.62) == pytest.approx(np.sqrt(1.62))


def test_com_matches_a_numerical_integration_of_the_pendulum():
    """c̈ = ω² (c - p(t)) integrated with DOP853 from c0 and ċ0 = ω (ξ(t_0) - c0), knot to knot;
    c and ċ agree with the closed form over a 6-step walk and 0.4 s after it."""
    times, points = _walk()
    com0 = np.array([0.01, 0.02])
    plan = DCMPlan(OMEGA, times, points, com0)
    xi0, _ = plan.dcm(times[0])

    def rhs(t, y):
        return np.concatenate([y[2:], OMEGA ** 2 * (y[:2] - _zmp(times, points, t))])

    y = np.concatenate([com0, OMEGA * (xi0 - com0)])
    bounds = list(times) + [times[-1] + 0.4]
    worst_c = worst_v = 0.0
    for a, b in zip(bounds[:-1], bounds[1:]):
        t_eval = np.linspace(a, b, 6)
        sol = solve_ivp(rhs, (a, b), y, method="DOP853", t_eval=t_eval, rtol=1e-12, atol=1e-13)
        assert sol.success
        c, v, _ = plan.com(t_eval)
        worst_c = max(worst_c, np.abs(sol.y[:2].T - c).max())
        worst_v = max(worst_v, np.abs(sol.y[2:].T - v).max())
        y = sol.y[:, -1]
    # the pendulum is unstable (its DCM mode grows as exp(ω t), ~1e7 over the walk), so the
    # integration's own error grows with it: ~1e-7 at the end
    assert worst_c < 1e-6
    assert worst_v < 1e-6


def test_dcm_obeys_its_dynamics_by_finite_differences():
    """(ξ(t + h) - ξ(t - h)) / 2h = ω (ξ - p) and = ξ̇, with p interpolated independently."""
    times, points = _walk()
    plan = DCMPlan(OMEGA, times, points, [0.0, 0.0])
    ts = _between_knots(times)
    h = 1e-5
    xi, xi_dot = plan.dcm(ts)
    fd = (plan.dcm(ts + h)[0] - plan.dcm(ts - h)[0]) / (2 * h)
    p = np.array([_zmp(times, points, t) for t in ts])
    np.testing.assert_allclose(fd, OMEGA * (xi - p), atol=1e-7)
    np.testing.assert_allclose(fd, xi_dot, atol=1e-7)
    np.testing.assert_allclose(plan.zmp(ts), p, atol=1e-15)


def test_com_derivatives_by_finite_differences():
    """ċ = dc/dt, c̈ = dċ/dt (central differences), c̈ = ω² (c - p) and ċ = ω (ξ - c)."""
    times, points = _walk()
    plan = DCMPlan(OMEGA, times, points, [0.03, -0.01])
    ts = _between_knots(times)
    h = 1e-5
    c, v, a = plan.com(ts)
    np.testing.assert_allclose((plan.com(ts + h)[0] - plan.com(ts - h)[0]) / (2 * h), v, atol=1e-8)
    np.testing.assert_allclose((plan.com(ts + h)[1] - plan.com(ts - h)[1]) / (2 * h), a, atol=1e-7)
    p = np.array([_zmp(times, points, t) for t in ts])
    np.testing.assert_allclose(a, OMEGA ** 2 * (c - p), atol=1e-12)
    np.testing.assert_allclose(v, OMEGA * (plan.dcm(ts)[0] - c), atol=1e-12)
    # the DCM from the CoM state is the DCM of the closed form
    np.testing.assert_allclose(capture_point(c, v, OMEGA), plan.dcm(ts)[0], atol=1e-12)


def test_continuous_at_the_knots():
    times, points = _walk()
    plan = DCMPlan(OMEGA, times, points, [0.0, 0.05])
    eps = 1e-9
    before, after = times - eps, times + eps
    for f in (plan.dcm, plan.com):
        for left, right in zip(f(before), f(after)):
            np.testing.assert_allclose(left, right, atol=1e-7)
    np.testing.assert_allclose(plan.zmp(times), points, atol=1e-15)


def test_at_rest_at_the_end():
    times, points = _walk()
    plan = DCMPlan(OMEGA, times, points, [0.0, 0.0])
    assert plan.end_time == times[-1]
    for t in (times[-1], times[-1] + 0.5, times[-1] + 50.0):
        xi, xi_dot = plan.dcm(t)
        np.testing.assert_allclose(xi, points[-1], atol=1e-15)
        np.testing.assert_allclose(xi_dot, 0.0, atol=1e-15)
    c, v, a = plan.com(times[-1] + 10.0)                  # 34 time constants later
    np.testing.assert_allclose(c, points[-1], atol=1e-12)
    np.testing.assert_allclose(v, 0.0, atol=1e-12)
    np.testing.assert_allclose(a, 0.0, atol=1e-12)
    c_far = plan.com(times[-1] + 1e4)
    assert all(np.all(np.isfinite(x)) for x in c_far)


@pytest.mark.parametrize("knot", [1, 2])
def test_a_later_solved_knot_keeps_the_first_zmp(knot):
    """solve_knot > 0: the first ZMP stays (continuous with the one commanded before), the
    plan still starts at dcm0, and c, ξ follow the pendulum of the new ZMP (integration)."""
    times, points = _walk()
    com0, dcm0 = np.array([0.01, -0.02]), np.array([0.05, 0.03])
    plan = DCMPlan(OMEGA, times, points, com0, dcm0=dcm0, solve_knot=knot)
    np.testing.assert_allclose(plan.dcm(times[0])[0], dcm0, atol=1e-12)
    np.testing.assert_array_equal(plan.zmp_knots[0], points[0])
    moved = [k for k in range(len(points)) if not np.allclose(plan.zmp_knots[k], points[k])]
    assert moved == [knot]
    new = np.array(plan.zmp_knots)
    v0 = OMEGA * (dcm0 - com0)

    def rhs(t, y):
        return np.concatenate([y[2:], OMEGA ** 2 * (y[:2] - _zmp(times, new, t))])

    sol = solve_ivp(rhs, (times[0], times[2]), np.r_[com0, v0], method="DOP853",
                    t_eval=np.linspace(times[0], times[2], 7), rtol=1e-12, atol=1e-14)
    c, v, _ = plan.com(sol.t)
    np.testing.assert_allclose(c, sol.y[:2].T, atol=1e-9)
    np.testing.assert_allclose(v, sol.y[2:].T, atol=1e-8)
    with pytest.raises(ValueError, match="solve_knot"):
        DCMPlan(OMEGA, times, points, com0, dcm0=dcm0, solve_knot=len(points))


def test_starting_at_the_dcm_of_a_robot_at_rest():
    """dcm0 = com0: the reference starts at rest (ċ(t_0) = 0, ξ(t_0) = c0) and is the pendulum
    from that state (numerical integration of c̈ = ω² (c - p) from rest with the new ZMP)."""
    times, points = _walk()
    com0 = np.array([0.0, 0.0])
    plan = DCMPlan(OMEGA, times, points, com0, dcm0=com0)
    c, v, _ = plan.com(times[0])
    xi, _ = plan.dcm(times[0])
    np.testing.assert_allclose(xi, com0, atol=1e-14)
    np.testing.assert_allclose(c, com0, atol=1e-15)
    np.testing.assert_allclose(v, 0.0, atol=1e-14)
    assert not np.allclose(plan.zmp_knots[0], points[0])   # moved to start the DCM at c0
    np.testing.assert_array_equal(plan.zmp_knots[1:], points[1:])
    new = np.array(plan.zmp_knots)

    def rhs(t, y):
        return np.concatenate([y[2:], OMEGA ** 2 * (y[:2] - _zmp(times, new, t))])

    sol = solve_ivp(rhs, (times[0], times[1]), np.zeros(4), method="DOP853",
                    t_eval=np.linspace(times[0], times[1], 5), rtol=1e-12, atol=1e-14)
    c, v, _ = plan.com(sol.t)
    np.testing.assert_allclose(c, sol.y[:2].T, atol=1e-10)
    np.testing.assert_allclose(v, sol.y[2:].T, atol=1e-9)


def test_a_replan_at_the_current_dcm_recovers_the_zmp():
    """Re-planning mid-segment from the plan's own DCM and the remaining knots: the substituted
    first ZMP is the old plan's ZMP at that time, and the references continue unchanged."""
    times, points = _walk()
    old = DCMPlan(OMEGA, times, points, [0.02, 0.0])
    for t_r in (0.05, 1.0, times[5] + 0.3):
        k = int(np.searchsorted(times, t_r, side="right"))
        later = np.concatenate([[t_r], times[k:]])
        guess = np.vstack([[0.5, -0.7], points[k:]])          # first ZMP to be replaced
        c_r, _, _ = old.com(t_r)
        xi_r, _ = old.dcm(t_r)
        new = DCMPlan(OMEGA, later, guess, c_r, dcm0=xi_r)
        np.testing.assert_allclose(new.zmp_knots[0], _zmp(times, points, t_r), atol=1e-12)
        ts = t_r + np.linspace(0.0, 2.0, 9)
        for a, b in zip(old.com(ts) + old.dcm(ts), new.com(ts) + new.dcm(ts)):
            np.testing.assert_allclose(a, b, atol=1e-9)


@pytest.mark.parametrize("dcm0", [None, [0.1, 0.2]])
def test_constant_zmp_is_the_analytic_pendulum(dcm0):
    p = np.array([0.1, -0.05]) if dcm0 is None else np.array(dcm0)
    com0 = np.array([0.13, 0.02])
    t0 = 1.5
    plan = DCMPlan(OMEGA, [t0], [[0.1, -0.05]], com0, dcm0=dcm0)
    np.testing.assert_array_equal(plan.zmp_knots[0], p)
    for t in (t0, t0 + 0.2, t0 + 1.7):
        decay = np.exp(-OMEGA * (t - t0))
        c, v, a = plan.com(t)
        np.testing.assert_allclose(c, p + (com0 - p) * decay, atol=1e-15)
        np.testing.assert_allclose(v, -OMEGA * (com0 - p) * decay, atol=1e-14)
        np.testing.assert_allclose(a, OMEGA ** 2 * (com0 - p) * decay, atol=1e-13)
        np.testing.assert_allclose(plan.dcm(t)[0], p, atol=1e-15)
        np.testing.assert_allclose(plan.zmp(t), p, atol=1e-15)


def test_before_the_first_knot_and_vectorised_calls():
    times, points = _walk(steps=2, t0=0.7)
    plan = DCMPlan(OMEGA, times, points, [0.01, 0.01])
    for f in (plan.com, plan.dcm):
        for early, first in zip(f(-3.0), f(times[0])):
            np.testing.assert_array_equal(early, first)
    np.testing.assert_array_equal(plan.zmp(0.0), points[0])
    ts = np.array([0.0, 0.75, 1.2, times[-1], times[-1] + 0.3])
    c, v, a = plan.com(ts)
    assert c.shape == v.shape == a.shape == (5, 2)
    for j, t in enumerate(ts):
        for batch, single in zip((c, v, a), plan.com(float(t))):
            np.testing.assert_allclose(batch[j], single, atol=1e-15)
        assert plan.dcm(float(t))[0].shape == (2,)


def test_predicted_dcm_against_integration():
    xi0, p = np.array([0.05, -0.02]), np.array([0.01, 0.03])
    for horizon in (0.0, 0.3, 1.1):
        sol = solve_ivp(lambda t, x: OMEGA * (x - p), (0.0, max(horizon, 1e-12)), xi0,
                        method="DOP853", rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(predicted_dcm(xi0, p, OMEGA, horizon), sol.y[:, -1],
                                   atol=1e-10)
    # 3-D inputs: the horizontal part
    np.testing.assert_allclose(predicted_dcm([*xi0, 0.9], [*p, 0.0], OMEGA, 0.3),
                               predicted_dcm(xi0, p, OMEGA, 0.3), atol=0)


def test_capture_point_of_a_3d_state():
    c, v = np.array([0.1, 0.2, 0.85]), np.array([0.34, -0.68, 5.0])
    np.testing.assert_allclose(capture_point(c, v, 3.4), [0.2, 0.0], atol=1e-15)


_TIMES, _POINTS = [0.0, 0.1, 0.7], [[0, 0], [0, -0.1], [0, -0.1]]


@pytest.mark.parametrize("kwargs, name", [
    (dict(omega=0.0), "omega"),
    (dict(omega=-3.0), "omega"),
    (dict(omega=np.nan), "omega"),
    (dict(knot_times=[0.0, 0.1, 0.1]), "knot_times"),
    (dict(knot_times=[0.0, 0.2, 0.1]), "knot_times"),
    (dict(knot_times=[0.0, np.inf, 0.7]), "knot_times"),
    (dict(knot_times=[]), "knot_times"),
    (dict(knot_times=[[0.0, 0.1, 0.7]]), "knot_times"),
    (dict(zmp_knots=[[0, 0], [0, -0.1]]), "zmp_knots"),
    (dict(zmp_knots=[[0, 0, 0], [0, -0.1, 0], [0, -0.1, 0]]), "zmp_knots"),
    (dict(zmp_knots=[[0, 0], [0, np.nan], [0, -0.1]]), "zmp_knots"),
    (dict(com0=[0.0, 0.0, 0.8]), "com0"),
    (dict(com0=[0.0, np.inf]), "com0"),
    (dict(dcm0=[0.0]), "dcm0"),
    (dict(dcm0=[np.nan, 0.0]), "dcm0"),
])
def test_invalid_inputs_name_the_argument(kwargs, name):
    args = dict(omega=OMEGA, knot_times=_TIMES, zmp_knots=_POINTS, com0=[0.0, 0.0])
    args.update(kwargs)
    with pytest.raises(ValueError, match=f"^{name}:"):
        DCMPlan(**args)


def test_invalid_function_arguments():
    with pytest.raises(ValueError, match="^com_height:"):
        lipm_frequency(0.0)
    with pytest.raises(ValueError, match="^omega:"):
        capture_point([0, 0], [0, 0], -1.0)
    with pytest.raises(ValueError, match="^horizon:"):
        predicted_dcm([0, 0], [0, 0], OMEGA, -0.1)


def test_one_time_and_many_times_give_the_same_values():
    """The scalar path (the control loop's) and the array path agree, before the first knot, on
    the knots, inside segments and on the tail."""
    times, points = _walk()
    plan = DCMPlan(OMEGA, times, points, np.array([0.01, 0.02]), dcm0=np.array([0.03, -0.01]))
    ts = np.concatenate([[times[0] - 0.3], times, times[:-1] + 0.37 * np.diff(times),
                         [times[-1] + 0.8]])
    many_com, many_dcm = plan.com(ts), plan.dcm(ts)
    for k, t in enumerate(ts):
        for one, many in zip((*plan.com(float(t)), *plan.dcm(float(t))),
                             (*many_com, *many_dcm)):
            np.testing.assert_allclose(one, many[k], rtol=0, atol=1e-12)
