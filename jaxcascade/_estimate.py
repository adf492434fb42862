"""The paper's iterative least-squares estimator (Vörös 2016, eqs. 19-28)."""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ._model import CascadeParams, Orders, is_admissible
from ._normal_equations import (
    normal_equations,
    resolve,
    solve_first,
    solve_step,
    step_regression,
)
from ._regression import block_columns, solve_normal_equations
from ._status import Status

_RUNNING = -1


class Solution(eqx.Module):
    """Result of one fit. Under `vmap` every field gains a leading batch axis.

    - `params`: the estimate (the last accepted iterate; never NaN).
    - `history`: `Float[Array, "K+1 P"]`, iterate k in row k (row 0 = initial values) in
      `Orders.names` order; rows after `iterations` repeat the final estimate.
    - `iterations`: `Int[Array, ""]`, number of accepted least-squares steps.
    - `cost`: `Float[Array, ""]`, the regression cost J (eq. 28) of the last step.
    - `status`: `Int[Array, ""]`, a `Status` code.
    """

    params: CascadeParams
    history: Float[Array, "K P"]
    iterations: Int[Array, ""]
    cost: Float[Array, ""]
    status: Int[Array, ""]


def initial_guess(orders: Orders, u_min, u_max, dtype=None) -> CascadeParams:
    """The paper's initial values, generalised to any orders.

    Slopes and linear-block coefficients 0; breakpoints evenly spaced over the input
    range (`DR_i = i u_max / nR`, `DL_j = j u_min / nL`, which gives the paper's
    DR1 = 1.0, DL1 = -1.0 for nR = nL = 2 and |u| < 2); `mR = 0.5`, `cL = cR = 0.001`.
    """
    dtype = dtype or jnp.result_type(float)
    u_min, u_max = jnp.asarray(u_min, dtype), jnp.asarray(u_max, dtype)
    o = orders
    return CascadeParams(
        MR=jnp.zeros((o.nR,), dtype),
        DR=jnp.arange(1, o.nR, dtype=dtype) * u_max / o.nR,
        ML=jnp.zeros((o.nL,), dtype),
        DL=jnp.arange(1, o.nL, dtype=dtype) * u_min / o.nL,
        a=jnp.zeros((o.r - 1,), dtype),
        b=jnp.zeros((o.p,), dtype),
        cL=jnp.asarray(0.001, dtype),
        mR=jnp.asarray(0.5, dtype),
        cR=jnp.asarray(0.001, dtype),
        orders=o,
    )


def first_step(init: CascadeParams, u, y, backend: str = "xla"):
    """The paper's first iteration: v ~ u, x ~ y, backlash held at its initial values.

    Only the NS and LD parameters are estimated. The switching functions use unit
    slopes (the all-zero initial slopes would zero the breakpoint regressors), so the
    breakpoint coefficients estimate `D * M`; they are divided by the new slopes here.
    `backend` chooses how the normal equations are formed (`_normal_equations`).
    """
    o = init.orders
    ns_ld, bl = block_columns(o)
    if resolve(backend, o, u.dtype) == "fused":
        ne = normal_equations(init, u, y, first=True, backend="fused")
        coef, singular, cost = solve_first(ne, init, u.shape[0])
    else:
        reg = step_regression(init, u, y, first=True)
        target = reg.yc - reg.phi[:, bl] @ init.to_theta()[bl]
        coef, singular, cost = solve_normal_equations(reg.phi[:, ns_ld], target)
    vector = jnp.concatenate([coef, init.to_vector()[bl]])
    params = CascadeParams.from_vector(vector, o, check=False)
    params = eqx.tree_at(
        lambda p: (p.DR, p.DL),
        params,
        (_safe_divide(params.DR, params.MR[1:]), _safe_divide(params.DL, params.ML[1:])),
    )
    return params.to_vector(), singular, cost


def _safe_divide(num, den):
    # A zero slope increment leaves its breakpoint undefined: report it through a
    # non-finite value, which the caller turns into a status, not a NaN estimate.
    return jnp.where(den != 0, num / jnp.where(den != 0, den, 1.0), jnp.inf)


