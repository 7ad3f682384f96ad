"""Tests of wholebody.control.lqr (Herzog et al. 2016, Sect. 3.2, eqs. 21, 23, 24, 26).

Every check compares against an independent computation written here: the nonlinear centroidal
model (eq. 21) with np.cross, finite differences, the Riccati residual, a simulation of the
nonlinear closed loop, and the momentum map built from the contact placements.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import wholebody as wb
from wholebody.control.lqr import ContactGains, MomentumLQR, blend_gains, contact_cost, lqr_gains
from wholebody.control.momentum_model import momentum_model
from wholebody.tasks.momentum import MomentumForce
from wholebody.variables import Variables

G0 = 9.81
TALOS_DS = ("left_sole", "right_sole")
TALOS_SS = ("left_sole",)
HYQ_FEET = ("lf_foot", "rf_foot", "lh_foot", "rh_foot")


# ------------------------------------------------------------------ independent reference model
def centroidal_rhs(s, lam, positions, dims, mass, g=G0):
    """s' = f(s, lambda) of eq. 21, written with np.cross (independent of the module)."""
    x, h_lin = s[:3], s[3:6]
    force = np.array([0.0, 0.0, -mass * g])
    torque = np.zeros(3)
    start = 0
    for p, d in zip(positions, dims):
        f = lam[start:start + 3]
        force = force + f
        torque = torque + np.cross(p - x, f)
        if d == 6:
            torque = torque + lam[start + 3:start + 6]
        start += d
    return np.concatenate([h_lin / mass, force, torque])


def fd_jacobian(fun, x0, eps=1e-6):
    cols = []
    for i in range(len(x0)):
        e = np.zeros(len(x0))
        e[i] = eps
        cols.append((fun(x0 + e) - fun(x0 - e)) / (2 * eps))
    return np.array(cols).T


def contact_setup(robot, names):
    robot.update(robot.q_ref, np.zeros(robot.nv))
    pos = np.array([robot.data.oMf[robot.contact(n).frame_id].translation for n in names])
    dims = [robot.contact(n).dim for n in names]
    return pos, dims


def vertical_force(lam, dims):
    starts = np.cumsum([0] + list(dims[:-1]))
    return float(sum(lam[s + 2] for s in starts))


@pytest.fixture(scope="module")
def talos():
    r = wb.load_robot("talos14")
    r.update(r.q_ref, np.zeros(r.nv))
    return r


@pytest.fixture(scope="module")
def hyq():
    r = wb.load_robot("hyq")
    r.update(r.q_ref, np.zeros(r.nv))
    return r


CONFIGS = [("talos", TALOS_DS), ("talos", TALOS_SS), ("hyq", HYQ_FEET)]


def get_robot(request, which):
    return request.getfixturevalue(which)


# ------------------------------------------------------------------------------ linearisation
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), dims=st.lists(st.sampled_from([3, 6]), min_size=1,
                                                      max_size=4))
def test_linearisation_matches_finite_differences(seed, dims):
    rng = np.random.default_rng(seed)
    n = sum(dims)
    pos = rng.normal(scale=0.5, size=(len(dims), 3))
    com = rng.normal(scale=0.5, size=3)
    mass = rng.uniform(5.0, 100.0)
    lam0 = rng.normal(scale=50.0, size=n)  # arbitrary, not balancing: exercises the general F0
    h0 = rng.normal(size=6)
    A, B, c = momentum_model(pos, com, mass, nominal_forces=lam0, dims=dims)
    s0 = np.concatenate([com, h0])

    A_fd = fd_jacobian(lambda s: centroidal_rhs(s, lam0, pos, dims, mass), s0)
    B_fd = fd_jacobian(lambda u: centroidal_rhs(s0, u, pos, dims, mass), lam0)
    np.testing.assert_allclose(A, A_fd, atol=1e-6)
    np.testing.assert_allclose(B, B_fd, atol=1e-6)
    # the affine model is exact at the linearisation point
    np.testing.assert_allclose(A @ s0 + B @ lam0 + c, centroidal_rhs(s0, lam0, pos, dims, mass),
                               atol=1e-8)
    # and second order accurate nearby (the only nonlinearity is x_cog x f)
    ds, du = rng.normal(scale=1e-3, size=9), rng.normal(scale=1e-2, size=n)
    lin = A @ (s0 + ds) + B @ (lam0 + du) + c
    np.testing.assert_allclose(lin, centroidal_rhs(s0 + ds, lam0 + du, pos, dims, mass),
                               atol=1e-3 * 1e-2 * 10 * n)


