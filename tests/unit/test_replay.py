"""The replay page without a browser: self-contained (nothing fetched from the network), its frames
are the simulator's log subsampled, its robot poses are Pinocchio's forward kinematics, its capture
point is CoM + v / omega, a walking run's footsteps come from its summary.json; and the command
line refuses --replay/--view where they cannot work, before anything is simulated."""

from __future__ import annotations

import json
import logging
import re
import sys
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from wholebody.cli import main
from wholebody.control.standing import StandingController
from wholebody.report.replay import (COLORS, build_commands, capture_points, collada_drawable,
                                     pack, replay_html, robot_visuals, summary_footsteps, unpack,
                                     write_replay)
from wholebody.robots.locate import resolve_model_path
from wholebody.scenarios import SCENARIOS, get_scenario
from wholebody.scenarios.base import Scenario
from wholebody.scenarios.loop import run_closed_loop
from wholebody.sim.recorder import Recording, ReplayRecorder
from wholebody.sim.simulator import Simulator

#: XML namespace names (three.js createElementNS, Collada meshes): identifiers, never fetched
NAMESPACES = {"http://www.w3.org/1999/xhtml", "http://www.w3.org/2000/svg",
              "http://www.collada.org/2005/11/COLLADASchema"}
DURATION, FPS = 0.3, 40.0


@pytest.fixture(scope="module")
def replay(robots):
    """A short standing run of hyq, recorded; (simulator, recorder, html)."""
    robot = robots["hyq"]
    recorder = ReplayRecorder(fps=FPS)
    sim = Simulator(robot, observers=[recorder])
    run_closed_loop(sim, StandingController(robot), DURATION)
    return sim, recorder, replay_html(recorder.recordings, title="hyq stands")


def _element(html: str, element_id: str) -> str:
    match = re.search(rf'<script[^>]*id="{element_id}"[^>]*>(.*?)</script>', html, re.DOTALL)
    assert match, f"no <script id={element_id}> in the page"
    return match.group(1)


def _commands(html: str) -> list[dict]:
    return unpack(_element(html, "wb-data"))


def test_the_page_fetches_nothing(replay):
    html = replay[2]
    urls = set(re.findall(r"""https?://[^\s"'<>)\\]+""", html))
    assert urls <= NAMESPACES, f"network references: {sorted(urls - NAMESPACES)}"
    assert not re.search(r"<(script|img|iframe)[^>]*\ssrc=|<link\b", html, re.IGNORECASE)
    for command in _commands(html):  # textures and meshes are inline too
        text = repr(command)
        assert "http" not in text or set(re.findall(r"https?://[^\s'\"]+", text)) <= NAMESPACES


def test_incidents_are_in_the_settings_and_cannot_close_the_script(replay):
    """A run's incidents ride in the page's settings as given, even text that looks like markup
    or would end the <script> element (the page shows them as text, see the browser test)."""
    _, recorder, html = replay
    assert json.loads(_element(html, "wb-settings"))["incidents"] == []
    incidents = [{"t": 0.1, "what": "first failed controller cycle (held): </script><b>x</b>",
                  "run": "passive"}]
    settings = json.loads(_element(replay_html(recorder.recordings, "t", incidents),
                                   "wb-settings"))
    assert settings["incidents"] == incidents


def test_text_that_html_would_read_is_escaped_in_the_settings(replay):
    """A title or an incident holding '<!--', '<script>', '&' or a line separator is embedded
    with those characters as JSON escapes: no '<' or '>' reaches the settings element (a '<!--'
    there left the page on "loading..."), and the JSON reads back the same."""
    _, recorder, _ = replay
    title = "<!--<script> & \u2028 \u2029 -->"
    incidents = [{"t": 0.1, "what": "<!-- x", "run": "r"}]
    html = replay_html(recorder.recordings, title, incidents)
    raw = _element(html, "wb-settings")
    assert not set("<>&\u2028\u2029") & set(raw)
    settings = json.loads(raw)
    assert settings["title"] == title and settings["incidents"] == incidents


