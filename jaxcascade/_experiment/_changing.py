"""Systems that change: parameters of the cascade step at a sample or drift linearly,
and the cascade's simulation with a parameter vector per sample.

A wearing drive train widens its backlash, a valve's dead zone drifts, a process moves
its operating point: the true system of an on-line identification benchmark is a
trajectory `theta(t)`, recorded with the data so that a tracker's error is known at
every sample. `Change` describes the change (the `[system.change]` table of a spec:
`parameter = "cR", at = 2000, to = 0.45` or `drift = 1e-5`; several parameters at
once as lists, `parameter = ["cL", "cR"], to = [0.3, 0.45]`: a worn drive train widens
both gaps), `trajectory` builds the
true parameters sample by sample, and `simulate_changing` runs eqs. 1-11 with them: at
sample t the blocks use the parameters of sample t (`x(t) = sum_i a_i(t) v(t-i) -
sum_j b_j(t) x(t-j)`, the backlash with the gaps and slope of sample t).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._system._model import CascadeParams, Orders
from .._system._simulate import backlash_switches, heaviside


@dataclasses.dataclass(frozen=True)
class Change:
    """Parameters change from sample `at` on: a step to `to`, or a linear drift of
    `drift` per sample (exactly one of the two). One parameter: `parameter` a name and
    `to` / `drift` a number; several at once: a tuple of names and a tuple of as many
    numbers (lists are taken as tuples). Checked at construction; whether the changed
    system is admissible is checked by `trajectory`, which knows the record."""

    parameter: str | tuple[str, ...]
    at: int
    to: float | tuple[float, ...] | None = None
    drift: float | tuple[float, ...] | None = None

    def __post_init__(self):
        for name in ("parameter", "to", "drift"):
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))
        several = isinstance(self.parameter, tuple)
        names = self.parameter if several else (self.parameter,)
        if not names or not all(isinstance(name, str) for name in names):
            raise ValueError(
                f"change: parameter must be a name or a list of names, got {self.parameter!r}."
            )
        if len(set(names)) != len(names):
            raise ValueError(f"change: a parameter is named twice in {list(names)}.")
        if isinstance(self.at, bool) or not isinstance(self.at, int | np.integer) or self.at < 0:
            raise ValueError(f"change: at must be a sample index >= 0, got {self.at!r}.")
        if (self.to is None) == (self.drift is None):
            raise ValueError("change: give exactly one of to (a step) and drift (per sample).")
        value = self.to if self.to is not None else self.drift
        if several != isinstance(value, tuple) or (several and len(value) != len(names)):
            raise ValueError(
                f"change: {len(names)} parameter(s) need as many values of to / drift, "
                f"got {value!r}."
            )
        for number in value if several else (value,):
            if (
                isinstance(number, bool)
                or not isinstance(number, int | float)
                or not np.isfinite(number)
            ):
                raise ValueError(f"change: to / drift must be finite numbers, got {value!r}.")

    @classmethod
    def from_table(cls, table: Mapping) -> Change:
        """From a spec's `[system.change]` table; an unknown key is a `ValueError`."""
        unknown = sorted(set(table) - {"parameter", "at", "to", "drift"})
        if unknown:
            raise ValueError(
                f"Unknown key {unknown[0]!r} in [system.change]; known: parameter, at, to, drift."
            )
        if "parameter" not in table or "at" not in table:
            raise ValueError("[system.change] needs parameter and at.")
        return cls(**dict(table))

    @property
    def parameters(self) -> tuple[str, ...]:
        """The changed parameters' names."""
        return self.parameter if isinstance(self.parameter, tuple) else (self.parameter,)

    def steps(self) -> tuple[tuple[str, float | None, float | None], ...]:
        """`(name, to, drift)` for each changed parameter (one of `to`, `drift` None)."""
        count = len(self.parameters)

        def spread(value):
            if value is None:
                return (None,) * count
            return value if isinstance(value, tuple) else (value,)

        return tuple(zip(self.parameters, spread(self.to), spread(self.drift), strict=True))

    def describe(self) -> str:
        """In words, e.g. `cR to 0.45 at sample 4000`."""
        parts = [
            f"{name} to {to:g}" if to is not None else f"{name} drift {drift:g}/sample"
            for name, to, drift in self.steps()
        ]
        return f"{', '.join(parts)} at sample {self.at}"


