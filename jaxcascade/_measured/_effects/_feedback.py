"""Feedback inside the linear block: what the dynamics of real devices feed back.

Each effect here adds a term to the linear block's recursion (`Effect.recursion`,
`_recursion.linear_with_terms`):

    x(t) = sum_i a_i v(t-i) - sum_j b_j x(t-j) + term(v(t), x(t-1))

- `NonlinearFeedback` (`nonlinear_feedback`): a static polynomial of the block's own past
  output, `k2 x(t-1)^2 + k3 x(t-1)^3`: a hardening or softening spring (the Duffing
  oscillator: Silverbox's cubic stiffness), a Lur'e loop, a level-dependent outflow
  (a tank's square-root law around its operating point).
- `DirectTerm` (`direct_term`): the input acting within the sample, `d v(t)`: a zero at
  lag 0, which sampled continuous dynamics have when the input moves between samples
  (a smooth or first-order-hold input) and the cascade's `a_1 v(t-1)` cannot give.
- `VelocityFriction` (`velocity_friction`): Coulomb friction on the velocity of an
  integrating plant, `-f+ s+ - f- s-` with `s = tanh(x(t-1) / EPS)` split by its sign:
  a force of constant size against the motion (another size each way), acting on the
  model's own velocity; the viscous part is the block's pole. Tried only where the loop
  models an output that integrates its input (`_integrating`: `x` is then a velocity).

Their residual signature: a polynomial feedback leaves an error that is a nonlinear
function of past inputs, which the higher-order correlation tests see (`u2_e`, `u2_e2`,
`e_eu`: Billings' tests, odd terms in `u2_e2`); an input within the sample correlates
with the residual at lag 0 (`cross_correlation`); friction makes the error depend on
the direction of motion (`regime`, `level`, `hysteresis`). Each is tried only where a
test of its signature failed (`needs_signature`).

Starts: the term's first-order effect on the output is its signal filtered by the
block's poles, `term / A(q)`, so the residual is regressed on those filtered columns
(host side); the fit, half of it and zero are the starts, refined with the cascade.
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import scipy.signal
from jaxtyping import Array, Float

from ._base import Effect, Start, _batched, _repeat, simulate_padded


def _poles(model) -> np.ndarray:
    """`A(q)` of the model's linear block: `[1, b_1, .., b_p]`."""
    return np.concatenate([[1.0], np.asarray(model.params.b, float)])


def _pwl(params, u) -> np.ndarray:
    """The static block's output `v` on the host (`_system._simulate.pwl` in NumPy: an
    eager JAX call would compile a program per record length)."""
    p = params.to_dict()
    o = params.orders
    DR = [0.0] + [p[f"DR{i}"] for i in range(1, o.nR)]
    DL = [0.0] + [p[f"DL{i}"] for i in range(1, o.nL)]
    v = np.zeros_like(u)
    for i, D in enumerate(DR, start=1):
        v += p[f"MR{i}"] * np.where(u > D, u - D, 0.0)
    for i, D in enumerate(DL, start=1):
        v += p[f"ML{i}"] * np.where(u < D, u - D, 0.0)
    return v


def _regressed(records, columns_of, model):
    """Least-squares coefficients of the residual on `columns_of(x_prev, v)` filtered by
    `1 / A(q)`, over every record `(u, y, residual)`; `x_prev` the simulated `x(t-1)`."""
    A = _poles(model)
    rows, targets = [], []
    for u, _, residual in records:
        u = np.asarray(u, float)
        x = simulate_padded(model, u)[1]
        x_prev = np.concatenate([[0.0], x[:-1]])
        v = _pwl(model.params, u)
        columns = columns_of(x_prev, v)
        rows.append(np.stack([scipy.signal.lfilter([1.0], A, c) for c in columns], axis=1))
        targets.append(np.asarray(residual, float))
    X, r = np.concatenate(rows), np.concatenate(targets)
    if not np.all(np.isfinite(X)) or X.shape[0] < 10 * X.shape[1]:
        return None
    scale = np.sqrt(np.mean(X**2, axis=0)) + 1e-300
    return np.linalg.lstsq(X / scale, r, rcond=None)[0] / scale