def test_linearisation_sign_of_force_cross_term():
    """d(h_ang')/d(x_cog) = +[F0]x: CoM moved +y under a vertical load F gives h_ang_x' = -F dy."""
    pos = np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])
    m = 50.0
    A, B, c = momentum_model(pos, [0.0, 0.0, 1.0], m, dims=[6, 6])
    F = m * G0
    np.testing.assert_allclose(A[6:9, 0:3], [[0, -F, 0], [F, 0, 0], [0, 0, 0]], atol=1e-9)
    np.testing.assert_allclose(A[0:3, 3:6], np.eye(3) / m)


@pytest.mark.parametrize("which,names", CONFIGS)
def test_default_nominal_forces_balance_gravity(request, which, names):
    robot = get_robot(request, which)
    pos, dims = contact_setup(robot, names)
    model = momentum_model(pos, robot.com, robot.mass, dims=dims)
    s0 = np.concatenate([robot.com, np.zeros(6)])
    np.testing.assert_allclose(centroidal_rhs(s0, model.lambda0, pos, dims, robot.mass),
                               np.zeros(9), atol=1e-8)
    # robot-based model: same A as the finite differences
    ctl = MomentumLQR(robot, names)
    m2 = ctl.model(robot)
    A_fd = fd_jacobian(lambda s: centroidal_rhs(s, m2.lambda0, pos, dims, robot.mass), s0)
    np.testing.assert_allclose(m2.A, A_fd, atol=1e-6)
    np.testing.assert_allclose(vertical_force(m2.lambda0, dims), robot.mass * G0, rtol=1e-10)


# ------------------------------------------------------------------------------------ Riccati
@pytest.mark.parametrize("which,names", CONFIGS)
def test_riccati_solution_and_hurwitz(request, which, names):
    robot = get_robot(request, which)
    ctl = MomentumLQR(robot, names)
    model = ctl.model(robot)
    A, B, _ = model
    Q = np.diag([30, 30, 50, .5, .5, .5, .1, .1, .1])
    R6 = np.diag([.1, .1, .01, 2, 2, 2])
    R = np.zeros((model.n_lambda, model.n_lambda))
    start = 0
    for d in model.dims:
        R[start:start + d, start:start + d] = R6[:d, :d]
        start += d
    np.testing.assert_allclose(contact_cost(model.dims), R)

    K, P = lqr_gains(model, Q, R, full_output=True)
    residual = A.T @ P + P @ A - P @ B @ np.linalg.solve(R, B.T @ P) + Q
    assert np.abs(residual).max() < 1e-8 * max(1.0, np.abs(P).max())
    np.testing.assert_allclose(P, P.T, atol=1e-9)
    assert np.linalg.eigvalsh(P).min() > 0
    np.testing.assert_allclose(K, np.linalg.solve(R, B.T @ P), atol=1e-8)
    poles = np.linalg.eigvals(A - B @ K)
    assert poles.real.max() < -1e-3
    # the defaults are eq. 26's weights, and the class gives the same K
    np.testing.assert_allclose(lqr_gains(model), K, rtol=1e-9, atol=1e-9)
    g = ctl.gains(robot)
    np.testing.assert_allclose(g.K, K, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.sort_complex(g.poles), np.sort_complex(poles), atol=1e-9)


def test_discrete_design_approaches_continuous(talos):
    model = MomentumLQR(talos, TALOS_DS).model(talos)
    Kc = lqr_gains(model)
    Kd = lqr_gains(model, dt=1e-3)
    assert np.abs(Kd - Kc).max() < 1e-2 * np.abs(Kc).max()
    Kd2 = lqr_gains(model, dt=1e-4)
    assert np.abs(Kd2 - Kc).max() < np.abs(Kd - Kc).max()


def test_single_point_contact_is_not_stabilizable(hyq):
    with pytest.raises(ValueError, match="^model:"):
        MomentumLQR(hyq, ["lf_foot"]).gains(hyq)


# -------------------------------------------------------------------------------- closed loop
def simulate(K, k, pos, dims, mass, s_init, t_end):
    def rhs(_t, s):
        return centroidal_rhs(s, k - K @ s, pos, dims, mass)
    sol = solve_ivp(rhs, (0.0, t_end), s_init, method="LSODA", rtol=1e-9, atol=1e-11)
    assert sol.success
    return sol.y[:, -1]


