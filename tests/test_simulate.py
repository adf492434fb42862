"""Simulation: the JAX blocks against the NumPy oracle, noise, keys and vmap."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pytest

from jaxcascade import (
    CascadeParams,
    Orders,
    add_noise,
    example,
    measure,
    pwl,
    signals,
    simulate,
    uniform_input,
)

# compiled: called eagerly, every `lax.scan` inside compiles a program of its own at
# every call
_signals = eqx.filter_jit(signals)

# p = 0, r = 1, nR = nL = 1 and three segments all appear
ORDERS = [
    Orders(2, 2, 2, 2),
    Orders(1, 1, 1, 0),
    Orders(3, 2, 3, 1),
    Orders(2, 3, 1, 2),
    Orders(3, 3, 2, 3),
    Orders(1, 2, 2, 0),
]


@pytest.mark.parametrize("orders", ORDERS, ids=str)
def test_simulate_matches_oracle(orders):
    rng = np.random.default_rng(sum(map(int, str(orders).split(","))))
    for _ in range(2):
        vector = oracle.random_system(rng, orders)
        u = rng.uniform(-2, 2, 500)
        v, x, y = oracle.simulate(oracle.unpack(vector, orders), u)
        params = CascadeParams.from_vector(jnp.asarray(vector), orders)
        got = _signals(params, jnp.asarray(u))
        # same sums in another order through a stable recursion: rounding stays ~1e-14
        np.testing.assert_allclose(got.v, v, rtol=0, atol=1e-10)
        np.testing.assert_allclose(got.x, x, rtol=0, atol=1e-10)
        np.testing.assert_allclose(got.y, y, rtol=0, atol=1e-10)
        np.testing.assert_allclose(simulate(params, jnp.asarray(u)), y, rtol=0, atol=1e-10)
        assert np.ptp(y) > 0  # the backlash moved


@pytest.mark.parametrize("orders", ORDERS[:3], ids=str)
def test_pwl_equals_its_matrix_form(orders):
    # pwl sums its segments element-wise in the order of the matrix product it replaced
    # (`MR @ right + ML @ left`); batched as in a Monte-Carlo run, the two agree to
    # rounding (on XLA's CPU backend, bit for bit)
    rng = np.random.default_rng(7)
    vectors = jnp.asarray(np.stack([oracle.random_system(rng, orders) for _ in range(8)]))
    u = jnp.asarray(rng.uniform(-2, 2, (8, 400)))

    def matrix_form(vector, u):
        p = CascadeParams.from_vector(vector, orders)
        zero = jnp.zeros((1,), u.dtype)
        DR, DL = jnp.concatenate([zero, p.DR]), jnp.concatenate([zero, p.DL])
        right = (DR[:, None] - u[None, :] < 0) * (u[None, :] - DR[:, None])
        left = (u[None, :] - DL[:, None] < 0) * (u[None, :] - DL[:, None])
        return p.MR @ right + p.ML @ left

    got = jax.jit(jax.vmap(lambda v, u: pwl(CascadeParams.from_vector(v, orders), u)))(vectors, u)
    want = jax.jit(jax.vmap(matrix_form))(vectors, u)
    scale = float(jnp.max(jnp.abs(want)))
    np.testing.assert_allclose(got, want, rtol=0, atol=8 * np.finfo(float).eps * scale)


def test_pwl_slopes_are_cumulative():
    # METHOD.md: the slope of right segment k is MR1 + ... + MRk (left likewise).
    orders = Orders(3, 3, 1, 0)
    P = {
        "MR": [0.5, -1.0, 2.0],
        "DR": [0.5, 1.0],
        "ML": [0.3, 0.7, -1.5],
        "DL": [-0.4, -1.2],
        "a": [],
        "b": [],
        "cL": 0.1,
        "mR": 1.0,
        "cR": 0.1,
    }
    params = CascadeParams.from_vector(jnp.asarray(oracle.pack(P)), orders)
    midpoints = jnp.asarray([0.25, 0.75, 1.5, -0.2, -0.8, -1.6])
    step = 1e-3
    slopes = (pwl(params, midpoints + step) - pwl(params, midpoints - step)) / (2 * step)
    # the block is exactly linear inside a segment: only rounding in the difference
    np.testing.assert_allclose(slopes, [0.5, -0.5, 1.5, 0.3, 1.0, -0.5], atol=1e-9)
    assert float(pwl(params, jnp.zeros(1))[0]) == 0.0


def test_dtype_follows_input():
    params = example(1).params()
    u = uniform_input(jax.random.key(0), 100, dtype=jnp.float32)
    assert u.dtype == jnp.float32
    assert simulate(params, u).dtype == jnp.float32
    y64 = simulate(params, u.astype(jnp.float64))
    # float32 rounding (~1e-7 relative) through a short, stable recursion
    np.testing.assert_allclose(simulate(params, u), y64, atol=1e-4)


@pytest.mark.parametrize("snr", [25.0, 5.0])
def test_noise_at_requested_snr(snr):
    ex = example(1)
    params = ex.params()
    u = uniform_input(jax.random.key(1), 20000)
    y_meas, y = measure(jax.random.key(2), params, u, snr)
    np.testing.assert_array_equal(y, simulate(params, u))  # the backlash state is noise-free
    e = np.asarray(y_meas - y)
    empirical = np.sqrt(np.var(np.asarray(y)) / np.var(e))
    # the sample variance of 20000 Gaussians has relative sd sqrt(2/N) = 1%: 3% is > 5 sd
    assert empirical == pytest.approx(snr, rel=0.03)
    assert abs(np.mean(e)) < 5 * np.std(e) / np.sqrt(e.size)  # zero mean, 5 sd


def test_infinite_snr_adds_nothing():
    y = simulate(example(2).params(), uniform_input(jax.random.key(3), 200))
    np.testing.assert_array_equal(add_noise(jax.random.key(4), y, jnp.inf), y)


def test_noise_is_deterministic_per_key():
    params = example(1).params()
    u = uniform_input(jax.random.key(5), 300)
    first, _ = measure(jax.random.key(6), params, u, 25.0)
    again, _ = measure(jax.random.key(6), params, u, 25.0)
    other, _ = measure(jax.random.key(7), params, u, 25.0)
    np.testing.assert_array_equal(first, again)
    assert np.max(np.abs(first - other)) > 0.01
    np.testing.assert_array_equal(
        uniform_input(jax.random.key(8), 50), uniform_input(jax.random.key(8), 50)
    )


def test_vmap_over_keys_equals_loop():
    params = example(1).params()
    u = uniform_input(jax.random.key(9), 400)
    keys = jax.random.split(jax.random.key(10), 5)
    batched, y = jax.vmap(measure, in_axes=(0, None, None, None))(keys, params, u, 25.0)
    for i, key in enumerate(keys):
        one, y_one = measure(key, params, u, 25.0)
        # the same computation batched: XLA may fuse it differently, so allow rounding
        np.testing.assert_allclose(batched[i], one, rtol=0, atol=1e-12)
        np.testing.assert_allclose(y[i], y_one, rtol=0, atol=1e-12)


def test_vmap_over_parameter_sets_equals_loop():
    rng = np.random.default_rng(11)
    orders = Orders(2, 2, 2, 2)
    vectors = np.stack([oracle.random_system(rng, orders) for _ in range(5)])
    batch = CascadeParams.from_vector(jnp.asarray(vectors), orders)
    u = uniform_input(jax.random.key(12), 400)
    batched = jax.vmap(simulate, in_axes=(0, None))(batch, u)
    assert batched.shape == (5, 400)
    for i, vector in enumerate(vectors):
        one = simulate(CascadeParams.from_vector(jnp.asarray(vector), orders), u)
        # batched reductions may round differently: ~1e-15 per step, stable recursion
        np.testing.assert_allclose(batched[i], one, rtol=0, atol=1e-12)
