"""The result of one fit, whatever the estimator, and a batch of them as a table."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._status import Status, status_names
from .._system._model import CascadeParams

# `Solution.path`: which of an estimator's paths gave the estimate.
PATH_ONLY = 0  # the estimator has one path (the literal iteration)
PATH_ADAPTIVE = 1  # robust: the literal estimate, refined, passed the residual test
PATH_MULTISTART = 2  # robust: the multi-start fallback
PATH_NAMES = ("only", "adaptive", "multistart")


class Solution(eqx.Module):
    """Result of one fit. Under `vmap` every field gains a leading batch axis.

    - `params`: the estimate (never NaN or inf: `finite`).
    - `history`: `Float[Array, "K P"]`, iterates in `Orders.names` order, row 0 the
      start; what the rows are is the estimator's (the literal iteration: every iterate,
      rows after `iterations` repeating the estimate; robust: its stages).
    - `iterations`: `Int[Array, ""]`, steps taken (least-squares or Levenberg-Marquardt).
    - `cost`: `Float[Array, ""]`, the estimator's final cost (the literal iteration: J of
      eq. 28; output-error estimators: the mean squared simulation error).
    - `status`: `Int[Array, ""]`, a `Status` code.
    - `cycle_amplitude`: `Float[Array, ""]`, with status `cycled` the largest spread of
      one parameter over the cycle's iterates (the literal iteration); 0 otherwise.
    - `path`: `Int[Array, ""]`, which path gave the estimate: `PATH_ONLY` (0) for an
      estimator with one path; robust: `PATH_ADAPTIVE` (1) or `PATH_MULTISTART` (2).
    """

    params: CascadeParams
    history: Float[Array, "K P"]
    iterations: Int[Array, ""]
    cost: Float[Array, ""]
    status: Int[Array, ""]
    cycle_amplitude: Float[Array, ""]
    path: Int[Array, ""]

    def to_frame(self):
        """A pandas DataFrame, one row per record: `solution_table(self)`."""
        return solution_table(self)


def solution_table(solution):
    """A `Solution` of any batch shape (after `jax.vmap`, nested too, or none) as a pandas
    DataFrame with one row per record: the estimate by parameter name, `status` (the
    name), `iterations`, `cost`, `cycle_amplitude` and `path` (`only`, `adaptive` or
    `multistart`). The index is the record's position in the batch: `record` for one
    batch axis, levels `axis0`, `axis1`, ... for nested batches, a single row 0 for an
    unbatched solution. A `CascadeParams` (of any batch shape) gives the estimate columns
    alone. Host side: call it outside `jit`.
    """
    import pandas as pd

    params = solution.params if isinstance(solution, Solution) else solution
    if not isinstance(params, CascadeParams):
        raise TypeError(
            f"solution_table takes a Solution or CascadeParams, not {type(solution).__name__}."
        )
    vector = np.asarray(jax.device_get(params.to_vector()), dtype=float)
    batch = vector.shape[:-1]
    columns = dict(zip(params.names, vector.reshape(-1, vector.shape[-1]).T, strict=True))
    if isinstance(solution, Solution):
        fields = jax.device_get(solution)

        def flat(values):
            return np.broadcast_to(np.asarray(values), batch).reshape(-1)

        codes = flat(fields.status)
        paths = flat(fields.path)
        names = np.array([*PATH_NAMES, "unknown"], dtype=object)
        columns |= {
            "status": status_names(codes),
            "iterations": flat(fields.iterations).astype(int),
            "cost": flat(fields.cost).astype(float),
            "cycle_amplitude": flat(fields.cycle_amplitude).astype(float),
            "path": names[np.where((paths >= 0) & (paths < len(PATH_NAMES)), paths, -1)],
        }
    if len(batch) == 0:
        index = pd.RangeIndex(1)
    elif len(batch) == 1:
        index = pd.RangeIndex(batch[0], name="record")
    else:
        index = pd.MultiIndex.from_product(
            [range(size) for size in batch], names=[f"axis{k}" for k in range(len(batch))]
        )
    return pd.DataFrame(columns, index=index)


def finite(solution: Solution, fallback: Float[Array, " P"]) -> Solution:
    """`solution` with no non-finite number left in it: the contract of every estimator.

    Bad data that reaches an estimator inside `jit` or `vmap` (NaN or inf in a record,
    which only the eager checks of `_validate` refuse) makes its estimate non-finite. The
    estimate then falls back to the finite entries of `fallback` (the start; zeros where
    it too is non-finite), the history likewise, a non-finite cost becomes inf, and a
    status that says the estimate is usable becomes `diverged` (a failure status stays:
    it already says why). Traceable.
    """
    vector = solution.params.to_vector()
    ok = jnp.all(jnp.isfinite(vector)) & jnp.all(jnp.isfinite(solution.history))
    safe = jnp.where(jnp.isfinite(fallback), fallback, 0.0).astype(vector.dtype)
    vector = jnp.where(ok, vector, safe)
    history = jnp.where(ok, solution.history, jnp.broadcast_to(safe, solution.history.shape))
    usable = (solution.status == Status.converged) | (solution.status == Status.cycled)
    status = jnp.where(~ok & usable, Status.diverged, solution.status).astype(jnp.int32)
    cost = jnp.where(jnp.isnan(solution.cost), jnp.inf, solution.cost)
    return Solution(
        params=CascadeParams.from_vector(vector, solution.params.orders, check=False),
        history=history,
        iterations=solution.iterations,
        cost=cost,
        status=status,
        cycle_amplitude=jnp.where(
            jnp.isfinite(solution.cycle_amplitude), solution.cycle_amplitude, 0.0
        ),
        path=solution.path,
    )
