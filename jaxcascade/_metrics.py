"""Validation error of a free-run simulation, as in MATLAB's `compare`."""

from __future__ import annotations

import jax.numpy as jnp


def nrmse(y_measured, y_simulated):
    """Root-mean-square simulation error divided by the standard deviation of the
    measured output. A correct model on data with white output noise at amplitude SNR
    `s` reaches about `1/s` (the noise floor), not zero. Works on numpy and jnp arrays.
    """
    return jnp.sqrt(jnp.mean((y_measured - y_simulated) ** 2)) / jnp.std(y_measured)


def fit_percent(error):
    """MATLAB's fit percentage, `100 (1 - NRMSE)`."""
    return 100.0 * (1.0 - error)
