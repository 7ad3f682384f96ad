"""benchmarks/push_bound.py: the LP bound on recoverable pushes against closed forms of the linear
inverted pendulum (LIP) it contains."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import push_bound  # noqa: E402

import wholebody as wb  # noqa: E402


def lip_geometry(edge=0.1, z0=0.9, height=0.0, inertia=10.0):
    return {"support": (-edge, edge), "z0": z0, "push_height": height, "inertia": inertia,
            "mass": 80.0, "gravity": 9.81}


def test_a_push_at_the_com_without_rotation_is_the_capture_point_bound():
    """A push at the CoM with no rotation allowed is the LIP: with the CoP on the edge e from the
    start, the capture point xi' = omega (xi - e) + F / (m omega) ends inside the support iff
    int_0^T exp(-omega s) F(s) ds <= e m omega, i.e. dv <= e omega / <exp(-omega s)>_F (the mean
    over the half-sine's impulse, integrated here with the trapezoid rule)."""
    geom = lip_geometry()
    omega = np.sqrt(9.81 / 0.9)
    s = np.linspace(0.0, 0.1, 20001)
    F = np.sin(np.pi * s / 0.1)
    lip = 0.1 * omega / (np.trapezoid(np.exp(-omega * s) * F, s) / np.trapezoid(F, s))
    bound = push_bound.threshold(geom, np.radians(0.01), steps=12, high=1.0)
    assert bound == pytest.approx(lip, rel=3e-3)
    assert not push_bound.recoverable(geom, 1.01 * lip, np.radians(0.01))


def test_rotation_and_support_widen_the_bound():
    """More allowed rotation (hip strategy) or a wider support recover more; a push above the
    CoM with no rotation allowed recovers less than one at the CoM."""
    geom = lip_geometry(height=0.3)
    t = [push_bound.threshold(geom, np.radians(p), steps=8) for p in (1.0, 10.0, 30.0)]
    assert t[0] < t[1] < t[2]
    wide = push_bound.threshold(lip_geometry(edge=0.15, height=0.3), np.radians(1.0), steps=8)
    assert wide > t[0]
    at_com = push_bound.threshold(lip_geometry(height=0.0), np.radians(1.0), steps=8)
    assert at_com > t[0]


def test_geometry_of_a_preset():
    """talos14's soles reach 0.099 m ahead of and 0.111 m behind its CoM (corners from the
    contacts' frames here), the torso point is above the CoM and the hip point below it."""
    robot = wb.load_robot("talos14")
    front = push_bound.push_geometry(robot, "front")
    robot.update(robot.q_ref, np.zeros(robot.nv))
    xs = []
    for name in robot.contact_names:
        pos, _ = robot.frame_placement(robot.contact(name).frame)
        hx = robot.contact(name).spec.half_size[0]
        xs += [pos[0] - hx, pos[0] + hx]
    # the front push points backwards: "ahead" is the heel side
    assert front["support"][1] == pytest.approx(robot.com[0] - min(xs), abs=1e-9)
    assert -front["support"][0] == pytest.approx(max(xs) - robot.com[0], abs=1e-9)
    assert front["push_height"] > push_bound.push_geometry(robot, "hip-front")["push_height"]
    assert front["z0"] == pytest.approx(robot.com[2] - robot.contact_point(robot.contact_names[0])[2],
                                        abs=1e-3)


def test_capture_mpc_prediction_is_the_stepped_model():
    """benchmarks/capture_mpc.py's condensed prediction Phi x0 + Gamma w equals stepping the
    discrete model x+ = Ad x + Bd (f, p, 0) one input at a time."""
    import capture_mpc

    geom = lip_geometry(height=0.3)
    mpc = capture_mpc.AxisMPC(geom, dt=0.02, steps=12)
    Ad, Bd = push_bound.discrete_model(geom, 0.02)
    rng = np.random.default_rng(3)
    x0, w = rng.normal(size=4), rng.normal(size=24)
    x, states = x0.copy(), []
    for k in range(12):
        x = Ad @ x + Bd @ np.r_[w[2 * k:2 * k + 2], 0.0]
        states.append(x)
    np.testing.assert_allclose(mpc.Phi @ x0 + mpc.Gamma @ w, np.concatenate(states), atol=1e-9)
    f, p = mpc.first_step(np.array([0.02, 0.2, 0.0, 0.0]))  # moving along +u: the CoP leads it
    assert p > 0.02 and f < 0.0


def test_push_trial_runs_the_controller_it_is_given(robots):
    from wholebody.control.balance import MomentumBalance
    from wholebody.scenarios.push import PARAMETERS
    from wholebody.scenarios.pushes import push_trial

    robot = robots["talos14"]
    calls = []

    class Counting(MomentumBalance):
        def compute(self, q, v, t=0.0):
            calls.append(t)
            return super().compute(q, v, t)

    params = {p.name: p.default for p in PARAMETERS}
    params.update(duration=0.02, start=0.0, peak_force=10.0)
    push_trial(robot, "lqr", params, balance=Counting(robot, gains="pd"))
    assert len(calls) >= 20
