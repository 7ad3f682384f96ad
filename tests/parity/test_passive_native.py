"""PassiveWBC's engines — its QP a stack of library tasks (control/passive_stack.py) solved by
the compiled hierarchy program (engine "native", its tasks and programs kept across cycles, its
references around the QP compiled in native/passive_references.cpp) or by the Python Formulation
(engine "python") — against each other and against the same QP assembled by hand
(tests/passive_oracle.py), on closed-loop HyQ trot and crawl states (and an 8-DoF Solo's crawl,
whose stance rows are dependent), and in closed loop in the twin."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from wholebody.control.observer import MomentumObserver
from wholebody.control.passive import STACK_SETTINGS, PassiveWBC
from wholebody.formulation import Formulation
from wholebody.tasks import JointTrajectoryTask

from conftest import ForceCap, native_cycle_or_skip
from passive_oracle import hand_assembled

native_cycle_or_skip("_passive_references")
native_cycle_or_skip("_hierarchy_cycle")


def gait_states(robot, gait, duration):
    """(q, v, plan) of every WBC cycle of a closed-loop run of ``gait`` (a speed ramp from
    standing), every 3rd kept."""
    from wholebody.planning.trunk import VelocityCommand
    from wholebody.scenarios.locomotion import run_gait
    states = []

    def keep(t, result, ctrl, sim):
        q, v = sim.state()
        states.append((q, v, ctrl.last_plan.copy()))

    run_gait(robot, "passive", gait, VelocityCommand.speed_ramp(0.0, 0.3, 1.0, 2.0),
             duration=duration, on_cycle=keep)
    return states[::3]


@pytest.fixture(scope="module")
def trot_states(robots):
    """2 s of trot."""
    return gait_states(robots["hyq"], "trot", 2.0)


@pytest.fixture(scope="module")
def crawl_states(robots):
    """3 s of crawl (its legs swing one at a time)."""
    return gait_states(robots["hyq"], "crawl", 3.0)


def planner(robot):
    return SimpleNamespace(legs=robot.contact_names)


def tilted(plan, angle=0.26):
    """The plan with every foot's terrain normal tilted by ``angle`` about x (a 15° ramp)."""
    plan = plan.copy()
    plan.touchdown_normal = np.tile([0.0, -np.sin(angle), np.cos(angle)], (len(plan.legs), 1))
    return plan


def assert_same_solution(a, b, where=""):
    assert a.ok == b.ok, where
    np.testing.assert_allclose(b.tau, a.tau, atol=1e-6, rtol=0, err_msg=where)
    np.testing.assert_allclose(b.lam, a.lam, atol=1e-5, rtol=0, err_msg=where)
    np.testing.assert_allclose(b.qdd, a.qdd, atol=1e-5, rtol=0, err_msg=where)
    assert [t.name for t in a.tasks] == [t.name for t in b.tasks], where
    np.testing.assert_allclose([t.error for t in b.tasks], [t.error for t in a.tasks],
                               atol=1e-5, err_msg=where)
    assert a.contacts == b.contacts, where


def assert_matches_hand_assembled(wbc, plan, sol, where=""):
    """``sol``, the Python-engine controller ``wbc``'s solution of ``plan`` at the robot's cached
    state, equals the hand-assembled QP's: ok, torques, forces, accelerations, swing residuals
    and single slacks."""
    ref = hand_assembled(wbc, plan)
    assert ref.ok == sol.ok, where
    if not ref.ok:
        return
    np.testing.assert_allclose(sol.tau, ref.tau, atol=1e-6, rtol=0, err_msg=where)
    np.testing.assert_allclose(sol.lam, ref.lam, atol=1e-5, rtol=0, err_msg=where)
    np.testing.assert_allclose(sol.qdd, ref.qdd, atol=1e-5, rtol=0, err_msg=where)
    swing = {t.name: t.error for t in sol.tasks if t.name.startswith("swing ")}
    swinging = np.flatnonzero(~plan.contact[wbc._leg])
    assert set(swing) == {f"swing {wbc.contacts[i]}" for i in swinging}, where
    for i in swinging:
        error = swing[f"swing {wbc.contacts[i]}"]
        assert error == pytest.approx(ref.swing_errors[i], abs=1e-5), where
    assert set(sol.auxiliary) == set(ref.slacks), where
    for key, value in ref.slacks.items():
        assert float(sol.auxiliary[key][0]) == pytest.approx(value, abs=1e-5), where


