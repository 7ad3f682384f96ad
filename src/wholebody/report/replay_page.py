"""The HTML page of a replay: meshcat's viewer bundle, the packed scene commands and our own
controls (play/pause, time slider, speed) in one file. See :mod:`wholebody.report.replay`."""

from __future__ import annotations

import html
import json

SPEEDS = (0.1, 0.25, 0.5, 1.0, 2.0)

_STYLE = """
html, body { margin: 0; height: 100%; overflow: hidden; font: 13px system-ui, sans-serif; }
#wb-pane { position: absolute; inset: 0; }
#wb-info { position: absolute; left: 10px; top: 10px; max-width: 46%; padding: 6px 9px;
  background: rgba(255, 255, 255, 0.85); border-radius: 4px; line-height: 1.5; }
#wb-info .title { font-weight: 600; }
#wb-info .swatch { display: inline-block; width: 10px; height: 10px; border-radius: 2px;
  margin: 0 4px 0 0; vertical-align: -1px; }
#wb-info .item { margin-right: 10px; white-space: nowrap; }
#wb-bar { position: absolute; left: 0; right: 0; bottom: 0; display: flex; gap: 10px;
  align-items: center; padding: 7px 12px; background: rgba(255, 255, 255, 0.88); }
#wb-bar button { min-width: 5.5em; }
#wb-time { flex: 1; }
#wb-clock { font-variant-numeric: tabular-nums; min-width: 10em; }
#wb-push { color: #d02090; min-width: 7em; font-variant-numeric: tabular-nums; }
#wb-incidents a { display: block; color: #a03000; text-decoration: none;
  font-variant-numeric: tabular-nums; }
#wb-incidents a.past { color: #606060; }
"""

# Our player: meshcat's animator only evaluates the clip at a time (``seek``); the clock, the
# slider and the speed are ours.
_SCRIPT = r"""
(function () {
  "use strict";
  const settings = JSON.parse(document.getElementById("wb-settings").textContent);
  const $ = (id) => document.getElementById(id);
  const status = $("wb-status");

  async function unpack(text) {
    const raw = Uint8Array.from(atob(text.trim()), (c) => c.charCodeAt(0));
    const stream = new Blob([raw]).stream().pipeThrough(new DecompressionStream("gzip"));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }

  function placeCamera(viewer, cam) {
    // meshcat turns its z-up scene into three.js's y-up world, and its camera lives in the
    // latter: (x, y, z) of the scene is (x, z, -y) there
    const three = (p) => [p[0], p[2], -p[1]];
    const camera = viewer.camera;
    camera.fov = cam.fov;
    camera.position.set(...three(cam.position));
    viewer.controls.target.set(...three(cam.target));
    viewer.controls.update();
    viewer.set_3d_pane_size();
  }

  function legend() {
    const c = settings.colors, s = settings.scale;
    const item = (color, text) =>
      `<span class="item"><span class="swatch" style="background:${color}"></span>${text}</span>`;
    const pushed = (settings.push_magnitude || []).some((x) => x > 0);  // a run with a push
    let out = item(c.contact, `contact forces (weight ${s.weight_N.toFixed(0)} N = ` +
                   `${s.weight_length_m.toFixed(2)} m)`) +
              (pushed ? item(c.push, `push (&times;${s.push_gain})`) : "") +
              item(c.com, "CoM") + item(c.cop, "CoP") + item(c.capture_point, "capture point");
    const steps = (settings.footsteps || []).flat();
    if (steps.length) {
      out += "<br>" + item(c.footstep, "footstep targets (outline: planned, filled: landed)");
      if (steps.some((x) => x.recovery)) out += item(c.recovery, "recovery steps");
    }
    if (settings.runs.length > 1) {
      out += "<br>" + settings.runs.map((r) =>
        `<span class="item">${r.label}: y = ${r.offset_y.toFixed(2)} m</span>`).join("");
    }
    $("wb-legend").innerHTML = out;
  }

  // the run's first incidents (summary.json's), each a link to its time
  function incidents(seek) {
    const list = settings.incidents || [];
    if (!list.length) return;
    const several = new Set(list.map((x) => x.run || "")).size > 1;
    const box = $("wb-incidents");
    box.textContent = "first incidents:";
    for (const x of list.slice(0, settings.shown_incidents)) {
      const a = document.createElement("a");
      a.href = "#";
      a.dataset.t = x.t;
      a.textContent = `${x.t.toFixed(3)} s  ${several && x.run ? "[" + x.run + "] " : ""}${x.what}`;
      a.addEventListener("click", (e) => { e.preventDefault(); seek(x.t - settings.t0); });
      box.appendChild(a);
    }
    if (list.length > settings.shown_incidents) {
      const more = document.createElement("div");
      more.textContent = `${list.length - settings.shown_incidents} more in summary.json`;
      box.appendChild(more);
    }
  }

  async function main() {
    const viewer = new MeshCat.Viewer($("wb-pane"));
    viewer.gui.close();
    const bytes = await unpack($("wb-data").textContent);
    const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    const path = (text) => text.split("/").filter((x) => x.length > 0);
    const failed = [];  // a command the viewer cannot carry out (a mesh it cannot read) is skipped
    for (let at = 0; at < bytes.length;) {  // records: uint32 length, kind, body
      const n = view.getUint32(at, true);
      const body = bytes.slice(at + 5, at + 4 + n);
      try {
        if (bytes[at + 4] === 0) {
          viewer.handle_command_bytearray(body);
        } else {  // a clone of an object already loaded: "source path\nnew path"
          const [source, target] = new TextDecoder().decode(body).split("\n");
          const object = viewer.scene_tree.find(path(source).concat(["<object>"])).object;
          viewer.set_object(path(target), object.clone());
        }
      } catch (err) {
        failed.push(String(err));
      }
      at += 4 + n;
    }
    viewer.set_dirty();
    placeCamera(viewer, settings.camera);
    legend();
    const animator = viewer.animator;
    animator.play();  // makes the clip's actions active; the clock below drives them
    animator.playing = false;

    const slider = $("wb-time"), button = $("wb-play"), speed = $("wb-speed");
    const span = settings.duration, period = settings.frame_period;
    slider.max = span;
    slider.step = period;
    let time = 0, playing = false, last = null;

    function show(t) {
      time = Math.min(Math.max(t, 0), span);
      animator.seek(time);
      animator.display_progress(time);
      slider.value = time;
      $("wb-clock").textContent =
        `t = ${(settings.t0 + time).toFixed(2)} / ${(settings.t0 + span).toFixed(2)} s`;
      for (const a of document.querySelectorAll("#wb-incidents a")) {
        a.classList.toggle("past", parseFloat(a.dataset.t) <= settings.t0 + time + 1e-9);
      }
      const k = Math.min(Math.round(time / period), settings.push_magnitude.length - 1);
      const push = settings.push_magnitude[k] || 0;
      $("wb-push").textContent = push > 0 ? `push ${push.toFixed(0)} N` : "";
    }
    function setPlaying(on) {
      playing = on;
      last = null;
      button.textContent = on ? "\u23f8 pause" : "\u25b6 play";
    }
    button.addEventListener("click", () => {
      if (!playing && time >= span) show(0);
      setPlaying(!playing);
    });
    slider.addEventListener("input", () => { setPlaying(false); show(parseFloat(slider.value)); });
    document.addEventListener("keydown", (e) => {
      if (e.target.tagName === "SELECT") return;
      if (e.key === " ") { e.preventDefault(); button.click(); }
      else if (e.key === "ArrowRight") { setPlaying(false); show(time + period); }
      else if (e.key === "ArrowLeft") { setPlaying(false); show(time - period); }
    });
    function tick(now) {
      if (playing) {
        if (last !== null) {
          const t = time + (now - last) / 1000 * parseFloat(speed.value);
          show(t);
          if (t >= span) setPlaying(false);
        }
        last = now;
      }
      requestAnimationFrame(tick);
    }
    incidents((t) => { setPlaying(false); show(t); });
    show(settings.opening || 0);
    requestAnimationFrame(tick);
    requestAnimationFrame(() => requestAnimationFrame(() => {
      status.textContent = failed.length ?
        `${failed.length} scene command(s) could not be drawn (first: ${failed[0]})` : "";
      document.body.dataset.ready = "true";
      window.wholebodyReplay = { show: show, duration: span, viewer: viewer, failed: failed };
    }));
  }

  if (typeof DecompressionStream === "undefined") {
    status.textContent = "this browser cannot unpack the replay (no DecompressionStream)";
    return;
  }
  main().catch((err) => { status.textContent = "replay failed: " + err; throw err; });
})();
"""