def test_frames_are_the_log_subsampled(replay):
    sim, recorder, html = replay
    stride = recorder.stride
    assert stride == round(1.0 / (FPS * sim.dt))
    log_t, log_q = np.asarray(sim.log.t), np.asarray(sim.log.q)
    (rec,) = recorder.recordings
    assert rec.frames == len(log_t[::stride]) == int(np.ceil(round(DURATION / sim.dt) / stride))
    np.testing.assert_array_equal(rec.t, log_t[::stride])
    np.testing.assert_array_equal(rec.q, log_q[::stride])
    settings = json.loads(_element(html, "wb-settings"))
    assert settings["frames"] == rec.frames
    assert settings["frame_period"] == pytest.approx(stride * sim.dt)
    assert settings["duration"] == pytest.approx(rec.t[-1] - rec.t[0])
    (animate,) = [c for c in _commands(html) if c["type"] == "set_animation"]
    for entry in animate["animations"]:
        clip = entry["clip"]
        assert clip["fps"] == pytest.approx(1.0 / (stride * sim.dt))
        for track in clip["tracks"]:
            times = [key["time"] for key in track["keys"]]
            assert times == list(range(rec.frames)), (entry["path"], track["name"])


def test_link_poses_are_forward_kinematics(replay, robots):
    """The animated pose of the foot meshes at a sampled frame = Pinocchio's kinematics of the
    logged configuration, computed here from the URDF."""
    sim, recorder, html = replay
    robot = robots["hyq"]
    urdf = resolve_model_path(robot.description.urdf, robot.description.base_dir)
    model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    visual = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.VISUAL,
                                   package_dirs=[str(p) for p in urdf.parents])
    frame = recorder.recordings[0].frames // 2
    q = np.asarray(sim.log.q)[frame * recorder.stride]
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    (animate,) = [c for c in _commands(html) if c["type"] == "set_animation"]
    clips = {entry["path"]: entry["clip"] for entry in animate["animations"]}
    deepest = max(range(1, model.njoints), key=lambda j: len(model.supports[j]))
    checked = 0
    for g in visual.geometryObjects:
        if g.parentJoint != deepest:
            continue
        expected = data.oMi[g.parentJoint] * g.placement
        tracks = {t["name"]: t["keys"] for t in
                  clips[f"/meshcat/run0/robot/visuals/{g.name}"]["tracks"]}
        position = np.array(tracks[".position"][frame]["value"])
        x, y, z, w = tracks[".quaternion"][frame]["value"]
        rotation = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
        # the page stores single precision: 1e-7 relative
        np.testing.assert_allclose(position, expected.translation, atol=1e-6)
        np.testing.assert_allclose(rotation, expected.rotation, atol=1e-6)
        checked += 1
    assert checked


def test_a_mesh_scale_applies_once(robots):
    """A URDF mesh's scale (talos14 draws its left parts with the right ones' meshes mirrored,
    scale (1, -1, 1)) is on the mesh object, and the node that the animation moves carries the pose
    alone: the animation sets only a node's position and quaternion, so a scale there would apply
    on top of the object's (mirrored parts drawn unmirrored; meshes in millimetres, scale 0.001,
    shrunk a thousandfold)."""
    robot = robots["talos14"]
    recorder = ReplayRecorder()
    run_closed_loop(Simulator(robot, observers=[recorder]), StandingController(robot), 0.03)
    _, visual = robot_visuals(robot)
    mirrored = [g for g in visual.geometryObjects if np.prod(g.meshScale) < 0]
    assert mirrored, "talos14 has mirrored meshes"
    static, scale = {}, {}
    for command in _commands(replay_html(recorder.recordings)):
        path = command.get("path", "")
        if command.get("type") == "set_transform" and "/visuals/" in path:
            static[path] = np.asarray(command["matrix"], float).reshape(4, 4).T
        if command.get("type") == "set_property" and command.get("property") == "scale":
            scale[path] = np.asarray(command["value"], float)
    for g in visual.geometryObjects:
        node = f"/meshcat/run0/robot/visuals/{g.name}"
        np.testing.assert_allclose(scale[f"{node}/<object>"], g.meshScale, rtol=1e-6)
        linear = static[node][:3, :3]
        np.testing.assert_allclose(linear.T @ linear, np.eye(3), atol=1e-9)
        assert np.linalg.det(linear) > 0


