"""Gains derived from the robot: the standing PD (kp = ω² M_ii, kd = 2 ζ ω M_ii) and the passive
WBC's trunk impedance and force bound (K = m ω², D = 2 ζ m ω, K_θ = I ω_θ², f_max = n m g).

The evidence is independent of the code under test: the joint inertia is measured by Newton-Euler
(RNEA, a unit joint acceleration), the centroidal inertia is summed body by body with the parallel
axis theorem, the mass scaling comes from a URDF whose masses and inertias are multiplied by k, and
HyQ's gains are compared with the numbers printed in Fahmi et al. 2019 (Sect. V)."""

import math
import re

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.control import StandingController
from wholebody.control.passive import PassiveConfig, PassiveWBC
from wholebody.control.quasi_static import QuasiStaticController
from wholebody.robots.locate import resolve_model_path
from wholebody.scenarios import get_scenario
from wholebody.tasks.wrench import TrunkImpedance, force_bound, trunk_gains, trunk_inertia

G = 9.81
# Fahmi et al. 2019, Sect. V (HyQ): K_x, D_x, K_theta, D_theta, f_max
PAPER = {"K_x": 2000.0, "D_x": 400.0, "K_theta": 1000.0, "D_theta": 200.0, "f_max": 2000.0}
SMALL = ("go1", "go2", "a1", "solo12")


@pytest.fixture(scope="module")
def quadrupeds():
    return {name: wb.load_robot(name) for name in ("hyq",) + SMALL}


def planner(robot):
    from types import SimpleNamespace
    return SimpleNamespace(legs=robot.contact_names)


def free_joint_inertia(robot):
    """Each joint's inertia with the rest of the robot free, by the articulated-body algorithm: a
    unit torque on joint i alone, at rest, accelerates it by (M^-1)_ii (gravity removed by
    subtracting the zero-torque acceleration); the inertia is its inverse."""
    model, q = robot.model, robot.q_ref
    zero = np.zeros(robot.nv)
    drift = pin.aba(model, model.createData(), q, zero, zero)
    out = np.empty(robot.na)
    for i in range(robot.na):
        tau = zero.copy()
        tau[6 + i] = 1.0
        out[i] = 1.0 / (pin.aba(model, model.createData(), q, zero, tau) - drift)[6 + i]
    return out


def centroidal_inertia_by_bodies(robot):
    """I_G at the reference posture from the bodies' inertias: Σ R I_b Rᵀ + m (|r|² 1 − r rᵀ)
    about the robot's CoM."""
    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, robot.q_ref)
    masses, centres, rotated = [], [], []
    for j in range(1, model.njoints):
        body, placement = model.inertias[j], data.oMi[j]
        masses.append(body.mass)
        centres.append(placement.act(body.lever))
        rotated.append(placement.rotation @ body.inertia @ placement.rotation.T)
    masses, centres = np.array(masses), np.array(centres)
    com = masses @ centres / masses.sum()
    inertia = np.zeros((3, 3))
    for m, c, rot in zip(masses, centres, rotated):
        r = c - com
        inertia += rot + m * (r @ r * np.eye(3) - np.outer(r, r))
    return inertia


# ---------------------------------------------------------------------- standing PD
@pytest.mark.parametrize("name", ["talos14", "hyq", "go1", "solo12"])
def test_standing_gains_are_frequency_and_damping_on_the_joint_inertia(name, robots, quadrupeds):
    robot = robots[name] if name in robots else quadrupeds[name]
    inertia = free_joint_inertia(robot)  # includes the armature (talos14: 0.1 kg m²)
    held = np.diag(pin.crba(robot.model, robot.model.createData(), robot.q_ref))[6:]
    assert np.all(inertia <= held * (1 + 1e-9))  # never more than with the other joints held
    ctrl = StandingController(robot, frequency_hz=4.0, damping_ratio=0.7)
    omega = 2 * math.pi * 4.0
    np.testing.assert_allclose(ctrl.kp, omega ** 2 * inertia, rtol=1e-9)
    np.testing.assert_allclose(ctrl.kd, 2 * 0.7 * omega * inertia, rtol=1e-9)
    # every joint's loop has the same frequency and damping ratio
    np.testing.assert_allclose(np.sqrt(ctrl.kp / inertia), omega, rtol=1e-9)
    np.testing.assert_allclose(ctrl.kd / (2 * np.sqrt(ctrl.kp * inertia)), 0.7, rtol=1e-9)


