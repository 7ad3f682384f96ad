"""Task parameters are validated on every assignment (tasks/base.py ``checked_attribute``): at
construction and when a controller changes them between cycles, each error naming the field
(``<TaskClass>.<attr>`` or ``<TaskClass>('<name>').<attr>``) and the bad value.

Defects this guards against (adversarial review): ``task.mu = -0.5`` on a friction cone in a stack
gave zero contact forces with ok=True (FrictionCone checked mu only in its constructor); a
joint-limit ``horizon`` of 0, NaN or < 0 switched the braking bound off or flipped its sign."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from wholebody.control.stacks import table2_stack
from wholebody.cycle import HierarchyCycle, native_available
from wholebody.robot import FREE_FLYER_NQ, FREE_FLYER_NV
from wholebody.tasks import (CenterOfPressure, CoMTask, ContactConstraint, ForceRegularizer,
                             FrameTask, FrictionCone, FullDynamics, JointAccelerationLimits,
                             JointTrajectoryTask, MomentumForce, MomentumPD, NewtonEuler,
                             NormalForceBounds, PostureTask, SlackedFrameTask, Task, TorqueLimits)
from wholebody.tasks.regularization import (AccelerationRegularizer, AccelerationTarget,
                                            AuxiliaryRegularizer, ContactTorqueRegularizer,
                                            TangentialForceRegularizer)
from wholebody.tasks.wrench import TrunkImpedance, TrunkWrenchTask
from wholebody.variables import Variables

NAN, INF = math.nan, math.inf
native = pytest.mark.skipif(not native_available(), reason="native cycle not built")

#: Every task class, with the arguments that make a valid instance.
TASKS = {
    NewtonEuler: {}, FullDynamics: {}, TorqueLimits: {}, JointAccelerationLimits: {},
    ContactConstraint: {}, FrictionCone: {"mu": 0.7}, NormalForceBounds: {},
    CenterOfPressure: {}, ForceRegularizer: {}, MomentumPD: {}, MomentumForce: {},
    CoMTask: {}, FrameTask: {"frame": "left_sole_link"}, PostureTask: {},
    JointTrajectoryTask: {"joints": ["leg_left_4_joint", "leg_right_4_joint"]},
    AccelerationRegularizer: {}, TangentialForceRegularizer: {}, ContactTorqueRegularizer: {},
    AccelerationTarget: {"target": np.zeros(18)},
    TrunkWrenchTask: {},
    SlackedFrameTask: {"frame": "left_sole_link", "slack": "slack"},
    AuxiliaryRegularizer: {"names": ["slack"]},
}


def test_every_task_class_is_covered():
    """A new task class must be added to TASKS (and get its parameter cases below)."""
    def subclasses(cls):
        for sub in cls.__subclasses__():
            yield sub
            yield from subclasses(sub)
    found = {c for c in subclasses(Task) if c.__module__.startswith("wholebody.tasks")
             and not c.__name__.startswith("_")}
    assert found <= set(TASKS), sorted(c.__name__ for c in found - set(TASKS))


def field_pattern(cls, attr: str) -> str:
    """The start of an error naming ``cls``'s field ``attr`` (with or without the task name)."""
    return rf"^{cls.__name__}(\('[^']*'\))?\.{re.escape(attr)}\b"


def check_error(exc_info, cls, attr: str, shown: str) -> None:
    message = str(exc_info.value)
    assert re.match(field_pattern(cls, attr), message), message
    assert shown in message, f"{shown!r} not in {message!r}"