CONFIGS = {
    "default": {},
    "hard swing": {"swing_slack": "none"},
    "torque regularisation": {"regularization": "torque"},
    "the paper's force regulariser": {"regularization": "force-normal", "tangential_weight": 1.0},
    "weak knee, eq. 10 stance": {"torque_limit_override": {"lf_kfe_joint": 26.0}, "K_st": 0.0,
                                 "D_st": 0.0},
    "no feed-forward, mu 0.4": {"mu": 0.4, "f_min": 10.0},
}


@pytest.mark.parametrize("gait", ["trot", "crawl"])
@pytest.mark.parametrize("name", list(CONFIGS))
@pytest.mark.parametrize("ramp", [False, True], ids=["flat", "ramp"])
def test_matches_python_engine(robots, request, gait, name, ramp):
    """Same torques, forces, accelerations and task reports as the Python engine, cycle by cycle
    (the stance anchors of eq. 32 evolve in both), and as the hand-assembled QP."""
    robot = robots["hyq"]
    states = request.getfixturevalue(f"{gait}_states")
    options = CONFIGS[name]
    python = PassiveWBC(robot, planner=planner(robot), engine="python", **options)
    native = PassiveWBC(robot, planner=planner(robot), engine="native", **options)
    if name.startswith("no feed-forward"):
        for wbc in (python, native):
            wbc.impedance.feedforward = False
            wbc.swing.feedforward = False
            wbc.configure()
    swinging = 0
    for k, (q, v, plan) in enumerate(states):
        plan = tilted(plan) if ramp else plan
        a = python.cycle(q, v, plan)
        b = native.cycle(q, v, plan)
        assert_same_solution(a, b, f"{name} cycle {k}")
        assert_matches_hand_assembled(python, plan, a, f"{name} cycle {k}")
        np.testing.assert_allclose(native.impedance.last_errors, python.impedance.last_errors,
                                   atol=1e-12)
        swinging += not plan.contact.all()
    assert swinging > len(states) // 4  # the states exercise the swing rows


@pytest.mark.parametrize("gait", ["trot", "crawl"])
@pytest.mark.parametrize("slack_weight", [1e4, 1.0])
@pytest.mark.parametrize("ramp", [False, True], ids=["flat", "ramp"])
def test_single_slack_stack_matches_python_engine(robots, request, gait, slack_weight, ramp):
    """The single swing slack (one ε per swing foot, |J q̈ − b| ≤ ε, cost α ε²: Fahmi et al.
    2019's ∞-norm) as a stack of tasks with auxiliary variables gives, on both engines, the
    hand-assembled QP's torques, forces, accelerations, swing residuals and slacks cycle by
    cycle; with a small α the slack binds (the residuals are large)."""
    robot = robots["hyq"]
    states = request.getfixturevalue(f"{gait}_states")
    options = {"swing_slack": "single", "slack_weight": slack_weight}
    python = PassiveWBC(robot, planner=planner(robot), engine="python", **options)
    stack = PassiveWBC(robot, planner=planner(robot), **options)
    assert stack.engine == "native"
    largest = 0.0
    for k, (q, v, plan) in enumerate(states):
        plan = tilted(plan) if ramp else plan
        a, b = python.cycle(q, v, plan), stack.cycle(q, v, plan)
        assert_same_solution(a, b, f"single slack cycle {k}")
        assert_matches_hand_assembled(python, plan, a, f"single slack cycle {k}")
        largest = max([largest] + [t.error for t in a.tasks if t.name.startswith("swing")])
    assert largest > (1e-2 if slack_weight == 1.0 else 1e-6)  # the swing rows were relaxed


