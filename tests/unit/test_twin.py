"""The MuJoCo twin reproduces the Pinocchio model exactly, and the simulator's conventions and
disturbances obey the equations of motion."""

import mujoco
import numpy as np
import pytest

from wholebody.sim import convert
from wholebody.sim.disturbance import Push
from wholebody.sim.environment import Box, Environment, Platform
from wholebody.sim.mismatch import Mismatch
from wholebody.sim.simulator import Simulator
from wholebody.sim.twin import build_twin

PRESETS = ("talos14", "talos", "hyq", "anymal_c", "romeo")


def _rel(a, b):
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-12)


@pytest.mark.parametrize("name", PRESETS)
def test_twin_matches_pinocchio(robots, name, rng):
    """Mass, CoM, M(q) and nonlinear effects agree to 1e-9 (relative) at random states."""
    robot = robots[name]
    twin = build_twin(robot)
    m = twin.model
    d = mujoco.MjData(m)
    assert m.body_mass.sum() == pytest.approx(robot.mass, rel=1e-12)
    for _ in range(5):
        q, v = robot.random_state(rng)
        d.qpos[:], d.qvel[:] = convert.pin_to_mj(q, v)
        mujoco.mj_forward(m, d)
        M_mj = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M_mj)
        robot.update(q, v)
        assert _rel(d.subtree_com[1], robot.com) < 1e-9
        assert _rel(convert.mass_matrix_to_pin(q, M_mj), robot.M) < 1e-9
        assert _rel(convert.bias_to_pin(q, v, M_mj, d.qfrc_bias), robot.h) < 1e-9


@pytest.mark.parametrize("name", PRESETS)
def test_contact_sites_at_contact_frames(robots, name, rng):
    robot = robots[name]
    sim = Simulator(robot, record=False)
    q, v = robot.random_state(rng)
    sim.reset(q, v)
    robot.update(q, v)
    for n, (p, R) in sim.contact_frame_poses().items():
        p_pin, R_pin = robot.frame_placement(robot.contact(n).frame)
        np.testing.assert_allclose(p, p_pin, atol=1e-12)
        np.testing.assert_allclose(R, R_pin, atol=1e-12)


def test_state_conversion_round_trip(robots, rng):
    robot = robots["hyq"]
    for _ in range(5):
        q, v = robot.random_state(rng)
        q2, v2 = convert.mj_to_pin(*convert.pin_to_mj(q, v))
        np.testing.assert_allclose(q2, q, atol=1e-14)
        np.testing.assert_allclose(v2, v, atol=1e-13)


def test_state_conversion_is_pinocchios_rotation(rng):
    """MuJoCo's (w, x, y, z) quaternion, not normalised, and world linear velocity -> the unit
    (x, y, z, w) quaternion and the base-frame velocity Rᵀ v, R from Pinocchio's quaternion
    (an independent rotation); the joints' entries copied."""
    import pinocchio as pin
    for scale in (1e-3, 1.0, 1e3):
        for _ in range(50):
            qpos, qvel = rng.normal(size=19), scale * rng.normal(size=18)
            q, v = convert.mj_to_pin(qpos, qvel)
            quat = pin.Quaternion(*qpos[3:7])  # (w, x, y, z)
            quat.normalize()
            np.testing.assert_allclose(q[3:7], quat.coeffs(), rtol=0, atol=1e-15)
            np.testing.assert_allclose(v[:3], quat.toRotationMatrix().T @ qvel[:3], rtol=0,
                                       atol=1e-14 * scale)
            np.testing.assert_array_equal(q[[0, 1, 2, *range(7, 19)]],
                                          qpos[[0, 1, 2, *range(7, 19)]])
            np.testing.assert_array_equal(v[3:], qvel[3:])


def test_free_fall_and_push_obey_newton(robots):
    """Without floor or torques, the change of linear momentum equals m g T + the push impulse."""
    robot = robots["hyq"]
    sim = Simulator(robot, Environment(floor=False))
    q0 = robot.q_ref.copy()
    q0[2] += 1.0
    sim.reset(q0)
    push = Push("trunk", direction=(1.0, 2.0, 0.0), peak_force=300.0, start=0.05, duration=0.1,
                offset=(0.2, 0.0, 0.1))
    sim.add_push(push)
    robot.update(*sim.state())
    h0 = robot.h_G[:3].copy()
    steps = 200
    for _ in range(steps):
        sim.step(np.zeros(robot.na))
    robot.update(*sim.state())
    T = steps * sim.dt
    expected = robot.mass * np.array([0, 0, -9.81]) * T + push.impulse * push.unit_direction
    logged = np.sum(sim.log.arrays()["push_force"], axis=0) * sim.dt
    np.testing.assert_allclose(logged, push.impulse * push.unit_direction, rtol=2e-3)
    np.testing.assert_allclose(robot.h_G[:3] - h0, expected, rtol=2e-3, atol=0.05)
    # pushed off-centre: the robot now spins
    assert np.linalg.norm(robot.h_G[3:]) > 1.0


