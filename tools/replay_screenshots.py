"""Screenshots of replay pages for the docs, and the headless-Chromium helpers of the browser test.

Runs ``wholebody run push --robot talos14 --replay``, ``wholebody run crawl --robot hyq
--replay`` and a short ``wholebody run walk --robot talos14 --replay`` (about a minute each), opens
each ``replay.html`` from disk in headless Chromium (Python playwright, /usr/bin/chromium; no
network) and writes ``docs/img/replay_push_talos14.png``, ``docs/img/replay_crawl_hyq.png`` and
``docs/img/replay_walk_talos14.png``::

    .venv/bin/python tools/replay_screenshots.py [--runs results/replays] [--skip-runs]
        [--only replay_walk_talos14]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
VIEWPORT = {"width": 1280, "height": 720}
#: (name, command-line arguments, simulated time of the screenshot in s, camera zoom: 1 = the
#: page's own view of the whole motion, more = closer to the robot, see close_up)
SHOTS = (
    ("replay_push_talos14", ["push", "--robot", "talos14"], 0.55, 1.0),  # during the push
    ("replay_crawl_hyq", ["crawl", "--robot", "hyq"], 9.0, 1.0),
    ("replay_walk_talos14", ["walk", "--robot", "talos14", "--set", "steps=6", "--set", "turn=0",
                             "--set", "side_distance=0"], 4.0, 1.4),  # a swing, the target ahead
)


@contextmanager
def replay_page(path: Path, timeout_s: float = 120.0):
    """A headless Chromium page (fresh profile) showing the replay file ``path``, once rendered;
    yields ``(page, problems)``: ``problems`` collects page errors, console errors and every
    request that is not for a local file or inline data."""
    from playwright.sync_api import sync_playwright

    problems: list[str] = []
    with tempfile.TemporaryDirectory(prefix="wholebody-chromium-") as profile, \
            sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            profile, executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS,
            viewport=VIEWPORT, offline=True)
        try:
            def route(r):
                if r.request.url.startswith(("file:", "data:", "blob:")):
                    return r.continue_()
                problems.append(f"request: {r.request.url}")
                return r.abort()
            context.route("**/*", route)
            page = context.new_page()
            page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
            page.on("console", lambda m: problems.append(f"console error: {m.text}")
                    if m.type == "error" else None)
            page.goto(Path(path).resolve().as_uri())
            page.wait_for_selector("body[data-ready=true]", timeout=timeout_s * 1000)
            yield page, problems
        finally:
            context.close()


def rendered(page) -> None:
    """Wait until the viewer has drawn what was just changed (two animation frames)."""
    page.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")


def move_slider(page, t: float) -> None:
    """Move the page's time slider to simulated time ``t`` as a user would (an input event)."""
    page.evaluate("""t => { const s = document.getElementById("wb-time");
        s.value = t; s.dispatchEvent(new Event("input")); }""", t)
    rendered(page)


def show_robots(page, visible: bool) -> None:
    """Show or hide the robot of every run (its meshes only: arrows and markers stay)."""
    page.evaluate("""visible => { const v = window.wholebodyReplay.viewer;
        const root = v.scene_tree.find(["meshcat"]);
        for (const [name, node] of Object.entries(root.children))
            if (name.startsWith("run")) node.children["robot"].object.visible = visible;
        v.set_dirty(); }""", visible)
    rendered(page)


def close_up(page, zoom: float) -> None:
    """Move the camera ``zoom`` times closer, aimed at the first robot (its CoM, at 0.6 of its
    height), along the page's viewing direction (as a user's scroll and right-drag would)."""
    page.evaluate("""zoom => { const v = window.wholebodyReplay.viewer;
        const com = v.camera.position.clone();
        v.scene_tree.find(["meshcat", "run0", "com"]).object.getWorldPosition(com);
        const back = v.camera.position.clone().sub(v.controls.target).multiplyScalar(1 / zoom);
        v.controls.target.set(com.x, 0.6 * com.y, com.z);  // three.js: y up
        v.camera.position.copy(v.controls.target).add(back);
        v.controls.update(); v.set_dirty(); }""", zoom)
    rendered(page)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", default="results/replays", help="output folder of the runs")
    parser.add_argument("--skip-runs", action="store_true", help="reuse the runs' replay.html")
    parser.add_argument("--img", default=str(ROOT / "docs" / "img"), help="where the PNGs go")
    parser.add_argument("--only", action="append", choices=[s[0] for s in SHOTS],
                        help="this screenshot only (repeatable; default: all)")
    args = parser.parse_args(argv)
    Path(args.img).mkdir(parents=True, exist_ok=True)
    for name, command, t, zoom in SHOTS:
        if args.only and name not in args.only:
            continue
        out = Path(args.runs) / name
        if not args.skip_runs:
            subprocess.run([sys.executable, "-m", "wholebody", "run", *command, "--replay",
                            "--no-progress", "--out", str(out)], check=False)
        replay = out / "replay.html"
        with replay_page(replay) as (page, problems):
            move_slider(page, t)
            if zoom != 1.0:
                close_up(page, zoom)
            png = Path(args.img) / f"{name}.png"
            page.screenshot(path=str(png))
        print(f"{png} from {replay} ({replay.stat().st_size / 1e6:.1f} MB) at t = {t} s"
              + "".join(f"\n  {p}" for p in problems))
    return 0


if __name__ == "__main__":
    sys.exit(main())
