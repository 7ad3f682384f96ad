"""Screenshots of replay pages for the docs, and the headless-Chromium helpers of the browser test.

Runs ``wholebody run push --robot talos14 --replay`` and ``wholebody run crawl --robot hyq
--replay`` (about a minute each), opens each ``replay.html`` from disk in headless Chromium (Python
playwright, /usr/bin/chromium; no network) and writes ``docs/img/replay_push_talos14.png`` and
``docs/img/replay_crawl_hyq.png``::

    .venv/bin/python tools/replay_screenshots.py [--runs results/replays] [--skip-runs]
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
#: (name, command-line arguments, simulated time of the screenshot in s)
SHOTS = (
    ("replay_push_talos14", ["push", "--robot", "talos14"], 0.55),  # during the push
    ("replay_crawl_hyq", ["crawl", "--robot", "hyq"], 9.0),
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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", default="results/replays", help="output folder of the runs")
    parser.add_argument("--skip-runs", action="store_true", help="reuse the runs' replay.html")
    parser.add_argument("--img", default=str(ROOT / "docs" / "img"), help="where the PNGs go")
    args = parser.parse_args(argv)
    Path(args.img).mkdir(parents=True, exist_ok=True)
    for name, command, t in SHOTS:
        out = Path(args.runs) / name
        if not args.skip_runs:
            subprocess.run([sys.executable, "-m", "wholebody", "run", *command, "--replay",
                            "--no-progress", "--out", str(out)], check=False)
        replay = out / "replay.html"
        with replay_page(replay) as (page, problems):
            move_slider(page, t)
            png = Path(args.img) / f"{name}.png"
            page.screenshot(path=str(png))
        print(f"{png} from {replay} ({replay.stat().st_size / 1e6:.1f} MB) at t = {t} s"
              + "".join(f"\n  {p}" for p in problems))
    return 0


if __name__ == "__main__":
    sys.exit(main())
