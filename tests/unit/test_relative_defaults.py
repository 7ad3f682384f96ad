"""Robot-relative parameter defaults: lengths of the paper's HyQ set-ups keep their proportion to
the standing height on any robot, HyQ keeps the paper's numbers, and ``--set`` still takes
metres."""

import json

import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.cli import main
from wholebody.scenarios import get_scenario

# Fahmi et al. 2019, Sect. V-F/V-G: a 22 cm gap with a 7 cm step; our stone: 6 cm deep, 20 cm wide
PAPER_HYQ = {("ramp", "gap"): 0.22, ("ramp", "step"): 0.07,
             ("unstable-foothold", "depth"): 0.06, ("unstable-foothold", "size"): 0.2}


@pytest.fixture(scope="module")
def quadrupeds():
    return {n: wb.load_robot(n) for n in ("hyq", "go1", "solo12")}


@pytest.mark.parametrize("scenario, name", sorted(PAPER_HYQ))
def test_hyq_keeps_the_papers_lengths_and_others_their_proportion(quadrupeds, scenario, name):
    values = {n: get_scenario(scenario).validate(r, {})[name] for n, r in quadrupeds.items()}
    assert values["hyq"] == PAPER_HYQ[(scenario, name)]
    # the standing base height, measured here as the base above the lowest foot point
    heights = {}
    for n, r in quadrupeds.items():
        data = r.model.createData()
        pin.framesForwardKinematics(r.model, data, r.q_ref)
        lowest = min(data.oMf[c.frame_id].translation[2] - c.spec.radius for c in r.contacts)
        heights[n] = r.q_ref[2] - lowest
    for n in ("go1", "solo12"):
        assert values[n] / heights[n] == pytest.approx(values["hyq"] / heights["hyq"], rel=1e-12)


def test_set_still_takes_metres(quadrupeds):
    assert get_scenario("ramp").validate(quadrupeds["go1"], {"gap": "0.1"})["gap"] == 0.1


def test_listing_shows_relative_defaults(capsys):
    assert main(["scenarios", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    gap = listed["ramp"]["parameters"]["gap"]
    assert gap["default"]["base_height"] == pytest.approx(0.22 / wb.load_robot("hyq").q_ref[2])
    assert main(["scenarios"]) == 0
    assert "--set gap=0.367" in capsys.readouterr().out


def test_leg_stretch_is_the_law_of_cosines_on_talos14():
    """talos14's legs are planar chains in the posture (hip roll and yaw at zero): thigh and
    shin, the knee's and the ankle's joint offsets in the model, bent by the knee's angle. The
    hip-to-ankle distance grows from sqrt(a² + b² + 2ab cos k) to a + b when the leg is straight;
    that is its stretch, and the reference constant is talos14's."""
    import numpy as np

    from wholebody.robots.reference import HUMANOID_LEG_STRETCH, leg_stretch
    from wholebody.robots.roles import leg_joints

    robot = wb.load_robot("talos14")
    model = robot.model
    stretch = []
    for contact in robot.contact_names:
        joints = [model.getJointId(j) for j in leg_joints(robot, contact)]
        lengths = [np.linalg.norm(model.jointPlacements[j].translation) for j in joints[1:]]
        a, b = sorted(lengths)[-2:]  # the two long links: thigh and shin
        bent = [abs(robot.q_ref[model.joints[j].idx_q]) for j in joints]
        k = max(bent)  # the knee: the most bent joint of a standing leg
        stretch.append(a + b - np.sqrt(a * a + b * b + 2 * a * b * np.cos(k)))
    assert leg_stretch(robot) == pytest.approx(min(stretch), abs=1e-9)
    assert HUMANOID_LEG_STRETCH == pytest.approx(leg_stretch(robot), rel=1e-12)


def test_squat_amplitudes_keep_the_papers_on_talos14_and_scale_elsewhere():
    """The squat's 2 cm forward and 3 cm vertical are talos14's; on romeo the forward one scales
    with the standing height and the vertical one with how far the legs can stretch."""
    from wholebody.robots.reference import leg_stretch

    talos14, romeo = wb.load_robot("talos14"), wb.load_robot("romeo")
    ref = get_scenario("squat").validate(talos14, {})
    assert (ref["amplitude_x"], ref["amplitude_z"]) == (0.02, 0.03)
    p = get_scenario("squat").validate(romeo, {})
    assert p["amplitude_x"] == pytest.approx(0.02 * romeo.q_ref[2] / talos14.q_ref[2], rel=1e-12)
    assert p["amplitude_z"] == pytest.approx(0.03 * leg_stretch(romeo) / leg_stretch(talos14),
                                             rel=1e-12)
    assert p["amplitude_z"] < leg_stretch(romeo)


def test_push_default_is_talos14s_velocity_change():
    """push's default 100 N (0.1 s half-sine) and the angle-mode push height 0.1 m are talos14's;
    on romeo the force gives the same velocity change (impulse over mass, 2 F T / pi / m) and the
    height the same proportion of the standing height."""
    import math

    talos14, romeo = wb.load_robot("talos14"), wb.load_robot("romeo")
    ref = get_scenario("push").validate(talos14, {})
    p = get_scenario("push").validate(romeo, {})
    assert (ref["peak_force"], ref["height"]) == (100.0, 0.1)
    dv = {name: 2 * q["peak_force"] * q["push_duration"] / math.pi / robot.mass
          for name, q, robot in (("talos14", ref, talos14), ("romeo", p, romeo))}
    assert dv["romeo"] == pytest.approx(dv["talos14"], rel=1e-12)
    assert p["height"] == pytest.approx(0.1 * romeo.q_ref[2] / talos14.q_ref[2], rel=1e-12)


def test_push_series_forces_are_talos14s_velocity_changes():
    """push-series' default forces 60, 100, 140, 180 N are talos14's; on romeo each gives the same
    velocity change (times its mass over talos14's), still increasing."""
    talos14, romeo = wb.load_robot("talos14"), wb.load_robot("romeo")
    ref = get_scenario("push-series").validate(talos14, {})["forces"]
    scaled = get_scenario("push-series").validate(romeo, {})["forces"]
    assert [float(f) for f in ref.split(",")] == [60.0, 100.0, 140.0, 180.0]
    expected = [f * romeo.mass / talos14.mass for f in (60.0, 100.0, 140.0, 180.0)]
    assert [float(f) for f in scaled.split(",")] == pytest.approx(expected, rel=1e-3)


def test_stepping_lift_is_the_papers_on_talos_and_in_proportion_elsewhere():
    """Table 1's 3 cm lift and the 3 mm touchdown depth on talos (and talos14, the same legs);
    on romeo the same share of its standing height."""
    talos, talos14, romeo = (wb.load_robot(n) for n in ("talos", "talos14", "romeo"))
    for robot in (talos, talos14):
        params = get_scenario("stepping").validate(robot, {})
        assert (params["lift"], params["touchdown_depth"]) == (0.03, 0.003)
    params = get_scenario("stepping").validate(romeo, {})
    ratio = romeo.q_ref[2] / talos14.q_ref[2]
    assert params["lift"] == pytest.approx(0.03 * ratio, rel=1e-12)
    assert params["touchdown_depth"] == pytest.approx(0.003 * ratio, rel=1e-12)
