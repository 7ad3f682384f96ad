"""The simulator: step the MuJoCo twin at 1 kHz with joint torques, read state and contact wrenches.

Everything the outside sees is in Pinocchio convention (see :mod:`wholebody.sim.convert`).
Torques are saturated here to the robot's limits tau_min(q), tau_max(q) (the actuators' ctrlrange is
disabled so that MuJoCo never clamps silently); the amount clipped is logged.
"""

from __future__ import annotations

import logging
from collections import deque
from typing import Protocol, Sequence

import mujoco
import numpy as np

from ..robot import Robot, check_vector
from . import convert
from .disturbance import Push
from .environment import Environment
from .mismatch import Mismatch
from .series import RowLog
from .twin import SimOptions, Twin, build_twin

try:
    from .. import _sim_reads
except ImportError:  # built without the compiled parts (see setup.py): the Python reference
    _sim_reads = None

#: the compiled reads of MuJoCo's own structs: built with the headers of the MuJoCo that runs
_DIRECT_READS = (_sim_reads is not None and hasattr(_sim_reads, "contact_wrenches_at")
                 and _sim_reads.mujoco_version == mujoco.mj_version())

#: MuJoCo's (qpos, qvel) -> Pinocchio's (q, v): compiled where built (the same operations as the
#: Python reference :func:`~wholebody.sim.convert.mj_to_pin`, bit for bit), else that reference
_mj_to_pin = convert.mj_to_pin if _sim_reads is None else _sim_reads.mj_to_pin

log = logging.getLogger(__name__)

#: MuJoCo's warnings for a state it cannot integrate; on any of them it resets the simulation
_DIVERGENCE_WARNINGS = (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                        mujoco.mjtWarning.mjWARN_BADQACC)


_PYRAMIDAL = mujoco.mjtCone.mjCONE_PYRAMIDAL


class SimulationDiverged(RuntimeError):
    """MuJoCo found NaN, inf or huge values in the state or its accelerations during a step (and
    reset its data); ``t`` is the simulated time at which that step started."""

    def __init__(self, t: float, what: str):
        self.t = t
        #: what first went wrong before (:class:`~wholebody.sim.incidents.Incident` dicts), filled
        #: in by :meth:`~wholebody.scenarios.base.Scenario.run`; None if nobody watched
        self.incidents: list[dict] | None = None
        super().__init__(f"the simulation diverged at t = {t:.3f} s ({what}): the torques or the "
                         f"robot model drove the state to NaN/inf")


class SimLog(RowLog):
    """Time series recorded by :class:`Simulator`, one float64 row per step (Pinocchio
    convention), each read as an array (steps, ...): ``t``, ``q``, ``v``, ``tau_command``,
    ``tau_applied``, ``contact_wrenches`` (steps, ncontact, 6: world [force; torque about the
    contact frame]) and ``push_force`` (steps, 3: world). Stored as numbers, the fields of a step
    side by side in one row (:class:`~wholebody.sim.series.RowLog`): about 8 bytes per number per
    step, no object per row."""

    FIELDS = ("t", "q", "v", "tau_command", "tau_applied", "contact_wrenches", "push_force")

    def __init__(self, contact_names: Sequence[str], nq: int, nv: int, na: int):
        self.contact_names = tuple(contact_names)
        super().__init__(dict(zip(self.FIELDS, ((), (nq,), (nv,), (na,), (na,),
                                                 (len(self.contact_names), 6), (3,)))))

    def arrays(self) -> dict[str, np.ndarray]:
        """The log as numpy arrays (read-only), and the ``contact_names``."""
        out = super().arrays()
        out["contact_names"] = np.asarray(self.contact_names)
        return out

    def save(self, path) -> None:
        np.savez_compressed(path, **self.arrays())


class SimObserver(Protocol):
    """Watches a :class:`Simulator`: ``start(sim)`` after every reset (the state at t = 0), then
    ``step(sim)`` at the start of every step, when the simulator holds what its log records for
    that step: the state (``sim.t``, ``sim.state()``), the contact wrenches of that state and the
    pushes applied during the step (``sim.active_pushes``); ``controller_result(sim, result)``
    with each control cycle's :class:`~wholebody.formulation.Solution`, from the closed loop
    (:func:`~wholebody.scenarios.loop.run_closed_loop`), before the step that applies it. The
    replay recorder, the live viewer and the incident log are observers; one with
    ``draws_twin = True`` gets a twin with the robot's skeleton geoms (visual only)."""

    def start(self, sim: "Simulator") -> None: ...

    def step(self, sim: "Simulator") -> None: ...

    def controller_result(self, sim: "Simulator", result) -> None: ...