@pytest.mark.parametrize("which,names", CONFIGS)
def test_closed_loop_nonlinear_converges(request, which, names):
    robot = get_robot(request, which)
    pos, dims = contact_setup(robot, names)
    ctl = MomentumLQR(robot, names)
    com_ref = robot.com.copy()
    K, k = ctl.feedback(robot, com_ref)
    s_ref = np.concatenate([com_ref, np.zeros(6)])
    # at the reference the force law balances gravity: total vertical force = m g, s' = 0
    lam_eq = k - K @ s_ref
    np.testing.assert_allclose(vertical_force(lam_eq, dims), robot.mass * G0, rtol=1e-9)
    np.testing.assert_allclose(centroidal_rhs(s_ref, lam_eq, pos, dims, robot.mass), 0, atol=1e-8)

    s_init = s_ref + np.concatenate([[0.02, -0.02, 0.02], [4.0, -3.0, 2.0], [1.0, -0.8, 0.5]])
    slowest = -np.max(np.linalg.eigvals(ctl.model(robot).A - ctl.model(robot).B @ K).real)
    s_end = simulate(K, k, pos, dims, robot.mass, s_init, t_end=8.0 / slowest)
    err = s_end - s_ref
    assert np.abs(err[:3]).max() < 2e-5  # CoM within 20 um (from 2 cm)
    assert np.abs(err[3:]).max() < 2e-3  # momentum (kick of several N s) damped
    np.testing.assert_allclose(vertical_force(k - K @ s_end, dims), robot.mass * G0, rtol=1e-5)


def test_closed_loop_tracks_offset_reference(talos):
    """rebalance=True makes an offset com_ref an exact equilibrium of the nonlinear model."""
    pos, dims = contact_setup(talos, TALOS_DS)
    ctl = MomentumLQR(talos, TALOS_DS)
    com_ref = talos.com + np.array([0.01, 0.03, -0.02])
    K, k = ctl.feedback(talos, com_ref)
    s_ref = np.concatenate([com_ref, np.zeros(6)])
    np.testing.assert_allclose(centroidal_rhs(s_ref, k - K @ s_ref, pos, dims, talos.mass), 0,
                               atol=1e-8)
    s_end = simulate(K, k, pos, dims, talos.mass, np.concatenate([talos.com, np.zeros(6)]), 80.0)
    assert np.abs(s_end[:3] - com_ref).max() < 1e-4
    # the literal k = lambda0 + K s_ref equals it when com_ref is the linearisation CoM
    K1, k1 = ctl.feedback(talos, talos.com, rebalance=False)
    K2, k2 = ctl.feedback(talos, talos.com)
    np.testing.assert_allclose(k1, k2, atol=1e-8)


# ----------------------------------------------------------------------- MomentumForce (eq. 24)
@pytest.mark.parametrize("which,names", CONFIGS)
def test_momentum_force_projection(request, which, names, rng):
    robot = get_robot(request, which)
    q, v = robot.q_ref.copy(), rng.normal(scale=0.3, size=robot.nv)
    robot.update(q, v)
    ctl = MomentumLQR(robot, names)
    K, k = ctl.feedback(robot, robot.com + [0.01, 0.0, 0.0], h_ref=rng.normal(size=6))
    n_lam = sum(robot.contact(n).dim for n in names)
    assert K.shape == (n_lam, 9) and k.shape == (n_lam,)
    variables = Variables(robot, names)
    rows = MomentumForce(K, k).rows(robot, variables)
    s = np.concatenate([robot.com, robot.h_G])
    lam = -K @ s + k  # eq. 23
    # independent G of eq. 21 from the contact placements
    blocks = []
    for n in names:
        c = robot.contact(n)
        r = robot.data.oMf[c.frame_id].translation - robot.com
        if c.dim == 3:  # point feet push at the bottom of the foot sphere
            r = r - np.array([0.0, 0.0, c.spec.radius])
        b = np.zeros((6, c.dim))
        b[:3, :3] = np.eye(3)
        for j in range(3):
            b[3:, j] = np.cross(r, np.eye(3)[j])
        if c.dim == 6:
            b[3:, 3:] = np.eye(3)
        blocks.append(b)
    G = np.hstack(blocks)
    np.testing.assert_allclose(rows.target, G @ lam, atol=1e-8)
    np.testing.assert_allclose(rows.lam @ lam, rows.target, atol=1e-8)
    robot.update(robot.q_ref, np.zeros(robot.nv))


