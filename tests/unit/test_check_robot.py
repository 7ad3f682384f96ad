"""``wholebody check-robot``: every preset passes; each kind of problem is an error or a warning
that names the contact, joint or link, and exit code 2 for errors."""

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.cli import main
from wholebody.robots import preset_description, preset_names
from wholebody.robots.roles import leg_joints


def check(capsys, *args):
    code = main(["check-robot", *args])
    return code, capsys.readouterr().out


def check_text(capsys, *args):
    """(exit code, stdout, stderr) of the text report: errors go to stderr."""
    code = main(["check-robot", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def write(tmp_path, text, name="robot.toml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


HYQ = '''name = "myhyq"
urdf = "erd:hyq_description/robots/hyq_no_sensors.urdf"
srdf = "erd:hyq_description/srdf/hyq.srdf"
posture = "standing"
contacts = [
  {{ name = "a", frame = "lf_foot", type = "point", radius = 0.02175 }},
  {{ name = "b", frame = "rf_foot", type = "point", radius = 0.02175 }},
  {{ name = "c", frame = "lh_foot", type = "point", radius = 0.02175 }},
  {{ name = "d", frame = "{last}", type = "point", radius = 0.02175 }},
]
'''


@pytest.mark.parametrize("name", preset_names())
def test_every_preset_passes(capsys, name):
    code, out = check(capsys, name, "--json")
    report = json.loads(out)
    assert code == 0 and report["ok"], report["findings"]
    roles = {c["role"] for c in report["contacts"]}
    assert roles in ({"left-front", "right-front", "left-hind", "right-hind"}, {"left", "right"})
    assert all(c["touches_floor"] for c in report["contacts"])
    assert not [f for f in report["findings"] if f["topic"] == "roles"]  # names agree with roles
    # every preset humanoid shifts its CoG over either sole at its standing height within its
    # joint limits
    assert not [f for f in report["findings"] if f["topic"] == "single support"]


def test_a_lifted_contact_is_an_error(tmp_path, capsys):
    """A 'foot' on the knee frame: the check reports it above the floor by the knee's height,
    measured here from Pinocchio's kinematics at the preset's standing posture."""
    code, out = check(capsys, write(tmp_path, HYQ.format(last="rh_lowerleg")), "--json")
    report = json.loads(out)
    assert code == 2 and not report["ok"]
    robot = wb.load_robot("hyq")
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    knee = data.oMf[robot.model.getFrameId("rh_lowerleg")].translation[2] - 0.02175
    row = next(c for c in report["contacts"] if c["name"] == "d")
    assert row["height_above_floor_m"] == pytest.approx(knee, abs=1e-9)
    assert any(f["level"] == "error" and "'d'" in f["message"] for f in report["findings"])


def test_torque_limits_too_low_to_hold_the_posture(tmp_path, capsys):
    """At 1 % of HyQ's limits its knees cannot carry it (a quarter of 87 kg on a ~0.3 m lever
    needs tens of Nm)."""
    text = HYQ.format(last="rh_foot") + "[torque_limits]\nscale = 0.01\n"
    code, out, err = check_text(capsys, write(tmp_path, text))
    assert code == 2
    assert "holding the posture needs" in err and "_joint'" in err
    assert "error:" not in out and "holding the posture needs" not in out


def test_zero_inertia_names_the_link(tmp_path, capsys):
    """iCub's URDF in example-robot-data has a massive link with zero inertia (a known flaw)."""
    text = '''name = "icub"
urdf = "erd:icub_description/robots/icub_reduced.urdf"
srdf = "erd:icub_description/srdf/icub.srdf"
posture = "half_sitting"
contacts = [
  { name = "l", frame = "l_sole", type = "rectangle", half_size = [0.06, 0.03] },
  { name = "r", frame = "r_sole", type = "rectangle", half_size = [0.06, 0.03] },
]
'''
    code, out, err = check_text(capsys, write(tmp_path, text))
    assert code == 2
    assert "r_hip_pitch" in err and "inertia" in err


def test_placeholder_effort_limits_are_a_warning(tmp_path, capsys):
    solo = preset_description("solo12")
    contacts = ",\n".join(f'  {{ name = "{c.name}", frame = "{c.frame}", type = "point", '
                          f'radius = {c.radius} }}' for c in solo.contacts)
    text = (f'name = "solo_urdf_limits"\nurdf = "{solo.urdf}"\nsrdf = "{solo.srdf}"\n'
            f'posture = "standing"\ncontacts = [\n{contacts}\n]\n')
    code, out = check(capsys, write(tmp_path, text), "--json")
    report = json.loads(out)
    assert code == 0
    warnings = [f for f in report["findings"] if f["level"] == "warning"]
    assert any("placeholder" in f["message"] and "FL_KFE" in f["message"] for f in warnings)


def test_two_point_feet_report_no_support_polygon(tmp_path, capsys):
    """Bolt (a biped on two point feet) has no support area: the summary line says so instead of
    printing a 'nan mm' margin, and the support error is reported."""
    text = '''name = "bolt"
urdf = "erd:bolt_description/robots/bolt.urdf"
srdf = "erd:bolt_description/srdf/bolt.srdf"
posture = "standing"
contacts = [
  { name = "l", frame = "FL_FOOT", type = "point", radius = 0.0 },
  { name = "r", frame = "FR_FOOT", type = "point", radius = 0.0 },
]
[torque_limits]
scale = 0.0027
'''
    code, out, err = check_text(capsys, write(tmp_path, text))
    assert code == 2
    assert "no support polygon" in out and "nan" not in out + err
    assert "span no support area" in err


def test_unknown_robot_exits_2(capsys):
    code, out, err = check_text(capsys, "no-such-robot")
    assert code == 2 and "unknown robot" in err and out == ""
    assert err.rstrip().endswith("no-such-robot: 1 error(s) (above)")


def test_holding_torques_balance_the_robot(robots):
    """The torques check-robot compares with the limits hold the robot still: with them and the
    contact forces, the equations of motion give zero acceleration (M·0 + h = Sᵀτ + Jᵀλ)."""
    from wholebody.control.standing import gravity_compensation
    robot = robots["talos14"]
    robot.update(robot.q_ref, np.zeros(robot.nv))
    tau, lam = gravity_compensation(robot)
    J = robot.stacked_contact_jacobian()
    residual = robot.h - robot.joint_selection.T @ tau - J.T @ lam
    assert np.abs(residual).max() < 1e-8 * robot.mass * 9.81


def test_the_g1_walk_through_of_the_docs_loads_and_passes(tmp_path):
    """docs/robots.md's G1 file, as printed there: it loads, its soles get their roles and lie flat
    on the floor, and check-robot has nothing to warn about (armature given)."""
    import re
    from pathlib import Path

    from wholebody.robots.check import check_robot

    text = (Path(__file__).resolve().parents[2] / "docs" / "robots.md").read_text()
    section = text.split("## A robot without a preset", 1)[1]
    block = re.search(r"```toml\n(.*?)```", section, re.DOTALL).group(1)
    report = check_robot(write(tmp_path, block, "g1.toml"))
    assert report.ok and not [f for f in report.findings if f.level == "warning"], report.findings
    assert {c["role"] for c in report.contacts} == {"left", "right"}
    assert all(c["touches_floor"] for c in report.contacts)


@pytest.mark.parametrize("command", [["run", "stand"], ["sweep", "stand", "--grid", "duration=1,2"]])
def test_run_and_sweep_refuse_what_check_robot_rejects(tmp_path, capsys, monkeypatch, command):
    """A robot that cannot stand (limits at 1 % of HyQ's) is refused by `run` and `sweep` with
    check-robot's error and exit 2, before anything is simulated."""
    from wholebody.scenarios.base import Scenario

    monkeypatch.setattr(Scenario, "run", lambda *a, **k: pytest.fail("simulated an unfit robot"))
    path = write(tmp_path, HYQ.format(last="rh_foot") + "[torque_limits]\nscale = 0.01\n")
    code = main([*command, "--robot", path, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "holding the posture needs" in err and "check-robot" in err
    assert not (tmp_path / "out").exists()


def test_two_joint_legs_are_a_warning():
    """ODRI's 8-DoF Solo (hip and knee flexion only): each stance foot's lateral row depends on the
    base alone, so four feet give four lateral rows of rank 3 (checked here on the stacked contact
    Jacobian from Pinocchio); check-robot warns what this means for the walking scenarios."""
    from wholebody.robots.check import check_robot

    from conftest import solo8_description

    description = solo8_description()
    robot = wb.load_robot(description)
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, robot.q_ref)
    pin.updateFramePlacements(robot.model, data)
    J = np.vstack([pin.getFrameJacobian(robot.model, data, c.frame_id,
                                        pin.LOCAL_WORLD_ALIGNED)[:3] for c in robot.contacts])
    assert np.linalg.matrix_rank(J, tol=1e-9) < 12
    report = check_robot(description)
    (finding,) = [f for f in report.findings if "fewer than 3 moving joints" in f.message]
    assert finding.level == "warning" and report.ok
    assert not [f for f in check_robot("solo12").findings if "fewer than 3" in f.message]
    # the scenarios refuse the trot before simulating, and let it crawl
    from wholebody.scenarios.locomotion import check_quadruped
    with pytest.raises(ValueError, match="a trot needs legs of at least 3 moving joints.*FL_HFE, "
                                         "FL_KFE.*--set gait=crawl"):
        check_quadruped(robot, "the ramp scenario", "trot")
    check_quadruped(robot, "the crawl scenario", "crawl")
    from wholebody.scenarios import crawl
    for engine in ("auto", "native", "python"):
        crawl.validate(robot, {"gait": "crawl", "engine": engine, "duration": 12.0})


def test_joints_with_equal_limits_do_not_count_as_leg_joints():
    """TSID's toy quadruped: each leg a hip and a knee whose limits are [0, 0] (URDF), i.e. one
    joint that moves: the crawl refuses it, naming the hips."""
    from wholebody.robots.roles import leg_joints, moving_leg_joints
    from wholebody.scenarios.locomotion import check_quadruped

    robot = wb.load_robot({
        "name": "toy", "urdf": "erd:quadruped_description/urdf/quadruped.urdf",
        "contacts": [{"name": n, "frame": f"{n}_contact", "type": "point", "radius": 0.0,
                      "role": r} for n, r in (("FL", "left-front"), ("FR", "right-front"),
                                              ("BL", "left-hind"), ("BR", "right-hind"))],
        "posture": {"FL_HFE": 0.0}})
    knee = robot.joint_names.index("FL_KFE")
    assert robot.q_min[knee] == robot.q_max[knee]
    assert leg_joints(robot, "FL") == ("FL_HFE", "FL_KFE")
    assert moving_leg_joints(robot, "FL") == ("FL_HFE",)
    with pytest.raises(ValueError, match="a crawl needs legs of at least 2 moving joints.*FL: FL_HFE"):
        check_quadruped(robot, "the crawl scenario", "crawl")


SWAPPED = """name = "swapped"
urdf = "erd:hyq_description/robots/hyq_no_sensors.urdf"
srdf = "erd:hyq_description/srdf/hyq.srdf"
posture = "standing"
contacts = [
  {{ name = "RF_FOOT", frame = "lf_foot", type = "point", radius = 0.02175{a} }},
  {{ name = "LF_FOOT", frame = "rf_foot", type = "point", radius = 0.02175{b} }},
  {{ name = "LH_FOOT", frame = "lh_foot", type = "point", radius = 0.02175{c} }},
  {{ name = "RH_FOOT", frame = "rh_foot", type = "point", radius = 0.02175{d} }},
]
"""


def test_a_name_that_contradicts_the_role_is_a_warning(tmp_path, capsys):
    """HyQ's front feet given each other's names: found from the geometry, LF_FOOT (on HyQ's
    right-front foot frame) is the right-front foot, so both front feet are flagged, with the
    way out; declared roles that contradict the names are flagged too; a warning, not an error."""
    path = write(tmp_path, SWAPPED.format(a="", b="", c="", d=""))
    code, out = check(capsys, path, "--json")
    report = json.loads(out)
    flagged = [f for f in report["findings"] if f["topic"] == "roles"]
    assert code == 0 and report["ok"]
    assert {f["level"] for f in flagged} == {"warning"} and len(flagged) == 2
    assert any("'LF_FOOT' is named like the left-front foot but is the right-front" in f["message"]
               for f in flagged)
    assert all("declare role" in f["fix"] for f in flagged)
    roles = [', role = "left-front"', ', role = "right-front"', ', role = "left-hind"',
             ', role = "right-hind"']
    path = write(tmp_path, SWAPPED.format(a=roles[0], b=roles[1], c=roles[2], d=roles[3]),
                 "declared.toml")
    code, out = check(capsys, path, "--json")
    flagged = [f for f in json.loads(out)["findings"] if f["topic"] == "roles"]
    assert code == 0 and len(flagged) == 2 and "declared role" in flagged[0]["message"]


@pytest.mark.parametrize("name, kind, role", [
    ("LF_FOOT", "point", "left-front"), ("rh_foot", "point", "right-hind"),
    ("FR_foot", "point", "right-front"), ("RL_calf", "point", "left-hind"),
    ("BL", "point", "left-hind"), ("front_left_foot", "point", "left-front"),
    ("foot_3", "point", None), ("l_sole", "rectangle", "left"),
    ("leg_right_6_link", "rectangle", "right"), ("sole", "rectangle", None)])
def test_role_in_name(name, kind, role):
    from wholebody.robots.roles import role_in_name
    assert role_in_name(name, kind) == role


@pytest.mark.slow
def test_a_biped_whose_shift_needs_a_lower_cog_gets_a_note():
    """iCub's swing hip abduction ends before its pelvis is over either sole at the standing CoG
    height (tests/unit/test_support_shift.py): check-robot says so for both soles, with a drop
    at which a pose inside the limits exists, and still passes."""
    from conftest import ICUB_RIGHT_LEG_INERTIAS, icub_description
    from wholebody.planning.support_shift import KEY_POSE_TOLERANCE, key_pose
    from wholebody.robots.check import check_robot

    description = icub_description(inertia_overrides=ICUB_RIGHT_LEG_INERTIAS)
    report = check_robot(description)
    notes = [f.message for f in report.findings if f.topic == "single support"]
    assert report.ok and len(notes) == 2, report.findings
    robot = wb.load_robot(description)
    for note, (stance, swing) in zip(notes, (robot.contact_names, robot.contact_names[::-1])):
        assert note.startswith(f"over {stance},")
        drop = float(note.split(" mm lower")[0].rsplit(" ", 1)[1]) / 1e3
        assert key_pose(robot, stance, swing, drop)[1] <= 2 * KEY_POSE_TOLERANCE
        assert key_pose(robot, stance, swing, 0.0)[1] > KEY_POSE_TOLERANCE


def test_a_sphere_as_large_as_a_wheel_gets_a_note():
    """IIT Centauro's wheels described as spheres of their 0.119 m radius (15 % of its standing
    height, from the posture's own kinematics here) get a note each, and the check passes; the
    feet of the quadruped presets (spheres of 2-3 cm) get none."""
    from conftest import centauro_description
    from wholebody.robots.check import WHEEL_RADIUS_FRACTION, check_robot

    description = centauro_description()
    report = check_robot(description)
    notes = [f for f in report.findings if f.topic == "contacts" and "rolls" in f.message]
    assert report.ok and len(notes) == 4, report.findings
    robot = wb.load_robot(description)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    lowest = min(data.oMf[c.frame_id].translation[2] - 0.119 for c in robot.contacts)
    assert 0.119 > WHEEL_RADIUS_FRACTION * (robot.q_ref[2] - lowest)
    for preset in ("hyq", "anymal_c", "go1", "solo12"):
        assert not [f for f in check_robot(preset).findings if "rolls" in f.message], preset


def test_leg_joints_that_do_not_move_their_foot_get_a_note():
    """Centauro's ankle yaws turn each wheel (a sphere) about its centre: the note lists exactly
    the leg joints that, turned by 0.01 rad in the posture (forward kinematics), move their foot's
    centre by less than a micrometre; the presets' legs have none."""
    from conftest import centauro_description
    from wholebody.robots.check import check_robot

    description = centauro_description()
    report = check_robot(description)
    notes = [f for f in report.findings if "about the sphere's centre" in f.message]
    assert report.ok and len(notes) == 1
    listed = set(notes[0].message.split("joint(s) ")[1].split(" turn")[0].split(", "))
    robot = wb.load_robot(description)
    data = robot.model.createData()
    idle = set()
    for c in robot.contacts:
        for joint in leg_joints(robot, c.name):
            q = robot.q_ref.copy()
            pin.framesForwardKinematics(robot.model, data, q)
            before = data.oMf[c.frame_id].translation.copy()
            q[7 + robot.joint_names.index(joint)] += 0.01
            pin.framesForwardKinematics(robot.model, data, q)
            if np.linalg.norm(data.oMf[c.frame_id].translation - before) < 1e-6:
                idle.add(joint)
    assert listed == idle and len(idle) == 4
    for preset in ("hyq", "anymal_c", "go1", "solo12"):
        assert not [f for f in check_robot(preset).findings
                    if "about the sphere's centre" in f.message], preset


def test_a_quadrupeds_reach_and_ramp_attitude_are_reported():
    """The legs' lift (what caps a swing) and the ramp's trunk attitude, as the planner will use
    them: Centauro lifts its feet less than HyQ's clearance in proportion to its height and
    stands a slope with a level trunk; HyQ keeps the paper's parallel one; legs of two joints
    (no trot, so no ramp) get the lift only."""
    from conftest import centauro_description, solo8_description
    from wholebody.planning.reach import foot_lift
    from wholebody.robots.check import check_robot
    from wholebody.scenarios.locomotion import gait_options

    for description, attitude, capped in ((centauro_description(), "level", True),
                                          ("hyq", "parallel", False)):
        report = check_robot(description)
        notes = [f.message for f in report.findings if f.topic == "legs"]
        assert len(notes) == 2 and notes[1].endswith(f"the ramp takes it {attitude}"), notes
        robot = wb.load_robot(description)
        lifts = [foot_lift(robot, c) for c in robot.contact_names]
        assert report.facts["foot_lift_m"] == pytest.approx(lifts)
        clearance = gait_options(robot)["clearance"]
        assert (max(lifts) < clearance) if capped else (min(lifts) > clearance)
    notes = [f for f in check_robot(solo8_description()).findings if f.topic == "legs"]
    assert len(notes) == 1 and "rises at most" in notes[0].message


def test_walking_torque_on_one_sole_is_the_static_equilibrium(robots):
    """check-robot's walking check: romeo's weak joints (38 Nm knees, 47 Nm hip rolls) need
    more than the warning's share of their limits to stand still on one sole at its walking
    height, talos14's far less. The torque is checked against the static equilibrium solved as one least-squares
    system over (torques, the sole's wrench): S^T tau + J^T f = g(q)."""
    from wholebody.control.walking import WalkingConfig
    from wholebody.planning.support_shift import shift_key_pose
    from conftest import one_sole_holding_torques
    from wholebody.robots.check import WALKING_TORQUE_SHARE, check_robot

    for name, warned in (("romeo", True), ("talos14", False)):
        robot = robots[name]
        report = check_robot(name)
        walking = [f for f in report.findings if f.topic == "walking" and f.level == "warning"]
        assert bool(walking) == warned, report.findings
        share = report.facts["walking_single_support_torque_max_fraction_of_limit"]
        assert (share > WALKING_TORQUE_SHARE) == warned
        stance, swing = robot.contact_names
        _, q, _ = shift_key_pose(robot, stance, swing, WalkingConfig.for_robot(robot).com_drop)
        tau = one_sole_holding_torques(robot, q, stance)
        lo, hi = robot.torque_bounds(q)
        oracle = float(np.max(np.maximum(tau / hi, tau / lo)))
        # the worse of the two soles is reported; these robots are symmetric
        assert oracle == pytest.approx(share, rel=0.02)
    robots["romeo"].update(robots["romeo"].q_ref, np.zeros(robots["romeo"].nv))
    robots["talos14"].update(robots["talos14"].q_ref, np.zeros(robots["talos14"].nv))


def test_five_joint_legs_are_named_with_what_they_cannot_do(tmp_path, capsys):
    """talos14 with its ankle rolls locked has five-joint legs: check-robot says each sole cannot
    roll relative to the trunk and what that means; talos14 itself (six joints) gets no such
    warning. Independent evidence: the rank of the locked leg's Jacobian is 5 (Pinocchio)."""
    from conftest import talos14_five_joint_toml

    path = write(tmp_path, talos14_five_joint_toml())
    code, out = check(capsys, path, "--json")
    legs = [f for f in json.loads(out)["findings"] if f["topic"] == "legs"]
    assert code == 0 and len(legs) == 2
    assert all("in 5 of 6 directions" in f["message"] and "no ankle roll" in f["message"]
               and "lateral CoP" in f["message"] for f in legs)
    robot = wb.robots.load_robot(path)
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, robot.q_ref)
    c = robot.contacts[0]
    J = pin.getFrameJacobian(robot.model, data, c.frame_id, pin.LOCAL)
    assert np.linalg.matrix_rank(J[:, [6 + robot.joint_names.index(j)
                                       for j in leg_joints(robot, c.name)]]) == 5
    code, out = check(capsys, "talos14", "--json")
    assert not [f for f in json.loads(out)["findings"] if f["topic"] == "legs"]
