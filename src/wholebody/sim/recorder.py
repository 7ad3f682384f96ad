"""Record what a replay shows, as a :class:`~wholebody.sim.simulator.SimObserver`: every
``1 / fps`` s the robot's configuration, CoM, contact forces (with their points of application), the
overall CoP, the pushes acting, and the poses of the moving scene bodies; once per run, the scene's
geometry (the environment geoms of the MuJoCo twin: floor, boxes, ramps, platform, board).

Numpy only; :mod:`wholebody.report.replay` turns :class:`Recording` objects into an HTML file.
"""

from __future__ import annotations

import logging
import weakref
from dataclasses import dataclass, field

import mujoco
import numpy as np
import pinocchio as pin

log = logging.getLogger(__name__)

#: MuJoCo geom types of the environment that a replay can draw
SCENE_KINDS = {int(mujoco.mjtGeom.mjGEOM_PLANE): "plane", int(mujoco.mjtGeom.mjGEOM_BOX): "box",
               int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
               int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
               int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule"}
#: a contact carries load when its normal force exceeds this fraction of the robot's weight
LOADED_FRACTION = 0.01


@dataclass(frozen=True)
class SceneGeom:
    """One environment geom: ``kind`` (see :data:`SCENE_KINDS`), MuJoCo ``size``, ``rgba``; its
    pose (``position``, ``quaternion`` w, x, y, z) in the world, or relative to moving body
    ``body`` (an index into :attr:`Recording.body_poses`; -1 for a static geom)."""

    name: str
    kind: str
    size: np.ndarray
    rgba: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    body: int = -1


@dataclass
class Recording:
    """One simulation, sampled at frames ``t`` (s): configurations ``q`` (Pinocchio convention),
    ``com``; per contact its force on the robot ``contact_forces`` (world) applied at
    ``contact_points`` (the CoP of a sole, the bottom of a point foot) and whether it is
    ``loaded``; the overall ``cop`` (NaN while nothing is loaded); the pushes acting
    (``push_points``, ``push_forces``, one row per push, zero while a push is off); the poses
    (x, y, z, qw, qx, qy, qz) of the moving scene bodies, and the scene's geoms."""

    robot: object
    label: str
    frame_period: float
    geoms: list[SceneGeom]
    t: list = field(default_factory=list)
    q: list = field(default_factory=list)
    com: list = field(default_factory=list)
    cop: list = field(default_factory=list)
    contact_points: list = field(default_factory=list)
    contact_forces: list = field(default_factory=list)
    loaded: list = field(default_factory=list)
    pushes: list = field(default_factory=list)  # per frame: list of (point, force)
    body_poses: list = field(default_factory=list)

    @property
    def frames(self) -> int:
        return len(self.t)

    def arrays(self) -> dict[str, np.ndarray]:
        """The frames as numpy arrays; ``push_points``/``push_forces`` (frames, pushes, 3)."""
        n = max((len(p) for p in self.pushes), default=0)
        points, forces = np.zeros((self.frames, n, 3)), np.zeros((self.frames, n, 3))
        for k, acting in enumerate(self.pushes):
            for j, (point, force) in enumerate(acting):
                points[k, j], forces[k, j] = point, force
        out = {key: np.asarray(getattr(self, key), dtype=float) for key in
               ("t", "q", "com", "cop", "contact_points", "contact_forces")}
        out["loaded"] = np.asarray(self.loaded, dtype=bool)
        out["push_points"], out["push_forces"] = points, forces
        out["body_poses"] = np.asarray(self.body_poses, dtype=float).reshape(self.frames, -1, 7)
        return out


class ReplayRecorder:
    """A :class:`~wholebody.sim.simulator.SimObserver` that samples each simulation it sees into a
    :class:`Recording` (``recordings``, one per run) every ``1 / fps`` s of simulated time (a
    whole number of steps: ``stride`` steps of the log)."""

    def __init__(self, fps: float = 40.0):
        if not fps > 0:
            raise ValueError(f"fps must be > 0, got {fps}")
        self.fps = float(fps)
        self.recordings: list[Recording] = []
        self._current = lambda: None  # a weak reference to the simulation being recorded

    def start(self, sim) -> None:
        if self.recordings and self.recordings[-1].frames == 0 and self._current() is sim:
            self.recordings.pop()  # a reset before the first step: the run starts over
        self._current = weakref.ref(sim)  # the simulator (and its log) is not kept for the replay
        self._stride = max(1, int(round(1.0 / (self.fps * sim.dt))))
        self._steps = 0
        robot = sim.robot
        self._data = robot.model.createData()
        self._bodies, geoms = _scene(sim)
        self._sites = [sim.twin.contact_sites[n] for n in robot.contact_names]
        self._radii = np.array([c.spec.radius if c.spec.type == "point" else 0.0
                                for c in robot.contacts])
        self._soles = np.array([c.spec.type != "point" for c in robot.contacts])
        self._weight = robot.mass * float(np.linalg.norm(robot.model.gravity.linear))
        self.recordings.append(Recording(robot, sim.label, self._stride * sim.dt, geoms))

    @property
    def stride(self) -> int:
        """Simulation steps per frame (of the last run started)."""
        return self._stride

    def step(self, sim) -> None:
        k, self._steps = self._steps, self._steps + 1
        if k % self._stride:
            return
        rec = self.recordings[-1]
        q, _ = sim.state()
        model = sim.robot.model
        rec.t.append(sim.t)
        rec.q.append(q)
        rec.com.append(pin.centerOfMass(model, self._data, q).copy())
        wrenches = sim.contact_wrenches_array()
        points, loaded = self._contact_points(sim, wrenches)
        rec.contact_points.append(points)
        rec.contact_forces.append(wrenches[:, :3].copy())
        rec.loaded.append(loaded)
        rec.cop.append(self._cop(sim, points, wrenches[:, :3], loaded))
        rec.pushes.append([(np.array(p), np.array(f)) for p, f in sim.active_pushes])
        d = sim.data
        rec.body_poses.append([np.r_[d.xpos[b], d.xquat[b]] for b in self._bodies])

    def controller_result(self, sim, result) -> None:
        """A replay shows the twin only."""

    def _contact_points(self, sim, wrenches: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where each contact force acts (sole: its CoP; point foot: the bottom of the sphere)
        and whether the contact carries load."""
        d = sim.data
        points = np.array([d.site_xpos[s] for s in self._sites]).reshape(-1, 3)
        normals = np.array([d.site_xmat[s].reshape(3, 3)[:, 2] for s in self._sites]).reshape(-1, 3)
        normal_force = np.einsum("ij,ij->i", normals, wrenches[:, :3])
        loaded = normal_force > LOADED_FRACTION * self._weight
        out = points - self._radii[:, None] * np.array([0.0, 0.0, 1.0])
        for i in np.flatnonzero(loaded & self._soles):  # CoP on the sole's plane
            out[i] = points[i] + np.cross(normals[i], wrenches[i, 3:]) / normal_force[i]
        return out, loaded

    def _cop(self, sim, points, forces, loaded) -> np.ndarray:
        """The point of the support plane (through the loaded contacts, normal of the support)
        about which the contact forces have no tangential moment; NaN if nothing is loaded."""
        if not loaded.any():
            return np.full(3, np.nan)
        normal = sim.support_pose()[1][:, 2]
        origin = points[loaded].mean(axis=0)
        total = forces[loaded].sum(axis=0)
        moment = np.cross(points[loaded] - origin, forces[loaded]).sum(axis=0)
        return origin + np.cross(normal, moment) / float(normal @ total)


def _scene(sim) -> tuple[list[int], list[SceneGeom]]:
    """The environment geoms of the twin (every geom not on a robot body) and the ids of the
    moving bodies that carry some of them."""
    m = sim.model
    robot_bodies = sim.twin.bodies()
    bodies: list[int] = []
    geoms = []
    for g in range(m.ngeom):
        body = int(m.geom_bodyid[g])
        if body in robot_bodies:
            continue
        kind = SCENE_KINDS.get(int(m.geom_type[g]))
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"
        if kind is None:
            log.warning("replay: scene geom '%s' of type %d is not drawn", name,
                        int(m.geom_type[g]))
            continue
        index = -1
        if body != 0:
            if body not in bodies:
                bodies.append(body)
            index = bodies.index(body)
        if index < 0:  # static: its pose in the world
            pos = sim.data.geom_xpos[g].copy()
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, sim.data.geom_xmat[g])
        else:
            pos, quat = m.geom_pos[g].copy(), m.geom_quat[g].copy()
        geoms.append(SceneGeom(name, kind, m.geom_size[g].copy(), m.geom_rgba[g].copy(), pos,
                               quat, index))
    return bodies, geoms
