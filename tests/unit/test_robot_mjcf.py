"""Robots from MJCF files, and URDFs declaring their own floating joint.

The evidence is independent of the conversion: MuJoCo's own mass matrix, centre of mass and
keyframes of the same file, and Pinocchio's URDF parser on the same robot written as a URDF (which
MuJoCo itself converts to MJCF here)."""

import logging

import mujoco
import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.robots.description import DescriptionError
from wholebody.robots.mjcf import build_model, load_mjcf
from wholebody.sim import convert
from wholebody.solvers import SolverSettings

LEGS = {"lf": (0.25, 0.12), "rf": (0.25, -0.12), "lh": (-0.25, 0.12), "rh": (-0.25, -0.12)}


def _inertial(mass, xyz, rpy, ixx, iyy, izz, ixy=0.0, ixz=0.0, iyz=0.0) -> str:
    return (f'<inertial><origin xyz="{xyz}" rpy="{rpy}"/><mass value="{mass}"/>'
            f'<inertia ixx="{ixx}" iyy="{iyy}" izz="{izz}" ixy="{ixy}" ixz="{ixz}" iyz="{iyz}"/>'
            f'</inertial>')


def quadruped_urdf(floating: bool = False, mujoco_tags: bool = False) -> str:
    """A small quadruped: rotated joint origins, an axis along -y (an unaligned joint), offset and
    rotated inertials with products of inertia, a fixed foot link with a sphere."""
    parts = ['<robot name="quad">']
    if mujoco_tags:  # MuJoCo's URDF import: keep the fixed links as bodies
        parts.append('<mujoco><compiler fusestatic="false" discardvisual="true" '
                     'balanceinertia="false"/></mujoco>')
    if floating:
        parts.append('<link name="world"/><joint name="float_base" type="floating">'
                     '<parent link="world"/><child link="base"/></joint>')
    parts.append('<link name="base">' + _inertial(8.0, "0.02 0.01 -0.01", "0.1 0 0.2",
                                                  0.05, 0.2, 0.22, 0.003, -0.002, 0.001)
                 + '</link>')
    for leg, (x, y) in LEGS.items():
        axis = "0 -1 0" if leg == "rh" else "0 1 0"
        parts.append(
            f'<joint name="{leg}_haa" type="revolute"><parent link="base"/><child link="{leg}_hip"/>'
            f'<origin xyz="{x} {y} 0" rpy="0.05 0 0"/><axis xyz="1 0 0"/>'
            f'<limit lower="-0.8" upper="0.8" effort="30" velocity="20"/></joint>'
            f'<link name="{leg}_hip">' + _inertial(0.7, "0 0.03 0", "0 0 0", 1e-3, 1.2e-3, 9e-4,
                                                   1e-5) + '</link>'
            f'<joint name="{leg}_hfe" type="revolute"><parent link="{leg}_hip"/>'
            f'<child link="{leg}_thigh"/><origin xyz="0 {0.05 if y > 0 else -0.05} 0" '
            f'rpy="0 0.1 0"/><axis xyz="{axis}"/>'
            f'<limit lower="-1.5" upper="1.5" effort="30" velocity="20"/></joint>'
            f'<link name="{leg}_thigh">' + _inertial(1.0, "0 0 -0.1", "0 0.2 0", 8e-3, 8e-3, 1e-3,
                                                     0, 2e-4) + '</link>'
            f'<joint name="{leg}_kfe" type="revolute"><parent link="{leg}_thigh"/>'
            f'<child link="{leg}_shank"/><origin xyz="0 0 -0.2"/><axis xyz="0 1 0"/>'
            f'<limit lower="-2.5" upper="-0.2" effort="40" velocity="20"/></joint>'
            f'<link name="{leg}_shank">' + _inertial(0.3, "0 0 -0.1", "0 0 0", 3e-3, 3e-3, 2e-4)
            + '</link>'
            f'<joint name="{leg}_foot_fixed" type="fixed"><parent link="{leg}_shank"/>'
            f'<child link="{leg}_foot"/><origin xyz="0 0 -0.2"/></joint>'
            f'<link name="{leg}_foot">' + _inertial(0.05, "0 0 0", "0 0 0", 1e-5, 1e-5, 1e-5)
            + '<collision><geometry><sphere radius="0.02"/></geometry></collision></link>')
    parts.append("</robot>")
    return "".join(parts)


def _with_continuous(text: str, joint: str, limits: str) -> str:
    """The quadruped URDF ``text`` with each leg's ``joint`` (``hfe``, ``kfe``) continuous: its
    type changed and its ``limits`` attributes removed."""
    for leg in LEGS:
        start = text.index(f'<joint name="{leg}_{joint}" type="revolute">')
        end = text.index("</joint>", start)
        changed = text[start:end].replace('type="revolute"', 'type="continuous"').replace(
            limits, "")
        text = text[:start] + changed + text[end:]
    return text


def _mapped(q_from, model_from, model_to):
    """``q_from`` (a configuration of ``model_from``) as a configuration of ``model_to``: the
    base's 7 coordinates, then each joint by name."""
    q = pin.neutral(model_to)
    q[:7] = q_from[:7]
    for jid in range(2, model_to.njoints):
        src = model_from.joints[model_from.getJointId(model_to.names[jid])]
        dst = model_to.joints[jid]
        q[dst.idx_q:dst.idx_q + dst.nq] = q_from[src.idx_q:src.idx_q + src.nq]
    return q


