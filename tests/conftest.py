import os
import shutil
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

import wholebody as wb
from wholebody.tasks import Task, TaskRows

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fuzz  # noqa: E402  (the fuzz harness's state and plan samplers)

PRESETS = ("talos14", "talos", "hyq", "anymal_c", "romeo")


@pytest.fixture
def no_simulation(monkeypatch):
    """Scenario.run fails the test: the checks under test must come before any simulation."""
    from wholebody.scenarios.base import Scenario

    def run(self, *args, **kwargs):
        pytest.fail(f"scenario '{self.name}' was run: the bad input was not caught before it")
    monkeypatch.setattr(Scenario, "run", run)


@pytest.fixture(scope="session")
def robots():
    """Each preset loaded once per test session."""
    return {name: wb.load_robot(name) for name in PRESETS}


def g1_description(armature: float = 0.0, lock_arms: bool = True) -> dict:
    """Unitree G1 from example-robot-data as docs/robots.md describes it (no preset: its URDF has
    no sole frame, so the soles are rectangles on the ankle roll links with an ``offset``; legs
    and waist, arms locked unless ``lock_arms`` is False: all 29 joints), with rotor inertia
    ``armature``."""
    arms = [f"{side}_{joint}_joint" for side in ("left", "right")
            for joint in ("shoulder_pitch", "shoulder_roll", "shoulder_yaw", "elbow",
                          "wrist_roll", "wrist_pitch", "wrist_yaw")]
    posture = {f"{side}_{joint}_joint": angle for side in ("left", "right")
               for joint, angle in (("hip_pitch", -0.3), ("knee", 0.6), ("ankle_pitch", -0.3))}
    posture.update(left_shoulder_roll_joint=0.2, right_shoulder_roll_joint=-0.2,
                   left_elbow_joint=0.9, right_elbow_joint=0.9)
    return {"name": "g1", "urdf": "erd:g1_description/urdf/g1_29dof_rev_1_0.urdf",
            "posture": posture, "locked_joints": arms if lock_arms else [], "armature": armature,
            "trunk_frame": "torso_link",
            "contacts": [{"name": f"{side}_sole", "frame": f"{side}_ankle_roll_link",
                          "type": "rectangle", "half_size": [0.085, 0.025],
                          "offset": [0.035, 0.0, -0.035]} for side in ("left", "right")]}


def talos14_five_joint_toml(sole_half_width: float | None = None) -> str:
    """talos14's description with its ankle rolls locked (five-joint legs, as Unitree H1's), and
    with soles ``sole_half_width`` m wide on each side of their x axis if given (H1's: 0.015)."""
    text = (Path(wb.__file__).parent / "robots/presets/talos14.toml").read_text().replace(
        '"head_1_joint", "head_2_joint",',
        '"head_1_joint", "head_2_joint", "leg_left_6_joint", "leg_right_6_joint",')
    if sole_half_width is not None:
        text = text.replace("half_size = [0.105, 0.065]", f"half_size = [0.105, {sole_half_width}]")
    return text


#: iCub's right leg has masses but zero inertias in example-robot-data: the left leg's moments
ICUB_RIGHT_LEG_INERTIAS = {
    "r_hip_1": [0.000471, 0.000346, 0.00051], "r_hip_2": [0.000562, 0.000738, 0.000294],
    "r_upper_leg": [0.007591, 0.001423, 0.007554], "r_lower_leg": [0.000999, 0.004451, 0.004208],
    "r_ankle_1": [0.000633, 0.000688, 0.000314]}


