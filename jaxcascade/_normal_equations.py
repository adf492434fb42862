"""Normal equations of one step of the Vörös iteration, and their solution (eq. 28).

The least-squares problem of a step, `argmin |yc - phi theta|^2`, is reduced to its
normal equations. The regressor columns fall into two blocks with disjoint supports in
time (the NS, LD and cL columns carry g1, the mR and C columns carry g2, and g1 g2 = 0),
so `phi^T phi` is block diagonal:

- `gram1`, `rhs1`: block 1, `Float[Array, "P-2 P-2"]` and `Float[Array, " P-2"]`;
- `gram2`, `rhs2`: block 2, `Float[Array, "2 2"]` and `Float[Array, " 2"]`;
- `ycc`: `yc^T yc`, so that the cost of any theta follows without the regressors.

Two implementations give the same numbers up to rounding:

- `"xla"`: from the materialised regressors of `_regression.regression`, traced by JAX
  (any dtype, any device);
- `"fused"`: the native kernel of `_fused` (float64 on a CPU), one pass over time that
  never stores the regressors, batched over records under `vmap`.

`"auto"` picks `"fused"` where it applies and `"xla"` elsewhere.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import _fused
from ._model import CascadeParams
from ._regression import Regression, block_columns, regression, solve_gram
from ._simulate import linear_block, pwl

BACKENDS = ("auto", "xla", "fused")


class NormalEquations(NamedTuple):
    gram1: Array
    rhs1: Array
    gram2: Array
    rhs2: Array
    ycc: Array


def resolve(backend: str, orders, dtype) -> str:
    """The implementation `backend` stands for, for these orders and dtype."""
    if backend not in BACKENDS:
        raise ValueError(f"Unknown backend {backend!r}; known: {', '.join(BACKENDS)}.")
    if backend == "auto":
        return "fused" if _fused.supports(orders, dtype) else "xla"
    if backend == "fused" and not _fused.supports(orders, dtype):
        why = _fused.reason() or "it needs float64 on a CPU and orders within its limits"
        raise ValueError(f"The fused kernel cannot run here: {why}.")
    return backend


def step_regression(params: CascadeParams, u, y, *, first: bool = False) -> Regression:
    """The materialised regression of a step: v and x simulated from `params`, or, with
    `first`, the paper's first iteration (v ~ u, x ~ y, unit slopes)."""
    if first:
        return regression(params, u, y, u, y, unit_slopes=True)
    v = pwl(params, u)
    return regression(params, u, y, v, linear_block(params, v))


def normal_equations(
    params: CascadeParams,
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    *,
    first: bool = False,
    backend: str = "auto",
) -> NormalEquations:
    """Normal equations of the step from `params` (module docstring).

    With `first`, the paper's first iteration: v ~ u, x ~ y and unit slopes in the
    breakpoint columns (`_estimate.first_step`).
    """
    o = params.orders
    dtype = u.dtype
    if resolve(backend, o, dtype) == "xla":
        reg = step_regression(params, u, y, first=first)
        one, two = reg.phi[:, : o.size - 2], reg.phi[:, o.size - 2 :]
        return NormalEquations(
            one.T @ one, one.T @ reg.yc, two.T @ two, two.T @ reg.yc, reg.yc @ reg.yc
        )
    k = o.size - 2
    shapes = (
        jax.ShapeDtypeStruct((k, k), dtype),
        jax.ShapeDtypeStruct((k,), dtype),
        jax.ShapeDtypeStruct((2, 2), dtype),
        jax.ShapeDtypeStruct((2,), dtype),
        jax.ShapeDtypeStruct((), dtype),
    )
    call = jax.ffi.ffi_call(_fused.TARGET, shapes, vmap_method="broadcast_all")
    out = call(
        u,
        y.astype(dtype),
        params.to_vector().astype(dtype),
        nR=np.int64(o.nR),
        nL=np.int64(o.nL),
        r=np.int64(o.r),
        p=np.int64(o.p),
        first=np.int64(first),
    )
    return NormalEquations(*out)


def cost(ne: NormalEquations, theta: Float[Array, " P"], n: int) -> Float[Array, ""]:
    """The regression cost J = mean((yc - phi theta)^2) (eq. 28), from the normal
    equations: `(yc^T yc - 2 theta^T phi^T yc + theta^T phi^T phi theta) / n`, clipped at
    0 (its rounding error is about `eps yc^T yc / n`, not relative to J)."""
    k = ne.gram1.shape[0]
    t1, t2 = theta[:k], theta[k:]
    total = ne.ycc - 2 * (t1 @ ne.rhs1 + t2 @ ne.rhs2) + t1 @ ne.gram1 @ t1 + t2 @ ne.gram2 @ t2
    return jnp.maximum(total, 0.0) / n


def solve_step(ne: NormalEquations, n: int):
    """`(theta, singular, cost)` of a full step: both blocks solved (`solve_gram`)."""
    theta1, singular1 = solve_gram(ne.gram1, ne.rhs1)
    theta2, singular2 = solve_gram(ne.gram2, ne.rhs2)
    theta = jnp.concatenate([theta1, theta2])
    return theta, singular1 | singular2, cost(ne, theta, n)


def solve_first(ne: NormalEquations, init: CascadeParams, n: int):
    """`(coefficients, singular, cost)` of the first step: only the NS and LD columns, the
    backlash columns held at `init` and moved to the right-hand side."""
    o = init.orders
    _, backlash = block_columns(o)
    m = o.size - 3  # NS and LD columns; column m of block 1 is the cL column
    held = init.to_theta()[backlash].astype(ne.rhs1.dtype)
    rhs = ne.rhs1[:m] - held[0] * ne.gram1[:m, m]
    coefficients, singular = solve_gram(ne.gram1[:m, :m], rhs)
    theta = jnp.concatenate([coefficients, held])
    return coefficients, singular, cost(ne, theta, n)
