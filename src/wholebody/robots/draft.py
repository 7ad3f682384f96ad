"""A first robot description drafted from a model file alone (``wholebody init-robot MODEL``).

From a URDF or an MJCF file, :func:`draft_description` guesses what a description needs and says
what it guessed:

* **feet**: the chains of joints from the floating base to a leaf of the kinematic tree are the
  limbs; in the model's neutral configuration (clipped into the joint limits), the limbs whose
  collision geometry reaches down to within :data:`FOOT_BAND` of the leg length of the lowest one
  are legs, their lowest geometry is the foot (arms, heads and tails are limbs too, but end
  higher);
* **contact type and geometry**: four or more legs: point feet, the sphere's radius and centre
  (``offset`` in the foot's frame); two legs: soles, the rectangle spanned by the foot's lowest
  collision geometry (a box's bottom face, the footprint of spheres at the sole's corners, a mesh's
  bounding box in the frame of the body carrying it: an MJCF's meshes as MuJoCo compiled them, a
  URDF's STL or OBJ files read by MuJoCo's mesh loader), ``offset`` at its centre; a URDF foot
  whose mesh cannot be read (not found, another format) is taken as a point at its frame with
  radius 0 (flagged);
* **posture**: an MJCF keyframe inside the joint limits (one named like "home"/"stand", else the
  first), or an SRDF group state of an ``.srdf`` beside the URDF or in a sibling ``srdf`` folder,
  else a computed one: each foot where it is with the joints at 0 (clipped into their limits) in
  x and y, all at one level, :data:`LEG_HEIGHT_FRACTION` of the shortest leg below the hips
  (soles flat), found by damped least squares within the joint limits from a bent seed;
* **torque limits**: the model file's; a joint without one gets an override placeholder to fill;
* **armature**: the MJCF's comes with the model; a URDF has none (a line to fill is written).

The draft is text (TOML) with a comment on each guessed line; :attr:`Draft.notes` lists them for
the user to check. Nothing here is robot-specific: names only come from the model file.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from xml.sax.saxutils import quoteattr
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from .description import NAME_PATTERN, RobotDescription
from .locate import example_robot_data_dir
from .model_file import ModelSource, captured_stderr, load_model_file
from .mjcf import KEYFRAME_PREFIX


#: a limb is a leg when its lowest point is within this fraction of the leg length of the lowest
FOOT_BAND = 0.15
#: the computed posture's foot height below the leg's first joint, in leg lengths
LEG_HEIGHT_FRACTION = {"point": 0.75, "rectangle": 0.9}
#: collision points within this fraction of the leg length of a foot's lowest point are its sole
SOLE_BAND = 0.03
#: a foot whose sole spans less than this (m) in both directions is a point
POINT_SPAN = 0.03
#: lowest collision points whose extent along one axis is below this (m) are an edge, not a sole
EDGE_SPAN = 1e-3
#: keyframe / group-state names preferred as the standing posture, in this order
POSTURE_NAMES = ("stand", "standing", "home", "half_sitting", "default", "init")


@dataclass
class Geometry:
    """A collision shape in the frame of the Pinocchio joint that moves it: ``points`` (n, 3) with
    a common ``radius`` (a sphere: one point; a capsule: two; a box: eight corners, radius 0)."""

    joint: int
    frame: str  # the body frame carrying it
    points: np.ndarray
    radius: float
    kind: str
    name: str = ""  # the geom's own name (MJCF), if any


@dataclass
class Draft:
    """The drafted description (TOML text and the same as a dict) and what was guessed."""

    text: str
    data: dict
    notes: list[str] = field(default_factory=list)


def _frame_placement(model: pin.Model, name: str) -> tuple[int, pin.SE3]:
    frame = model.frames[model.getFrameId(name, pin.FrameType.BODY)]
    return int(frame.parentJoint), frame.placement


def _box_corners(half) -> np.ndarray:
    return np.array([[sx * half[0], sy * half[1], sz * half[2]]
                     for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])


def _mjcf_geometries(source: ModelSource) -> list[Geometry]:
    import mujoco

    m = source.mujoco_model
    model = source.model
    out = []
    for g in range(m.ngeom):
        if not (m.geom_contype[g] or m.geom_conaffinity[g]):
            continue  # visual only
        body = m.body(int(m.geom_bodyid[g])).name
        if not body or not model.existFrame(body, pin.FrameType.BODY):
            continue
        joint, placement = _frame_placement(model, body)
        pose = placement * pin.SE3(pin.Quaternion(*m.geom_quat[g]).normalized().matrix(),
                                   np.asarray(m.geom_pos[g], float))
        kind, size = int(m.geom_type[g]), m.geom_size[g]
        T = mujoco.mjtGeom
        if kind == T.mjGEOM_SPHERE:
            local, radius, name = np.zeros((1, 3)), float(size[0]), "sphere"
        elif kind == T.mjGEOM_CAPSULE:
            local, radius, name = np.array([[0, 0, -size[1]], [0, 0, size[1]]]), float(size[0]), \
                "capsule"
        elif kind == T.mjGEOM_BOX:
            local, radius, name = _box_corners(size), 0.0, "box"
        elif kind == T.mjGEOM_CYLINDER:
            angles = np.linspace(0, 2 * np.pi, 12, endpoint=False)
            ring = np.c_[size[0] * np.cos(angles), size[0] * np.sin(angles)]
            local = np.vstack([np.c_[ring, np.full(12, z)] for z in (-size[1], size[1])])
            radius, name = 0.0, "cylinder"
        elif kind == T.mjGEOM_MESH:
            centre, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
            local, radius, name = centre + _box_corners(half), 0.0, "mesh"
        else:
            continue
        points = np.array([pose.act(p) for p in local])
        out.append(Geometry(joint, body, points, radius, name, m.geom(g).name))
    return out


def _urdf_geometries(source: ModelSource) -> list[Geometry]:
    model = source.model
    root = ET.parse(source.path).getroot()
    out = []
    for link in root.findall("link"):
        name = link.get("name")
        if not model.existFrame(name, pin.FrameType.BODY):
            continue
        joint, placement = _frame_placement(model, name)
        for col in link.iter("collision"):
            origin = col.find("origin")
            xyz = np.array([float(x) for x in (origin.get("xyz", "0 0 0") if origin is not None
                                               else "0 0 0").split()])
            rpy = np.array([float(x) for x in (origin.get("rpy", "0 0 0") if origin is not None
                                               else "0 0 0").split()])
            pose = placement * pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz)
            geometry = col.find("geometry")
            shape = geometry[0] if geometry is not None and len(geometry) else None
            if shape is None:
                continue
            if shape.tag == "sphere":
                local, radius = np.zeros((1, 3)), float(shape.get("radius"))
            elif shape.tag == "box":
                local = _box_corners(0.5 * np.array([float(x) for x in shape.get("size").split()]))
                radius = 0.0
            elif shape.tag == "cylinder":
                r, length = float(shape.get("radius")), float(shape.get("length"))
                angles = np.linspace(0, 2 * np.pi, 12, endpoint=False)
                ring = np.c_[r * np.cos(angles), r * np.sin(angles)]
                local = np.vstack([np.c_[ring, np.full(12, z)] for z in (-length / 2, length / 2)])
                radius = 0.0
            elif shape.tag == "mesh":
                corners = _mesh_box(shape, source.path)
                kind = "mesh" if corners is not None else "unread mesh"
                local = corners if corners is not None else np.zeros((1, 3))  # its frame's origin
                out.append(Geometry(joint, name, np.array([pose.act(p) for p in local]), 0.0,
                                    kind))
                continue
            else:
                continue
            out.append(Geometry(joint, name, np.array([pose.act(p) for p in local]), radius,
                                shape.tag))
    return out


def _mesh_file(filename: str, urdf: Path) -> Path | None:
    """A URDF mesh reference as a file: ``package://PKG/REST`` in a folder PKG above the URDF (a
    vendor's repository) or in example-robot-data, ``file://`` or a path relative to the URDF's
    folder; None if not found."""
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://"):].partition("/")
        roots = [parent / package for parent in urdf.resolve().parents if parent.name == package]
        roots += [parent.parent / package for parent in urdf.resolve().parents]
        try:
            roots.append(example_robot_data_dir() / package)
        except FileNotFoundError:
            pass
        candidates = [root / rest for root in roots]
    else:
        path = Path(filename[len("file://"):] if filename.startswith("file://") else filename)
        candidates = [path if path.is_absolute() else urdf.parent / path]
    return next((c for c in candidates if c.is_file()), None)


def _mesh_box(shape, urdf: Path) -> np.ndarray | None:
    """The corners of the axis-aligned bounding box of a URDF ``<mesh>`` in its own frame, scaled
    (``scale``); the file read by MuJoCo's mesh loader (STL, OBJ), which re-centres a mesh on its
    inertia and places the geom back where the file has it. None if the file is not found or
    MuJoCo cannot read it (e.g. COLLADA)."""
    import mujoco

    path = _mesh_file(shape.get("filename", ""), urdf)
    if path is None:
        return None
    scale = quoteattr(shape.get("scale", "1 1 1"))
    xml = (f'<mujoco><asset><mesh name="m" file={quoteattr(str(path))} scale={scale}/></asset>'
           f'<worldbody><geom type="mesh" mesh="m"/></worldbody></mujoco>')
    try:
        with captured_stderr(f"mesh {path.name}"):
            m = mujoco.MjModel.from_xml_string(xml)
    except ValueError:
        return None
    start, count = int(m.mesh_vertadr[0]), int(m.mesh_vertnum[0])
    rotation = pin.Quaternion(*m.geom_quat[0]).normalized().matrix()
    vertices = m.mesh_vert[start:start + count] @ rotation.T + m.geom_pos[0]
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    return 0.5 * (low + high) + _box_corners(0.5 * (high - low))


def _neutral(model: pin.Model) -> np.ndarray:
    q = pin.neutral(model)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    for jid in range(2, model.njoints):
        j = model.joints[jid]
        if j.nq == 1:
            q[j.idx_q] = np.clip(0.0, lo[j.idx_q], hi[j.idx_q])
    return q


def _seed(model: pin.Model) -> np.ndarray:
    """A bent start for the posture search: each joint a quarter of the way to its range's middle
    (the whole way when 0 is outside its range)."""
    q = _neutral(model)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    for jid in range(2, model.njoints):
        j = model.joints[jid]
        if j.nq == 1 and np.isfinite(lo[j.idx_q]) and np.isfinite(hi[j.idx_q]):
            mid = 0.5 * (lo[j.idx_q] + hi[j.idx_q])
            q[j.idx_q] = 0.25 * mid if lo[j.idx_q] <= 0.0 <= hi[j.idx_q] else mid
    return q


def _chain(model: pin.Model, joint: int) -> list[int]:
    chain = []
    while joint > 1:
        chain.append(joint)
        joint = model.parents[joint]
    return chain[::-1]


def _world_points(data: pin.Data, g: Geometry) -> np.ndarray:
    return g.points @ data.oMi[g.joint].rotation.T + data.oMi[g.joint].translation


@dataclass
class Foot:
    leaf: int  # the leaf joint
    chain: list[int]
    frame: str
    type: str = "point"
    radius: float = 0.0
    half_size: tuple[float, float] = (0.0, 0.0)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    geometry: str = ""
    length: float = 0.0
    label: str = ""  # the foot geometry's own name, if it has one
    edge: bool = False  # its lowest collision points form an edge (a sole tilted in the posture)


def _find_feet(model: pin.Model, geometries: list[Geometry], notes: list[str]) -> list[Foot]:
    data = model.createData()
    q = _neutral(model)
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    leaves = [j for j in range(2, model.njoints) if j not in set(model.parents[2:])]
    limbs = []
    for leaf in leaves:
        chain = _chain(model, leaf)
        moved = [g for g in geometries if g.joint == leaf]
        if moved:
            lows = [(float(np.min(_world_points(data, g)[:, 2]) - g.radius), g) for g in moved]
            low, _ = min(lows, key=lambda x: x[0])
        else:  # no collision geometry: the lowest frame on the leaf joint
            low = min(float(data.oMf[i].translation[2]) for i, f in enumerate(model.frames)
                      if f.parentJoint == leaf)
        hip = float(data.oMi[chain[0]].translation[2])
        limbs.append((low, leaf, chain, hip - low, moved))
    if not limbs:
        return []
    lowest = min(limb[0] for limb in limbs)
    length = max(limb[3] for limb in limbs if limb[0] - lowest < 1e-9)
    feet = []
    for low, leaf, chain, leg, moved in sorted(limbs, key=lambda x: x[1]):
        if low - lowest > FOOT_BAND * length:
            continue
        foot = Foot(leaf, chain, frame="", length=max(leg, 1e-3))
        if moved:
            foot_geometry = [g for g in moved if float(np.min(_world_points(data, g)[:, 2])
                                                       - g.radius) - low < SOLE_BAND * length]
            foot.frame = foot_geometry[0].frame
            named = {g.name for g in foot_geometry if g.name}
            foot.label = named.pop() if len(named) == 1 else ""
            foot.geometry = ", ".join(sorted({g.kind for g in foot_geometry}))
            _shape_foot(model, data, foot, foot_geometry, low, length)
        else:
            frames = [(float(data.oMf[i].translation[2]), f.name) for i, f in
                      enumerate(model.frames) if f.parentJoint == leaf
                      and f.type == pin.FrameType.BODY]
            foot.frame = min(frames)[1]
            foot.geometry = "none"
        feet.append(foot)
    return feet


def _shape_foot(model, data, foot: Foot, geometry: list[Geometry], low: float,
                length: float) -> None:
    """The foot's sole in its frame's coordinates: the lowest collision points (sphere bottoms)."""
    fid = model.getFrameId(foot.frame, pin.FrameType.BODY)
    frame = data.oMf[fid]
    pts, radii = [], []
    for g in geometry:
        world = _world_points(data, g)
        keep = world[:, 2] - g.radius - low < SOLE_BAND * length
        for p in world[keep]:
            pts.append(frame.actInv(p))
            radii.append(g.radius)
    pts, radii = np.array(pts), np.array(radii)
    span = pts[:, :2].max(axis=0) - pts[:, :2].min(axis=0)
    foot.span = span
    # a sole tilted onto an edge: its lowest points on a line (narrow soles are wider than this)
    foot.edge = bool(len(pts) > 1 and np.sum(span < EDGE_SPAN) == 1)
    if len(pts) == 1 or np.all(span < POINT_SPAN) or foot.edge:
        k = int(np.argmin(pts[:, 2] - radii))
        foot.type, foot.radius = "point", float(radii[k])
        foot.offset = tuple(float(x) for x in pts[k])
        return
    bottom = float(np.min(pts[:, 2] - radii))
    centre = 0.5 * (pts[:, :2].max(axis=0) + pts[:, :2].min(axis=0))
    # spheres at the corners: the sole reaches their outer edges
    half = 0.5 * span + float(np.max(radii))
    foot.type = "rectangle"
    foot.half_size = (float(half[0]), float(half[1]))
    foot.offset = (float(centre[0]), float(centre[1]), bottom)


def _posture(source: ModelSource, feet: list[Foot], notes: list[str]) -> tuple[object, str | None]:
    """(posture value for the TOML, srdf path or None)."""
    model = source.model
    keys = [getattr(k, "key", lambda k=k: k)() for k in model.referenceConfigurations]
    keyframes = [k[len(KEYFRAME_PREFIX):] for k in keys if k.startswith(KEYFRAME_PREFIX)]
    inside = [k for k in keyframes if _within_limits(model, model.referenceConfigurations[
        KEYFRAME_PREFIX + k])]
    if keyframes and not inside:
        notes.append(f"posture: the MJCF keyframes {keyframes} put joints outside their limits: "
                     f"not used")
    if inside:
        chosen = _preferred(inside)
        notes.append(f"posture: the MJCF keyframe '{chosen}' (keyframes: {keyframes}); check "
                     f"that the robot stands in it")
        return KEYFRAME_PREFIX + chosen, None
    if source.format == "urdf":
        for srdf in _srdf_candidates(source.path):
            states = [s.get("name") for s in ET.parse(srdf).getroot().iter("group_state")]
            if states:
                chosen = _preferred(states)
                notes.append(f"posture: the group state '{chosen}' of {srdf} (states: {states})")
                return chosen, str(srdf)
    angles = _computed_posture(model, feet)
    notes.append("posture: computed (no keyframe or SRDF state): the feet where straight legs put "
                 "them, legs bent to a common height; check the knees bend the right way")
    return angles, None


def _within_limits(model: pin.Model, q: np.ndarray) -> bool:
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    return all(lo[j.idx_q] - 1e-9 <= q[j.idx_q] <= hi[j.idx_q] + 1e-9
               for j in model.joints[2:] if j.nq == 1)


def _preferred(names: list[str]) -> str:
    for wanted in POSTURE_NAMES:
        for n in names:
            if n.lower() == wanted:
                return n
    for wanted in POSTURE_NAMES:
        for n in names:
            if wanted in n.lower():
                return n
    return names[0]


def _srdf_candidates(urdf: Path) -> list[Path]:
    folders = [urdf.parent, urdf.parent.parent / "srdf", urdf.parent.parent]
    found = []
    for folder in folders:
        if folder.is_dir():
            found += sorted(folder.glob("*.srdf"))
    same = [p for p in found if p.stem == urdf.stem]
    return same + [p for p in found if p not in same]


def _computed_posture(model: pin.Model, feet: list[Foot]) -> dict[str, float]:
    data = model.createData()
    q = _seed(model)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    # every joint at zero, even one whose range excludes it (a knee held at its stop would put
    # the foot ahead of or behind where the straight leg does)
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    hips = {id(f): data.oMi[f.chain[0]].translation.copy() for f in feet}
    # where each foot is with the legs at zero (hanging straight below their hips)
    below = {id(f): (data.oMf[model.getFrameId(f.frame, pin.FrameType.BODY)]
                     * pin.SE3(np.eye(3), np.array(f.offset))).translation.copy() for f in feet}
    # one sole level for every foot: the hips' mean height less a fraction of the shortest leg
    level = (float(np.mean([h[2] for h in hips.values()]))
             - LEG_HEIGHT_FRACTION[feet[0].type] * min(f.length for f in feet))
    for foot in feet:
        fid = model.getFrameId(foot.frame, pin.FrameType.BODY)
        offset = pin.SE3(np.eye(3), np.array(foot.offset))
        target = np.array([*below[id(foot)][:2], level])
        idx_v = [model.joints[j].idx_v for j in foot.chain]
        flat = foot.type == "rectangle"
        for _ in range(200):
            pin.framesForwardKinematics(model, data, q)
            pose = data.oMf[fid] * offset
            err = np.r_[target - pose.translation,
                        pin.log3(pose.rotation.T) if flat else np.zeros(0)]
            if np.linalg.norm(err) < 1e-6:
                break
            J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
            lin = J[:3] - pin.skew(pose.translation - data.oMf[fid].translation) @ J[3:]
            A = np.vstack([lin, J[3:]]) if flat else lin
            A = A[:, idx_v]
            step = A.T @ np.linalg.solve(A @ A.T + 1e-4 * np.eye(A.shape[0]), err)
            dv = np.zeros(model.nv)
            dv[idx_v] = 0.5 * step
            q = pin.integrate(model, q, dv)  # a continuous joint's (cos, sin) stays on the circle
            for j in foot.chain:
                if model.joints[j].nq == 1:
                    i = model.joints[j].idx_q
                    q[i] = np.clip(q[i], lo[i], hi[i])
    return {model.names[j]: round(_angle(model.joints[j], q), 6) for j in range(2, model.njoints)
            if model.joints[j].nq == 1 or _continuous(model.joints[j])}


def _continuous(joint) -> bool:
    """A URDF continuous joint: one velocity, its angle as (cos, sin) in q."""
    return joint.nq == 2 and joint.nv == 1


def _angle(joint, q: np.ndarray) -> float:
    if _continuous(joint):
        return float(np.arctan2(q[joint.idx_q + 1], q[joint.idx_q]))
    return float(q[joint.idx_q])


QUADRUPED_TAGS = {("left", "front"): "LF", ("right", "front"): "RF", ("left", "hind"): "LH",
                  ("right", "hind"): "RH"}


def _contact_names(model: pin.Model, feet: list[Foot]) -> list[str]:
    """Names from the feet's frames (characters a name may not hold replaced by _)."""
    names = []
    for foot in feet:
        name = re.sub(r"[^A-Za-z0-9 _.+()-]", "_", foot.label or foot.frame).lstrip("_.") or "foot"
        while name in names:
            name += "_"
        names.append(name)
    return names