def _random_q(model, rng):
    lo = np.where(np.isfinite(model.lowerPositionLimit), model.lowerPositionLimit, -1.0)
    hi = np.where(np.isfinite(model.upperPositionLimit), model.upperPositionLimit, 1.0)
    q = pin.randomConfiguration(model, lo, hi)
    q[:3] = rng.normal(size=3)
    quat = rng.normal(size=4)
    q[3:7] = quat / np.linalg.norm(quat)
    return q


def _full_mass_matrix(model, q):
    M = pin.crba(model, model.createData(), q)
    return np.triu(M) + np.triu(M, 1).T


def test_mjcf_converted_by_mujoco_from_a_urdf_gives_the_urdfs_model(tmp_path, rng):
    """The quadruped's URDF read by Pinocchio's URDF parser, and the same URDF compiled by
    MuJoCo's own URDF import (no free joint: the world's moving child is the base) and converted:
    same mass, centre of mass, frames and M(q) at random configurations. The MJCF file MuJoCo
    writes of it loads too, equal to the precision of the numbers it prints (~6 digits)."""
    urdf = tmp_path / "quad.urdf"
    urdf.write_text(quadruped_urdf(mujoco_tags=True))
    compiled = mujoco.MjModel.from_xml_path(str(urdf))
    xml = tmp_path / "quad.xml"
    mujoco.mj_saveLastXML(str(xml), compiled)
    reference = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    model = build_model(compiled).model
    assert model.nv == reference.nv and set(model.names[2:]) == set(reference.names[2:])
    assert pin.computeTotalMass(model) == pytest.approx(pin.computeTotalMass(reference), rel=1e-12)
    written = load_mjcf(xml).model
    M_written = _full_mass_matrix(written, pin.neutral(written))
    np.testing.assert_allclose(M_written, _full_mass_matrix(model, pin.neutral(model)),
                               atol=1e-5 * np.abs(M_written).max())
    data, ref_data = model.createData(), reference.createData()
    for _ in range(5):
        q_ref = _random_q(reference, rng)
        q = _mapped(q_ref, reference, model)
        com = pin.centerOfMass(model, data, q)
        np.testing.assert_allclose(com, pin.centerOfMass(reference, ref_data, q_ref), atol=1e-9)
        M, M_ref = _full_mass_matrix(model, q), _full_mass_matrix(reference, q_ref)
        # the same rows/columns: joints by name (both order them depth-first from the URDF)
        perm = list(range(6)) + [reference.joints[reference.getJointId(n)].idx_v
                                 for n in model.names[2:]]
        np.testing.assert_allclose(M, M_ref[np.ix_(perm, perm)], atol=1e-9 * np.abs(M_ref).max())
        for name in ("lf_foot", "rh_shank"):
            pin.framesForwardKinematics(model, data, q)
            pin.framesForwardKinematics(reference, ref_data, q_ref)
            np.testing.assert_allclose(data.oMf[model.getFrameId(name)].homogeneous,
                                       ref_data.oMf[reference.getFrameId(name)].homogeneous,
                                       atol=1e-9)


