"""``wholebody run ... --replay`` writes a replay.html that headless Chromium opens from disk and
renders: not blank, no page or console errors, no network request, moving the time slider
moves the robot, and the legend lists a push only in a run with one. Without /usr/bin/chromium (or playwright) the test skips, unless
WHOLEBODY_REQUIRE_BROWSER=1 (CI) makes that a failure."""

from __future__ import annotations

import io
import os
import sys
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from wholebody.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
import replay_screenshots as browser  # noqa: E402  (the headless-Chromium helpers)

pytestmark = pytest.mark.slow

#: scenario, robot, short settings, two slider times (s)
CASES = [
    ("push", "talos14", ["--set", "duration=1.2", "--set", "start=0.2", "--set",
                         "peak_force=150"], (0.0, 0.45)),
    ("crawl", "hyq", ["--set", "duration=3", "--set", "ramp_time=1", "--set", "speed_start=0.1",
                      "--set", "speed_end=0.2"], (0.5, 2.9)),
]


def _browser_or_skip() -> None:
    problem = None
    if not Path(browser.CHROMIUM).is_file():
        problem = f"{browser.CHROMIUM} not found (Debian: apt-get install chromium)"
    else:
        try:
            import playwright.sync_api  # noqa: F401
        except ImportError:
            problem = "playwright is not installed (pip install -e '.[test]')"
    if problem is None:
        return
    if os.environ.get("WHOLEBODY_REQUIRE_BROWSER") == "1":
        pytest.fail(f"{problem}, and WHOLEBODY_REQUIRE_BROWSER=1 requires the browser test")
    pytest.skip(problem)


def _pixels(page) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), dtype=np.int16)


def _changed(a: np.ndarray, b: np.ndarray, threshold: int = 24) -> np.ndarray:
    return np.abs(a - b).max(axis=2) > threshold


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    out = mask.copy()
    for axis in (0, 1):
        for shift in range(1, r + 1):
            out |= np.roll(mask, shift, axis) | np.roll(mask, -shift, axis)
    return out