# ---------------------------------------------------------------------- configurations, blend
def test_gains_per_configuration_and_blend(talos):
    talos.update(talos.q_ref, np.zeros(talos.nv))
    ctl = MomentumLQR(talos, TALOS_DS)
    ds = ctl.gains(talos)
    ss = ctl.gains(talos, TALOS_SS)
    assert ctl.gains(talos, TALOS_DS) is ds  # cached per configuration
    assert ctl.gains(talos, TALOS_DS, recompute=True) is not ds
    assert ds.K.shape == (12, 9) and ss.K.shape == (6, 9)
    assert not np.allclose(ds.K[:6], ss.K, rtol=0.05)  # different gains per configuration
    assert not np.allclose(ds.lambda0[:6], ss.lambda0)

    b0 = blend_gains(ds, ss, 0.0)
    b1 = MomentumLQR.blend(ds, ss, 1.0)
    assert b0.contacts == TALOS_DS == b1.contacts
    np.testing.assert_array_equal(b0.K, ds.K)
    np.testing.assert_array_equal(b0.lambda0, ds.lambda0)
    np.testing.assert_array_equal(b1.K[:6], ss.K)
    np.testing.assert_array_equal(b1.K[6:], 0.0)  # the leaving contact's rows vanish
    np.testing.assert_array_equal(b1.lambda0[6:], 0.0)
    bh = blend_gains(ds, ss, 0.5)
    np.testing.assert_allclose(bh.K[:6], 0.5 * (ds.K[:6] + ss.K))
    np.testing.assert_allclose(bh.K[6:], 0.5 * ds.K[6:])
    # landing: single -> double, the arriving contact starts at zero
    land = blend_gains(ss, ds, 0.0)
    assert land.contacts == TALOS_DS
    np.testing.assert_array_equal(land.K[6:], 0.0)
    np.testing.assert_array_equal(blend_gains(ss, ds, 1.0).K, ds.K)
    # explicit order
    rev = blend_gains(ds, ss, 0.3, contacts=("right_sole", "left_sole"))
    np.testing.assert_allclose(rev.K[:6], blend_gains(ds, ss, 0.3).K[6:])

    # blended feedback: the feedforward keeps gravity balanced at every alpha, and the leaving
    # contact carries no force at alpha = 1
    for alpha in (0.0, 0.4, 1.0):
        g = blend_gains(ds, ss, alpha)
        K, k = ctl.feedback(talos, talos.com, gains=g)
        lam = k - K @ np.concatenate([talos.com, np.zeros(6)])
        np.testing.assert_allclose(vertical_force(lam, g.dims), talos.mass * G0, rtol=1e-9)
        if alpha == 1.0:
            np.testing.assert_array_equal(lam[6:], 0.0)
        rows = MomentumForce(K, k, contacts=g.contacts).rows(talos, Variables(talos, TALOS_DS))
        np.testing.assert_allclose(rows.target[:3], [0, 0, talos.mass * G0], atol=1e-6)


# ------------------------------------------------------------------------------------ errors
def test_errors_name_the_argument(talos):
    pos = np.zeros((2, 3))
    cases = [
        (lambda: momentum_model(np.zeros((2, 2)), np.zeros(3), 1.0), "contact_positions"),
        (lambda: momentum_model(pos, np.zeros(2), 1.0), "com"),
        (lambda: momentum_model(pos, np.zeros(3), -1.0), "mass"),
        (lambda: momentum_model(pos, np.zeros(3), 1.0, nominal_forces=np.zeros(5)),
         "nominal_forces"),
        (lambda: momentum_model(pos, np.zeros(3), 1.0, dims=[6, 4]), "dims"),
        (lambda: momentum_model(pos, np.zeros(3), 1.0, dims=[6]), "dims"),
        (lambda: momentum_model(pos, np.zeros(3), 1.0, gravity=0.0), "gravity"),
        (lambda: MomentumLQR(talos, ["left_sole", "nose"]), "contacts"),
        (lambda: MomentumLQR(talos, "left_sole"), "contacts"),
        (lambda: MomentumLQR(talos, TALOS_DS, Q=np.eye(8)), "Q"),
        (lambda: MomentumLQR(talos, TALOS_DS, Q=-np.eye(9)), "Q"),
        (lambda: MomentumLQR(talos, TALOS_DS, R=np.zeros(6)), "R"),
        (lambda: MomentumLQR(talos, TALOS_DS).gains(talos, ["left_sole", "left_sole"]),
         "contacts"),
        (lambda: MomentumLQR(talos, TALOS_DS).feedback(talos, np.zeros(2)), "com_ref"),
        (lambda: MomentumLQR(talos, TALOS_DS).feedback(talos, np.zeros(3), np.zeros(9)),
         "h_ref"),
        (lambda: MomentumLQR(talos, TALOS_DS).feedback(talos, np.zeros(3),
                                                       hdot_ref=np.full(6, np.nan)), "hdot_ref"),
        (lambda: MomentumLQR(talos, TALOS_DS).feedback(talos, np.zeros(3),
                                                       integral=np.zeros(3)), "integral"),
        (lambda: MomentumLQR(talos, TALOS_DS, q_integral=1e4).feedback(
            talos, np.zeros(3), integral=np.zeros(2)), "integral"),
        (lambda: lqr_gains((np.eye(9), np.zeros((8, 3)))), "model"),
        (lambda: lqr_gains(momentum_model(pos + [[0, 1, 0], [0, -1, 0]], [0, 0, 1], 1.0),
                           R=np.eye(3)), "R"),
        (lambda: contact_cost([6, 6], R=np.eye(5)), "R"),
    ]
    ctl = MomentumLQR(talos, TALOS_DS)
    ds, ss = ctl.gains(talos), ctl.gains(talos, TALOS_SS)
    cases += [
        (lambda: blend_gains(ds, ss, 1.5), "alpha"),
        (lambda: blend_gains(ds, "x", 0.5), "gains_b"),
        (lambda: blend_gains(ds, ss, 0.5, contacts=["left_sole"]), "contacts"),
        (lambda: ctl.feedback(talos, talos.com, gains=ds.K), "gains"),
    ]
    for call, name in cases:
        with pytest.raises(ValueError, match=f"^{name}:"):
            call()
    assert isinstance(ds, ContactGains)


