"""The simulated output and its Jacobian with respect to the parameters, by forward
sensitivities (what output-error Levenberg-Marquardt needs at every step).

Differentiating `simulate` with `jax.jacfwd` pushes P tangents through the generic
graph of three sequential scans; the structure of the cascade gives the same Jacobian
more cheaply, in one pass:

- NS and the numerator of LD are static: the tangents of `w(t) = sum_i a_i v(t-i)` with
  respect to the slopes, breakpoints and `a` are written out elementwise (`_numerator`:
  `dv/dM = (u - D) h(...)`, `dv/dD = -M h(...)`), no scan.
- LD's pole recursion is linear: `dx(t) = dw(t) - sum_j b_j dx(t-j)`, plus `-x(t-j)` in
  the column of `b_j`.
- The backlash switches g1, g2 are piecewise constant in the parameters (derivative
  zero almost everywhere), so eq. (9) differentiates to
  `dy(t) = g1 (dx + dcL) + g2 (dmR (x - cR) + mR (dx - dcR)) + (1 - g1)(1 - g2) dy(t-1)`.

One `lax.scan` over time carries LD's past outputs and their tangents and the backlash
state and its tangent (`output_jacobian`); per step it costs O(p P) flops, so the scan's
per-step overhead, not arithmetic, sets its time. Exact up to rounding: it equals
`jax.jacfwd` of `_simulate.signals(...).y` (the test compares them; the switching rule
is `_simulate.backlash_switches`).

On an accelerator (`_scans.parallel`) the same recursions run as associative scans
(`output_jacobian_parallel`): the pole recursion of `x` and, with the same poles, of
its tangents (`_scans.poles_blocked`, `dw` and `-x(t-j)` as right-hand sides), the backlash
(`_scans.backlash`), its switches from the output before, and `dy` as the value of the
last sample on a branch (`_scans.last_active`). Equal up to rounding.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._system import _scans
from .._system._model import CascadeParams
from .._system._simulate import backlash_switches, shift


def _shift_rows(matrix, lag: int):
    return jnp.concatenate([jnp.zeros((lag, matrix.shape[1]), matrix.dtype), matrix[:-lag]])


def _numerator(params: CascadeParams, u):
    """`w(t) = sum_i a_i v(t - i)` (a_1 = 1) and its derivatives with respect to the
    NS entries and `a` (columns in `Orders.names` order, up to `b`): `(w, dw)`."""
    o = params.orders
    dtype = u.dtype
    zero = jnp.zeros((1,), dtype)
    DR = jnp.concatenate([zero, params.DR.astype(dtype)])
    DL = jnp.concatenate([zero, params.DL.astype(dtype)])
    on_right = (u[:, None] > DR[None, :]).astype(dtype)  # T x nR, h(D - u) of eq. 1
    on_left = (u[:, None] < DL[None, :]).astype(dtype)
    right = on_right * (u[:, None] - DR[None, :])
    left = on_left * (u[:, None] - DL[None, :])
    v = right @ params.MR.astype(dtype) + left @ params.ML.astype(dtype)
    dv = jnp.concatenate(
        [
            right,
            -on_right[:, 1:] * params.MR[1:].astype(dtype),
            left,
            -on_left[:, 1:] * params.ML[1:].astype(dtype),
        ],
        axis=1,
    )
    a = jnp.concatenate([jnp.ones((1,), dtype), params.a.astype(dtype)])
    w = sum(a[i - 1] * shift(v, i) for i in range(1, o.r + 1))
    dw = sum(a[i - 1] * _shift_rows(dv, i) for i in range(1, o.r + 1))
    if o.r > 1:
        dw = jnp.concatenate([dw, jnp.stack([shift(v, i) for i in range(2, o.r + 1)], 1)], 1)
    return w, dw


def output_jacobian(
    params: CascadeParams, u: Float[Array, " T"]
) -> tuple[Float[Array, " T"], Float[Array, "T P"]]:
    """Noise-free output `y` of one record and `d y(t) / d theta` (columns in
    `Orders.names` order), in one scan (module docstring); on an accelerator by
    associative scans (`output_jacobian_parallel`)."""
    if _scans.parallel():
        return output_jacobian_parallel(params, u)
    o = params.orders
    dtype = u.dtype
    vector = params.to_vector().astype(dtype)
    b = vector[o.slices["b"]]
    cL, mR, cR = vector[-3], vector[-2], vector[-1]
    w, dw = _numerator(params, u)
    e_cL, e_mR, e_cR = jnp.eye(3, dtype=dtype)

    def step(carry, inputs):
        x_past, dx_past, y_prev, dy_prev = carry  # p, p x (P - 3), scalar, P
        w_t, dw_t = inputs
        x_t = w_t - b @ x_past
        dx_t = jnp.concatenate([dw_t, -x_past]) - b @ dx_past
        g1, g2 = backlash_switches(x_t, y_prev, cL, mR, cR)
        y_t = g1 * (x_t + cL) + g2 * mR * (x_t - cR) + (1 - g1) * (1 - g2) * y_prev
        dx_full = jnp.concatenate([dx_t, jnp.zeros((3,), dtype)])
        on_line = g1 * (dx_full + jnp.concatenate([jnp.zeros_like(dx_t), e_cL]))
        on_line += g2 * (
            jnp.concatenate([jnp.zeros_like(dx_t), e_mR * (x_t - cR) - mR * e_cR]) + mR * dx_full
        )
        dy_t = on_line + (1 - g1) * (1 - g2) * dy_prev
        if o.p:
            x_past = jnp.concatenate([x_t[None], x_past[:-1]])
            dx_past = jnp.concatenate([dx_t[None], dx_past[:-1]])
        return (x_past, dx_past, y_t, dy_t), (y_t, dy_t)

    P = o.size
    carry = (
        jnp.zeros((o.p,), dtype),
        jnp.zeros((o.p, P - 3), dtype),
        jnp.zeros((), dtype),
        jnp.zeros((P,), dtype),
    )
    _, (y, J) = jax.lax.scan(step, carry, (w, dw))
    return y, J


def output_jacobian_parallel(
    params: CascadeParams, u: Float[Array, " T"]
) -> tuple[Float[Array, " T"], Float[Array, "T P"]]:
    """`output_jacobian` by associative scans (module docstring): the same output and
    Jacobian up to rounding, in log-depth rounds over time."""
    o = params.orders
    dtype = u.dtype
    vector = params.to_vector().astype(dtype)
    b = vector[o.slices["b"]]
    cL, mR, cR = vector[-3], vector[-2], vector[-1]
    w, dw = _numerator(params, u)
    x = _scans.poles_blocked(b, w)
    # the tangents' recursion has the poles of x's; `b_j`'s column is driven by -x(t-j)
    T = x.shape[0]
    drive = [dw] + [-jnp.pad(x, (j, 0))[:T, None] for j in range(1, o.p + 1)]
    dx = _scans.poles_blocked(b, jnp.concatenate(drive, axis=1))
    y = _scans.backlash(x, x + cL, mR * (x - cR), mR)
    g1, g2 = backlash_switches(x, shift(y, 1), cL, mR, cR)
    # the step's expressions of `output_jacobian`, every sample at once
    zeros = jnp.zeros((T, dx.shape[1]), dtype)
    dx_full = jnp.concatenate([dx, jnp.zeros((T, 3), dtype)], axis=1)
    e_cL, e_mR, e_cR = jnp.eye(3, dtype=dtype)
    gap = jnp.concatenate([zeros, jnp.broadcast_to(e_cL, (T, 3))], axis=1)
    on_line = g1[:, None] * (dx_full + gap)
    on_line += g2[:, None] * (
        jnp.concatenate([zeros, e_mR * (x - cR)[:, None] - mR * e_cR], 1) + mR * dx_full
    )
    # off both branches the output holds, and so does its derivative
    held = (1 - g1) * (1 - g2)
    return y, _scans.last_active(held == 0, on_line)
