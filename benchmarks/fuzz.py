"""Fuzz harness: random states through every controller and engine, each solution checked
independently. A tool, not a timed test (tests/unit/test_fuzz.py runs its core on fewer states).

For every (robot, controller, engine, state family) it counts

* ``nan``: torques with a NaN/inf entry;
* ``limit``: torques beyond ``LIMIT_TOLERANCE`` (1e-6 Nm) of the limits the controller enforces,
  ``robot.torque_bounds(q)`` at that state lowered by the controller's overrides;
* ``unflagged``: ``ok`` True but the solution is wrong. For the controllers whose ``qdd``/``lam``
  are meant to satisfy the dynamics (MomentumBalance, PassiveWBC) the equations of motion are
  checked with Pinocchio's RNEA and contact Jacobians computed here, on a Data of their own:
  ``rnea(q, v, qdd)[6:] - J_c[:, 6:]^T lam == tau`` and ``rnea(q, v, qdd)[:6] == J_c[:, :6]^T lam``
  within ``DYNAMICS_TOLERANCE`` times the robot's weight (m g). The quasi-static and standing
  controllers do not compute q̈ (their qdd is zero or absent): finiteness and limits only;
* ``exceptions``: a controller raised on a finite state (the first message is kept);
* the outcomes (SOLVED/FALLBACK/CLIPPED/HELD; a result without ``outcome`` counts ok/not-ok);
* for the cascade controllers (MomentumBalance), the level QPs handed to a backend and the share
  DAQP solved (the rest went to the fallback backend, quadprog, or failed);
* for controllers with two engines, the disagreement on the same state and plan: max
  |τ_python − τ_native|, the fraction of states above 1e-6 Nm and above 1 Nm, and the fraction
  where ``ok`` differs. Every state above 1e-6 Nm (or whose ``ok`` differs) is solved again by
  both engines with (q, v) changed by 1e-12 relative (:func:`perturbed`): if an engine's torque
  then moves by more than 1e-7 Nm the state is *ill-posed* — its solution is not determined to
  1e-6 Nm by double-precision data (nearly dependent active rows in a level QP, or a backend
  that fails on one side of rounding) and no two engines that round differently can agree on
  it. The "well-posed" columns count the disagreements on the other states: the engines are
  meant to agree there to 1e-6 Nm (reported, not a failure of the exit code).

Robots and controllers: talos14 — ``pd`` and ``lqr`` (MomentumBalance, built as the push scenario
builds it: ``scenarios.pushes.controller_options``, all contacts active); hyq — ``passive``
(PassiveWBC on a plan like tests/conftest.py's ``passive_plan``: all four feet, three, or a
diagonal pair in stance) and ``quasi-static`` (the same plan); ``standing`` on both.

State families (every state is a pure function of (seed, robot, family, index), see
:func:`make_state`):

* ``near-upright``: base roll/pitch uniform in ±10°, any yaw, base position within a few cm of the
  reference; joints uniform in the posture ± 0.3 rad intersected with the middle 80 % of their
  limits (the posture's neighbourhood is where the robot operates; the middle 80 % alone would
  put Talos's knee at up to 2.4 rad — a deep crouch — in the "near upright" family); velocities
  normal, 0.3 rad/s on the joints, 0.2 m/s and 0.3 rad/s on the base;
* ``wild``: roll/pitch ±45°, joints uniform over their whole range, base position ±10 cm,
  velocities 3x larger;
* ``beyond-limits``: as near-upright, and on 20 % of the states (drawn) one joint (drawn) is
  beyond its lower or upper limit (drawn) by up to :data:`BEYOND_SPAN` — what a controller sees
  after an overshoot, a fall or an encoder offset;
* ``in-contact``: the robot standing on its feet — base roll/pitch within ±5°, joints drawn
  around the posture, then moved (Gauss-Newton on the contact frames' Jacobians, within the
  limits) until every contact is where it stands in the posture (turned with the base's yaw),
  and the velocity projected so that no contact moves (``J_c v = 0``). The other two families
  put the soles wherever the joints take them (on talos14 near-upright, the worse sole tilted by
  26° in the median, the soles 3.5 cm apart in height), which no standing robot meets.

PassiveWBC is built afresh for every state (0.3-0.8 ms): its stance anchors (eq. 32) and warm
start would otherwise carry one random state into the next. MomentumBalance (the LQR costs
~20 ms to build) and the stateless controllers are built once per chunk.

    OPENBLAS_NUM_THREADS=1 python benchmarks/fuzz.py --states 2000 [--seed 0]
        [--robots talos14 hyq] [--controllers pd lqr passive quasi-static standing]
        [--families near-upright wild in-contact beyond-limits] [--engines python native] [--jobs 1]
        [--json OUT]

``--states`` counts per robot and family; the exit code is 1 when any NaN, limit violation,
unflagged failure or exception was counted. The disagreement table's "both S" column counts the
states above 1e-6 Nm where both engines report SOLVED (the rest involve a fallback, clip or hold).
    python benchmarks/fuzz.py --robots hyq --families wild --index 123 [--seed 0]   # one state
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # a benchmark-like tool: one BLAS thread

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from dataclasses import asdict, dataclass, field  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

import wholebody as wb  # noqa: E402
from wholebody.guard import LIMIT_TOLERANCE  # noqa: E402
from wholebody.planning.trunk import TrunkState  # noqa: E402

ROBOTS = ("talos14", "hyq")
FAMILIES = ("near-upright", "wild", "in-contact", "beyond-limits")
#: controllers per robot, each with its engines and whether its qdd/lam satisfy the dynamics
CONTROLLERS = {
    "talos14": {"pd": (("python", "native"), True), "lqr": (("python", "native"), True),
                "standing": (("python",), False)},
    "hyq": {"passive": (("python", "native"), True), "quasi-static": (("python",), False),
            "standing": (("python",), False)},
}
CONTROLLER_NAMES = ("pd", "lqr", "passive", "quasi-static", "standing")
#: equations of motion residual allowed, relative to the robot's weight m g (N, Nm). The joint
#: rows are eq. 14/19 evaluated directly (~1e-12 m g); the floating-base rows hold to the QP's
#: tolerance (DAQP's primal tolerance in the formulation's scaled units, forces in m g).
DYNAMICS_TOLERANCE = 1e-6
DISAGREE_SMALL, DISAGREE_LARGE = 1e-6, 1.0  # Nm
#: relative size of the perturbation of (q, v) that tells a well-posed state from an ill-posed one
PERTURBATION = 1e-12
#: a state is ill-posed when that perturbation moves an engine's torque by more than this (Nm):
#: a tenth of DISAGREE_SMALL, since the two engines' rounding differs by less than PERTURBATION
ILL_POSED = 0.1 * DISAGREE_SMALL
#: well-posed disagreements listed by index in a report (reproduce each with --index)
WELL_POSED_LISTED = 50

#: state families: roll/pitch bound (deg), joint sampling, base position noise (m), velocity factor
FAMILY_SPECS = {
    "near-upright": {"tilt": 10.0, "joints": "posture", "position": 0.02, "speed": 1.0},
    "wild": {"tilt": 45.0, "joints": "range", "position": 0.1, "speed": 3.0},
    "in-contact": {"tilt": 5.0, "joints": "posture", "position": 0.02, "speed": 1.0},
    "beyond-limits": {"tilt": 10.0, "joints": "posture", "position": 0.02, "speed": 1.0,
                      "beyond": 0.2},
}
#: beyond-limits states: a joint outside its range by up to this much (rad)
BEYOND_SPAN = 0.2
#: in-contact states: Gauss-Newton iterations that put the contacts back on the floor, and the
#: largest contact placement error (m, rad) accepted (else the state is drawn again)
CONTACT_ITERATIONS, CONTACT_TOLERANCE, CONTACT_DRAWS = 50, 1e-9, 20
JOINT_SPEED, BASE_SPEED, BASE_RATE = 0.3, 0.2, 0.3  # rad/s, m/s, rad/s (near-upright scale)
POSTURE_SPAN = 0.3  # rad
STANCES = {  # hyq plan stance patterns (legs lf, rf, lh, rh)
    "all": [(True, True, True, True)],
    "three": [(False, True, True, True), (True, False, True, True), (True, True, False, True),
              (True, True, True, False)],
    "diagonal": [(True, False, False, True), (False, True, True, False)],
}


# ------------------------------------------------------------------------------------ states
def state_rng(seed: int, robot_name: str, family: str, index: int) -> np.random.Generator:
    """The generator of state ``index`` (independent of every other state)."""
    return np.random.default_rng([int(seed), ROBOTS.index(robot_name), FAMILIES.index(family),
                                  int(index)])


def joint_box(robot, family: str) -> tuple[np.ndarray, np.ndarray]:
    """The box the joints of ``family`` are drawn from (uniformly)."""
    lo = np.where(np.isfinite(robot.q_min), robot.q_min, -np.pi)
    hi = np.where(np.isfinite(robot.q_max), robot.q_max, np.pi)
    if FAMILY_SPECS[family]["joints"] == "range":
        return lo, hi
    span = hi - lo
    posture = robot.q_ref[7:]
    a = np.maximum(posture - POSTURE_SPAN, lo + 0.1 * span)
    b = np.minimum(posture + POSTURE_SPAN, hi - 0.1 * span)
    empty = a > b  # posture outside the middle 80 %: its neighbourhood within the limits
    a[empty] = np.maximum(posture - POSTURE_SPAN, lo)[empty]
    b[empty] = np.minimum(posture + POSTURE_SPAN, hi)[empty]
    return a, b


def sample_state(robot, family: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(q, v) of ``family`` (Pinocchio convention) drawn with ``rng``."""
    spec = FAMILY_SPECS[family]
    q = robot.q_ref.copy()
    q[:3] += rng.normal(scale=spec["position"], size=3)
    tilt = math.radians(spec["tilt"])
    roll, pitch = rng.uniform(-tilt, tilt, size=2)
    yaw = rng.uniform(-math.pi, math.pi)
    quat = pin.Quaternion(pin.rpy.rpyToMatrix(roll, pitch, yaw)).normalized()
    q[3:7] = quat.coeffs()  # (x, y, z, w)
    lo, hi = joint_box(robot, family)
    q[7:] = rng.uniform(lo, hi)
    k = spec["speed"]
    v = np.concatenate([rng.normal(scale=k * BASE_SPEED, size=3),
                        rng.normal(scale=k * BASE_RATE, size=3),
                        rng.normal(scale=k * JOINT_SPEED, size=robot.na)])
    if rng.uniform() < spec.get("beyond", 0.0):
        q[7:] = joint_beyond_limit(robot, q[7:], rng)
    return q, v


