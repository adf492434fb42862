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

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._compile import filter_jit
from .._status import Status
from .._system._general_backlash import GeneralBacklash, branch_report, general_backlash
from .._system._model import CascadeParams
from .._system._simulate import linear_block, pwl
from .._system._validate import record
from ._refine import from_unconstrained, least_squares, to_unconstrained


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
    from ._robust import Robust

    u, y = record(u, y, orders=orders, where="robust_general")
    straight = Robust(**settings)(u, y, orders, key=key).params
    return refine_general(straight, GeneralBacklash.straight(straight, degree), u, y)
