"""The associative-scan forms of the recursions in time (`_system._scans`), run here on
the CPU, against the sequential `lax.scan`s they replace on an accelerator: the pole
recursion, the backlash (straight and curved), the forward sensitivities, and the
dispatch of `signals` and `output_jacobian` when the parallel forms are chosen."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pytest

from jaxcascade import CascadeParams, Orders
from jaxcascade._estimator import _sensitivity
from jaxcascade._system import _scans, _simulate
from jaxcascade._system._general_backlash import GeneralBacklash

# Record lengths: one sample, fewer than a scan level's pair, odd and even, a power of
# two and one past it, and a longer odd one.
LENGTHS = [1, 2, 3, 7, 64, 65, 1001]
# The issue's bound on the parallel forms' difference from the sequential ones,
# relative to the signal's scale (measured: about 3e-16, sums in another order).
TOLERANCE = 1e-12


def _stable(rng, p):
    return jnp.asarray(np.real(np.poly(rng.uniform(-0.9, 0.9, p)))[1:])


def _close(got, want):
    scale = max(float(jnp.max(jnp.abs(want))), 1.0) if want.size else 1.0
    np.testing.assert_allclose(got, want, rtol=0, atol=TOLERANCE * scale)


_poles = jax.jit(_scans.poles)
_poles_blocked = jax.jit(_scans.poles_blocked, static_argnums=2)
_sequential_poles = jax.jit(_simulate._poles_scan)


@pytest.mark.parametrize("p", [1, 2, 3, 6])
def test_poles_equal_the_sequential_recursion(p):
    rng = np.random.default_rng(p)
    b = _stable(rng, p)
    for T in LENGTHS:
        w = jnp.asarray(rng.normal(size=T))
        want = _sequential_poles(b, w)
        _close(_poles(b, w), want)
        # several right-hand sides: each column its own recursion
        for block in (8, 64):  # blocks of the state's length or longer, and the default
            _close(_poles_blocked(b, w, block), want)
        W = jnp.asarray(rng.normal(size=(T, 3)))
        want = jnp.stack([_sequential_poles(b, W[:, k]) for k in range(3)], axis=1)
        _close(_poles(b, W), want)
        _close(_poles_blocked(b, W, 64), want)


def test_poles_without_poles_and_unstable():
    rng = np.random.default_rng(0)
    w = jnp.asarray(rng.normal(size=200))
    assert _scans.poles(jnp.zeros((0,)), w) is w
    assert _scans.poles_blocked(jnp.zeros((0,)), w) is w
    # a growing recursion (an iterate of the literal iteration may be unstable): the
    # relative difference stays at rounding
    b = jnp.asarray([-1.2, 0.1])  # a pole at 1.11
    want = _sequential_poles(b, w)
    assert float(jnp.max(jnp.abs(want))) > 1e6
    _close(_poles(b, w), want)
    _close(_poles_blocked(b, w, 64), want)


def _straight(mR, cL=0.2, cR=0.3):
    return GeneralBacklash(*(jnp.asarray(v) for v in (cL, mR, cR, jnp.zeros(0), jnp.zeros(0))))


def _signal(rng, T):
    t = np.arange(T)
    return jnp.asarray(2 * np.sin(0.05 * t) + 0.3 * rng.normal(size=T))


def test_backlash_equals_the_sequential_scan():
    # mR != 1: the branches cross and the threshold maps appear beside the clamps; the
    # slopes side by side under `vmap` (one program per length)
    rng = np.random.default_rng(10)
    orders = Orders(2, 2, 2, 2)
    slopes = jnp.asarray([0.5, 1.0, 1.2, 3.0])
    vector = jnp.asarray(oracle.random_system(rng, orders))
    params = jax.vmap(
        lambda mR: CascadeParams.from_vector(vector.at[-2].set(mR), orders, check=False)
    )(slopes)
    sequential = jax.jit(jax.vmap(_simulate.backlash, (0, None)))

    @jax.jit
    @functools.partial(jax.vmap, in_axes=(0, None))
    def parallel(params, x):
        return _scans.backlash(x, x + params.cL, params.mR * (x - params.cR), params.mR)

    for T in LENGTHS:
        x = _signal(rng, T)
        _close(parallel(params, x), sequential(params, x))


@pytest.mark.parametrize("degree", [2, 3])
def test_general_backlash_equals_the_sequential_scan(degree):
    rng = np.random.default_rng(degree)
    sequential = jax.jit(_simulate.general_backlash)

    @jax.jit
    def parallel(nd, x, y_prev):
        return _scans.backlash(x, *_simulate.general_branches(nd, x), nd.mR, y_prev)

    curve = jnp.asarray([0.05, -0.02][: degree - 1])
    nd = GeneralBacklash(*(jnp.asarray(v) for v in (0.2, 1.2, 0.3)), curve, -curve)
    for T in LENGTHS:
        x = _signal(rng, T)
        for y_prev in (0.0, 1.5):
            _close(parallel(nd, x, y_prev), sequential(nd, x, y_prev))


def test_backlash_outside_its_domain_is_nan():
    # mR <= 0 is outside the parallel form's domain (and the model's); a non-finite
    # input spoils the output from there on, as in the sequential recursion
    x = jnp.linspace(-1.0, 1.0, 9)
    assert jnp.all(jnp.isnan(_scans.backlash(x, x, -x, jnp.asarray(-0.5))))
    broken = x.at[4].set(jnp.nan)
    got = _scans.backlash(broken, broken + 0.1, broken - 0.1, jnp.asarray(1.0))
    want = _simulate.backlash(
        CascadeParams.from_dict(
            {"MR1": 1.0, "ML1": 1.0, "cL": 0.1, "mR": 1.0, "cR": 0.1}, Orders(1, 1, 1, 0)
        ),
        broken,
    )
    assert np.array_equal(np.isnan(got), np.isnan(want))
    assert np.all(np.isnan(got[4:])) and np.all(np.isfinite(got[:4]))


def _random_hold(rng, size):
    left, right = rng.normal(size=(2, size))
    return _scans.backlash_maps(jnp.asarray(left), jnp.asarray(right))


def test_hold_maps_compose_associatively_and_as_functions():
    # composed maps (clamps, threshold maps, constants) act as the maps one after
    # another, and the composition does not depend on the grouping: exactly
    rng = np.random.default_rng(3)
    f, g, h = (_random_hold(rng, 500) for _ in range(3))
    y = jnp.asarray(rng.normal(size=500) * 2)
    one_by_one = _scans.apply_hold(h, _scans.apply_hold(g, _scans.apply_hold(f, y)))
    left = _scans.compose_hold(_scans.compose_hold(f, g), h)
    right = _scans.compose_hold(f, _scans.compose_hold(g, h))
    assert np.array_equal(_scans.apply_hold(left, y), one_by_one)
    assert np.array_equal(_scans.apply_hold(right, y), one_by_one)
    assert bool(jnp.any(f.step)) and bool(jnp.any(~f.step))  # both kinds were drawn


def test_last_active_is_the_held_recursion():
    rng = np.random.default_rng(4)

    @jax.jit
    def held(active, values):
        def step(before, inputs):
            now = jnp.where(inputs[0], inputs[1], before)
            return now, now

        return jax.lax.scan(step, jnp.zeros(values.shape[1:]), (active, values))[1]

    for T in LENGTHS:
        active = jnp.asarray(rng.uniform(size=T) < 0.3)
        values = jnp.asarray(rng.normal(size=(T, 4)))
        got = jax.jit(_scans.last_active)(active, values)
        assert np.array_equal(got, held(active, values))


# no poles, and three poles with three numerator terms (`tests/test_sensitivity.py`
# holds the sequential form against `jax.jacfwd` on more orders)
ORDERS = [Orders(1, 1, 1, 0), Orders(3, 3, 2, 3)]


@pytest.mark.parametrize("orders", ORDERS, ids=str)
def test_output_jacobian_parallel_equals_the_scan(orders):
    rng = np.random.default_rng(sum(map(int, str(orders).split(","))))
    vector = jnp.asarray(oracle.random_system(rng, orders))
    params = CascadeParams.from_vector(vector, orders)
    sequential = eqx.filter_jit(_sensitivity.output_jacobian)
    parallel = eqx.filter_jit(_sensitivity.output_jacobian_parallel)
    for T in (2, 65, 1001):
        u = jnp.asarray(rng.uniform(-2, 2, T))
        y, J = sequential(params, u)
        y_parallel, J_parallel = parallel(params, u)
        _close(y_parallel, y)
        _close(J_parallel, J)


def test_the_parallel_forms_are_chosen_on_an_accelerator(monkeypatch):
    # what an accelerator runs, here on the CPU: `signals` and `output_jacobian` take
    # the associative scans when `_scans.parallel()` says so, at trace time, batched
    rng = np.random.default_rng(5)
    orders = Orders(2, 2, 2, 2)
    vectors = jnp.asarray(np.stack([oracle.random_system(rng, orders) for _ in range(4)]))
    u = jnp.asarray(rng.uniform(-2, 2, (4, 700)))

    def run(vector, u):
        params = CascadeParams.from_vector(vector, orders, check=False)
        return _simulate.signals(params, u), _sensitivity.output_jacobian(params, u)

    # the CPU's forms first (the default there; chosen here on any backend)
    monkeypatch.setattr(_scans, "parallel", lambda: False)
    want = jax.jit(jax.vmap(run))(vectors, u)
    params = CascadeParams.from_vector(vectors[0], orders)
    plain = _simulate.linear_block(params, u[0], block=1)
    # the sequential forms step through the record's 700 samples; the parallel ones loop
    # over log2 rounds only
    assert "length=700" in str(jax.make_jaxpr(jax.vmap(run))(vectors, u))
    monkeypatch.setattr(_scans, "parallel", lambda: True)
    assert "length=700" not in str(jax.make_jaxpr(jax.vmap(run))(vectors, u))
    got = jax.jit(jax.vmap(run))(vectors, u)
    for g, w in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want), strict=True):
        _close(g, w)
    # the plain recursion stays the oracle: block=1 is never the parallel form
    assert np.array_equal(_simulate.linear_block(params, u[0], block=1), plain)