def test_stack_matches_python_engine_on_dependent_stance_rows():
    """ODRI's 8-DoF Solo (legs of two joints): the native engine, whose stance task takes an
    independent set of its rows, gives the Python engine's and the hand-assembled QP's torques,
    forces and task reports cycle by cycle on the states of a closed-loop crawl."""
    from conftest import solo8_description

    import wholebody as wb
    solo = wb.load_robot(solo8_description())
    states = gait_states(solo, "crawl", 2.0)
    python = PassiveWBC(solo, planner=planner(solo), engine="python")
    stack = PassiveWBC(solo, planner=planner(solo), engine="native")
    assert python.dependent_stance and PassiveWBC(solo, planner=planner(solo)).engine == "native"
    swinging = 0
    for k, (q, v, plan) in enumerate(states):
        a, b = python.cycle(q, v, plan), stack.cycle(q, v, plan)
        assert a.ok, a.status
        assert_same_solution(a, b, f"solo8 cycle {k}")
        assert_matches_hand_assembled(python, plan, a, f"solo8 cycle {k}")
        swinging += not plan.contact.all()
    assert swinging > len(states) // 4


def test_heading_weights_match_python_engine(robots, trot_states):
    """Trunk weights that differ about x and y act in the heading frame of the trunk reference:
    with the references turned by 0.7 rad about z both engines weigh the wrench error alike."""
    robot = robots["hyq"]
    Q = (1.0, 0.8, 1.0, 1.2, 0.6, 1.0)
    python = PassiveWBC(robot, planner=planner(robot), engine="python", Q=Q)
    native = PassiveWBC(robot, planner=planner(robot), engine="native", Q=Q)
    turn = pin.rpy.rpyToMatrix(0.0, 0.0, 0.7)
    for k, (q, v, plan) in enumerate(trot_states[:120]):
        plan = plan.copy()
        plan.trunk = replace(plan.trunk, rotation=turn @ plan.trunk.rotation)
        a = python.cycle(q, v, plan)
        assert_same_solution(a, native.cycle(q, v, plan), f"cycle {k}")
        assert_matches_hand_assembled(python, plan, a, f"cycle {k}")


def test_observer_matches_python_engine(robots, trot_states):
    """With the W_ext observer (its input is the engine's centroidal momentum and commanded
    wrench) both engines stay equal."""
    robot = robots["hyq"]
    python = PassiveWBC(robot, planner=planner(robot), observer=MomentumObserver(10.0),
                         engine="python")
    native = PassiveWBC(robot, planner=planner(robot), observer=MomentumObserver(10.0),
                        engine="native")
    for q, v, plan in trot_states[:150]:
        a = python.cycle(q, v, plan)
        assert_same_solution(a, native.cycle(q, v, plan))
        assert_matches_hand_assembled(python, plan, a)
    np.testing.assert_allclose(native.impedance.external_wrench,
                               python.impedance.external_wrench, atol=1e-6)
    assert np.abs(python.impedance.external_wrench).max() > 0.1  # the observer did something


def test_configure_hands_over_changed_settings(robots, trot_states):
    """Settings are copied when the tasks are built: a change is seen only after configure()."""
    robot = robots["hyq"]
    python = PassiveWBC(robot, planner=planner(robot), engine="python")
    native = PassiveWBC(robot, planner=planner(robot), engine="native")
    q, v, plan = next(s for s in trot_states if not s[2].contact.all())
    for wbc in (python, native):
        wbc.Q[:] = (1.0, 1.0, 1.0, 10.0, 10.0, 10.0)
        wbc.joint_limits.mode = "tanh"
    python.configure()
    a = python.cycle(q, v, plan)
    assert_matches_hand_assembled(python, plan, a)
    assert np.abs(native.cycle(q, v, plan).tau - a.tau).max() > 1e-3
    native.configure()
    # both engines now have one cycle of stance history (the stance task integrates slip)
    assert_same_solution(python.cycle(q, v, plan), native.cycle(q, v, plan))