def test_armature_enters_the_joint_inertia(robots):
    """talos14's 0.1 kg m² reflected rotor inertia is part of the inertia the gains scale: with it
    removed from the model, every joint's free inertia (and so its kp) is smaller by about that."""
    robot = robots["talos14"]
    model = pin.Model(robot.model)
    model.armature[:] = 0.0
    bare = 1.0 / np.diag(pin.computeMinverse(model, model.createData(), robot.q_ref))[6:]
    ctrl = StandingController(robot, frequency_hz=1.0 / (2 * math.pi))  # ω = 1: kp = m_i
    np.testing.assert_allclose(ctrl.kp, free_joint_inertia(robot), rtol=1e-9)
    assert np.all(ctrl.kp - bare > 0.09)  # every joint's own 0.1, and its neighbours' through M


def _scaled_robot(tmp_path, name: str, k: float):
    """The preset ``name`` with every link mass and inertia of its URDF multiplied by ``k``."""
    base = wb.load_robot(name).description
    text = resolve_model_path(base.urdf, base.base_dir).read_text()

    def scale(match):
        return f'{match.group(1)}="{float(match.group(2)) * k!r}"'
    text = re.sub(r'<mass\s+value="([^"]+)"',
                  lambda m: f'<mass value="{float(m.group(1)) * k!r}"', text)
    text = re.sub(r'\b(i[xyz]{2})="([^"]+)"', scale, text)
    urdf = tmp_path / f"{name}_x{k:g}.urdf"
    urdf.write_text(text)
    return wb.load_robot({
        "name": f"{name}_x{k:g}", "urdf": str(urdf), "srdf": base.srdf, "posture": base.posture,
        "contacts": [{"name": c.name, "frame": c.frame, "type": c.type, "radius": c.radius}
                     for c in base.contacts],
        "torque_limits": base.torque_limits, "friction": base.friction})


@pytest.mark.parametrize("name", ["go1", "solo12"])
def test_gains_scale_with_the_robots_masses(tmp_path, quadrupeds, name):
    """Masses and inertias x k (same geometry): every derived gain and the force bound x k."""
    k = 3.0
    robot, heavy = quadrupeds[name], _scaled_robot(tmp_path, name, k)
    assert heavy.mass == pytest.approx(k * robot.mass, rel=1e-12)
    np.testing.assert_allclose(heavy.q_ref, robot.q_ref, atol=1e-12)
    light_pd, heavy_pd = StandingController(robot), StandingController(heavy)
    np.testing.assert_allclose(heavy_pd.kp, k * light_pd.kp, rtol=1e-9)
    np.testing.assert_allclose(heavy_pd.kd, k * light_pd.kd, rtol=1e-9)
    light, heavy_wbc = PassiveWBC(robot, planner(robot)), PassiveWBC(heavy, planner(heavy))
    for gain in ("K_x", "D_x", "K_theta", "D_theta"):
        np.testing.assert_allclose(getattr(heavy_wbc.impedance, gain),
                                   k * getattr(light.impedance, gain), rtol=1e-9, err_msg=gain)
    assert heavy_wbc.f_max == pytest.approx(k * light.f_max, rel=1e-9)
    light_qs, heavy_qs = (QuasiStaticController(robot, planner(robot)),
                          QuasiStaticController(heavy, planner(heavy)))
    assert heavy_qs.swing_K == pytest.approx(k * light_qs.swing_K, rel=1e-9)
    assert heavy_qs.swing_D == pytest.approx(k * light_qs.swing_D, rel=1e-9)