def _local_hyq(tmp_path, mesh_package: str | None = None):
    """hyq from a copy of its URDF in ``tmp_path`` (meshes moved to ``package://mesh_package/``
    if given), as a user's own file would be."""
    import wholebody as wb

    urdf = resolve_model_path("erd:hyq_description/robots/hyq_no_sensors.urdf").read_text()
    if mesh_package is not None:
        urdf = re.sub(r'filename="package://[^"]*/([^/"]+)"',
                      rf'filename="package://{mesh_package}/\1"', urdf)
    (tmp_path / "hyq.urdf").write_text(urdf)
    preset = (resources.files("wholebody.robots") / "presets" / "hyq.toml").read_text()
    (tmp_path / "hyq.toml").write_text(preset.replace(
        'urdf = "erd:hyq_description/robots/hyq_no_sensors.urdf"', 'urdf = "hyq.urdf"'))
    return wb.load_robot(tmp_path / "hyq.toml")


def test_a_local_urdf_finds_example_robot_data_meshes(tmp_path):
    """A URDF copied out of example-robot-data still names its meshes package://example-robot-data/
    ...: they are found (example-robot-data is one of the package directories)."""
    _, visual = robot_visuals(_local_hyq(tmp_path))
    meshes = [g.meshPath for g in visual.geometryObjects
              if Path(g.meshPath).suffix.lower() in (".dae", ".stl", ".obj")]
    assert meshes and all(Path(m).is_file() for m in meshes)


def test_missing_meshes_give_a_stick_figure_along_the_bones(tmp_path, caplog, monkeypatch):
    """Meshes that cannot be found (a package nowhere): a warning, and capsules from each joint to
    its children and to the feet, checked against Pinocchio's forward kinematics."""
    robot = _local_hyq(tmp_path, mesh_package="nowhere")
    replay_log = logging.getLogger("wholebody.report.replay")
    # the handler on the module's logger itself: whatever earlier tests left in the logging tree
    # (a disabled logger, propagation off) cannot hide the record
    monkeypatch.setattr(replay_log, "disabled", False)
    replay_log.addHandler(caplog.handler)
    try:
        with caplog.at_level("WARNING", logger=replay_log.name):
            model, figure = robot_visuals(robot)
    finally:
        replay_log.removeHandler(caplog.handler)
    assert "stick figure" in caplog.text and "nowhere" in caplog.text
    assert model is robot.model
    data, gdata = model.createData(), figure.createData()
    pin.forwardKinematics(model, data, robot.q_ref)
    pin.updateFramePlacements(model, data)
    pin.updateGeometryPlacements(model, data, figure, gdata)
    ends = set()
    for g, placement in zip(figure.geometryObjects, gdata.oMg):
        half = g.geometry.halfLength
        start = placement.act(np.array([0.0, 0.0, -half]))
        np.testing.assert_allclose(start, data.oMi[g.parentJoint].translation, atol=1e-9)
        ends.add(tuple(np.round(placement.act(np.array([0.0, 0.0, half])), 9)))
    children = {tuple(np.round(data.oMi[j].translation, 9)) for j in range(2, model.njoints)}
    feet = {tuple(np.round(data.oMf[c.frame_id].translation, 9)) for c in robot.contacts}
    assert ends == (children | feet) - {tuple(np.round(data.oMi[1].translation, 9))}


def _collada(*primitives: str) -> str:
    """A Collada document with one mesh per primitive (``"triangles:NORMAL,TEXCOORD"``: its tag
    and the inputs besides VERTEX, whose <vertices> give POSITION)."""
    meshes = []
    for i, text in enumerate(primitives):
        tag, _, inputs = text.partition(":")
        extra = "".join(f'<input semantic="{x}" source="#s{i}" offset="{k + 1}"/>'
                        for k, x in enumerate(filter(None, inputs.split(","))))
        meshes.append(f'<geometry id="g{i}"><mesh><vertices id="v{i}"><input semantic="POSITION" '
                      f'source="#p{i}"/></vertices><{tag} count="1"><input semantic="VERTEX" '
                      f'source="#v{i}" offset="0"/>{extra}<p>0 0 0</p></{tag}></mesh></geometry>')
    return ('<?xml version="1.0"?><COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" '
            f'version="1.4.1"><library_geometries>{"".join(meshes)}</library_geometries>'
            '</COLLADA>')


