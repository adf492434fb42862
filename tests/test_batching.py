"""`chunked_vmap`: vmap in micro-batches equals vmap, with the least padding."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcascade._batching import chunked_vmap


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
