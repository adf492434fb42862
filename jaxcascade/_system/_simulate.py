"""Simulation of the cascade: piecewise-linear NS, linear LD, backlash ND (eqs. 1-11),
with straight branches or, at branch degree > 1 (`Orders.degree`), curved ones."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from . import _scans
from ._model import CascadeParams
from ._validate import record


def heaviside(s):
    """The paper's switching function (eq. 4): 1 where `s < 0`, else 0."""
    return (s < 0).astype(s.dtype)


def shift(signal: Float[Array, " T"], lag: int) -> Float[Array, " T"]:
    """`signal(t - lag)` with zeros before the record starts (`u = y = 0` for `t <= 0`)."""
    if lag == 0:
        return signal
    return jnp.concatenate([jnp.zeros((lag,), signal.dtype), signal[:-lag]])


def pwl(params: CascadeParams, u: Float[Array, " T"]) -> Float[Array, " T"]:
    """Static piecewise-linear block NS (eq. 1)."""
    zero = jnp.zeros((1,), u.dtype)
    DR = jnp.concatenate([zero, params.DR.astype(u.dtype)])
    DL = jnp.concatenate([zero, params.DL.astype(u.dtype)])
    right = heaviside(DR[:, None] - u[None, :]) * (u[None, :] - DR[:, None])
    left = heaviside(u[None, :] - DL[:, None]) * (u[None, :] - DL[:, None])
    return _weighted_sum(params.MR.astype(u.dtype), right) + _weighted_sum(
        params.ML.astype(u.dtype), left
    )


def _weighted_sum(weights, rows):
    """`weights @ rows` for a few rows, element-wise: XLA's CPU dot of a (K,) vector with
    (K, T) rows (K = 2 segments) is a slow loop (under `vmap`, 16 ms of a 250-record
    simulation against 0.3 ms this way). Accumulated in the dot's order, the first
    product then one multiply-add per row, so the sums are the dot's (bit for bit on
    XLA's CPU backend, which fuses `w * x + acc` into one multiply-add as the dot does)."""
    total = weights[0] * rows[0]
    for k in range(1, rows.shape[0]):
        total = weights[k] * rows[k] + total
    return total


def linear_block(
    params: CascadeParams, v: Float[Array, " T"], *, block: int = 64
) -> Float[Array, " T"]:
    """Linear dynamic block LD (eq. 6, with a1 = 1).

    The pole recursion `x(t) = w(t) - sum_j b_j x(t-j)` runs block-wise: within a block
    of `block` samples `x = H w + G s`, with `H` the impulse-response Toeplitz matrix and
    `G` the response to the `p` past outputs `s`, so the sequential `lax.scan` takes
    `T / block` steps instead of `T` (exact up to rounding; the per-step overhead of a
    scan, not its arithmetic, dominates on a CPU). `block=1` is the plain recursion.
    On an accelerator (`_scans.parallel`) the blocks' starting states come from an
    associative scan of their affine maps instead (`_scans.poles_blocked`, equal up to
    rounding), except with `block=1`.
    """
    a = jnp.concatenate([jnp.ones((1,), v.dtype), params.a.astype(v.dtype)])
    w = sum(a[i - 1] * shift(v, i) for i in range(1, params.orders.r + 1))
    p = params.orders.p
    if p == 0:
        return w
    b = params.b.astype(v.dtype)
    if block > 1 and _scans.parallel():
        return _scans.poles_blocked(b, w, block)
    if block <= 1 or v.shape[0] <= block:
        return _poles_scan(b, w)
    return _poles_blocked(b, w, block)


def _poles_scan(b, w):
    def step(past, w_t):
        x_t = w_t - jnp.dot(b, past)
        return jnp.concatenate([x_t[None], past[:-1]]), x_t

    _, x = jax.lax.scan(step, jnp.zeros(b.shape, w.dtype), w)
    return x


