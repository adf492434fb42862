"""Key-term separated regression of the cascade (Vörös 2016, eqs. 15-18 and 23-25)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .. import _linalg
from .._system._model import CascadeParams
from .._system._simulate import backlash_switches, general_switches, heaviside, shift


class Regression(NamedTuple):
    """Data of one least-squares step: `yc = phi @ theta + e` (eq. 16).

    - `phi`: `Float[Array, "T P"]`, regressors in theta order (eq. 17).
    - `yc`: `Float[Array, " T"]`, the corrected output (eq. 25).
    - `g1`, `g2`: `Float[Array, " T"]`, the switching variables used (eqs. 23-24).
    """

    phi: Array
    yc: Array
    g1: Array
    g2: Array


def regression(
    params: CascadeParams,
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    v: Float[Array, " T"],
    x: Float[Array, " T"],
    *,
    unit_slopes: bool = False,
) -> Regression:
    """Regressors and corrected output for the current estimates.

    **Arguments:**

    - `params`: the s-th estimates; they set the breakpoints and slopes inside the
      switching functions f1, f2 (eqs. 19-20) and the backlash parameters in g1, g2.
    - `u`, `y`: measured input and output (`y` may be noisy: it enters g1, g2 and yc).
    - `v`, `x`: estimates of the internal signals (eqs. 21-22), or `u`, `y` in the
      paper's first iteration.
    - `unit_slopes`: use M = 1 inside f1, f2. With the paper's all-zero initial slopes
      the breakpoint regressors `-f` vanish identically; with unit slopes the breakpoint
      column's coefficient is `D * M` instead of `D` (`_estimator._literal`).

    At branch degree `q > 1` (`Orders.degree`) the switches are the general backlash's
    and the curvature's columns follow (the recursive estimator's regressor).
    """
    dtype = u.dtype
    y_prev = shift(y, 1)
    degree = params.orders.degree
    if degree > 1:  # curved branches: the general backlash's switches
        g1, g2 = general_switches(params, x, y_prev)
    else:
        g1, g2 = backlash_switches(
            x, y_prev, params.cL.astype(dtype), params.mR.astype(dtype), params.cR.astype(dtype)
        )
    yc = y - y_prev * (1 - g1) * (1 - g2)
    ns_ld = key_term_columns(params, u, v, x, unit_slopes=unit_slopes) * g1[None, :]
    rows = [ns_ld, jnp.stack([g1, x * g2, -g2])]
    if degree > 1:
        # the curvature's columns `g1 (x + cL)^i`, `g2 (x - cR)^i`, i = 2..q
        # (`_general_keyterm.general_regression`), after the straight ones, as in theta
        cL, cR = params.cL.astype(dtype), params.cR.astype(dtype)
        powers = range(2, degree + 1)
        rows.append(
            jnp.stack([g1 * (x + cL) ** i for i in powers] + [g2 * (x - cR) ** i for i in powers])
        )
    phi = jnp.concatenate(rows, axis=0).T
    return Regression(phi, yc, g1, g2)


def key_term_columns(params: CascadeParams, u, v, x, *, unit_slopes: bool = False) -> Array:
    """The NS and LD regressors of the key term `x(t)` (eq. 17's first columns, in theta
    order, one row per column: `Float[Array, "P_ns_ld T"]`), before they are switched on
    by `g1`: the right and left segments' `h u(t-1)` and breakpoint columns `-f`, the
    numerator's `v(t-i)`, `i >= 2`, and the denominator's `-x(t-j)`. Shared by the
    cascade's regression and the general backlash's (`_estimator._general_keyterm`)."""
    o = params.orders
    dtype = u.dtype
    u1 = shift(u, 1)
    zero = jnp.zeros((1,), dtype)
    DR = jnp.concatenate([zero, params.DR.astype(dtype)])
    DL = jnp.concatenate([zero, params.DL.astype(dtype)])
    MR = jnp.ones_like(params.MR) if unit_slopes else params.MR.astype(dtype)
    ML = jnp.ones_like(params.ML) if unit_slopes else params.ML.astype(dtype)

    right = heaviside(DR[:, None] - u1[None, :])  # h(DR_{i-1} - u(t-1)), i = 1..nR
    left = heaviside(u1[None, :] - DL[:, None])  # h(u(t-1) - DL_{j-1}), j = 1..nL
    columns = [
        right * u1,
        -MR[1:, None] * right[1:],  # -f1,i+1(t-1): coefficient DR_i
        left * u1,
        -ML[1:, None] * left[1:],  # -f2,j+1(t-1): coefficient DL_j
        jnp.stack([shift(v, i) for i in range(2, o.r + 1)]) if o.r > 1 else None,
        jnp.stack([-shift(x, j) for j in range(1, o.p + 1)]) if o.p > 0 else None,
    ]
    return jnp.concatenate([c for c in columns if c is not None], axis=0)


def solve_normal_equations(
    phi: Float[Array, "T P"], yc: Float[Array, " T"], *, blocks: int | None = None
) -> tuple[Float[Array, " P"], Array, Float[Array, ""]]:
    """Least squares `argmin |yc - phi theta|^2` through the normal equations (eq. 28).

    With `blocks = k`, columns `[:k]` and `[k:]` have disjoint supports in time (true of
    the cascade: the NS, LD and cL columns carry g1, the mR and C columns carry g2, and
    g1 g2 = 0), so the Gram matrix is block diagonal and the two blocks are solved
    separately: same solution, fewer flops.

    Columns are scaled to unit norm before the solve; the problem is reported singular
    when a column is identically zero (a regime or segment never active) or the scaled
    Gram matrix is numerically singular (a pivot of its Cholesky factor below
    ~sqrt(1e4 eps)). Never raises.

    **Returns:** `(theta, singular, cost)` with `cost = mean(residual^2)` (eq. 28).
    """
    parts = [phi] if blocks is None else [phi[:, :blocks], phi[:, blocks:]]
    thetas, flags = [], []
    for part in parts:
        theta, singular, _ = solve_gram(part.T @ part, part.T @ yc)
        thetas.append(theta)
        flags.append(singular)
    theta = jnp.concatenate(thetas)
    cost = jnp.mean((yc - phi @ theta) ** 2)
    return theta, jnp.any(jnp.stack(flags)), cost


def solve_gram(gram, rhs):
    """Solve `gram @ theta = rhs` (symmetric positive semi-definite) with Jacobi scaling
    and Gauss-Jordan elimination, and flag a singular system. Never raises, never NaN.

    A singular system (a column identically zero: a regime or segment never active; or a
    pivot of the scaled Cholesky factor below ~sqrt(1e4 eps): columns that are linearly
    dependent at this estimate) still gets a solution, the one the paper's iteration can
    go on from (`_estimator._literal.voros`): close to the minimum-norm least-squares
    solution that `numpy.linalg.lstsq` gives, from a second elimination with a
    ridge of `1e-8 max(diag gram)` on the unscaled diagonal (a direction the record does
    not determine gets ~0, a determined one is changed by ~1e-8 relative). A ridge, not
    an eigendecomposition: it costs one small elimination per step. The algebra is
    `_linalg`'s plain loops (Gauss-Jordan), not LAPACK (see there: batched LAPACK calls
    can deadlock).

    **Returns:** `(theta, singular, inverse_diagonal)`, the last the diagonal of
    `gram^-1` (the standard errors of a least-squares estimate are
    `sigma sqrt(inverse_diagonal)`; of the regularised system when singular).
    """
    eps = jnp.finfo(gram.dtype).eps
    d = jnp.sqrt(jnp.diagonal(gram))
    zero = d <= jnp.max(d) * eps
    d = jnp.where(zero, 1.0, d)
    identity = jnp.eye(gram.shape[0], dtype=gram.dtype)
    scaled = gram / (d[:, None] * d[None, :])
    scaled = jnp.where(zero[:, None] | zero[None, :], identity, scaled)
    # the ridge in scaled variables: 1e-8 max(d)^2 / d_i^2 on the diagonal
    ridged = scaled + jnp.diag(1e-8 * (jnp.max(d) / d) ** 2)
    rhs = jnp.where(zero, 0.0, rhs)
    # both systems in one loop, solution and inverse together (`_linalg.gauss_jordan`:
    # its pivots are the squared diagonal of the Cholesky factor)
    augmented = jnp.concatenate([(rhs / d)[:, None], identity], axis=1)
    (plain, regular), (pivots, _) = jax.vmap(_linalg.gauss_jordan, (0, None))(
        jnp.stack([scaled, ridged]), augmented
    )
    singular = jnp.any(zero) | ~_linalg.positive(pivots) | (jnp.min(pivots) <= 1e4 * eps)
    solution = jnp.where(singular, regular, plain)
    solution = jnp.where(jnp.all(jnp.isfinite(solution)), solution, augmented)
    return solution[:, 0] / d, singular, jnp.diagonal(solution[:, 1:]) / d**2
