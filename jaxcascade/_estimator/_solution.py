"""The result of one fit, whatever the estimator."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._model import CascadeParams
from .._status import Status

# `Solution.path`: which of an estimator's paths gave the estimate.
PATH_ONLY = 0  # the estimator has one path (the literal iteration)
PATH_ADAPTIVE = 1  # robust: the literal estimate, refined, passed the residual test
PATH_MULTISTART = 2  # robust: the multi-start fallback


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
