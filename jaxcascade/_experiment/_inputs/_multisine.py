"""A random-phase multisine: equal-amplitude cosines on the record's frequency grid.

`u(t) = g sum_k cos(2 pi k t / n + phi_k)` over lines `k` of the n-point DFT grid whose
frequency `2 k / n` (as a fraction of Nyquist) lies in `band`, each phase uniform in
`(0, 2 pi)` and drawn per record. On the grid the record's rms is exactly `sqrt(K / 2)`
per unit gain (K lines), so `rms` scaling is exact for every record; `amplitude`
scaling sets each record's peak instead, and its rms then follows the record's crest
factor `max|u| / rms(u)` (about 3.5 for hundreds of lines), which the Monte-Carlo
table reports per realisation (`input_crest`).
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ._base import DEFAULT_RMS, InputDesign, gaussian_reach, one_scale, setting


class Multisine(InputDesign):
    """Random-phase multisine on the DFT lines in `band = (low, high)` (fractions of
    Nyquist, default every line), `lines` of them evenly spread (0: all), scaled to
    `rms` (default the paper's input power) or to a peak `amplitude` per record."""

    name: ClassVar[str] = "multisine"
    summary: ClassVar[str] = "random-phase multisine on lines in a band (fractions of Nyquist)"

    band: tuple[float, float] = setting((0.0, 1.0))
    lines: int = setting(0)
    amplitude: float | None = setting(None)
    rms: float | None = setting(None)

    def __check_init__(self):
        one_scale("Input multisine", self.amplitude, self.rms)
        band = self.band
        if (
            not isinstance(band, tuple | list)
            or len(band) != 2
            or not all(isinstance(b, int | float) and not isinstance(b, bool) for b in band)
            or not 0.0 <= band[0] < band[1] <= 1.0
        ):
            raise ValueError(
                "Input multisine: band must be [low, high], fractions of Nyquist with "
                f"0 <= low < high <= 1, got {band!r}."
            )
        if isinstance(self.lines, bool) or not isinstance(self.lines, int) or self.lines < 0:
            raise ValueError(f"Input multisine: lines must be an integer >= 0, got {self.lines!r}.")

    def grid_lines(self, n: int) -> np.ndarray:
        """The DFT line numbers `k` used for a record of `n` samples."""
        k = np.arange(1, (n + 1) // 2)  # neither the mean nor the Nyquist line
        low, high = self.band
        k = k[(2.0 * k / n >= low) & (2.0 * k / n <= high)]
        if self.lines and k.size > self.lines:
            k = k[np.unique(np.round(np.linspace(0, k.size - 1, self.lines)).astype(int))]
        return k

    def check(self, n):
        if not self.grid_lines(n).size:
            raise ValueError(
                f"Input multisine: no line of a {n}-sample record lies in the band "
                f"{list(self.band)}; widen the band."
            )

    @property
    def _rms(self) -> float:
        return float(self.rms) if self.rms is not None else DEFAULT_RMS

    @property
    def bound(self) -> float:
        return float(self.amplitude) if self.amplitude is not None else self._rms * math.sqrt(3.0)

    def __call__(self, key, n, dtype=None):
        dtype = dtype or jnp.result_type(float)
        k = self.grid_lines(n)
        phases = jax.random.uniform(key, (k.size,), dtype, 0.0, 2.0 * jnp.pi)
        spectrum = jnp.zeros((n // 2 + 1,), jnp.result_type(dtype, jnp.complex64))
        spectrum = spectrum.at[k].set((n / 2.0) * jnp.exp(1j * phases))
        unit = jnp.fft.irfft(spectrum, n).astype(dtype) / math.sqrt(k.size / 2.0)
        if self.amplitude is not None:
            return float(self.amplitude) * unit / jnp.max(jnp.abs(unit))
        return self._rms * unit

    def settings(self):
        scale = (
            {"amplitude": float(self.amplitude)}
            if self.amplitude is not None
            else {"rms": self._rms}
        )
        return {"band": [float(b) for b in self.band], "lines": self.lines, **scale}

    def span(self, n):
        if self.amplitude is not None:
            return -self.bound, self.bound
        # many lines: nearly Gaussian samples; never beyond all lines in phase
        lines = max(int(self.grid_lines(n).size), 1)
        reach = self._rms * min(gaussian_reach(n), math.sqrt(2.0 * lines))
        return -reach, reach