def draft_description(path: str | Path, name: str | None = None) -> Draft:
    """Draft a description of the robot in the URDF or MJCF file at ``path`` (module docstring);
    DescriptionError when the file cannot be read or has no leg."""
    path = Path(path).expanduser().resolve()
    name = name or re.sub(r"[^A-Za-z0-9 _.+()-]", "_", path.stem)
    if not NAME_PATTERN.fullmatch(name):
        name = "robot"
    where = f"init-robot {path.name}"
    source = load_model_file(RobotDescription(name=name, urdf=str(path), posture={},
                                              contacts=()), where)
    model = source.model
    notes: list[str] = []
    for jid in range(2, model.njoints):
        j = model.joints[jid]
        if j.nv != 1:
            notes.append(f"joint '{model.names[jid]}' ({j.shortname()}) is not a 1-DoF joint")
    geometries = (_mjcf_geometries(source) if source.format == "mjcf"
                  else _urdf_geometries(source))
    feet = _find_feet(model, geometries, notes)
    from .description import DescriptionError

    if not feet:
        raise DescriptionError(f"{where}: no leg found (no joint chain from the floating base)")
    kinds = {f.type for f in feet}
    if len(feet) >= 3 and kinds != {"point"}:  # many feet: points at each foot's lowest point
        for foot in feet:
            if foot.type == "rectangle":
                foot.type, foot.radius = "point", 0.0
                foot.offset = (foot.offset[0], foot.offset[1], foot.offset[2])
        notes.append("contacts: more than two feet: every foot is a point contact")
    if len(feet) == 2 and kinds != {"rectangle"}:
        notes.append("contacts: two feet but not both soles: wholebody's biped scenarios need two "
                     "rectangle contacts; edit the contacts")
    posture, srdf = _posture(source, feet, notes)
    names = _contact_names(model, feet)
    contacts = []
    for foot, cname in zip(feet, names):
        entry = {"name": cname, "frame": foot.frame, "type": foot.type}
        if foot.type == "point":
            entry["radius"] = round(foot.radius, 4)
        else:
            entry["half_size"] = [round(x, 4) for x in foot.half_size]
        if any(abs(x) > 1e-6 for x in foot.offset):
            entry["offset"] = [round(x, 4) for x in foot.offset]
        contacts.append(entry)
        if foot.geometry in ("unread mesh", "none"):
            notes.append(f"contacts: '{cname}': the foot's collision is "
                         f"{'a mesh that could not be read' if foot.geometry != 'none' else 'missing'}"
                         f": a point with radius 0 at frame '{foot.frame}'; give the foot's radius "
                         f"and offset")
        elif foot.edge:
            notes.append(f"contacts: '{cname}': the lowest points of the foot's collision "
                         f"({foot.geometry}) form an edge, not a face, with the joints at zero (a "
                         f"sole tilted, or a frame whose z is not the sole's normal): a point with "
                         f"radius 0 at its lowest point; give the sole (a frame normal to it, "
                         f"half_size, offset) and a posture with the soles flat")
        elif foot.geometry == "mesh":
            notes.append(f"contacts: '{cname}': taken from the bounding box of a mesh; check the "
                         f"size and offset")
    effort = model.effortLimit[6:]
    joints = list(model.names[2:])
    missing = [j for j, e in zip(joints, effort) if not (np.isfinite(e) and e > 0)]
    data = {"name": name, "model": str(path)}
    if srdf:
        data["srdf"] = srdf
    data["posture"] = posture
    data["contacts"] = contacts
    if missing:
        data["torque_limits"] = {"overrides": {j: 0.0 for j in missing}}
        notes.append(f"torque_limits: no effort limit in the model file for {missing}: fill "
                     f"torque_limits.overrides (N m) before loading")
    if source.format == "urdf":
        notes.append("armature: a URDF has none; give the rotors' reflected inertia (armature = "
                     "kg m^2) if known")
    text = _toml(data, source, feet)
    return Draft(text, data, notes)