# a hand-written MJCF using what Menagerie files use: default classes and childclass, degrees,
# euler angles, a joint away from its body's origin, full inertias, sites, keyframes, motors
# with gear and ctrlrange, a position servo with a forcerange, a joint actuatorfrcrange, armature
BIPED_MJCF = """
<mujoco model="biped">
  <compiler angle="degree" autolimits="true"/>
  <default>
    <default class="leg">
      <joint axis="0 1 0" range="-90 90" armature="0.02" damping="0.1"/>
      <motor ctrlrange="-1 1" gear="50"/>
      <default class="knee"><joint range="0 150"/></default>
    </default>
  </default>
  <worldbody>
    <light pos="0 0 3"/>
    <geom name="ground" type="plane" size="5 5 0.1"/>
    <body name="pelvis" pos="0 0 0.9">
      <freejoint name="root"/>
      <inertial pos="0 0 0.05" mass="10" fullinertia="0.2 0.15 0.1 0.01 0 0.002"/>
      <site name="imu" pos="0 0 0.1"/>
      <body name="torso" pos="0 0 0.2" euler="0 5 0">
        <inertial pos="0 0 0.1" mass="5" diaginertia="0.1 0.1 0.05"/>
      </body>
      <body name="l_thigh" pos="0 0.1 -0.05" childclass="leg" euler="3 0 0">
        <joint name="l_hip_roll" axis="1 0 0" range="-30 30"/>
        <inertial pos="0 0 -0.05" mass="1" diaginertia="0.01 0.01 0.002"/>
        <body name="l_upper" pos="0 0 -0.05">
          <joint name="l_hip_pitch" pos="0 0 0.02"/>
          <inertial pos="0 0 -0.15" quat="0.98 0.1 0.1 0" mass="2" diaginertia="0.03 0.03 0.004"/>
          <body name="l_shank" pos="0 0 -0.35">
            <joint name="l_knee" class="knee"/>
            <inertial pos="0 0 -0.17" mass="1.5" diaginertia="0.02 0.02 0.002"/>
            <body name="l_foot" pos="0 0 -0.35">
              <joint name="l_ankle" range="-45 45"/>
              <inertial pos="0.02 0 -0.03" mass="0.6" diaginertia="0.002 0.003 0.003"/>
              <geom name="l_sole" type="box" size="0.1 0.05 0.01" pos="0.02 0 -0.05"/>
            </body>
          </body>
        </body>
      </body>
      <body name="r_thigh" pos="0 -0.1 -0.05" childclass="leg" euler="-3 0 0">
        <joint name="r_hip_roll" axis="1 0 0" range="-30 30" actuatorfrcrange="-80 80"/>
        <inertial pos="0 0 -0.05" mass="1" diaginertia="0.01 0.01 0.002"/>
        <body name="r_upper" pos="0 0 -0.05">
          <joint name="r_hip_pitch" pos="0 0 0.02"/>
          <inertial pos="0 0 -0.15" quat="0.98 -0.1 0.1 0" mass="2" diaginertia="0.03 0.03 0.004"/>
          <body name="r_shank" pos="0 0 -0.35">
            <joint name="r_knee" class="knee"/>
            <inertial pos="0 0 -0.17" mass="1.5" diaginertia="0.02 0.02 0.002"/>
            <body name="r_foot" pos="0 0 -0.35">
              <joint name="r_ankle" range="-45 45"/>
              <inertial pos="0.02 0 -0.03" mass="0.6" diaginertia="0.002 0.003 0.003"/>
              <geom name="r_sole" type="box" size="0.1 0.05 0.01" pos="0.02 0 -0.05"/>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="l_hip_roll" joint="l_hip_roll" class="leg"/>
    <motor name="l_hip_pitch" joint="l_hip_pitch" class="leg"/>
    <motor name="l_knee" joint="l_knee" class="leg" gear="100"/>
    <position name="l_ankle" joint="l_ankle" kp="100" forcerange="-30 30"/>
    <motor name="r_hip_roll" joint="r_hip_roll" class="leg"/>
    <motor name="r_hip_pitch" joint="r_hip_pitch" class="leg"/>
    <motor name="r_knee" joint="r_knee" class="leg" gear="100"/>
    <position name="r_ankle" joint="r_ankle" kp="100" forcerange="-30 30"/>
  </actuator>
  <keyframe>
    <key name="crouch" qpos="0 0 0.8 1 0 0 0  0.0 -0.4 0.8 -0.4  0.0 -0.4 0.8 -0.4"/>
  </keyframe>
</mujoco>
"""


def biped_description(path, **extra) -> dict:
    return {"name": "biped", "model": str(path), "posture": "keyframe:crouch",
            "contacts": [{"name": f"{s}_sole", "frame": f"{s}_foot", "type": "rectangle",
                          "half_size": [0.1, 0.05], "offset": [0.02, 0.0, -0.06]}
                         for s in ("l", "r")], **extra}


@pytest.fixture()
def biped_xml(tmp_path):
    path = tmp_path / "biped.xml"
    path.write_text(BIPED_MJCF)
    return path


def test_mjcf_robot_has_mujocos_dynamics(biped_xml, rng):
    """M(q) (armature included) and the CoM of the Robot built from the MJCF are MuJoCo's own for
    the same file, at random states; the MJCF's joint frames, sites and welded bodies are
    frames of the model."""
    robot = wb.load_robot(biped_description(biped_xml))
    m = mujoco.MjModel.from_xml_path(str(biped_xml))
    d = mujoco.MjData(m)
    assert robot.mass == pytest.approx(m.body_mass.sum(), rel=1e-12)
    assert robot.source.format == "mjcf" and robot.source.own_floating_joint
    for name in ("imu", "torso", "l_foot", "r_knee"):
        assert robot.model.existFrame(name)
    for _ in range(5):
        q, v = robot.random_state(rng)
        d.qpos[:], d.qvel[:] = convert.pin_to_mj(q, v)
        mujoco.mj_forward(m, d)
        M_mj = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M_mj)
        robot.update(q, v)
        np.testing.assert_allclose(robot.M, convert.mass_matrix_to_pin(q, M_mj),
                                   atol=1e-10 * np.abs(robot.M).max())
        np.testing.assert_allclose(robot.com, d.subtree_com[1], atol=1e-12)
        sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "imu")
        np.testing.assert_allclose(robot.frame_placement("imu")[0], d.site_xpos[sid], atol=1e-12)


