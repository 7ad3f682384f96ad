"""What the simulator reads from MuJoCo's data. The contact wrenches are MuJoCo's contact forces
(``mj_contactForce``, contact by contact) summed per robot contact, whatever the friction cone and
contact dimension, and are computed anew after every step and reset. The state is the conversion
of MuJoCo's qpos and qvel (:mod:`wholebody.sim.convert`) of the moment, also when they were
written directly, and each call returns arrays of its own."""

import mujoco
import numpy as np
import pytest

from wholebody.sim import convert
from wholebody.sim.disturbance import Push
from wholebody.sim.simulator import Simulator


def reference_wrenches(sim) -> np.ndarray:
    """Contact by contact with ``mj_contactForce``: the force geom1 exerts on geom2 in the
    contact frame, rotated to the world, signed as the force on the robot's geom, and its moment
    about the robot contact's frame origin."""
    m, d, robot = sim.model, sim.data, sim.robot
    geom_owner = {g: i for i, name in enumerate(robot.contact_names)
                  for g in sim.twin.contact_geoms[name]}
    out = np.zeros((len(robot.contact_names), 6))
    local = np.zeros(6)
    for k in range(d.ncon):
        con = d.contact[k]
        g1, g2 = int(con.geom[0]), int(con.geom[1])
        if g1 in geom_owner:
            i, sign = geom_owner[g1], -1.0
        elif g2 in geom_owner:
            i, sign = geom_owner[g2], 1.0
        else:
            continue
        mujoco.mj_contactForce(m, d, k, local)
        force = sign * con.frame.reshape(3, 3).T @ local[:3]
        origin = d.site_xpos[sim.twin.contact_sites[robot.contact_names[i]]]
        out[i, :3] += force
        out[i, 3:] += np.cross(con.pos - origin, force)
    return out


def shaken(sim, rng, steps: int):
    """``steps`` steps under noisy torques and a push: contacts load, unload and slide."""
    robot = sim.robot
    sim.add_push(Push(frame=robot.base_frame, start=0.02, duration=0.05,
                      peak_force=0.5 * robot.mass * 9.81, direction=(1.0, 0.5, 0.0)))
    for _ in range(steps):
        sim.step(rng.normal(scale=3.0, size=robot.na))
        yield


@pytest.mark.parametrize("name", ["talos14", "hyq"])
@pytest.mark.parametrize("cone, condim", [("elliptic", 3), ("elliptic", 1), ("elliptic", 4),
                                          ("elliptic", 6), ("pyramidal", 3), ("pyramidal", 4)])
def test_contact_wrenches_sum_mujoco_contact_forces(robots, rng, name, cone, condim):
    sim = Simulator(robots[name], record=False)
    sim.model.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{cone.upper()}")
    sim.model.geom_condim[:] = condim
    sim.reset()
    seen, dims = 0, set()
    for _ in shaken(sim, rng, 120):
        expected = reference_wrenches(sim)
        np.testing.assert_allclose(sim.contact_wrenches_array(), expected, rtol=1e-12,
                                   atol=1e-9 * robots[name].mass)
        seen += sim.data.ncon
        dims.update(sim.data.contact.dim.tolist())
    assert seen > 120  # the feet were in contact
    assert dims == {condim}


@pytest.mark.parametrize("name", ["talos14", "hyq"])
@pytest.mark.parametrize("condim", [1, 3, 4, 6])
def test_compiled_contact_wrenches_are_the_python_sums_bit_for_bit(robots, rng, name, condim):
    """The compiled sums (``wholebody._sim_reads``, reading MuJoCo's structs in place; built with
    the headers of the MuJoCo that runs, so the simulator uses them) are those of the Python
    reference, every entry to the bit, on states where contacts load, unload and slide; an
    owner table not of the model's geoms is refused naming the field."""
    from conftest import native_cycle_or_skip
    native_cycle_or_skip("_sim_reads")
    from wholebody import _sim_reads
    from wholebody.sim import simulator
    assert simulator._DIRECT_READS, "built without MuJoCo's headers, or for another MuJoCo"
    sim = Simulator(robots[name], record=False)
    sim.model.geom_condim[:] = condim
    sim.reset()
    seen = 0
    for _ in shaken(sim, rng, 120):
        expected = sim._contact_wrenches_reference()
        got = _sim_reads.contact_wrenches_at(sim.model._address, sim.data._address,
                                             sim._geom_contact, sim._contact_site)
        assert got.tobytes() == expected.tobytes()
        seen += sim.data.ncon
    assert seen > 120
    with pytest.raises(ValueError, match="owner"):
        _sim_reads.contact_wrenches_at(sim.model._address, sim.data._address,
                                       sim._geom_contact[:-1], sim._contact_site)


