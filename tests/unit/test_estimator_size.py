"""The filter's leg terms follow the robot's size: EstimatorNoise.for_robot scales the two lengths
(kinematics_noise, stance_foot_walk) by the standing height against the reference robot of the
kind (HyQ for point feet, talos14 for soles), and leaves every other term as for_sensors gives it."""

from dataclasses import fields

import pytest

import wholebody as wb
from wholebody.estimation import EstimatorNoise
from wholebody.sim.sensors import SensorSpec

LENGTHS = ("kinematics_noise", "stance_foot_walk")


@pytest.mark.parametrize("name, reference", [("go1", "hyq"), ("solo12", "hyq"),
                                             ("hyq", "hyq"), ("talos14", "talos14"),
                                             ("romeo", "talos14")])
def test_leg_noise_in_proportion_to_the_standing_height(name, reference):
    robot, ref = wb.load_robot(name), wb.load_robot(reference)
    ratio = float(robot.q_ref[2]) / float(ref.q_ref[2])
    spec = SensorSpec()
    plain, scaled = EstimatorNoise.for_sensors(spec), EstimatorNoise.for_robot(robot, spec)
    for f in fields(EstimatorNoise):
        expected = getattr(plain, f.name) * (ratio if f.name in LENGTHS else 1.0)
        assert getattr(scaled, f.name) == pytest.approx(expected, rel=1e-12), f.name
    if name == reference:  # the robots the defaults were set on keep them to the bit
        assert scaled == plain


def test_an_override_wins_over_the_scaling():
    go1 = wb.load_robot("go1")
    noise = EstimatorNoise.for_robot(go1, SensorSpec(), kinematics_noise=5e-3)
    assert noise.kinematics_noise == 5e-3
    assert noise.stance_foot_walk < EstimatorNoise().stance_foot_walk
