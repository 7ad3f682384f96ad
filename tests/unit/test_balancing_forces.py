"""The weighted least-norm contact forces of eq. 21 (``balancing_forces``) against a generic solve
of the same problem written here: the KKT system of min lambda^T W lambda s.t. G lambda = w, with
G built with np.cross; the weighted pseudo-inverse when w cannot be reached. The LQR's feedforward,
which keeps each configuration's factored weight from one cycle to the next, gives the numbers
of a fresh, fully checked call."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import wholebody as wb
from wholebody.control.lqr import ContactGains, MomentumLQR, blend_gains
from wholebody.control.momentum_model import _momentum_map, balancing_forces
from wholebody.tasks.momentum import centroidal_map

G0 = 9.81


def momentum_rows(positions, com, dims) -> np.ndarray:
    """The 6 x n map from stacked contact forces/wrenches to [total force; moment about com]:
    column by column, the momentum rate of a unit force/torque (np.cross)."""
    cols = []
    for p, d in zip(positions, dims):
        for axis in range(3):
            f = np.eye(3)[axis]
            cols.append(np.r_[f, np.cross(p - com, f)])
        for axis in range(d - 3):
            cols.append(np.r_[np.zeros(3), np.eye(3)[axis]])
    return np.array(cols).T


def kkt_solution(G, w, W) -> np.ndarray:
    """Stationarity 2 W lambda + G^T nu = 0 with G lambda = w, solved as one linear system."""
    n = G.shape[1]
    K = np.block([[2.0 * W, G.T], [G, np.zeros((6, 6))]])
    return np.linalg.solve(K, np.r_[np.zeros(n), w])[:n]


def random_weight(rng, n) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1),
       dims=st.lists(st.sampled_from([3, 6]), min_size=1, max_size=4),
       diagonal=st.booleans())
def test_balancing_forces_solve_the_weighted_least_norm_problem(seed, dims, diagonal):
    rng = np.random.default_rng(seed)
    n = sum(dims)
    X = rng.uniform(-0.4, 0.4, size=(len(dims), 3))
    X[:, 2] = rng.uniform(-0.05, 0.05, size=len(dims))
    com = np.array([*rng.uniform(-0.1, 0.1, size=2), rng.uniform(0.4, 1.0)])
    mass = rng.uniform(10.0, 100.0)
    hdot = rng.normal(scale=20.0, size=6)
    W = np.diag(rng.uniform(0.01, 3.0, size=n)) if diagonal else random_weight(rng, n)
    lam = balancing_forces(X, com, mass, dims, G0, weight=np.diag(W) if diagonal else W,
                           hdot=hdot)
    G = momentum_rows(X, com, dims)
    w = hdot - np.r_[0.0, 0.0, -mass * G0, 0.0, 0.0, 0.0]
    if np.linalg.matrix_rank(G) == 6:
        expected = kkt_solution(G, w, W)
        np.testing.assert_allclose(G @ lam, w, atol=1e-8 * max(1.0, np.abs(w).max()))
    else:  # w out of reach: the least-squares wrench, least weighted norm among those
        S = np.linalg.cholesky(W)
        expected = np.linalg.solve(S.T, np.linalg.pinv(G @ np.linalg.inv(S.T)) @ w)
    np.testing.assert_allclose(lam, expected, rtol=1e-8, atol=1e-8 * max(1.0, np.abs(w).max()))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1),
       dims=st.lists(st.sampled_from([3, 6]), min_size=1, max_size=5))
def test_the_loops_momentum_map_is_the_tasks(seed, dims):
    """The feedforward's own G is tasks.momentum.centroidal_map to the bit (and eq. 21's map)."""
    rng = np.random.default_rng(seed)
    X, com = rng.normal(size=(len(dims), 3)), rng.normal(size=3)
    G = _momentum_map(X, com, tuple(dims))
    np.testing.assert_array_equal(G, centroidal_map(X, com, dims))
    np.testing.assert_allclose(G, momentum_rows(X, com, dims), atol=1e-15)


@pytest.fixture(scope="module")
def talos():
    r = wb.load_robot("talos14")
    r.update(r.q_ref, np.zeros(r.nv))
    return r


def test_feedforward_keeps_the_numbers_of_a_checked_call(talos):
    """Cycle after cycle (moving references, a blend, a weight changed in place), the LQR's
    feedforward equals balancing_forces called afresh with every check."""
    rng = np.random.default_rng(7)
    names = ("left_sole", "right_sole")
    lqr = MomentumLQR(talos, names)
    both, left = lqr.gains(talos, names), lqr.gains(talos, ("left_sole",))
    X = np.array([talos.contact_point(n) for n in names])
    for k in range(20):
        com = talos.com + rng.normal(scale=0.02, size=3)
        hdot = rng.normal(scale=5.0, size=6) if k % 2 else None
        lam = lqr.feedforward(talos, both, com, hdot)
        fresh = balancing_forces(X, com, talos.mass, both.dims, G0, weight=both.weight.copy(),
                                 hdot=hdot)
        np.testing.assert_array_equal(lam, fresh)
    blend = blend_gains(both, left, 0.3)
    com = talos.com + 0.01
    lam = lqr.feedforward(talos, blend, com)
    expected = 0.7 * balancing_forces(X, com, talos.mass, both.dims, G0, weight=both.weight)
    expected[:6] += 0.3 * balancing_forces(X[:1], com, talos.mass, (6,), G0, weight=left.weight)
    np.testing.assert_allclose(lam, expected, rtol=1e-12, atol=1e-9)
    # a configuration whose weight is changed in place: the new weight is the one used
    weight = both.weight.copy()
    own = ContactGains(names, both.dims, both.K, both.lambda0, both.com0, weight=weight)
    before = lqr.feedforward(talos, own, com)
    weight[2, 2] *= 10.0  # the left sole's vertical force costs more
    after = lqr.feedforward(talos, own, com)
    np.testing.assert_array_equal(after, balancing_forces(X, com, talos.mass, both.dims, G0,
                                                          weight=weight))
    assert after[2] < before[2]
