"""A multilevel input: a random level held until it switches (a random telegraph).

At every sample the input switches with probability `switch_probability` (the first
sample always draws). With `levels = 0` each switch draws a fresh level uniform in
`(-A, A)`; with `levels = k >= 2` the levels are `k` evenly spaced values in `[-A, A]`
and a switch moves to one of the other `k - 1` at random (`levels = 2`: a random binary
signal of +-A). A small switching probability makes a slow input, rich at low
frequencies; 1 with `levels = 0` is white.
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from ._base import InputDesign, one_scale, setting


class Multilevel(InputDesign):
    """Random levels in `[-A, A]` held between switches; `A = amplitude`, or the level
    bound whose stationary rms is `rms` (default the paper's input power)."""

    name: ClassVar[str] = "multilevel"
    summary: ClassVar[str] = "random levels held between random switches (levels = 2: binary)"

    levels: int = setting(0)
    switch_probability: float = setting(0.5)
    amplitude: float | None = setting(None)
    rms: float | None = setting(None)

    def __check_init__(self):
        one_scale("Input multilevel", self.amplitude, self.rms)
        levels = self.levels
        if isinstance(levels, bool) or not isinstance(levels, int) or levels < 0 or levels == 1:
            raise ValueError(
                "Input multilevel: levels must be 0 (continuous) or an integer >= 2, "
                f"got {levels!r}."
            )
        p = self.switch_probability
        if isinstance(p, bool) or not isinstance(p, int | float) or not 0.0 < p <= 1.0:
            raise ValueError(f"Input multilevel: switch_probability must lie in (0, 1], got {p!r}.")

    def unit_rms(self) -> float:
        """The stationary rms of the levels in `[-1, 1]` (each level equally likely)."""
        k = self.levels
        return 1.0 / math.sqrt(3.0) if k == 0 else math.sqrt((k + 1) / (3.0 * (k - 1)))

    @property
    def bound(self) -> float:
        if self.amplitude is not None:
            return float(self.amplitude)
        return (float(self.rms) if self.rms is not None else 2.0 / math.sqrt(3.0)) / self.unit_rms()

    def __call__(self, key, n, dtype=None):
        dtype = dtype or jnp.result_type(float)
        key_switch, key_level, key_start = jax.random.split(key, 3)
        switch = jax.random.bernoulli(key_switch, float(self.switch_probability), (n,))
        switch = switch.at[0].set(True)
        if self.levels == 0:
            candidate = jax.random.uniform(key_level, (n,), dtype, -1.0, 1.0)
            last = jax.lax.cummax(jnp.where(switch, jnp.arange(n), 0))
            unit = candidate[last]
        else:
            k = self.levels
            start = jax.random.randint(key_start, (), 0, k)
            step = jax.random.randint(key_level, (n,), 1, k)  # to another level
            index = (start + jnp.cumsum(jnp.where(switch, step, 0))) % k
            unit = -1.0 + 2.0 * index.astype(dtype) / (k - 1)
        return self.bound * unit

    def input_range(self, u):
        return -self.bound, self.bound

    def settings(self):
        return {
            "levels": self.levels,
            "switch_probability": float(self.switch_probability),
            "amplitude": self.bound,
        }