def test_mjcf_limits_armature_and_keyframe(biped_xml):
    """Position limits (degrees in the file), effort limits (motor: |gear| ctrlrange; position
    servo: forcerange; actuatorfrcrange wins), armature from the default class, the keyframe's
    joint angles as the posture."""
    robot = wb.load_robot(biped_description(biped_xml))
    limits = dict(zip(robot.joint_names, robot.torque_limits.constant))
    assert limits == pytest.approx({"l_hip_roll": 50, "l_hip_pitch": 50, "l_knee": 100,
                                    "l_ankle": 30, "r_hip_roll": 80, "r_hip_pitch": 50,
                                    "r_knee": 100, "r_ankle": 30})
    i = robot.joint_names.index("l_knee")
    assert (robot.q_min[i], robot.q_max[i]) == pytest.approx((0.0, np.radians(150)))
    np.testing.assert_allclose(robot.model.armature[6:], 0.02)
    angles = dict(zip(robot.joint_names, robot.q_ref[7:]))
    assert angles == pytest.approx({"l_hip_roll": 0, "l_hip_pitch": -0.4, "l_knee": 0.8,
                                    "l_ankle": -0.4, "r_hip_roll": 0, "r_hip_pitch": -0.4,
                                    "r_knee": 0.8, "r_ankle": -0.4})
    # the description's armature replaces the file's: a table only for the joints it names
    robot = wb.load_robot(biped_description(biped_xml, armature={"l_knee": 0.5}))
    arm = dict(zip(robot.joint_names, robot.model.armature[6:]))
    assert arm["l_knee"] == 0.5 and arm["r_knee"] == 0.02


def test_twin_of_an_mjcf_robot_compiles_with_its_mass(biped_xml):
    """The twin generated from the MJCF robot's Pinocchio model compiles, with the same mass."""
    from wholebody.sim.simulator import Simulator

    robot = wb.load_robot(biped_description(biped_xml))
    sim = Simulator(robot, record=False)
    assert sum(sim.model.body_mass) == pytest.approx(robot.mass, rel=1e-12)


@pytest.mark.parametrize("edit,needle", [
    (('<joint name="l_ankle" range="-45 45"/>', '<joint name="l_ankle" type="ball"/>'),
     ["'l_ankle'", "ball joint"]),
    (('<joint name="l_ankle" range="-45 45"/>',
      '<joint name="l_ankle" range="-45 45"/><joint name="l_ankle2" axis="1 0 0"/>'),
     ["body 'l_foot'", "2 joints", "one joint per body"]),
    (('<light pos="0 0 3"/>', '<light pos="0 0 3"/><body name="box"><freejoint/>'
      '<geom type="box" size="0.1 0.1 0.1"/></body>'), ["2 free joints", "'box'"]),
    (('<joint name="l_knee" class="knee"/>', '<joint name="l_knee" class="nope"/>'),
     ["does not compile", "nope"]),
])
def test_mjcf_that_cannot_be_read_is_named(tmp_path, edit, needle):
    path = tmp_path / "bad.xml"
    path.write_text(BIPED_MJCF.replace(*edit))
    with pytest.raises(DescriptionError) as err:
        wb.load_robot(biped_description(path))
    assert all(n in str(err.value) for n in needle), str(err.value)


def test_unknown_keyframe_and_both_model_fields_are_named(biped_xml):
    with pytest.raises(DescriptionError, match=r"keyframe:stand.*keyframes: \['crouch'\]"):
        wb.load_robot(biped_description(biped_xml, posture="keyframe:stand"))
    data = biped_description(biped_xml)
    with pytest.raises(DescriptionError, match="'model' and 'urdf' are both given"):
        wb.load_robot({**data, "urdf": data["model"]})


def test_urdf_with_its_own_floating_joint(tmp_path, rng):
    """A URDF with a floating joint from a massless world link: that joint is the free flyer (no
    second one is added), and the robot is the same as the URDF without it."""
    plain, floating = tmp_path / "plain.urdf", tmp_path / "floating.urdf"
    plain.write_text(quadruped_urdf())
    floating.write_text(quadruped_urdf(floating=True))
    description = {"name": "quad", "posture": {f"{leg}_kfe": -1.0 for leg in LEGS},
                   "contacts": [{"name": leg, "frame": f"{leg}_foot", "type": "point",
                                 "radius": 0.02} for leg in LEGS]}
    a = wb.load_robot({**description, "urdf": str(plain)})
    b = wb.load_robot({**description, "model": str(floating)})
    assert b.model.names[1] == "float_base" and b.nq == a.nq and b.nv == a.nv
    assert b.source.own_floating_joint and not a.source.own_floating_joint
    assert b.base_frame == "base" and b.mass == pytest.approx(a.mass, rel=1e-12)
    np.testing.assert_allclose(b.q_ref, a.q_ref, atol=1e-12)
    for _ in range(3):
        q, v = a.random_state(rng)
        a.update(q, v)
        b.update(q, v)
        np.testing.assert_allclose(b.M, a.M, atol=1e-12)
        np.testing.assert_allclose(b.h, a.h, atol=1e-10)


def test_urdf_parser_noise_is_collected(tmp_path, caplog):
    """What urdfdom prints on stderr while parsing ends up in one log record, not on the
    terminal."""
    import os

    from wholebody.robots.model_file import captured_stderr

    with caplog.at_level(logging.INFO, logger="wholebody.robots.model_file"):
        with captured_stderr("robot 'x': URDF x.urdf"):
            os.write(2, b"Error: unknown element\nline 2\n")
    assert any("unknown element" in r.getMessage() for r in caplog.records)