def _as_slice(index: np.ndarray) -> slice | np.ndarray:
    """``index`` as the slice it equals when its entries are consecutive and ascending (a view
    of the same entries), else itself."""
    index = np.asarray(index)
    if index.ndim == 1 and index.size and (np.diff(index) == 1).all():
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


#: how many robot surfaces a ground ray may pass before it gives up (ground_height)
_RAY_PASSES = 64


class Simulator:
    """A MuJoCo twin of ``robot`` with an environment, optional model mismatch and pushes.

    The plant is the exact twin (:mod:`wholebody.sim.twin`) unless the robot's description names
    a ``plant``: the vendor's MJCF, loaded by :func:`wholebody.sim.plant.build_plant` with the
    controller's joints mapped by name (``plant`` says which, for summaries).

    ``observers`` (:class:`SimObserver`) see every reset and step; ``label`` names the run for them
    (e.g. the controller of a comparison). An observer may bring a ``mismatch`` (real-robot
    conditions): it is the twin's, with ``mismatch`` given here on top of it
    (:meth:`Mismatch.on_top_of`)."""

    def __init__(self, robot: Robot, environment: Environment | None = None,
                 mismatch: Mismatch | None = None, options: SimOptions | None = None,
                 record: bool = True, observers: Sequence[SimObserver] = (), label: str = ""):
        self.robot = robot
        self.observers = tuple(observers)
        self.label = label
        self.environment = environment or Environment()
        # a mismatch given here on top of one an observer brings (real-robot conditions)
        brought = next((o.mismatch for o in self.observers
                        if getattr(o, "mismatch", None) is not None), None)
        if mismatch is not None and brought is not None:
            self.mismatch = mismatch.on_top_of(brought)
        else:
            self.mismatch = mismatch or brought or Mismatch()
        self.options = options or SimOptions()
        # an observer that draws the twin itself (the live view) asks for the robot's skeleton
        skeleton = any(getattr(o, "draws_twin", False) for o in self.observers)
        from .plant import build_plant, plant_path

        plant = plant_path(robot)
        if plant is None:
            self.twin: Twin = build_twin(robot, self.environment, self.mismatch, self.options,
                                         skeleton)
        else:  # the vendor's model draws itself
            self.twin = build_plant(robot, plant, self.environment, self.mismatch, self.options)
        twin = self.twin
        #: what is simulated: "exact twin" or "vendor MJCF <file>"
        self.plant = twin.label
        # MuJoCo's qpos of the robot holds the joints' angles (a continuous joint's one angle
        # where Pinocchio's q has its (cos, sin)): 7 + na numbers
        # (a run of consecutive indices is kept as a slice: a view, read without numpy's fancy
        # indexing, per step)
        self._qpos = _as_slice(np.arange(7 + robot.na) if twin.qpos_index is None
                               else twin.qpos_index)
        self._qvel = _as_slice(np.arange(robot.nv) if twin.dof_index is None else twin.dof_index)
        self._ctrl = _as_slice(np.arange(robot.na) if twin.actuator_index is None
                               else twin.actuator_index)
        # None: every actuator's scale is 1 (x * 1.0 is x: nothing to multiply)
        self._ctrl_scale = (None if twin.actuator_scale is None
                            or (np.asarray(twin.actuator_scale) == 1.0).all()
                            else twin.actuator_scale)
        self._held = twin.held_qpos
        self.model = self.twin.model
        self._robot_bodies: frozenset[int] | None = None  # the twin's (ground_height)
        self.data = mujoco.MjData(self.model)
        self.dt = self.model.opt.timestep
        self.record = record
        self._rng = np.random.default_rng(self.mismatch.seed + 1)
        self._pushes: list[Push] = []
        self._push_bodies: list[int] = []
        self._push_offsets: list[np.ndarray] = []
        self._geom_to_contact = {g: i for i, c in enumerate(robot.contact_names)
                                 for g in self.twin.contact_geoms[c]}
        # geom id -> index of the robot contact it belongs to (-1: not a contact geom)
        self._geom_contact = np.full(self.model.ngeom, -1, dtype=np.intp)
        for g, i in self._geom_to_contact.items():
            self._geom_contact[g] = i
        self._geom_owner = self._geom_contact.tolist()
        self._contact_site = np.array([self.twin.contact_sites[n] for n in robot.contact_names],
                                      dtype=np.intp).reshape(-1)
        self._contact_site_ids = self._contact_site.tolist()
        self._options = self.model.opt  # MuJoCo's options, read in place (the cone per step)
        # MuJoCo's data is computed anew by each reset and step: ``_generation`` counts them, and
        # the contact wrenches are kept for the generation they were computed in
        self._generation = 0
        self._wrenches_generation = -1
        self._wrenches = np.zeros((len(robot.contact_names), 6))
        self._tau_given = self._tau_given_bytes = self._tau_checked = None  # see step()
        self._state_key: tuple[bytes, bytes] | None = None  # see state()
        self._state: tuple[np.ndarray, np.ndarray] | None = None
        self._pin_data = robot.model.createData()
        self._platform_body = (None if self.environment.platform is None else
                               mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "platform"))
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, q=None, v=None) -> None:
        """Reset to ``q`` (default: the robot's reference posture resting on the support surface)."""
        robot = self.robot
        if q is None:
            q = robot.q_ref.copy()
            q[2] += self.environment.support_height()
        q = check_vector(q, robot.nq, "q")
        norm = float(np.linalg.norm(q[3:7]))
        if not abs(norm - 1.0) <= 1e-3:
            raise ValueError(f"q[3:7]: the base orientation must be a unit quaternion (x, y, z, w), "
                             f"got norm {norm:.6g}")
        v = np.zeros(robot.nv) if v is None else check_vector(v, robot.nv, "v")
        mujoco.mj_resetData(self.model, self.data)
        self._set_platform(0.0)
        self.data.qpos[self._qpos], self.data.qvel[self._qvel] = self._to_mujoco(q, v)
        for address, value in self._held:
            self.data.qpos[address] = value
        mujoco.mj_forward(self.model, self.data)
        self._generation += 1
        self._delay = deque([np.zeros(robot.na)] * self.mismatch.torque_delay)
        self._lagged = None  # the actuators' torque (Mismatch.torque_bandwidth), from the first
        self.log = SimLog(robot.contact_names, robot.nq, robot.nv, robot.na)
        self.last_clipped = np.zeros(robot.na)
        self.active_pushes: list[tuple[np.ndarray, np.ndarray]] = []
        for observer in self.observers:
            observer.start(self)

    @property
    def t(self) -> float:
        return float(self.data.time)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) of the simulated robot in Pinocchio convention (new arrays). The conversion is
        kept with the bytes of MuJoCo's qpos and qvel it came from: asked again for the same
        numbers (the controller, the simulator's log and a scenario's measures all read the
        state of one step), it is not redone."""
        q, v = self._current_state()
        return q.copy(), v.copy()

    def _current_state(self) -> tuple[np.ndarray, np.ndarray]:
        """The kept (q, v) of :meth:`state`, not copied: read it, do not write to it."""
        qpos, qvel = self.data.qpos[self._qpos], self.data.qvel[self._qvel]
        key = (qpos.tobytes(), qvel.tobytes())
        if key != self._state_key:
            self._state = self._to_pinocchio(qpos, qvel)
            self._state_key = key
        return self._state

    def ground_height(self, x: float, y: float) -> float:
        """Height of the environment's surface under (x, y): the first geom not on the robot
        along a ray cast straight down from above the scene (MuJoCo's ``mj_ray``; a robot geom in
        the way is passed by casting again from where the ray met it, its body excluded); -inf
        where nothing is under (a gap). The terrain map a real robot's planner has."""
        m, d = self.model, self.data
        if self._robot_bodies is None:
            self._robot_bodies = frozenset(self.twin.bodies())
        top = float(m.stat.extent) + float(d.qpos[2]) + abs(float(m.stat.center[2]))
        point, down, hit = np.array([x, y, top]), np.array([0.0, 0.0, -1.0]), np.array([-1],
                                                                                      np.int32)
        exclude = -1
        for _ in range(_RAY_PASSES):
            distance = mujoco.mj_ray(m, d, point, down, None, 1, exclude, hit)
            if hit[0] < 0:
                return -np.inf
            exclude = int(m.geom_bodyid[hit[0]])
            if exclude not in self._robot_bodies:
                return float(point[2] - distance)
            point[2] -= distance  # on the robot's surface, its body excluded from the next cast
        return -np.inf

    def _to_mujoco(self, q, v) -> tuple[np.ndarray, np.ndarray]:
        """(qpos, qvel) of the robot's MuJoCo joints from Pinocchio's (q, v)."""
        robot = self.robot
        if not robot.angles_are_coordinates:  # (cos, sin) pairs -> hinge angles
            q = np.concatenate([np.asarray(q, dtype=float)[:7], robot.joint_angles(q)])
        return convert.pin_to_mj(q, v)

    def _to_pinocchio(self, qpos, qvel) -> tuple[np.ndarray, np.ndarray]:
        """Pinocchio's (q, v) from the robot's MuJoCo (qpos, qvel)."""
        q, v = _mj_to_pin(qpos, qvel)
        robot = self.robot
        if not robot.angles_are_coordinates:  # hinge angles -> (cos, sin) pairs
            full = robot.q_ref.copy()
            full[:7] = q[:7]
            q = robot.with_joint_angles(full, q[7:])
        return q, v

    def acceleration(self) -> np.ndarray:
        """MuJoCo's generalised acceleration of the robot's coordinates (MuJoCo's convention:
        the free joint's linear part is d/dt of its world velocity), in the controller's order."""
        return self.data.qacc[self._qvel].copy()

    # ------------------------------------------------------------------ disturbances
    def add_push(self, push: Push) -> None:
        """Schedule a push (see :class:`Push`)."""
        model = self.robot.model
        if not model.existFrame(push.frame):
            raise ValueError(f"push.frame: '{push.frame}' is not a frame of robot "
                             f"'{self.robot.name}'")
        frame = model.frames[model.getFrameId(push.frame)]
        joint = model.names[frame.parentJoint]
        body = self.twin.joint_bodies[joint]
        local = frame.placement.act(np.asarray(push.offset, dtype=float))
        if self.twin.joint_frames is not None:  # a plant: the joint's frame in the body's
            local = self.twin.joint_frames[joint].act(local)
        self._pushes.append(push)
        self._push_bodies.append(body)
        self._push_offsets.append(local)

    def _apply_pushes(self, t: float) -> np.ndarray:
        """Apply the pushes acting at ``t``; their (point, force) in ``active_pushes`` (world)."""
        if not self._pushes:  # nothing was ever applied: xfrc_applied holds the zeros of reset
            self.active_pushes = []
            return np.zeros(3)
        self.data.xfrc_applied[:] = 0.0
        self.active_pushes = []
        total = np.zeros(3)
        for push, body, local in zip(self._pushes, self._push_bodies, self._push_offsets):
            magnitude = push.magnitude(t)
            if magnitude == 0.0:
                continue
            force = magnitude * push.unit_direction
            point = self.data.xpos[body] + self.data.xmat[body].reshape(3, 3) @ local
            self.data.xfrc_applied[body, :3] += force
            self.data.xfrc_applied[body, 3:] += np.cross(point - self.data.xipos[body], force)
            self.active_pushes.append((point, force))
            total += force
        return total

    def _set_platform(self, t: float) -> None:
        platform = self.environment.platform
        if platform is None or platform.motion is None:
            return
        pose = np.concatenate(platform.motion(t))
        h = 1e-4
        rate = (np.concatenate(platform.motion(t + h)) - np.concatenate(platform.motion(t - h))) / (
            2 * h)
        self.data.qpos[self.twin.platform_qpos] = pose
        self.data.qvel[self.twin.platform_qvel] = rate

    # ------------------------------------------------------------------ stepping
    def step(self, tau) -> None:
        """Advance one time step with the commanded actuated-joint torques ``tau``.
        :class:`SimulationDiverged` (with the time) if MuJoCo cannot integrate the state."""
        robot, mismatch, data = self.robot, self.mismatch, self.data
        # a controller's torque is held over several steps: checked once while the same array
        # holds the same numbers
        if not (tau is self._tau_given and type(tau) is np.ndarray
                and tau.tobytes() == self._tau_given_bytes):
            self._tau_checked = check_vector(tau, robot.na, "tau")
            self._tau_given = tau
            self._tau_given_bytes = tau.tobytes() if type(tau) is np.ndarray else None
        tau = self._tau_checked
        q, v = self._current_state()  # read here; the log copies them
        if mismatch.torque_delay:
            self._delay.append(tau)
            applied = self._delay.popleft()
        else:
            applied = tau
        if mismatch.torque_bandwidth:
            if self._lagged is None:
                self._lagged = np.array(applied, dtype=float)
            self._lagged += mismatch.lag_gain(self.dt) * (applied - self._lagged)
            applied = self._lagged.copy()
        if mismatch.torque_noise:
            applied = applied + self._rng.normal(scale=mismatch.torque_noise, size=robot.na)
        lo, hi = robot.torque_bounds(q)
        if self.twin.torque_lower is not None:  # a plant's own actuator limits
            lo, hi = np.maximum(lo, self.twin.torque_lower), np.minimum(hi, self.twin.torque_upper)
        clipped = applied.clip(lo, hi)
        self.last_clipped = applied - clipped
        data.ctrl[self._ctrl] = clipped if self._ctrl_scale is None else clipped * self._ctrl_scale
        t_start = data.time
        push_force = self._apply_pushes(t_start)
        self._set_platform(t_start)
        if self.record:
            self.log.append(t=t_start, q=q, v=v, tau_command=tau, tau_applied=clipped,
                            contact_wrenches=self._current_wrenches(), push_force=push_force)
        for observer in self.observers:
            observer.step(self)
        self._generation += 1
        mujoco.mj_step(self.model, data)
        if data.time < t_start + 0.5 * self.dt:  # MuJoCo reset its data: it diverged
            raise SimulationDiverged(t_start, self._divergence_reason())

    def _divergence_reason(self) -> str:
        names = {mujoco.mjtWarning.mjWARN_BADQPOS: "positions", mujoco.mjtWarning.mjWARN_BADQVEL:
                 "velocities", mujoco.mjtWarning.mjWARN_BADQACC: "accelerations"}
        bad = [names[w] for w in _DIVERGENCE_WARNINGS if self.data.warning[w].number]
        return "MuJoCo: NaN, inf or huge " + (" and ".join(bad) or "values")

    # ------------------------------------------------------------------ contact forces
    def contact_wrenches_array(self) -> np.ndarray:
        """(ncontact, 6): force on the robot and torque about each contact frame origin (world).

        Each MuJoCo contact of a robot contact geom adds its force (that of MuJoCo's
        ``mj_contactForce``: the contact-frame force in ``efc_force``, rotated to the world, with
        the sign of the force on the robot's geom) and that force's moment about the contact
        frame's origin. Computed once per step (MuJoCo's data changes only when it steps or
        resets) and returned as a copy."""
        return self._current_wrenches().copy()

    def _current_wrenches(self) -> np.ndarray:
        """The kept array of :meth:`contact_wrenches_array`, not copied: read it, do not write
        to it."""
        if self._wrenches_generation != self._generation:
            self._wrenches = self._contact_wrenches()
            self._wrenches_generation = self._generation
        return self._wrenches

    def _contact_wrenches(self) -> np.ndarray:
        """The sums of :meth:`contact_wrenches_array` over MuJoCo's contacts: compiled where built
        for this MuJoCo (``wholebody._sim_reads``, reading MuJoCo's structs in place; the same
        products and sums bit for bit), else :meth:`_contact_wrenches_reference`."""
        d = self.data
        if d.ncon == 0 or not _DIRECT_READS or self._options.cone == _PYRAMIDAL:
            return self._contact_wrenches_reference()
        return _sim_reads.contact_wrenches_at(self.model._address, d._address,
                                              self._geom_contact, self._contact_site)

    def _contact_wrenches_reference(self) -> np.ndarray:
        """The sums of :meth:`contact_wrenches_array` over MuJoCo's contacts in plain floats (the
        reference of the compiled sums): with the few contacts of a robot's feet a loop over
        Python numbers costs less than numpy's per-call overhead (the same products and sums as
        ``frame.T @ f`` and ``np.cross``)."""
        d = self.data
        out = [[0.0] * 6 for _ in self.robot.contact_names]
        n = d.ncon
        if n == 0:
            return np.array(out).reshape(-1, 6)
        if self._options.cone == _PYRAMIDAL:  # the pyramid's forces need MuJoCo's decoding
            return self._contact_wrenches_pyramidal()
        con = d.contact
        owners = self._geom_owner
        geoms, address, dim = con.geom.tolist(), con.efc_address.tolist(), con.dim.tolist()
        frames, points = con.frame.tolist(), con.pos.tolist()
        efc = d.efc_force.tolist()
        site_xpos = d.site_xpos.tolist()
        sites = [site_xpos[s] for s in self._contact_site_ids]
        for k in range(n):
            g1, g2 = geoms[k]
            j, sign = owners[g1], -1.0  # geom1 is the robot's: the force on it is minus MuJoCo's
            if j < 0:
                j, sign = owners[g2], 1.0
            a = address[k]
            if j < 0 or a < 0:  # not a robot contact, or excluded (no force)
                continue
            if dim[k] >= 3:  # normal, two tangential forces (then, condim 4 or 6, torques)
                f0, f1, f2 = efc[a], efc[a + 1], efc[a + 2]
            else:  # condim 1: a normal force only
                f0, f1, f2 = efc[a], 0.0, 0.0
            r = frames[k]  # rows: the contact frame's axes (normal first), world
            fx = sign * (f0 * r[0] + f1 * r[3] + f2 * r[6])
            fy = sign * (f0 * r[1] + f1 * r[4] + f2 * r[7])
            fz = sign * (f0 * r[2] + f1 * r[5] + f2 * r[8])
            p, o = points[k], sites[j]
            lx, ly, lz = p[0] - o[0], p[1] - o[1], p[2] - o[2]
            w = out[j]
            w[0] += fx
            w[1] += fy
            w[2] += fz
            w[3] += ly * fz - lz * fy
            w[4] += lz * fx - lx * fz
            w[5] += lx * fy - ly * fx
        return np.array(out).reshape(-1, 6)

    def _contact_wrenches_pyramidal(self) -> np.ndarray:
        """:meth:`_contact_wrenches` through ``mj_contactForce``, contact by contact."""
        d, m = self.data, self.model
        out = np.zeros((len(self.robot.contact_names), 6))
        buf = np.zeros(6)
        for i in range(d.ncon):
            con = d.contact[i]
            g1, g2 = int(con.geom[0]), int(con.geom[1])
            j, sign = int(self._geom_contact[g1]), -1.0
            if j < 0:
                j, sign = int(self._geom_contact[g2]), 1.0
            if j < 0:
                continue
            mujoco.mj_contactForce(m, d, i, buf)
            force = sign * (con.frame.reshape(3, 3).T @ buf[:3])
            lever = con.pos - d.site_xpos[self._contact_site[j]]
            out[j, :3] += force
            out[j, 3:] += np.cross(lever, force)
        return out

    def contact_wrenches(self) -> dict[str, np.ndarray]:
        """Contact name -> 6D wrench on the robot [force; torque about the contact frame] (world axes)."""
        arr = self.contact_wrenches_array()
        return {n: arr[i] for i, n in enumerate(self.robot.contact_names)}

    def support_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(position, rotation) of the surface the robot starts on: the platform body (its frame is
        the board's top-centre, see :class:`~wholebody.sim.environment.Platform`) if there is one,
        else the floor (origin at ``ground_height``, world axes). Lets a scenario measure the feet
        relative to a moving support (slip, tilt)."""
        if self._platform_body is None:
            return np.array([0.0, 0.0, self.environment.ground_height]), np.eye(3)
        b = self._platform_body
        return self.data.xpos[b].copy(), self.data.xmat[b].reshape(3, 3).copy()

    def contact_frame_poses(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Contact name -> (position, rotation) of the contact frame in the simulator."""
        d = self.data
        return {n: (d.site_xpos[s].copy(), d.site_xmat[s].reshape(3, 3).copy())
                for n, s in self.twin.contact_sites.items()}
