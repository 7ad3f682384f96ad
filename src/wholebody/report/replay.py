"""``replay.html``: one self-contained page that replays recorded simulations in 3D.

The scene is built with meshcat (its three.js viewer and animation player, ``main.min.js``, are
embedded in the page): the robot's URDF visual meshes loaded by Pinocchio's ``MeshcatVisualizer``,
the twin's environment geoms (floor, boxes, ramps, platform, board), contact forces and pushes as
arrows, CoM, CoP and capture-point markers, the footsteps of a walking run as sole outlines on the
floor, all animated by one meshcat ``set_animation`` command (built by
:class:`~wholebody.report.animation_tracks.TrackAnimation`, which keeps the keyframes as numbers).
No meshcat server runs: the viewer's commands are recorded by :class:`_CommandLog`, packed with
msgpack, gzipped and embedded in base64; the page
unpacks them with the browser's ``DecompressionStream`` and feeds them to
``viewer.handle_command_bytearray``. Opens from disk, no network.

Sizes are robot-relative: ``h`` is the robot's standing base height (``robot.q_ref[2]``), ``W`` its
weight; a contact force of ``W`` is drawn ``FORCE_LENGTH h`` long, a push ``PUSH_GAIN`` times
longer.
The capture point is CoM_xy + v_xy / omega, omega = sqrt(g / z_c), z_c the CoM's height above the
lowest loaded contact point, v the CoM velocity from central differences of the recorded frames.
The footsteps come from ``summary.json`` (:func:`summary_footsteps`).
Several recordings (a comparison of two controllers) are laid out side by side along y.
"""

from __future__ import annotations

import base64
import gzip
import hashlib
import logging
import math
import struct
import warnings
import xml.etree.ElementTree as ElementTree
from importlib import resources
from pathlib import Path
from typing import Sequence

import numpy as np
import pinocchio as pin

from ..sim.recorder import Recording
from .animation_tracks import TrackAnimation
from .replay_page import page

log = logging.getLogger(__name__)

MAX_RUNS = 2  # simulations one replay shows (side by side): a single run or a comparison
FORCE_LENGTH = 0.75  # arrow length of a contact force equal to the robot's weight, in h
PUSH_GAIN = 4.0  # pushes are drawn this many times longer than contact forces
LANE_SPACING = 1.5  # least distance between side-by-side runs, in h
FOV_DEG = 35.0  # vertical field of view of the camera
FRAME_FILL = 0.8  # the motion fills this fraction of the view (height or width)
CAMERA_AZIMUTH_DEG, CAMERA_ELEVATION_DEG = -45.0, 18.0  # from the robot's front-right, above
FLOOR_SIZE = 20.0  # side of the drawn floor, in h
GRID_CELL = 0.5  # side of the grid cells drawn on the floor and the scene's boxes, in h
SHOWN_INCIDENTS = 8  # incidents listed on the page (summary.json has them all)
COLORS = {"contact": 0x2f6fdf, "push": 0xd02090, "com": 0xe02020, "cop": 0x10a040,
          "capture_point": 0x8a2be2, "footstep": 0x0097a7, "recovery": 0xf57c00,
          "floor": 0xd8d8dc}
SOLE_LINE = 0.008  # width of a footstep's outline, in h
LANDED_OPACITY = 0.45  # of a landed footstep's fill
#: what the page draws of each footstep (summary.json's rows carry more)
FOOTSTEP_KEYS = ("contact", "lift_off_s", "touchdown_s", "recovery", "target_xy_m", "yaw_rad")


COMMAND, CLONE = b"\x00", b"\x01"  # record kinds of the page's data


class _CommandLog:
    """A meshcat window that keeps the packed commands instead of sending them to a server. An
    object identical to one already sent (the same mesh on a left and a right link, every mesh of
    a second run) becomes a ``CLONE`` record ``source path, new path``: the page clones the
    three.js object (shared geometry) instead of parsing the mesh again."""

    def __init__(self):
        self.records: list[bytes] = []
        self._objects: dict[bytes, str] = {}

    def send(self, command) -> None:
        import umsgpack

        data = command.lower()
        if data.get("type") == "set_object":
            key = _fingerprint(data["object"])
            if key in self._objects:
                self.records.append(CLONE + f"{self._objects[key]}\n{data['path']}".encode())
                return
            self._objects[key] = data["path"]
        self.records.append(COMMAND + umsgpack.packb(data, force_float_precision="single"))


