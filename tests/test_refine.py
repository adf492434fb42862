"""The admissible parameterisation used by output-error refinement and the robust fit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcascade as jc
from jaxcascade._estimator._refine import _chain, from_unconstrained, to_unconstrained


@pytest.mark.parametrize("orders", [jc.Orders(), jc.Orders(3, 2, 3, 3), jc.Orders(1, 1, 1, 0)])
def test_round_trip(orders):
    for seed in range(10):
        p = jc.random_system(jax.random.PRNGKey(seed), orders)
        q = from_unconstrained(to_unconstrained(p, -2.0, 2.0), orders, -2.0, 2.0)
        # Exact up to rounding in the softmax / tanh maps.
        np.testing.assert_allclose(q.to_vector(), p.to_vector(), atol=1e-12)


@pytest.mark.parametrize("orders", [jc.Orders(), jc.Orders(3, 3, 2, 4)])
def test_every_unconstrained_vector_is_admissible(orders):
    z = 3.0 * jax.random.normal(jax.random.PRNGKey(0), (500, orders.size))
    params = jax.vmap(lambda v: from_unconstrained(v, orders, -2.0, 2.0))(z)
    ok = jax.vmap(lambda p: jc.is_admissible(p, -2.0, 2.0))(params)
    assert bool(jnp.all(ok))
    assert bool(jnp.all(params.cL >= 0)) and bool(jnp.all(params.cR >= 0))


def test_running_out_of_steps_is_max_iterations():
    # optimistix reports the outer loop's limit as `nonlinear_max_steps_reached`; it is
    # a budget, not a failure of the method, and must say so in the results table.
    from jaxcascade._estimator._refine import refine

    truth = jc.example(1).params()
    u = jax.random.uniform(jax.random.PRNGKey(0), (400,), minval=-2.0, maxval=2.0)
    y = jc.simulate(truth, u)
    start = jc.random_system(jax.random.PRNGKey(3), truth.orders)
    stopped = refine(start, u, y, max_steps=2)
    assert int(stopped.status) == int(jc.Status.max_iterations)
    done = refine(truth, u, y, max_steps=50)
    assert int(done.status) == int(jc.Status.converged)
    assert float(done.cost) < 1e-20


@pytest.mark.parametrize("orders", [jc.Orders(), jc.Orders(3, 2, 3, 3), jc.Orders(1, 1, 1, 0)])
def test_chain_is_the_jacobian_of_the_map(orders):
    # Levenberg-Marquardt's chain rule is written out (`_chain`); jacfwd is the oracle
    z = jnp.asarray(np.random.default_rng(1).normal(size=orders.size))
    expected = jax.jacfwd(lambda z: from_unconstrained(z, orders, -1.7, 1.9).to_vector())(z)
    np.testing.assert_allclose(_chain(z, orders, -1.7, 1.9), expected, rtol=1e-12, atol=1e-14)
