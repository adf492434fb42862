"""The key-term iteration for the cascade with a general output backlash (issue 39).

`../shared/GENERAL_BACKLASH.md` derives it the way the 2016 paper derives its own
(METHOD.md, eqs. 15-28): with the switching variables `g1`, `g2` of the general
backlash (`_general_backlash.general_switches`) and the corrected output
`yc = y - (1 - g1)(1 - g2) y(t-1)`,

    yc = g1 x + cL g1 + mR g2 x - C g2
         + sum_{i=2..q} mL_i g1 (x + cL)^i + sum_{i=2..q} mR_i g2 (x - cR)^i

with `C = cR mR`. The key term `g1 x(t)` is replaced by the input and linear blocks
(`_regression.key_term_columns`, switched on by `g1`), `g2 x`, the powers
`(x + cL)^i`, `(x - cR)^i` and the switches are internal variables computed from the
previous estimate (v, x simulated with it), and one least-squares solve gives every
parameter: the cascade's theta (eq. 18) followed by `mL_2..q` and `mR_2..q`.

Like `Literal` it starts from the paper's initial values (`_literal.initial_guess`,
curvature 0) with the paper's first iteration (`_literal.first_iteration`: v ~ u,
x ~ y; with curvature 0 the general backlash's switches are the straight one's), then
repeats the step, and it stops by `Literal`'s rules (`_literal.stopping_rule`,
`_literal.cycle_detection`, the same settings and defaults). Statuses:

- `converged`: every element of theta moved by less than `se_tol` standard errors plus
  `tol (1 + |theta|)`, or the cost J settled, or the iterates circle within a few such
  tolerances (an oscillating approach);
- `cycled`: the iterates revisit an earlier one (period 2 to `cycle_period`) farther
  apart: the switching pattern cycles between neighbouring estimates (usable, as
  `Literal`'s);
- `singular`: the final step's regression was rank deficient (a regime never visited,
  columns dependent at the estimate): the data do not determine every parameter;
- `diverged`: an estimate became non-finite or larger than `divergence_bound`;
- `max_iterations`: none of these within `max_iterations` steps.

Noise-free, the truth is a fixed point (`tests/test_general_backlash.py`); the
iteration counts on the note's examples are in `results/general_backlash/keyterm.md`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._compile import filter_jit
from .._status import Status
from .._system._general_backlash import GeneralBacklash, general_switches
from .._system._model import CascadeParams, Orders
from .._system._simulate import linear_block, pwl, shift
from .._system._validate import record
from ._literal import (
    _RUNNING,
    cycle_detection,
    first_iteration,
    initial_guess,
    standard_errors,
    stopping_rule,
)
from ._regression import key_term_columns, solve_gram
from ._solution import PATH_ONLY, Solution, finite


class KeyTermGeneral(eqx.Module):
    """Output of `key_term_general`: the estimate (cascade and general backlash), a
    `Status` code, the steps taken (the first iteration counted), the last step's
    cost J (mean squared equation error) and the iterates (`history`: row 0 the paper's
    initial values, row k iteration k, in theta order then the curvature terms; the
    rows after `iterations` hold no iterate)."""

    params: CascadeParams
    backlash: GeneralBacklash
    status: Array
    iterations: Array
    cost: Float[Array, ""]
    history: Float[Array, "K P"]  # theta (then curveL, curveR) at iterations 0..K-1


def general_regression(params: CascadeParams, nd: GeneralBacklash, u, y):
    """`(phi, yc)` of one step from the estimate `(params, nd)`: v and x simulated with
    it, the general backlash's switches on the measured output's past (module
    docstring); columns in theta order, then the curvature columns."""
    v = pwl(params, u)
    x = linear_block(params, v)
    y_prev = shift(y, 1)
    g1, g2 = general_switches(nd, x, y_prev)
    yc = y - y_prev * (1 - g1) * (1 - g2)
    cL, cR = (jnp.asarray(c, u.dtype) for c in (nd.cL, nd.cR))
    powers = range(2, nd.degree + 1)
    curved = [g1 * (x + cL) ** i for i in powers] + [g2 * (x - cR) ** i for i in powers]
    rows = [key_term_columns(params, u, v, x) * g1[None, :], jnp.stack([g1, x * g2, -g2])]
    if curved:
        rows.append(jnp.stack(curved))
    return jnp.concatenate(rows, axis=0).T, yc


def _unpack(theta, orders: Orders, degree: int):
    size = orders.size
    params = CascadeParams.from_theta(theta[:size], orders, check=False)
    q1 = degree - 1
    nd = GeneralBacklash(
        params.cL, params.mR, params.cR, theta[size : size + q1], theta[size + q1 :]
    )
    return params, nd


def _theta(params: CascadeParams, nd: GeneralBacklash):
    return jnp.concatenate([params.to_theta(), nd.curveL, nd.curveR])


@filter_jit
def _iterate(u, y, orders: Orders, degree: int, max_iterations: int, settings):
    tol, se_tol, cost_tol, cycle_period, divergence_bound = settings
    dtype = u.dtype
    n = u.shape[0]
    init = initial_guess(orders, jnp.min(u), jnp.max(u), dtype)
    vector, singular, cost = first_iteration(init, u, y)
    params = CascadeParams.from_vector(vector, orders, check=False)
    nd = GeneralBacklash.straight(params, degree)
    theta = _theta(params, nd)
    history = (
        jnp.broadcast_to(theta, (max_iterations + 1, theta.shape[0]))
        .at[0]
        .set(_theta(init, GeneralBacklash.straight(init, degree)))
    )

    def usable(theta):
        return jnp.all(jnp.isfinite(theta)) & (jnp.max(jnp.abs(theta)) <= divergence_bound)

    def step(carry):
        theta, history, _, cost, k, _ = carry
        params, nd = _unpack(theta, orders, degree)
        phi, yc = general_regression(params, nd, u, y)
        new, singular, inverse = solve_gram(phi.T @ phi, phi.T @ yc)
        new_cost = jnp.mean((yc - phi @ new) ** 2)
        se = standard_errors(new_cost, inverse, n, new.shape[0])
        converged, tolerance = stopping_rule(new, theta, se, cost, new_cost, tol, se_tol, cost_tol)
        revisited, tight, _ = cycle_detection(new, history, k, tolerance, cycle_period)
        revisited = ~converged & revisited
        status = jnp.select(
            [~usable(new), converged | (revisited & tight), revisited],
            [Status.diverged, Status.converged, Status.cycled],
            jnp.where(k + 1 >= max_iterations, Status.max_iterations, _RUNNING),
        )
        history = history.at[k + 1].set(new)
        return new, history, singular, new_cost, k + 1, status

    # the first iteration is iteration 1: with `max_iterations` 1 it is the estimate
    running = jnp.where(max_iterations <= 1, Status.max_iterations, _RUNNING)
    status = jnp.where(usable(theta), running, Status.diverged)
    start = (theta, history, singular, cost, jnp.asarray(1), status)
    theta, history, singular, cost, k, status = jax.lax.while_loop(
        lambda carry: carry[-1] == _RUNNING, step, start
    )
    # judged on the final estimate: from a rank-deficient regression the data do not
    # determine every parameter
    status = jnp.where((status != Status.diverged) & singular, Status.singular, status)
    params, nd = _unpack(theta, orders, degree)
    return KeyTermGeneral(params, nd, status.astype(jnp.int32), k, cost, history)


def key_term_general(
    u,
    y,
    orders: Orders,
    degree: int,
    *,
    max_iterations: int = 200,
    tol: float = 1e-8,
    se_tol: float = 1e-3,
    cost_tol: float = 1e-12,
    cycle_period: int = 16,
    divergence_bound: float = 1e6,
) -> KeyTermGeneral:
    """The key-term iteration of the note (module docstring) on one record: the cascade
    of `orders` with a general backlash of `degree`, from the paper's initial values,
    with `Literal`'s stopping settings (`_literal.voros`). Never raises on a bad
    record's numbers: the status says what happened."""
    u, y = record(u, y, orders=orders, where="key_term_general")
    settings = (tol, se_tol, cost_tol, int(cycle_period), divergence_bound)
    return _iterate(u, y, orders, int(degree), int(max_iterations), settings)