# ------------------------------------------------- integral action (LQI; our extension, not eq. 23)
Q_TALOS = np.diag([30, 30, 50, .5, .5, .5, 10, 10, 10])


@pytest.mark.parametrize("which,names", CONFIGS)
def test_integral_augmented_riccati_and_stable(request, which, names):
    """The augmented system built here (A, B of eq. 21, checked against finite differences of the
    model written in this file, plus z' = x_cog) satisfies the Riccati equation with the returned
    P and K, and its closed loop [A - B K_s, -B K_z; S, 0] is Hurwitz."""
    robot = get_robot(request, which)
    pos, dims = contact_setup(robot, names)
    ctl = MomentumLQR(robot, names, q_integral=1e5)
    model = ctl.model(robot)
    pos = model.contact_positions  # the contact points (hyq: the foot centre, not the frame)
    s0 = np.concatenate([robot.com, np.zeros(6)])
    A = fd_jacobian(lambda s: centroidal_rhs(s, model.lambda0, pos, dims, robot.mass), s0)
    B = fd_jacobian(lambda u: centroidal_rhs(s0, u, pos, dims, robot.mass), model.lambda0)
    np.testing.assert_allclose(A, model.A, atol=1e-6)
    np.testing.assert_allclose(B, model.B, atol=1e-6)
    A, B = model.A, model.B  # exact (FD round-off is amplified by P ~ 1e5 in the residual)
    Aa = np.block([[A, np.zeros((9, 3))], [np.eye(3), np.zeros((3, 9))]])
    Ba = np.vstack([B, np.zeros((3, B.shape[1]))])
    Qa = np.diag(np.r_[np.diag(DEFAULT_Q := np.diag([30, 30, 50, .5, .5, .5, .1, .1, .1])),
                       [1e5] * 3])
    R = contact_cost(model.dims)
    K, P = lqr_gains(model, DEFAULT_Q, R, q_integral=1e5, full_output=True)
    assert K.shape == (model.n_lambda, 12) and P.shape == (12, 12)
    residual = Aa.T @ P + P @ Aa - P @ Ba @ np.linalg.solve(R, Ba.T @ P) + Qa
    assert np.abs(residual).max() < 1e-6 * max(1.0, np.abs(P).max())
    np.testing.assert_allclose(K, np.linalg.solve(R, Ba.T @ P), atol=1e-6 * np.abs(K).max())
    poles = np.linalg.eigvals(Aa - Ba @ K)
    assert poles.real.max() < -1e-3
    # the class splits K into the state part and the integral part and reports the same poles
    g = ctl.gains(robot)
    np.testing.assert_allclose(np.hstack([g.K, g.K_integral]), K, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.sort_complex(g.poles), np.sort_complex(poles), atol=1e-6)
    # off by default: the paper's gains, unchanged
    g0 = MomentumLQR(robot, names).gains(robot)
    assert g0.K_integral is None
    np.testing.assert_allclose(g0.K, lqr_gains(model, DEFAULT_Q, R), rtol=1e-12, atol=1e-12)
    assert np.abs(g.K - g0.K).max() > 1e-3  # the integral changes the state feedback too