def test_contact_wrenches_follow_each_step_and_reset(robots, rng):
    """Two reads in a step give the same numbers, each an array of its own; a step or a reset
    gives the wrenches of the new state."""
    robot = robots["hyq"]
    sim = Simulator(robot, record=False)
    first = sim.contact_wrenches_array()
    first[:] = np.nan  # the caller's copy
    np.testing.assert_array_equal(sim.contact_wrenches_array(), reference_wrenches(sim))
    before = sim.contact_wrenches_array()
    for _ in shaken(sim, rng, 30):
        now = sim.contact_wrenches_array()
        np.testing.assert_array_equal(now, reference_wrenches(sim))
    assert not np.array_equal(now, before)
    q = robot.q_ref.copy()
    q[2] += 0.5  # in the air: no contact
    sim.reset(q)
    np.testing.assert_array_equal(sim.contact_wrenches_array(), np.zeros((4, 6)))
    assert set(sim.contact_wrenches()) == set(robot.contact_names)


def test_state_is_mujocos_of_the_moment(robots, rng):
    robot = robots["talos14"]
    sim = Simulator(robot, record=False)

    def converted():
        return convert.mj_to_pin(sim.data.qpos[:robot.nq].copy(), sim.data.qvel[:robot.nv].copy())

    for _ in shaken(sim, rng, 10):
        q, v = sim.state()
        for got, expected in zip((q, v), converted()):
            np.testing.assert_array_equal(got, expected)
        q[:] = np.nan  # the caller's arrays
        v[:] = np.nan
        assert np.isfinite(np.concatenate(sim.state())).all()
    sim.data.qvel[0] += 0.5  # written directly, without a step
    sim.data.qpos[7] += 0.1
    q, v = sim.state()
    np.testing.assert_array_equal(q, converted()[0])
    np.testing.assert_array_equal(v, converted()[1])


def test_compiled_state_conversion_is_the_python_reference_bit_for_bit(robots, rng):
    """The compiled (qpos, qvel) -> (q, v) (what the simulator converts with where it was built)
    is :func:`wholebody.sim.convert.mj_to_pin` to the bit: random states over six decades,
    quaternions far from unit norm, strided views of MuJoCo's arrays; its arrays are new; a
    vector too short for a free base is refused naming the field."""
    from conftest import native_cycle_or_skip
    native_cycle_or_skip("_sim_reads")
    from wholebody import _sim_reads
    for _ in range(2000):
        scale = 10.0 ** rng.integers(-3, 4)
        qpos, qvel = scale * rng.normal(size=19), scale * rng.normal(size=18)
        for q, v in ((qpos, qvel), (np.repeat(qpos, 2)[::2], np.repeat(qvel, 3)[1::3])):
            expected, got = convert.mj_to_pin(q, v), _sim_reads.mj_to_pin(q, v)
            assert got[0].tobytes() == expected[0].tobytes()
            assert got[1].tobytes() == expected[1].tobytes()
            assert not np.shares_memory(got[0], q) and not np.shares_memory(got[1], v)
    sim = Simulator(robots["hyq"], record=False)
    for _ in shaken(sim, rng, 50):
        qpos, qvel = sim.data.qpos, sim.data.qvel
        for a, b in zip(_sim_reads.mj_to_pin(qpos, qvel), convert.mj_to_pin(qpos, qvel)):
            assert a.tobytes() == b.tobytes()
    with pytest.raises(ValueError, match="qvel"):
        _sim_reads.mj_to_pin(np.zeros(7), np.zeros(5))


def test_a_held_torque_is_read_anew_when_its_numbers_change(robots):
    """The simulator checks a torque once while the same array holds the same numbers (a
    controller's torque held over steps): numbers written into that array in place are applied
    at the next step, and a NaN written there is refused naming the field."""
    robot = robots["hyq"]
    sim = Simulator(robot)
    _, hi = robot.torque_bounds(robot.q_ref)
    tau = 0.1 * hi
    sim.step(tau)
    sim.step(tau)
    tau *= -2.0
    sim.step(tau)
    np.testing.assert_array_equal(sim.log.tau_command, [0.1 * hi, 0.1 * hi, -0.2 * hi])
    tau[3] = np.nan
    with pytest.raises(ValueError, match="tau"):
        sim.step(tau)
    sim.step(list(0.05 * hi))
    np.testing.assert_array_equal(sim.log.tau_command[-1], 0.05 * hi)
