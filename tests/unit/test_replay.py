"""The replay page without a browser: self-contained (nothing fetched from the network), its frames
are the simulator's log subsampled, its robot poses are Pinocchio's forward kinematics; and the
command line refuses --replay/--view where they cannot work, before anything is simulated."""

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
from wholebody.report.replay import collada_drawable, replay_html, robot_visuals, unpack
from wholebody.robots.locate import resolve_model_path
from wholebody.scenarios import SCENARIOS, get_scenario
from wholebody.scenarios.base import Scenario
from wholebody.scenarios.loop import run_closed_loop
from wholebody.sim.recorder import ReplayRecorder
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


def test_observers_need_a_declared_scenario(robots):
    undeclared = next(s for s in SCENARIOS.values() if s.simulations is None)
    with pytest.raises(ValueError, match="does not declare"):
        undeclared.run(robots["hyq"], observers=[ReplayRecorder()])


def _never(*args, **kwargs):
    raise AssertionError("the scenario ran")


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