def icub_description(**extra) -> dict:
    """iCub from example-robot-data as docs/robots.md describes it: legs and torso, arms locked
    (their wrists have zero inertia too), soles with declared roles (its base frame faces
    backwards); ``extra`` fields on top (``inertia_overrides``, ``armature``, ...)."""
    arms = [f"{s}_{j}" for s in "lr" for j in ("shoulder_pitch", "shoulder_roll", "shoulder_yaw",
                                                "elbow", "wrist_prosup", "wrist_pitch",
                                                "wrist_yaw")]
    return {"name": "icub", "urdf": "erd:icub_description/robots/icub_reduced.urdf",
            "srdf": "erd:icub_description/srdf/icub.srdf", "posture": "half_sitting",
            "posture_overrides": {"l_ankle_pitch": 0.035, "r_ankle_pitch": 0.035},
            "locked_joints": arms,
            "contacts": [{"name": f"{s}_sole", "frame": f"{s[0]}_sole", "type": "rectangle",
                          "half_size": [0.06, 0.03], "role": s} for s in ("left", "right")],
            **extra}


def alexander_description() -> dict:
    """Boardwalk Robotics' Alexander (lower body) from example-robot-data as docs/robots.md
    describes it: no sole frame, so the soles are rectangles on the ankle roll links from the
    foot mesh's extent, with an ``offset``."""
    return {"name": "alexander",
            "urdf": "erd:alexander_description/urdf/alexander_v1.lowerBodyOnly.urdf",
            "srdf": "erd:alexander_description/srdf/alexander.srdf", "posture": "default",
            "contacts": [{"name": f"{side.lower()}_sole", "frame": f"{side}_FOOT",
                          "type": "rectangle", "half_size": [0.1, 0.045],
                          "offset": [0.051, 0.0, -0.072]} for side in ("LEFT", "RIGHT")]}


def centauro_description() -> dict:
    """IIT Centauro's legs (4 x 5 joints) from example-robot-data; wheels, torso, arms and head
    locked at homing_nominal; each wheel a point contact with a sphere of its radius."""
    return {"name": "centauro", "urdf": "erd:centauro_description/urdf/centauro.urdf",
            "srdf": "erd:centauro_description/srdf/centauro.srdf", "posture": "homing_nominal",
            "locked_joints": ["j_wheel_1", "j_wheel_2", "j_wheel_3", "j_wheel_4", "torso_yaw",
                              *(f"j_arm{a}_{j}" for a in (1, 2) for j in range(1, 7)),
                              "d435_head_joint", "velodyne_joint"],
            "contacts": [{"name": f"wheel_{i}", "frame": f"wheel_{i}", "type": "point",
                          "radius": 0.119} for i in range(1, 5)]}


def anymal_b_description() -> dict:
    """ANYbotics' ANYmal B (simple description) from example-robot-data: point feet whose spheres
    (radius 3.1 cm) are centred 2.325 cm above the FOOT frames."""
    return {"name": "anymal_b", "urdf": "erd:anymal_b_simple_description/robots/anymal.urdf",
            "srdf": "erd:anymal_b_simple_description/srdf/anymal.srdf", "posture": "standing",
            "contacts": [{"name": f"{leg}_FOOT", "frame": f"{leg}_FOOT", "type": "point",
                          "radius": 0.031, "offset": [0.0, 0.0, 0.02325]}
                         for leg in ("LF", "RF", "LH", "RH")]}