# ---------------------------------------------------------------------- trunk impedance
def test_hyq_gets_the_papers_gains(quadrupeds):
    """HyQ's defaults are Fahmi et al.'s numbers, not a rounding of them (its crawl and passivity
    results must not change)."""
    robot = quadrupeds["hyq"]
    for wbc in (PassiveWBC(robot, planner(robot)), QuasiStaticController(robot, planner(robot))):
        imp = wbc.impedance
        np.testing.assert_array_equal(imp.K_x, PAPER["K_x"])
        np.testing.assert_array_equal(imp.D_x, PAPER["D_x"])
        assert wbc.f_max == PAPER["f_max"]
        # the rotational gains go through Pinocchio's centroidal inertia: exact on this build,
        # allowed the last bit elsewhere
        np.testing.assert_allclose(imp.K_theta, PAPER["K_theta"], rtol=1e-13, atol=0)
        np.testing.assert_allclose(imp.D_theta, PAPER["D_theta"], rtol=1e-13, atol=0)
        assert tuple(wbc.Q) == (1.0,) * 6  # the trunk weights stay ours, exactly 1
    # the baseline's swing PD of the crawl comparison keeps the values it was tuned with on HyQ
    qs = QuasiStaticController(robot, planner(robot))
    assert (qs.swing_K, qs.swing_D) == (2000.0, 50.0)
    # explicit absolute values still win
    wbc = PassiveWBC(robot, planner(robot), f_max=1500.0, impedance=TrunkImpedance(K_x=123.0))
    assert wbc.f_max == 1500.0 and np.all(wbc.impedance.K_x == 123.0)


def test_trunk_inertia_is_the_mean_centroidal_moment(quadrupeds):
    for robot in quadrupeds.values():
        expected = np.trace(centroidal_inertia_by_bodies(robot)) / 3
        assert trunk_inertia(robot) == pytest.approx(expected, rel=1e-9), robot.name


def standing_height(robot):
    """The base above the lowest foot point in the reference posture (Pinocchio kinematics)."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    lowest = min(data.oMf[c.frame_id].translation[2] - c.spec.radius for c in robot.contacts)
    return robot.q_ref[2] - lowest


def test_small_quadrupeds_get_hyqs_dynamics_scaled_to_their_size(quadrupeds):
    """Not HyQ's absolute gains (a 2000 N/m spring on a 2.5 kg Solo12) but its dynamics: the same
    damping ratios ζ = D / (2 sqrt(K m)) for the CoM, and for the trunk rotation on I_G, and the
    frequencies ω = sqrt(K/m) of a dynamically similar robot, HyQ's times sqrt(h_HyQ / h) (h the
    standing height: the gait's times scale by sqrt(h / h_HyQ))."""
    hyq = quadrupeds["hyq"]
    m0, i0 = hyq.mass, np.trace(centroidal_inertia_by_bodies(hyq)) / 3
    w_x, z_x = math.sqrt(PAPER["K_x"] / m0), PAPER["D_x"] / (2 * math.sqrt(PAPER["K_x"] * m0))
    w_t = math.sqrt(PAPER["K_theta"] / i0)
    z_t = PAPER["D_theta"] / (2 * math.sqrt(PAPER["K_theta"] * i0))
    for name in SMALL:
        robot = quadrupeds[name]
        m, inertia = robot.mass, np.trace(centroidal_inertia_by_bodies(robot)) / 3
        faster = math.sqrt(standing_height(hyq) / standing_height(robot))
        imp = PassiveWBC(robot, planner(robot)).impedance
        K_x, D_x, K_t, D_t = (float(getattr(imp, g)[0])
                              for g in ("K_x", "D_x", "K_theta", "D_theta"))
        assert K_x < 0.5 * PAPER["K_x"]  # a fraction of HyQ's: these robots weigh 2.5-16 kg
        assert math.sqrt(K_x / m) == pytest.approx(w_x * faster, rel=1e-9), name
        assert D_x / (2 * math.sqrt(K_x * m)) == pytest.approx(z_x, rel=1e-9), name
        assert math.sqrt(K_t / inertia) == pytest.approx(w_t * faster, rel=1e-9), name
        assert D_t / (2 * math.sqrt(K_t * inertia)) == pytest.approx(z_t, rel=1e-9), name
        f_max = PassiveWBC(robot, planner(robot)).f_max
        assert f_max / (m * G) == pytest.approx(PAPER["f_max"] / (m0 * G), rel=1e-9), name