# ------------------------------------------------------------------ init-robot
def test_init_robot_drafts_a_quadruped_from_a_urdf(tmp_path):
    """The quadruped URDF: four point feet at the foot links with the collision spheres' radius,
    a computed posture with the feet where the legs at zero put them (legs bent, inside the
    limits) that stands on
    all four (check-robot finds no error); the URDF given as the robot loads the same draft."""
    from wholebody.robots.check import check_robot
    from wholebody.robots.draft import draft_description

    urdf = tmp_path / "quad.urdf"
    urdf.write_text(quadruped_urdf())
    draft = draft_description(urdf)
    contacts = {c["frame"]: c for c in draft.data["contacts"]}
    assert set(contacts) == {f"{leg}_foot" for leg in LEGS}
    assert all(c["type"] == "point" and c["radius"] == 0.02 and "offset" not in c
               for c in contacts.values())
    assert isinstance(draft.data["posture"], dict)
    assert any("posture: computed" in n for n in draft.notes)
    path = tmp_path / "quad.toml"
    path.write_text(draft.text)
    report = check_robot(str(path))
    assert report.ok, [f.message for f in report.findings]
    _assert_feet_where_the_legs_at_zero_put_them(wb.load_robot(str(path)))
    assert wb.load_robot(str(urdf)).na == 12  # a model file loads through the same draft


def test_init_robot_drafts_continuous_hips_and_knees_bent_at_zero(tmp_path):
    """A URDF as vendors ship it: continuous hip flexion joints, knees whose range excludes 0
    (straight legs are out of reach) and Gazebo plugin elements holding ``<link>`` and
    ``<joint>`` tags of their own. The draft bends the continuous joints too (their angles in the
    posture) and puts each foot where the legs at zero put it (not where a knee held at its stop
    does), as the kinematics of the loaded robot show."""
    from wholebody.robots.check import check_robot
    from wholebody.robots.draft import draft_description

    text = _with_continuous(quadruped_urdf(), "hfe", 'lower="-1.5" upper="1.5" ')
    text = text.replace('lower="-2.5" upper="-0.2"', 'lower="-2.5" upper="-0.6"')
    text = text.replace("</robot>", '<gazebo><plugin name="contact"><link>base</link>'
                        '<joint>lf_haa</joint></plugin></gazebo><transmission name="t">'
                        '<joint name="lf_haa"/></transmission></robot>')
    urdf = tmp_path / "vendor.urdf"
    urdf.write_text(text)
    draft = draft_description(urdf)
    posture = draft.data["posture"]
    assert {f"{leg}_hfe" for leg in LEGS} <= set(posture)
    assert all(-2.5 <= posture[f"{leg}_kfe"] <= -0.6 for leg in LEGS)
    path = tmp_path / "vendor.toml"
    path.write_text(draft.text)
    report = check_robot(str(path))
    assert report.ok, [f.message for f in report.findings]
    robot = wb.load_robot(str(path))
    angles = robot.joint_angles(robot.q_ref)
    for leg in LEGS:
        assert angles[robot.joint_names.index(f"{leg}_hfe")] == pytest.approx(
            posture[f"{leg}_hfe"], abs=1e-6)
    _assert_feet_where_the_legs_at_zero_put_them(robot)


def _assert_feet_where_the_legs_at_zero_put_them(robot):
    """Each foot of the posture is, in the horizontal plane, where it is with the base in its
    posture pose and every joint at zero (the zero configuration's kinematics, Pinocchio's)."""
    model, data = robot.model, robot.model.createData()
    q_zero = pin.neutral(model)
    q_zero[:7] = robot.q_ref[:7]
    pin.framesForwardKinematics(model, data, q_zero)
    for c in robot.contacts:
        at_zero = data.oMf[c.frame_id].translation
        np.testing.assert_allclose(robot.contact_point(c.name)[:2], at_zero[:2], atol=0.005)


def test_init_robot_drafts_a_biped_from_an_mjcf(biped_xml, tmp_path):
    """The biped MJCF: two soles from the box geoms (half sizes and bottom-face centres in the
    foot bodies' frames), the keyframe as the posture."""
    from wholebody.robots.draft import draft_description

    draft = draft_description(biped_xml)
    assert draft.data["posture"] == "keyframe:crouch"
    soles = {c["frame"]: c for c in draft.data["contacts"]}
    assert set(soles) == {"l_foot", "r_foot"}
    for c in soles.values():
        assert c["type"] == "rectangle" and c["half_size"] == [0.1, 0.05]
        assert c["offset"] == pytest.approx([0.02, 0.0, -0.06])
        assert c["name"] in ("l_sole", "r_sole")  # the geoms' own names
    path = tmp_path / "biped.toml"
    path.write_text(draft.text)
    assert wb.load_robot(str(path)).na == 8


def test_init_robot_cli(tmp_path, biped_xml, capsys):
    from wholebody.cli import main

    out = tmp_path / "b.toml"
    assert main(["init-robot", str(biped_xml), "--out", str(out)]) == 0
    assert "check: posture" in capsys.readouterr().out and out.is_file()
    assert main(["init-robot", str(biped_xml), "--out", str(out)]) == 2  # exists: --force
    assert main(["init-robot", str(tmp_path / "none.xml")]) == 2
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body><joint type='nope'/></body></worldbody></mujoco>")
    assert main(["init-robot", str(bad)]) == 2
    assert "does not compile" in capsys.readouterr().err


