"""Coloured noise: a stationary ARMA process, unit variance.

`e = C(q) / A(q) w` with `w` white Gaussian, `A(q) = prod_i (1 - p_i q^-1)` (the poles,
inside the unit circle) and `C(q) = prod_k (1 - z_k q^-1)` (the zeros), divided by the
process's stationary standard deviation. The process is stationary from its first
sample: the `m = max(p, q)` values of the AR part before the record are drawn from
their stationary distribution (the Toeplitz matrix of the AR autocovariances, from the
Yule-Walker equations), so no burn-in is needed and a pole near 1 costs nothing extra.
A pole or zero is a real number or a pair `[radius, angle]`, the conjugate pair `radius
exp(+-i angle)` (`_noise_filter.roots`): `poles = [[0.95, 0.6]]` is a resonance at 0.6
rad/sample, the noise of a lightly damped structure.
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .._noise_filter import polynomial, roots
from ._base import Disturbance, number, setting

MAX_ORDER = 8


def _roots(values, what: str) -> tuple:
    if isinstance(values, int | float) and not isinstance(values, bool):
        values = (values,)
    if not isinstance(values, tuple | list):
        raise ValueError(
            f"{what} must be a list of numbers or [radius, angle] pairs, got {values!r}."
        )
    count = sum(1 if isinstance(v, int | float) else 2 for v in values)
    if count > MAX_ORDER:
        raise ValueError(
            f"{what}: at most {MAX_ORDER} are supported (a pair counts two), got {count}."
        )
    return tuple(values)


def autocovariance(ar: np.ndarray, lags: int) -> np.ndarray:
    """Autocovariances `gamma_0 .. gamma_{lags-1}` of `s(t) = w(t) - sum_j ar_j s(t-j)`
    with unit-variance white `w` (`ar = [a_1, ..., a_p]`; Yule-Walker, then the AR
    recursion for the longer lags)."""
    p = len(ar)
    coefficients = np.concatenate([[1.0], ar])
    # gamma_k + sum_j a_j gamma_|k-j| = delta_k0, k = 0..p, unknowns gamma_0..gamma_p
    system = np.zeros((p + 1, p + 1))
    for k in range(p + 1):
        for j in range(p + 1):
            system[k, abs(k - j)] += coefficients[j]
    rhs = np.zeros(p + 1)
    rhs[0] = 1.0
    gamma = list(np.linalg.solve(system, rhs))
    while len(gamma) < lags:
        k = len(gamma)
        gamma.append(-sum(ar[j - 1] * gamma[k - j] for j in range(1, p + 1)))
    return np.asarray(gamma[: max(lags, 1)])


def _pair(value, what: str, *, high: float) -> None:
    """A `[radius, angle]` pair: radius in [0, high), angle in (0, pi) (`roots` checks
    the shape and the angle)."""
    roots((value,), "pole or zero")
    number(value[0], what, low=0, high=high, high_open=True)


class ARMA(Disturbance):
    """Stationary ARMA noise with `poles` (inside the unit circle) and `zeros`, each a
    real number or a `[radius, angle]` conjugate pair (module docstring)."""

    name: ClassVar[str] = "arma"
    summary: ClassVar[str] = "stationary ARMA noise (poles and zeros real or [radius, angle] pairs)"

    poles: tuple[float, ...] = setting((0.9,))
    zeros: tuple[float, ...] = setting(())

    def __check_init__(self):
        for pole in _roots(self.poles, f"Noise {self.name}: poles"):
            if isinstance(pole, tuple | list):
                _pair(pole, f"Noise {self.name}: a pole pair's radius", high=1)
            else:
                number(pole, f"Noise {self.name}: every pole", low=-1, high=1, low_open=True,
                       high_open=True)  # fmt: skip
        for zero in _roots(self.zeros, f"Noise {self.name}: zeros"):
            if isinstance(zero, tuple | list):
                _pair(zero, f"Noise {self.name}: a zero pair's radius", high=1e3)
            else:
                number(zero, f"Noise {self.name}: every zero", low=-1e3, high=1e3)

    def coefficients(self) -> tuple[np.ndarray, np.ndarray]:
        """`(a, c)`: `A(q) = 1 + a_1 q^-1 + ...`, `C(q) = 1 + c_1 q^-1 + ...` (no leading 1)."""
        return polynomial(roots(self.poles, "pole")), polynomial(roots(self.zeros, "zero"))

    def stationary(self) -> tuple[np.ndarray, np.ndarray, float]:
        """`(gamma, factor, std)`: the AR part's autocovariances at lags `0..m-1`, the
        Cholesky factor of their Toeplitz matrix (the `m` past values' covariance) and
        the stationary standard deviation of the ARMA output."""
        a, c = self.coefficients()
        m = max(len(a), len(c))
        gamma = autocovariance(a, max(m, len(c) + 1, 1))
        full = np.concatenate([[1.0], c])
        variance = sum(
            full[i] * full[k] * gamma[abs(i - k)]
            for i in range(len(full))
            for k in range(len(full))
        )
        toeplitz = np.array([[gamma[abs(i - j)] for j in range(m)] for i in range(m)])
        factor = np.linalg.cholesky(toeplitz) if m else np.zeros((0, 0))
        return gamma, factor, math.sqrt(variance)

    def __call__(self, key, n, dtype=None):
        dtype = dtype or jnp.result_type(float)
        a, c = self.coefficients()
        p, q = len(a), len(c)
        _, factor, std = self.stationary()
        m = max(p, q)
        key_w, key_past = jax.random.split(key)
        w = jax.random.normal(key_w, (n,), dtype)
        # past[0] = s(-1), past[1] = s(-2), ...: stationary jointly with the record
        past = jnp.asarray(factor, dtype) @ jax.random.normal(key_past, (m,), dtype)
        if p:
            ar = jnp.asarray(a, dtype)

            def step(carry, w_t):
                s_t = w_t - jnp.dot(ar, carry)
                return jnp.concatenate([s_t[None], carry[:-1]]), s_t

            _, s = jax.lax.scan(step, past[:p], w)
        else:
            s = w
        # oldest first: s(-m) .. s(-1), s(0) .. s(n-1)
        history = jnp.concatenate([past[::-1], s])
        e = s
        for k in range(1, q + 1):
            e = e + c[k - 1] * jax.lax.dynamic_slice_in_dim(history, m - k, n)
        return e / std


class AR(ARMA):
    """Stationary AR noise with `poles` (real in (-1, 1), or `[radius, angle]` pairs);
    `poles = [0.9]` is AR(1), `poles = [[0.95, 0.6]]` an AR(2) resonance."""

    name: ClassVar[str] = "ar"
    summary: ClassVar[str] = "stationary AR noise (poles real or [radius, angle] pairs)"

    def __check_init__(self):
        if tuple(_roots(self.zeros, "zeros")):
            raise ValueError('Noise ar has poles only; give zeros with kind = "arma".')

    def settings(self):
        return {"poles": super().settings()["poles"]}
