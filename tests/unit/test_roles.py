"""Contact roles (which foot is the left-front one) and leg joint chains, declared or found from the
geometry. The evidence: the robots' own names, which encode the answer (hyq's ``lf_foot``, Unitree's
``FL_foot``, Talos' ``left_sole``), and the URDF's kinematic tree read with Pinocchio's parents."""

import pytest

import wholebody as wb
from wholebody.robots import DescriptionError, preset_description
from wholebody.robots.roles import (biped_soles, contact_roles, foot_of_joint, leg_joints,
                                    quadruped_legs)
from wholebody.scenarios import get_scenario
from wholebody.scenarios.locomotion import make_schedule


def hyq_with(contacts):
    d = preset_description("hyq")
    return wb.load_robot({"name": "hyq-roles", "urdf": d.urdf, "srdf": d.srdf,
                          "posture": d.posture, "contacts": contacts})


def point(name, frame, **extra):
    return {"name": name, "frame": frame, "type": "point", "radius": 0.02, **extra}


@pytest.mark.parametrize("name, expected", [
    ("hyq", ("lf_foot", "rf_foot", "lh_foot", "rh_foot")),
    ("go1", ("FL_foot", "FR_foot", "RL_foot", "RR_foot")),
    ("solo12", ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")),
])
def test_quadruped_feet_found_from_their_positions(name, expected):
    assert quadruped_legs(wb.load_robot(name)) == expected


def test_biped_soles_found_from_their_positions(robots):
    assert biped_soles(robots["talos14"]) == ("left_sole", "right_sole")


def test_declared_roles_win_over_the_geometry():
    """A description that declares the left feet as the right ones is taken at its word."""
    swap = {"lf_foot": "right-front", "rf_foot": "left-front", "lh_foot": "right-hind",
            "rh_foot": "left-hind"}
    robot = hyq_with([point(f"foot{i}", frame, role=swap[frame])
                      for i, frame in enumerate(("lf_foot", "rf_foot", "lh_foot", "rh_foot"))])
    roles = contact_roles(robot)
    assert roles["left-front"] == "foot1" and roles["right-front"] == "foot0"
    assert quadruped_legs(robot) == ("foot1", "foot0", "foot3", "foot2")


def test_ambiguous_geometry_asks_for_roles():
    """Four contacts all on the left side: the geometry cannot tell which is which."""
    robot = hyq_with([point("a", "lf_foot"), point("b", "lh_foot"), point("c", "lf_lowerleg"),
                      point("d", "lh_lowerleg")])
    with pytest.raises(DescriptionError, match="declare role"):
        contact_roles(robot)


@pytest.mark.parametrize("contacts, match", [
    ([point("a", "lf_foot", role="front-left")], "contacts\\[0\\].role"),
    ([point("a", "lf_foot", role="left-front"), point("b", "rf_foot", role="left-front")],
     "more than one"),
])
def test_bad_roles_are_refused_at_load(contacts, match):
    with pytest.raises(DescriptionError, match=match):
        hyq_with(contacts)


def test_some_roles_declared_is_an_error():
    robot = hyq_with([point("a", "lf_foot", role="left-front"), point("b", "rf_foot"),
                      point("c", "lh_foot"), point("d", "rh_foot")])
    with pytest.raises(DescriptionError, match="on every contact or on none"):
        contact_roles(robot)


def test_not_a_quadruped_is_a_clear_error(robots):
    with pytest.raises(ValueError, match="four point-foot contacts"):
        quadruped_legs(robots["talos14"])


def test_leg_joints_follow_the_kinematic_tree(robots):
    hyq = wb.load_robot("hyq")
    assert leg_joints(hyq, "lh_foot") == ("lh_haa_joint", "lh_hfe_joint", "lh_kfe_joint")
    talos = robots["talos14"]
    chain = leg_joints(talos, "right_sole")
    assert chain == tuple(f"leg_right_{k}_joint" for k in range(1, 7))
    # each joint's parent in the model is the previous one
    ids = [talos.model.getJointId(j) for j in chain]
    assert all(talos.model.parents[b] == a for a, b in zip(ids, ids[1:]))
    assert foot_of_joint(talos, "leg_left_4_joint") == "left_sole"
    assert foot_of_joint(talos, "torso_1_joint") is None


def test_quadruped_scenarios_address_feet_by_role():
    """go1's own contact names work in the gait schedule and the joint choices of the scenarios."""
    go1 = wb.load_robot("go1")
    schedule = make_schedule(go1, "crawl", 1.0)
    assert tuple(schedule.legs) == ("FL_foot", "FR_foot", "RL_foot", "RR_foot")
    from wholebody.scenarios.joint_limit import limited_joint
    from wholebody.scenarios.weak_joint import weak_leg, weakened_joint
    assert weakened_joint(go1, "") == "FL_calf_joint"
    assert weak_leg(go1, "FL_calf_joint") == (
        ("FL_hip_joint", "FL_thigh_joint", "FL_calf_joint"), "FL_foot")
    assert limited_joint(go1, "") == "RL_thigh_joint"
    for name in ("weak-joint", "regularization", "crawl"):
        get_scenario(name).validate(go1, {})  # no robot names needed
    get_scenario("joint-limit").validate(go1, {"limit": "0.0"})  # -0.85 rad is outside go1's


def test_pitch_joints_are_the_lateral_axes_of_the_urdf(robots):
    """The flexion joints of a leg, read independently from the URDF's <axis> elements: those
    along y (Talos' legs are built with the base frame's axes in the posture)."""
    import xml.etree.ElementTree as ET

    from wholebody.robots.locate import resolve_model_path
    from wholebody.robots.roles import pitch_joints

    robot = robots["talos14"]
    urdf = ET.parse(resolve_model_path(robot.description.urdf, robot.description.base_dir))
    axes = {j.get("name"): [float(x) for x in j.find("axis").get("xyz").split()]
            for j in urdf.getroot().iter("joint") if j.find("axis") is not None}
    for sole in ("left_sole", "right_sole"):
        expected = tuple((j, float(axes[j][1])) for j in leg_joints(robot, sole)
                         if abs(axes[j][1]) > 0.9)
        assert pitch_joints(robot, sole) == expected and len(expected) == 3


def test_single_support_picks_the_swing_legs_hip_and_knee(robots):
    from wholebody.scenarios.single_support import config
    robot = robots["talos14"]
    scenario = get_scenario("single-support")
    cfg = config(robot, scenario.validate(robot, {}))  # stance: the left sole
    assert cfg.sine_joints == ("leg_right_3_joint", "leg_right_4_joint")
    assert cfg.held_joints == tuple(f"leg_right_{k}_joint" for k in range(1, 7))
    cfg = config(robot, scenario.validate(robot, {"stance": "right"}))
    assert cfg.sine_joints == ("leg_left_3_joint", "leg_left_4_joint")
    with pytest.raises(ValueError, match="lateral-axis joints"):
        scenario.validate(robot, {"sine_joints": "leg_right_1_joint,leg_right_4_joint"})