def test_integral_zero_weight_axis_is_not_augmented(talos):
    model = MomentumLQR(talos, TALOS_DS).model(talos)
    K = lqr_gains(model, Q_TALOS, q_integral=[0.0, 0.0, 1e5])
    assert np.all(K[:, 9:11] == 0.0) and np.abs(K[:, 11]).max() > 1.0
    assert lqr_gains(model, Q_TALOS, q_integral=0.0).shape == (model.n_lambda, 9)
    with pytest.raises(ValueError, match="^q_integral"):
        lqr_gains(model, Q_TALOS, q_integral=-1.0)


def simulate_biased(ctl, robot, pos, dims, true_mass, t_end, integral: bool):
    """Eq. 21 written in this file, for a robot whose true mass differs from the controller's
    model (gravity m_true g and x_cog' = h_lin / m_true): a constant unknown vertical force bias.
    The controller's force law is taken from ``ctl.feedback`` every evaluation; the integral z of
    (x_cog - x_ref) is the ODE's 10th-12th state. An axis of z that reaches the controller's clamp
    stops growing there: the integration stops at that event and goes on with the axis frozen, so
    the integrator never steps across the switch (an ODE with a discontinuous right-hand side)."""
    com_ref = robot.com.copy()
    limit = ctl.integral_limit if integral else np.inf
    frozen = np.zeros(3, dtype=bool)

    def rhs(_t, y):
        s, z = y[:9], y[9:]
        K, k = ctl.feedback(robot, com_ref, integral=z if integral else None)
        dz = np.where(frozen, 0.0, s[:3] - com_ref)
        return np.concatenate([centroidal_rhs(s, k - K @ s, pos, dims, true_mass), dz])

    def reaches_clamp(axis):
        def event(_t, y):
            return 1.0 if frozen[axis] else limit - abs(y[9 + axis])
        event.terminal = True
        return event

    events = [reaches_clamp(i) for i in range(3)] if integral else None
    t0, y0, pieces = 0.0, np.concatenate([com_ref, np.zeros(9)]), []
    while True:
        sol = solve_ivp(rhs, (t0, t_end), y0, method="LSODA", rtol=1e-8, atol=1e-10,
                        dense_output=True, events=events)
        assert sol.success
        pieces.append(sol)
        if sol.status == 0:  # reached t_end
            break
        hit = [i for i in range(3) if sol.t_events[i].size]
        frozen[hit] = True
        t0, y0 = sol.t[-1], sol.y[:, -1].copy()
        y0[9:] = np.clip(y0[9:], -limit, limit)
    return _Joined(pieces), com_ref


class _Joined:
    """Several solve_ivp pieces as one solution: ``y`` of the last piece, ``sol(t)`` over all."""

    def __init__(self, pieces):
        self.pieces, self.y, self.success = pieces, pieces[-1].y, True

    def sol(self, t):
        t = np.atleast_1d(t)
        out = np.empty((self.y.shape[0], t.size))
        for piece in self.pieces:
            inside = (t >= piece.t[0]) & (t <= piece.t[-1])
            out[:, inside] = piece.sol(t[inside])
        return out


def test_integral_removes_cog_offset_of_a_mass_error(talos):
    """True robot 3 % heavier than the model (2.7 kg, 27 N of unknown vertical bias): the paper's
    LQR (Q of eq. 26 with q_angular=10) lets the CoG sink towards bias / stiffness (~0.27 m, pole
    0.11 rad/s: > 3 cm after 10 s); with the integral the CoG error goes to zero (< 0.1 mm after
    10 s) and the integral settles at bias / integral gain."""
    pos, dims = contact_setup(talos, TALOS_DS)
    true_mass = 1.03 * talos.mass
    bias = (true_mass - talos.mass) * G0
    plain = MomentumLQR(talos, TALOS_DS, Q=Q_TALOS)
    lqi = MomentumLQR(talos, TALOS_DS, Q=Q_TALOS, q_integral=1e6)
    sol0, com_ref = simulate_biased(plain, talos, pos, dims, true_mass, 10.0, integral=False)
    sol1, _ = simulate_biased(lqi, talos, pos, dims, true_mass, 10.0, integral=True)
    e0 = sol0.y[:3, -1] - com_ref
    e1 = sol1.y[:3, -1] - com_ref
    assert e0[2] < -0.03, e0  # sinks (heavier robot), still going
    assert np.abs(e1).max() < 1e-4, e1
    assert np.abs(sol1.sol(np.linspace(0.0, 10.0, 201))[2] - com_ref[2]).max() < 5e-3
    # at rest the integral's forces carry the bias: the model's weight plus the bias, m_true g
    K, k = lqi.feedback(talos, com_ref, integral=sol1.y[9:, -1])
    np.testing.assert_allclose(vertical_force(k - K @ sol1.y[:9, -1], dims),
                               talos.mass * G0 + bias, rtol=1e-5)


