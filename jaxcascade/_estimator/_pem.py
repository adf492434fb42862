"""Prediction-error estimation: the cascade with an autoregressive noise model.

Output-error least squares (`robust`) is consistent under coloured output noise (the
noise is independent of the input) but not efficient: it weighs every sample alike
although neighbouring noise samples are correlated. The prediction-error method fits
the cascade and a noise model `e(t) = c1 e(t-1) + ... + cq e(t-q) + w(t)` together by
minimising the one-step-ahead prediction error

    w(t) = A(q) (y(t) - simulate(theta, u)(t)),   A(q) = 1 - c1 q^-1 - ... - cq q^-q,

(`_noise_filter.whiten`, from rest), which for Gaussian noise is maximum likelihood
(Ljung, "System identification", 1999, ch. 7; the Box-Jenkins structure with an AR
noise model). It attains the Cramér-Rao bound of coloured noise (`_efficiency.crlb`
with the noise filter) where output error does not.

One record:

1. the start: `robust`'s two paths, with its basin test applied to the *whitened*
   simulation error (an AR model of order <= `order`, chosen by `criterion`, fitted to
   the residual and removed): under coloured noise the raw residual of a fit in the
   true basin is not white, so `robust`'s own test would send every record to the
   multi-start. Its multi-start (`retries` repeats from fresh draws) runs only for the
   records whose literal-then-refined fit fails that test;
2. the AR model of the start's residual (order chosen by `criterion` among
   `0..order`, or `order` itself with `criterion = "none"`);
3. Levenberg-Marquardt (`_levenberg`) on `w` over the cascade (its admissible
   parameterisation, `_refine.from_unconstrained`) and the AR coefficients (their
   reflection coefficients, so the predictor stays stable) together, the order held:
   coefficients beyond it stay zero. The Jacobian is the output's (`_sensitivity`)
   filtered by `A(q)`, and `-e(t-i)` for `c_i`;
4. the status the data allow (`_basin.claim`): `local_minimum` where the prediction
   error `w` fails Billings and Voon's correlation tests (its whiteness alone can be
   bought by the AR model: noise-free, one random-family estimate 0.31 from the truth
   passed the whitened basin test of step 1), `on_edge` for a breakpoint on the edge
   of the input's range.

`Solution.cost` is the mean squared prediction error `mean w^2`; `history` holds the
start's start, the start and the estimate; `path` the start's path. The noise model
itself is `pem_noise`'s.
"""

from __future__ import annotations

import functools
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from .._compile import jit
from .._experiment._noise_filter import (
    CRITERIA,
    ar_from_unconstrained,
    ar_to_unconstrained,
    fit_ar,
    lagged,
    whiten,
)
from .._status import Status
from .._system._model import Orders, is_admissible
from .._system._validate import record
from ._base import Estimator, curved_form, keyword_defaults, setting
from ._basin import claim, off_edge, residual_statistic
from ._levenberg import levenberg_marquardt
from ._refine import _chain, from_unconstrained, simulation_error, to_unconstrained
from ._robust import DEFAULTS as ROBUST
from ._robust import _adaptive, _fallback, _multistart, judge
from ._sensitivity import output_jacobian
from ._solution import Solution, finite


class PemFit(eqx.Module):
    """What `pem_fit` returns: the `Solution` and the AR noise model (`c`, padded with
    zeros to the setting `order`; `noise_order` the order chosen)."""

    solution: Solution
    c: Float[Array, " q"]
    noise_order: Array


def pem(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    key: PRNGKeyArray | None = None,
    *,
    order: int = 4,
    criterion: str = "bic",
    max_steps: int = 50,
    rtol: float = 1e-6,
    atol: float = 1e-9,
    threshold: float = 5.0,
    n_starts: int = 16,
    fallback_batch: int = 8,
    retries: int = 0,
) -> Solution:
    """Prediction-error estimate of one record (module docstring).

    - `order`: the AR noise model's largest order (`criterion` "aic" or "bic" chooses
      among `0..order`; "none" fixes it at `order`).
    - `max_steps`: Levenberg-Marquardt's budget on the prediction error.
    - `rtol`, `atol`, `threshold`, `n_starts`, `fallback_batch`, `retries`: those of
      `robust`'s start (its basin test on the whitened residual).
    """
    return pem_fit(
        u,
        y,
        orders,
        key,
        order=order,
        criterion=criterion,
        max_steps=max_steps,
        rtol=rtol,
        atol=atol,
        threshold=threshold,
        n_starts=n_starts,
        fallback_batch=fallback_batch,
        retries=retries,
    ).solution


