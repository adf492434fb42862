"""Robust estimation: multi-start output-error least squares, batched over starts.

The paper's iteration is a fixed-point map without a convergence guarantee; the
simulation-error landscape is friendlier (METHOD.md). This estimator

1. draws `n_starts` initial values from the random-system prior (`_prior.py`, with the
   breakpoints scaled to the record's input range) and adds the literal iteration's
   result as one more start;
2. refines every start with Levenberg-Marquardt on the simulation error of the first
   `subset` samples (`vmap` over starts);
3. keeps the `n_refine` best by simulation error on the whole record and refines them
   on the whole record;
4. restarts the refinement once from the best and keeps the lower cost, with its
   status, except that the fit counts as converged when the restart moved neither the
   estimate nor the cost by more than `rtol` (relative): at a minimum on a kink of the
   piecewise-smooth error, Levenberg-Marquardt can creep until its step budget runs out
   without going anywhere.

Tolerances. Levenberg-Marquardt stops after an accepted step that moves every
(unconstrained) parameter by less than `atol + rtol |z|` and every residual sample by
less than `atol + rtol |residual|`. The defaults, `rtol = 1e-6` and `atol = 1e-9`, are
those of MATLAB's `lsqnonlin` (StepTolerance and FunctionTolerance 1e-6) and lie three
orders of magnitude below the statistical precision of the estimates (standard
deviations >= 1e-3 at SNR 50). The tighter `refine` defaults (1e-8, 1e-10) ask for more
than a piecewise-smooth cost can give: with the backlash's switching instants moving
under every step, the trust region crept on at an estimate already at the noise floor
until `max_steps` (optimistix's `nonlinear_max_steps_reached`; every robust "failure"
of the first issue-4 comparison, at NRMSE on the noise floor). Refitted with these
tolerances, such a record converged and the other estimates of its batch moved by
less than 1e-8. Some records still creep; on those measured, the restart of step 4
moved the estimate by at most 2e-10 (relative) and the cost by at most 4e-12, far
inside `rtol`, so step 4 tells them from a start that is still going somewhere.

Every iterate is admissible by construction (`_refine.from_unconstrained`), so the
result is never NaN; a start that fails is simply outranked.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from .._estimate import Solution, initial_guess, voros
from .._model import CascadeParams, Orders
from .._prior import random_system
from .._refine import refine, simulation_error
from .._status import Status


def _best(costs, k):
    costs = jnp.where(jnp.isfinite(costs), costs, jnp.inf)
    return jnp.argsort(costs)[:k]


def _take(tree, index):
    return jax.tree_util.tree_map(lambda leaf: leaf[index], tree)


@functools.partial(
    jax.jit,
    static_argnames=(
        "orders",
        "n_starts",
        "n_refine",
        "subset",
        "max_steps",
        "literal_start",
        "rtol",
        "atol",
    ),
)
def robust(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    key: PRNGKeyArray | None = None,
    *,
    n_starts: int = 16,
    n_refine: int = 3,
    subset: int = 1000,
    max_steps: tuple[int, int] = (60, 150),
    literal_start: bool = True,
    rtol: float = 1e-6,
    atol: float = 1e-9,
) -> Solution:
    """Multi-start output-error estimate of one record (see module docstring).

    **Arguments:**

    - `u`, `y`: `Float[Array, " T"]` input and measured output.
    - `orders`: static model orders.
    - `key`: PRNG key for the starts; a fixed default keeps the estimator deterministic.
    - `rtol`, `atol`: Levenberg-Marquardt's termination tolerances (module docstring).

    **Returns:** a `Solution` whose `history` has three rows (chosen start, after the
    subset stage, final), `iterations` the Levenberg-Marquardt steps of the chosen
    start over both stages, and `cost` the mean squared simulation error.
    """
    dtype = u.dtype
    y = y.astype(dtype)
    tolerances = {"rtol": rtol, "atol": atol}
    key = jax.random.PRNGKey(0) if key is None else key
    u_max = 0.5 * (jnp.max(u) - jnp.min(u))
    starts = jax.vmap(lambda k: random_system(k, orders, 1.0, dtype))(
        jax.random.split(key, n_starts)
    )
    starts = CascadeParams.from_vector(
        starts.to_vector().at[:, _breakpoint_columns(orders)].multiply(u_max), orders, check=False
    )
    if literal_start:
        init = initial_guess(orders, jnp.min(u), jnp.max(u), dtype)
        literal = voros(u, y, orders, init, max_iterations=30).params.to_vector()
        starts = CascadeParams.from_vector(
            jnp.concatenate([starts.to_vector(), literal[None]]), orders, check=False
        )

    n = min(subset, u.shape[0])
    first = jax.vmap(lambda p: refine(p, u[:n], y[:n], max_steps=max_steps[0], **tolerances))(
        starts
    )
    full_cost = jax.vmap(lambda p: jnp.mean(simulation_error(p, u, y) ** 2))(first.params)
    chosen = _best(full_cost, n_refine)
    second = jax.vmap(lambda p: refine(p, u, y, max_steps=max_steps[1], **tolerances))(
        _take(first.params, chosen)
    )
    best = _best(second.cost, 1)[0]
    final = _take(second, best)
    # The backlash makes the simulation error piecewise smooth: Levenberg-Marquardt can
    # creep along kinks at a point that is in fact the minimum, until its step budget
    # runs out. One restart from the chosen estimate tells the two apart: at a minimum
    # it terminates within a few steps, or it creeps without moving the estimate or the
    # cost by more than `rtol` (relative), the criterion of MATLAB's lsqnonlin
    # (StepTolerance, FunctionTolerance), which then counts as converged.
    restart = refine(final.params, u, y, max_steps=max_steps[1], **tolerances)
    before, after = final.params.to_vector(), restart.params.to_vector()
    moved = jnp.max(jnp.abs(after - before) / (1 + jnp.abs(before)))
    settled = (moved <= rtol) & (jnp.abs(restart.cost - final.cost) <= rtol * final.cost)
    final = jax.tree_util.tree_map(
        lambda again, first: jnp.where(restart.cost <= final.cost, again, first), restart, final
    )
    status = jnp.where(settled, Status.converged, final.status)
    final = eqx.tree_at(lambda r: (r.steps, r.status), final, (final.steps + restart.steps, status))
    history = jnp.stack(
        [
            starts.to_vector()[chosen[best]],
            first.params.to_vector()[chosen[best]],
            final.params.to_vector(),
        ]
    )
    return Solution(
        params=final.params,
        history=history,
        iterations=(first.steps[chosen[best]] + final.steps).astype(jnp.int32),
        cost=final.cost,
        status=final.status,
    )


def _breakpoint_columns(orders: Orders):
    names = orders.names
    return jnp.array([i for i, name in enumerate(names) if name[:2] in ("DR", "DL")], int)