def test_integral_clamp_limits_the_correction(talos):
    """Anti-windup: with the clamp below what the bias needs, the integral stops at the limit and a
    residual offset remains (the clamp is effective); with the default limit it does not."""
    pos, dims = contact_setup(talos, TALOS_DS)
    true_mass = 1.03 * talos.mass
    small = MomentumLQR(talos, TALOS_DS, Q=Q_TALOS, q_integral=1e6, integral_limit=5e-4)
    sol, com_ref = simulate_biased(small, talos, pos, dims, true_mass, 10.0, integral=True)
    assert sol.y[11, -1] == pytest.approx(-5e-4, abs=1e-9)
    assert sol.y[2, -1] - com_ref[2] < -1e-3
    np.testing.assert_allclose(small.clamp_integral([1.0, -1.0, 1e-4]), [5e-4, -5e-4, 1e-4])


def test_integral_gains_blend_and_feedback(talos):
    ctl = MomentumLQR(talos, TALOS_DS, q_integral=1e5)
    g_ds, g_ss = ctl.gains(talos, TALOS_DS), ctl.gains(talos, TALOS_SS)
    mid = blend_gains(g_ds, g_ss, 0.25)
    np.testing.assert_allclose(mid.K_integral[:6], 0.75 * g_ds.K_integral[:6]
                               + 0.25 * g_ss.K_integral[:6])
    np.testing.assert_allclose(mid.K_integral[6:], 0.75 * g_ds.K_integral[6:])
    z = np.array([1e-3, -2e-3, 3e-3])
    K0, k0 = ctl.feedback(talos, talos.com)
    K1, k1 = ctl.feedback(talos, talos.com, integral=z)
    np.testing.assert_allclose(K1, K0)
    np.testing.assert_allclose(k1, k0 - g_ds.K_integral @ z)
    with pytest.raises(ValueError, match="^integral"):
        MomentumLQR(talos, TALOS_DS).feedback(talos, talos.com, integral=z)


# ------------------------------------------------------------ orientation state (our extension)
def locked_inertia(robot):
    """I_G summed here from the links (parallel-axis theorem on Pinocchio's placements), not from
    ccrba: sum_i R_i I_i R_i^T + m_i ([c_i - x_cog]x)^T [c_i - x_cog]x."""
    model, data = robot.model, robot.model.createData()
    import pinocchio as pin
    pin.forwardKinematics(model, data, robot.q)
    parts, total, mass = [], np.zeros(3), 0.0
    for i in range(1, model.njoints):
        inertia, placement = model.inertias[i], data.oMi[i]
        c = placement.act(inertia.lever)
        parts.append((inertia.mass, c, placement.rotation @ inertia.inertia @ placement.rotation.T))
        total, mass = total + inertia.mass * c, mass + inertia.mass
    com = total / mass
    out = np.zeros((3, 3))
    for m_i, c, I_rot in parts:
        r = c - com
        out += I_rot + m_i * (r @ r * np.eye(3) - np.outer(r, r))
    return out


def rotation_rhs(y, K, k, pos, dims, mass, inertia):
    """[s; theta]' with s' of eq. 21 (this file's model) and theta' = I_G^-1 h_ang."""
    s, theta = y[:9], y[9:12]
    lam = k - K @ np.concatenate([s, theta])
    return np.concatenate([centroidal_rhs(s, lam, pos, dims, mass),
                           np.linalg.solve(inertia, s[6:9])])


