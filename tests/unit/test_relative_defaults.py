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
