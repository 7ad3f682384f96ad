"""A contact ``offset``: the sphere or sole centre placed relative to the described frame. The
evidence is Pinocchio's own placement of the described frame, composed independently, and the
MuJoCo twin's geometry."""

import tomllib
from importlib import resources

import mujoco
import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.sim.simulator import Simulator
from wholebody.sim.twin import build_twin


def shifted_hyq(offset):
    """hyq with every foot's contact moved by ``offset`` (in the foot frame) and its radius kept."""
    with resources.as_file(resources.files("wholebody.robots") / "presets" / "hyq.toml") as path:
        data = tomllib.loads(path.read_text())
    for contact in data["contacts"]:
        contact["offset"] = list(offset)
    return wb.load_robot(data)


def test_offset_contact_sits_at_the_offset_of_its_frame(rng):
    offset = np.array([0.01, -0.02, 0.03])
    robot = shifted_hyq(offset)
    q, v = robot.random_state(rng)
    robot.update(q, v)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    for c in robot.contacts:
        assert c.frame == f"{c.name}_contact" and c.spec.frame != c.frame
        described = data.oMf[robot.model.getFrameId(c.spec.frame)]
        expected = described.translation + described.rotation @ offset
        p, R = robot.frame_placement(c.frame)
        np.testing.assert_allclose(p, expected, atol=1e-12)
        np.testing.assert_allclose(R, described.rotation, atol=1e-12)
        # the contact point is the bottom of the sphere around the offset centre
        np.testing.assert_allclose(robot.contact_point(c.name),
                                   expected - [0.0, 0.0, c.spec.radius], atol=1e-12)
        # its Jacobian moves that point: finite differences along a random velocity
        dq = rng.standard_normal(robot.nv) * 1e-6
        data2 = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data2, pin.integrate(robot.model, q, dq))
        moved = data2.oMf[c.frame_id].translation - data.oMf[c.frame_id].translation
        J = robot.frame_jacobian(c.frame)[:3]
        np.testing.assert_allclose(J @ dq, moved, atol=1e-10)


def test_twin_puts_the_foot_sphere_at_the_offset(rng):
    robot = shifted_hyq([0.0, 0.0, 0.05])
    twin = build_twin(robot)
    sim = Simulator(robot, record=False)
    q, v = robot.random_state(rng)
    sim.reset(q, v)
    robot.update(q, v)
    for name, (p, _) in sim.contact_frame_poses().items():
        np.testing.assert_allclose(p, robot.frame_placement(robot.contact(name).frame)[0],
                                   atol=1e-12)
    d = mujoco.MjData(twin.model)
    d.qpos[:] = sim.data.qpos
    mujoco.mj_forward(twin.model, d)
    spheres = [g for g in range(twin.model.ngeom)
               if twin.model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
    centres = sorted(tuple(np.round(d.geom_xpos[g], 9)) for g in spheres)
    expected = sorted(tuple(np.round(robot.frame_placement(c.frame)[0], 9))
                      for c in robot.contacts)
    assert centres == expected


def test_the_robot_stands_on_the_offset_spheres():
    """The base is placed so the lowest sphere (around the offset centre) touches z = 0."""
    plain, shifted = wb.load_robot("hyq"), shifted_hyq([0.0, 0.0, 0.05])
    plain.update(plain.q_ref, np.zeros(plain.nv))
    shifted.update(shifted.q_ref, np.zeros(shifted.nv))
    assert min(shifted.contact_point(n)[2] for n in shifted.contact_names) == pytest.approx(0.0,
                                                                                           abs=1e-12)
    # the base comes down by the lowest rise of the offset in the world, from the plain model
    rises = [(plain.frame_placement(c.frame)[1] @ [0.0, 0.0, 0.05])[2] for c in plain.contacts]
    assert plain.q_ref[2] - shifted.q_ref[2] == pytest.approx(min(rises), abs=1e-12)
