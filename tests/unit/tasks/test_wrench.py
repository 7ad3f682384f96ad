"""The trunk wrench task of Fahmi et al. 2019 (eqs. 2, 4): its rows map the point-foot forces to
the wrench about the CoM, Σ [f_i; (p_i − c) × f_i], with p_i the sphere bottoms and c the CoM
from an independent kinematics pass, which is the Newton-Euler law ḣ_G = W + m g of the whole
robot; the impedance wrench is gravity compensation plus the impedance of the errors measured
independently, plus the feed-forward with the locked inertia summed body by body."""

import numpy as np
import pinocchio as pin
import pytest

from wholebody.planning.trunk import TrunkState
from wholebody.tasks.wrench import GRAVITY, TrunkImpedance, TrunkWrenchTask
from wholebody.variables import Variables

from . import _fd


def _at(robot, seed):
    q, v = _fd.state_near_reference(robot, seed)
    robot.update(q, v)
    return q, v


def _contact_points(robot, q):
    return {n: _fd.BodyPoint.contact(robot, n, q).pose(q)[0] for n in robot.contact_names}


@pytest.mark.parametrize("seed", (0, 1))
def test_rows_map_forces_to_the_wrench_about_the_com(robots, seed):
    robot = robots["hyq"]
    q, _ = _at(robot, seed)
    for names in (robot.contact_names, robot.contact_names[:3]):
        variables = Variables(robot, names)
        rows = TrunkWrenchTask().rows(robot, variables)
        assert rows.qdd is None and rows.tau is None and rows.m == 6
        forces = np.random.default_rng(seed).normal(scale=100.0, size=(len(names), 3))
        lam = forces.reshape(-1)
        c, points = _fd.com_fd(robot)(q), _contact_points(robot, q)
        expected = sum(np.r_[f, np.cross(points[n] - c, f)] for n, f in zip(names, forces))
        np.testing.assert_allclose(rows.lam @ lam, expected, rtol=1e-9, atol=1e-9)


def test_rows_are_the_newton_euler_law(robots):
    """For a motion consistent with the dynamics (q̈ from ABA), A λ + m g = ḣ_G."""
    robot = robots["hyq"]
    q, v = _at(robot, 2)
    J = _fd.contact_jacobians_fd(robot, q, robot.contact_names)
    rng = np.random.default_rng(2)
    lam, tau = rng.normal(scale=100.0, size=12), rng.normal(scale=10.0, size=robot.na)
    qdd = _fd.forward_dynamics(robot, q, v, tau, J, lam)
    hdot = pin.computeCentroidalMomentumTimeVariation(robot.model, robot.model.createData(),
                                                      q, v, qdd).vector
    rows = TrunkWrenchTask().rows(robot, Variables(robot))
    gravity = np.r_[0.0, 0.0, -robot.mass * GRAVITY, 0.0, 0.0, 0.0]
    np.testing.assert_allclose(rows.lam @ lam + gravity, hdot, rtol=1e-6, atol=1e-5)


def test_rectangle_contacts_are_rejected(robots):
    robot = robots["talos14"]
    with pytest.raises(ValueError, match="point contacts"):
        TrunkWrenchTask().rows(robot, Variables(robot))


def _trunk_measurements(robot, q, v):
    """CoM, CoM velocity, base rotation and world angular velocity, from finite differences."""
    com = _fd.com_fd(robot)
    vcom = (com(_fd.moved(robot, q, v, _fd.EPS)) - com(_fd.moved(robot, q, v, -_fd.EPS))) / (2 * _fd.EPS)
    base = _fd.BodyPoint(robot, robot.model.getFrameId(robot.model.frames[1].name))
    assert robot.model.frames[1].parentJoint == 1  # the free flyer's body frame
    _, R = base.pose(q)
    omega = _fd.twist_fd(robot, base.pose, q, v)[3:]
    return com(q), vcom, R, omega


def _locked_inertia(robot, q):
    """Rotational inertia of the whole robot about its CoM, world axes: the sum of every body's
    spatial inertia moved to the world."""
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    total = pin.Inertia.Zero()
    for i in range(1, robot.model.njoints):
        total += data.oMi[i].act(robot.model.inertias[i])
    return total.inertia


def test_impedance_at_the_reference_is_gravity_compensation(robots):
    robot = robots["hyq"]
    q, v = _at(robot, 3)
    com, vcom, R, omega = _trunk_measurements(robot, q, v)
    ref = TrunkState(position=com, velocity=vcom, rotation=R, angular_velocity=omega)
    wrench = TrunkImpedance().wrench(robot, ref)
    np.testing.assert_allclose(wrench, [0, 0, robot.mass * GRAVITY, 0, 0, 0], atol=1e-4)
    task = TrunkWrenchTask()
    task.reference = ref
    np.testing.assert_allclose(task.rows(robot, Variables(robot)).target, wrench, atol=1e-12)


