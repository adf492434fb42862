"""Validation error of a free-run simulation, as in MATLAB's `compare`."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np


def nrmse(y_measured, y_simulated):
    """Root-mean-square simulation error divided by the standard deviation of the
    measured output. A correct model on data with white output noise at amplitude SNR
    `s` reaches about `1/s` (the noise floor), not zero. Works on numpy and jnp arrays.
    """
    return jnp.sqrt(jnp.mean((y_measured - y_simulated) ** 2)) / jnp.std(y_measured)


def fit_percent(error):
    """MATLAB's fit percentage, `100 (1 - NRMSE)`."""
    return 100.0 * (1.0 - error)


def score(y_measured, y_simulated) -> float:
    """`nrmse` as a host float, `inf` when it is not finite (an estimate that blows up in
    simulation is infinitely bad, never NaN): the one guard every report uses. Computed
    by NumPy in the arrays' own precision: on the host, eager `jax.numpy` would compile
    a program for every record length it sees (the model-error loop scores records of
    many lengths); the figure agrees with `nrmse`'s to rounding."""
    measured, simulated = np.asarray(y_measured), np.asarray(y_simulated)
    # a simulation that overflowed warns in NumPy: expected here, and answered with inf
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        error = float(np.sqrt(np.mean((measured - simulated) ** 2)) / np.std(measured))
    return error if math.isfinite(error) else math.inf
