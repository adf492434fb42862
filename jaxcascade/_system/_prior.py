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

import functools
import itertools

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


# the prior's ranges (module docstring); breakpoints as fractions of u_max
_SLOPE = (0.2, 1.5)
_BREAKPOINT = (0.15, 0.75)
_A = (-0.4, 0.4)
_RADIUS = 0.7
_GAP = (0.05, 0.5)
_MR = (0.6, 1.5)


def _assemble(o: Orders, MR, DR, ML, DL, a, radius, angle, real, cL, mR, cR, dtype):
    pairs = radius * jnp.exp(1j * angle)
    roots = jnp.concatenate([pairs, jnp.conj(pairs), real])
    b = jnp.real(_poly_from_roots(roots.astype(jnp.result_type(dtype, 1j))))[1:].astype(dtype)
    return CascadeParams.from_vector(
        jnp.concatenate([MR, DR, ML, DL, a, b, cL, mR, cR]), o, check=False
    )


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
        return sign * uniform((n,), *_SLOPE)

    low, high = (_BREAKPOINT[0] * u_max, _BREAKPOINT[1] * u_max)
    MR, ML = slopes(o.nR), slopes(o.nL)
    DR = jnp.sort(uniform((o.nR - 1,), low, high))
    DL = -jnp.sort(uniform((o.nL - 1,), low, high))
    radius = uniform((o.p // 2,), 0.0, _RADIUS)
    angle = uniform((o.p // 2,), 0.0, jnp.pi)
    real = uniform((o.p % 2,), -_RADIUS, _RADIUS)
    a = uniform((o.r - 1,), *_A)
    cL, mR, cR = uniform((1,), *_GAP), uniform((1,), *_MR), uniform((1,), *_GAP)
    return _assemble(o, MR, DR, ML, DL, a, radius, angle, real, cL, mR, cR, dtype)


def random_systems(
    key: PRNGKeyArray, count: int, orders: Orders | None = None, u_max: float = 2.0, dtype=None
) -> CascadeParams:
    """`count` cascades from the same prior, batched (leading axis `count`), from one
    draw of uniforms: a different stream from `random_system` with the same key. One
    draw is one PRNG computation in the compiled program (the robust estimator's
    multi-start starts): `random_system` per key costs a dozen, and each costs compile
    time."""
    dtype = dtype or jnp.result_type(float)
    o = orders or Orders()
    sizes = (o.nR, o.nR, o.nR - 1, o.nL, o.nL, o.nL - 1, o.p // 2, o.p // 2, o.p % 2)
    sizes += (o.r - 1, 1, 1, 1)
    unit = jax.random.uniform(key, (count, sum(sizes)), dtype)
    parts = jnp.split(unit, list(itertools.accumulate(sizes))[:-1], axis=1)
    sR, MR, DR, sL, ML, DL, radius, angle, real, a, cL, mR, cR = parts

    def scale(x, bounds):
        return bounds[0] + (bounds[1] - bounds[0]) * x

    def slopes(sign, magnitude):
        return jnp.where(sign < 0.5, 1.0, -1.0).astype(dtype) * scale(magnitude, _SLOPE)

    bounds = (_BREAKPOINT[0] * u_max, _BREAKPOINT[1] * u_max)
    return jax.vmap(functools.partial(_assemble, o, dtype=dtype))(
        slopes(sR, MR),
        jnp.sort(scale(DR, bounds), axis=1),
        slopes(sL, ML),
        -jnp.sort(scale(DL, bounds), axis=1),
        scale(a, _A),
        _RADIUS * radius,
        jnp.pi * angle,
        scale(real, (-_RADIUS, _RADIUS)),
        scale(cL, _GAP),
        scale(mR, _MR),
        scale(cR, _GAP),
    )
