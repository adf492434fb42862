"""Monte-Carlo tracking study of the recursive estimator on a system that changes.

Per realisation: a uniform input, the cascade simulated with parameters that step or
drift (`_changing`), output noise at the SNR (of the whole noise-free record, as
`_simulate.add_noise`), and one on-line pass of `recursive` keeping its estimate every
`every` samples. From the error trajectory `estimate - truth(t)`:

- `reentry`: samples after the change until every parameter is first back within
  `band` of the new truth (inf when it never is);
- `settled`: whether, from the re-entry on, every parameter stays within the band to the
  end of the record (a tracker that re-enters and wanders off again is not settled);
- `steady_rmse`: the root mean square error over the parameters and the recorded
  samples from the re-entry to the end (NaN without re-entry), and the same for the
  changed parameters alone (`steady_rmse_changed`);
- `before`: whether every parameter was within the band just before the change (a
  realisation that had not converged then says nothing about tracking).

All realisations run as one `vmap` (one `lax.scan` over time); the keys follow
`seed` (input and noise keys the halves of each realisation's key).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._estimator._recursive import recursive
from .._experiment._changing import Change, simulate_changing, trajectory
from .._system._model import CascadeParams
from .._system._simulate import uniform_input

# re-entry: every parameter back within this distance of the new truth
BAND = 0.05


def tracking_samples(n: int, every: int) -> np.ndarray:
    """The samples (1-based counts) after which `recursive` with `every` records its
    estimate on a record of `n` samples (the last row: the final estimate)."""
    return np.minimum(np.arange(1, -(-n // every) + 1) * every, n)


class Tracking(NamedTuple):
    """Result of `tracking` (NumPy arrays; R realisations, K recorded samples, P
    parameters in `Orders.names` order).

    - `samples`: `(K,)` the sample after which each row was recorded (1-based count).
    - `errors`: `(R, K, P)` estimate minus the true parameters at that sample.
    - `reentry`, `steady_rmse`, `steady_rmse_changed`: `(R,)` (module docstring).
    - `settled`, `before`: `(R,)` booleans.
    - `status`: `(R,)` the final `Status` codes.
    """

    samples: np.ndarray
    errors: np.ndarray
    reentry: np.ndarray
    settled: np.ndarray
    steady_rmse: np.ndarray
    steady_rmse_changed: np.ndarray
    before: np.ndarray
    status: np.ndarray


def tracking(
    truth: CascadeParams,
    change: Change,
    *,
    n: int,
    snr: float,
    realisations: int,
    seed: int = 0,
    every: int = 10,
    band: float = BAND,
    amplitude: float = 2.0,
    **settings,
) -> Tracking:
    """Run the study; `settings` go to `recursive` (e.g. `lam`)."""
    if not change.at < n:
        raise ValueError(f"tracking: the change at sample {change.at} is outside N = {n}.")
    o = truth.orders
    dtype = truth.to_vector().dtype
    truths = trajectory(truth, change, n)
    columns = [o.names.index(name) for name in change.parameters]
    bounds = (-amplitude, amplitude)

    def one(key):
        key_u, key_e = jax.random.split(key)
        u = uniform_input(key_u, n, amplitude, dtype)
        y = simulate_changing(truths, u, o)
        y = y + jnp.std(y) / snr * jax.random.normal(key_e, y.shape, dtype)
        solution = recursive(u, y, o, every=every, input_range=bounds, **settings).solution
        return solution.history[1:], solution.status

    keys = jax.random.split(jax.random.PRNGKey(seed), realisations)
    rows, status = jax.jit(jax.vmap(one))(keys)
    samples = tracking_samples(n, every)
    errors = np.asarray(rows) - np.asarray(truths)[samples - 1][None]
    return Tracking(
        samples, errors, *_measures(errors, samples, change.at, band, columns), np.asarray(status)
    )


def _measures(errors, samples, at, band, columns):
    """Per realisation (module docstring); `columns`: the changed parameters' indices."""
    inside = np.all(np.abs(errors) <= band, axis=2)  # (R, K)
    after = samples > at
    R = errors.shape[0]
    reentry = np.full(R, np.inf)
    settled = np.zeros(R, bool)
    steady = np.full(R, np.nan)
    steady_changed = np.full(R, np.nan)
    for r in range(R):
        hits = np.flatnonzero(inside[r] & after)
        if hits.size:
            k = hits[0]
            reentry[r] = samples[k] - at
            settled[r] = bool(np.all(inside[r, k:]))
            steady[r] = np.sqrt(np.mean(errors[r, k:] ** 2))
            steady_changed[r] = np.sqrt(np.mean(errors[r, k:][:, columns] ** 2))
    last_before = np.flatnonzero(samples <= at)
    before = inside[:, last_before[-1]] if last_before.size else np.zeros(R, bool)
    return reentry, settled, steady, steady_changed, before