def _fingerprint(obj) -> bytes:
    """A hash of a three.js object's JSON with its uuids numbered in order of appearance."""
    import umsgpack

    uuids: dict[str, int] = {}

    def walk(x):
        if isinstance(x, dict):
            return {k: uuids.setdefault(v, len(uuids)) if k in _UUID_KEYS and isinstance(v, str)
                    else walk(v) for k, v in x.items()}
        if isinstance(x, list):
            return [walk(v) for v in x]
        return x
    return hashlib.sha256(umsgpack.packb(walk(obj))).digest()


_UUID_KEYS = {"uuid", "geometry", "material", "map", "image"}


def robot_visuals(robot) -> tuple[pin.Model, pin.GeometryModel]:
    """``robot``'s model rebuilt with its URDF visual geometry (meshes found through the URDF's
    parent folders and example-robot-data's as package directories), locked joints merged as in
    ``robot.model``; if a mesh cannot be found, the robot's own model with a stick figure
    (:func:`stick_figure`, a warning says why)."""
    from ..robots.locate import example_robot_data_dir, resolve_model_path

    d = robot.description
    source = getattr(robot, "source", None)
    if source is not None and source.format != "urdf":
        log.info("replay: the robot's model file is %s, whose meshes the replay does not read; "
                 "the robot is drawn as a stick figure", source.format.upper())
        return robot.model, stick_figure(robot)
    urdf = resolve_model_path(d.urdf, d.base_dir)
    root = () if source is not None and source.own_floating_joint else (pin.JointModelFreeFlyer(),)
    full = pin.buildModelFromUrdf(str(urdf), *root)
    packages = [str(p) for p in urdf.parents] + [str(example_robot_data_dir().parents[1])]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            visual = pin.buildGeomFromUrdf(full, str(urdf), pin.GeometryType.VISUAL,
                                           package_dirs=packages)
    except ValueError as exc:  # Pinocchio's "Mesh ... could not be found"
        log.warning("replay: %s; the robot is drawn as a stick figure", str(exc).rstrip("."))
        return robot.model, stick_figure(robot)
    model = full
    if d.locked_joints:
        posture = type(robot).full_posture(full, d)  # the posture robot.model was reduced at
        lock = [full.getJointId(j) for j in d.locked_joints]
        model, (visual,) = pin.buildReducedModel(full, [visual], lock, posture)
    if list(model.names) != list(robot.model.names):
        raise RuntimeError(f"robot '{robot.name}': the visual model's joints differ from the "
                           f"robot's")
    return model, visual


#: Collada primitives that three.js's ColladaLoader makes meshes of (lines are drawn apart)
_COLLADA_MESH_PRIMITIVES = {"triangles", "polylist", "polygons", "trifans", "tristrips"}


def collada_drawable(path) -> bool:
    """Whether meshcat's viewer can draw the Collada file ``path``: it merges the file's meshes
    into one geometry, which fails (and, unguarded, stops the page) unless they all carry the same
    vertex attributes (ANYmal C's ``base.dae``: five parts without texture coordinates, one
    with)."""
    try:
        root = ElementTree.parse(path).getroot()
    except (ElementTree.ParseError, OSError):
        return False
    ns = root.tag[:root.tag.index("}") + 1] if root.tag.startswith("{") else ""
    kinds = set()
    for mesh in root.iter(f"{ns}mesh"):
        shared = {i.get("semantic") for v in mesh.iter(f"{ns}vertices")
                  for i in v.findall(f"{ns}input")}
        for primitive in mesh:
            if primitive.tag[len(ns):] not in _COLLADA_MESH_PRIMITIVES:
                continue
            semantics = set()
            for i in primitive.findall(f"{ns}input"):
                semantic = i.get("semantic")
                semantics |= shared if semantic == "VERTEX" else {semantic + (i.get("set") or "")}
            kinds.add(frozenset(semantics))
    return len(kinds) <= 1


def _draw_from_triangles(visual: pin.GeometryModel) -> set[int]:
    """Geometry objects whose mesh file meshcat cannot draw (:func:`collada_drawable`) are sent as
    the triangles Pinocchio loaded instead (already scaled, in the URDF material's colour): their
    mesh path is cleared, which makes ``MeshcatVisualizer`` use the loaded geometry. Returns their
    indices."""
    undrawable, drawable = set(), {}  # a file shared by several links is read once
    for gid, g in enumerate(visual.geometryObjects):
        if not g.meshPath.lower().endswith(".dae"):
            continue
        if g.meshPath not in drawable:
            drawable[g.meshPath] = collada_drawable(g.meshPath)
        if not drawable[g.meshPath]:
            log.info("replay: %s drawn from its triangles (meshcat cannot merge its parts)",
                     g.meshPath)
            g.meshPath = ""
            undrawable.add(gid)
    return undrawable