@pytest.mark.parametrize(("scenario", "robot", "settings", "times"), CASES,
                         ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test_replay_renders_and_the_slider_moves_the_robot(scenario, robot, settings, times,
                                                       tmp_path):
    _browser_or_skip()
    out = tmp_path / scenario
    code = main(["run", scenario, "--robot", robot, *settings, "--replay", "--no-progress",
                 "--out", str(out)])
    assert code in (0, 1)  # short runs may miss the success criterion; the replay is written
    replay = out / "replay.html"
    assert replay.is_file() and replay.stat().st_size > 100_000
    with browser.replay_page(replay) as (page, problems):
        shots, robot_masks = [], []
        for t in times:
            browser.move_slider(page, t)
            shots.append(_pixels(page))
            browser.show_robots(page, False)
            robot_masks.append(_changed(shots[-1], _pixels(page)))
            browser.show_robots(page, True)
        shown = page.evaluate("document.getElementById('wb-clock').textContent")
        assert f"t = {times[-1]:.2f}" in shown
        legend = page.evaluate("document.getElementById('wb-legend').textContent")
        assert "contact forces" in legend
        assert ("push (" in legend) == (scenario == "push")  # the push's entry only with a push
    assert not problems, problems
    for image in shots:  # not blank: varied, many colours
        assert image.std() > 20
        assert len(np.unique(image.reshape(-1, 3) // 16, axis=0)) > 50
    robot_area = _dilate(robot_masks[0] | robot_masks[1], 3)
    assert robot_area.mean() > 0.01, "the robot is not on screen"
    moved = _changed(shots[0], shots[1])
    assert (moved & robot_area).sum() > 300, "the robot did not move between the slider positions"
    assert (moved & robot_area).sum() > 0.5 * moved.sum(), "what changed is not the robot"


def test_an_incident_link_moves_the_replay_to_its_time(tmp_path):
    """The first incidents are listed on the page; clicking one stops the player at its time
    (the clock and the slider say so) and marks it and the earlier ones as past."""
    _browser_or_skip()
    import wholebody as wb
    from wholebody.control.standing import StandingController
    from wholebody.report.replay import write_replay
    from wholebody.scenarios.loop import run_closed_loop
    from wholebody.sim.recorder import ReplayRecorder
    from wholebody.sim.simulator import Simulator

    robot = wb.load_robot("hyq")
    recorder = ReplayRecorder()
    run_closed_loop(Simulator(robot, observers=[recorder]), StandingController(robot), 1.0)
    incidents = [{"t": 0.3, "what": "joint lf_kfe_joint at its upper position limit (1.000)"},
                 {"t": 0.725, "what": "first failed controller cycle (held): <b>not markup</b>"}]
    replay = write_replay(tmp_path / "replay.html", recorder.recordings, "hyq", incidents)
    with browser.replay_page(replay) as (page, problems):
        links = page.locator("#wb-incidents a")
        assert links.count() == 2
        assert links.nth(1).text_content() == "0.725 s  " + incidents[1]["what"]  # text, not HTML
        links.nth(1).click()
        browser.rendered(page)
        assert "t = 0.7" in page.evaluate("document.getElementById('wb-clock').textContent")
        assert abs(float(page.evaluate("document.getElementById('wb-time').value")) - 0.725) < 0.03
        past = page.evaluate("[...document.querySelectorAll('#wb-incidents a')]"
                             ".map(a => a.classList.contains('past'))")
        assert past == [True, True]
        links.nth(0).click()
        browser.rendered(page)
        assert page.evaluate("[...document.querySelectorAll('#wb-incidents a')]"
                             ".map(a => a.classList.contains('past'))") == [True, False]
    assert not problems, problems


def _standing_recordings(name: str, duration: float):
    import wholebody as wb
    from wholebody.control.standing import StandingController
    from wholebody.scenarios.loop import run_closed_loop
    from wholebody.sim.recorder import ReplayRecorder
    from wholebody.sim.simulator import Simulator

    robot = wb.load_robot(name)
    recorder = ReplayRecorder()
    run_closed_loop(Simulator(robot, observers=[recorder]), StandingController(robot), duration)
    return recorder.recordings


def test_a_command_the_viewer_cannot_carry_out_is_skipped_and_reported(tmp_path):
    """One broken record (bytes msgpack cannot decode) does not stop the page: it becomes ready,
    draws the rest, and says how many commands failed."""
    _browser_or_skip()
    from wholebody.report import replay as rp

    commands, settings = rp.build_commands(_standing_recordings("hyq", 0.2))
    commands.insert(len(commands) // 2, rp.COMMAND + b"\xc1")  # 0xc1: never used by msgpack
    viewer_js = (resources.files("meshcat") / "viewer" / "dist" / "main.min.js").read_text(
        encoding="utf-8")
    path = tmp_path / "broken.html"
    path.write_text(rp.page(viewer_js, {**settings, "title": "broken"}, rp.pack(commands)))
    with browser.replay_page(path) as (page, problems):
        assert page.evaluate("window.wholebodyReplay.failed.length") == 1
        assert "1 scene command(s) could not be drawn" in page.evaluate(
            "document.getElementById('wb-status').textContent")
    assert not problems, problems


def test_anymal_c_meshes_are_drawn_without_a_failed_command(tmp_path, monkeypatch):
    """ANYmal C's base.dae mixes parts with and without texture coordinates, which meshcat's
    viewer cannot merge: sent as a Collada file, the page reports failed commands; drawn from the
    triangles Pinocchio loaded (what collada_drawable decides), none."""
    _browser_or_skip()
    from wholebody.report import replay as rp

    recordings = _standing_recordings("anymal_c", 0.1)
    failed = {}
    for label, convert in (("as files", False), ("converted", True)):
        if not convert:
            monkeypatch.setattr(rp, "_draw_from_triangles", lambda visual: set())
        else:
            monkeypatch.undo()
        path = rp.write_replay(tmp_path / f"{label}.html", recordings, label)
        with browser.replay_page(path) as (page, problems):
            failed[label] = page.evaluate("window.wholebodyReplay.failed.length")
    assert failed["as files"] >= 1 and failed["converted"] == 0