def joint_beyond_limit(robot, joints: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``joints`` with one joint of finite range (drawn uniformly) moved beyond its lower or
    upper limit (drawn) by up to :data:`BEYOND_SPAN` (uniform)."""
    bounded = np.flatnonzero(np.isfinite(robot.q_min) & np.isfinite(robot.q_max))
    joints = joints.copy()
    j = bounded[rng.integers(bounded.size)]
    past = rng.uniform(0.0, BEYOND_SPAN)
    joints[j] = robot.q_max[j] + past if rng.integers(2) else robot.q_min[j] - past
    return joints


def contact_targets(robot, yaw: float) -> dict:
    """{frame id: placement} of every contact in the posture, turned by ``yaw`` about the
    vertical through the origin (the floor is z = 0 there)."""
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, robot.q_ref)
    turn = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.zeros(3))
    return {c.frame_id: turn * data.oMf[c.frame_id] for c in robot.contacts}


def put_contacts_on_floor(robot, q: np.ndarray, targets: dict) -> tuple[np.ndarray, float]:
    """``q`` with its joints (the base stays) moved so that every contact frame reaches its
    target placement (position and orientation for a sole, position for a point foot), by
    Gauss-Newton on Pinocchio's frame Jacobians within the joint limits → (q, largest error)."""
    model, data = robot.model, robot.model.createData()
    dims = {c.frame_id: c.dim for c in robot.contacts}
    error = np.inf
    for _ in range(CONTACT_ITERATIONS):
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        rows, jacobians = [], []
        for frame, target in targets.items():
            e = pin.log6(target.actInv(data.oMf[frame])).vector
            J = pin.getFrameJacobian(model, data, frame, pin.LOCAL)
            if dims[frame] == 3:  # a point foot: its position only (in the frame's axes)
                e, J = e[:3], J[:3]
            rows.append(e)
            jacobians.append(J[:, 6:])
        e, J = np.concatenate(rows), np.vstack(jacobians)
        error = float(np.abs(e).max())
        if error < CONTACT_TOLERANCE:
            break
        q = q.copy()
        q[7:] = np.clip(q[7:] - np.linalg.lstsq(J, e, rcond=None)[0], robot.q_min, robot.q_max)
    return q, error


def sample_in_contact(robot, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(q, v) near the posture with every contact flat on the floor where it stands and the
    velocity moving none of them (``J_c v = 0``): the states a controller meets while the robot
    stands on its feet. The base is drawn as in the near-upright family (tilt ±5°), the joints
    around the posture, then moved to put the contacts back (:func:`put_contacts_on_floor`)."""
    for _ in range(CONTACT_DRAWS):
        q, v = sample_state(robot, "in-contact", rng)
        yaw = float(pin.rpy.matrixToRpy(pin.Quaternion(q[3:7]).toRotationMatrix())[2])
        turn = pin.rpy.rpyToMatrix(0.0, 0.0, yaw)
        q[:3] = turn @ robot.q_ref[:3] + (q[:3] - robot.q_ref[:3])  # the base turns with the feet
        q, error = put_contacts_on_floor(robot, q, contact_targets(robot, yaw))
        if error < CONTACT_TOLERANCE:
            break
    robot.update(q, np.zeros(robot.nv))
    J = robot.stacked_contact_jacobian()
    v = v - np.linalg.pinv(J) @ (J @ v)
    return q, v


def plan_near(robot, rng: np.random.Generator, stance, swing_noise=(0.02, 0.1, 0.5),
              normal=(0.0, 0.0, 1.0)):
    """A PassiveWBC/quasi-static plan at the robot's cached state for ``stance`` (one bool per
    contact): the trunk reference near the current trunk, swing targets near the current feet
    (position, velocity and acceleration drawn with the standard deviations ``swing_noise``),
    touchdown where the feet are, on ground of ``normal``."""
    legs = robot.contact_names
    feet = np.array([robot.data.oMf[robot.contact(n).frame_id].translation for n in legs])
    R = pin.Quaternion(robot.q[3:7]).normalized().toRotationMatrix()
    trunk = TrunkState(position=robot.com + rng.normal(scale=0.01, size=3),
                       velocity=rng.normal(scale=0.05, size=3),
                       acceleration=rng.normal(scale=0.2, size=3),
                       rotation=R @ pin.exp3(rng.normal(scale=0.02, size=3)),
                       angular_velocity=rng.normal(scale=0.05, size=3))
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    position, velocity, acceleration = swing_noise
    return SimpleNamespace(legs=legs, contact=np.array(stance, dtype=bool),
                           foot_position=feet + rng.normal(scale=position, size=feet.shape),
                           foot_velocity=rng.normal(scale=velocity, size=feet.shape),
                           foot_acceleration=rng.normal(scale=acceleration, size=feet.shape),
                           touchdown_position=feet.copy(),
                           touchdown_normal=np.tile(n, (len(legs), 1)), trunk=trunk)


def sample_plan(robot, rng: np.random.Generator):
    """:func:`plan_near` with the stance pattern drawn uniformly among all four feet, three (one
    of four) and a diagonal pair (one of two)."""
    kind = ("all", "three", "diagonal")[rng.integers(3)]
    patterns = STANCES[kind]
    return plan_near(robot, rng, patterns[rng.integers(len(patterns))])


def make_state(robot, family: str, seed: int, index: int):
    """(q, v, plan) of state ``index``: plan None for robots with rectangular soles."""
    rng = state_rng(seed, robot.name, family, index)
    q, v = (sample_in_contact(robot, rng) if family == "in-contact"
            else sample_state(robot, family, rng))
    plan = None
    if all(c.dim == 3 for c in robot.contacts):
        robot.update(q, v)
        plan = sample_plan(robot, rng)
    return q, v, plan


# ------------------------------------------------------------------------------------ controllers
class Runner:
    """One controller with one engine: ``run(q, v, plan) -> result`` and the limits it enforces."""

    def __init__(self, robot, controller: str, engine: str):
        from wholebody.control.balance import MomentumBalance
        from wholebody.control.quasi_static import QuasiStaticController
        from wholebody.control.standing import StandingController
        from wholebody.scenarios.pushes import controller_options
        self.robot, self.controller, self.engine = robot, controller, engine
        self.dynamics = CONTROLLERS[robot.name][controller][1]
        self.override: dict[str, float] = {}
        self._planner = SimpleNamespace(legs=robot.contact_names)
        if controller in ("pd", "lqr"):
            self.ctrl = MomentumBalance(robot, gains=controller,
                                        **controller_options(controller, {"engine": engine}))
        elif controller == "passive":
            self.ctrl = None  # built per state (see the module docstring)
        elif controller == "quasi-static":
            self.ctrl = QuasiStaticController(robot, planner=self._planner)
            self.override = dict(self.ctrl.torque_limits.upper_override)
        elif controller == "standing":
            self.ctrl = StandingController(robot)
        else:
            raise ValueError(f"controller: unknown '{controller}'")

    def run(self, q, v, plan):
        if self.controller == "passive":
            from wholebody.control.passive import PassiveWBC
            ctrl = PassiveWBC(self.robot, planner=self._planner, engine=self.engine)
            self.override = dict(ctrl.torque_limits.upper_override)
            return ctrl.cycle(q, v, plan)
        if self.controller == "quasi-static":
            self.robot.update(q, v)
            return self.ctrl.solve(plan)
        return self.ctrl.compute(q, v, 0.0)

    def limits(self, q) -> tuple[np.ndarray, np.ndarray]:
        """robot.torque_bounds at q, lowered by the controller's overrides."""
        lo, hi = self.robot.torque_bounds(q)
        lo, hi = lo.copy(), hi.copy()
        for joint, cap in self.override.items():
            i = self.robot.joint_names.index(joint)
            hi[i], lo[i] = min(hi[i], cap), max(lo[i], -cap)
        return lo, hi


class DynamicsCheck:
    """Equations of motion at (q, v) from Pinocchio's RNEA and frame Jacobians, on Data of its
    own (nothing shared with the robot's cache or the compiled engines)."""

    def __init__(self, robot):
        self.robot, self.model = robot, robot.model
        self.data = robot.model.createData()
        self.weight = robot.mass * 9.81
        self.tolerance = DYNAMICS_TOLERANCE * self.weight

    def jacobian(self, q) -> np.ndarray:
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        rows = []
        for c in self.robot.contacts:
            J6 = pin.getFrameJacobian(model, data, c.frame_id, pin.LOCAL_WORLD_ALIGNED)
            if c.dim == 6:  # sole: wrench about the sole frame
                rows.append(J6)
            else:  # point under the foot sphere's centre, d = (0, 0, -r) in world axes
                d = np.array([0.0, 0.0, -c.spec.radius])
                rows.append(J6[:3] - pin.skew(d) @ J6[3:])
        return np.vstack(rows)

    def residuals(self, q, v, result) -> tuple[float, float]:
        """(joint rows, floating-base rows) max residual in N/Nm; inf for unusable qdd/lam."""
        qdd = np.asarray(getattr(result, "qdd", None), dtype=float)
        lam = np.asarray(getattr(result, "lam", None), dtype=float)
        robot = self.robot
        J = self.jacobian(q)
        if qdd.shape != (robot.nv,) or lam.shape != (J.shape[0],) or not (
                np.isfinite(qdd).all() and np.isfinite(lam).all()):
            return math.inf, math.inf
        tau_id = pin.rnea(self.model, self.data, q, v, qdd)
        joint = tau_id[6:] - J[:, 6:].T @ lam - np.asarray(result.tau, dtype=float)
        base = tau_id[:6] - J[:, :6].T @ lam
        return float(np.abs(joint).max()), float(np.abs(base).max())


# ------------------------------------------------------------------------------------ statistics
@dataclass
class Stats:
    """Counts of one (robot, controller, engine, family)."""

    robot: str
    controller: str
    engine: str
    family: str
    states: int = 0
    nan: int = 0
    limit: int = 0
    unflagged: int = 0
    exceptions: int = 0
    outcomes: dict = field(default_factory=dict)
    checks_dynamics: bool = False
    max_limit_excess: float = 0.0  # Nm
    max_residual_ok: float = 0.0  # N/Nm, over ok solutions
    seconds: float = 0.0  # in the controller's call
    qps: int = 0  # level QPs handed to a backend (cascade controllers: ``timings["qps"]``)
    daqp_failed: int = 0  # of them, those DAQP did not solve (a fallback then solved, or none)
    first: dict = field(default_factory=dict)  # category -> {"index", "message"}

    def note(self, category: str, index: int, message: str) -> None:
        if category not in self.first or index < self.first[category]["index"]:
            self.first[category] = {"index": int(index), "message": message}

    def merge(self, other: "Stats") -> None:
        for name in ("states", "nan", "limit", "unflagged", "exceptions", "seconds", "qps",
                     "daqp_failed"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        for key, n in other.outcomes.items():
            self.outcomes[key] = self.outcomes.get(key, 0) + n
        self.max_limit_excess = max(self.max_limit_excess, other.max_limit_excess)
        self.max_residual_ok = max(self.max_residual_ok, other.max_residual_ok)
        for category, entry in other.first.items():
            self.note(category, entry["index"], entry["message"])


@dataclass
class Disagreement:
    """python vs native on the same states of one (robot, controller, family)."""

    robot: str
    controller: str
    family: str
    states: int = 0
    max_diff: float = 0.0  # Nm
    above_small: int = 0  # > DISAGREE_SMALL
    above_large: int = 0  # > DISAGREE_LARGE
    ok_differs: int = 0
    above_small_solved: int = 0  # > DISAGREE_SMALL with both engines SOLVED (no fallback, clip)
    # of the states above DISAGREE_SMALL or whose ok differs: those whose solution moves by more
    # than ILL_POSED under a PERTURBATION of (q, v) (:func:`sensitivity`), and the rest
    ill_posed: int = 0
    above_small_well_posed: int = 0
    ok_differs_well_posed: int = 0
    max_diff_well_posed: float = 0.0  # Nm, over every state not found ill-posed
    worst_index: int = -1
    first_ok_differs: int = -1
    first_well_posed: int = -1  # first state above DISAGREE_SMALL that is not ill-posed
    #: the first WELL_POSED_LISTED well-posed states above DISAGREE_SMALL or whose ok differs
    well_posed_indices: list = field(default_factory=list)

    def merge(self, other: "Disagreement") -> None:
        for name in ("states", "above_small", "above_large", "ok_differs", "above_small_solved",
                     "ill_posed", "above_small_well_posed", "ok_differs_well_posed"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.max_diff_well_posed = max(self.max_diff_well_posed, other.max_diff_well_posed)
        if other.max_diff > self.max_diff or self.worst_index < 0:
            self.max_diff, self.worst_index = max(self.max_diff, other.max_diff), other.worst_index
        if other.first_well_posed >= 0 and (self.first_well_posed < 0
                                            or other.first_well_posed < self.first_well_posed):
            self.first_well_posed = other.first_well_posed
        self.well_posed_indices = sorted(self.well_posed_indices
                                         + other.well_posed_indices)[:WELL_POSED_LISTED]
        if other.first_ok_differs >= 0 and (self.first_ok_differs < 0
                                            or other.first_ok_differs < self.first_ok_differs):
            self.first_ok_differs = other.first_ok_differs


def perturbed(q, v, index: int, size: float = PERTURBATION):
    """(q, v) with the joint angles and all velocities scaled by 1 + size ξ (ξ standard normal,
    drawn from ``index``): a change of the problem's data near rounding level."""
    rng = np.random.default_rng([int(index), 12])
    q2, v2 = q.copy(), v * (1.0 + size * rng.standard_normal(v.size))
    q2[7:] *= 1.0 + size * rng.standard_normal(q2.size - 7)
    return q2, v2


def sensitivity(runners, q, v, plan, index: int, taus) -> float:
    """How far the torque of each of ``runners`` moves when (q, v) are :func:`perturbed` (max over
    the engines, Nm; inf if one raises). Above ``ILL_POSED`` the state has no solution that is
    unique at double precision: its torque depends on the rounding of the data (a level QP whose
    active rows are nearly dependent, or a backend that fails on one side of rounding and not
    on the other), and two engines that round differently cannot agree on it."""
    q2, v2 = perturbed(q, v, index)
    worst = 0.0
    for runner in runners:
        try:
            tau = np.asarray(runner.run(q2, v2, plan).tau, dtype=float)
        except Exception:  # noqa: BLE001 - counted by the main pass already
            return math.inf
        diff = float(np.abs(tau - taus[runner.controller, runner.engine][0]).max())
        worst = max(worst, math.inf if diff != diff else diff)
    return worst


#: relative size of the perturbation of a cascade's level arrays in :func:`row_sensitivity`: the
#: engines' level arrays differ by up to ~1e-13 relative (their rigid-body terms round differently)
ROW_PERTURBATION = 1e-13


def row_sensitivity(robot, controller: str, q, v, trials: int = 5, seed: int = 0) -> dict:
    """For a cascade controller (``pd``, ``lqr``) at (q, v): the level arrays of both engines,
    each solved again by the same :func:`~wholebody.formulation.solve_levels` (``reproduce``: how
    far that torque is from the engine's own, Nm; 0 up to round-off says the engines differ only
    through their arrays), and how far the reference's torque moves when its arrays (matrices,
    targets, bounds) are scaled by 1 + ROW_PERTURBATION ξ (``moves``: max and min over
    ``trials``, Nm). A move as large as the engines' difference says the torque is not determined
    by double-precision rows: a perturbation of (q, v) (:func:`sensitivity`) moves the rows along
    the state's own directions only and can miss that."""
    from wholebody.formulation import solve_levels
    from wholebody.solvers import Level
    fields = ("B", "b", "w", "C", "lower", "upper", "v")

    def copied(levels):
        return [Level.trusted(*(np.array(getattr(L, f), float) for f in fields), name=L.name)
                for L in levels]

    runners = {e: Runner(robot, controller, e) for e in ("python", "native")}
    taus = {e: np.asarray(r.run(q, v, None).tau, float) for e, r in runners.items()}
    ctrl = runners["python"].ctrl
    levels = {"python": copied([lp.level for lp in ctrl.formulation._plan.levels]),
              "native": copied(runners["native"].ctrl.cycle.levels)}
    robot.update(q, v)
    scales = ctrl.formulation.scales(ctrl.variables)
    nv, nl = ctrl.variables.nv, ctrl.variables.n_lambda
    J_u = robot.stacked_contact_jacobian(ctrl.variables.contacts)[:, 6:]
    lo, hi = robot.torque_bounds(q)

    def torque(lv):
        x = solve_levels(lv, True, "cascade", "daqp", 1e-6, "quadprog")[0].x * scales
        return np.clip(robot.M[6:] @ x[:nv] + robot.h[6:] - J_u.T @ x[nv:nv + nl], lo, hi)

    out = {"engines": float(np.abs(taus["python"] - taus["native"]).max()),
           "reproduce": {e: float(np.abs(torque(lv) - taus[e]).max())
                         for e, lv in levels.items()}}
    rng = np.random.default_rng([seed, 13])
    moves = []
    for _ in range(trials):
        lv = copied(levels["python"])
        for L in lv:
            for f in ("B", "b", "C", "lower", "upper"):
                a = getattr(L, f)
                finite = np.isfinite(a)
                a[finite] *= 1.0 + ROW_PERTURBATION * rng.standard_normal(int(finite.sum()))
        moves.append(float(np.abs(torque(lv) - taus["python"]).max()))
    out["moves"] = (max(moves), min(moves))
    return out


def daqp_failures(result) -> int:
    """The level QPs of a cascade result that DAQP did not solve: its status names DAQP's
    failure once per such level ("level 2 ('level 3'): daqp: infeasible (-1); solved with
    quadprog")."""
    if "qps" not in getattr(result, "timings", {}):
        return 0
    return str(result.status).count("'): daqp: ")  # after the level's name


def outcome_key(result) -> str:
    outcome = getattr(result, "outcome", None)
    if outcome is not None:
        return outcome.name
    return "ok" if result.ok else "not-ok"


def check(stats: Stats, runner: Runner, dyn: DynamicsCheck, index: int, q, v, result) -> None:
    """Count one result into ``stats``."""
    robot = runner.robot
    key = outcome_key(result)
    stats.outcomes[key] = stats.outcomes.get(key, 0) + 1
    stats.qps += int(getattr(result, "timings", {}).get("qps", 0))
    stats.daqp_failed += daqp_failures(result)
    tau = np.asarray(result.tau, dtype=float)
    if tau.shape != (robot.na,) or not np.isfinite(tau).all():
        stats.nan += 1
        stats.note("nan", index, f"tau {tau!r}, status {result.status!r}")
        return
    lo, hi = runner.limits(q)
    excess = float(max((tau - hi).max(), (lo - tau).max(), 0.0))
    if excess > LIMIT_TOLERANCE:
        stats.limit += 1
        stats.max_limit_excess = max(stats.max_limit_excess, excess)
        joint = robot.joint_names[int(np.argmax(np.maximum(tau - hi, lo - tau)))]
        stats.note("limit", index, f"{excess:.3g} Nm beyond the limits ({joint}), outcome "
                                   f"{key}, status {result.status!r}")
    if runner.dynamics and result.ok:
        joint_res, base_res = dyn.residuals(q, v, result)
        worst = max(joint_res, base_res)
        stats.max_residual_ok = max(stats.max_residual_ok, worst)
        if not worst <= dyn.tolerance:
            stats.unflagged += 1
            stats.note("unflagged", index,
                       f"ok with dynamics residual joint rows {joint_res:.3g}, floating-base "
                       f"rows {base_res:.3g} (N, Nm; tolerance {dyn.tolerance:.3g}), outcome "
                       f"{key}, status {result.status!r}")


# ------------------------------------------------------------------------------------ fuzzing
def fuzz_chunk(robot_name: str, family: str, seed: int, start: int, stop: int,
               controllers=CONTROLLER_NAMES, engines=("python", "native")) -> dict:
    """States ``start``..``stop``-1 of (robot, family) through the selected controllers and
    engines: {"stats": [Stats], "disagreement": [Disagreement]} (plain dicts, picklable)."""
    logging.getLogger("wholebody").setLevel(logging.ERROR)  # failed cycles are counted here
    robot = wb.load_robot(robot_name)
    dyn = DynamicsCheck(robot)
    runners = [Runner(robot, name, engine)
               for name, (engs, _) in CONTROLLERS[robot_name].items() if name in controllers
               for engine in engs if engine in engines]
    stats = {(r.controller, r.engine): Stats(robot_name, r.controller, r.engine, family,
                                             checks_dynamics=r.dynamics) for r in runners}
    pairs = {r.controller for r in runners if r.engine == "native"} & {
        r.controller for r in runners if r.engine == "python"}
    disagreement = {name: Disagreement(robot_name, name, family) for name in sorted(pairs)}
    for index in range(start, stop):
        q, v, plan = make_state(robot, family, seed, index)
        taus = {}
        for runner in runners:
            s = stats[runner.controller, runner.engine]
            s.states += 1
            t0 = time.perf_counter()
            try:
                result = runner.run(q, v, plan)
            except Exception as exc:  # noqa: BLE001 - counted: a controller must not raise
                s.seconds += time.perf_counter() - t0
                s.exceptions += 1
                where = traceback.extract_tb(exc.__traceback__)[-1]
                s.note("exception", index, f"{type(exc).__name__}: {exc} "
                                           f"({os.path.basename(where.filename)}:{where.lineno})")
                continue
            s.seconds += time.perf_counter() - t0
            check(s, runner, dyn, index, q, v, result)
            taus[runner.controller, runner.engine] = (np.asarray(result.tau, float), result.ok,
                                                      outcome_key(result))
        for name, d in disagreement.items():
            a, b = taus.get((name, "python")), taus.get((name, "native"))
            if a is None or b is None:
                continue
            d.states += 1
            diff = float(np.abs(a[0] - b[0]).max())
            diff = math.inf if diff != diff else diff
            if diff > d.max_diff or d.worst_index < 0:
                d.max_diff, d.worst_index = max(diff, d.max_diff), index
            d.above_small += diff > DISAGREE_SMALL
            d.above_large += diff > DISAGREE_LARGE
            d.above_small_solved += diff > DISAGREE_SMALL and a[2] == b[2] == "SOLVED"
            if a[1] != b[1]:
                d.ok_differs += 1
                if d.first_ok_differs < 0:
                    d.first_ok_differs = index
            ill = False
            if diff > DISAGREE_SMALL or a[1] != b[1]:
                pair = [r for r in runners if r.controller == name]
                ill = sensitivity(pair, q, v, plan, index, taus) > ILL_POSED
                d.ill_posed += ill
                if not ill:
                    d.above_small_well_posed += diff > DISAGREE_SMALL
                    d.ok_differs_well_posed += a[1] != b[1]
                    if diff > DISAGREE_SMALL and d.first_well_posed < 0:
                        d.first_well_posed = index
                    if len(d.well_posed_indices) < WELL_POSED_LISTED:
                        d.well_posed_indices.append(int(index))
            if not ill:
                d.max_diff_well_posed = max(d.max_diff_well_posed, diff)
    return {"stats": [asdict(s) for s in stats.values()],
            "disagreement": [asdict(d) for d in disagreement.values()]}


def _chunk(args):
    return fuzz_chunk(*args)


def fuzz(states: int, seed: int = 0, robots=ROBOTS, controllers=CONTROLLER_NAMES,
         families=FAMILIES, engines=("python", "native"), jobs: int = 1, start: int = 0) -> dict:
    """``states`` states per (robot, family), indices ``start`` .. ``start + states - 1``: merged
    {"stats", "disagreement", "wall_time_s"}."""
    t0 = time.perf_counter()
    tasks = []
    for robot_name in robots:
        if not any(c in CONTROLLERS[robot_name] for c in controllers):
            continue
        for family in families:
            edges = start + np.linspace(0, states, max(1, min(jobs, states)) + 1).astype(int)
            tasks += [(robot_name, family, seed, int(a), int(b), tuple(controllers),
                       tuple(engines)) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    if jobs > 1 and len(tasks) > 1:
        import multiprocessing
        with multiprocessing.get_context("spawn").Pool(jobs) as pool:
            parts = pool.map(_chunk, tasks)
    else:
        parts = [_chunk(t) for t in tasks]
    return {"seed": seed, "states_per_family": states, "start": start, **merge(parts),
            "wall_time_s": time.perf_counter() - t0}


def merge(parts) -> dict:
    """{"stats", "disagreement"} of several chunks or reports (of the same seed) summed per
    (robot, controller, engine, family)."""
    stats: dict[tuple, Stats] = {}
    disagreement: dict[tuple, Disagreement] = {}
    for part in parts:
        for entry in part["stats"]:
            s = Stats(**entry)
            key = (s.robot, s.controller, s.engine, s.family)
            stats.setdefault(key, Stats(*key, checks_dynamics=s.checks_dynamics)).merge(s)
        for entry in part["disagreement"]:
            d = Disagreement(**entry)
            key = (d.robot, d.controller, d.family)
            disagreement.setdefault(key, Disagreement(*key)).merge(d)
    return {"stats": [asdict(s) for s in stats.values()],
            "disagreement": [asdict(d) for d in disagreement.values()]}


# ------------------------------------------------------------------------------------ report
def _outcomes(outcomes: dict) -> str:
    order = ("SOLVED", "FALLBACK", "CLIPPED", "HELD", "ok", "not-ok")
    keys = [k for k in order if k in outcomes] + sorted(set(outcomes) - set(order))
    short = {"SOLVED": "S", "FALLBACK": "F", "CLIPPED": "C", "HELD": "H"}
    return " ".join(f"{short.get(k, k)} {outcomes[k]}" for k in keys)


def table(report: dict) -> str:
    """The report as text tables."""
    lines = [f"{'robot':<8} {'controller':<12} {'engine':<7} {'family':<12} {'states':>6} "
             f"{'NaN':>4} {'limit':>5} {'unflag':>6} {'exc':>4} {'ms/state':>8} "
             f"{'level QPs':>9} {'by DAQP':>8}  outcomes (S solved, F fallback, C clipped, H held)"]
    for s in report["stats"]:
        ms = 1e3 * s["seconds"] / max(s["states"], 1)
        qps = s.get("qps", 0)
        by_daqp = f"{1 - s.get('daqp_failed', 0) / qps:.1%}" if qps else "-"
        lines.append(f"{s['robot']:<8} {s['controller']:<12} {s['engine']:<7} {s['family']:<12} "
                     f"{s['states']:>6} {s['nan']:>4} {s['limit']:>5} "
                     f"{s['unflagged'] if s['checks_dynamics'] else '-':>6} "
                     f"{s['exceptions']:>4} {ms:>8.2f} {qps if qps else '-':>9} {by_daqp:>8}  "
                     f"{_outcomes(s['outcomes'])}")
    if report["disagreement"]:
        lines += ["", "engine disagreement |tau_python - tau_native|; 'ill-posed': the state's "
                      f"torque moves by > {ILL_POSED:g} Nm when (q, v) change by "
                      f"{PERTURBATION:g} relative; 'well-posed' columns: the other states",
                  f"{'robot':<8} {'controller':<12} {'family':<12} {'states':>6} "
                  f"{'max Nm':>10} {'>1e-6':>7} {'>1 Nm':>7} {'ok differs':>10} "
                  f"{'>1e-6 both S':>12} {'ill-posed':>9} {'well-posed: max Nm':>18} "
                  f"{'>1e-6':>5} {'ok differs':>10}  worst, first ok-differs, first well-posed >1e-6"]
        for d in report["disagreement"]:
            n = max(d["states"], 1)
            lines.append(f"{d['robot']:<8} {d['controller']:<12} {d['family']:<12} "
                         f"{d['states']:>6} {d['max_diff']:>10.3g} "
                         f"{d['above_small'] / n:>7.1%} {d['above_large'] / n:>7.1%} "
                         f"{d['ok_differs'] / n:>10.1%} {d['above_small_solved'] / n:>12.1%} "
                         f"{d['ill_posed'] / n:>9.1%} {d['max_diff_well_posed']:>18.3g} "
                         f"{d['above_small_well_posed']:>5} {d['ok_differs_well_posed']:>10}  "
                         f"{d['worst_index']}, {d['first_ok_differs']}, {d['first_well_posed']}")
    listed = [d for d in report["disagreement"] if d.get("well_posed_indices")]
    if listed:
        lines += ["", "well-posed disagreements (> 1e-6 Nm or ok differs), first "
                      f"{WELL_POSED_LISTED}: indices"]
        lines += [f"  {d['robot']} {d['controller']} {d['family']}: "
                  f"{' '.join(map(str, d['well_posed_indices']))}" for d in listed]
    firsts = [(s, c, e) for s in report["stats"] for c, e in sorted(s["first"].items())]
    if firsts:
        lines += ["", f"first state of each kind (reproduce: --robots R --families F --index I "
                      f"--seed {report['seed']})"]
        lines += [f"  {s['robot']} {s['controller']}/{s['engine']} {s['family']} {c} "
                  f"index {e['index']}: {e['message']}" for s, c, e in firsts]
    lines += ["", f"wall time {report['wall_time_s']:.1f} s"]
    return "\n".join(lines)


def totals(report: dict) -> dict:
    """Sums over every row: states, nan, limit, unflagged, exceptions."""
    keys = ("states", "nan", "limit", "unflagged", "exceptions")
    return {k: sum(s[k] for s in report["stats"]) for k in keys}


def exit_code(report: dict) -> int:
    """1 when any NaN, limit violation, unflagged failure or exception was counted, else 0."""
    total = totals(report)
    return int(bool(total["nan"] or total["limit"] or total["unflagged"] or total["exceptions"]))


def show_state(robot_name: str, family: str, seed: int, index: int, controllers) -> None:
    """Every selected controller and engine on one state, with its checks (a reproducer)."""
    logging.getLogger("wholebody").setLevel(logging.ERROR)
    robot = wb.load_robot(robot_name)
    dyn = DynamicsCheck(robot)
    q, v, plan = make_state(robot, family, seed, index)
    np.set_printoptions(precision=6, suppress=True, linewidth=150)
    print(f"{robot_name} {family} seed {seed} index {index}\nq = {q!r}\nv = {v!r}")
    if plan is not None:
        print(f"stance {plan.contact.astype(int)}")
    for name, (engines, _) in CONTROLLERS[robot_name].items():
        if name not in controllers:
            continue
        for engine in engines:
            runner = Runner(robot, name, engine)
            try:
                result = runner.run(q, v, plan)
            except Exception as exc:  # noqa: BLE001
                print(f"{name}/{engine}: raised {type(exc).__name__}: {exc}")
                continue
            s = Stats(robot_name, name, engine, family, checks_dynamics=runner.dynamics)
            check(s, runner, dyn, index, q, v, result)
            residual = dyn.residuals(q, v, result) if runner.dynamics else None
            print(f"{name}/{engine}: outcome {outcome_key(result)}, status {result.status!r}, "
                  f"residuals {residual}, tau {np.asarray(result.tau)!r}")
            for category, entry in s.first.items():
                print(f"    {category}: {entry['message']}")
        if name in ("pd", "lqr") and set(engines) == {"python", "native"}:
            r = row_sensitivity(robot, name, q, v)
            print(f"{name}: engines {r['engines']:.3g} Nm apart; the same cascade on each engine's "
                  f"level arrays: {r['reproduce']['python']:.3g} / {r['reproduce']['native']:.3g} "
                  f"Nm from its torque; the reference's arrays x (1 + {ROW_PERTURBATION:g} xi) "
                  f"move its torque by {r['moves'][0]:.3g} Nm (least {r['moves'][1]:.3g})")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--states", type=int, default=200, help="states per robot and family")
    parser.add_argument("--start", type=int, default=0,
                        help="index of the first state (a run in parts: --start 0, N, 2N ...)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--robots", nargs="+", choices=ROBOTS, default=list(ROBOTS))
    parser.add_argument("--controllers", nargs="+", choices=CONTROLLER_NAMES,
                        default=list(CONTROLLER_NAMES))
    parser.add_argument("--families", nargs="+", choices=FAMILIES, default=list(FAMILIES))
    parser.add_argument("--engines", nargs="+", choices=("python", "native"),
                        default=["python", "native"])
    parser.add_argument("--jobs", type=int, default=1, help="worker processes")
    parser.add_argument("--json", metavar="OUT", help="write the numbers to this file")
    parser.add_argument("--index", type=int, help="show this one state (a reproducer) and stop")
    parser.add_argument("--merge", nargs="+", metavar="JSON",
                        help="print the table of these --json reports (parts of one run) summed")
    args = parser.parse_args(argv)
    if args.merge:
        reports = [json.load(open(path)) for path in args.merge]
        if len({r["seed"] for r in reports}) != 1:
            parser.error("--merge: the reports have different seeds")
        report = {"seed": reports[0]["seed"], **merge(reports),
                  "wall_time_s": sum(r["wall_time_s"] for r in reports)}
        print(table(report))
        return exit_code(report)
    if args.index is not None:
        for robot_name in args.robots:
            for family in args.families:
                show_state(robot_name, family, args.seed, args.index, args.controllers)
        return 0
    if args.states < 1 or args.jobs < 1 or args.start < 0:
        parser.error("--states and --jobs must be >= 1, --start >= 0")
    report = fuzz(args.states, args.seed, args.robots, args.controllers, args.families,
                  args.engines, args.jobs, args.start)
    print(table(report))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)
    return exit_code(report)


if __name__ == "__main__":
    sys.exit(main())