def stick_figure(robot) -> pin.GeometryModel:
    """Capsules along the bones of :func:`~wholebody.sim.twin.skeleton_segments` on
    ``robot.model``, the live view's stick figure, for a robot whose meshes cannot be drawn."""
    import coal

    from ..sim.twin import SKELETON_RADIUS, SKELETON_RGBA, skeleton_segments

    radius = SKELETON_RADIUS * float(robot.q_ref[2])
    figure = pin.GeometryModel()
    for j, k, end in skeleton_segments(robot):
        length = float(np.linalg.norm(end))
        placement = pin.SE3(_turn_to(end, axis=(0.0, 0.0, 1.0)), 0.5 * end)  # a capsule: along z
        bone = pin.GeometryObject(f"bone_{robot.model.names[j]}_{k}", j, placement,
                                  coal.Capsule(radius, length))
        bone.meshColor = np.array(SKELETON_RGBA)
        figure.addGeometryObject(bone)
    return figure


def _homogeneous(position, quaternion_wxyz=None, rotation=None) -> np.ndarray:
    T = np.eye(4)
    if rotation is not None:
        T[:3, :3] = rotation
    elif quaternion_wxyz is not None:
        w, x, y, z = quaternion_wxyz
        T[:3, :3] = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
    T[:3, 3] = position
    return T


def _turn_to(direction: np.ndarray, axis=(0.0, 1.0, 0.0)) -> np.ndarray:
    """A rotation taking ``axis`` (default y: three.js cylinders) to ``direction``."""
    n = np.linalg.norm(direction)
    if n == 0:
        return np.eye(3)
    return pin.Quaternion.FromTwoVectors(np.asarray(axis, float),
                                         direction / n).toRotationMatrix()


class _Arrow:
    """An arrow node ``path`` (shaft + head along its y axis) animated frame by frame."""

    def __init__(self, vis, path: str, radius: float, color: int):
        import meshcat.geometry as mg

        self.path, self.radius = path, radius
        self.head = 5.0 * radius
        material = mg.MeshPhongMaterial(color=color, depthTest=False)
        vis[f"{path}/shaft"].set_object(mg.Cylinder(1.0, radius), material)
        vis[f"{path}/head"].set_object(mg.Cylinder(self.head, radiusTop=0.0,
                                                   radiusBottom=2.2 * radius), material)
        for part in ("shaft", "head"):  # drawn over the robot's meshes
            vis[f"{path}/{part}/<object>"].set_property("renderOrder", 10)

    def frame(self, frame, start: np.ndarray, vector: np.ndarray, shown: bool) -> None:
        length = float(np.linalg.norm(vector))
        shown = shown and length > 2.0 * self.head
        node = frame[self.path]
        node.set_property("visible", "bool", bool(shown))
        node.set_transform(_homogeneous(start, rotation=_turn_to(vector)))
        shaft = max(length - self.head, 1e-6) if shown else 1e-6
        node["shaft"].set_property("position", "vector3", [0.0, 0.5 * shaft, 0.0])
        node["shaft"].set_property("scale", "vector3", [1.0, shaft, 1.0])
        node["head"].set_property("position", "vector3", [0.0, shaft + 0.5 * self.head, 0.0])


def _marker(vis, path: str, geometry, color: int, order: int = 11) -> None:
    """A marker drawn over the robot's meshes (later ``order`` over earlier)."""
    import meshcat.geometry as mg

    vis[path].set_object(geometry, mg.MeshPhongMaterial(color=color, depthTest=False))
    vis[f"{path}/<object>"].set_property("renderOrder", order)