def test_torque_delay_noise_and_saturation(robots):
    robot = robots["hyq"]
    sim = Simulator(robot, mismatch=Mismatch(torque_delay=2))
    commands = [np.full(robot.na, float(k)) for k in range(1, 6)]
    for tau in commands:
        sim.step(tau)
    applied = sim.log.arrays()["tau_applied"]
    np.testing.assert_allclose(applied[2:], np.array(commands[:3]))
    np.testing.assert_allclose(applied[:2], 0.0)
    sim = Simulator(robot)
    sim.step(np.full(robot.na, 1e4))
    lo, hi = robot.torque_bounds(sim.log.q[0])
    np.testing.assert_allclose(sim.log.tau_applied[0], hi)
    assert np.all(sim.last_clipped > 0)
    sim = Simulator(robot, mismatch=Mismatch(torque_noise=1.0, seed=3))
    for _ in range(200):
        sim.step(np.zeros(robot.na))
    noise = sim.log.arrays()["tau_applied"]
    assert 0.8 < noise.std() < 1.2


def test_mass_mismatch_is_simulator_side(robots):
    robot = robots["talos14"]
    sim = Simulator(robot, mismatch=Mismatch(mass_scale=1.1, mass_noise=0.05, com_offset=0.01))
    total = sim.model.body_mass.sum()
    assert total == pytest.approx(1.1 * robot.mass, rel=0.05) and total != pytest.approx(robot.mass)
    assert robot.mass == pytest.approx(90.272192, rel=1e-9)  # the controller's model is untouched


def test_platform_follows_prescribed_motion(robots):
    robot = robots["hyq"]

    def motion(t):
        return np.array([0.1 * np.sin(2 * t), 0.0, 0.0]), np.array([0.0, 0.05 * t, 0.0])

    env = Environment(platform=Platform(half_size=(1.0, 1.0, 0.02), center=(0, 0, 0.1),
                                        motion=motion))
    sim = Simulator(robot, env)
    q, _ = sim.state()
    assert q[2] == pytest.approx(robot.q_ref[2] + 0.1)  # starts resting on the platform
    for _ in range(300):
        sim.step(np.zeros(robot.na))
    t = sim.t
    qpos = sim.data.qpos[sim.twin.platform_qpos]
    np.testing.assert_allclose(qpos[0], 0.1 * np.sin(2 * t), atol=3e-3)
    np.testing.assert_allclose(qpos[4], 0.05 * t, atol=1e-4)


def test_ramp_surface_geometry():
    """Box.ramp's top face passes through (start_x, 0, 0) and rises at the given angle."""
    angle = np.radians(15)
    ramp = Box.ramp(start_x=1.0, length=2.0, angle=angle, thickness=0.1)
    from wholebody.sim.twin import _rpy_to_wxyz
    quat = _rpy_to_wxyz(ramp.rpy)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, quat)
    R = R.reshape(3, 3)
    top_start = np.asarray(ramp.center) + R @ np.array([-ramp.half_size[0], 0, ramp.half_size[2]])
    top_end = np.asarray(ramp.center) + R @ np.array([ramp.half_size[0], 0, ramp.half_size[2]])
    np.testing.assert_allclose(top_start, [1.0, 0.0, 0.0], atol=1e-12)
    assert np.degrees(np.arctan2(top_end[2] - top_start[2], top_end[0] - top_start[0])) == \
        pytest.approx(15.0)


def test_state_setters_reject_bad_input(robots):
    sim = Simulator(robots["hyq"], record=False)
    with pytest.raises(ValueError, match="^tau:"):
        sim.step(np.zeros(3))
    with pytest.raises(ValueError, match="^q:"):
        sim.reset(np.full(19, np.nan))
    with pytest.raises(ValueError, match="push.frame"):
        sim.add_push(Push("nowhere", (1, 0, 0), 10.0, 0.0, 0.1))


@pytest.mark.parametrize("quaternion", [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 2.0)])
def test_reset_rejects_a_base_orientation_that_is_no_rotation(robots, quaternion):
    sim = Simulator(robots["hyq"])
    q = robots["hyq"].q_ref.copy()
    q[3:7] = quaternion
    with pytest.raises(ValueError, match=r"q\[3:7\].*unit quaternion"):
        sim.reset(q)


def test_a_diverging_step_says_when(robots, tmp_path, monkeypatch):
    """A state MuJoCo cannot integrate (velocities of 1e30): it resets its data; the step raises
    SimulationDiverged with the time the step started at instead of going on from t = 0."""
    from wholebody.sim.simulator import SimulationDiverged

    monkeypatch.chdir(tmp_path)  # MuJoCo writes MUJOCO_LOG.TXT into the working directory
    robot = robots["hyq"]
    sim = Simulator(robot)
    for _ in range(5):
        sim.step(np.zeros(robot.na))
    t = sim.t
    sim.data.qvel[:] = 1e30
    with pytest.raises(SimulationDiverged, match=r"diverged at t = 0.005 s") as info:
        sim.step(np.zeros(robot.na))
    assert info.value.t == pytest.approx(t)
