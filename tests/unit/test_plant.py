"""The vendor's MJCF as the simulated plant (wholebody.sim.plant).

A small hand-written quadruped: the controller's model from one MJCF, the plant from a second
file of the same robot that differs in known ways (a heavier trunk, joint damping, motors of gear
10, legs written in another order, a scene floor). The evidence is MuJoCo's own: the joint forces
its actuators produce (``qfrc_actuator``), the model's joint addresses, the floor's reaction."""

from pathlib import Path

import mujoco
import numpy as np
import pytest

from wholebody.cli import main
from wholebody.scenarios import get_scenario
from wholebody.robots import RobotDescription, load_robot
from wholebody.sim.plant import PlantError, build_plant, check_plant, plant_label, with_plant
from wholebody.sim.simulator import Simulator

LEGS = {"lf": (0.2, 0.1), "rf": (0.2, -0.1), "lh": (-0.2, 0.1), "rh": (-0.2, -0.1)}
POSTURE = {f"{leg}_{j}": a for leg in LEGS for j, a in (("hfe", 0.6), ("kfe", -1.2))}


def quad_mjcf(trunk_mass=6.0, damping=0.0, gear=1.0, order=tuple(LEGS), floor=False,
              extra_joint=False, servo=False, flip="", trunk_z=0.0) -> str:
    """The test quadruped as MJCF text; the keyword arguments change the plant's copy."""
    legs = []
    for leg in order:
        x, y = LEGS[leg]
        side = 0.05 if y > 0 else -0.05
        hfe_axis = "0 -1 0" if leg == flip else "0 1 0"
        legs.append(f"""
      <body name="{leg}_hip" pos="{x} {y} 0">
        <joint name="{leg}_haa" axis="1 0 0" range="-0.8 0.8"/>
        <inertial pos="0 0 0" mass="0.6" diaginertia="1e-3 1e-3 1e-3"/>
        <body name="{leg}_thigh" pos="0 {side} 0">
          <joint name="{leg}_hfe" axis="{hfe_axis}" range="-1.5 1.5"/>
          <inertial pos="0 0 -0.1" mass="0.9" diaginertia="8e-3 8e-3 1e-3"/>
          <geom type="capsule" fromto="0 0 -0.03 0 0 -0.17" size="0.015"/>
          <body name="{leg}_shank" pos="0 0 -0.2">
            <joint name="{leg}_kfe" axis="0 1 0" range="-2.5 -0.2"/>
            <inertial pos="0 0 -0.1" mass="0.3" diaginertia="3e-3 3e-3 2e-4"/>
            <geom name="{leg}_foot" type="sphere" size="0.02" pos="0 0 -0.2"/>
            <site name="{leg}_foot_site" pos="0 0 -0.2"/>
          </body>
        </body>
      </body>""")
    joints = [f"{leg}_{j}" for leg in order for j in ("haa", "hfe", "kfe")]
    if servo:
        actuators = "".join(f'<position joint="{j}" kp="50" forcerange="-30 30"/>' for j in joints)
    else:
        actuators = "".join(f'<motor name="m_{j}" joint="{j}" gear="{gear}" '
                            f'ctrlrange="{-30 / gear} {30 / gear}"/>' for j in joints)
    extra = ('<body name="tail" pos="-0.25 0 0"><joint name="tail_joint" axis="0 1 0"/>'
             '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/></body>'
             if extra_joint else "")
    return f"""<mujoco model="pquad">
  <compiler angle="radian" autolimits="true"/>
  <default><joint damping="{damping}" armature="0.01"/></default>
  <worldbody>
    {'<geom name="ground" type="plane" size="5 5 0.1"/>' if floor else ''}
    <body name="trunk" pos="0 0 0.4">
      <freejoint name="root"/>
      <inertial pos="0 0 {trunk_z}" mass="{trunk_mass}" diaginertia="0.05 0.15 0.17"/>
      <geom type="box" size="0.25 0.1 0.05"/>{''.join(legs)}{extra}
    </body>
  </worldbody>
  <actuator>{actuators}</actuator>
</mujoco>
"""


def quad_description(path: Path, **extra) -> dict:
    return {"name": "pquad", "model": str(path), "posture": dict(POSTURE),
            "contacts": [{"name": f"{leg}_foot", "frame": f"{leg}_foot_site", "type": "point",
                          "radius": 0.02} for leg in LEGS], **extra}


@pytest.fixture()
def controller(tmp_path):
    path = tmp_path / "controller.xml"
    path.write_text(quad_mjcf())
    return load_robot(quad_description(path))


def write(tmp_path, name="plant.xml", **kwargs) -> Path:
    path = tmp_path / name
    path.write_text(quad_mjcf(**kwargs))
    return path


def test_the_exact_twin_stays_the_default(controller):
    assert controller.description.plant is None
    assert plant_label(controller) == "exact twin"
    assert check_plant(controller) is None
    assert Simulator(controller).plant == "exact twin"


def test_joints_are_mapped_by_name_and_torques_go_through_geared_motors(controller, tmp_path):
    """Legs in another order and motors of gear 10: each commanded torque arrives on its own
    joint, as MuJoCo's actuator force (control x gear), not ten times larger or on another leg."""
    path = write(tmp_path, gear=10.0, order=("rh", "lh", "rf", "lf"), floor=True)
    sim = Simulator(with_plant(controller, path))
    assert sim.plant == f"vendor MJCF {path.resolve()}"
    m = sim.model
    for jid in range(2, controller.model.njoints):  # the plant's own joint addresses
        name = controller.model.names[jid]
        assert sim._qpos[5 + jid] == m.jnt_qposadr[m.joint(name).id]
    assert m.jnt_qposadr[m.joint("lf_haa").id] != 7  # the order really differs
    tau = np.linspace(-5.0, 6.0, controller.na)
    sim.step(tau)
    for i, name in enumerate(controller.joint_names):
        assert sim.data.qfrc_actuator[m.jnt_dofadr[m.joint(name).id]] == pytest.approx(tau[i])
    q, _ = sim.state()  # the state is read back in the controller's order
    assert np.allclose(q[7:], controller.q_ref[7:], atol=0.05)
    assert "ground" not in [m.geom(g).name for g in range(m.ngeom)]  # the file's floor removed


