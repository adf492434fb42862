"""The random-system family: a documented prior over cascades, used as a benchmark
family and to draw multi-start initial values.

Prior (for orders (nR, nL, r, p), input uniform in (-u_max, u_max), default u_max = 2):

- slope increments |MR_i|, |ML_j| uniform in [0.2, 1.5], signs random;
- right breakpoints sorted uniform in [0.15, 0.75] u_max (i.e. [0.3, 1.5] for u_max = 2),
  left breakpoints their mirror image, drawn independently;
- a2..ar uniform in [-0.4, 0.4];
- poles of the linear block inside radius 0.7: complex pairs with radius uniform in
  [0, 0.7] and angle uniform in [0, pi], plus one real pole uniform in [-0.7, 0.7] when
  p is odd;
- mR uniform in [0.6, 1.5]; cL and cR uniform in [0.05, 0.5].
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import PRNGKeyArray

from ._model import CascadeParams, Orders


def _poly_from_roots(roots):
    poly = jnp.ones((1,), roots.dtype)
    for root in roots:
        poly = jnp.concatenate([poly, jnp.zeros((1,), poly.dtype)]) - root * jnp.concatenate(
            [jnp.zeros((1,), poly.dtype), poly]
        )
    return poly


def random_system(
    key: PRNGKeyArray, orders: Orders | None = None, u_max: float = 2.0, dtype=None
) -> CascadeParams:
    """Draw one cascade from the prior above (traceable, `vmap` over keys)."""
    dtype = dtype or jnp.result_type(float)
    o = orders or Orders()
    keys = iter(jax.random.split(key, 16))

    def uniform(shape, low, high):
        return jax.random.uniform(next(keys), shape, dtype, low, high)

    def slopes(n):
        sign = jnp.where(jax.random.bernoulli(next(keys), 0.5, (n,)), 1.0, -1.0).astype(dtype)
        return sign * uniform((n,), 0.2, 1.5)

    MR, ML = slopes(o.nR), slopes(o.nL)
    DR = jnp.sort(uniform((o.nR - 1,), 0.15 * u_max, 0.75 * u_max))
    DL = -jnp.sort(uniform((o.nL - 1,), 0.15 * u_max, 0.75 * u_max))
    radius = uniform((o.p // 2,), 0.0, 0.7)
    angle = uniform((o.p // 2,), 0.0, jnp.pi)
    pairs = radius * jnp.exp(1j * angle)
    roots = jnp.concatenate([pairs, jnp.conj(pairs), uniform((o.p % 2,), -0.7, 0.7)])
    b = jnp.real(_poly_from_roots(roots.astype(jnp.result_type(dtype, 1j))))[1:].astype(dtype)
    return CascadeParams.from_vector(
        jnp.concatenate(
            [
                MR,
                DR,
                ML,
                DL,
                uniform((o.r - 1,), -0.4, 0.4),
                b,
                uniform((1,), 0.05, 0.5),
                uniform((1,), 0.6, 1.5),
                uniform((1,), 0.05, 0.5),
            ]
        ),
        o,
        check=False,
    )