def solo8_description() -> dict:
    """ODRI's 8-DoF Solo (hip and knee flexion only) with solo12's feet and 2.7 Nm actuators."""
    joints = [f"{leg}_{j}" for leg in ("FL", "FR", "HL", "HR") for j in ("HFE", "KFE")]
    return {"name": "solo8", "urdf": "erd:solo_description/robots/solo.urdf",
            "srdf": "erd:solo_description/srdf/solo.srdf", "posture": "standing",
            "torque_limits": {"overrides": {j: 2.7 for j in joints}},
            "contacts": [{"name": n, "frame": n, "type": "point", "radius": 0.016}
                         for n in ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")]}


def one_sole_holding_torques(robot, q, stance) -> np.ndarray:
    """The joint torques holding ``robot`` still at ``q`` on the sole ``stance`` alone: the
    static equilibrium S^T tau + J^T f = g(q) solved as one least-squares system over (tau, f)
    (square: the floating base's six rows and the sole's six unknowns), its residual checked."""
    import pinocchio as pin

    robot.update(q, np.zeros(robot.nv))
    J = robot.stacked_contact_jacobian([stance])
    g = pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q)
    S = np.hstack([np.zeros((robot.na, 6)), np.eye(robot.na)])
    A = np.hstack([S.T, J.T])
    x, *_ = np.linalg.lstsq(A, g, rcond=None)
    np.testing.assert_allclose(A @ x, g, atol=1e-8)
    return x[:robot.na]


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def ray_height(sim, x: float, y: float, top: float = 3.0) -> float:
    """Height of the twin's surface under (x, y): a MuJoCo ray cast straight down from ``top``
    onto its static geoms (-inf where nothing is hit)."""
    import mujoco

    geom = np.zeros(1, dtype=np.int32)
    d = mujoco.mj_ray(sim.model, sim.data, np.array([x, y, top]), np.array([0.0, 0.0, -1.0]),
                      None, 1, -1, geom)
    return top - d if d >= 0 else -np.inf


class ForceCap(Task):
    """A user's own inequality (no compiled kernel): every stance foot's vertical force at most
    ``cap`` N."""

    kind = "ineq"

    def __init__(self, cap, name="force cap"):
        super().__init__(name)
        self.cap = cap

    def rows(self, robot, variables):
        A = np.zeros((len(variables.contacts), variables.n_lambda))
        for i, sl in enumerate(variables.lambda_slices.values()):
            A[i, sl.start + 2] = 1.0
        m = len(variables.contacts)
        return TaskRows(qdd=None, lam=A, tau=None, lower=np.full(m, -np.inf),
                        upper=np.full(m, self.cap))


def native_cycle_or_skip(module: str = "_hierarchy_cycle"):
    """Import a compiled part of wholebody (``_hierarchy_cycle``, ``_cascade``...). Skip only where
    it cannot have been built (no C++ compiler on this machine, or WHOLEBODY_NO_NATIVE set at
    install); anywhere else a missing extension is a broken build and fails the test."""
    import importlib
    try:
        return importlib.import_module(f"wholebody.{module}")
    except ImportError:
        compiler = (sysconfig.get_config_var("CXX") or "c++").split()[0]
        if os.environ.get("WHOLEBODY_NO_NATIVE") or shutil.which(compiler) is None:
            pytest.skip(f"wholebody.{module} not built here (no C++ compiler '{compiler}' or "
                        "WHOLEBODY_NO_NATIVE set)", allow_module_level=True)
        raise


def pytest_collection_modifyitems(config, items):
    """Every test under tests/closed_loop/ runs the MuJoCo twin for seconds: marked slow, so the
    fast subset is ``pytest -m "not slow"``."""
    for item in items:
        if "closed_loop" in item.path.parts:
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def plan_for():
    """``plan_near(robot, rng, stance, swing_noise=, normal=)`` of benchmarks/fuzz.py: a PassiveWBC
    plan near the robot's cached state, for tests that build such plans."""
    return fuzz.plan_near


def torque_tolerance(solve, q, v, nq: int, atol: float = 1e-6) -> float:
    """How close two engines' torques must be at (q, v): ``atol`` plus 100 times how far the
    reference ``solve(q, v) -> tau`` itself moves when the base position moves by 1e-13 m. A
    cascade whose levels conflict (a task sacrificed at a large cost, saturated torques) is
    ill-conditioned: inputs that differ in the last bits (two engines round differently) move its
    solution by far more than round-off, and this measures by how much."""
    tau = solve(q, v)
    nearby = solve(q + np.r_[np.full(3, 1e-13), np.zeros(nq - 3)], v)
    return atol + 100.0 * float(np.abs(nearby - tau).max())