def test_infeasible_is_a_flagged_value(robots, rng):
    """An infeasible QP (normal-force floor above the weight share): ok False, the reason, and the
    same finite, limited torque as the Python engine."""
    robot = robots["hyq"]
    options = {"f_min": 1500.0, "f_max": 2000.0, "torque_limit_override": {"lf_kfe_joint": 1.0}}
    python = PassiveWBC(robot, planner=planner(robot), engine="python", **options)
    native = PassiveWBC(robot, planner=planner(robot), engine="native", **options)
    q = robot.q_ref.copy()
    q[7:] += rng.normal(scale=0.02, size=robot.na)
    v = rng.normal(scale=0.05, size=robot.nv)
    robot.update(q, v)
    plan = SimpleNamespace(
        legs=robot.contact_names, contact=np.ones(4, dtype=bool),
        foot_position=robot.contact_points.copy(), foot_velocity=np.zeros((4, 3)),
        foot_acceleration=np.zeros((4, 3)), touchdown_normal=np.tile([0.0, 0.0, 1.0], (4, 1)),
        trunk=SimpleNamespace(position=robot.com.copy(), velocity=np.zeros(3),
                              acceleration=np.zeros(3), rotation=np.eye(3),
                              angular_velocity=np.zeros(3), angular_acceleration=np.zeros(3)))
    a, b = python.cycle(q, v, plan), native.cycle(q, v, plan)
    assert not b.ok and "previous torque held" in b.status
    np.testing.assert_allclose(b.tau, a.tau, atol=1e-9)
    hi = robot.torque_bounds()[1]
    hi[robot.joint_names.index("lf_kfe_joint")] = 1.0
    assert np.all(np.isfinite(b.tau)) and np.all(np.abs(b.tau) <= hi + 1e-12)