def voros_step(params: CascadeParams, u, y, backend: str = "xla"):
    """One iteration s -> s+1 (steps a and b of the paper): returns the new vector.

    `backend`: `"xla"` solves the regression from its materialised regressors (cost J
    from the residual); `"fused"` from the native kernel's normal equations (cost J
    from them, accurate to about `eps |yc|^2 / N`); `"auto"` picks (`_normal_equations`).
    """
    if resolve(backend, params.orders, u.dtype) == "fused":
        ne = normal_equations(params, u, y, backend="fused")
        theta, singular, cost = solve_step(ne, u.shape[0])
    else:
        reg = step_regression(params, u, y)
        theta, singular, cost = solve_normal_equations(
            reg.phi, reg.yc, blocks=params.orders.size - 2
        )
    new = CascadeParams.from_theta(theta, params.orders, check=False)
    return new.to_vector(), singular, cost


def _classify(new, singular, u_min, u_max, orders, bound):
    diverged = ~jnp.all(jnp.isfinite(new)) | (jnp.max(jnp.abs(new)) > bound)
    safe = jnp.where(jnp.isfinite(new), new, 0.0)
    admissible = is_admissible(CascadeParams.from_vector(safe, orders, check=False), u_min, u_max)
    return jnp.where(
        singular,
        Status.singular,
        jnp.where(diverged, Status.diverged, jnp.where(admissible, _RUNNING, Status.left_domain)),
    )


@functools.partial(jax.jit, static_argnames=("orders", "max_iterations", "backend"))
def voros(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    init: CascadeParams | None = None,
    *,
    max_iterations: int = 50,
    tol: float = 1e-10,
    divergence_bound: float = 1e6,
    backend: str = "auto",
) -> Solution:
    """The paper's iterative least-squares estimator, literally (eqs. 19-28).

    Step 1 is `first_step`; each later step rebuilds v, x, g1, g2 and yc from the current
    estimate and solves the full regression. Stops when
    `max|theta_{s+1} - theta_s| <= tol (1 + max|theta_s|)` (converged), after
    `max_iterations` steps, or when a step is singular, non-finite or larger than
    `divergence_bound` (diverged), or leaves the model's domain; the offending step is
    not accepted, so the returned estimate is the last admissible one.

    **Arguments:**

    - `u`, `y`: `Float[Array, " T"]` input and measured output of one record.
    - `orders`: static model orders.
    - `init`: initial values; default `initial_guess(orders, min(u), max(u))`.
    - `backend`: how each step's normal equations are formed: `"xla"` (materialised
      regressors), `"fused"` (the native CPU kernel, float64) or `"auto"` (fused where
      it applies); the same estimates up to rounding (`_normal_equations`).
    """
    dtype = u.dtype
    y = y.astype(dtype)
    u_min, u_max = jnp.min(u), jnp.max(u)
    if init is None:
        init = initial_guess(orders, u_min, u_max, dtype)
    init = init.astype(dtype)
    start = init.to_vector()
    classify = functools.partial(
        _classify, u_min=u_min, u_max=u_max, orders=orders, bound=divergence_bound
    )

    first, singular, cost = first_step(init, u, y, backend)
    status = classify(first, singular)
    accepted = status == _RUNNING
    vector = jnp.where(accepted, first, start)
    status = jnp.where(accepted & (max_iterations <= 1), Status.max_iterations, status)
    history = jnp.broadcast_to(start, (max_iterations + 1, orders.size))
    history = history.at[1].set(vector)
    carry = (jnp.asarray(1) * accepted, vector, history, status, cost)

    def running(carry):
        return carry[3] == _RUNNING

    def body(carry):
        k, vector, history, status, cost = carry
        new, singular, new_cost = voros_step(
            CascadeParams.from_vector(vector, orders, check=False), u, y, backend
        )
        new_status = classify(new, singular)
        accepted = new_status == _RUNNING
        change = jnp.max(jnp.abs(new - vector))
        converged = change <= tol * (1 + jnp.max(jnp.abs(vector)))
        new_status = jnp.where(accepted & converged, Status.converged, new_status)
        new_status = jnp.where(
            accepted & (new_status == _RUNNING) & (k + 1 >= max_iterations),
            Status.max_iterations,
            new_status,
        )
        k = jnp.where(accepted, k + 1, k)
        vector = jnp.where(accepted, new, vector)
        history = jnp.where(accepted, history.at[k].set(new), history)
        cost = jnp.where(accepted, new_cost, cost)
        return k, vector, history, new_status, cost

    k, vector, history, status, cost = jax.lax.while_loop(running, body, carry)
    rows = jnp.arange(max_iterations + 1)[:, None]
    history = jnp.where(rows > k, vector[None, :], history)
    return Solution(
        params=CascadeParams.from_vector(vector, orders, check=False),
        history=history,
        iterations=k,
        cost=cost,
        status=status.astype(jnp.int32),
    )