# ------------------------------------------------------------------ continuous joints
def _continuous_quadruped(tmp_path):
    """The quadruped with its knees as continuous joints (unbounded revolute: nq = 2, nv = 1)."""
    text = _with_continuous(quadruped_urdf(), "kfe", 'lower="-2.5" upper="-0.2" ')
    path = tmp_path / "wheels.urdf"
    path.write_text(text)
    return {"name": "wheels", "model": str(path),
            "posture": {**{f"{leg}_kfe": -1.2 for leg in LEGS}, **{f"{leg}_hfe": 0.6
                                                                 for leg in LEGS}},
            "contacts": [{"name": leg, "frame": f"{leg}_foot", "type": "point", "radius": 0.02}
                         for leg in LEGS]}


def test_continuous_joints_have_angles(tmp_path, rng):
    """Continuous joints load (not refused, not converted: (cos, sin) coordinates); their angle
    is atan2(sin, cos), they have no limits, the joint error is the shortest signed angle
    (pin.difference), and the angles' time derivative along a motion is the joint velocity
    (finite differences)."""
    robot = wb.load_robot(_continuous_quadruped(tmp_path))
    knees = [robot.joint_names.index(f"{leg}_kfe") for leg in LEGS]
    assert robot.nq == 7 + 12 + 4 and robot.na == 12 and not robot.angles_are_coordinates
    assert np.all(np.isinf(robot.q_min[knees])) and np.all(np.isinf(robot.q_max[knees]))
    angles = robot.joint_angles(robot.q_ref)
    np.testing.assert_allclose(angles[knees], -1.2, atol=1e-12)
    q, v = robot.random_state(rng)
    np.testing.assert_allclose(robot.joint_angles(robot.with_joint_angles(q, angles)), angles,
                               atol=1e-12)
    # the error wraps: from 3.1 to -3.1 is +0.083 rad, not -6.2
    a, b = angles.copy(), angles.copy()
    a[knees], b[knees] = 3.1, -3.1
    err = robot.joint_error(robot.with_joint_angles(q, a), robot.with_joint_angles(q, b))
    np.testing.assert_allclose(err[knees], 2 * np.pi - 6.2, atol=1e-12)
    dt = 1e-7
    q2 = pin.integrate(robot.model, q, v * dt)
    rate = (robot.joint_angles(q2) - robot.joint_angles(q)) / dt
    np.testing.assert_allclose(rate, v[6:], atol=1e-5)
    lo, hi = robot.torque_bounds(q)
    assert np.all(hi == 40.0 * (np.arange(12) % 3 == 2) + 30.0 * (np.arange(12) % 3 != 2))


def test_continuous_joints_in_the_twin(tmp_path, rng):
    """The twin simulates continuous joints as hinges: MuJoCo's qpos holds the angle where
    Pinocchio's q holds (cos, sin), and a state set into the simulator reads back the same (q, v)
    (the angles wrap into (-pi, pi]); the MuJoCo mass matrix equals Pinocchio's at that state."""
    from wholebody.sim.simulator import Simulator

    robot = wb.load_robot(_continuous_quadruped(tmp_path))
    sim = Simulator(robot, record=False)
    knees = [robot.joint_names.index(f"{leg}_kfe") for leg in LEGS]
    for _ in range(5):
        q, v = robot.random_state(rng, velocity_scale=0.5)
        angles = robot.joint_angles(q)
        angles[knees] += 2 * np.pi * rng.integers(-2, 3, len(knees))  # one wrap or two
        q = robot.with_joint_angles(q, angles)
        sim.reset(q, v)
        q2, v2 = sim.state()
        np.testing.assert_allclose(q2, q, atol=1e-12)
        np.testing.assert_allclose(v2, v, atol=1e-12)
        np.testing.assert_allclose(sim.data.qpos[7:7 + robot.na], robot.joint_angles(q), atol=1e-12)
        M_mj = np.zeros((sim.model.nv, sim.model.nv))
        mujoco.mj_fullM(sim.model, sim.data, M_mj)
        M_pin = pin.crba(robot.model, robot.model.createData(), q)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        q_mujoco = np.r_[q[:7], robot.joint_angles(q)]  # the velocity map needs only the base
        np.testing.assert_allclose(convert.mass_matrix_to_pin(q_mujoco, M_mj[:robot.nv, :robot.nv]),
                                   M_pin, atol=1e-9 * np.abs(M_pin).max())


@pytest.mark.slow
def test_continuous_knees_simulate_as_the_same_revolute_knees(tmp_path):
    """The quadruped with continuous knees and the same quadruped with revolute knees (their
    limits far from the motion) in the same closed loop (`stand`, 1 s): the same run to
    round-off, every metric — the (cos, sin) coordinates, the hinge conversion and the
    controllers' angle handling change nothing but the representation."""
    from wholebody.scenarios import SCENARIOS

    continuous = _continuous_quadruped(tmp_path)
    revolute_urdf = tmp_path / "revolute.urdf"
    revolute_urdf.write_text(quadruped_urdf())
    revolute = {**continuous, "name": "revolute", "model": str(revolute_urdf)}
    runs = [SCENARIOS["stand"].run(wb.load_robot(d), None, {"duration": "1"}).metrics
            for d in (continuous, revolute)]
    numbers = [k for k, v in runs[1].items() if isinstance(v, float)]
    assert len(numbers) >= 4
    for key in numbers:
        assert runs[0][key] == pytest.approx(runs[1][key], rel=1e-6, abs=1e-9), key


