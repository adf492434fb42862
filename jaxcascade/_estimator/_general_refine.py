"""Output-error refinement of a cascade with a general output backlash (issue 39).

Levenberg-Marquardt (`_refine.least_squares`, optimistix's) on the simulation error of
the cascade NS -> LD -> ND with curved branches (`_general_backlash`), over the cascade's
parameters in the admissible parameterisation of `_refine` (sorted breakpoints inside
the input range, a stable linear block, `mR > 0`, gaps >= 0) and the branches'
curvature terms, which are unconstrained. It is the refinement step of an output-error
estimator: it starts from an estimate (typically the straight backlash's, curvature 0)
and converges to the nearest minimum; `robust_general` starts it from the robust
estimator's straight fit. Whether the fitted branches increase on the
record's range is not enforced during the iteration; `refine_general` reports it
(`GeneralRefined.increasing`, `_general_backlash.branch_report`) and a fit whose branches
turn is not `converged`.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._compile import filter_jit
from .._status import Status
from .._system._general_backlash import GeneralBacklash, branch_report, general_backlash
from .._system._model import CascadeParams
from .._system._simulate import linear_block, pwl
from .._system._validate import record
from ._levenberg import levenberg_marquardt
from ._refine import from_unconstrained, least_squares, to_unconstrained
from ._robust import Robust, _robust
from ._solution import Solution, finite


class GeneralRefined(eqx.Module):
    """Output of `refine_general`: the cascade (its `cL`, `mR`, `cR` are the backlash's),
    the general backlash, the mean squared simulation error, a `Status` code, the steps
    taken, and whether both fitted branches increase on the record's range of x."""

    params: CascadeParams
    backlash: GeneralBacklash
    cost: Float[Array, ""]
    status: Array
    steps: Array
    increasing: bool = eqx.field(static=True, default=True)


def _output(params: CascadeParams, nd: GeneralBacklash, u):
    x = linear_block(params, pwl(params, u))
    return general_backlash(nd, x), x


def packed(init: CascadeParams, nd: GeneralBacklash, u) -> Array:
    """The unconstrained vector of a cascade with a general backlash on the input `u`'s
    range: the cascade's (`_refine.to_unconstrained`), then `curveL` and `curveR`."""
    u_min, u_max = jnp.min(u), jnp.max(u)
    return jnp.concatenate(
        [
            to_unconstrained(init.astype(u.dtype), u_min, u_max),
            jnp.asarray(nd.curveL, u.dtype),
            jnp.asarray(nd.curveR, u.dtype),
        ]
    )


def unpack(z, orders, degree: int, u):
    """`(params, backlash)` of the first `orders.size + 2 (degree - 1)` elements of the
    unconstrained vector `z` (`packed`'s inverse)."""
    size, q1 = orders.size, degree - 1
    params = from_unconstrained(z[:size], orders, jnp.min(u), jnp.max(u))
    curved = GeneralBacklash(
        params.cL, params.mR, params.cR, z[size : size + q1], z[size + q1 : size + 2 * q1]
    )
    return params, curved


@filter_jit
def _refine(init: CascadeParams, nd: GeneralBacklash, u, y, max_steps: int, rtol, atol):
    orders, degree = init.orders, nd.degree
    z0 = packed(init, nd, u)

    def unpack_(z):
        return unpack(z, orders, degree, u)

    def residual(z, args):
        params, curved = unpack_(z)
        return _output(params, curved, u)[0] - y

    z, cost, status, steps = least_squares(
        residual, z0, None, max_steps=max_steps, rtol=rtol, atol=atol
    )
    params, curved = unpack_(z)
    return params, curved, cost, status, steps, _output(params, curved, u)[1]


def refine_general(
    init: CascadeParams,
    backlash: GeneralBacklash,
    u,
    y,
    *,
    max_steps: int = 200,
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> GeneralRefined:
    """Refine the cascade `init` with the general backlash `backlash` (its degree is
    kept; `GeneralBacklash.straight(init, degree)` starts from straight branches) on the
    record `(u, y)` by output-error least squares. Never raises on a bad fit: the status
    says it (`diverged`, `max_iterations`, `singular`, or `failed` where the fitted
    branches do not increase on the record's range of x)."""
    u, y = record(u, y, where="refine_general")
    params, curved, cost, status, steps, x = _refine(
        init, backlash, u, y, int(max_steps), rtol, atol
    )
    report = branch_report(curved, np.asarray(x)) if np.isfinite(float(cost)) else None
    increasing = bool(
        report is not None and report["min_slope_left"] > 0 and report["min_slope_right"] > 0
    )
    if not increasing and int(status) == Status.converged:
        status = jnp.asarray(Status.failed, jnp.int32)
    return GeneralRefined(params, curved, cost, status, steps, increasing)


def robust_general(u, y, orders, degree: int, *, key=None, **settings) -> GeneralRefined:
    """An output-error estimate of the cascade with a general backlash of `degree`: the
    robust estimator's straight-backlash fit (`Robust`, with `settings`), then
    `refine_general` from it with straight branches (curvature 0), the paper's initial
    values for the curvature."""
    u, y = record(u, y, orders=orders, where="robust_general")
    straight = Robust(**settings)(u, y, orders, key=key).params
    return refine_general(straight, GeneralBacklash.straight(straight, degree), u, y)


# Points of the record's range of x at which a traced fit's branches are checked to rise
# (`curved_solution`; `branch_report` also finds the slopes' minima between grid points).
_SLOPE_POINTS = 401


def fit_traced(residual, z0, max_steps: int, rtol, atol):
    """Levenberg-Marquardt on `residual(z)` from `z0` for the traced estimators of curved
    branches: the package's own (`_levenberg`, on normal equations; the Jacobian by
    forward differentiation, `jax.jacfwd`), which needs no LAPACK call. (Optimistix's,
    which the single-record functions use, solves each step by a QR factorisation; in
    the batched robust program of `general2` XLA's CPU compiler could not find that
    LAPACK kernel.) Returns `(z, cost, status, steps)` as `levenberg_marquardt`."""

    def evaluate(z):
        J, r = jax.jacfwd(lambda v: (residual(v), residual(v)), has_aux=True)(z)
        return r, J.T @ J, J.T @ r

    size = jax.eval_shape(residual, z0).shape[0]
    return levenberg_marquardt(
        evaluate, z0, max_steps=max_steps, rtol=rtol, atol=atol, residual_size=size
    )


def with_curvature(cascade: CascadeParams, nd: GeneralBacklash, orders) -> CascadeParams:
    """`cascade` (straight orders, its `cL`, `mR`, `cR` the block's) with `nd`'s
    curvature, as parameters of `orders` (`Orders.degree > 1`). Traceable."""
    vector = jnp.concatenate([cascade.to_vector(), nd.curveL, nd.curveR])
    return CascadeParams.from_vector(vector.astype(cascade.mR.dtype), orders, check=False)


def _error(z, *, orders, u, y):
    """The simulation error of the unconstrained vector `z` (`packed`) for `orders`."""
    params, curved = unpack(z, orders.straight, orders.degree, u)
    return _output(params, curved, u)[0] - y


def rising(nd: GeneralBacklash, x) -> Array:
    """Whether both branches of `nd` rise on `[min x, max x]`, checked on `_SLOPE_POINTS`
    evenly spaced values (traceable: `branch_report` is its exact host form)."""
    grid = jnp.linspace(jnp.min(x), jnp.max(x), _SLOPE_POINTS)
    slopes = jax.vmap(jax.jacfwd(lambda s: jnp.stack(nd.branches(s))))(grid)
    return jnp.all(slopes > 0)


def curved_solution(u, y, orders, key=None, *, steps=200, rtol=1e-10, atol=1e-12, **settings):
    """The `robust` estimator's answer where `orders` have curved branches
    (`Orders.degree > 1`): its straight-backlash fit (`_robust._robust` on
    `orders.straight`, with `settings`), then Levenberg-Marquardt with the branches'
    curvature from zero (`refine_general`'s fit). Traceable and `vmap`-able (the record
    is checked by the caller; Levenberg-Marquardt is `fit_traced`'s); the status is the
    curved fit's, `failed` where it converged to branches that do not rise on the fitted
    range of x (`rising`). The history's rows: the straight estimate (no curvature), the
    curved one."""
    straight = _robust(u, y, orders.straight, key, **settings)
    start = GeneralBacklash.straight(straight.params, orders.degree)
    residual = functools.partial(_error, orders=orders, u=u, y=y)
    z0 = packed(straight.params, start, u)
    z, cost, status, fit_steps = fit_traced(residual, z0, steps, rtol, atol)
    params, curved = unpack(z, orders.straight, orders.degree, u)
    x = _output(params, curved, u)[1]
    status = jnp.where(
        (status == Status.converged) & ~rising(curved, x), Status.failed, status
    ).astype(jnp.int32)

    estimate = with_curvature(params, curved, orders)
    first = with_curvature(straight.params, start, orders)
    history = jnp.stack([first.to_vector(), estimate.to_vector()])
    solution = Solution(
        params=estimate,
        history=history,
        iterations=(straight.iterations + fit_steps).astype(jnp.int32),
        cost=cost,
        status=status,
        cycle_amplitude=jnp.zeros((), u.dtype),
        path=straight.path,
    )
    return finite(solution, history[0])
