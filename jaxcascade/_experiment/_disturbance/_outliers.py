"""White Gaussian noise with outliers: a fraction of samples hit by a gross error."""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from ._base import Disturbance, number, setting


class Outliers(Disturbance):
    """Gaussian noise `g` plus, at a random `fraction` of the samples (independently,
    Bernoulli), an outlier of `size` standard deviations of `g` with a random sign;
    the sum divided by `sqrt(1 + fraction size^2)`, so that its variance is 1 and the
    SNR counts the outliers as noise (`fraction = 0.02`, `size = 10`: the Gaussian part
    holds a third of the noise power, the outliers two thirds).
    """

    name: ClassVar[str] = "outliers"
    summary: ClassVar[str] = "Gaussian noise plus outliers (fraction, size in stds)"

    fraction: float = setting(0.02)
    size: float = setting(10.0)

    def __check_init__(self):
        number(self.fraction, "Noise outliers: fraction", low=0.0, high=1.0)
        number(self.size, "Noise outliers: size", low=0.0, high=1e6)

    def __call__(self, key, n, dtype=None):
        dtype = dtype or jnp.result_type(float)
        key_g, key_hit, key_sign = jax.random.split(key, 3)
        g = jax.random.normal(key_g, (n,), dtype)
        hit = jax.random.bernoulli(key_hit, float(self.fraction), (n,)).astype(dtype)
        sign = jnp.where(jax.random.bernoulli(key_sign, 0.5, (n,)), 1.0, -1.0).astype(dtype)
        size, fraction = float(self.size), float(self.fraction)
        return (g + hit * sign * size) / math.sqrt(1.0 + fraction * size**2)