DEFAULTS = keyword_defaults(pem)


def pem_fit(u, y, orders: Orders, key=None, **settings) -> PemFit:
    """`pem`, with the fitted noise model (`PemFit`); the settings are `pem`'s."""
    u, y = record(u, y, orders=orders, where="pem")
    unknown = sorted(set(settings) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"pem: unknown setting {unknown[0]!r}.")
    settings = {**DEFAULTS, **settings}
    _check(settings)
    settings["threshold"] = float(settings["threshold"])
    return _core(u, y, orders, key, **settings)


def _check(settings) -> None:
    for name, lowest in (("order", 0), ("max_steps", 1), ("n_starts", 1), ("retries", 0)):
        value = settings[name]
        if isinstance(value, bool) or not isinstance(value, int) or value < lowest:
            raise ValueError(f"pem: {name} must be an integer >= {lowest}, got {value!r}.")
    if settings["criterion"] not in CRITERIA:
        raise ValueError(
            f"pem: criterion must be one of {', '.join(CRITERIA)}, got {settings['criterion']!r}."
        )


def _whitened_statistic(params, u, y, order, criterion):
    residual = simulation_error(params, u, y)
    c, _ = fit_ar(residual, order, criterion)
    return residual_statistic(whiten(residual, c), u)


def _in_basin(params, status, cost, u, y, bound, order, criterion):
    """`robust`'s basin test on the whitened simulation error (module docstring), and
    no breakpoint on the domain's edge (`_basin.EDGE`): the AR model can absorb a wrong basin's
    model error into a white enough residual (measured on Example 2, AR(1) noise with
    pole 0.9: one fit in 100 with a breakpoint at 0 passed the whitened test)."""
    statistic = _whitened_statistic(params, u, y, order, criterion)
    exact = cost <= 1e-20 * jnp.var(y)
    u_min, u_max = jnp.min(u), jnp.max(u)
    admissible = is_admissible(params, u_min, u_max) & off_edge(params, u_min, u_max)
    return (status == Status.converged) & ((statistic <= bound) | exact) & admissible


def _tested(u, y, key, stage, *, threshold, order, criterion, **settings):
    solution = _multistart(u, y, key, stage, **settings)
    passed = _in_basin(
        solution.params, solution.status, solution.cost, u, y, threshold, order, criterion
    )
    return solution, passed


@jit(static_argnames=("orders", *DEFAULTS))
def _core(
    u,
    y,
    orders,
    key,
    *,
    order,
    criterion,
    max_steps,
    rtol,
    atol,
    threshold,
    n_starts,
    fallback_batch,
    retries,
) -> PemFit:
    dtype = u.dtype
    y = y.astype(dtype)
    key = jax.random.PRNGKey(0) if key is None else key
    stage = _adaptive(
        u, y, orders, rtol=rtol, atol=atol, steps=ROBUST["adaptive_steps"], bound=threshold
    )
    fitted = stage.solution
    accepted = _in_basin(
        fitted.params, fitted.status, fitted.cost, u, y, threshold, order, criterion
    )
    stage = eqx.tree_at(lambda s: s.accepted, stage, accepted)
    multistart = functools.partial(
        _tested,
        orders=orders,
        threshold=threshold,
        order=order,
        criterion=criterion,
        n_starts=n_starts,
        n_refine=ROBUST["n_refine"],
        subset=ROBUST["subset"],
        max_steps=ROBUST["max_steps"],
        literal_start=True,
        rtol=rtol,
        atol=atol,
    )
    start = _fallback(multistart, fallback_batch, retries)(u, y, key, stage)
    return _refine(start, u, y, orders, order, criterion, max_steps, rtol, atol, threshold)


