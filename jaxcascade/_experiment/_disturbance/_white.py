"""White Gaussian noise: the paper's measurement noise (and the sweep's default)."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from ._base import Disturbance


class White(Disturbance):
    """Independent standard normal samples (`_simulate.add_noise` without a disturbance
    draws exactly these, so a sweep's white noise is the same bit for bit)."""

    name: ClassVar[str] = "white"
    summary: ClassVar[str] = "white Gaussian noise (the paper's)"

    def __call__(self, key, n, dtype=None):
        return jax.random.normal(key, (n,), dtype or jnp.result_type(float))
