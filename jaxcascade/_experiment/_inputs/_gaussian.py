"""Independent Gaussian input samples of a given standard deviation."""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from ._base import DEFAULT_RMS, InputDesign, gaussian_reach, positive, setting


class Gaussian(InputDesign):
    """Independent zero-mean Gaussian samples of standard deviation `std` (its rms;
    default the paper's input power). Unbounded: the estimators get the record's range."""

    name: ClassVar[str] = "gaussian"
    summary: ClassVar[str] = "independent zero-mean Gaussian samples (std)"

    std: float = setting(DEFAULT_RMS)

    def __check_init__(self):
        positive(self.std, "Input gaussian: std")

    @property
    def bound(self) -> float:
        return float(self.std) * math.sqrt(3.0)

    def __call__(self, key, n, dtype=None):
        return float(self.std) * jax.random.normal(key, (n,), dtype or jnp.result_type(float))

    def span(self, n):
        reach = float(self.std) * gaussian_reach(n)
        return -reach, reach