def _value(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if not float(v).is_integer() else f"{float(v):.1f}"
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v))


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _value(k)


def _toml(data: dict, source: ModelSource, feet: list[Foot]) -> str:
    lines = [f"# drafted by `wholebody init-robot` from {source.path.name} "
             f"({source.format.upper()});",
             "# lines marked CHECK are guesses: check them, then `wholebody check-robot` this file",
             f"name = {_value(data['name'])}",
             f"model = {_value(data['model'])}"]
    if "srdf" in data:
        lines.append(f"srdf = {_value(data['srdf'])}")
    posture = data["posture"]
    if not isinstance(posture, dict):
        lines.append(f"posture = {_value(posture)}  # CHECK: the robot stands in it")
    if source.format == "urdf":
        lines.append("# armature = 0.0  # CHECK: rotor inertia reflected through the gearbox "
                     "(kg m^2)")
    lines.append("")
    if isinstance(posture, dict):
        lines.append("# CHECK: computed posture (feet under the hips, legs bent)")
        lines.append("[posture]")
        lines += [f"{_key(j)} = {_value(a)}" for j, a in posture.items()]
        lines.append("")
    if "torque_limits" in data:
        lines.append("# CHECK: no effort limit in the model file for these joints: fill them (N m)")
        lines.append("[torque_limits.overrides]")
        lines += [f"{_key(j)} = 0.0" for j in data["torque_limits"]["overrides"]]
        lines.append("")
    lines.append("# CHECK: feet found as the lowest collision geometry of each leg")
    for entry, foot in zip(data["contacts"], feet):
        lines.append("[[contacts]]")
        lines += [f"{_key(k)} = {_value(v)}" for k, v in entry.items()]
        lines[-1] += f"  # from: {foot.geometry or 'frame'}"
    return "\n".join(lines) + "\n"
