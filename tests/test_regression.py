"""Key-term separated regression (eqs. 15-18, 23-25) against the row-by-row oracle."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import oracle
import pytest

from jaxcascade import CascadeParams, Orders, regression, signals
from jaxcascade._estimator._regression import solve_normal_equations

# compiled: called eagerly, every `lax.scan` inside compiles a program of its own at
# every call
_signals = eqx.filter_jit(signals)

ORDERS = [Orders(2, 2, 2, 2), Orders(1, 1, 1, 0), Orders(3, 2, 3, 1), Orders(2, 3, 1, 2)]


def _params(vector, orders):
    return CascadeParams.from_vector(jnp.asarray(vector), orders)


@pytest.mark.parametrize("unit_slopes", [False, True])
@pytest.mark.parametrize("orders", ORDERS, ids=str)
def test_phi_and_yc_match_oracle(orders, unit_slopes):
    # Estimates that are not the truth, noisy y and arbitrary v, x: every branch of
    # g1, g2, f1, f2 is exercised away from the fixed point.
    rng = np.random.default_rng(20 + orders.size)
    true, estimate = (oracle.random_system(rng, orders) for _ in range(2))
    u = rng.uniform(-2, 2, 300)
    v, x, y = oracle.simulate(oracle.unpack(true, orders), u)
    y = y + 0.05 * np.std(y) * rng.standard_normal(y.shape)
    P = oracle.unpack(estimate, orders)
    phi, yc = oracle.regression(P, u, y, v, x, unit_slopes)
    got = regression(
        _params(estimate, orders),
        *(jnp.asarray(s) for s in (u, y, v, x)),
        unit_slopes=unit_slopes,
    )
    assert got.phi.shape == (300, orders.size)
    # entries are products of at most three numbers: equal up to one rounding
    np.testing.assert_allclose(got.phi, phi, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(got.yc, yc, rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(got.g1, phi[:, -3])
    np.testing.assert_array_equal(got.g2, -phi[:, -1])
    assert 0 < np.mean(got.g1) < 1 and 0 < np.mean(got.g2) < 1  # both lines and the gap


@pytest.mark.parametrize("orders", ORDERS, ids=str)
def test_truth_solves_noise_free_regression(orders):
    rng = np.random.default_rng(30 + orders.size)
    vector = oracle.random_system(rng, orders)
    params = _params(vector, orders)
    u = jnp.asarray(rng.uniform(-2, 2, 500))
    s = _signals(params, u)
    reg = regression(params, u, s.y, s.v, s.x)
    assert np.all(np.asarray(reg.g1 * reg.g2) == 0)  # where both lines switch, left wins
    # eq. 16 holds identically at the truth; a dozen O(1) products: rounding only
    residual = reg.yc - reg.phi @ params.to_theta()
    assert np.max(np.abs(residual)) < 1e-12 * (1 + np.max(np.abs(s.y)))
    # the NumPy oracle's row-by-row regression agrees
    phi, yc = oracle.regression(oracle.unpack(vector, orders), *map(np.asarray, (u, s.y, s.v, s.x)))
    assert np.max(np.abs(yc - phi @ oracle.theta(oracle.unpack(vector, orders)))) < 1e-12 * (
        1 + np.max(np.abs(yc))
    )


def test_solver_matches_lstsq_and_flags_zero_column():
    rng = np.random.default_rng(40)
    phi = rng.standard_normal((200, 6)) * np.array([1, 10, 0.1, 1, 100, 1])
    yc = rng.standard_normal(200)
    theta, singular, cost = solve_normal_equations(jnp.asarray(phi), jnp.asarray(yc))
    expected = np.linalg.lstsq(phi, yc, rcond=None)[0]
    assert not bool(singular)
    # condition number of the scaled Gram matrix is ~1: normal equations lose nothing
    np.testing.assert_allclose(theta, expected, rtol=1e-10, atol=1e-12)
    assert float(cost) == pytest.approx(np.mean((yc - phi @ expected) ** 2), rel=1e-10)

    phi[:, 2] = 0.0  # a regime never visited
    theta, singular, _ = solve_normal_equations(jnp.asarray(phi), jnp.asarray(yc))
    assert bool(singular) and np.all(np.isfinite(theta))
    # a singular system gets (close to) the minimum-norm least-squares solution (what
    # lstsq gives), from which the paper's iteration goes on; the ridge, 1e-8 of the
    # largest column's squared norm, moves a coefficient by ~1e-8 (d_max / d_i)^2
    # relative: up to 1e-4 for these column scales (1 to 100)
    expected = np.linalg.lstsq(phi, yc, rcond=None)[0]
    np.testing.assert_allclose(theta, expected, rtol=3e-4, atol=1e-12)

    phi[:, 3] = phi[:, 0] + 2 * phi[:, 1]  # linearly dependent columns
    theta, singular, _ = solve_normal_equations(jnp.asarray(phi), jnp.asarray(yc))
    assert bool(singular)
    np.testing.assert_allclose(
        theta, np.linalg.lstsq(phi, yc, rcond=None)[0], rtol=3e-4, atol=1e-12
    )