# (class, attribute, bad value, text the message must show)
BAD = [
    (FrictionCone, "mu", -0.5, "-0.5"), (FrictionCone, "mu", 0.0, "0.0"),
    (FrictionCone, "mu", NAN, "nan"), (FrictionCone, "mu", INF, "inf"),
    (FrictionCone, "mu", "high", "'high'"), (FrictionCone, "mu", [0.5, 0.6], "[0.5, 0.6]"),
    (FrictionCone, "torsion", "yes", "'yes'"),
    (NormalForceBounds, "f_min", -1.0, "-1.0"), (NormalForceBounds, "f_min", NAN, "nan"),
    (NormalForceBounds, "f_min", INF, "inf"), (NormalForceBounds, "f_max", 0.0, "0.0"),
    (NormalForceBounds, "f_max", -5.0, "-5.0"), (NormalForceBounds, "f_max", NAN, "nan"),
    (CenterOfPressure, "margin", -0.1, "-0.1"), (CenterOfPressure, "margin", 1.0, "1.0"),
    (CenterOfPressure, "margin", NAN, "nan"),
    (ContactConstraint, "kp", -1.0, "-1.0"), (ContactConstraint, "kd", NAN, "nan"),
    (ContactConstraint, "kp", INF, "inf"), (ContactConstraint, "kd", np.ones(3), "shape (3,)"),
    (TorqueLimits, "scale", 0.0, "0.0"), (TorqueLimits, "scale", -1.0, "-1.0"),
    (TorqueLimits, "scale", 1.5, "1.5"), (TorqueLimits, "scale", NAN, "nan"),
    (TorqueLimits, "upper_override", {"leg_left_4_joint": NAN}, "nan"),
    (TorqueLimits, "upper_override", {"leg_left_4_joint": -10.0}, "-10.0"),
    (JointAccelerationLimits, "horizon", 0.0, "0.0"),
    (JointAccelerationLimits, "horizon", -0.01, "-0.01"),
    (JointAccelerationLimits, "horizon", NAN, "nan"),
    (JointAccelerationLimits, "horizon", INF, "inf"),
    (JointAccelerationLimits, "a_max", 0.0, "0.0"), (JointAccelerationLimits, "a_max", NAN, "nan"),
    (JointAccelerationLimits, "steepness", -10.0, "-10.0"),
    (JointAccelerationLimits, "steepness", INF, "inf"),
    (JointAccelerationLimits, "mode", "linear", "'linear'"),
    (CoMTask, "kp", -100.0, "-100.0"), (CoMTask, "kd", NAN, "nan"), (CoMTask, "kp", INF, "inf"),
    (CoMTask, "kp", np.ones(2), "shape (2,)"), (CoMTask, "kd", [20.0, -1.0, 20.0], "-1.0"),
    (CoMTask, "kp", -np.eye(3), "eigenvalue -1"), (CoMTask, "kp", np.ones((3, 3, 3)), "shape"),
    (FrameTask, "kp", np.ones(3), "shape (3,)"), (FrameTask, "kd", -1.0, "-1.0"),
    (FrameTask, "kp", np.full(6, NAN), "nan"), (FrameTask, "mask", "xy", "'xy'"),
    (PostureTask, "kp", -50.0, "-50.0"), (PostureTask, "kd", NAN, "nan"),
    (PostureTask, "kp", np.ones((2, 3)), "shape (2, 3)"), (PostureTask, "kp", -np.eye(4), "-1"),
    (PostureTask, "base_kp", -1.0, "-1.0"), (PostureTask, "base_kd", NAN, "nan"),
    (PostureTask, "base_kp", np.ones(6), "shape (6,)"),
    (JointTrajectoryTask, "kp", np.ones(3), "shape (3,)"),
    (JointTrajectoryTask, "kd", -2.0, "-2.0"),
    (MomentumPD, "P", -np.eye(6), "eigenvalue -1"), (MomentumPD, "D", np.full((6, 6), NAN), "nan"),
    (MomentumPD, "P", np.ones(5), "shape (5,)"), (MomentumPD, "D", 5.0, "5.0"),
    (MomentumPD, "P", np.eye(3), "shape (3, 3)"),
    (TangentialForceRegularizer, "normals", {"left_sole": [0.0, 0.0, 0.0]}, "[0.0, 0.0, 0.0]"),
    (TangentialForceRegularizer, "lean", [0.0, NAN, 1.0], "nan"),
    (TangentialForceRegularizer, "lean", [0.0, 1.0], "shape (2,)"),
    (TangentialForceRegularizer, "mu", 0.0, "0.0"), (TangentialForceRegularizer, "mu", NAN, "nan"),
    (AccelerationTarget, "target", [0.0, INF], "inf"),
    (AccelerationTarget, "target", np.zeros((2, 2)), "shape (2, 2)"),
    (FrictionCone, "normals", {"left_sole": [NAN, 0.0, 1.0]}, "nan"),
    (NormalForceBounds, "normals", {"left_sole": [0.0, 1.0]}, "got (2,)"),
    (FrictionCone, "contacts", "left_sole", "'left_sole'"),
    (ForceRegularizer, "contacts", ["left_sole", "left_sole"], "duplicate"),
    (MomentumForce, "contacts", [3], "3"),
    (ContactTorqueRegularizer, "contacts", "right_sole", "'right_sole'"),
    (TrunkWrenchTask, "contacts", "lf_foot", "'lf_foot'"),
    (SlackedFrameTask, "kd", -1.0, "-1.0"), (SlackedFrameTask, "mask", "xy", "'xy'"),
]


