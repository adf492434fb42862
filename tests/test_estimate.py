"""The literal Vörös iteration: fixed point, paper Example 1, oracle history, status, jit, vmap."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pytest

import jaxcascade
from jaxcascade import (
    CascadeParams,
    Orders,
    Status,
    _estimate,
    example,
    initial_guess,
    measure,
    simulate,
)
from jaxcascade._estimate import voros_step


def _example1_record(seed=0, n=None):
    ex = example(1)
    u = jaxcascade.uniform_input(jax.random.key(seed), n or ex.n_samples)
    return ex, u, simulate(ex.params(), u)


@pytest.mark.parametrize(
    "orders",
    [Orders(2, 2, 2, 2), Orders(1, 1, 1, 0), Orders(3, 2, 3, 1), Orders(2, 3, 1, 2)],
    ids=str,
)
def test_truth_is_a_fixed_point(orders):
    rng = np.random.default_rng(50 + orders.size)
    u = rng.uniform(-2, 2, 1000)
    for _ in range(2):
        vector, (_, _, y) = oracle.identifiable_system(rng, orders, u)
        params = CascadeParams.from_vector(jnp.asarray(vector), orders)
        new, singular, cost = voros_step(params, jnp.asarray(u), jnp.asarray(y))
        assert not bool(singular)
        # zero-residual least squares, scaled condition number < 1e4: error ~1e4 eps
        np.testing.assert_allclose(new, vector, rtol=0, atol=1e-10)
        assert float(cost) < 1e-24


def test_example1_noise_free_recovered():
    ex, u, y = _example1_record()
    sol = jaxcascade.voros(u, y, ex.orders, initial_guess(ex.orders, -2.0, 2.0))
    assert sol.status == Status.converged
    # converged at tol 1e-10 to an exact fixed point (linear rate ~0.5 near the end)
    np.testing.assert_allclose(sol.params.to_vector(), ex.params().to_vector(), atol=1e-8)
    np.testing.assert_array_equal(sol.history[0], initial_guess(ex.orders, -2.0, 2.0).to_vector())


@pytest.mark.parametrize(
    "seed, snr, expected",
    [(1, np.inf, "converged"), (2, 25.0, "converged"), (1, 25.0, "max_iterations")],
    ids=["noise-free", "snr25", "snr25-limit-cycle"],
)
def test_matches_oracle_history(seed, snr, expected):
    # The third record does not converge: under noise the discontinuous map can settle
    # on a short cycle (here period 2). Both implementations must find the same one.
    ex, u, _ = _example1_record(seed=seed, n=2000)
    y, _ = measure(jax.random.key(100 + seed), ex.params(), u, snr)
    init = initial_guess(ex.orders, -2.0, 2.0)
    sol = jaxcascade.voros(u, y, ex.orders, init)
    history, status = oracle.voros(
        np.asarray(u), np.asarray(y), ex.orders, np.asarray(init.to_vector())
    )
    assert status == expected and sol.status == Status[expected]
    assert int(sol.iterations) == len(history) - 1
    # normal equations with Jacobi scaling vs lstsq on a well-conditioned problem
    # (~1e-13 per step), carried through a contracting iteration
    np.testing.assert_allclose(sol.history[: len(history)], history, rtol=0, atol=1e-8)
    # rows after the last accepted iterate repeat the estimate
    np.testing.assert_array_equal(sol.history[len(history) :], np.broadcast_to(
        sol.params.to_vector(), sol.history[len(history) :].shape
    ))  # fmt: skip


def test_max_iterations_status():
    ex, u, y = _example1_record(seed=1, n=2000)
    init = initial_guess(ex.orders, -2.0, 2.0)
    sol = jaxcascade.voros(u, y, ex.orders, init, max_iterations=3)
    history, status = oracle.voros(
        np.asarray(u), np.asarray(y), ex.orders, np.asarray(init.to_vector()), max_iterations=3
    )
    assert status == "max_iterations" and sol.status == Status.max_iterations
    assert int(sol.iterations) == 3 and sol.history.shape == (4, ex.orders.size)
    # three steps of a well-conditioned least squares: rounding only
    np.testing.assert_allclose(sol.history, history, rtol=0, atol=1e-10)


@pytest.mark.parametrize(
    "low, high",
    [(0.05, 2.0), (-2.0, 0.8)],
    ids=["positive-input", "segment-DR1-never-reached"],
)
def test_unvisited_regime_reports_status(low, high):
    # u > 0 never visits the left segments; u < 0.8 never passes DR1 = 1 (the init's
    # breakpoint): their slope columns vanish, so the regression cannot be solved.
    ex = example(1)
    u = jax.random.uniform(jax.random.key(3), (2000,), minval=low, maxval=high)
    y, _ = measure(jax.random.key(4), ex.params(), u, 25.0)
    for init in (initial_guess(ex.orders, -2.0, 2.0), None):
        sol = jaxcascade.voros(u, y, ex.orders, init)
        assert int(sol.status) in (Status.singular, Status.left_domain)
        assert np.all(np.isfinite(sol.params.to_vector()))
        assert np.all(np.isfinite(sol.history))
        assert np.isfinite(float(sol.cost))


def test_no_retrace_for_same_shapes(monkeypatch):
    # `first_step` is called once per trace of `voros`; a length used nowhere else
    # makes sure the first call here traces.
    counted = eqx.debug.assert_max_traces(_estimate.first_step, max_traces=1)
    monkeypatch.setattr(_estimate, "first_step", counted)
    ex = example(1)
    n = 701
    for seed in range(3):
        u = jaxcascade.uniform_input(jax.random.key(seed), n)
        y, _ = measure(jax.random.key(seed + 10), ex.params(), u, 25.0)
        init = initial_guess(ex.orders, -2.0 + 0.1 * seed, 2.0)
        # new data, initial values and tolerances; the same keywords each call (jit keys
        # its cache on which keywords are passed)
        jaxcascade.voros(u, y, ex.orders, init, tol=10.0**-seed, divergence_bound=1e3 + seed)
    assert eqx.debug.get_num_traces(counted) == 1


def test_vmap_over_realisations_equals_loop():
    ex = example(1)
    u = jaxcascade.uniform_input(jax.random.key(5), 2000)
    keys = jax.random.split(jax.random.key(6), 3)
    ys, _ = jax.vmap(measure, in_axes=(0, None, None, None))(keys, ex.params(), u, 25.0)
    init = initial_guess(ex.orders, -2.0, 2.0)
    batched = jax.vmap(lambda y: jaxcascade.voros(u, y, ex.orders, init))(ys)
    assert batched.params.MR.shape == (3, 2)
    for i in range(3):
        one = jaxcascade.voros(u, ys[i], ex.orders, init)
        assert int(batched.status[i]) == int(one.status)
        assert int(batched.iterations[i]) == int(one.iterations)
        # batched linear algebra may round differently; the iteration contracts
        np.testing.assert_allclose(batched.history[i], one.history, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            batched.params.to_vector()[i], one.params.to_vector(), rtol=0, atol=1e-9
        )
