"""Linear output-noise filters: ARMA noise, its whitening filter, and an AR fit.

Coloured output noise is white noise `w` through a stable, inversely stable filter,

    e(t) = c1 e(t-1) + ... + cq e(t-q) + w(t) + d1 w(t-1) + ... + dm w(t-m),

`e = C(q)/A(q) w` with `A(q) = 1 - c1 q^-1 - ... - cq q^-q` (poles) and `C(q) = 1 + d1
q^-1 + ...` (zeros); AR noise has no `d` (the convention of `_noise.ARNoise`). Its
one-step-ahead predictor's error is `w = A(q)/C(q) e` (`whiten`, from rest: `e(t) = w(t)
= 0` for `t <= 0`), what a prediction-error estimator minimises and what the Cramér-Rao
bound of coloured noise whitens the output's Jacobian with (`_efficiency.crlb`).
Everything here is traceable except `roots` and `coefficients` (host side: poles and
zeros are settings). A pole or zero is a real number, or a pair `[radius, angle]`: the
complex conjugate pair `radius exp(+-i angle)` (`angle` in radians per sample, in
`(0, pi)`), a resonance of the noise's spectrum at `angle` (or, for zeros, a notch).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._linalg import spd_solve
from .._system._model import reflection_coefficients

CRITERIA = ("aic", "bic", "none")


def _real(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def roots(values, kind: str = "root") -> np.ndarray:
    """Poles or zeros (module docstring: real numbers and `[radius, angle]` pairs) as
    complex numbers, each pair as its two conjugates. A `ValueError` naming `kind`
    for anything else, a negative radius or an angle outside `(0, pi)` (a real root
    is a number)."""
    out = []
    for value in values:
        if _real(value):
            out.append(complex(value))
            continue
        if not (isinstance(value, tuple | list) and len(value) == 2 and all(map(_real, value))):
            raise ValueError(
                f"A noise {kind} must be a real number or a pair [radius, angle], got {value!r}."
            )
        radius, angle = (float(v) for v in value)
        if not (radius >= 0 and 0 < angle < np.pi):
            raise ValueError(
                f"A noise {kind} pair [radius, angle] needs radius >= 0 and 0 < angle < pi "
                f"(radians per sample), got {list(value)}."
            )
        out += [radius * np.exp(1j * angle), radius * np.exp(-1j * angle)]
    return np.asarray(out, complex)


def polynomial(values: np.ndarray) -> np.ndarray:
    """`prod (1 - r q^-1)` over complex `values` closed under conjugation: the real
    coefficients after the leading 1."""
    return np.real(np.poly(values))[1:].astype(float) if len(values) else np.zeros(0)


def coefficients(poles=(), zeros=()) -> tuple[np.ndarray, np.ndarray]:
    """`(c, d)` of the noise with `poles` (inside the unit circle) and `zeros`, real or
    in pairs (`roots`): `A(q) = prod (1 - p q^-1)`, `c = -A[1:]`; `C(q) = prod (1 - z
    q^-1)`, `d = C[1:]`. A zero outside the unit circle is replaced by the reciprocal of
    its conjugate: the same spectrum up to a gain (which `variance_ratio` absorbs), and
    the predictor's (minimum-phase) form. A `ValueError` for a pole on or outside the
    unit circle (not stationary) or a zero on it (no stable predictor)."""
    poles, zeros = roots(poles, "pole"), roots(zeros, "zero")
    for pole in poles:
        if not abs(pole) < 1:
            raise ValueError(f"A noise pole must lie inside the unit circle, got {pole:g}.")
    for zero in zeros:
        if abs(zero) == 1:
            raise ValueError(f"A noise zero on the unit circle has no stable predictor: {zero:g}.")
    zeros = np.asarray([z if abs(z) < 1 else 1 / np.conj(z) for z in zeros], complex)
    return -polynomial(poles), polynomial(zeros)


def _shift(signal, lag: int):
    pad = jnp.zeros((lag, *signal.shape[1:]), signal.dtype)
    return jnp.concatenate([pad, signal[:-lag]])


def lagged(signal: Float[Array, " T"], order: int) -> Float[Array, "T order"]:
    """Columns `signal(t-1), ..., signal(t-order)` (zeros before the start)."""
    if order == 0:
        return jnp.zeros((signal.shape[0], 0), signal.dtype)
    return jnp.stack([_shift(signal, i) for i in range(1, order + 1)], axis=1)


def whiten(signal, c, d=None):
    """`w = A(q)/C(q) signal` (module docstring) along the first axis: the innovations of
    a residual, or the whitened columns of a Jacobian (`T` or `T x P`)."""
    c = jnp.asarray(c, signal.dtype)
    out = signal
    for i in range(1, c.shape[0] + 1):
        out = out - c[i - 1] * _shift(signal, i)
    if d is None or len(d) == 0:
        return out
    d = jnp.asarray(d, signal.dtype)
    m = d.shape[0]

    def step(past, value):  # past: w(t-1), ..., w(t-m)
        w = value - jnp.tensordot(d, past, axes=1)
        return jnp.concatenate([w[None], past[:-1]]), w

    past = jnp.zeros((m, *signal.shape[1:]), signal.dtype)
    return jax.lax.scan(step, past, out)[1]


def variance_ratio(c, d=None, length: int = 4096):
    """`var(e) / var(w)` of stationary ARMA noise: the sum of the squared impulse response
    of `C(q)/A(q)`, over `length` samples (pole 0.97: 0.97^4096 ~ 1e-54)."""
    c = jnp.asarray(c)
    d = jnp.zeros((0,), c.dtype) if d is None else jnp.asarray(d, c.dtype)
    impulse = jnp.zeros((length,), c.dtype).at[0].set(1.0)
    moving = impulse + sum(d[j - 1] * _shift(impulse, j) for j in range(1, d.shape[0] + 1))
    q = c.shape[0]
    if q == 0:
        return jnp.sum(moving**2)

    def step(past, value):
        h = value + jnp.dot(c, past)
        return jnp.concatenate([h[None], past[:-1]]), h

    response = jax.lax.scan(step, jnp.zeros((q,), c.dtype), moving)[1]
    return jnp.sum(response**2)


def fit_ar(residual: Float[Array, " T"], max_order: int, criterion: str = "bic"):
    """AR coefficients of a residual by least squares on its own lags (from rest), the
    order chosen among `0..max_order` by `criterion` (`aic`: `T log s2 + 2 q`; `bic`: `T
    log s2 + q log T`; `none`: `max_order` itself). Traceable.

    **Returns:** `(c, order)`: `c` padded with zeros to `max_order` (an order below it has
    zero coefficients beyond), and the chosen order.
    """
    if criterion not in CRITERIA:
        raise ValueError(f"Unknown order criterion {criterion!r}; known: {', '.join(CRITERIA)}.")
    n = residual.shape[0]
    dtype = residual.dtype
    X = lagged(residual, max_order)
    gram, moment = X.T @ X, X.T @ residual
    power = residual @ residual
    tiny = jnp.finfo(dtype).tiny
    fits, scores = [], []
    for q in range(max_order + 1):
        if q == 0:
            c = jnp.zeros((max_order,), dtype)
        else:
            ridge = 1e-12 * (jnp.trace(gram[:q, :q]) / q) + tiny
            solution, _ = spd_solve(gram[:q, :q] + ridge * jnp.eye(q, dtype=dtype), moment[:q])
            solution = jnp.where(jnp.isfinite(solution), solution, 0.0)
            c = jnp.zeros((max_order,), dtype).at[:q].set(solution)
        variance = (power - 2 * c @ moment + c @ gram @ c) / n
        penalty = {"aic": 2.0, "bic": float(np.log(n)), "none": 0.0}[criterion]
        scores.append(n * jnp.log(jnp.maximum(variance, tiny)) + penalty * q)
        fits.append(c)
    if criterion == "none":
        return fits[-1], jnp.asarray(max_order, jnp.int32)
    order = jnp.argmin(jnp.stack(scores)).astype(jnp.int32)
    return jnp.stack(fits)[order], order


REFLECTION_LIMIT = 0.999


def ar_to_unconstrained(c):
    """An unconstrained vector for AR coefficients `c` (their reflection coefficients,
    `arctanh` of them, pulled inside +-`REFLECTION_LIMIT`): `ar_from_unconstrained`
    maps it back to a stable AR polynomial."""
    k = reflection_coefficients(-c) if c.shape[0] else c
    k = jnp.clip(jnp.where(jnp.isfinite(k), k, 0.0) / REFLECTION_LIMIT, -1 + 1e-6, 1 - 1e-6)
    return jnp.arctanh(k)


def ar_from_unconstrained(z):
    """Stable AR coefficients `c` from an unconstrained vector (the step-up recursion of
    the reflection coefficients `REFLECTION_LIMIT tanh(z)`)."""
    k = REFLECTION_LIMIT * jnp.tanh(z)
    poly = jnp.ones((1,), z.dtype)
    for m in range(z.shape[0]):
        padded = jnp.concatenate([poly, jnp.zeros((1,), z.dtype)])
        poly = padded + k[m] * padded[::-1]
    return -poly[1:]
