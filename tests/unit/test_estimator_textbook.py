"""One step of the kinematic-inertial EKF against a dense textbook step of the same model written
here (Bloesch et al. 2013: IMU prediction eqs. 5-11, leg-kinematics update eq. 12, world-axes
orientation error): full transition and measurement matrices, K = P H^T S^-1, the Joseph-form
covariance, Pinocchio's per-frame placements and velocities for the legs. Random states,
covariances and readings; the filter's structured products (either engine) must agree to 1e-9."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.estimation import EstimatorNoise, KinematicInertialEKF
from wholebody.robot import GRAVITY
from wholebody.sim.sensors import Sensors, SensorSpec

from conftest import native_cycle_or_skip


def skew(x):
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def points(robot):
    """The feet's points as the filter defines them: (contact index, frame, point in the frame):
    a point foot's frame origin; a sole's heel and toe, its centre -/+ its half length along x."""
    out = []
    for i, c in enumerate(robot.contacts):
        if c.dim == 3:
            out.append((i, c.frame_id, np.zeros(3)))
        else:
            for sign in (-1.0, 1.0):
                out.append((i, c.frame_id, np.array(c.spec.offset)
                            + sign * np.array([c.spec.half_size[0], 0.0, 0.0])))
    return out


def legs(robot, joint_positions, joint_velocities, omega):
    """Each point's position and its body's angular velocity in the IMU (= base) frame, one
    Pinocchio frame query per point, the base at the identity turning at ``omega``."""
    model = robot.model
    data = model.createData()
    q = robot.with_joint_angles(pin.neutral(model), joint_positions)
    v = np.concatenate([np.zeros(3), omega, joint_velocities])
    pin.forwardKinematics(model, data, q, v)
    positions, rates = [], []
    for _, frame, point in points(robot):
        positions.append(pin.updateFramePlacement(model, data, frame).act(point))
        rates.append(pin.getFrameVelocity(model, data, frame, pin.LOCAL_WORLD_ALIGNED).angular)
    return np.array(positions), np.array(rates)


def textbook_step(robot, noise, x, P, reading, dt):
    """The dense EKF step; ``x`` = dict(r, v, R, feet, ba, bg). Returns (x, P, innovation in the
    IMU frame, per-foot normalised innovations)."""
    feet_points = points(robot)
    n = len(feet_points)
    N = 15 + 3 * n
    ba, bg = slice(9 + 3 * n, 12 + 3 * n), slice(12 + 3 * n, 15 + 3 * n)
    radii = np.array([robot.contacts[i].spec.radius if robot.contacts[i].dim == 3 else 0.0
                      for i, _, _ in feet_points])
    contact = np.array([reading.contact[i] for i, _, _ in feet_points], bool)
    omega = reading.gyro - x["bg"]
    s, w = legs(robot, reading.joint_positions, reading.joint_velocities, omega)
    R = x["R"]
    f = R @ (reading.accel - x["ba"])
    a = f + np.array([0.0, 0.0, -GRAVITY])
    r = x["r"] + dt * x["v"] + 0.5 * dt ** 2 * a
    v = x["v"] + dt * a
    feet = x["feet"].copy()
    for i in range(n):  # a ball foot in contact rolls: p_i += dt rho_i (R w_i) x e_z
        feet[i] += dt * contact[i] * radii[i] * np.cross(R @ w[i], [0.0, 0.0, 1.0])
    R_pred = R @ pin.exp3(omega * dt)
    F = np.eye(N)
    F[0:3, 3:6] = dt * np.eye(3)
    F[3:6, 6:9] = -dt * skew(f)
    F[3:6, ba] = -dt * R
    F[6:9, bg] = -dt * R
    q = np.zeros(N)
    q[0:3] = (0.5 * dt ** 2 * noise.accel_noise) ** 2
    q[3:6] = (dt * noise.accel_noise) ** 2
    q[6:9] = (dt * noise.gyro_noise) ** 2
    for i in range(n):
        walk = noise.stance_foot_walk if contact[i] else noise.swing_foot_walk
        q[9 + 3 * i:12 + 3 * i] = walk ** 2 * dt
    q[ba] = noise.accel_bias_walk ** 2 * dt
    q[bg] = noise.gyro_bias_walk ** 2 * dt
    Q = np.diag(q)
    for i in range(n):  # a sole's points in stance move as one along the ground: their
        for j in range(n):  # horizontal walks are the same, their vertical ones independent
            if i != j and contact[i] and feet_points[i][0] == feet_points[j][0]:
                block = slice(9 + 3 * i, 12 + 3 * i), slice(9 + 3 * j, 12 + 3 * j)
                Q[block] = noise.stance_foot_walk ** 2 * dt * np.diag([1.0, 1.0, 0.0])
    P = F @ P @ F.T + Q
    H = np.zeros((3 * n, N))
    y = np.zeros(3 * n)
    for i in range(n):
        rows = slice(3 * i, 3 * i + 3)
        H[rows, 0:3] = -R_pred.T
        H[rows, 6:9] = R_pred.T @ skew(feet[i] - r)
        H[rows, 9 + 3 * i:12 + 3 * i] = R_pred.T
        y[rows] = s[i] - R_pred.T @ (feet[i] - r)
    V = noise.kinematics_noise ** 2 * np.eye(3 * n)
    S = H @ P @ H.T + V
    K = P @ H.T @ np.linalg.inv(S)
    dx = K @ y
    A = np.eye(N) - K @ H
    P = A @ P @ A.T + K @ V @ K.T
    tests = np.array([y[3 * i:3 * i + 3] @ np.linalg.inv(S[3 * i:3 * i + 3, 3 * i:3 * i + 3])
                      @ y[3 * i:3 * i + 3] for i in range(n)])
    out = dict(r=r + dx[0:3], v=v + dx[3:6], R=pin.exp3(dx[6:9]) @ R_pred,
               feet=feet + dx[9:9 + 3 * n].reshape(n, 3), ba=x["ba"] + dx[ba],
               bg=x["bg"] + dx[bg])
    return out, P, y.reshape(n, 3), tests


@pytest.mark.parametrize("engine", ["python", "native"])
@pytest.mark.parametrize("name", ["hyq", "talos14"])  # ball feet that roll; soles, two points each
def test_one_step_matches_the_dense_textbook_step(name, engine):
    if engine == "native":
        native_cycle_or_skip("_estimator")
    robot = wb.load_robot(name)
    spec = SensorSpec()
    noise = EstimatorNoise.for_sensors(spec)
    n, N = len(robot.contact_names), 15 + 3 * len(points(robot))
    rng = np.random.default_rng(7)
    first = Sensors(robot, spec).measure(0.0, robot.q_ref, np.zeros(robot.nv),
                                         np.zeros(robot.nv), np.zeros(n))
    for trial in range(10):
        dt = rng.uniform(5e-4, 4e-3)
        reading = Sensors(robot, spec).measure(dt, robot.q_ref, np.zeros(robot.nv),
                                               np.zeros(robot.nv), np.zeros(n))
        reading.gyro = rng.normal(scale=1.0, size=3)
        reading.accel = np.array([0.0, 0.0, GRAVITY]) + rng.normal(scale=2.0, size=3)
        reading.joint_positions = (robot.joint_angles(robot.q_ref)
                                   + rng.normal(scale=0.1, size=robot.na))
        reading.joint_velocities = rng.normal(scale=1.0, size=robot.na)
        reading.contact = rng.random(n) < 0.6
        R = pin.exp3(rng.normal(scale=0.5, size=3))
        r = rng.normal(scale=0.5, size=3)
        x = dict(r=r, v=rng.normal(scale=0.5, size=3), R=R, ba=rng.normal(scale=0.02, size=3),
                 bg=rng.normal(scale=0.002, size=3))
        s, _ = legs(robot, reading.joint_positions, reading.joint_velocities, np.zeros(3))
        x["feet"] = r + s @ R.T + rng.normal(scale=0.01, size=s.shape)
        stds = np.exp(rng.uniform(np.log(1e-3), np.log(1e-1), size=N))
        C = rng.normal(size=(N, N))
        C = C @ C.T / N + np.eye(N)
        P = stds[:, None] * C * stds[None, :]

        ekf = KinematicInertialEKF(robot, noise, engine=engine)
        ekf.reset(first)
        ekf.position, ekf.velocity, ekf.rotation = x["r"].copy(), x["v"].copy(), R.copy()
        ekf.feet, ekf.P = x["feet"].copy(), P.copy()
        ekf.accel_bias, ekf.gyro_bias = x["ba"].copy(), x["bg"].copy()
        estimate = ekf.update(reading)

        expected, P_expected, innovation, tests = textbook_step(robot, noise, x, P, reading, dt)
        for key, actual in (("r", ekf.position), ("v", ekf.velocity), ("R", ekf.rotation),
                            ("feet", ekf.feet), ("ba", ekf.accel_bias), ("bg", ekf.gyro_bias)):
            np.testing.assert_allclose(actual, expected[key], rtol=1e-9, atol=1e-9,
                                       err_msg=f"{name} trial {trial}: {key}")
        scale = np.abs(P_expected).max()
        np.testing.assert_allclose(estimate.covariance, P_expected, rtol=1e-9,
                                   atol=1e-9 * scale, err_msg=f"{name} trial {trial}: P")
        np.testing.assert_allclose(estimate.innovation, innovation, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(estimate.foot_test, tests, rtol=1e-9, atol=1e-9)