def test_impedance_is_eq_4(robots):
    """W = K Δx + D Δv + m g ẑ + [m a_d; I_G α_d] − W_ext for errors of position dx, rotation
    theta about axis w (R_d = exp(theta w) R), velocity and angular velocity."""
    robot = robots["hyq"]
    q, v = _at(robot, 4)
    com, vcom, R, omega = _trunk_measurements(robot, q, v)
    dx, dv = np.array([0.01, -0.02, 0.015]), np.array([0.1, 0.05, -0.1])
    axis, theta, dw = np.array([2.0, -1.0, 2.0]) / 3.0, 0.05, np.array([0.2, -0.1, 0.3])
    a_d, alpha_d = np.array([0.5, -0.2, 0.3]), np.array([1.0, 2.0, -1.0])
    ref = TrunkState(position=com + dx, velocity=vcom + dv, acceleration=a_d,
                     rotation=pin.exp3(theta * axis) @ R, angular_velocity=omega + dw,
                     angular_acceleration=alpha_d)
    K_x, D_x, K_t, D_t = np.array([2000.0, 1500, 1000]), 400.0, 800.0, np.array([200.0, 150, 100])
    impedance = TrunkImpedance(K_x, D_x, K_t, D_t)
    external = np.array([5.0, -3.0, 10.0, 1.0, 2.0, -1.0])
    impedance.external_wrench = external
    expected = np.r_[K_x * dx + D_x * dv + robot.mass * (a_d + [0, 0, GRAVITY]),
                     K_t * theta * axis + D_t * dw + _locked_inertia(robot, q) @ alpha_d] - external
    np.testing.assert_allclose(impedance.wrench(robot, ref), expected, rtol=1e-6, atol=1e-3)
    impedance.feedforward = False
    no_ff = expected - np.r_[robot.mass * a_d, _locked_inertia(robot, q) @ alpha_d]
    np.testing.assert_allclose(impedance.wrench(robot, ref), no_ff, rtol=1e-6, atol=1e-3)


def test_the_checks_detect_a_wrong_wrench_map(robots):
    """The wrench check rejects moments taken about the base origin instead of the CoM, or at
    the foot frames (sphere centres) instead of the sphere bottoms."""
    robot = robots["hyq"]
    q, _ = _at(robot, 0)
    rows = TrunkWrenchTask().rows(robot, Variables(robot))
    forces = np.random.default_rng(0).normal(scale=100.0, size=(4, 3))
    c, points = _fd.com_fd(robot)(q), _contact_points(robot, q)
    expected = sum(np.r_[f, np.cross(points[n] - c, f)] for n, f in zip(robot.contact_names, forces))
    about_base = sum(np.r_[f, np.cross(points[n] - q[:3], f)]
                     for n, f in zip(robot.contact_names, forces))
    at_centres = sum(np.r_[f, np.cross(points[n] + [0, 0, robot.contact(n).spec.radius] - c, f)]
                     for n, f in zip(robot.contact_names, forces))
    for wrong in (about_base, at_centres):
        with pytest.raises(AssertionError):
            np.testing.assert_allclose(wrong, expected, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(rows.lam @ forces.reshape(-1), expected, rtol=1e-9, atol=1e-9)


def _feet_about_their_centroid(robot):
    """(n, 2) horizontal sphere-centre positions of the feet about their centroid at the
    reference posture, by forward kinematics on a Data of this test's own (base yaw 0)."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    feet = np.array([data.oMf[c.frame_id].translation[:2] for c in robot.contacts])
    R = pin.Quaternion(robot.q_ref[3:7]).normalized().toRotationMatrix()
    feet = feet @ R[:2, :2]  # into the base's axes (identity at a level posture)
    return feet - feet.mean(axis=0)


def test_trunk_weights_are_ones_on_hyq_and_scale_pitch_by_the_stance_aspect(robots):
    """Q of eq. 7a: exactly 1 on HyQ (the paper's results stay); on a narrower stance only the
    pitch weight changes, by tan ψ / tan ψ_HyQ, tan ψ the feet's mean lateral over mean fore-aft
    distance from their centroid (measured here by forward kinematics)."""
    import wholebody as wb
    from conftest import anymal_b_description
    from wholebody.tasks.wrench import stance_aspect, trunk_weights

    assert trunk_weights(robots["hyq"]) == (1.0,) * 6
    hyq = np.abs(_feet_about_their_centroid(robots["hyq"])).mean(axis=0)
    for robot in (wb.load_robot(anymal_b_description()), wb.load_robot("go1")):
        feet = np.abs(_feet_about_their_centroid(robot)).mean(axis=0)
        aspect = feet[1] / feet[0]
        assert stance_aspect(robot) == pytest.approx(aspect, rel=1e-9)
        Q = trunk_weights(robot)
        assert Q[:4] == (1.0,) * 4 and Q[5] == 1.0
        assert Q[4] == pytest.approx(aspect / (hyq[1] / hyq[0]), rel=1e-9)
        assert 0.5 < Q[4] < 0.9  # both stand narrower than HyQ


def test_heading_weights_weigh_the_error_in_the_heading_frame(rng):
    """eᵀ W e equals the diagonal weights applied to the force and moment errors expressed in the
    heading frame (rotated by −yaw, with Pinocchio's rotation), whatever the trunk's pitch and
    roll; horizontally isotropic weights give diag(Q) exactly."""
    from wholebody.tasks.wrench import heading_weights

    Q = np.array([1.0, 0.5, 2.0, 1.0, 0.63, 1.5])
    for _ in range(5):
        yaw, pitch, roll = (rng.uniform(-np.pi, np.pi), rng.uniform(-0.5, 0.5),
                            rng.uniform(-0.5, 0.5))
        R = pin.rpy.rpyToMatrix(roll, pitch, yaw)
        e = rng.normal(size=6)
        Rz = pin.rpy.rpyToMatrix(0.0, 0.0, yaw)
        heading = np.concatenate([Rz.T @ e[:3], Rz.T @ e[3:]])
        W = heading_weights(Q, R)
        assert e @ W @ e == pytest.approx(heading @ (Q * heading), rel=1e-12)
        np.testing.assert_allclose(W, W.T, atol=1e-15)
    iso = np.array([1.0, 1.0, 3.0, 0.7, 0.7, 2.0])
    np.testing.assert_array_equal(heading_weights(iso, pin.rpy.rpyToMatrix(0.1, 0.2, 1.0)),
                                  np.diag(iso))