def _scene_geometry(geom, extent: tuple[np.ndarray, np.ndarray]):
    """The meshcat geometry and intrinsic transform of a scene geom (a plane becomes a thin box
    over ``extent``, the xy bounds of the motion plus a margin)."""
    import meshcat.geometry as mg

    s = geom.size
    if geom.kind == "plane":
        lo, hi = extent
        size = hi - lo
        centre = np.r_[0.5 * (lo + hi) - geom.position[:2], -0.005]
        if s[0] > 0 and s[1] > 0:  # a finite plane
            size, centre = 2 * s[:2], np.array([0.0, 0.0, -0.005])
        return mg.Box([float(size[0]), float(size[1]), 0.01]), _homogeneous(centre)
    if geom.kind == "box":
        return mg.Box([float(2 * v) for v in s[:3]]), np.eye(4)
    if geom.kind == "sphere":
        return mg.Sphere(float(s[0])), np.eye(4)
    # cylinder, capsule: along z in MuJoCo, along y in three.js
    return mg.Cylinder(float(2 * s[1]), float(s[0])), _homogeneous(np.zeros(3), rotation=np.array(
        [[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]))


def _extent(recordings: Sequence[Recording], margin: float) -> tuple[np.ndarray, np.ndarray]:
    """xy bounds of the CoM trajectories, widened by ``margin``."""
    com = np.concatenate([np.asarray(r.com)[:, :2] for r in recordings if r.frames])
    return com.min(axis=0) - margin, com.max(axis=0) + margin


def _lane_offsets(recordings: Sequence[Recording], h: float, width: float) -> list[np.ndarray]:
    """Side-by-side placement of several runs along y, apart by the largest of LANE_SPACING h,
    twice the robot's ``width`` and the scene's width plus h / 2."""
    scene = 0.0
    for r in recordings:
        for g in r.geoms:
            if g.kind != "plane":
                scene = max(scene, 2.0 * float(np.max(np.abs(g.size[:3]))))
    spacing = max(LANE_SPACING * h, 2.0 * width, scene + 0.5 * h)
    return [np.array([0.0, i * spacing, 0.0]) for i in range(len(recordings))]


def _camera(recordings, offsets, bounds: tuple[np.ndarray, np.ndarray]) -> dict:
    """Camera target and position that frame every run's motion: the robot's bounding box (at
    the first frame) swept along the CoM trajectories, seen from CAMERA_AZIMUTH/ELEVATION, fitted
    into FRAME_FILL of a 16:9 view."""
    lo, hi = bounds
    com0 = np.asarray(recordings[0].com[0])
    coms = np.concatenate([np.asarray(r.com) + off for r, off in zip(recordings, offsets)])
    lo, hi = coms.min(axis=0) + lo - com0, coms.max(axis=0) + hi - com0
    target = 0.5 * (lo + hi)
    az, el = math.radians(CAMERA_AZIMUTH_DEG), math.radians(CAMERA_ELEVATION_DEG)
    back = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    right = np.cross(-back, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -back)
    tan_v = math.tan(math.radians(FOV_DEG) / 2) * FRAME_FILL
    tan_h = tan_v * 16.0 / 9.0
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])]) - target
    distance = max(float(np.max(corners @ back + np.abs(corners @ up) / tan_v)),
                   float(np.max(corners @ back + np.abs(corners @ right) / tan_h)))
    return {"target": target.tolist(), "position": (target + distance * back).tolist(),
            "fov": FOV_DEG}


def _robot_bounds(model: pin.Model, visual: pin.GeometryModel, q) -> tuple[np.ndarray, np.ndarray]:
    """World bounding box of the robot's visual geometry at ``q``."""
    data, gdata = model.createData(), visual.createData()
    pin.forwardKinematics(model, data, np.asarray(q))
    pin.updateGeometryPlacements(model, data, visual, gdata)
    corners = []
    for g, M in zip(visual.geometryObjects, gdata.oMg):
        geom = g.geometry
        geom.computeLocalAABB()
        a, b = np.asarray(geom.aabb_local.min_), np.asarray(geom.aabb_local.max_)
        box = np.array([[x, y, z] for x in (a[0], b[0]) for y in (a[1], b[1])
                        for z in (a[2], b[2])])
        corners.append(box @ M.rotation.T + M.translation)
    points = np.concatenate(corners)
    return points.min(axis=0), points.max(axis=0)


def support_heights(arrays: dict) -> np.ndarray:
    """Per frame of :meth:`Recording.arrays`, the height of the lowest loaded contact point (NaN
    while nothing is loaded)."""
    z = np.where(arrays["loaded"], arrays["contact_points"][..., 2], np.inf)
    low = z.min(axis=1) if z.shape[1] else np.full(len(z), np.inf)
    return np.where(np.isfinite(low), low, np.nan)


def capture_points(recording: Recording) -> np.ndarray:
    """Per frame, the instantaneous capture point (x, y, z): CoM_xy + v_xy / omega with omega =
    sqrt(g / z_c), z_c the CoM's height above the lowest loaded contact point (z: that point's
    height), v the CoM's velocity from central differences of the frames (second order, also at
    the ends); NaN while nothing is loaded or the CoM is not above the support."""
    arrays = recording.arrays()
    t, com = arrays["t"], arrays["com"]
    if len(t) > 2:
        velocity = np.gradient(com, t, axis=0, edge_order=2)
    elif len(t) == 2:
        velocity = np.gradient(com, t, axis=0)
    else:
        velocity = np.zeros_like(com)
    g = float(np.linalg.norm(recording.robot.model.gravity.linear))
    support = support_heights(arrays)
    height = com[:, 2] - support
    with np.errstate(invalid="ignore", divide="ignore"):
        omega = np.sqrt(g / np.where(height > 0, height, np.nan))
    out = np.empty_like(com)
    out[:, :2] = com[:, :2] + velocity[:, :2] / omega[:, None]
    out[:, 2] = support
    out[~np.isfinite(omega)] = np.nan
    return out