def _poles_blocked(b, w, block):
    p, dtype = b.shape[0], w.dtype
    # Responses over one block to an impulse (column p) and to each past output (columns
    # 0..p-1), from the same recursion.
    basis = jnp.concatenate([jnp.eye(p, dtype=dtype), jnp.zeros((p, 1), dtype)], axis=1)
    drive = jnp.zeros((block, p + 1), dtype).at[0, p].set(1.0)

    def response(past, drive_t):
        x_t = drive_t - b @ past
        return jnp.concatenate([x_t[None], past[:-1]]), x_t

    _, columns = jax.lax.scan(response, basis, drive)
    G, h = columns[:, :p], columns[:, p]
    lag = jnp.arange(block)[:, None] - jnp.arange(block)[None, :]
    H = jnp.where(lag >= 0, h[jnp.clip(lag, 0, None)], 0.0)
    T = w.shape[0]
    count = -(-T // block)
    blocks = jnp.concatenate([w, jnp.zeros((count * block - T,), dtype)]).reshape(count, block)

    def step(past, w_block):
        x_block = H @ w_block + G @ past
        return x_block[::-1][:p], x_block

    _, x = jax.lax.scan(step, jnp.zeros((p,), dtype), blocks)
    return x.reshape(-1)[:T]


def backlash_switches(x, y_prev, cL, mR, cR) -> tuple[Array, Array]:
    """Switching variables g1 (left line active) and g2 (right line active), eqs. 10-11 with mL = 1.

    The two lines cross when `mR != 1`; where both conditions hold the left line wins
    (g2 is cleared). The simulator and the regression share this rule, so the true
    parameters stay an exact fixed point of the estimator.
    """
    g1 = heaviside(x + cL - y_prev)
    g2 = heaviside((y_prev - mR * x + mR * cR) / mR) * (1 - g1)
    return g1, g2


def backlash(params: CascadeParams, x: Float[Array, " T"]) -> Float[Array, " T"]:
    """Backlash ND (eq. 9) as a `lax.scan`; its state starts at y = 0. On an accelerator
    (`_scans.parallel`) an associative scan of the samples' clamp and threshold maps
    (`_scans.backlash`: the same values, `mR > 0`)."""
    cL, mR, cR = (jnp.asarray(c, x.dtype) for c in (params.cL, params.mR, params.cR))
    if _scans.parallel():
        return _scans.backlash(x, x + cL, mR * (x - cR), mR)

    def step(y_prev, x_t):
        g1, g2 = backlash_switches(x_t, y_prev, cL, mR, cR)
        y_t = g1 * (x_t + cL) + g2 * mR * (x_t - cR) + (1 - g1) * (1 - g2) * y_prev
        return y_t, y_t

    _, y = jax.lax.scan(step, jnp.zeros((), x.dtype), x)
    return y


# -- The general output backlash's branches (issue 39, `_general_backlash`) -------------
#
# `nd` below is anything with the fields `cL`, `mR`, `cR`, `curveL`, `curveR`: a
# `_general_backlash.GeneralBacklash`, or `CascadeParams` of branch degree > 1.


def _curvature(curve, s):
    """`sum_{i=2..q} curve[i-2] s^i` by Horner's rule; None without terms (degree 1), so
    that the straight backlash's expressions are used unchanged."""
    curve = jnp.asarray(curve, s.dtype)
    if curve.shape[-1] == 0:
        return None
    total = curve[-1]
    for c in curve[-2::-1]:
        total = c + s * total
    return s * s * total


def _plus(value, term):
    return value if term is None else value + term


def general_switches(nd, x, y_prev) -> tuple[Array, Array]:
    """Switching variables `g1` (left branch active) and `g2` (right branch active) of
    the general backlash; at degree 1 exactly `backlash_switches`."""
    cL, mR, cR = (jnp.asarray(c, x.dtype) for c in (nd.cL, nd.mR, nd.cR))
    g1 = heaviside(_plus(x + cL, _curvature(nd.curveL, x + cL)) - y_prev)
    rise = y_prev - mR * x + mR * cR
    curve = _curvature(nd.curveR, x - cR)
    g2 = heaviside((rise if curve is None else rise - curve) / mR) * (1 - g1)
    return g1, g2


def general_branches(nd, x) -> tuple[Array, Array]:
    """The values `(fL(x), fR(x))` the general backlash takes on its left and right
    branches, computed as `general_backlash`'s step computes them (at degree 1 the
    straight lines `x + cL`, `mR (x - cR)`)."""
    cL, mR, cR = (jnp.asarray(c, x.dtype) for c in (nd.cL, nd.mR, nd.cR))
    left = _plus(x + cL, _curvature(nd.curveL, x + cL))
    right = _curvature(nd.curveR, x - cR)
    return left, _plus(mR * (x - cR), right)


def general_backlash(nd, x: Float[Array, " T"], y_prev=None) -> Float[Array, " T"]:
    """The general backlash on the signal `x` as a `lax.scan`, its state starting at
    `y_prev` (the output before `x(0)`; default 0, rest). At degree 1 every expression
    is `backlash`'s: the same output bit for bit. On an accelerator (`_scans.parallel`)
    an associative scan of the samples' maps with the curved branches' values
    (`_scans.backlash`)."""
    cL, mR, cR = (jnp.asarray(c, x.dtype) for c in (nd.cL, nd.mR, nd.cR))
    y0 = jnp.zeros((), x.dtype) if y_prev is None else jnp.asarray(y_prev, x.dtype)
    if _scans.parallel():
        return _scans.backlash(x, *general_branches(nd, x), mR, y0)

    def step(y_prev, x_t):
        g1, g2 = general_switches(nd, x_t, y_prev)
        left = _curvature(nd.curveL, x_t + cL)
        right = _curvature(nd.curveR, x_t - cR)
        y_t = g1 * _plus(x_t + cL, left) + g2 * mR * (x_t - cR)
        if right is not None:
            y_t = y_t + g2 * right
        y_t = y_t + (1 - g1) * (1 - g2) * y_prev
        return y_t, y_t

    _, y = jax.lax.scan(step, y0, x)
    return y


class Signals(NamedTuple):
    """Internal and output signals of one simulated record, each `Float[Array, " T"]`."""

    v: Array
    x: Array
    y: Array


def signals(params: CascadeParams, u: Float[Array, " T"]) -> Signals:
    """Noise-free simulation returning v, x and y (dtype follows a float `u`; `u` is
    checked by `_validate.record`: one 1-D record of real, finite numbers)."""
    u = _input(params, u, "signals")
    v = pwl(params, u)
    x = linear_block(params, v)
    if params.orders.degree > 1:  # curved branches (`Orders.degree`)
        return Signals(v, x, general_backlash(params, x))
    return Signals(v, x, backlash(params, x))


def _input(params, u, where: str):
    if not isinstance(params, CascadeParams):
        raise TypeError(f"{where}: params must be CascadeParams, got {type(params).__name__}.")
    return record(u, where=where, cast=False)[0]


def simulate(params: CascadeParams, u: Float[Array, " T"]) -> Float[Array, " T"]:
    """Noise-free output y of the cascade for input u (dtype follows a float `u`; `u` is
    checked first, `_validate.record`)."""
    return _simulate(params, _input(params, u, "simulate"))


@jax.jit
def _simulate(params: CascadeParams, u: Float[Array, " T"]) -> Float[Array, " T"]:
    return signals(params, u).y


def add_noise(
    key: PRNGKeyArray, y: Float[Array, " T"], snr: float | Float[Array, ""], noise=None
) -> Float[Array, " T"]:
    """Add output noise at the paper's SNR = sqrt(var(y) / var(e)) (an amplitude ratio).

    `noise` draws the noise's shape, `noise(key, T, dtype)` with unit variance (a
    `_disturbance.Disturbance`: coloured, heavy-tailed, with outliers); without it,
    white Gaussian noise, the paper's. It is scaled by `std(y) / snr`, so the SNR is
    that of the noise as added. `snr = inf` adds nothing. The backlash state is not
    affected: noise is measurement noise.
    """
    snr = jnp.asarray(snr, y.dtype)
    sigma = jnp.std(y) / snr
    if noise is None:
        return y + sigma * jax.random.normal(key, y.shape, y.dtype)
    return y + sigma * noise(key, y.shape[0], y.dtype)


def uniform_input(key: PRNGKeyArray, n: int, amplitude: float = 2.0, dtype=None):
    """Input uniformly distributed in (-amplitude, amplitude), as in the paper's examples."""
    dtype = dtype or jnp.result_type(float)
    return jax.random.uniform(key, (n,), dtype, -amplitude, amplitude)


def measure(
    key: PRNGKeyArray, params: CascadeParams, u: Float[Array, " T"], snr
) -> tuple[Float[Array, " T"], Float[Array, " T"]]:
    """Simulate and add output noise; returns `(y_measured, y_noise_free)` (`u` checked
    first, as in `simulate`)."""
    return _measure(key, params, _input(params, u, "measure"), snr)


@jax.jit
def _measure(key, params, u, snr):
    y = _simulate(params, u)
    return add_noise(key, y, snr), y
