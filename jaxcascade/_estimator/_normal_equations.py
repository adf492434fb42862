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

from .._system._model import CascadeParams
from .._system._simulate import linear_block, pwl
from . import _fused
from ._regression import Regression, regression, solve_gram

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
    breakpoint columns (`_estimator._literal.first_iteration`).
    """
    o = params.orders
    dtype = u.dtype
    if resolve(backend, o, dtype) == "xla":
        return from_regression(step_regression(params, u, y, first=first), o)
    k = o.g1_columns
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


def from_regression(reg: Regression, orders) -> NormalEquations:
    """The normal equations of materialised regressors (the `"xla"` implementation)."""
    k = orders.g1_columns
    one, two = reg.phi[:, :k], reg.phi[:, k:]
    return NormalEquations(
        one.T @ one, one.T @ reg.yc, two.T @ two, two.T @ reg.yc, reg.yc @ reg.yc
    )


def cost(ne: NormalEquations, theta: Float[Array, " P"], n: int) -> Float[Array, ""]:
    """The regression cost J = mean((yc - phi theta)^2) (eq. 28), from the normal
    equations: `(yc^T yc - 2 theta^T phi^T yc + theta^T phi^T phi theta) / n`, clipped at
    0 (its rounding error is about `eps yc^T yc / n`, not relative to J)."""
    k = ne.gram1.shape[0]
    t1, t2 = theta[:k], theta[k:]
    total = ne.ycc - 2 * (t1 @ ne.rhs1 + t2 @ ne.rhs2) + t1 @ ne.gram1 @ t1 + t2 @ ne.gram2 @ t2
    return jnp.maximum(total, 0.0) / n


def solve_step(ne: NormalEquations, n: int):
    """`(theta, singular, cost, inverse_diagonal)` of a full step: both blocks solved
    (`solve_gram`); `inverse_diagonal` is the diagonal of `(phi^T phi)^-1`."""
    theta1, singular1, inverse1 = solve_gram(ne.gram1, ne.rhs1)
    theta2, singular2, inverse2 = solve_gram(ne.gram2, ne.rhs2)
    theta = jnp.concatenate([theta1, theta2])
    inverse = jnp.concatenate([inverse1, inverse2])
    return theta, singular1 | singular2, cost(ne, theta, n), inverse


FIRST_STEPS = ("full", "fixed", "drop")


def solve_first(ne: NormalEquations, init: CascadeParams, n: int, reading: str = "full"):
    """`(coefficients, singular, cost)` of the paper's first step: the NS and LD
    coefficients, under one of three readings of the paper's text (`_estimate.voros`):

    - `"full"`: the whole regression (eq. 27) is solved; only its NS and LD estimates
      are kept (the backlash keeps its initial values);
    - `"fixed"`: the backlash columns are held at `init` and moved to the right-hand side;
    - `"drop"`: the backlash columns are left out.

    `cost` is J (eq. 28) of the regression that was solved (`"drop"`: with the backlash
    coefficients zero)."""
    if reading not in FIRST_STEPS:
        raise ValueError(
            f"Unknown first-step reading {reading!r}; known: {', '.join(FIRST_STEPS)}."
        )
    o = init.orders
    backlash = o.backlash
    m = o.static_dynamic.stop  # NS and LD columns; column m of block 1 is the cL column
    if reading == "full":
        theta1, singular, _ = solve_gram(ne.gram1, ne.rhs1)
        theta2, _, _ = solve_gram(ne.gram2, ne.rhs2)
        # only block 1 (NS, LD, cL) feeds the kept estimates; a singular block 2 (no
        # g2 = 1 with the initial backlash) is no reason to stop
        return theta1[:m], singular, cost(ne, jnp.concatenate([theta1, theta2]), n)
    if reading == "fixed":
        held = init.to_theta()[backlash].astype(ne.rhs1.dtype)
        rhs = ne.rhs1[:m] - held[0] * ne.gram1[:m, m]
        coefficients, singular, _ = solve_gram(ne.gram1[:m, :m], rhs)
        theta = jnp.concatenate([coefficients, held])
        return coefficients, singular, cost(ne, theta, n)
    coefficients, singular, _ = solve_gram(ne.gram1[:m, :m], ne.rhs1[:m])
    theta = jnp.concatenate([coefficients, jnp.zeros((3,), coefficients.dtype)])
    return coefficients, singular, cost(ne, theta, n)