@pytest.mark.parametrize("mode", ["braking", "tanh"])
def test_continuous_joints_in_both_engines(tmp_path, rng, mode):
    """A stack with a posture (base rows on), joint-acceleration limits, torque limits and a joint
    trajectory on continuous knees: the native cycle's level arrays and torques equal the Python
    engine's on random states; a knee at -3.1 rad whose reference is 3.1 rad is driven the short
    way (-0.083 rad through ±pi, from atan2 of the two (cos, sin) pairs here), and the knees
    have no position limit (acceleration bounds infinite when braking, ±a_max with tanh)."""
    from wholebody.cycle import HierarchyCycle, native_available
    from wholebody.formulation import Stack
    from wholebody.tasks import (ContactConstraint, FrictionCone, JointAccelerationLimits,
                                 JointTrajectoryTask, NewtonEuler, PostureTask, TorqueLimits)
    from wholebody.variables import Variables

    if not native_available():
        pytest.skip("the compiled cycle is not built")
    robot = wb.load_robot(_continuous_quadruped(tmp_path))
    knees = [robot.joint_names.index(f"{leg}_kfe") for leg in LEGS]
    kp, kd = 40.0, 6.0

    def stack():
        return Stack([[NewtonEuler(), TorqueLimits()],
                      [ContactConstraint(), FrictionCone(0.8), JointAccelerationLimits(mode=mode)],
                      [JointTrajectoryTask([f"{next(iter(LEGS))}_kfe"], kp=80.0, kd=9.0, name="knee"),
                       PostureTask(kp=kp, kd=kd, base_kp=20.0, base_kd=5.0, name="posture")]])

    settings = SolverSettings(backend="quadprog", fallback_backend=None)
    engines = {e: HierarchyCycle(robot, stack(), engine=e, settings=settings)
               for e in ("native", "python")}
    assert engines["native"].native
    angles = robot.joint_angles(robot.q_ref)
    for i in range(4):
        q, v = robot.random_state(rng, velocity_scale=0.2)
        q[:7] = robot.q_ref[:7]
        a = robot.joint_angles(q)
        a[knees[0]] = -3.1
        q = robot.with_joint_angles(q, a)
        for e in engines.values():
            e.stack.find("posture").q_ref = robot.with_joint_angles(robot.q_ref, np.where(
                np.arange(robot.na) == knees[0], 3.1, angles))
        sols = {name: e.solve(q, v, Variables(robot)) for name, e in engines.items()}
        native_levels = [np.array(lv.B) for lv in engines["native"].levels]
        python_levels = [np.array(lv.B) for lv in engines["python"].levels]
        for x, y in zip(native_levels, python_levels):
            np.testing.assert_allclose(x, y, atol=1e-8 * max(1.0, np.abs(y).max()))
        for x, y in zip(engines["native"].levels, engines["python"].levels):
            np.testing.assert_allclose(x.b, y.b, atol=1e-8)
            np.testing.assert_array_equal(np.isinf(x.lower), np.isinf(y.lower))
        if sols["native"].ok and sols["python"].ok:
            from conftest import torque_tolerance
            tol = torque_tolerance(lambda q, v: engines["python"].solve(q, v).tau, q, v, robot.nq)
            np.testing.assert_allclose(sols["native"].tau, sols["python"].tau, atol=tol, rtol=0)
        # the posture row of the first knee: kp * (shortest angle from -3.1 to 3.1) - kd * v
        posture = engines["native"].levels[2]
        cs, cs_ref = (np.cos(-3.1), np.sin(-3.1)), (np.cos(3.1), np.sin(3.1))
        short = np.arctan2(cs[0] * cs_ref[1] - cs[1] * cs_ref[0], cs[0] * cs_ref[0] + cs[1] * cs_ref[1])
        assert short == pytest.approx(6.2 - 2 * np.pi)  # down through ±pi, not up by 6.2
        row = 1 + 6 + knees[0]  # after the knee trajectory's row and the base rows
        assert posture.b[row] == pytest.approx(kp * short - kd * v[6 + knees[0]], abs=1e-9)
        # the knees' acceleration limits: none (braking), the amplitude as far from any limit (tanh)
        limits = engines["native"].levels[1]
        lo, hi = limits.lower[-robot.na:], limits.upper[-robot.na:]
        bound = np.inf if mode == "braking" else JointAccelerationLimits().a_max
        assert np.all(lo[knees] == -bound) and np.all(hi[knees] == bound)