def key_term_solution(u, y, orders: Orders, key=None, **settings) -> Solution:
    """The key-term iteration as the `literal` estimator's answer where `orders` have
    curved branches (`Orders.degree > 1`): a `Solution` of those orders (the estimate's
    vector is `to_vector`'s, theta's `C` turned back into `cR`; the history's rows after
    `iterations` repeat the estimate, as `voros`'s do). Traceable and `vmap`-able (the
    record is checked by the caller). `settings`: `voros`'s stopping settings
    `max_iterations`, `tol`, `se_tol`, `cost_tol`, `cycle_period`, `divergence_bound`;
    the iteration starts from the paper's initial values on the record's own range.
    `key` is not used (the iteration is deterministic)."""
    del key
    keys = ("tol", "se_tol", "cost_tol", "cycle_period", "divergence_bound")
    values = (settings[k] for k in keys)
    tol, se_tol, cost_tol, cycle_period, divergence_bound = values
    out = _iterate(
        u,
        y,
        orders.straight,
        orders.degree,
        int(settings["max_iterations"]),
        (tol, se_tol, cost_tol, int(cycle_period), divergence_bound),
    )
    theta = _theta(out.params, out.backlash)
    params = CascadeParams.from_theta(theta, orders, check=False)
    rows = jax.vmap(lambda t: CascadeParams.from_theta(t, orders, check=False).to_vector())
    history = rows(out.history)
    later = jnp.arange(history.shape[0])[:, None] > out.iterations
    history = jnp.where(later, params.to_vector()[None], history)
    solution = Solution(
        params=params,
        history=history,
        iterations=out.iterations.astype(jnp.int32),
        cost=out.cost,
        status=out.status,
        cycle_amplitude=jnp.zeros((), u.dtype),
        path=jnp.asarray(PATH_ONLY, jnp.int32),
    )
    return finite(solution, history[0])
