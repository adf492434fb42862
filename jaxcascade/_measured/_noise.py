"""The output noise model of the model-error loop: autoregressive noise."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


class ARNoise(eqx.Module):
    """Autoregressive output noise `e(t) = w(t) + c1 e(t-1) + ... + cq e(t-q)`, `w` white.

    It changes no simulated output: it explains a coloured residual that the input
    cannot, and whitens the residual the tests see (`innovations`). Order 0 is white
    noise (`white`). `fit` chooses the order by BIC up to `max_order`.
    """

    name: ClassVar[str] = "colored_noise"
    signature: ClassVar[tuple[str, ...]] = ("autocorrelation", "spectrum")
    description: ClassVar[str] = (
        "autoregressive output noise e(t) = w(t) + c1 e(t-1) + ... + cq e(t-q)"
    )
    max_order: ClassVar[int] = 4

    coefficients: Float[Array, " q"]

    @classmethod
    def white(cls, dtype=None) -> ARNoise:
        return cls(jnp.zeros((0,), dtype or jnp.result_type(float)))

    @property
    def order(self) -> int:
        return int(self.coefficients.shape[-1])

    def innovations(self, residual):
        """`w(t) = e(t) - sum_i c_i e(t-i)` (the residual itself for white noise)."""
        out = residual
        for i in range(1, self.order + 1):
            past = jnp.concatenate([jnp.zeros((i,), residual.dtype), residual[:-i]])
            out = out - self.coefficients[i - 1] * past
        return out

    @classmethod
    def fit(cls, residual, max_order: int | None = None) -> tuple[ARNoise, float]:
        """AR coefficients by least squares with the order chosen by BIC, and the p-value
        of the likelihood-ratio test against white noise (host side)."""
        return cls.fit_records([residual], max_order)

    @classmethod
    def fit_records(cls, residuals, max_order: int | None = None) -> tuple[ARNoise, float]:
        """`fit` on several records at once: one set of coefficients, each record's
        regression built from its own samples only (no lag crosses a record's start)."""
        import scipy.stats

        max_order = cls.max_order if max_order is None else max_order
        records = [np.asarray(e, dtype=float) for e in residuals]
        n = sum(e.size for e in records)
        power = sum(float(e @ e) for e in records) / n
        best = (n * np.log(power), np.zeros(0), power)
        for q in range(1, max_order + 1):
            usable = [e for e in records if e.size > q]
            X = np.concatenate(
                [np.stack([e[q - i : e.size - i] for i in range(1, q + 1)], 1) for e in usable]
            )
            target = np.concatenate([e[q:] for e in usable])
            c, *_ = np.linalg.lstsq(X, target, rcond=None)
            variance = np.mean((target - X @ c) ** 2)
            bic = n * np.log(variance) + q * np.log(n)
            if bic < best[0]:
                best = (bic, c, variance)
        noise = cls(jnp.asarray(best[1]))
        if noise.order == 0:
            return noise, 1.0
        statistic = n * np.log(power / best[2])
        return noise, float(scipy.stats.chi2.sf(statistic, noise.order))
