"""MomentumBalance (Herzog et al. 2016 Table 2, no joint PD) in closed loop in the twin."""

import numpy as np
import pytest

from wholebody.control.balance import MomentumBalance
from wholebody.scenarios.measures import TwinCentroidal
from wholebody.sim.simulator import Simulator


def run(robot, controller, steps, push=None):
    sim = Simulator(robot)
    if push is not None:
        sim.add_push(push)
    com_error, failures = [], 0
    twin = TwinCentroidal(robot)
    for _ in range(steps):
        q, v = sim.state()
        sol = controller.compute(q, v, sim.t)
        failures += not sol.ok
        com_error.append(twin.at(q, v)[0] - controller.com_ref)  # the twin's CoG
        sim.step(sol.tau)
    return np.array(com_error), failures


@pytest.mark.slow  # closed loop in the twin
@pytest.mark.parametrize("gains", ["pd", "lqr"])
def test_balance_holds_still(robots, gains):
    robot = robots["talos14"]
    err, failures = run(robot, MomentumBalance(robot, gains=gains), 1000)
    assert failures == 0 and np.abs(err).max() < 1e-3


@pytest.mark.slow  # closed loop in the twin
def test_push_scenario_recovers_and_detects_a_fall(robots):
    """Sect. 5.2.2 protocol, one push: 100 N x 0.1 s (6.4 Ns, Δv = 0.07 m/s on 90 kg) from the
    front above the hip is survived (CoG back within 5 mm, feet flat and in place); 350 N is not,
    and the scenario says so rather than calling it a success."""
    from wholebody.scenarios import get_scenario

    robot = robots["talos14"]
    push = get_scenario("push")
    ok = push.run(robot, "pd", {"peak_force": "100", "start": "0.2", "duration": "2.5"})
    assert ok.success and ok.metrics["failed_cycles"] == 0
    assert ok.metrics["impulse_Ns"] == pytest.approx(2 / np.pi * 100 * 0.1)
    assert 1e-3 < ok.metrics["max_cog_error_m"] < 0.05 and ok.metrics["final_cog_error_m"] < 5e-3
    assert ok.metrics["max_foot_tilt_deg"] < 2.0
    # independent check of the reported CoG error: the simulator's own state
    q_final = ok.log.arrays()["q"][-1]
    robot.update(q_final, np.zeros(robot.nv))
    assert np.linalg.norm(robot.com - MomentumBalance(robot).com_ref) < 5e-3
    bad = push.run(robot, "pd", {"peak_force": "350", "start": "0.2", "duration": "2.5"})
    assert not bad.success


@pytest.mark.slow  # closed loop in the twin
def test_push_series_table_and_claim(robots, tmp_path):
    """A one-point, one-force slice of the Sect. 5.2.2 protocol: both controllers run, Table 3 holds
    the strongest survived push per controller and point, the LQR-vs-PD claim is measured."""
    from wholebody.scenarios import get_scenario

    robot = robots["talos14"]
    series = get_scenario("push-series")
    res = series.run(robot, None, {"locations": "front", "forces": "60", "duration": "2.0",
                                   "q_angular": "10"}, out_dir=tmp_path)
    m = res.metrics
    assert m["trials"] == 2 and m["survived"] == {"pd": 1, "lqr": 1}
    for key in ("pd/front", "lqr/front"):
        row = m["table3"][key]
        assert row["peak_force_N"] == 60.0
        assert row["delta_v_mps"] == pytest.approx(row["impulse_Ns"] / robot.mass)
    assert m["pairs_survived_by_both"] == 1 and m["lqr_cog_error_le_pd_fraction"] in (0.0, 1.0)
    assert (tmp_path / "push_series.png").stat().st_size > 10_000
    with pytest.raises(ValueError, match="locations"):
        series.run(robot, None, {"locations": "nose"})



