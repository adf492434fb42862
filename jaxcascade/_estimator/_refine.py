"""Output-error refinement: least squares on the simulation error.

The simulation error `simulate(params, u) - y` is minimised over all parameters by
Levenberg-Marquardt: `refine` with this package's own (`_levenberg`, on the normal
equations that `_sensitivity` forms from forward sensitivities), `least_squares` with
optimistix's on any residual (the general backlash's single-record fits; the
model-error loop uses `_levenberg.least_squares`). Parameters are
mapped to an unconstrained vector `z` so that every iterate is admissible by
construction: breakpoints stay sorted inside the input range, `mR > 0`, gaps >= 0 and
the linear block stays stable (it is parameterised by its reflection coefficients). The
backlash makes the error piecewise smooth, which is why several starts are used.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Float

from .._status import Status
from .._system._model import CascadeParams, Orders, reflection_coefficients
from .._system._simulate import signals
from ._levenberg import levenberg_marquardt
from ._sensitivity import output_jacobian

_REFLECTION_LIMIT = 0.999


def _step_up(k):
    poly = jnp.ones((1,), k.dtype)
    for m in range(k.shape[0]):
        padded = jnp.concatenate([poly, jnp.zeros((1,), k.dtype)])
        poly = padded + k[m] * padded[::-1]
    return poly[1:]


def _breakpoints(z, bound):
    fractions = jax.nn.softmax(jnp.concatenate([z, jnp.zeros((1,), z.dtype)]))
    return bound * jnp.cumsum(fractions)[:-1]


def _breakpoints_inverse(D, bound):
    fractions = jnp.diff(jnp.concatenate([jnp.zeros((1,)), D / bound, jnp.ones((1,))]))
    fractions = jnp.clip(fractions, 1e-6, None)
    return jnp.log(fractions[:-1]) - jnp.log(fractions[-1])


def _softplus_inverse(c):
    c = jnp.clip(c, 1e-8, None)
    return c + jnp.log(-jnp.expm1(-c))


def from_unconstrained(z: Float[Array, " P"], orders: Orders, u_min, u_max) -> CascadeParams:
    """Map an unconstrained vector to admissible parameters (see module docstring)."""
    s = orders.slices
    b = _step_up(_REFLECTION_LIMIT * jnp.tanh(z[s["b"]])) if orders.p else z[s["b"]]
    vector = jnp.concatenate(
        [
            z[s["MR"]],
            _breakpoints(z[s["DR"]], u_max),
            z[s["ML"]],
            _breakpoints(z[s["DL"]], u_min),
            z[s["a"]],
            b,
            jax.nn.softplus(z[s["cL"]]),
            jnp.exp(z[s["mR"]]),
            jax.nn.softplus(z[s["cR"]]),
        ]
    )
    return CascadeParams.from_vector(vector, orders, check=False)


def to_unconstrained(params: CascadeParams, u_min, u_max) -> Float[Array, " P"]:
    """Inverse of `from_unconstrained`; values on or past a bound are pulled just inside."""
    o = params.orders
    dtype = params.mR.dtype
    k = reflection_coefficients(params.b) if o.p else params.b
    k = jnp.clip(k / _REFLECTION_LIMIT, -1 + 1e-6, 1 - 1e-6)
    z = jnp.concatenate(
        [
            params.MR,
            _breakpoints_inverse(params.DR, u_max).astype(dtype),
            params.ML,
            _breakpoints_inverse(params.DL, u_min).astype(dtype),
            params.a,
            jnp.arctanh(k),
            _softplus_inverse(params.cL)[None],
            jnp.log(jnp.clip(params.mR, 1e-8, None))[None],
            _softplus_inverse(params.cR)[None],
        ]
    )
    return jnp.where(jnp.isfinite(z), z, 0.0)


def simulation_error(params: CascadeParams, u, y) -> Float[Array, " T"]:
    return signals(params, u).y - y


class Refined(eqx.Module):
    """Output of `refine` (batched under `vmap`)."""

    params: CascadeParams
    cost: Float[Array, ""]  # mean squared simulation error
    status: Array
    steps: Array


def least_squares(residual, z0, args, *, max_steps: int = 100, rtol=1e-8, atol=1e-10):
    """Levenberg-Marquardt on `residual(z, args)` from `z0`, never raising.

    Terminates (optimistix's Cauchy test) after an accepted step that moves every
    element of `z` by less than `atol + rtol |z|` and every residual by less than
    `atol + rtol |residual|`.

    **Returns:** `(z, cost, status, steps)` with `cost` the mean squared residual
    (inf if non-finite) and `status` a `Status` code.
    """
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    solution = optx.least_squares(residual, solver, z0, args=args, max_steps=max_steps, throw=False)
    cost = jnp.mean(residual(solution.value, args) ** 2)
    finite = jnp.isfinite(cost) & jnp.all(jnp.isfinite(solution.value))
    result = solution.result
    # Linear-solver outcomes inside a step mean the Jacobian is numerically rank
    # deficient at the iterate (a parameter direction the record does not excite, or a
    # kink of the backlash): report them as `singular`, not as a generic failure.
    rank_deficient = (
        (result == optx.RESULTS.singular)
        | (result == optx.RESULTS.breakdown)
        | (result == optx.RESULTS.stagnation)
    )
    # `nonlinear_max_steps_reached` is the outer iteration running out of `max_steps`;
    # `max_steps_reached` would be an iterative linear solver's (none is used here).
    status = jnp.select(
        [
            ~finite
            | (result == optx.RESULTS.nonlinear_divergence)
            | (result == optx.RESULTS.nonfinite),
            result == optx.RESULTS.successful,
            (result == optx.RESULTS.nonlinear_max_steps_reached)
            | (result == optx.RESULTS.max_steps_reached),
            rank_deficient,
        ],
        [Status.diverged, Status.converged, Status.max_iterations, Status.singular],
        Status.failed,
    )
    z = jnp.where(finite, solution.value, z0)
    return (
        z,
        jnp.where(finite, cost, jnp.inf),
        status.astype(jnp.int32),
        solution.stats["num_steps"],
    )


def _breakpoints_jacobian(z, bound):
    # d/dz_k of bound * cumsum(softmax([z, 0]))[i]: bound s_k ([k <= i] - c_i)
    fractions = jax.nn.softmax(jnp.concatenate([z, jnp.zeros((1,), z.dtype)]))[:-1]
    cumulative = jnp.cumsum(fractions)
    lower = jnp.tril(jnp.ones((z.shape[0], z.shape[0]), z.dtype))
    return bound * fractions[None, :] * (lower - cumulative[:, None])


def _chain(z, orders: Orders, u_min, u_max):
    """`d from_unconstrained(z).to_vector() / dz`, written out: block diagonal, every
    block but the breakpoints' and the poles' diagonal. (`jax.jacfwd` of the map gives
    the same matrix; it pushes P tangents through the whole map at every call site of
    Levenberg-Marquardt, which costs compile time.)"""
    s = orders.slices
    dtype = z.dtype
    if orders.p:
        poles = jax.jacfwd(lambda k: _step_up(_REFLECTION_LIMIT * jnp.tanh(k)))(z[s["b"]])
    else:
        poles = jnp.zeros((0, 0), dtype)
    blocks = {
        "DR": _breakpoints_jacobian(z[s["DR"]], u_max),
        "DL": _breakpoints_jacobian(z[s["DL"]], u_min),
        "b": poles,
    }
    diagonal = jnp.ones_like(z)
    diagonal = diagonal.at[s["cL"]].set(jax.nn.sigmoid(z[s["cL"]]))
    diagonal = diagonal.at[s["mR"]].set(jnp.exp(z[s["mR"]]))
    diagonal = diagonal.at[s["cR"]].set(jax.nn.sigmoid(z[s["cR"]]))
    for name in blocks:
        diagonal = diagonal.at[s[name]].set(0.0)
    chain = jnp.diag(diagonal)
    for name, block in blocks.items():
        if block.size:
            chain = chain.at[s[name], s[name]].set(block.astype(dtype))
    return chain


def normal_equations(z, orders: Orders, u, y, u_min, u_max):
    """`(r, JtJ, Jtr)` of the simulation error at the unconstrained `z`: the Jacobian with
    respect to the parameters by forward sensitivities (`_sensitivity`), chained with
    the small Jacobian of `from_unconstrained` (`_chain`)."""

    params = from_unconstrained(z, orders, u_min, u_max)
    chain = _chain(z, orders, u_min, u_max)
    y_sim, J = output_jacobian(params, u)
    J = J @ chain
    r = y_sim - y
    return r, J.T @ J, J.T @ r


def refine(
    init: CascadeParams,
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    *,
    max_steps: int = 100,
    rtol: float = 1e-8,
    atol: float = 1e-10,
) -> Refined:
    """Levenberg-Marquardt (`_levenberg`) on the simulation error, from `init`, in the
    admissible parameterisation. Never raises."""
    orders = init.orders
    u_min, u_max = jnp.min(u), jnp.max(u)
    z0 = to_unconstrained(init.astype(u.dtype), u_min, u_max)
    z, cost, status, steps = levenberg_marquardt(
        lambda z: normal_equations(z, orders, u, y, u_min, u_max),
        z0,
        max_steps=max_steps,
        rtol=rtol,
        atol=atol,
        residual_size=u.shape[0],
    )
    return Refined(
        params=from_unconstrained(z, orders, u_min, u_max), cost=cost, status=status, steps=steps
    )