def _id(case):
    cls, attr, bad, _ = case
    return f"{cls.__name__}.{attr}={bad!r}"[:60]


@pytest.mark.parametrize("case", BAD, ids=[_id(c) for c in BAD])
def test_bad_parameter_at_construction(case):
    cls, attr, bad, shown = case
    with pytest.raises(ValueError) as exc_info:
        cls(**{**TASKS[cls], attr: bad})
    check_error(exc_info, cls, attr, shown)


@pytest.mark.parametrize("case", BAD, ids=[_id(c) for c in BAD])
def test_bad_parameter_on_assignment(case):
    """After construction (a controller changing a gain between cycles): the error names the task
    and the field, and the previous value is kept."""
    cls, attr, bad, shown = case
    task = cls(**TASKS[cls], name="my task")
    before = getattr(task, attr)
    with pytest.raises(ValueError) as exc_info:
        setattr(task, attr, bad)
    check_error(exc_info, cls, attr, shown)
    assert str(exc_info.value).startswith(f"{cls.__name__}('my task').{attr}")
    after = getattr(task, attr)
    assert after is before


BAD_WEIGHTS = [(NAN, "nan"), (INF, "inf"), (-1.0, "-1.0"), ([1.0, -2.0], "-2.0"),
               (np.ones((2, 2)), "shape (2, 2)"), ("heavy", "'heavy'")]


@pytest.mark.parametrize("cls", list(TASKS), ids=lambda c: c.__name__)
@pytest.mark.parametrize("bad,shown", BAD_WEIGHTS, ids=[repr(b)[:20] for b, _ in BAD_WEIGHTS])
def test_bad_weight(cls, bad, shown):
    """Task.weight (finite >= 0, a number or one per row) of every task class, at construction
    and on assignment."""
    with pytest.raises(ValueError) as exc_info:
        cls(**TASKS[cls], weight=bad)
    check_error(exc_info, cls, "weight", shown)
    task = cls(**TASKS[cls])
    with pytest.raises(ValueError) as exc_info:
        task.weight = bad
    check_error(exc_info, cls, "weight", shown)
    assert task.weight == 1.0


@pytest.mark.parametrize("cls", [c for c in TASKS if c.kind == "ineq"], ids=lambda c: c.__name__)
def test_inequality_weight_must_be_positive(cls):
    """An inequality task's weight scales its slacks: 0 is refused (the formulation would reject
    it at the next solve); an equality task's 0 switches it off and is fine."""
    with pytest.raises(ValueError, match=field_pattern(cls, "weight") + r".*> 0"):
        cls(**TASKS[cls], weight=0.0)
    with pytest.raises(ValueError, match=field_pattern(cls, "weight")):
        cls(**TASKS[cls]).weight = np.array([1.0, 0.0])
    assert ForceRegularizer(weight=0.0).weight == 0.0