def test_explicit_trunk_frequencies(quadrupeds):
    robot = quadrupeds["go1"]
    gains = trunk_gains(robot, frequency_x_hz=2.0, damping_ratio_x=0.7, frequency_theta_hz=3.0,
                        damping_ratio_theta=1.0)
    m, inertia = robot.mass, np.trace(centroidal_inertia_by_bodies(robot)) / 3
    w_x, w_t = 2 * math.pi * 2.0, 2 * math.pi * 3.0
    assert gains["K_x"] == pytest.approx(m * w_x ** 2, rel=1e-9)
    assert gains["D_x"] == pytest.approx(2 * 0.7 * m * w_x, rel=1e-9)
    assert gains["K_theta"] == pytest.approx(inertia * w_t ** 2, rel=1e-9)
    assert gains["D_theta"] == pytest.approx(2 * 1.0 * inertia * w_t, rel=1e-9)
    assert force_bound(robot, 3.0) == pytest.approx(3.0 * m * G, rel=1e-9)
    wbc = PassiveWBC(robot, planner(robot), f_max_weights=3.0)
    assert wbc.f_max == pytest.approx(3.0 * m * G, rel=1e-9)


# ---------------------------------------------------------------------- checks
@pytest.mark.parametrize("kwargs,needle", [
    ({"frequency_hz": 0.0}, "frequency_hz: expected a positive number, got 0.0"),
    ({"frequency_hz": float("nan")}, "frequency_hz"),
    ({"damping_ratio": -0.5}, "damping_ratio: expected a finite number in [0, inf], got -0.5"),
    ({"damping_ratio": float("inf")}, "damping_ratio"),
    ({"kp": -1.0}, "kp"), ({"kd": float("nan")}, "kd"),
])
def test_standing_arguments_are_checked(robots, kwargs, needle):
    with pytest.raises(ValueError, match=re.escape(needle)):
        StandingController(robots["hyq"], **kwargs)


def test_explicit_standing_gains_override(robots):
    robot = robots["hyq"]
    relative = StandingController(robot)
    both = StandingController(robot, kp=1000.0, kd=30.0)
    assert np.all(both.kp == 1000.0) and np.all(both.kd == 30.0)
    only_kp = StandingController(robot, kp=50.0)
    assert np.all(only_kp.kp == 50.0)
    np.testing.assert_array_equal(only_kp.kd, relative.kd)