@pytest.mark.parametrize(("primitives", "drawable"), [
    (("triangles:NORMAL", "polylist:NORMAL"), True),
    (("triangles:NORMAL", "triangles:NORMAL,TEXCOORD"), False),  # ANYmal C's base.dae
    (("triangles:NORMAL,TEXCOORD", "lines:"), True),  # lines are not merged with the meshes
])
def test_collada_files_meshcat_can_merge(primitives, drawable, tmp_path):
    path = tmp_path / "mesh.dae"
    path.write_text(_collada(*primitives))
    assert collada_drawable(path) is drawable


def test_an_unreadable_collada_file_is_not_drawable(tmp_path):
    path = tmp_path / "broken.dae"
    path.write_text("<COLLADA><unclosed>")
    assert collada_drawable(path) is False
    assert collada_drawable(tmp_path / "missing.dae") is False


def test_the_scene_holds_robot_floor_and_markers(replay):
    commands = _commands(replay[2])
    paths = {c["path"] for c in commands if c["type"] in ("set_object", "clone")}
    loaded = {c["path"] for c in commands if c["type"] == "set_object"}
    assert all(c["source"] in loaded for c in commands if c["type"] == "clone")
    assert any(p.startswith("/meshcat/run0/robot/visuals/") for p in paths)
    assert "/meshcat/run0/scene/floor" in paths
    assert {"/meshcat/run0/com", "/meshcat/run0/cop"} <= paths
    assert sum(p.startswith("/meshcat/run0/forces/") for p in paths) == 2 * 4  # shaft + head


def test_a_reset_before_any_step_starts_the_recording_over(robots):
    recorder = ReplayRecorder()
    sim = Simulator(robots["hyq"], observers=[recorder])
    sim.reset()
    assert len(recorder.recordings) == 1 and recorder.recordings[0].frames == 0


def test_scenarios_declare_their_simulations():
    params = get_scenario("crawl").resolve({})
    assert get_scenario("crawl").simulation_count(params, "passive+quasi-static") == 2
    assert get_scenario("crawl").simulation_count(params, "passive") == 1
    for name in ("push", "stand", "squat", "platform", "tilt-board", "ramp", "single-support"):
        assert get_scenario(name).simulation_count(get_scenario(name).resolve({})) == 1, name
    stepping = get_scenario("stepping")
    assert stepping.simulation_count(stepping.resolve({})) == 2  # reduced and full
    assert stepping.simulation_count(stepping.resolve({"formulations": "full"})) == 1


def test_single_support_is_watched(robots):
    """single-support passes its observers to its simulator: a short run is recorded (one
    recording with frames) and has its incident list."""
    recorder = ReplayRecorder()
    result = get_scenario("single-support").run(robots["talos14"], "lqr", {"duration": "0.1"},
                                                observers=[recorder])
    assert len(recorder.recordings) == 1 and recorder.recordings[0].frames > 0
    assert result.incidents == []


def _never(*args, **kwargs):
    raise AssertionError("the scenario ran")


def test_observers_need_a_declared_scenario(robots):
    undeclared = Scenario("undeclared", "?", (), ("x",), "hyq", _never)
    with pytest.raises(ValueError, match="does not declare"):
        undeclared.run(robots["hyq"], observers=[ReplayRecorder()])


@pytest.mark.parametrize("flag", ["--replay", "--view"])
def test_many_simulations_are_refused_before_running(flag, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(SCENARIOS, "many", Scenario("many", "runs 3", (), ("x",), "hyq", _never,
                                                    simulations=3))
    assert main(["run", "many", flag, "--out", str(tmp_path / "many")]) == 2
    err = capsys.readouterr().err
    assert f"scenario 'many' runs 3 simulations; {flag} needs a single-run scenario" in err
    monkeypatch.setitem(SCENARIOS, "unknown", Scenario("unknown", "?", (), ("x",), "hyq", _never))
    assert main(["run", "unknown", flag, "--out", str(tmp_path / "unknown")]) == 2
    assert f"does not declare how many simulations it runs; {flag} needs" in capsys.readouterr().err
    assert not (tmp_path / "many").exists() and not (tmp_path / "unknown").exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="display variables: Linux")