def test_normal_force_bounds_are_ordered():
    """0 <= f_min < f_max, checked against the other bound on assignment too."""
    with pytest.raises(ValueError, match=r"^NormalForceBounds\.f_min: must be < f_max = 500.*600"):
        NormalForceBounds(f_min=600.0, f_max=500.0)
    with pytest.raises(ValueError, match=r"^NormalForceBounds\.f_min: .* 10"):
        NormalForceBounds(f_min=10.0, f_max=10.0)
    task = NormalForceBounds(f_min=5.0, f_max=500.0)
    with pytest.raises(ValueError, match=r"^NormalForceBounds\.f_max: must be > f_min = 5.0.*2.0"):
        task.f_max = 2.0
    with pytest.raises(ValueError, match=r"^NormalForceBounds\.f_min: must be < f_max.*800"):
        task.f_min = 800.0
    assert (task.f_min, task.f_max) == (5.0, 500.0)
    task.f_max = INF  # no upper bound is valid
    task.f_min = 800.0
    assert (task.f_min, task.f_max) == (800.0, INF)


def test_valid_values_are_accepted_and_normalised():
    """Lists become float arrays, numbers floats; the values read back are what the tasks use."""
    com = CoMTask(kp=[10, 20, 30], kd=np.diag([1.0, 2.0, 3.0]), weight=[1, 2, 3])
    assert isinstance(com.kp, np.ndarray) and com.kp.dtype == float
    np.testing.assert_array_equal(com.weight, [1.0, 2.0, 3.0])
    com.kp = 0  # a zero gain is valid
    assert com.kp == 0.0 and isinstance(com.kp, float)
    pd = MomentumPD(P=np.arange(6.0), D=np.eye(6))
    np.testing.assert_array_equal(pd.P, np.diag(np.arange(6.0)))  # a diagonal is expanded
    limits = JointAccelerationLimits(horizon=0.02)
    limits.horizon = 0.05
    limits.mode = "tanh"
    assert (limits.horizon, limits.mode) == (0.05, "tanh")
    assert TorqueLimits(upper_override={"leg_left_4_joint": INF}).upper_override == {
        "leg_left_4_joint": INF}
    cone = FrictionCone(np.float64(0.4), contacts=["left_sole"], torsion=np.bool_(True))
    assert cone.mu == 0.4 and cone.contacts == ("left_sole",) and cone.torsion is True
    assert ForceRegularizer(contacts=[]).contacts == ()
    assert TangentialForceRegularizer(contacts=None).contacts is None
    posture = PostureTask(kp=50.0 * np.eye(14))  # a full gain matrix (python engine)
    assert posture.kp.shape == (14, 14)


@pytest.mark.parametrize("bad,shown", [(-1.0, "-1.0"), (NAN, "nan"), (np.ones(2), "shape (2,)"),
                                       ("stiff", "'stiff'")])
@pytest.mark.parametrize("attr", ["K_x", "D_x", "K_theta", "D_theta"])
def test_trunk_impedance_gains(attr, bad, shown):
    with pytest.raises(ValueError) as exc_info:
        TrunkImpedance(**{attr: bad})
    check_error(exc_info, TrunkImpedance, attr, shown)
    impedance = TrunkImpedance()
    with pytest.raises(ValueError) as exc_info:
        setattr(impedance, attr, bad)
    check_error(exc_info, TrunkImpedance, attr, shown)
    with pytest.raises(ValueError, match=r"^TrunkImpedance\.feedforward: .*'no'"):
        TrunkImpedance(feedforward="no")
    impedance.K_x = [1.0, 2.0, 3.0]
    np.testing.assert_array_equal(impedance.K_x, [1.0, 2.0, 3.0])