@pytest.mark.parametrize("kwargs,needle", [
    ({"frequency_x_hz": 0.0}, "frequency_x_hz"),
    ({"frequency_theta_hz": -1.0}, "frequency_theta_hz"),
    ({"damping_ratio_x": float("nan")}, "damping_ratio_x"),
    ({"damping_ratio_theta": -1.0}, "damping_ratio_theta"),
])
def test_trunk_arguments_are_checked(quadrupeds, kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        TrunkImpedance.for_robot(quadrupeds["go1"], **kwargs)


@pytest.mark.parametrize("kwargs,needle", [
    ({"f_max_weights": 0.0}, "f_max_weights"), ({"f_max_weights": float("nan")}, "f_max_weights"),
    ({"f_min": 1e6}, "f_max_weights"),  # the derived bound must exceed f_min
])
def test_force_bound_arguments_are_checked(quadrupeds, kwargs, needle):
    robot = quadrupeds["go1"]
    with pytest.raises(ValueError, match=needle):
        PassiveWBC(robot, planner(robot), **kwargs)
    with pytest.raises(ValueError, match="f_max_weights"):
        PassiveConfig(f_max_weights=-1.0)


def test_stand_scenario_declares_frequency_and_damping_ratio():
    params = {p.name: p for p in get_scenario("stand").parameters}
    freq, zeta = params["frequency_hz"], params["damping_ratio"]
    assert freq.low == 0.0 and freq.low_open and math.isfinite(freq.high)
    assert zeta.low == 0.0 and math.isfinite(zeta.high)
    assert freq.parse("5") == 5.0 and zeta.parse("0.7") == 0.7
    for p, bad in ((freq, "0"), (freq, "1e6"), (zeta, "-0.1"), (zeta, "nan")):
        with pytest.raises(ValueError, match=f"--set {p.name}"):
            p.parse(bad)
    # kp / kd: -1 (derived) or an explicit gain >= 0
    assert params["kp"].parse("-1") == -1.0 and params["kp"].parse("1000") == 1000.0
    with pytest.raises(ValueError, match="--set kd"):
        params["kd"].parse("-5")


QUADRUPED_SCENARIOS = ("crawl", "ramp", "friction-mismatch", "joint-limit", "weak-joint",
                       "regularization", "unstable-foothold", "passivity", "steer")


@pytest.mark.parametrize("name", QUADRUPED_SCENARIOS)
def test_quadruped_scenarios_take_the_trunk_gains(name):
    """Every quadruped scenario declares the trunk impedance's frequencies and damping ratios
    (their defaults, 0 Hz, keep the robot-relative gains) and the swing impedance's gains."""
    params = {p.name: p for p in get_scenario(name).parameters}
    for key in ("trunk_frequency", "trunk_damping_ratio", "trunk_angular_frequency",
                "trunk_angular_damping_ratio", "trunk_pitch_weight", "swing_stiffness",
                "swing_damping", "stance_stiffness", "stance_damping", "posture_frequency",
                "posture_damping_ratio", "clearance", "period"):
        assert key in params, (name, key)
    assert params["trunk_frequency"].default == 0.0
    assert params["posture_frequency"].default == 0.0
    assert params["period"].default == 0.0  # HyQ's, Froude-scaled
    assert str(params["clearance"].default).endswith(" h")  # HyQ's 0.1 m in proportion
    # the defaults are the controllers' own
    assert (params["stance_stiffness"].default, params["stance_damping"].default) == (
        PassiveConfig.K_st, PassiveConfig.D_st)
    assert params["posture_damping_ratio"].default == PassiveConfig.posture_damping
    baseline = any("quasi-static" in c for c in get_scenario(name).controllers)
    assert ("baseline_swing_stiffness" in params) == baseline  # those that run the baseline
    with pytest.raises(ValueError, match="--set trunk_frequency"):
        params["trunk_frequency"].parse("-1")


def test_trunk_gains_reach_the_controller_in_closed_loop(quadrupeds):
    """``--set trunk_frequency=2 --set trunk_angular_frequency=3 --set swing_stiffness=900
    --set trunk_pitch_weight=0.4``: the passive WBC that run_gait builds has K_x = m (2 pi 2)^2
    and K_theta = I (2 pi 3)^2 (I summed body by body here), K_sw = 900 and the pitch weight 0.4;
    without them, the robot-relative defaults."""
    from wholebody.scenarios.locomotion import run_gait, wbc_gains
    robot = quadrupeds["go1"]
    params = {"trunk_frequency": 2.0, "trunk_damping_ratio": 0.7,
              "trunk_angular_frequency": 3.0, "trunk_angular_damping_ratio": 1.0,
              "swing_stiffness": 900.0, "swing_damping": 15.0, "trunk_pitch_weight": 0.4}
    run = run_gait(robot, "passive", "stand", duration=0.02, gains=wbc_gains(params))
    assert (run.controller.swing.K, run.controller.swing.D) == (900.0, 15.0)
    assert tuple(run.controller.Q) == (1.0, 1.0, 1.0, 1.0, 0.4, 1.0)
    imp = run.controller.impedance
    m, inertia = robot.mass, np.trace(centroidal_inertia_by_bodies(robot)) / 3
    np.testing.assert_allclose(imp.K_x, m * (2 * math.pi * 2.0) ** 2, rtol=1e-9)
    np.testing.assert_allclose(imp.D_x, 2 * 0.7 * m * 2 * math.pi * 2.0, rtol=1e-9)
    np.testing.assert_allclose(imp.K_theta, inertia * (2 * math.pi * 3.0) ** 2, rtol=1e-9)
    default = run_gait(robot, "passive", "stand", duration=0.02, gains=wbc_gains({}))
    np.testing.assert_allclose(default.controller.impedance.K_x,
                               TrunkImpedance.for_robot(robot).K_x, rtol=1e-12)
    assert 0.0 < default.controller.Q[4] < 1.0  # go1 stands narrower than HyQ


def test_stance_and_posture_gains_reach_both_controllers(quadrupeds):
    """``--set stance_stiffness=150 --set stance_damping=12 --set posture_frequency=2
    --set posture_damping_ratio=0.5 --set baseline_swing_stiffness=700
    --set baseline_swing_damping=9``: the passive WBC that run_gait builds has K_st = 150, D_st = 12
    and the posture regulariser's K = (2 pi 2)^2, D = 2 * 0.5 * 2 pi 2; the quasi-static baseline
    the same posture PD and a 700 N/m, 9 N s/m swing PD. Without them: the controllers' own
    defaults (the posture Froude-scaled from HyQ's 8 rad/s)."""
    from wholebody.control.passive import POSTURE_FREQUENCY
    from wholebody.control.quasi_static import swing_gains
    from wholebody.robots.reference import froude_ratio
    from wholebody.scenarios.locomotion import run_gait, wbc_gains
    robot = quadrupeds["go1"]
    params = {"stance_stiffness": 150.0, "stance_damping": 12.0, "posture_frequency": 2.0,
              "posture_damping_ratio": 0.5, "baseline_swing_stiffness": 700.0,
              "baseline_swing_damping": 9.0}
    omega = 2 * math.pi * 2.0
    for controller in ("passive", "quasi-static"):
        ctrl = run_gait(robot, controller, "stand", duration=0.02,
                        gains=wbc_gains(params)).controller
        np.testing.assert_allclose((ctrl.posture_K, ctrl.posture_D),
                                   (omega ** 2, 2 * 0.5 * omega), rtol=1e-12)
        default = run_gait(robot, controller, "stand", duration=0.02,
                           gains=wbc_gains({})).controller
        omega0 = POSTURE_FREQUENCY / froude_ratio(robot)
        np.testing.assert_allclose((default.posture_K, default.posture_D),
                                   (omega0 ** 2, 2 * omega0), rtol=1e-12)
        if controller == "passive":
            assert (ctrl.K_st, ctrl.D_st) == (150.0, 12.0)
            assert (default.K_st, default.D_st) == (PassiveConfig.K_st, PassiveConfig.D_st)
        else:
            assert (ctrl.swing_K, ctrl.swing_D) == (700.0, 9.0)
            assert (default.swing_K, default.swing_D) == swing_gains(robot)
    # options a scenario passes itself win over the parameters (friction-mismatch's runs
    # without a stance task)
    run = run_gait(robot, "passive", "stand", duration=0.02, gains=wbc_gains(params),
                   controller_options={"K_st": 0.0, "D_st": 0.0})
    assert (run.controller.K_st, run.controller.D_st) == (0.0, 0.0)


def test_friction_mismatch_needs_a_stance_task(quadrupeds):
    """The stance-task runs of ``friction-mismatch`` need K_st > 0: ``--set stance_stiffness=0``
    is refused naming the parameter."""
    scenario = get_scenario("friction-mismatch")
    with pytest.raises(ValueError, match="--set stance_stiffness"):
        scenario.validate(quadrupeds["hyq"], {"stance_stiffness": "0"})


def test_sway_gain_reaches_the_crawl_planner(quadrupeds):
    """``crawl``/``friction-mismatch --set sway_gain=g``: the planner's crawl sway targets (the CoM
    offsets toward each support triangle's centroid) are g times the full sway's, lateral only."""
    from wholebody.scenarios.locomotion import run_gait, sway_options
    robot = quadrupeds["hyq"]
    for name in ("crawl", "friction-mismatch"):
        params = {p.name: p for p in get_scenario(name).parameters}
        assert params["sway_gain"].default == 1.0
    full = run_gait(robot, "passive", "crawl", duration=0.02).controller.planner.trunk.sway
    half = run_gait(robot, "passive", "crawl", duration=0.02,
                    planner_options=sway_options({"sway_gain": 0.5})).controller.planner.trunk.sway
    np.testing.assert_allclose(half.targets, 0.5 * full.targets, atol=1e-12)
    assert np.all(full.targets[:, 0] == 0.0) and np.abs(full.targets[:, 1]).min() > 0.01
