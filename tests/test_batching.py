"""`chunked_vmap`: vmap in micro-batches equals vmap, with the least padding."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcascade._benchmark._batching import chunked_vmap, host_threads, split_batch


@pytest.mark.parametrize(
    "size, micro_batch, shape",
    [(300, 256, (2, 150)), (7, 3, (3, 3)), (16, 16, (1, 16)), (1, 8, (1, 1)), (1000, 16, (63, 16))],
)
def test_micro_batches_equal_vmap_with_least_padding(size, micro_batch, shape):
    x = jnp.arange(size, dtype=jnp.float64)
    fn = chunked_vmap(lambda v: jnp.sin(v) * v, micro_batch)
    np.testing.assert_allclose(jax.jit(fn)(x), jax.vmap(lambda v: jnp.sin(v) * v)(x))
    # the micro-batches as the lax.map sees them: count x size
    assert f"f64[{shape[0]},{shape[1]}]" in str(jax.make_jaxpr(fn)(x))


@pytest.mark.parametrize("size, workers", [(7, 3), (8, 2), (1, 2), (5, 1)])
def test_host_threads_equal_one_call_bit_for_bit(size, workers):
    # a pytree in and out, a shared argument, sizes that do not divide into the parts
    x = {"a": jnp.arange(size, dtype=jnp.float64), "b": jnp.ones((size, 3))}
    fn = jax.jit(jax.vmap(lambda r, s: (jnp.sin(r["a"]) * s, r["b"] * r["a"]), in_axes=(0, None)))
    pieces, total = split_batch(x, workers)
    assert total == size and len(pieces) == min(workers, size)
    assert len({p["a"].shape for p in pieces}) == 1  # one shape: one compiled program
    split = host_threads(fn, workers)(x, 2.5)
    whole = fn(x, 2.5)
    for got, want in zip(split, whole, strict=True):
        assert got.shape == want.shape
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


@pytest.mark.parametrize("records, exact", [(8, True), (10, False)])
def test_literal_workload_over_host_threads_equals_one_call(records, exact):
    # the bench's workload with the fused kernel (where built): two kernel calls at once
    # share the cores (`active_calls` in normal_equations.cc) and compute the same sums.
    # 8 records in micro-batches of 4: the parts' micro-batches are the whole's (2 x 4
    # against 1 x 4 each), bit for bit; 10 records: 3 x 4 against 2 x 3, to rounding.
    from jaxcascade._benchmark._timing import batched_fit
    from jaxcascade._system._examples import example

    params = example(1).params(jnp.float64)
    keys = jax.random.split(jax.random.PRNGKey(3), records)
    fit, _ = batched_fit(1, 300, 4, jnp.float64, batch=4)
    whole = fit(keys, params)
    split = host_threads(fit, 2)(keys, params)
    for got, want in zip(split, whole, strict=True):
        if exact:
            np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
        else:
            np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-9, atol=1e-12)