def test_integral_action_is_accumulated_clamped_on_by_default_and_off_at_zero(robots):
    """MomentumBalance(q_integral=...) (LQI, our extension; LQR only): the CoG-error integral grows
    by dt (com - com_ref) per compute() call, enters the force law as -K_integral z, and is clamped
    to +-integral_limit; the LQR integrates by default, and with q_integral=0 nothing is
    integrated (the paper's law)."""
    robot = robots["talos14"]
    with pytest.raises(ValueError, match="^q_integral"):
        MomentumBalance(robot, gains="pd", q_integral=1e6)
    q = robot.q_ref.copy()
    q[2] += 0.004  # base (and CoM) 4 mm above the reference
    v = np.zeros(robot.nv)
    assert MomentumBalance(robot, gains="lqr").lqr.integral
    assert not MomentumBalance(robot, gains="pd").lqr
    plain = MomentumBalance(robot, gains="lqr", q_integral=0)
    plain.compute(q, v, 0.0)
    plain.compute(q, v, 0.5)
    assert not plain.lqr.integral and np.all(plain.cog_integral == 0.0)
    k_plain = plain.momentum.k.copy()

    ctrl = MomentumBalance(robot, gains="lqr", q_integral=1e6, integral_limit=0.01)
    ctrl.compute(q, v, 0.0)  # first call: dt = 0
    assert np.all(ctrl.cog_integral == 0.0)
    k0 = ctrl.momentum.k.copy()
    ctrl.compute(q, v, 0.5)
    err = ctrl.com - ctrl.com_ref  # the CoM of the state the controller read
    assert err[2] == pytest.approx(0.004, abs=1e-6)
    np.testing.assert_allclose(ctrl.cog_integral, 0.5 * err, atol=1e-12)
    Ki = ctrl.lqr.gains(robot).K_integral
    np.testing.assert_allclose(ctrl.momentum.k, k0 - Ki @ ctrl.cog_integral, atol=1e-9)
    ctrl.compute(q, v, 10.5)  # 10 s more: 0.042 m s, clamped
    assert ctrl.cog_integral[2] == pytest.approx(0.01)
    ctrl.reset_integral()
    ctrl.compute(q, v, 11.0)
    assert np.all(ctrl.cog_integral == 0.0)
    assert np.abs(k0 - k_plain).max() > 1e-3  # the integral design also changes the state gains