def summary_footsteps(summary: dict) -> list[list[dict]]:
    """The footsteps of each run that a ``summary.json`` records, in the order of the runs:
    ``metrics["footsteps"]`` (``walk``), ``metrics["steps"]`` (``push-step``, one angle), or
    those of each entry of ``metrics["angles"]`` (``walk-push``, ``push-step`` over angles);
    ``[]`` if it records none."""
    def steps(metrics) -> list[dict] | None:
        if not isinstance(metrics, dict):
            return None
        for key in ("footsteps", "steps"):  # walk's "steps" is a count
            if isinstance(metrics.get(key), list):
                return metrics[key]
        return None

    metrics = summary.get("metrics") or {}
    own = steps(metrics)
    if own is not None:
        return [own]
    per_angle = [steps(m) for m in (metrics.get("angles") or {}).values()]
    return per_angle if per_angle and all(s is not None for s in per_angle) else []


def _footstep_shapes(robot, contact: str, h: float):
    """The meshcat geometries of a footstep of ``contact`` (a sole): its outline (a flat frame
    SOLE_LINE h wide along the rectangle's edge) and its fill, in the sole's frame."""
    import meshcat.geometry as mg

    hx, hy = (float(x) for x in robot.contact(contact).spec.half_size)
    w = 0.5 * SOLE_LINE * h
    outer = [[hx + w, hy + w], [-hx - w, hy + w], [-hx - w, -hy - w], [hx + w, -hy - w]]
    inner = [[max(hx - w, 0.0), max(hy - w, 0.0)], [-max(hx - w, 0.0), max(hy - w, 0.0)],
             [-max(hx - w, 0.0), -max(hy - w, 0.0)], [max(hx - w, 0.0), -max(hy - w, 0.0)]]
    vertices = np.array([[x, y, 0.0] for x, y in outer + inner])
    faces = [f for i in range(4) for f in ([i, (i + 1) % 4, 4 + i],
                                           [(i + 1) % 4, 4 + (i + 1) % 4, 4 + i])]
    fill = np.array([[hx, hy, 0.0], [-hx, hy, 0.0], [-hx, -hy, 0.0], [hx, -hy, 0.0]])
    return (mg.TriangularMeshGeometry(vertices, faces),
            mg.TriangularMeshGeometry(fill, [[0, 1, 2], [0, 2, 3]]))