@pytest.mark.parametrize("which,names", CONFIGS)
def test_orientation_augmented_riccati_and_stable(request, which, names):
    robot = get_robot(request, which)
    ctl = MomentumLQR(robot, names, q_orientation=100.0)
    model = ctl.model(robot)
    inertia = locked_inertia(robot)
    np.testing.assert_allclose(robot.centroidal_inertia(), inertia, rtol=1e-9, atol=1e-9)
    A, B = model.A, model.B
    Aa = np.zeros((12, 12))
    Aa[:9, :9] = A
    Aa[9:, 6:9] = np.linalg.inv(inertia)
    Ba = np.vstack([B, np.zeros((3, B.shape[1]))])
    Q = np.diag([30, 30, 50, .5, .5, .5, .1, .1, .1, 100, 100, 100])
    R = contact_cost(model.dims)
    K, P = lqr_gains(model, Q[:9, :9], R, q_orientation=100.0, inertia=inertia, full_output=True)
    assert K.shape == (model.n_lambda, 12)
    residual = Aa.T @ P + P @ Aa - P @ Ba @ np.linalg.solve(R, Ba.T @ P) + Q
    assert np.abs(residual).max() < 1e-7 * max(1.0, np.abs(P).max())
    poles = np.linalg.eigvals(Aa - Ba @ K)
    assert poles.real.max() < -1e-3
    g = ctl.gains(robot)
    np.testing.assert_allclose(np.hstack([g.K, g.K_orientation]), K, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(np.sort_complex(g.poles), np.sort_complex(poles), atol=1e-6)
    assert g.K_integral is None and MomentumLQR(robot, names).gains(robot).K_orientation is None


def test_orientation_state_returns_the_rotation(talos):
    """An angular-momentum kick (2 N m s about y, 1 about x) on eq. 21 written in this file: the
    paper's gains (q_angular=0.1) damp the momentum but leave the body turned by the rotation the
    momentum integrated to (> 0.05 rad); with the orientation state the rotation returns to zero
    (< 1 mrad after 30 s) and the CoG to its reference."""
    pos, dims = contact_setup(talos, TALOS_DS)
    inertia = locked_inertia(talos)
    com_ref = talos.com.copy()
    y0 = np.concatenate([com_ref, np.zeros(3), [1.0, 2.0, 0.0], np.zeros(3)])
    ends = {}
    for q in (None, 100.0):
        ctl = MomentumLQR(talos, TALOS_DS, q_orientation=q)
        K, k = ctl.feedback(talos, com_ref)
        g = ctl.gains(talos)
        K12 = np.hstack([K, np.zeros((K.shape[0], 3)) if g.K_orientation is None
                         else g.K_orientation])
        sol = solve_ivp(lambda _t, y: rotation_rhs(y, K12, k, pos, dims, talos.mass, inertia),
                        (0.0, 30.0), y0, method="LSODA", rtol=1e-9, atol=1e-11)
        assert sol.success
        ends[q] = sol.y[:, -1]
    assert np.abs(ends[None][6:9]).max() < 1e-3  # momentum damped either way
    assert np.linalg.norm(ends[None][9:12]) > 0.05  # ... the body stays turned
    assert np.linalg.norm(ends[100.0][9:12]) < 1e-3
    assert np.abs(ends[100.0][:3] - com_ref).max() < 1e-4


def test_orientation_feedback_folds_into_k_and_blends(talos):
    ctl = MomentumLQR(talos, TALOS_DS, q_orientation=10.0, q_integral=1e5)
    g = ctl.gains(talos)
    model = ctl.model(talos)
    K15 = lqr_gains(model, ctl.Q, contact_cost(model.dims), q_orientation=10.0,
                    inertia=locked_inertia(talos), q_integral=1e5)
    assert K15.shape == (model.n_lambda, 15)  # [K_s, K_theta, K_z]
    np.testing.assert_allclose(np.hstack([g.K, g.K_orientation, g.K_integral]), K15,
                               rtol=1e-8, atol=1e-8)
    theta, z = np.array([0.01, -0.02, 0.03]), np.array([1e-3, 0.0, -1e-3])
    s = np.concatenate([talos.com + 0.01, np.ones(6)])
    K, k = ctl.feedback(talos, talos.com, orientation=theta, integral=z)
    lam_ff = ctl.feedforward(talos, g, talos.com)
    s_ref = np.concatenate([talos.com, np.zeros(6)])
    np.testing.assert_allclose(k - K @ s, lam_ff - K15 @ np.concatenate([s - s_ref, theta, z]),
                               atol=1e-8)
    mid = blend_gains(g, ctl.gains(talos, TALOS_SS), 0.5)
    np.testing.assert_allclose(mid.K_orientation[6:], 0.5 * g.K_orientation[6:])
    with pytest.raises(ValueError, match="^orientation"):
        MomentumLQR(talos, TALOS_DS).feedback(talos, talos.com, orientation=theta)
    for bad in (-1.0, [1.0, 2.0], np.nan, "x"):
        with pytest.raises(ValueError, match="^q_orientation"):
            MomentumLQR(talos, TALOS_DS, q_orientation=bad)
    with pytest.raises(ValueError, match="^inertia"):
        lqr_gains(model, ctl.Q, contact_cost(model.dims), q_orientation=1.0)