def test_view_without_display_is_refused_before_running(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setitem(SCENARIOS, "stand", Scenario("stand", "", (), ("standing",), "hyq",
                                                     _never, simulations=1))
    assert main(["run", "stand", "--view", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "--view: no display (neither DISPLAY nor WAYLAND_DISPLAY is set)" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["talos14", "hyq"])
def test_the_live_views_skeleton_leaves_the_dynamics_alone(name, robots, rng):
    import mujoco

    from wholebody.sim import convert
    from wholebody.sim.twin import build_twin

    robot = robots[name]
    plain, drawn = build_twin(robot).model, build_twin(robot, skeleton=True).model
    assert drawn.ngeom > plain.ngeom
    np.testing.assert_array_equal(drawn.body_mass, plain.body_mass)
    np.testing.assert_array_equal(drawn.body_inertia, plain.body_inertia)
    q, v = robot.random_state(rng)
    matrices = []
    for m in (plain, drawn):
        d = mujoco.MjData(m)
        d.qpos[:robot.nq], d.qvel[:robot.nv] = convert.pin_to_mj(q, v)
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        matrices.append((M, d.qfrc_bias.copy(), d.ncon))
    np.testing.assert_array_equal(matrices[0][0], matrices[1][0])
    np.testing.assert_array_equal(matrices[0][1], matrices[1][1])
    assert matrices[0][2] == matrices[1][2]


def _synthetic(robot, t, com, loaded, contact_z) -> Recording:
    """A recording of ``robot`` at its reference posture whose CoM follows ``com`` (frames, 3) at
    times ``t``; contact ``i`` at height ``contact_z[i]``, loaded where ``loaded`` (frames,
    contacts) says."""
    n = len(robot.contact_names)
    rec = Recording(robot, "synthetic", float(t[1] - t[0]), [])
    for k, tk in enumerate(t):
        points = np.column_stack([0.1 * np.arange(n), np.zeros(n), contact_z])
        rec.t.append(float(tk))
        rec.q.append(robot.q_ref.copy())
        rec.com.append(np.asarray(com[k], float))
        rec.contact_points.append(points)
        rec.contact_forces.append(np.zeros((n, 3)))
        rec.loaded.append(np.asarray(loaded[k], bool))
        rec.cop.append(points[np.asarray(loaded[k], bool)].mean(axis=0) if np.any(loaded[k])
                       else np.full(3, np.nan))
        rec.pushes.append([])
        rec.body_poses.append([])
    return rec


def _tracks(commands: list[dict]) -> dict[str, dict[str, list]]:
    """The animation's keys: node path -> track name -> [(frame, value)]."""
    (animate,) = [c for c in commands if c["type"] == "set_animation"]
    return {e["path"]: {t["name"]: [(k["time"], k["value"]) for k in t["keys"]]
                        for t in e["clip"]["tracks"]} for e in animate["animations"]}


def _at(keys: list, frame: int):
    """A discrete track's value at ``frame``: its last key at or before it."""
    return [v for k, v in keys if k <= frame][-1]


def test_the_capture_point_is_com_plus_velocity_over_omega(robots):
    """A CoM moving along a parabola (central differences are exact there): the capture point is
    CoM_xy + v_xy / omega, omega = sqrt(g / z_c), z_c the CoM's height above the lowest loaded
    contact, on that contact's height; hidden while nothing is loaded. The page animates its
    marker there."""
    robot = robots["hyq"]
    t = 0.025 * np.arange(12)
    com = np.column_stack([0.1 + 0.3 * t + 0.8 * t**2, -0.05 + 0.2 * t - 0.5 * t**2,
                           0.55 + 0.1 * t])
    velocity = np.column_stack([0.3 + 1.6 * t, 0.2 - 1.0 * t, np.full_like(t, 0.1)])
    contact_z = 0.05 + 0.02 * np.arange(4)  # the lowest is contact 0
    loaded = np.ones((12, 4), bool)
    loaded[5:8, 0] = False  # then contact 1 is the lowest loaded
    loaded[9] = False  # nothing loaded
    rec = _synthetic(robot, t, com, loaded, contact_z)
    support = np.where(loaded[:, 0], contact_z[0], contact_z[1])
    omega = np.sqrt(9.81 / (com[:, 2] - support))
    expected = np.column_stack([com[:, :2] + velocity[:, :2] / omega[:, None], support])
    got = capture_points(rec)
    assert np.isnan(got[9]).all()
    shown = np.arange(12) != 9
    np.testing.assert_allclose(got[shown], expected[shown], rtol=1e-9, atol=1e-12)
    tracks = _tracks(unpack(pack(build_commands([rec])[0])))["/meshcat/run0/capture_point"]
    h = float(robot.q_ref[2])
    assert [v for _, v in tracks[".visible"]] == shown.tolist()
    position = np.array([v for _, v in tracks[".position"]])
    np.testing.assert_allclose(position[shown], expected[shown] + [0.0, 0.0, 0.004 * h],
                               atol=1e-6)  # single precision


#: footsteps as the walking scenarios' summary.json rows (more keys than the page draws)
FOOTSTEPS = [
    {"contact": "left_sole", "lift_off_s": 0.1, "touchdown_s": 0.3, "recovery": False,
     "planned_xy_m": [0.18, 0.1], "target_xy_m": [0.2, 0.1], "yaw_rad": 0.3,
     "landed_xy_m": [0.21, 0.1], "landing_from_start_xy_m": [0.2, 0.0]},
    {"contact": "right_sole", "lift_off_s": 0.35, "touchdown_s": None, "recovery": True,
     "planned_xy_m": [0.25, -0.1], "target_xy_m": [0.3, -0.12], "yaw_rad": -0.2,
     "landed_xy_m": None, "landing_from_start_xy_m": None},
    {"contact": "left_sole", "lift_off_s": 0.9, "touchdown_s": 1.5, "recovery": False,
     "planned_xy_m": [0.5, 0.1], "target_xy_m": [0.5, 0.1], "yaw_rad": 0.0,
     "landed_xy_m": [0.5, 0.1], "landing_from_start_xy_m": [0.5, 0.0]},  # after the last frame
]


@pytest.fixture(scope="module")
def standing_talos(robots):
    """talos14 standing still on a floor at z = 0.02 for 0.5 s (21 frames), without simulating."""
    robot = robots["talos14"]
    t = 0.025 * np.arange(21)
    com = np.tile(np.r_[0.0, 0.0, 0.9], (21, 1))
    return _synthetic(robot, t, com, np.ones((21, 2), bool), np.full(2, 0.02))


def test_a_walking_summary_draws_its_footsteps(standing_talos, robots, tmp_path):
    """The footsteps of a walking run's summary (as `wholebody run` passes them) are in the
    page's settings and drawn: each target as its sole's rectangle on the support, at its
    yaw, shown from its lift-off, filled from its touchdown, a recovery step in its own colour;
    one planned after the last frame is left out."""
    robot = robots["talos14"]
    summary = {"scenario": "walk", "robot": "talos14", "metrics": {"steps": 3,
                                                                 "footsteps": FOOTSTEPS}}
    html = write_replay(tmp_path / "replay.html", [standing_talos],
                        footsteps=summary_footsteps(summary)).read_text()
    settings = json.loads(_element(html, "wb-settings"))
    keys = ("contact", "lift_off_s", "touchdown_s", "recovery", "target_xy_m", "yaw_rad")
    assert settings["footsteps"] == [[{k: s[k] for k in keys} for s in FOOTSTEPS[:2]]]
    commands = _commands(html)
    objects = {c["path"]: c for c in commands if c["type"] == "set_object"}
    objects.update({c["path"]: objects[c["source"]] for c in commands if c["type"] == "clone"})
    placed = {c["path"]: np.asarray(c["matrix"], float).reshape(4, 4).T for c in commands
              if c["type"] == "set_transform"}
    tracks = _tracks(commands)
    assert not any(p.startswith("/meshcat/run0/footsteps/2") for p in objects)
    lift, land = {0: 4, 1: 14}, {0: 12, 1: None}  # first frames at or after the times
    for j, step in enumerate(FOOTSTEPS[:2]):
        node = f"/meshcat/run0/footsteps/{j}"
        yaw = step["yaw_rad"]
        np.testing.assert_allclose(placed[node][:3, 3], [*step["target_xy_m"], 0.02], atol=1e-9)
        np.testing.assert_allclose(placed[node][:2, :2], [[np.cos(yaw), -np.sin(yaw)],
                                                          [np.sin(yaw), np.cos(yaw)]], atol=1e-9)
        fill = objects[f"{node}/fill"]["object"]
        vertices = np.frombuffer(fill["geometries"][0]["data"]["attributes"]["position"]["array"]
                                 .data, np.float32).reshape(-1, 3)
        half = robot.contact(step["contact"]).spec.half_size
        np.testing.assert_allclose(np.abs(vertices[:, :2]), np.tile(half, (4, 1)), rtol=1e-6)
        color = COLORS["recovery" if step["recovery"] else "footstep"]
        for part in ("outline", "fill"):
            assert objects[f"{node}/{part}"]["object"]["materials"][0]["color"] == color
        shown = [_at(tracks[node][".visible"], k) for k in range(21)]
        assert shown == [k >= lift[j] for k in range(21)], j
        filled = [_at(tracks[f"{node}/fill"][".visible"], k) for k in range(21)]
        assert filled == [land[j] is not None and k >= land[j] for k in range(21)], j


def test_footsteps_for_another_number_of_runs_are_refused(standing_talos, tmp_path):
    """No footsteps, no footstep drawn; footsteps for a different number of recordings are
    refused."""
    html = write_replay(tmp_path / "replay.html", [standing_talos]).read_text()
    assert json.loads(_element(html, "wb-settings"))["footsteps"] == [[]]
    assert not any("/footsteps/" in c.get("path", "") for c in _commands(html))
    with pytest.raises(ValueError, match="2 footstep lists for 1 recordings"):
        build_commands([standing_talos], [FOOTSTEPS, FOOTSTEPS])


@pytest.mark.parametrize(("metrics", "expected"), [
    ({"steps": 8, "footsteps": [{"contact": "a"}]}, [[{"contact": "a"}]]),  # walk
    ({"steps_taken": 1, "steps": [{"contact": "b"}]}, [[{"contact": "b"}]]),  # push-step
    ({"angles": {"0": {"footsteps": [{"contact": "a"}]}, "90": {"footsteps": []}}},
     [[{"contact": "a"}], []]),  # walk-push: one run per angle, in order
    ({"angles": {"0": {"steps": [{"contact": "b"}]}}}, [[{"contact": "b"}]]),  # push-step angles
    ({"angles": {"0": {"strongest_survived_dv_mps": 0.5, "trials": []}}}, []),  # a bisection
    ({"duration": 4.0}, []),
])
def test_summary_footsteps(metrics, expected):
    assert summary_footsteps({"metrics": metrics}) == expected


def test_a_replay_opens_at_the_first_frame_whose_feet_carry_load():
    """HyQ's twin starts with its feet not yet pressing on the floor (the first frame's contact
    forces are zero, nothing to draw): the page opens at the first frame where the simulator's
    contact forces hold a share of the weight, not at t = 0."""
    from wholebody.report.replay import opening_frame

    import wholebody as wb

    robot = wb.load_robot("hyq")
    recorder = ReplayRecorder(fps=FPS)
    run_closed_loop(Simulator(robot, observers=[recorder]), StandingController(robot), DURATION)
    (rec,) = recorder.recordings
    forces = np.linalg.norm(rec.arrays()["contact_forces"], axis=2).sum(axis=1)
    weight = robot.mass * 9.81
    k = opening_frame(rec)
    assert forces[0] < 0.05 * weight  # the case this is for
    assert k > 0 and forces[k] > 0.05 * weight and np.all(forces[:k] < 0.05 * weight)
    _, settings = build_commands([rec])
    assert settings["opening"] == pytest.approx(k * rec.frame_period)
