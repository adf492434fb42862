"""Heavy-tailed white noise: Student's t with `dof` degrees of freedom, unit variance."""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from ._base import Disturbance, number, setting


class StudentT(Disturbance):
    """Independent Student-t samples scaled to unit variance (`t * sqrt((dof - 2) / dof)`).

    `dof > 2`: with fewer degrees of freedom the variance is infinite and the SNR
    `sqrt(var(y) / var(e))` has no meaning. `dof = 3` has a kurtosis of infinity, 5 of 9
    (Gaussian: 3).
    """

    name: ClassVar[str] = "student_t"
    summary: ClassVar[str] = "white Student-t noise (dof > 2 degrees of freedom)"

    dof: float = setting(3.0)

    def __check_init__(self):
        number(self.dof, "Noise student_t: dof", low=2.0, low_open=True, high=1e6)

    def __call__(self, key, n, dtype=None):
        dtype = dtype or jnp.result_type(float)
        dof = float(self.dof)
        return math.sqrt((dof - 2.0) / dof) * jax.random.t(key, dof, (n,), dtype)
