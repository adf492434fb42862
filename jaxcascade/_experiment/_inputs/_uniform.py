"""The paper's input: independent samples uniform in (-amplitude, amplitude)."""

from __future__ import annotations

import math
from typing import ClassVar

from ..._system._simulate import uniform_input
from ._base import InputDesign, one_scale, setting


class Uniform(InputDesign):
    """Independent uniform samples in `(-A, A)`; `A = amplitude`, or `rms sqrt(3)`,
    default 2 (the paper's). The estimators get the designed range `(-A, A)`."""

    name: ClassVar[str] = "uniform"
    summary: ClassVar[str] = "independent samples uniform in (-A, A) (the paper's, A = 2)"

    amplitude: float | None = setting(None)
    rms: float | None = setting(None)

    def __check_init__(self):
        one_scale("Input uniform", self.amplitude, self.rms)

    @property
    def bound(self) -> float:
        if self.amplitude is not None:
            return float(self.amplitude)
        return float(self.rms) * math.sqrt(3.0) if self.rms is not None else 2.0

    def __call__(self, key, n, dtype=None):
        return uniform_input(key, n, self.bound, dtype)

    def input_range(self, u):
        return -self.bound, self.bound

    def settings(self):
        return {"amplitude": self.bound}