def test_a_continuous_thigh_lifts_its_foot_as_the_same_revolute_thigh(tmp_path):
    """How high each foot can rise (:func:`~wholebody.planning.reach.foot_lift`, which caps the
    swings) and how a 10° slope moves the legs (``slope_stance_change``): the quadruped with
    continuous thighs gives what the same quadruped gives with revolute thighs whose limits are
    far from the motion (±100 rad) — the continuous joints move in the search (they were left
    out: every foot 'rose at most 0 m' and the swings stayed on the floor)."""
    from wholebody.planning.reach import foot_lift, slope_stance_change

    posture = {**{f"{leg}_kfe": -1.2 for leg in LEGS}, **{f"{leg}_hfe": 0.6 for leg in LEGS}}
    contacts = [{"name": leg, "frame": f"{leg}_foot", "type": "point", "radius": 0.02}
                for leg in LEGS]
    limits = 'lower="-1.5" upper="1.5" '
    continuous = tmp_path / "continuous.urdf"
    continuous.write_text(_with_continuous(quadruped_urdf(), "hfe", limits))
    wide = tmp_path / "wide.urdf"
    wide.write_text(quadruped_urdf().replace(limits, 'lower="-100" upper="100" '))
    robots = [wb.load_robot({"name": p.stem, "model": str(p), "posture": posture,
                             "contacts": contacts}) for p in (continuous, wide)]
    assert robots[0].nq == robots[1].nq + 4  # the thighs' (cos, sin)
    for leg in LEGS:
        lifts = [foot_lift(r, leg) for r in robots]
        assert lifts[1] > 0.02
        assert lifts[0] == pytest.approx(lifts[1], abs=1e-6), leg
    changes = [slope_stance_change(r, np.radians(10.0)) for r in robots]
    assert np.isfinite(changes[1])
    assert changes[0] == pytest.approx(changes[1], abs=1e-6)


def _box_stl(path, centre, half, unit: float = 1.0) -> None:
    """A binary STL (as vendors ship them) of the box ``centre`` ± ``half`` (m), written in
    ``unit``s (1e-3: mm)."""
    import struct

    corners = [np.asarray(centre) + np.asarray(half) * np.array(s)
               for s in ((-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1),
                         (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1))]
    faces = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4),
             (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)]
    out = bytearray(b"box".ljust(80, b" ")) + struct.pack("<I", len(faces))
    for face in faces:
        a, b, c = (corners[i] / unit for i in face)
        out += struct.pack("<12fH", *np.cross(b - a, c - a), *a, *b, *c, 0)
    path.write_bytes(bytes(out))


def test_init_robot_reads_a_urdf_foot_mesh_as_the_same_box(tmp_path):
    """A foot whose collision is an STL mesh (in mm, ``scale`` 0.001, a path relative to the
    URDF) drafts the same contacts as the same box written as a URDF ``<box>``; a mesh that
    cannot be read is a point at the foot's frame, flagged."""
    from wholebody.robots.draft import draft_description

    centre, half = np.array([0.015, -0.004, -0.012]), np.array([0.03, 0.02, 0.008])
    sphere = '<collision><geometry><sphere radius="0.02"/></geometry></collision>'
    box = (f'<collision><origin xyz="{centre[0]} {centre[1]} {centre[2]}"/><geometry>'
           f'<box size="{2 * half[0]} {2 * half[1]} {2 * half[2]}"/></geometry></collision>')
    (tmp_path / "meshes").mkdir()
    _box_stl(tmp_path / "meshes" / "foot.stl", centre, half, unit=1e-3)
    mesh = ('<collision><geometry><mesh filename="meshes/foot.stl" scale="0.001 0.001 0.001"/>'
            '</geometry></collision>')
    drafts = {}
    for name, collision in (("box", box), ("mesh", mesh),
                            ("dae", mesh.replace("foot.stl", "foot.dae"))):
        path = tmp_path / f"{name}.urdf"
        path.write_text(quadruped_urdf().replace(sphere, collision))
        drafts[name] = draft_description(path)
    by_frame = {k: {c["frame"]: c for c in d.data["contacts"]} for k, d in drafts.items()}
    assert set(by_frame["mesh"]) == {f"{leg}_foot" for leg in LEGS}
    for frame, contact in by_frame["box"].items():
        mesh_contact = by_frame["mesh"][frame]
        assert mesh_contact["type"] == contact["type"]
        for key in ("radius", "half_size", "offset"):
            assert np.allclose(mesh_contact.get(key, 0.0), contact.get(key, 0.0), atol=1e-4), key
        assert np.linalg.norm(contact.get("offset", [0, 0, 0])) > 0.01  # the box's, not 0
    unread = by_frame["dae"]["lf_foot"]
    assert unread["type"] == "point" and unread["radius"] == 0 and "offset" not in unread
    assert any("could not be read" in n for n in drafts["dae"].notes)
    assert not any("could not be read" in n for n in drafts["mesh"].notes)
    # the same box tilted 0.4 rad about y with the joints at zero: its lowest points are an
    # edge, not a sole; drafted as a point at that edge, flagged
    tilted = tmp_path / "tilted.urdf"
    tilted.write_text(quadruped_urdf().replace(sphere, box.replace('"/><geometry>',
                                                                   '" rpy="0 0.4 0"/><geometry>')))
    draft = draft_description(tilted)
    assert any("form an edge" in n for n in draft.notes)
    assert all(c["type"] == "point" and c["radius"] == 0 for c in draft.data["contacts"])