def _refine(
    start: Solution, u, y, orders, order, criterion, max_steps, rtol, atol, threshold
) -> PemFit:
    """Steps 2-4 (module docstring) from the start's estimate."""
    dtype = u.dtype
    u_min, u_max = jnp.min(u), jnp.max(u)
    c0, chosen = fit_ar(simulation_error(start.params, u, y), order, criterion)
    active = jnp.arange(order) < chosen  # coefficients beyond the order stay zero
    P = len(orders.names)
    z0 = jnp.concatenate([to_unconstrained(start.params, u_min, u_max), ar_to_unconstrained(c0)])
    z0 = z0.at[P:].set(jnp.where(active, z0[P:], 0.0))
    free = jnp.concatenate([jnp.ones((P,), bool), active])

    def evaluate(z):
        zk = jnp.where(active, z[P:], 0.0)
        params = from_unconstrained(z[:P], orders, u_min, u_max)
        y_sim, J = output_jacobian(params, u)
        e = y_sim - y
        c = ar_from_unconstrained(zk)
        w = whiten(e, c)
        J_theta = whiten(J @ _chain(z[:P], orders, u_min, u_max), c)
        # w = e - sum c_i e(t-i): dw/dc_i = -e(t-i), chained to the reflection parameters
        J_noise = -lagged(e, order) @ jax.jacfwd(ar_from_unconstrained)(zk)
        J_all = jnp.concatenate([J_theta, jnp.where(active, J_noise, 0.0)], axis=1)
        # a fixed coefficient's direction is empty: a unit diagonal keeps its step at 0
        JtJ = J_all.T @ J_all + jnp.diag((~free).astype(dtype))
        return w, JtJ, J_all.T @ w

    z, cost, status, steps = levenberg_marquardt(
        evaluate, z0, max_steps=max_steps, rtol=rtol, atol=atol, residual_size=u.shape[0]
    )
    params = from_unconstrained(z[:P], orders, u_min, u_max)
    c = ar_from_unconstrained(jnp.where(active, z[P:], 0.0))
    before, after = start.params.to_vector(), params.to_vector()
    oe_cost = jnp.mean(simulation_error(params, u, y) ** 2)
    status = judge(status, oe_cost, y, before, after, True, rtol)
    # a failed start stays a failure: refining a wrong basin's estimate does not save it
    status = jnp.where(_usable(start.status), status, start.status)
    inside = is_admissible(params, u_min, u_max)
    status = jnp.where(inside | ~_usable(status), status, Status.left_domain)
    # the data's word on it: its prediction error against the validity tests (`claim`)
    e = simulation_error(params, u, y)
    status = claim(status, params, e, u, y, threshold, prewhitened=whiten(e, c))
    solution = Solution(
        params=params,
        history=jnp.stack([start.history[0], before, after]),
        iterations=(start.iterations + steps).astype(jnp.int32),
        cost=cost,
        status=status.astype(jnp.int32),
        cycle_amplitude=jnp.zeros((), dtype),
        path=start.path,
    )
    return PemFit(finite(solution, before), c, chosen)


def _usable(status):
    return (status == Status.converged) | (status == Status.cycled)


class Pem(Estimator):
    """The cascade with an AR noise model by prediction error (`pem`, module docstring);
    the settings are `pem`'s keyword arguments. For orders with curved backlash branches
    (`Orders.degree > 1`), `pem_general`'s method (`_general_pem.curved_pem_solution`)."""

    name: ClassVar[str] = "pem"
    summary: ClassVar[str] = (
        "prediction error with an AR noise model (order by BIC), from the robust estimate"
    )

    order: int = setting(DEFAULTS["order"])
    criterion: str = setting(DEFAULTS["criterion"])
    max_steps: int = setting(DEFAULTS["max_steps"])
    rtol: float = setting(DEFAULTS["rtol"])
    atol: float = setting(DEFAULTS["atol"])
    threshold: float = setting(DEFAULTS["threshold"])
    n_starts: int = setting(DEFAULTS["n_starts"])
    fallback_batch: int = setting(DEFAULTS["fallback_batch"])
    retries: int = setting(DEFAULTS["retries"])

    def __check_init__(self):  # equinox runs `Estimator.__check_init__` (types) first
        _check({name: getattr(self, name) for name in DEFAULTS})

    def __call__(
        self,
        u: Float[Array, " T"],
        y: Float[Array, " T"],
        orders: Orders,
        *,
        key: PRNGKeyArray | None = None,
        input_range: tuple[float, float] | None = None,
    ) -> Solution:
        del input_range  # the starts are scaled to the record's own range
        u, y = record(u, y, orders=orders, where="Pem", curved=True)
        settings = {name: getattr(self, name) for name in DEFAULTS}
        if orders.degree > 1:
            # curved branches: `pem_general`'s method, traced (`_general_pem`)
            return curved_form(self.name)(u, y, orders, key, **settings)
        return pem(u, y, orders, key, **settings)