def test_servos_are_replaced_by_joint_motors(controller, tmp_path):
    sim = Simulator(with_plant(controller, write(tmp_path, servo=True)))
    assert any("position or velocity servo" in n for n in sim.twin.notes)
    tau = np.full(controller.na, 2.0)
    sim.step(tau)
    dofs = [sim.model.jnt_dofadr[sim.model.joint(n).id] for n in controller.joint_names]
    assert np.allclose(sim.data.qfrc_actuator[dofs], 2.0)  # no servo pulling toward 0


def test_the_plants_own_limits_bound_the_torque(controller, tmp_path):
    path = tmp_path / "weak.xml"
    path.write_text(quad_mjcf(gear=10.0).replace('ctrlrange="-3.0 3.0"', 'ctrlrange="-1 1"'))
    sim = Simulator(with_plant(controller, path))
    sim.step(np.full(controller.na, 25.0))
    assert np.allclose(sim.log.arrays()["tau_applied"][0], 10.0)  # 1 x gear 10, not 25


@pytest.mark.parametrize("kwargs, needle", [
    ({"extra_joint": True}, "joint(s) ['tail_joint'] the controller's model does not"),
    ({"flip": "lf"}, "joint 'lf_hfe' turns about a different axis"),
    ({"trunk_z": 0.0, "order": ("lf", "rf", "lh")}, "has no joint named ['rh_haa'"),
])
def test_mismatches_are_named(controller, tmp_path, kwargs, needle):
    with pytest.raises(PlantError) as err:
        build_plant(controller, write(tmp_path, **kwargs))
    assert needle in str(err.value)
    assert "plant = '" in str(err.value)


def test_the_description_field_and_bad_files(tmp_path):
    controller = tmp_path / "controller.xml"
    controller.write_text(quad_mjcf())
    write(tmp_path, trunk_mass=7.0)
    robot = load_robot(RobotDescription.from_dict(quad_description(controller, plant="plant.xml"),
                                                  base_dir=tmp_path))  # from its folder
    assert check_plant(robot).label == f"vendor MJCF {tmp_path / 'plant.xml'}"
    for plant, needle in (("nowhere.xml", "no such file"), (".", "not a file"),
                          ("controller.toml", "not an MJCF file")):
        (tmp_path / "controller.toml").write_text("name = 'x'\n")
        with pytest.raises(PlantError, match=needle) as err:
            check_plant(load_robot(RobotDescription.from_dict(
                quad_description(controller, plant=plant), base_dir=tmp_path)))
        assert str(err.value).startswith("robot 'pquad': plant = '")


def test_cli_refuses_a_bad_plant_before_running(tmp_path, capsys):
    controller = tmp_path / "controller.xml"
    controller.write_text(quad_mjcf())
    robot = tmp_path / "pquad.toml"
    robot.write_text(f"name = 'pquad'\nmodel = 'controller.xml'\nposture = {{ "
                     + ", ".join(f"{k} = {v}" for k, v in POSTURE.items()) + " }\ncontacts = ["
                     + ", ".join(f"{{ name = '{leg}_foot', frame = '{leg}_foot_site', type = "
                                 f"'point', radius = 0.02 }}" for leg in LEGS) + "]\n")
    extra = write(tmp_path, "extra.xml", extra_joint=True)
    for plant, needle in ((tmp_path / "none.xml", "no such file"),
                          (extra, "['tail_joint']")):
        code = main(["run", "stand", "--robot", str(robot), "--plant", str(plant),
                     "--out", str(tmp_path / "out"), "--no-progress"])
        err = capsys.readouterr().err
        assert code == 2
        assert f"--plant {plant}: " in err and needle in err
        assert not (tmp_path / "out" / "summary.json").exists()


GRAVITY = 9.81


@pytest.mark.slow
def test_a_heavier_plant_weighs_more_on_the_floor_and_sags(tmp_path):
    """The plant's trunk is 1.5 kg heavier (and its joints damped, its motors geared 10:1, its legs
    in another order): under the same controller the floor carries the plant's weight, not the
    controller's model's, and the joint PD lets the heavier body sit lower than the exact twin."""
    controller = tmp_path / "controller.xml"
    controller.write_text(quad_mjcf())
    plant = tmp_path / "plant.xml"
    plant.write_text(quad_mjcf(trunk_mass=7.5, damping=0.5, gear=10.0,
                               order=("rh", "lf", "lh", "rf"), floor=True))
    robot = load_robot(quad_description(controller))
    stand = get_scenario("stand")
    twin = stand.run(robot, overrides={"duration": "1.5"})
    vendor = stand.run(with_plant(robot, plant), overrides={"duration": "1.5"})
    assert twin.plant == "exact twin" and vendor.plant == f"vendor MJCF {plant.resolve()}"
    assert twin.success and not vendor.metrics["fell"]
    weight = {r.plant: sum(r.metrics["normal_force_mean_N"].values()) for r in (twin, vendor)}
    assert weight["exact twin"] == pytest.approx(robot.mass * GRAVITY, rel=0.02)
    assert weight[vendor.plant] == pytest.approx((robot.mass + 1.5) * GRAVITY, rel=0.02)
    assert vendor.metrics["base_height_min_m"] < twin.metrics["base_height_min_m"] - 1e-3
