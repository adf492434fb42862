"""Is an output-error fit in the true basin? A residual test that needs no noise level.

In the true basin the simulation error of a correct model is the measurement noise:
white, and uncorrelated with the input. In a wrong basin it carries model error, a
nonlinear function of the input's past shaped by the linear block and the backlash's
dead zone: coloured, and correlated with the input. The statistic is the larger of two
normalised portmanteau statistics over `lags` lags,

    S = (N sum_k rho_k^2 - lags) / sqrt(2 lags),

the Ljung-Box form for the residual's autocorrelation (lags 1..lags) and for its cross-
correlation with the input (lags 0..lags-1, `u` white in every experiment here): each
is about standard normal for a white residual independent of `u`. A fit is accepted
(`robust`'s adaptive path) when `S <= threshold`. Traceable.
"""

from __future__ import annotations

import jax.numpy as jnp


def _correlations(a, b, lags, first):
    a = a - jnp.mean(a)
    b = b - jnp.mean(b)
    n = a.shape[0]
    scale = jnp.sqrt(jnp.sum(a * a) * jnp.sum(b * b))
    values = jnp.stack([jnp.sum(a[k:] * b[: n - k]) for k in range(first, first + lags)])
    return values / jnp.where(scale > 0, scale, 1.0)


def residual_statistic(residual, u, lags: int = 10):
    """`max(S_auto, S_cross)` (module docstring) of a residual and its input record."""
    n = residual.shape[0]
    auto = _correlations(residual, residual, lags, 1)
    cross = _correlations(residual, u, lags, 0)

    def normalised(rho):
        return (n * jnp.sum(rho**2) - lags) / jnp.sqrt(2.0 * lags)

    statistic = jnp.maximum(normalised(auto), normalised(cross))
    return jnp.where(jnp.isfinite(statistic), statistic, jnp.inf)