#: characters of JSON text that HTML could read inside a <script> element (``</script>``,
#: ``<!--``), written as the JSON escapes of the same characters
_SCRIPT_ESCAPES = (("&", "\\u0026"), ("<", "\\u003c"), (">", "\\u003e"),
                   ("\u2028", "\\u2028"), ("\u2029", "\\u2029"))


def _script_safe(text: str) -> str:
    """JSON text that cannot end, or open a comment in, the <script> element it is embedded in:
    the same JSON value, its &, <, > and line separators escaped."""
    for character, escape in _SCRIPT_ESCAPES:
        text = text.replace(character, escape)
    return text


def page(viewer_js: str, settings: dict, data: str) -> str:
    """The page: ``viewer_js`` (meshcat's main.min.js), ``settings`` (JSON: title, time span,
    frame period, camera, legend, incidents, footsteps) and ``data`` (the packed commands, base64)."""
    if "</script" in viewer_js.lower():
        raise ValueError("meshcat's main.min.js contains '</script': cannot embed it")
    title = html.escape(settings.get("title", "replay"))
    options = "".join(f'<option value="{s:g}"{" selected" if s == 1.0 else ""}>{s:g}&times;'
                      f"</option>" for s in SPEEDS)
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>{_STYLE}</style>
</head>
<body>
<div id="wb-pane"></div>
<div id="wb-info"><div class="title">{title}</div><div id="wb-legend"></div>
<div id="wb-incidents"></div><div id="wb-status">loading&hellip;</div></div>
<div id="wb-bar">
<button id="wb-play" type="button">&#9654; play</button>
<input id="wb-time" type="range" min="0" max="1" step="0.001" value="0" aria-label="time">
<span id="wb-clock"></span><span id="wb-push"></span>
<label>speed <select id="wb-speed">{options}</select></label>
</div>
<script>{viewer_js}</script>
<script type="application/json" id="wb-settings">{_script_safe(json.dumps(settings))}</script>
<script type="text/plain" id="wb-data">{data}</script>
<script>{_SCRIPT}</script>
</body>
</html>
"""