def _values(start: float, n: int, at: int, to, drift) -> np.ndarray:
    """One parameter's values at samples 0..n-1, from `start`: a step or a drift at `at`."""
    t = np.arange(n)
    if to is not None:
        return np.where(t >= at, float(to), float(start))
    return float(start) + float(drift) * np.maximum(t - at, 0)


def trajectory(truth: CascadeParams, change: Change, n: int) -> Float[Array, "T P"]:
    """The true parameters at every sample (`Orders.names` order): `truth` with
    `change` applied. A `ValueError` when a parameter is unknown, or the system is
    inadmissible after the change (checked at the record's last sample, and for a drift
    also at every sample: `CascadeParams`' invariants)."""
    names = truth.orders.names
    for name in change.parameters:
        if name not in names:
            raise ValueError(f"change: unknown parameter {name!r}; known: {', '.join(names)}.")
    base = np.asarray(jax.device_get(truth.to_vector()), dtype=float)
    table = np.tile(base, (n, 1))
    for name, to, drift in change.steps():
        column = names.index(name)
        table[:, column] = _values(base[column], n, change.at, to, drift)
    for row in (table[-1],) if change.drift is None else table[:: max(n // 64, 1)]:
        try:
            CascadeParams.from_vector(jnp.asarray(row), truth.orders)
        except ValueError as error:
            what = ", ".join(change.parameters)
            raise ValueError(f"change of {what}: the changed system {error}") from None
    return jnp.asarray(table, dtype=truth.to_vector().dtype)


def trajectory_traced(
    truth_vector: Float[Array, " P"], change: Change, n: int, orders: Orders
) -> Float[Array, "T P"]:
    """`trajectory` inside traced code (the Monte-Carlo engine): the same table from a
    parameter vector, without the checks (the spec made them, `Spec.change`)."""
    dtype = truth_vector.dtype
    t = jnp.arange(n)
    table = jnp.tile(truth_vector, (n, 1))
    for name, to, drift in change.steps():
        column = orders.names.index(name)
        start = truth_vector[column]
        if to is not None:
            values = jnp.where(t >= change.at, jnp.asarray(to, dtype), start)
        else:
            values = start + jnp.asarray(drift, dtype) * jnp.maximum(t - change.at, 0)
        table = table.at[:, column].set(values.astype(dtype))
    return table


def simulate_changing(
    params: Float[Array, "T P"], u: Float[Array, " T"], orders: Orders
) -> Float[Array, " T"]:
    """Noise-free output of the cascade whose parameters at sample t are `params[t]`
    (`Orders.names` order), one `lax.scan` over time. Traceable; with a constant
    trajectory it is `_simulate.simulate`."""
    o = orders
    dtype = u.dtype
    lags = max(o.r, o.p, 1)

    def step(carry, inputs):
        v_past, x_past, y_prev = carry  # v_past[i - 1] = v(t - i), x_past[j - 1] = x(t - j)
        row, u_t = inputs
        p = CascadeParams.from_vector(row.astype(dtype), o, check=False)
        zero = jnp.zeros((1,), dtype)
        DR, DL = jnp.concatenate([zero, p.DR]), jnp.concatenate([zero, p.DL])
        v_t = p.MR @ (heaviside(DR - u_t) * (u_t - DR)) + p.ML @ (heaviside(u_t - DL) * (u_t - DL))
        a = jnp.concatenate([jnp.ones((1,), dtype), p.a])
        x_t = a @ v_past[: o.r] - p.b @ x_past[: o.p]
        g1, g2 = backlash_switches(x_t, y_prev, p.cL, p.mR, p.cR)
        y_t = g1 * (x_t + p.cL) + g2 * p.mR * (x_t - p.cR) + (1 - g1) * (1 - g2) * y_prev
        v_past = jnp.concatenate([v_t[None], v_past[:-1]])
        x_past = jnp.concatenate([x_t[None], x_past[:-1]])
        return (v_past, x_past, y_t), y_t

    zeros = jnp.zeros((lags,), dtype)
    _, y = jax.lax.scan(step, (zeros, zeros, jnp.zeros((), dtype)), (params, u))
    return y