def test_references_are_checked_when_set(robots):
    """The momentum law's references are checked on every assignment (a reference callable
    sets them every cycle), each error naming the field; the control loop then computes on them
    unchecked (MomentumLQR.force_law)."""
    ctrl = MomentumBalance(robots["talos14"], gains="lqr")
    for field, value in (("com_ref", [0.0, np.nan, 0.8]), ("h_ref", np.zeros(5)),
                         ("hdot_ref", [np.inf] + [0.0] * 5)):
        with pytest.raises(ValueError, match=f"^MomentumBalance.{field}:"):
            setattr(ctrl, field, value)
    ctrl.h_ref = [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    assert ctrl.h_ref.dtype == float and ctrl.h_ref[5] == 1.0


@pytest.mark.slow  # closed loop in the twin
@pytest.mark.parametrize("gains", ["pd", "lqr"])
def test_native_engine_gives_the_python_engines_torques_through_a_push(robots, gains):
    """MomentumBalance(engine="native") — the Table 2 stack solved by HierarchyCycle's compiled
    rigid-body terms and rows — drives the twin through a 150 N push; every 25th cycle a
    Python-engine controller fed the same state (and the same references) gives the same torques.
    The push is survived as with the Python engine (CoG back within 5 mm)."""
    pytest.importorskip("wholebody._hierarchy_cycle")
    from wholebody.sim.disturbance import Push

    robot = robots["talos14"]
    native = MomentumBalance(robot, gains=gains, engine="native")
    python = MomentumBalance(robot, gains=gains, engine="python")
    assert native.cycle is not None and native.cycle.native and python.cycle is None
    twin = TwinCentroidal(robot)
    sim = Simulator(robot)
    sim.add_push(Push("base_link", (-1.0, 0.0, 0.0), 150.0, 0.2, 0.1))
    diffs, com_error = [], []
    for k in range(1500):
        q, v = sim.state()
        sol = native.compute(q, v, sim.t)
        assert sol.ok
        ref = python.compute(q, v, sim.t)  # every cycle: the LQR's CoG-error integral in step
        if k % 25 == 0:
            diffs.append(np.linalg.norm(sol.tau - ref.tau) / np.linalg.norm(ref.tau))
        com_error.append(np.linalg.norm(twin.at(q, v)[0] - native.com_ref))
        sim.step(sol.tau)
    assert max(diffs) < 1e-6, max(diffs)
    assert max(com_error) > 5e-3 and com_error[-1] < 5e-3


def test_orientation_state_measures_the_base_and_enters_k(robots):
    """MomentumBalance(q_orientation=...) (ours; LQR only) feeds back the base's rotation from the
    posture's base reference as a world-axes rotation vector (checked against scipy's), through
    -K_orientation theta in the force law; without it the law is the paper's."""
    from scipy.spatial.transform import Rotation

    robot = robots["talos14"]
    with pytest.raises(ValueError, match="^q_orientation"):
        MomentumBalance(robot, gains="pd", q_orientation=10.0)
    turn = Rotation.from_rotvec([0.02, -0.05, 0.01])
    q = robot.q_ref.copy()
    q[3:7] = (turn * Rotation.from_quat(robot.q_ref[3:7])).as_quat()  # world-frame turn, xyzw
    v = np.zeros(robot.nv)
    ctrl = MomentumBalance(robot, gains="lqr", q_orientation=10.0, engine="python")
    ctrl.compute(q, v, 0.0)
    np.testing.assert_allclose(ctrl.base_orientation_error(), turn.as_rotvec(), atol=1e-12)
    plain = MomentumBalance(robot, gains="lqr", engine="python")
    plain.compute(q, v, 0.0)
    K_or = ctrl.lqr.gains(robot).K_orientation
    assert plain.lqr.gains(robot).K_orientation is None
    _, k_at_rest = ctrl.lqr.feedback(robot, ctrl.com_ref)
    np.testing.assert_allclose(ctrl.momentum.k, k_at_rest - K_or @ turn.as_rotvec(), atol=1e-9)


def test_measures_tilt_slip_and_recovery():
    """The shared measures: tilt of a rotation, horizontal slip, CoG recovery after a push."""
    import pinocchio as pin

    from wholebody.scenarios.measures import Thresholds, rotation_angle_deg, sole_slip, tilt_deg
    from scipy.spatial.transform import Rotation

    a, b = Rotation.from_rotvec([0.1, 0.2, -0.3]), Rotation.from_rotvec([0.0, 0.05, 0.02])
    assert rotation_angle_deg(a.as_quat(), b.as_quat()) == pytest.approx(
        np.degrees(np.linalg.norm((a * b.inv()).as_rotvec())))
    assert rotation_angle_deg(a.as_quat(), -a.as_quat()) == pytest.approx(0.0, abs=1e-4)
    assert tilt_deg(pin.rpy.rpyToMatrix(0.0, np.radians(3.0), 0.0)) == pytest.approx(3.0)
    assert sole_slip(np.array([0.003, 0.004, 0.5]), np.zeros(3)) == pytest.approx(0.005)
    talos14 = Thresholds()  # 1 cm slip, 5 mm CoG
    assert talos14.feet_in_place(1.9, 0.009) and not talos14.feet_in_place(2.0, 0.0)
    assert not talos14.feet_in_place(0.0, 0.011)
    t = np.arange(0.0, 5.0, 0.001)
    err = np.where((t > 0.6) & (t < 1.5), 0.01, 0.0)
    recovered, recovery = talos14.cog_recovered(t, err, end=0.6)
    assert recovered and recovery == pytest.approx(0.9, abs=2e-3)
    assert not talos14.cog_recovered(t, np.full_like(t, 1.0), end=0.6)[0]
    assert not talos14.cog_recovered(t, np.full_like(t, 0.0051), end=0.6)[0]
    assert "slip < 10.0 mm" in talos14.push_criteria()
    assert "within 5.0 mm" in talos14.push_criteria()


def test_measures_update_the_robot_only_to_a_new_state(robots):
    """The measures' update of the robot: none for the state of its cycle (the same bytes, or
    +0.0 where it has -0.0: equal numbers), one for any other state, after which the robot's CoM
    is Pinocchio's of that state."""
    import pinocchio as pin

    from wholebody.scenarios.measures import update_to_state

    robot = robots["talos14"]
    q, v = robot.q_ref.copy(), np.zeros(robot.nv)
    v[-1] = -0.0
    robot.update(q, v)
    cycle = robot.cycle
    update_to_state(robot, q.copy(), np.abs(v))  # -0.0 -> +0.0: equal numbers
    assert robot.cycle == cycle
    moved = q.copy()
    moved[0] += 0.01
    update_to_state(robot, moved, v)
    assert robot.cycle == cycle + 1
    data = robot.model.createData()
    np.testing.assert_allclose(robot.com, pin.centerOfMass(robot.model, data, moved), atol=1e-12)


@pytest.mark.parametrize("name", ["romeo", "g1"])
def test_thresholds_keep_talos14s_proportions(robots, name):
    """The survival thresholds are talos14's (1 cm slip, 5 mm CoG, 10 cm fall) on talos14 and
    the same dimensionless numbers on another humanoid: lengths over the standing base height,
    momenta over m sqrt(g h) and m h sqrt(g h)."""
    from wholebody.scenarios.measures import Thresholds

    import wholebody as wb
    from conftest import g1_description

    talos14 = robots["talos14"]
    other = wb.load_robot(g1_description()) if name == "g1" else robots[name]
    assert Thresholds.for_robot(talos14) == Thresholds(max_slip=0.01, cog_tolerance=0.005,
                                                       fall_cog_error=0.1)

    def dimensionless(robot):
        th, h, m, g = Thresholds.for_robot(robot), float(robot.q_ref[2]), robot.mass, 9.81
        v = np.sqrt(g * h)
        return np.array([th.max_slip / h, th.cog_tolerance / h, th.fall_cog_error / h,
                         th.max_base_drop / h, th.step_cog_error / h,
                         th.final_linear_momentum / (m * v),
                         th.final_angular_momentum / (m * h * v)])

    np.testing.assert_allclose(dimensionless(other), dimensionless(talos14), rtol=1e-12)
    assert Thresholds.for_robot(other).max_slip != 0.01  # a robot of another height


def test_quintic_blend_scalar_and_array_agree():
    from wholebody.planning.blend import quintic_blend

    u = np.linspace(-0.5, 1.5, 41)
    s, ds, dds = quintic_blend(u, 2.0)
    for i, x in enumerate(u):
        assert quintic_blend(float(x), 2.0) == (s[i], ds[i], dds[i])
    assert quintic_blend(0.5) == (0.5, 1.875, 0.0)


def test_pd_gains_from_the_scenario_parameters(robots):
    """``--set pd_stiffness/pd_damping/pd_angular_damping`` reach eq. 22: the momentum task's rate
    is P m (x_ref - x) + D (h_ref - h), recomputed here from the robot's CoM and momentum; with
    LQR gains they are ignored and say so."""
    from wholebody.scenarios.pushes import controller_options, ignored_option_notes
    robot = robots["talos14"]
    params = {"pd_stiffness": 14.0, "pd_damping": 7.5, "pd_angular_damping": 2.0}
    ctrl = MomentumBalance(robot, gains="pd", **controller_options("pd", params))
    q, v = robot.smooth_motion(3, 0.05)[2]
    robot.update(q, v)
    task = ctrl.stack.find("momentum")
    task.com_ref = robot.com + np.array([0.01, -0.02, 0.005])
    expected = np.r_[14.0 * robot.mass * (task.com_ref - robot.com), np.zeros(3)]
    expected += np.r_[np.full(3, 7.5), np.full(3, 2.0)] * (0.0 - robot.h_G)
    np.testing.assert_allclose(task.desired_rate(robot), expected, rtol=1e-12, atol=1e-9)
    assert ignored_option_notes("pd", params) == []
    notes = ignored_option_notes("lqr", params)
    assert len(notes) == 3 and all("ignored with the LQR gains" in n for n in notes)
    assert ignored_option_notes("pd", {"q_integral": 1.0}) == [
        "q_integral is an LQR option; ignored with the PD gains"]


def test_push_series_hands_every_controller_option_to_its_trials(monkeypatch):
    """push-series and its bisection build each trial from the scenario's parameters: the
    momentum-balance options (PD gains among them) reach every push."""
    from types import SimpleNamespace

    from wholebody.scenarios import push_series
    from wholebody.scenarios.pushes import CONTROLLER_PARAMETERS

    seen = []
    monkeypatch.setattr(push_series, "push_trial", lambda robot, controller, p, observers=(): (
        seen.append(p) or SimpleNamespace(success=True, metrics={})))
    params = {"push_duration": 0.1, "duration": 3.5, "q_angular": 2.0, "angular_weight": 1e-3,
              "q_integral": 0.0, "integral_limit": 0.01, "q_orientation": 5.0, "pd_stiffness": 14.0,
              "pd_damping": 7.5, "pd_angular_damping": 2.0, "posture_stiffness": 30.0,
              "posture_damping": 9.0, "cop_margin": 0.05, "engine": "python"}
    push_series._one(None, "pd", "front", 100.0, params)
    (p,) = seen
    assert {o.name: p[o.name] for o in CONTROLLER_PARAMETERS} == {
        o.name: params[o.name] for o in CONTROLLER_PARAMETERS}


HUMANOID_SCENARIOS = ("push", "push-series", "robust-push", "platform", "tilt-board", "squat",
                      "single-support", "stepping")


@pytest.mark.parametrize("name", HUMANOID_SCENARIOS)
def test_humanoid_scenarios_take_the_task_gains(name):
    """Every humanoid scenario declares the posture task's PD; those with a swing foot (single
    support, stepping) its PD, stepping the CoG task's; the defaults are the stacks' own."""
    from wholebody.control.stacks import COM_PD, POSTURE_PD, SWING_FOOT_PD
    from wholebody.scenarios import get_scenario

    params = {p.name: p.default for p in get_scenario(name).parameters}
    expected = {"posture": POSTURE_PD}
    if name in ("single-support", "stepping"):
        expected["swing"] = SWING_FOOT_PD
    if name == "stepping":
        expected["com"] = COM_PD
    for task in ("posture", "swing", "com"):
        declared = (params.get(f"{task}_stiffness"), params.get(f"{task}_damping"))
        assert declared == expected.get(task, (None, None)), (name, task)


def test_task_gains_reach_every_hierarchy(robots):
    """``--set posture_stiffness=30 --set posture_damping=9`` (and the swing-foot and CoG PDs where
    declared): the momentum balance of the push scenarios, every stack of the contact switch and
    of stepping hold exactly those gains (joints and base alike); the defaults are the stacks'."""
    from wholebody.control.contact_switch import ContactSwitch
    from wholebody.control.stacks import COP_MARGIN, POSTURE_PD
    from wholebody.control.stepping import Stepping
    from wholebody.scenarios import get_scenario, single_support, stepping
    from wholebody.scenarios.pushes import controller_options

    robot = robots["talos14"]
    sets = {"posture_stiffness": "30", "posture_damping": "9", "swing_stiffness": "250",
            "swing_damping": "31", "com_stiffness": "64", "com_damping": "16"}

    def check(stack, posture=(30.0, 9.0)):
        task = stack.find("posture")  # single support's swing leg: no stiffness, the rest kp
        assert (np.max(task.kp), task.kd, task.base_kp, task.base_kd) == (
            posture[0], posture[1], posture[0], posture[1])

    params = get_scenario("push").validate(robot, {**{k: v for k, v in sets.items()
                                                      if k.startswith("posture")},
                                                   "cop_margin": "0.2"})
    balance = MomentumBalance(robot, "pd", **controller_options("pd", params))
    check(balance.stack)
    assert balance.stack.find("center of pressure").margin == 0.2
    check(MomentumBalance(robot, "pd", **controller_options("pd", {})).stack, POSTURE_PD)

    params = get_scenario("single-support").validate(
        robot, {k: v for k, v in sets.items() if not k.startswith("com")})
    stance, _ = single_support.stance_and_swing(robot, params)
    ctrl = ContactSwitch(robot, stance, single_support.config(robot, params), gains="lqr")
    for stack in (ctrl.double, ctrl.single, ctrl.swinging):
        check(stack)
        assert stack.find("center of pressure").margin == COP_MARGIN
    assert (ctrl.swing.kp, ctrl.swing.kd) == (250.0, 31.0)

    params = get_scenario("stepping").validate(robot, sets)
    ctrl = Stepping(robot, stepping.config(robot, params), engine="python")
    for stack in (ctrl.double, *ctrl.single.values()):
        check(stack)
        com = stack.find("com")
        assert (com.kp, com.kd) == (64.0, 16.0)
    for task in ctrl.swing_task.values():
        assert (task.kp, task.kd) == (250.0, 31.0)


def test_single_support_takes_the_pd_gains(robots):
    """``single-support --set pd_stiffness/pd_damping``: every stack of the contact switch (double
    support, single support, leg swinging) has eq. 22's gains from the parameters; LQR gains
    refuse them."""
    from wholebody.control.contact_switch import ContactSwitch
    from wholebody.scenarios import get_scenario
    from wholebody.scenarios import single_support
    from wholebody.scenarios.base import momentum_gains

    robot = robots["talos14"]
    params = get_scenario("single-support").validate(robot, {"pd_stiffness": "14",
                                                               "pd_damping": "7.5"})
    stance, _ = single_support.stance_and_swing(robot, params)
    ctrl = ContactSwitch(robot, stance, single_support.config(robot, params), gains="pd",
                         **momentum_gains("pd", params))
    for stack in (ctrl.double, ctrl.single, ctrl.swinging):
        task = stack.find("momentum")
        np.testing.assert_array_equal(np.diag(task.P), [14.0] * 3 + [0.0] * 3)
        np.testing.assert_array_equal(np.diag(task.D), [7.5] * 3 + [5.0] * 3)
    with pytest.raises(ValueError, match="only used with gains='pd'"):
        ContactSwitch(robot, stance, single_support.config(robot, params), gains="lqr",
                      P=np.full(6, 14.0))