def test_constructor_only_arguments():
    """Arguments that are not attributes: CoMTask axes, JointTrajectoryTask joints."""
    for axes in ("", "xw", "xx", ["x"]):
        with pytest.raises(ValueError, match=r"^axes: .*" + re.escape(repr(axes))):
            CoMTask(axes=axes)
    for joints in ("leg_left_4_joint", []):
        with pytest.raises(ValueError, match=r"^joints: .*" + re.escape(repr(joints))):
            JointTrajectoryTask(joints)


# ---------------------------------------------------------------- defect 3: friction mu in a stack
ENGINES = [pytest.param("native", marks=native), "python"]


@pytest.mark.parametrize("engine", ENGINES)
def test_negative_mu_in_a_stack_is_refused_before_the_engine(robots, engine):
    """Before: ``stack.find("friction").mu = -0.5`` got through (mu was checked only by the
    constructor) and the cascade returned zero contact forces with ok=True. Now the assignment
    raises, the cone keeps its mu, and the next cycle is the one before."""
    robot = robots["talos14"]
    stack = table2_stack(robot)
    cycle = HierarchyCycle(robot, stack, engine=engine)
    q, v = robot.q_ref.copy(), np.zeros(robot.nv)
    first = cycle.solve(q, v)
    assert first.ok and first.lam.max() > 100.0  # the feet carry the robot
    friction = stack.find("friction")
    mu = friction.mu
    for bad, shown in ((-0.5, "-0.5"), (0.0, "0.0"), (NAN, "nan")):
        with pytest.raises(ValueError, match=r"^FrictionCone\('friction'\)\.mu: .*" + shown):
            friction.mu = bad
    assert friction.mu == mu
    again = cycle.solve(q, v)
    np.testing.assert_allclose(again.lam, first.lam, atol=1e-9, rtol=0)


# ------------------------------------------------------------ defect 4: joint-limit braking horizon
@pytest.mark.parametrize("bad,shown", [(0.0, "0.0"), (-0.02, "-0.02"), (NAN, "nan"), (INF, "inf")])
def test_braking_horizon_must_be_positive(bad, shown):
    """Before: horizon = 0 gave bounds of +-inf (braking silently off), NaN or < 0 a wrong bound."""
    with pytest.raises(ValueError, match=r"^JointAccelerationLimits\.horizon: .*" + shown):
        JointAccelerationLimits(horizon=bad)
    task = JointAccelerationLimits(name="qdd limits", horizon=0.02)
    with pytest.raises(ValueError, match=r"^JointAccelerationLimits\('qdd limits'\)\.horizon: "
                                         r".*" + shown):
        task.horizon = bad
    assert task.horizon == 0.02


def test_braking_bound_of_a_knee_near_its_limit(robots):
    """A knee 2 mm below its upper limit moving towards it at 2 rad/s, horizon 20 ms: the upper
    acceleration bound is the constant acceleration that stops at the limit exactly after the
    horizon. Expected value by hand: 2 (0.002 - 0.02 * 2) / 0.02^2 = -190 rad/s^2; and checked
    kinematically: q + qdot h + a h^2 / 2 reaches q_max."""
    robot = robots["talos14"]
    knee = robot.joint_names.index("leg_left_4_joint")
    h, gap, speed = 0.02, 0.002, 2.0
    q, v = robot.q_ref.copy(), np.zeros(robot.nv)
    q[FREE_FLYER_NQ + knee] = robot.q_max[knee] - gap
    v[FREE_FLYER_NV + knee] = speed
    robot.update(q, v)
    task = JointAccelerationLimits(horizon=0.5)
    task.horizon = h  # the value set on assignment is the one the rows use
    rows = task.rows(robot, Variables(robot))
    upper = rows.upper[knee]
    assert upper == pytest.approx(-190.0, rel=1e-9)
    q_end = q[FREE_FLYER_NQ + knee] + speed * h + 0.5 * upper * h ** 2
    assert q_end == pytest.approx(robot.q_max[knee], abs=1e-12)
    assert rows.lower[knee] < upper  # the lower bound does not cross it