def _draw_footsteps(vis, animation, root: str, robot, footsteps: Sequence[dict],
                    t: np.ndarray, support: np.ndarray, h: float) -> list[dict]:
    """Each footstep's target as an outline of its sole on the floor (at the height of the
    support when it lifted off), shown from its lift-off (planned) and filled from its
    touchdown (landed); recovery steps in their own colour. Animated by visibility keys at the
    first frame, the frames where it changes and the last frame. Returns the footsteps drawn (the
    page's settings: FOOTSTEP_KEYS of each)."""
    import meshcat.geometry as mg

    last, drawn = len(t) - 1, []
    known = np.flatnonzero(np.isfinite(support))
    for j, step in enumerate(footsteps):
        if step.get("contact") not in robot.contact_names or step.get("lift_off_s") is None:
            continue
        if robot.contact(step["contact"]).spec.type == "point":
            continue  # footsteps are of soles
        lift = int(np.searchsorted(t, float(step["lift_off_s"]) - 1e-9))
        if lift > last:
            continue  # planned after the last frame
        touchdown = step.get("touchdown_s")
        land = (int(np.searchsorted(t, float(touchdown) - 1e-9)) if touchdown is not None
                else last + 1)
        before = known[known <= lift]
        z = (support[before[-1]] if len(before) else support[known[0]] if len(known) else 0.0)
        x, y = (float(v) for v in step["target_xy_m"])
        yaw = float(step.get("yaw_rad") or 0.0)
        rotation = np.array([[math.cos(yaw), -math.sin(yaw), 0.0],
                             [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
        color = COLORS["recovery" if step.get("recovery") else "footstep"]
        outline, fill = _footstep_shapes(robot, step["contact"], h)
        path = f"{root}/footsteps/{j}"
        vis[f"{path}/outline"].set_object(outline, mg.MeshBasicMaterial(color=color))
        vis[f"{path}/fill"].set_object(fill, mg.MeshBasicMaterial(
            color=color, opacity=LANDED_OPACITY, depthWrite=False))
        vis[f"{path}/outline"].set_transform(_homogeneous([0.0, 0.0, 0.003 * h]))
        vis[f"{path}/fill"].set_transform(_homogeneous([0.0, 0.0, 0.002 * h]))
        vis[path].set_transform(_homogeneous([x, y, float(z)], rotation=rotation))
        for node, start in ((path, lift), (f"{path}/fill", land)):
            for k in sorted({0, min(start, last), last}):
                animation.at_frame(vis, k)[node].set_property("visible", "bool", k >= start)
        drawn.append({key: step.get(key) for key in FOOTSTEP_KEYS})
    return drawn


def opening_frame(recording: Recording) -> int:
    """The frame a replay opens at: the first where a contact carries load (the twin's first
    step may come before the feet press on the floor: nothing to draw), else the first."""
    loaded = np.flatnonzero(np.asarray(recording.loaded, dtype=bool).reshape(recording.frames, -1)
                            .any(axis=1))
    return int(loaded[0]) if loaded.size else 0


def build_commands(recordings: Sequence[Recording],
                   footsteps: Sequence[Sequence[dict]] | None = None
                   ) -> tuple[list[bytes], dict]:
    """The records (packed meshcat commands, clones) that build and animate the scene of
    ``recordings`` (all of one robot), and the page's settings (time span, frame rate, camera,
    legend, footsteps). ``footsteps``: one list per recording (``summary.json``'s rows, see
    :func:`summary_footsteps`), or None."""
    import meshcat
    import meshcat.geometry as mg
    from pinocchio.visualize import MeshcatVisualizer

    footsteps = list(footsteps or [])
    if footsteps and len(footsteps) != len(recordings):
        raise ValueError(f"replay: {len(footsteps)} footstep lists for {len(recordings)} "
                         f"recordings")
    footsteps = [f for r, f in zip(recordings, footsteps or [()] * len(recordings)) if r.frames]
    recordings = [r for r in recordings if r.frames]
    if not recordings:
        raise ValueError("replay: nothing was recorded (no simulation step)")
    robot = recordings[0].robot
    period = recordings[0].frame_period
    h = float(robot.q_ref[2])
    weight = robot.mass * float(np.linalg.norm(robot.model.gravity.linear))
    window = _CommandLog()
    vis = meshcat.Visualizer(window=window)
    vis["/Axes"].set_property("visible", False)
    vis["/Grid"].set_property("visible", False)  # lines: drawn as the floor's texture instead
    model, visual = robot_visuals(robot)
    from_triangles = _draw_from_triangles(visual)
    data, gdata = model.createData(), visual.createData()
    bounds = _robot_bounds(model, visual, recordings[0].q[0])
    top = float(bounds[1][2] - bounds[0][2])
    offsets = _lane_offsets(recordings, h, float(bounds[1][1] - bounds[0][1]))
    extent = _extent(recordings, 2.0 * h + top)
    lo = np.min([o[:2] for o in offsets], axis=0) + extent[0]
    hi = np.max([o[:2] for o in offsets], axis=0) + extent[1]
    centre = 0.5 * (lo + hi)
    half = np.maximum(0.5 * (hi - lo), 0.5 * FLOOR_SIZE * h)
    lo, hi = centre - half, centre + half
    animation = TrackAnimation(default_framerate=1.0 / period)
    drawn_steps = []
    for i, (rec, offset) in enumerate(zip(recordings, offsets)):
        root = f"run{i}"
        vis[root].set_transform(_homogeneous(offset))
        viz = MeshcatVisualizer(model, None, visual)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            viz.initViewer(viewer=vis)
            viz.loadViewerModel(rootNodeName=f"{root}/robot")
        for w in caught:
            log.warning("replay: %s", w.message)
        visuals = [f"{root}/robot/visuals/{g.name}" for g in visual.geometryObjects]
        for gid, (g, path) in enumerate(zip(visual.geometryObjects, visuals)):
            # the mesh's scale on the object (also resets what a clone copied from its source;
            # loaded triangles are scaled already); the node's transform is the pose alone: the
            # animation sets only its position and quaternion, so a scale left there by
            # loadViewerModel would apply twice
            scale = np.ones(3) if gid in from_triangles else g.meshScale
            vis[f"{path}/<object>"].set_property("scale", [float(x) for x in scale])
            vis[path].set_transform(np.eye(4))
        arrays = rec.arrays()
        moving = {}
        for j, g in enumerate(rec.geoms):
            if g.kind == "plane" and g.body < 0 and i > 0:
                continue  # one floor under every run
            geometry, intrinsic = _scene_geometry(g, (lo - offset[:2], hi - offset[:2]))
            parent = f"{root}/scene" if g.body < 0 else f"{root}/scene/body{g.body}"
            path = f"{parent}/{g.name or j}"
            color = COLORS["floor"] if g.kind == "plane" else _rgb(g.rgba)
            vis[path].set_object(geometry, _material(geometry, color, GRID_CELL * h))
            vis[path].set_transform(_homogeneous(g.position, g.quaternion) @ intrinsic)
            if g.body >= 0:
                moving[g.body] = parent
        r = 0.012 * h
        contacts = [_Arrow(vis, f"{root}/forces/{n}", r, COLORS["contact"])
                    for n in robot.contact_names]
        pushes = [_Arrow(vis, f"{root}/pushes/{j}", 1.3 * r, COLORS["push"])
                  for j in range(arrays["push_forces"].shape[1])]
        _marker(vis, f"{root}/com", mg.Sphere(0.035 * h), COLORS["com"])
        _marker(vis, f"{root}/com_ground", mg.Cylinder(0.004 * h, 0.022 * h), COLORS["com"], 13)
        _marker(vis, f"{root}/cop", mg.Cylinder(0.006 * h, 0.04 * h), COLORS["cop"])
        # between the CoP (larger, under) and the CoM's projection (smaller, over): all three
        # stay visible where they coincide
        _marker(vis, f"{root}/capture_point", mg.Cylinder(0.005 * h, 0.03 * h),
                COLORS["capture_point"], 12)
        flat = _homogeneous(np.zeros(3), rotation=_turn_to(np.array([0.0, 0.0, 1.0])))
        capture = capture_points(rec)
        drawn_steps.append(_draw_footsteps(vis, animation, root, robot, footsteps[i],
                                           arrays["t"], support_heights(arrays), h))
        force_scale = FORCE_LENGTH * h / weight
        for k in range(rec.frames):
            frame = animation.at_frame(vis, k)
            pin.forwardKinematics(model, data, arrays["q"][k])
            pin.updateGeometryPlacements(model, data, visual, gdata)
            for gid, path in enumerate(visuals):
                frame[path].set_transform(gdata.oMg[gid].homogeneous)
            for b, path in moving.items():
                pose = arrays["body_poses"][k, b]
                frame[path].set_transform(_homogeneous(pose[:3], pose[3:]))
            for c, arrow in enumerate(contacts):
                arrow.frame(frame, arrays["contact_points"][k, c],
                            force_scale * arrays["contact_forces"][k, c],
                            bool(arrays["loaded"][k, c]))
            for j, arrow in enumerate(pushes):
                vector = PUSH_GAIN * force_scale * arrays["push_forces"][k, j]
                arrow.frame(frame, arrays["push_points"][k, j] - vector, vector,
                            bool(np.any(arrays["push_forces"][k, j])))
            com, cop = arrays["com"][k], arrays["cop"][k]
            frame[f"{root}/com"].set_transform(_homogeneous(com))
            ground = bool(np.isfinite(cop).all())  # hidden (at the CoM) while nothing is loaded
            for name, point in (("cop", cop), ("com_ground", np.r_[com[:2], cop[2]])):
                point = point + [0.0, 0.0, 0.004 * h] if ground else com
                frame[f"{root}/{name}"].set_property("visible", "bool", ground)
                frame[f"{root}/{name}"].set_transform(_homogeneous(point) @ flat)
            shown = bool(np.isfinite(capture[k]).all())  # hidden (at the CoM) without support
            point = capture[k] + [0.0, 0.0, 0.004 * h] if shown else com
            frame[f"{root}/capture_point"].set_property("visible", "bool", shown)
            frame[f"{root}/capture_point"].set_transform(_homogeneous(point) @ flat)
    window.records.append(COMMAND + animation.packed_command(play=False, repetitions=1))
    t0 = float(recordings[0].t[0])
    frames = max(r.frames for r in recordings)
    pushes = [float(np.linalg.norm(sum((f for _, f in acting), np.zeros(3))))
              for acting in max(recordings, key=lambda r: r.frames).pushes]
    settings = {
        "t0": t0, "frame_period": period, "frames": frames, "duration": (frames - 1) * period,
        "opening": opening_frame(recordings[0]) * period,
        "camera": _camera(recordings, offsets, bounds), "push_magnitude": pushes,
        "runs": [{"label": r.label or f"run {i + 1}", "offset_y": float(o[1])}
                 for i, (r, o) in enumerate(zip(recordings, offsets))],
        "scale": {"weight_N": weight, "weight_length_m": FORCE_LENGTH * h, "push_gain": PUSH_GAIN},
        "colors": {k: f"#{v:06x}" for k, v in COLORS.items() if k != "floor"},
        "footsteps": drawn_steps,
    }
    return window.records, settings


def _grid_image(pixels: int = 64, line: int = 2):
    """A meshcat image of one grid cell (white, grey border), decoded synchronously by three.js
    (pixel data instead of a PNG)."""
    import meshcat.geometry as mg

    rgba = np.full((pixels, pixels, 4), 255, dtype=np.uint8)
    for edge in (slice(0, line // 2), slice(pixels - line + line // 2, pixels)):
        rgba[edge, :, :3] = rgba[:, edge, :3] = 185

    class PixelImage(mg.Image):
        def lower(self, object_data):
            return {"uuid": self.uuid, "url": {"data": rgba.tobytes(), "width": pixels,
                                               "height": pixels, "type": "Uint8Array"}}
    return PixelImage()


def _material(geometry, color: int, cell: float):
    """Phong material of a scene geom; boxes (floor, ramps, boards) carry a grid of ``cell``."""
    import meshcat.geometry as mg

    if not isinstance(geometry, mg.Box):
        return mg.MeshPhongMaterial(color=color)
    repeat = [max(1.0, float(length) / cell) for length in geometry.lengths[:2]]
    texture = mg.ImageTexture(_grid_image(), wrap=[1000, 1000], repeat=repeat, magFilter=1006,
                              minFilter=1006, anisotropy=8)
    return mg.MeshPhongMaterial(color=color, map=texture)


def _rgb(rgba) -> int:
    r, g, b = (int(round(255 * float(np.clip(c, 0, 1)))) for c in rgba[:3])
    return (r << 16) + (g << 8) + b


def pack(records: Sequence[bytes]) -> str:
    """Length-prefixed (uint32, little endian) records, gzipped, in base64."""
    payload = b"".join(struct.pack("<I", len(r)) + r for r in records)
    return base64.b64encode(gzip.compress(payload, compresslevel=9, mtime=0)).decode("ascii")


def unpack(text: str) -> list[dict]:
    """The inverse of :func:`pack`, decoded: meshcat commands, and clones as
    ``{"type": "clone", "source": path, "path": path}``."""
    import umsgpack

    payload = gzip.decompress(base64.b64decode(text))
    out, at = [], 0
    while at < len(payload):
        (n,) = struct.unpack_from("<I", payload, at)
        kind, body = payload[at + 4:at + 5], payload[at + 5:at + 4 + n]
        if kind == CLONE:
            source, path = body.decode().split("\n")
            out.append({"type": "clone", "source": source, "path": path})
        else:
            out.append(umsgpack.unpackb(body))
        at += 4 + n
    return out


def replay_html(recordings: Sequence[Recording], title: str = "",
                incidents: Sequence[dict] | None = None,
                footsteps: Sequence[Sequence[dict]] | None = None) -> str:
    """The self-contained replay page of ``recordings``; ``incidents`` (``summary.json``'s, see
    :mod:`wholebody.sim.incidents`) are listed on it as links to their times; ``footsteps`` (one
    list per recording, see :func:`summary_footsteps`) are drawn on the floor."""
    commands, settings = build_commands(recordings, footsteps)
    settings["title"] = title or recordings[0].robot.name
    settings["incidents"] = list(incidents or ())
    settings["shown_incidents"] = SHOWN_INCIDENTS
    viewer_js = (resources.files("meshcat") / "viewer" / "dist" / "main.min.js").read_text(
        encoding="utf-8")
    return page(viewer_js, settings, pack(commands))


def write_replay(path, recordings: Sequence[Recording], title: str = "",
                 incidents: Sequence[dict] | None = None,
                 footsteps: Sequence[Sequence[dict]] | None = None) -> Path:
    """Write :func:`replay_html` to ``path``; returns the path. ``footsteps``: one list per
    recording (:func:`summary_footsteps` of the run's summary), or None."""
    path = Path(path)
    path.write_text(replay_html(recordings, title, incidents, footsteps), encoding="utf-8")
    log.info("replay: wrote %s (%.1f MB)", path, path.stat().st_size / 1e6)
    return path
