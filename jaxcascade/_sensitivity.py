"""The simulated output and its Jacobian with respect to the parameters, by forward
sensitivities (what output-error Levenberg-Marquardt needs at every step).

Differentiating `simulate` with `jax.jacfwd` pushes P tangents through three sequential
scans; the structure of the cascade gives the same Jacobian more cheaply:

- NS and the numerator of LD are static: the tangents of `w(t) = sum_i a_i v(t-i)` with
  respect to the slopes, breakpoints and `a` are elementwise (`jax.jacfwd` of a
  vectorised function, no scan).
- LD's pole recursion is linear and time-invariant with zero initial conditions, so the
  tangents of `x` are the same filter applied to the tangents of `w`, one blocked scan
  for all columns (`_filter`, as `_simulate.linear_block`), and `dx/db_j` is
  `-x(t-j)` filtered, i.e. `-xx(t-j)` with `xx` the filter applied twice.
- The backlash switches g1, g2 are piecewise constant in the parameters (their
  derivative is zero almost everywhere), so eq. (9) differentiates to
  `dy(t) = g1 (dx + dcL) + g2 (dmR (x - cR) + mR (dx - dcR)) + (1 - g1)(1 - g2) dy(t-1)`:
  on a line the tangent is set, in the dead zone it is held. So `dy(t)` is the set
  value at the last sample on a line (`lax.cummax` over indices, a gather): the only
  sequential pass left is the backlash itself (`modes`).

Exact up to rounding: it equals `jax.jacfwd` of `_simulate.signals(...).y` (the test
compares them); the blocked filter and the switching rule are those of `_simulate`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._model import CascadeParams, Orders
from ._simulate import backlash_switches, pwl, shift


class Trajectory(NamedTuple):
    """One simulated record with what its Jacobian needs (each `Float[Array, " T"]`)."""

    w: Array  # LD's numerator output, sum_i a_i v(t - i)
    x: Array  # LD's output
    y: Array  # the cascade's output
    g1: Array  # left line active (0/1)
    g2: Array  # right line active (0/1)


def _numerator(vector, orders: Orders, u):
    # w(t) = sum_i a_i v(t - i), a_1 = 1, as a function of the NS and `a` entries
    params = CascadeParams.from_vector(
        jnp.concatenate([vector, jnp.zeros((orders.size - vector.shape[0],), vector.dtype)]),
        orders,
        check=False,
    )
    v = pwl(params, u)
    a = jnp.concatenate([jnp.ones((1,), u.dtype), params.a.astype(u.dtype)])
    return sum(a[i - 1] * shift(v, i) for i in range(1, orders.r + 1))


def _filter(b, columns, block: int):
    """`x(t) = w(t) - sum_j b_j x(t-j)` for every column of `columns` (`"T K"`), zero
    initial conditions, in blocks of `block` samples (`_simulate._poles_blocked`)."""
    p, dtype = b.shape[0], columns.dtype
    if p == 0:
        return columns
    T, K = columns.shape
    block = min(block, T)
    basis = jnp.concatenate([jnp.eye(p, dtype=dtype), jnp.zeros((p, 1), dtype)], axis=1)
    drive = jnp.zeros((block, p + 1), dtype).at[0, p].set(1.0)

    def response(past, drive_t):
        x_t = drive_t - b @ past
        return jnp.concatenate([x_t[None], past[:-1]]), x_t

    _, impulse = jax.lax.scan(response, basis, drive)
    G, h = impulse[:, :p], impulse[:, p]
    lag = jnp.arange(block)[:, None] - jnp.arange(block)[None, :]
    H = jnp.where(lag >= 0, h[jnp.clip(lag, 0, None)], 0.0)
    count = -(-T // block)
    padded = jnp.concatenate([columns, jnp.zeros((count * block - T, K), dtype)])

    def step(past, w_block):
        x_block = H @ w_block + G @ past
        return x_block[::-1][:p], x_block

    _, x = jax.lax.scan(step, jnp.zeros((p, K), dtype), padded.reshape(count, block, K))
    return x.reshape(count * block, K)[:T]


def modes(params: CascadeParams, x: Float[Array, " T"], *, unroll: int = 8):
    """The backlash (eq. 9, as `_simulate.backlash`) with its switches: `(y, g1, g2)`."""
    cL, mR, cR = (jnp.asarray(c, x.dtype) for c in (params.cL, params.mR, params.cR))

    def step(y_prev, x_t):
        g1, g2 = backlash_switches(x_t, y_prev, cL, mR, cR)
        y_t = g1 * (x_t + cL) + g2 * mR * (x_t - cR) + (1 - g1) * (1 - g2) * y_prev
        return y_t, (y_t, g1, g2)

    _, (y, g1, g2) = jax.lax.scan(step, jnp.zeros((), x.dtype), x, unroll=unroll)
    return y, g1, g2


def trajectory(params: CascadeParams, u: Float[Array, " T"], *, block: int = 64) -> Trajectory:
    """Simulate one record (noise-free), keeping what `jacobian` needs."""
    o = params.orders
    vector = params.to_vector().astype(u.dtype)
    w = _numerator(vector[: o.slices["b"].start], o, u)
    x = _filter(vector[o.slices["b"]], w[:, None], block)[:, 0]
    y, g1, g2 = modes(params, x)
    return Trajectory(w, x, y, g1, g2)


def jacobian(
    params: CascadeParams, u: Float[Array, " T"], path: Trajectory, *, block: int = 32
) -> Float[Array, "T P"]:
    """`d y(t) / d theta` (columns in `Orders.names` order) along `path = trajectory(params, u)`."""
    o = params.orders
    dtype = u.dtype
    vector = params.to_vector().astype(dtype)
    static = o.slices["b"].start
    b = vector[o.slices["b"]]
    mR, cR = vector[-2], vector[-1]
    # NS and a: d w / d theta, elementwise in time
    dw = jax.jacfwd(_numerator)(vector[:static], o, u)  # T x static
    if o.p:
        # d x / d b_j = filter(-x(t - j)) = -xx(t - j): the filter is LTI from rest
        xx = _filter(b, path.x[:, None], block)[:, 0]
        dx_db = -jnp.stack([shift(xx, j) for j in range(1, o.p + 1)], 1)
        dx = jnp.concatenate([_filter(b, dw, block), dx_db], 1)
    else:
        dx = dw
    T = u.shape[0]
    zeros = jnp.zeros((T, 3), dtype)
    dx = jnp.concatenate([dx, zeros], 1)
    e = jnp.eye(o.size, dtype=dtype)
    g1, g2 = path.g1[:, None], path.g2[:, None]
    # the value set on a line: d/dtheta of g1 (x + cL) + g2 mR (x - cR)
    set_value = g1 * (dx + e[-3]) + g2 * (e[-2] * (path.x - cR)[:, None] + mR * (dx - e[-1]))
    on_line = (path.g1 + path.g2) > 0
    last = jax.lax.cummax(jnp.where(on_line, jnp.arange(T), -1))
    return jnp.where((last >= 0)[:, None], set_value[jnp.clip(last, 0, None)], 0.0)