@pytest.mark.parametrize("gait", ["trot", "crawl"])
def test_stack_tasks_and_programs_kept_across_cycles(robots, request, gait):
    """engine="native" builds its tasks once and only changes their references; the compiled
    cycle builds one program per stance set met (with its swing tasks' level), no more."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, planner=planner(robot), engine="native")
    tasks = {id(t) for t in wbc._stack.hard + wbc._stack.objective + wbc._stack.swing}
    stance_sets = set()
    for q, v, plan in request.getfixturevalue(f"{gait}_states"):
        wbc.cycle(q, v, plan)
        stance_sets.add(tuple(plan.contact.tolist()))
        assert {id(t) for t in wbc._stack.stack.tasks()} <= tasks
    assert len(stance_sets) > 1
    assert len(wbc._stack_cycle._programs) == len(stance_sets)


@pytest.mark.parametrize("gait,posture", [("trot", False), ("crawl", False), ("trot", True)])
def test_stack_references_compiled_equal_python(robots, request, gait, posture, monkeypatch):
    """The native engine's per-cycle references computed in compiled code (τ bounds, stance
    anchors with their slip history, W_d and its errors, the posture target, the commanded
    wrench) equal those computed in Python from the same terms (the engine without
    ``wholebody._passive_references``), cycle after cycle, also after the impedance's gains, the
    torque limits' scale and caps, the posture gains and the control period change between
    cycles (read as they are, as the tasks' rows read theirs); so do the torques, on a robot
    whose own torque profile is scaled. ``posture``: the posture regulariser on every joint (on
    HyQ's legs of three joints it acts on none)."""
    robot = robots["hyq"]
    monkeypatch.setattr(robot.torque_limits, "scale", 0.9)  # the robot's own profile scaled
    compiled = PassiveWBC(robot, planner=planner(robot), engine="native")
    python = PassiveWBC(robot, planner=planner(robot), engine="native")
    python._references = None
    assert compiled._references is not None
    if posture:
        for wbc in (compiled, python):
            wbc.posture_mask[:] = 1.0
            wbc.configure()
        python._references = None
    states = request.getfixturevalue(f"{gait}_states")
    for k, (q, v, plan) in enumerate(states):
        if k == len(states) // 2:  # the impedance's gains are read as they are, as the QP's rows
            for wbc in (compiled, python):
                wbc.impedance.K_x = 1.5 * wbc.impedance.K_x
                wbc.impedance.D_theta = 0.5 * wbc.impedance.D_theta
                wbc.torque_limits.scale = 0.8
                wbc.torque_limits.upper_override = {robot.joint_names[2]: 30.0}
                wbc.posture_K, wbc.posture_D = 2.0 * wbc.posture_K, 0.5 * wbc.posture_D
                wbc.control_period = 0.005
        a, b = python.cycle(q, v, plan), compiled.cycle(q, v, plan)
        assert_same_solution(a, b)
        np.testing.assert_allclose(b.tau, a.tau, atol=1e-8, rtol=0)
        for x, y in zip(compiled._tau_bounds, python._tau_bounds):
            np.testing.assert_array_equal(x, y)
        np.testing.assert_allclose(compiled._anchors, python._anchors, atol=1e-14, rtol=0)
        np.testing.assert_allclose(compiled._stack.anchor_frames, python._stack.anchor_frames,
                                   atol=1e-14, rtol=0)
        np.testing.assert_allclose(compiled._stack.posture.target,
                                   python._stack.posture.target, atol=1e-10, rtol=1e-12)
        np.testing.assert_allclose(compiled.last_desired_wrench, python.last_desired_wrench,
                                   atol=1e-9, rtol=1e-12)
        np.testing.assert_allclose(compiled.impedance.last_errors, python.impedance.last_errors,
                                   atol=1e-12, rtol=0)
        np.testing.assert_allclose(compiled._commanded_wrench, python._commanded_wrench,
                                   atol=1e-7, rtol=1e-9)
    assert (np.abs(python._stack.posture.target).max() > 1e-3) == posture


@pytest.mark.parametrize("field,args", [
    ("q", lambda r: (np.full(r.nq, np.nan), np.zeros(r.nv))),
    ("q", lambda r: (np.zeros(r.nq - 1), np.zeros(r.nv))),
    ("v", lambda r: (r.q_ref, np.zeros(r.nv + 1))),
    ("quaternion", lambda r: (np.r_[r.q_ref[:3], 0.0, 0.0, 0.0, 2.0, r.q_ref[7:]], np.zeros(r.nv)))])
def test_bad_state_names_the_field(robots, field, args):
    robot = robots["hyq"]
    native = PassiveWBC(robot, planner=planner(robot), engine="native")
    with pytest.raises(ValueError, match=field):
        native.compute(*args(robot), 0.0)


@pytest.mark.parametrize("kwargs,match", [
    ({"engine": "gpu"}, "engine: expected one of .*'python'"),
    ({"engine": "stack"}, "engine: expected one of .*'native'")])
def test_bad_engine_options_name_the_field(robots, kwargs, match):
    with pytest.raises(ValueError, match=match):
        PassiveWBC(robots["hyq"], planner=planner(robots["hyq"]), **kwargs)


def test_trot_in_the_twin(robots):
    """Closed loop (250 Hz WBC, 1 kHz twin): HyQ trots with the native engine as with the Python
    one — no fall, no failed cycle, the same base trajectory to within 1 mm."""
    from wholebody.planning.trunk import VelocityCommand
    from wholebody.scenarios.locomotion import run_gait
    robot = robots["hyq"]
    command = VelocityCommand.speed_ramp(0.0, 0.3, 1.0, 2.0)
    runs = {engine: run_gait(robot, "passive", "trot", command, duration=3.0,
                             controller_options={"engine": engine})
            for engine in ("python", "native")}
    for run in runs.values():
        assert not run.fell and run.failures == 0
    assert runs["native"].distance > 0.2
    q_python, q_native = runs["python"].sim.state()[0], runs["native"].sim.state()[0]
    np.testing.assert_allclose(q_native[:3], q_python[:3], atol=1e-3)
    rotation = pin.Quaternion(q_native[3:7]).toRotationMatrix().T @ pin.Quaternion(
        q_python[3:7]).toRotationMatrix()
    assert np.linalg.norm(pin.log3(rotation)) < 1e-3


def extra_tasks(robot):
    """A hard force cap (a user's Python task) and a weighted hip posture (a library task)."""
    joints = [j for j in robot.joint_names if j.endswith("haa_joint")]
    hips = JointTrajectoryTask(joints, kp=60.0, kd=15.0, name="hips", weight=3.0)
    hips.position = np.full(len(joints), 0.1)
    return {"hard": [ForceCap(0.3 * robot.mass * 9.81)], "objective": [hips]}


def test_extra_tasks_equal_the_python_reference(robots, crawl_states):
    """Tasks added to the passive controller's QP (a user's Python constraint in the hard
    level, a library task in the objective) run on the native engine, the Python one's rows
    written into the compiled program: each cycle's torques equal the Python Formulation's on
    the same stack and the Python engine's, the user's cap holds on the solved forces (and
    binds: the controller without it exceeds it), and the hips' task residual is never larger
    than with the cap alone (a convex cost with one more term cannot increase that term at its
    optimum) and mostly smaller (the stance feet leave the hips little freedom)."""
    robot = robots["hyq"]
    wbc = PassiveWBC(robot, planner=planner(robot), extra_tasks=extra_tasks(robot))
    python = PassiveWBC(robot, planner=planner(robot), extra_tasks=extra_tasks(robot),
                        engine="python")
    plain = PassiveWBC(robot, planner=planner(robot), engine="native")
    cap_only = PassiveWBC(robot, planner=planner(robot),
                          extra_tasks={"hard": extra_tasks(robot)["hard"]})
    assert wbc.engine == "native" and wbc._stack_cycle.native
    cap = 0.3 * robot.mass * 9.81
    hips = [6 + robot.joint_names.index(j) for j in wbc.extra_tasks["objective"][0].joints]
    capped = closer = 0
    for k, (q, v, plan) in enumerate(crawl_states[::4]):
        sol, other = wbc.cycle(q, v, plan), plain.cycle(q, v, plan)
        without = cap_only.cycle(q, v, plan)
        assert sol.ok, sol.status
        _, variables = wbc._stack.update(plan, wbc.last_desired_wrench[:3])  # the same again
        robot.update(q, v)
        ref = Formulation(robot).solve(wbc._stack.stack, variables, STACK_SETTINGS)
        np.testing.assert_allclose(sol.tau, ref.tau, atol=1e-6, err_msg=f"cycle {k}")
        assert_same_solution(python.cycle(q, v, plan), sol, f"cycle {k}")
        fz = np.array([f[2] for f in sol.forces.values()])
        assert fz.max() <= cap + 1e-6
        capped += max(f[2] for f in other.forces.values()) > cap
        q_hip, v_hip = q[7 + np.array(hips) - 6], v[np.array(hips)]
        desired = 60.0 * (0.1 - q_hip) - 15.0 * v_hip
        residual = np.linalg.norm(sol.qdd[hips] - desired)
        assert residual <= np.linalg.norm(without.qdd[hips] - desired) + 1e-9, f"cycle {k}"
        closer += residual < np.linalg.norm(without.qdd[hips] - desired) - 1e-3
    assert capped > 0 and closer > len(crawl_states[::4]) // 2


@pytest.mark.parametrize("kwargs,match", [
    ({"extra_tasks": {"soft": []}}, "extra_tasks: level 'soft' is not one of"),
    ({"extra_tasks": {"hard": [1.0]}}, r"extra_tasks\['hard'\]: expected tasks"),
    ({"extra_tasks": {"hard": [ForceCap(1.0)], "objective": [ForceCap(2.0)]}},
     r"must be unique, got \['force cap'\]"),
    ({"extra_tasks": {"hard": [ForceCap(1.0, name="swing lf_foot")]}},
     r"the names \['swing lf_foot'\] are the controller's own")])
def test_bad_extra_tasks_name_the_field(robots, kwargs, match):
    robot = robots["hyq"]
    kwargs = {"extra_tasks": {"hard": [ForceCap(1.0)]}, **kwargs}
    with pytest.raises(ValueError, match=match):
        PassiveWBC(robot, planner=planner(robot), **kwargs)
