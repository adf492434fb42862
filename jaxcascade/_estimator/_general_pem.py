"""Prediction-error estimation of a cascade with a general output backlash (issue 39).

The general backlash's counterpart of `pem` (`_pem`): the cascade with curved branches
(`_general_backlash`) and an autoregressive noise model `e(t) = c1 e(t-1) + ... +
cq e(t-q) + w(t)`, fitted together by minimising the one-step-ahead prediction error

    w(t) = A(q) (y(t) - simulate_general(theta, u)(t)),   A(q) = 1 - c1 q^-1 - ... - cq q^-q,

(`_noise_filter.whiten`, from rest), which for Gaussian noise is maximum likelihood and
attains the coloured-noise Cramér-Rao bound (`_efficiency.crlb(..., backlash=,
poles=)`) where output error does not.

One record:

1. the start: an output-error fit with curved branches (`robust_general`, or the
   `start` given, e.g. the one a study has already computed);
2. the AR model of the start's simulation error, its order chosen by `criterion` among
   `0..order` (`_noise_filter.fit_ar`; `"none"`: `order` itself), on the host;
3. Levenberg-Marquardt (`_refine.least_squares`) on `w` over the cascade in its
   admissible parameterisation (`_refine.from_unconstrained`: the cascade stays
   admissible at every iterate), the curvature terms, and the AR coefficients through
   their reflection coefficients (`_noise_filter.ar_from_unconstrained`: the predictor
   stays stable), the chosen order held;
4. the status: Levenberg-Marquardt's, and `failed` where the fitted branches do not
   increase on the record's range of x (`_general_backlash.branch_report`), as
   `refine_general` reports it. With order 0 chosen, step 3 is `refine_general`'s
   output-error fit.

Never raises on a bad fit: the status says it.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._compile import filter_jit
from .._experiment._noise_filter import (
    CRITERIA,
    ar_from_unconstrained,
    ar_to_unconstrained,
    fit_ar,
    whiten,
)
from .._status import Status
from .._system._general_backlash import GeneralBacklash, branch_report
from .._system._model import CascadeParams, Orders
from .._system._validate import record
from ._general_refine import (
    GeneralRefined,
    _output,
    curved_solution,
    fit_traced,
    packed,
    rising,
    robust_general,
    unpack,
    with_curvature,
)
from ._refine import least_squares
from ._robust import DEFAULTS as ROBUST
from ._solution import Solution, finite


class GeneralPem(eqx.Module):
    """Output of `pem_general`: the cascade (its `cL`, `mR`, `cR` are the backlash's),
    the general backlash, the AR noise model `c` (its chosen order's coefficients), the
    mean squared prediction error `cost`, a `Status` code, the steps taken, and whether
    both fitted branches increase on the record's range of x."""

    params: CascadeParams
    backlash: GeneralBacklash
    c: Float[Array, " q"]
    cost: Float[Array, ""]
    status: Array
    steps: Array
    increasing: bool = eqx.field(static=True, default=True)


@filter_jit
def _core(init: CascadeParams, nd: GeneralBacklash, c0, u, y, max_steps: int, rtol, atol):
    orders, degree = init.orders, nd.degree
    head = orders.size + 2 * (degree - 1)
    z0 = jnp.concatenate([packed(init, nd, u), ar_to_unconstrained(jnp.asarray(c0, u.dtype))])

    def residual(z, args):
        params, curved = unpack(z, orders, degree, u)
        return whiten(_output(params, curved, u)[0] - y, ar_from_unconstrained(z[head:]))

    z, cost, status, steps = least_squares(
        residual, z0, None, max_steps=max_steps, rtol=rtol, atol=atol
    )
    params, curved = unpack(z, orders, degree, u)
    c = ar_from_unconstrained(z[head:])
    return params, curved, c, cost, status, steps, _output(params, curved, u)[1]


def pem_general(
    u,
    y,
    orders: Orders,
    degree: int,
    *,
    key=None,
    start: GeneralRefined | None = None,
    order: int = 4,
    criterion: str = "bic",
    max_steps: int = 200,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    **settings,
) -> GeneralPem:
    """Prediction-error estimate of the cascade with a general backlash of `degree` on
    the record `(u, y)` (module docstring).

    - `start`: an output-error fit with curved branches of this degree (`robust_general`
      or `refine_general`); by default `robust_general(u, y, orders, degree, key=key,
      **settings)`.
    - `order`, `criterion`: the AR noise model's largest order and how its order is
      chosen (`"bic"`, `"aic"` or `"none"`: `order` itself).
    - `max_steps`, `rtol`, `atol`: Levenberg-Marquardt's budget and stopping rule.
    """
    u, y = record(u, y, orders=orders, where="pem_general")
    if criterion not in CRITERIA:
        raise ValueError(
            f"pem_general: unknown order criterion {criterion!r}; known: {', '.join(CRITERIA)}."
        )
    if int(order) < 0:
        raise ValueError(f"pem_general: the noise model's order must be >= 0, got {order}.")
    if start is None:
        start = robust_general(u, y, orders, degree, key=key, **settings)
    elif settings:
        raise ValueError(f"pem_general: {sorted(settings)[0]!r} is a setting of the start's fit.")
    if start.backlash.degree != degree:
        raise ValueError(
            f"pem_general: the start has branches of degree {start.backlash.degree}, not {degree}."
        )
    residual = y - _output(start.params, start.backlash, u)[0]
    if not bool(jnp.all(jnp.isfinite(residual))):
        nan = jnp.asarray(jnp.nan, u.dtype)
        status = jnp.asarray(Status.failed, jnp.int32)
        empty = jnp.zeros((0,), u.dtype)
        return GeneralPem(start.params, start.backlash, empty, nan, status, 0, False)
    c, chosen = fit_ar(residual, int(order), criterion)
    c0 = np.asarray(c)[: int(chosen)]
    params, curved, c, cost, status, steps, x = _core(
        start.params, start.backlash, c0, u, y, int(max_steps), rtol, atol
    )
    report = branch_report(curved, np.asarray(x)) if np.isfinite(float(cost)) else None
    increasing = bool(
        report is not None and report["min_slope_left"] > 0 and report["min_slope_right"] > 0
    )
    if not increasing and int(status) == Status.converged:
        status = jnp.asarray(Status.failed, jnp.int32)
    return GeneralPem(params, curved, c, cost, status, steps, increasing)


def curved_pem_solution(
    u,
    y,
    orders: Orders,
    key=None,
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
):
    """The `pem` estimator's answer where `orders` have curved branches
    (`Orders.degree > 1`): `pem_general`'s method, traced and `vmap`-able (the record and
    the settings are checked by the caller). The output-error start is `robust`'s
    (`_general_refine.curved_solution`, with `pem`'s `threshold`, `n_starts`,
    `fallback_batch`, `retries`); the AR model's order is chosen on its residual
    (`fit_ar`, up to `order`), its coefficients beyond that order held at zero; then
    Levenberg-Marquardt (`fit_traced`) on the one-step-ahead prediction error over the
    cascade, the curvature and the AR model. A failed start stays a failure; a converged fit whose
    branches do not rise on the fitted range of x is `failed` (`rising`). The history's
    rows: the start's straight estimate, the start, the estimate."""
    dtype = u.dtype
    robust_settings = dict(
        ROBUST, threshold=threshold, n_starts=n_starts, fallback_batch=fallback_batch
    )
    start = curved_solution(u, y, orders, key, **dict(robust_settings, retries=retries))
    straight = CascadeParams.from_vector(
        start.params.to_vector()[: orders.straight_size], orders.straight, check=False
    )
    nd = GeneralBacklash.unchecked(
        straight.cL, straight.mR, straight.cR, start.params.curveL, start.params.curveR
    )
    c0, chosen = fit_ar(y - _output(straight, nd, u)[0], order, criterion)
    active = jnp.arange(order) < chosen  # coefficients beyond the order stay zero
    head = orders.size
    z0 = jnp.concatenate([packed(straight, nd, u), ar_to_unconstrained(c0)])
    z0 = z0.at[head:].set(jnp.where(active, z0[head:], 0.0))

    def noise(z):
        return ar_from_unconstrained(jnp.where(active, z[head:], 0.0))

    def residual(z):
        params, curved = unpack(z, orders.straight, orders.degree, u)
        return whiten(_output(params, curved, u)[0] - y, noise(z))

    z, cost, status, steps = fit_traced(residual, z0, max_steps, rtol, atol)
    params, curved = unpack(z, orders.straight, orders.degree, u)
    x = _output(params, curved, u)[1]
    status = jnp.where((status == Status.converged) & ~rising(curved, x), Status.failed, status)
    usable = (start.status == Status.converged) | (start.status == Status.cycled)
    status = jnp.where(usable, status, start.status).astype(jnp.int32)
    estimate = with_curvature(params, curved, orders)
    history = jnp.stack([start.history[0], start.params.to_vector(), estimate.to_vector()])
    solution = Solution(
        params=estimate,
        history=history,
        iterations=(start.iterations + steps).astype(jnp.int32),
        cost=cost,
        status=status,
        cycle_amplitude=jnp.zeros((), dtype),
        path=start.path,
    )
    return finite(solution, start.params.to_vector())