def _applies(cls, model) -> bool:
    """An effect of the recursion needs the cascade, a pole (`x(t-1)` in its state) and
    no effect of its own kind already."""
    return (
        model.cascade and model.orders.p >= 1 and not any(isinstance(e, cls) for e in model.effects)
    )


class NonlinearFeedback(Effect):
    name: ClassVar[str] = "nonlinear_feedback"
    signature: ClassVar[tuple[str, ...]] = ("u2_e", "u2_e2", "e_eu")
    description: ClassVar[str] = (
        "polynomial of the linear block's past output fed back into it: "
        "x(t) + k2 x(t-1)^2 + k3 x(t-1)^3 (a Duffing spring, a Lur'e loop)"
    )
    needs_signature: ClassVar[bool] = True

    coefficients: Float[Array, " 2"]  # k2, k3

    def recursion(self, v, x_prev):
        k = self.coefficients.astype(x_prev.dtype)
        return x_prev * x_prev * (k[0] + k[1] * x_prev)

    @classmethod
    def starts_records(cls, model, records):
        if not _applies(cls, model):
            return []
        fit = _regressed(records, lambda x, v: (x**2, x**3), model)
        if fit is None:
            return []
        values = np.array([fit, 0.5 * fit, np.zeros(2)])
        effect = _batched(cls, coefficients=values)
        return [Start(cls.name, model.orders, _repeat(model, len(values)), effect)]

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])


class DirectTerm(Effect):
    name: ClassVar[str] = "direct_term"
    signature: ClassVar[tuple[str, ...]] = ("cross_correlation",)
    description: ClassVar[str] = (
        "the input acting within the sample: x(t) + d v(t) (a zero at lag 0 of sampled "
        "continuous dynamics)"
    )
    needs_signature: ClassVar[bool] = True

    gain: Float[Array, " 1"]

    def recursion(self, v, x_prev):
        return self.gain.astype(v.dtype)[0] * v

    @classmethod
    def starts_records(cls, model, records):
        if not _applies(cls, model):
            return []
        fit = _regressed(records, lambda x, v: (v,), model)
        if fit is None:
            return []
        values = np.array([fit, 0.5 * fit, np.zeros(1)])
        effect = _batched(cls, gain=values)
        return [Start(cls.name, model.orders, _repeat(model, len(values)), effect)]

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])


class VelocityFriction(Effect):
    name: ClassVar[str] = "velocity_friction"
    signature: ClassVar[tuple[str, ...]] = ("regime", "level", "hysteresis", "mean")
    description: ClassVar[str] = (
        "Coulomb friction on the velocity of an integrating plant: x(t) - f+ s+ - f- s-, "
        "s = tanh(x(t-1) / eps) (positioning systems; with --integrate)"
    )
    needs_signature: ClassVar[bool] = True
    # tried only where the loop models an output that integrates its input
    integrating_only: ClassVar[bool] = True
    # the smoothing of the friction's sign, in model units of the velocity (its
    # standard deviation is about one): motion slower than this is nearly stuck
    EPS: ClassVar[float] = 0.02

    forces: Float[Array, " 2"]  # f+ (moving up), f- (moving down)

    def recursion(self, v, x_prev):
        f = self.forces.astype(x_prev.dtype)
        s = jnp.tanh(x_prev / self.EPS)
        return -(f[0] * jnp.maximum(s, 0.0) + f[1] * jnp.minimum(s, 0.0))

    @classmethod
    def starts_records(cls, model, records):
        if not _applies(cls, model):
            return []

        def columns(x, v):
            s = np.tanh(x / cls.EPS)
            return (-np.maximum(s, 0.0), -np.minimum(s, 0.0))

        fit = _regressed(records, columns, model)
        if fit is None:
            return []
        fit = np.maximum(fit, 0.0)  # a force against the motion
        values = np.array([fit, 0.5 * fit, np.zeros(2)])
        effect = _batched(cls, forces=values)
        return [Start(cls.name, model.orders, _repeat(model, len(values)), effect)]

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])
