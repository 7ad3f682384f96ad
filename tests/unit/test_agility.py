"""The ``agility`` scenario and the agility table of ``wholebody report``, without simulating:
the parts' parameters (the top speed from the Froude number), the checks before any run, the
verdicts from a part's metrics, and the table by robot written into the docs."""

from __future__ import annotations

import math

import pytest

from wholebody.report import claims as C
from wholebody.report import runner
from wholebody.scenarios import get_scenario
from wholebody.scenarios.agility import PARTS, froude_speed, part_overrides

AGILITY = get_scenario("agility")


def test_the_top_speed_is_the_froude_number_on_the_base_height(robots):
    """v = sqrt(Fr g h): Froude 0.5 on HyQ's 0.599 m is the 1.71 m/s of the issue's target."""
    hyq = robots["hyq"]
    assert froude_speed(hyq, 0.5) == pytest.approx(math.sqrt(0.5 * 9.81 * hyq.q_ref[2]))
    assert froude_speed(hyq, 0.5) == pytest.approx(1.71, abs=0.01)
    params = AGILITY.validate(hyq, {"froude": "0.3"})
    assert float(part_overrides("top-speed", hyq, params)["speed_end"]) == pytest.approx(
        math.sqrt(0.3 * 9.81 * hyq.q_ref[2]), rel=1e-3)


def test_parts_pass_the_realism_level_down(robots):
    params = AGILITY.validate(robots["anymal_c"], {"realism": "robot"})
    for name in PARTS:
        overrides = part_overrides(name, robots["anymal_c"], params)
        assert overrides["realism"] == "robot" and overrides["ground_map"] == "true"
        get_scenario(PARTS[name][0]).validate(robots["anymal_c"], overrides)
    exact = AGILITY.validate(robots["anymal_c"], {})
    assert "realism" not in part_overrides("steer", robots["anymal_c"], exact)


def test_checked_before_simulating(robots, monkeypatch):
    with pytest.raises(ValueError, match="quadrupeds"):
        AGILITY.validate(robots["talos14"], {})
    with pytest.raises(ValueError, match="parts"):
        AGILITY.validate(robots["hyq"], {"parts": "top-speed,moonwalk"})
    # a part's own scenario refuses its parameters: named with the part
    monkeypatch.setitem(PARTS, "stairs-trot", ("ramp", "passive", {"course": "stairs",
                                                                   "steps": "0"}))
    with pytest.raises(ValueError, match="part 'stairs-trot' .ramp.: .*steps"):
        AGILITY.validate(robots["hyq"], {})


# ---------------------------------------------------------------- verdicts
def _summary(part: str, met: bool, metrics: dict) -> dict:
    return {"success": met, "metrics": {"top_speed_mps": 1.714, "parts": {
        part: {"met": met, "success": met, "command": "wholebody run x", "metrics": metrics}}}}


def _claim(part: str, robot: str = "hyq") -> C.Claim:
    return next(c for c in C.AGILITY if c.id == f"{part}-{robot}")


def test_agility_verdicts_read_the_part_as_the_scenario_judged_it():
    fast = {"passive": {"fell": False, "failed_cycles": 0, "hold_velocity_error_share": 0.0074,
                        "max_stance_slip_m": 0.057}}
    ours, verdict = _claim("top-speed").evaluate(_summary("top-speed", True, fast))
    assert verdict == C.MET and "1.71 m/s reached" in ours and "0.7 %" in ours
    fell = {"passive": {"fell": True, "fell_at_s": 8.6, "failed_cycles": 3}}
    ours, verdict = _claim("top-speed").evaluate(_summary("top-speed", False, fell))
    assert verdict == C.MISSED and "fell at 8.6 s" in ours
    stairs = {"fell": True, "fell_at_s": 36.8, "failed_cycles": 40}
    assert _claim("stairs-trot").evaluate(_summary("stairs-trot", False, stairs)) == \
        ("fell at 36.8 s", C.MISSED)
    push = {"angles": {"90": {"dv_mps": 0.3, "survived": True},
                       "270": {"dv_mps": 0.3, "survived": False, "failed_cycles": 8}}}
    ours, verdict = _claim("push").evaluate(_summary("push", False, push))
    assert verdict == C.MISSED and ours == "Δv 0.30 m/s: left trotted on, right 8 failed cycles"
    steer = {"fell": False, "failed_cycles": 0, "heading_error_end_of_turn_deg": 0.3,
             "heading_error_final_deg": -0.1, "parts": {
                 "forward": {"velocity_error_share": 0.068}, "turn": {"velocity_error_share": 0.19},
                 "side": {"velocity_error_share": 0.37}, "stop": {"velocity_error_share": None}}}
    ours, verdict = _claim("steer").evaluate(_summary("steer", False, steer))
    assert verdict == C.MISSED
    assert ours.startswith("velocity error forward 7 %, turn 19 %, side 37 %; heading +0.3°")
    diverged = {"success": False, "metrics": {"parts": {"rough": {
        "met": False, "success": False, "command": "c", "diverged": "at 3.1 s"}}}}
    assert _claim("rough").evaluate(diverged) == ("the simulation diverged (at 3.1 s)", C.MISSED)


# ---------------------------------------------------------------- the table by robot
def test_the_table_by_robot_keeps_the_cells_it_did_not_run(tmp_path):
    """--update-docs writes one line per robot and one column per part; a second run of some
    cells (``--only``) replaces those and keeps the rest."""
    begin, end = runner.markers("agility")
    docs = tmp_path / "results.md"
    docs.write_text(f"intro\n{begin}\nold\n{end}\nafter\n")
    order = [c.id for c in C.AGILITY]

    def rows(robot, part, text, verdict):
        return [runner.Row(_claim(part, robot), text, verdict)]
    runner.update_docs(docs, "agility", rows("hyq", "push", "left | right", C.MET) +
                       rows("go2", "rough", "fell at 3 s", C.MISSED), order)
    runner.update_docs(docs, "agility", rows("hyq", "rough", "crossed", C.MET), order)
    text = docs.read_text()
    assert text.startswith("intro\n") and text.endswith("after\n") and "old" not in text
    region = text.split(begin)[1].split(end)[0]
    lines = [line for line in region.splitlines() if line.startswith("| ")]
    columns = [c.strip() for c in lines[0].strip("|").split(" | ")]
    assert columns[0] == "robot" and columns[-1] == "command"
    assert columns[1:-1] == [column for _, column, *_ in C.AGILITY_PARTS
                             if column in ("rough ground, trot", "lateral push while trotting")]
    hyq, go2 = (next(line for line in lines if line.startswith(f"| {r} |")) for r in ("hyq", "go2"))
    assert "met: crossed" in hyq and "met: left \\| right" in hyq
    assert "**missed**: fell at 3 s" in go2
    assert hyq.endswith("| `wholebody run agility --robot hyq` |")
    assert lines.index(go2) < lines.index(hyq)  # the claims' order: the presets by name

