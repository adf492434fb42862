"""Initialised scoring: a scored record sets the model's state, never its parameters,
from its measured output on the `n` samples before the scored ones.

This is the convention of the nonlinear system-identification benchmarks
(`state_initialization_window_length`) and of MATLAB's `compare`: the model may use the
record's input throughout and its measured output on samples `[start - n, start)`; the
score covers `[start, stop)`.

- `ModelState`: everything an `ExtendedModel` carries from one sample to the next: the
  linear block's past `v` (for the zeros) and `x` (for the poles, eq. 6), the backlash
  output `y(t-1)` (eq. 9), each effect's `EffectState` (stop-operator and rotor
  positions, a Dahl force, past inputs of a delay, the sample index of a drift) and the
  noise model's past residuals. `rest_state` is the state every simulation of the
  package starts from; `simulate_from` continues from any state and returns the state
  before any sample (`at`), so `simulate_from(model, u, rest_state(model, u))` is
  `simulate_with_switches(model, u)` (to rounding: the poles' recursion is the same
  blocked one).
- `initialise`: the state before sample `start - n` fitted to the measured output over
  the `n` samples, by Levenberg-Marquardt on the cascade's state (the linear block's
  past `v` and `x`: together they are its state, of dimension `max(r, p)` in what they
  do to later samples; and the backlash output) and each effect's free state (operator
  positions and forces); an effect's past inputs are the record's (zero before it).
  Starts: the state reached by simulating
  from rest up to `start - n`, and for each effect with positions a grid over their
  admissible range (operators are non-smooth in their state, so a local fit from one
  start can stop at a kink), each also with the backlash output that gives the measured
  output at the first sample (held, the backlash is flat in the linear block's state);
  the best fit is kept. The noise model's innovations over the scored samples use the
  residuals of the `n` initialisation samples as their past. Samples where the system
  hardly moves (an earthquake record's quiet start) do not determine an operator's
  state: fits of many starts match them about equally and score the samples after
  them very differently (`docs/loop.md`, on scoring); a longer `n` that
  reaches motion is the remedy, not a rule among the starts.
- `scored`: NRMSE (`_metrics.score`) over `[start, stop)`, initialised and from rest
  (the whole record simulated from rest, scored on the same samples), and the same for
  the one-step prediction error (the innovations).

Compilation is bounded: one program per model structure, record-length bucket
(`_compile.bucket_length`: the length rounded up to 3 significant bits, the input
padded with its last value) and `n`; the start is a traced index, and an effect enters
as its group's `Choice` (`_effects._choice`: one program for every member).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, Float

from .._compile import exported, pad
from .._estimator._levenberg import least_squares
from .._metrics import score
from .._system._general_backlash import general_backlash
from .._system._model import CascadeParams
from .._system._simulate import _poles_blocked, _poles_scan, backlash_switches, pwl
from ._effects import choose, unchoose_states
from ._effects._base import (
    EffectState,
    ExtendedModel,
    backlash_of,
    output_order,
    recent,
    recursion_terms,
)
from ._effects._recursion import linear_with_terms

# Start positions of each operator in an initial-state fit: fractions of its
# admissible range (0: against the lower limit, 1: the upper one).
GRID = (0.0, 1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6, 1.0)
MAX_STEPS = 60


class CascadeState(eqx.Module):
    """The cascade's state before a sample: `v_past` (`v(t-1) .. v(t-r)`), `x_past`
    (`x(t-1) .. x(t-p)`) and `y_prev` (the backlash output `y(t-1)`)."""

    v_past: Float[Array, " r"]
    x_past: Float[Array, " p"]
    y_prev: Float[Array, ""]


class ModelState(eqx.Module):
    """An `ExtendedModel`'s state before a sample (module docstring): the cascade's,
    one entry per effect (`None` for an effect without state) and the noise model's
    past residuals `e(t-1) .. e(t-q)`."""

    cascade: CascadeState
    effects: tuple[EffectState | None, ...]
    noise: Float[Array, " q"]


def rest_state(model: ExtendedModel, u) -> ModelState:
    """The state every simulation starts from: zero before the record (`u = y = 0` for
    `t <= 0`), operators at rest with no first increment. Needs the record's input `u`
    (an operator's rest takes the input before the record equal to `u(0)`)."""
    o, dtype = model.orders, u.dtype
    cascade = CascadeState(jnp.zeros((o.r,), dtype), jnp.zeros((o.p,), dtype), jnp.zeros((), dtype))
    effects = tuple(effect.rest_state(u) for effect in model.effects)
    return ModelState(cascade, effects, jnp.zeros((model.noise.order,), dtype))


def linear_block_from(params: CascadeParams, v, v_past, x_past):
    """`_simulate.linear_block` continued from the past `v_past`, `x_past` (newest
    first): the past enters as a forcing of the first `max(r, p)` samples, then the same
    (blocked) recursion from zero."""
    o, T = params.orders, v.shape[0]
    a = jnp.concatenate([jnp.ones((1,), v.dtype), params.a.astype(v.dtype)])
    joined = jnp.concatenate([v_past[::-1].astype(v.dtype), v])
    w = sum(a[i - 1] * joined[o.r - i : o.r - i + T] for i in range(1, o.r + 1))
    if o.p == 0:
        return w
    b = params.b.astype(v.dtype)
    # x(t) = w(t) - sum_j b_j x(t-j): the terms with t - j < 0 come from x_past
    for t in range(min(o.p, T)):
        w = w.at[t].add(-sum(b[j - 1] * x_past[j - t - 1] for j in range(t + 1, o.p + 1)))
    block = 64
    return _poles_scan(b, w) if T <= block else _poles_blocked(b, w, block)


def backlash_from(params: CascadeParams, x, y_prev):
    """`_simulate.backlash` from the output `y_prev` before the first sample."""
    cL, mR, cR = (jnp.asarray(c, x.dtype) for c in (params.cL, params.mR, params.cR))

    def step(y_prev, x_t):
        g1, g2 = backlash_switches(x_t, y_prev, cL, mR, cR)
        y_t = g1 * (x_t + cL) + g2 * mR * (x_t - cR) + (1 - g1) * (1 - g2) * y_prev
        return y_t, y_t

    _, y = jax.lax.scan(step, jnp.asarray(y_prev, x.dtype), x)
    return y


def simulate_from(model: ExtendedModel, u, state: ModelState, at=None):
    """Free-run simulation of `model` from `state` (the state before `u(0)`).

    **Returns:** `(y, x, y_cascade, state_at)` as `simulate_with_switches`, plus the
    state before sample `at` (default the record's end; a traced index `0 <= at <= T`
    reads it inside a padded record). The noise past is passed through (it needs the
    measured output: `innovations_from`)."""
    at = u.shape[0] if at is None else at
    u_model = u
    states = list(state.effects)
    for i, effect in enumerate(model.effects):
        u, states[i] = effect.input_with_state(u, states[i], at)
    c = state.cascade
    terms = recursion_terms(model)
    if model.cascade:
        v = pwl(model.params, u)
        if terms:  # a feedback inside the linear block (`_effects._recursion`)
            x = linear_with_terms(model.params, v, terms, c.v_past, c.x_past)
        else:
            x = linear_block_from(model.params, v, c.v_past, c.x_past)
        nd = backlash_of(model)
        if nd is None:
            y_cascade = backlash_from(model.params, x, c.y_prev)
        else:  # an effect's curved backlash (`_effects._curved`)
            y_cascade = general_backlash(nd, x, c.y_prev)
    else:  # an effect replaced the cascade (`ExtendedModel.cascade`): its state stays put
        v, x = jnp.zeros_like(u), u
        y_cascade = jnp.zeros_like(u) + 0 * c.y_prev
    y = y_cascade
    for i in output_order(model.effects):
        effect = model.effects[i]
        y, states[i] = effect.output_with_state(y, x, states[i], at)
        path, states[i] = effect.parallel_with_state(u_model, states[i], at)
        if path is not None:
            y = y + path
    y_prev = jnp.concatenate([jnp.reshape(c.y_prev, (1,)).astype(y.dtype), y_cascade])[at]
    cascade = CascadeState(recent(c.v_past, v, at), recent(c.x_past, x, at), y_prev)
    return y, x, y_cascade, ModelState(cascade, tuple(states), state.noise)


def innovations_from(model: ExtendedModel, residual, past):
    """`ARNoise.innovations` with the residuals before the record `past` (newest first)
    in place of zeros."""
    c = model.noise.coefficients.astype(residual.dtype)
    q, T = model.noise.order, residual.shape[0]
    joined = jnp.concatenate([past[::-1].astype(residual.dtype), residual])
    out = residual
    for i in range(1, q + 1):
        out = out - c[i - 1] * joined[q - i : q - i + T]
    return out


def _free(state: ModelState):
    """The parts of `state` an initial-state fit chooses (module docstring)."""
    effects = tuple(None if s is None else s.free for s in state.effects)
    c = state.cascade
    return (c.v_past, c.x_past, c.y_prev, effects)


def _with_free(state: ModelState, free) -> ModelState:
    v_past, x_past, y_prev, effects = free
    cascade = CascadeState(v_past, x_past, y_prev)
    states = tuple(
        None if s is None else EffectState(f, s.known)
        for s, f in zip(state.effects, effects, strict=True)
    )
    return ModelState(cascade, states, state.noise)


def _starts(model: ExtendedModel, warm: ModelState, grid, y_prev):
    """Starting states: `warm`, and for each effect with a range, `warm` with that
    effect's positions at each grid fraction of it; each of these with the backlash
    output `y_prev` as well (the backlash is non-smooth in it too: held, its output is
    flat in the linear block's state)."""
    starts = [warm]
    for i, (effect, s) in enumerate(zip(model.effects, warm.effects, strict=True)):
        bounds = None if s is None else effect.state_range(s)
        if bounds is None or s.free.size == 0:
            continue
        low, high = bounds
        for fraction in grid:
            states = list(warm.effects)
            states[i] = EffectState(low + fraction * (high - low), s.known)
            starts.append(ModelState(warm.cascade, tuple(states), warm.noise))
    held = [eqx.tree_at(lambda s: s.cascade.y_prev, s, y_prev) for s in starts]
    return starts + held


def _shifted(signal, first):
    """`signal(first + t)` for `t = 0 .. T-1`, its last value repeated past its end."""
    T = signal.shape[0]
    padded = jnp.concatenate([signal, jnp.full((T,), signal[-1], signal.dtype)])
    return jax.lax.dynamic_slice(padded, (first,), (T,))


def _unshifted(signal, first):
    """Inverse of `_shifted`: `signal(t - first)`, NaN before `first`."""
    T = signal.shape[0]
    padded = jnp.concatenate([jnp.full((T,), jnp.nan, signal.dtype), signal])
    return jax.lax.dynamic_slice(padded, (T - first,), (T,))


class _Fit(eqx.Module):
    state: ModelState
    cost: Array
    status: Array
    y: Array  # initialised output, NaN before `first`
    y_from_rest: Array
    innovations: Array  # initialised, NaN before `first`
    innovations_from_rest: Array


@exported
def _initialise(model: ExtendedModel, u, y, first, n: int, grid: tuple, max_steps: int):
    """One compiled program per model structure, padded length, `n` and settings."""
    return _fit(model, u, y, first, n, grid, max_steps)


def _fit(model: ExtendedModel, u, y, first, n: int, grid: tuple, max_steps: int):
    dtype = u.dtype
    rest = rest_state(model, u)
    y_rest, _, y_cascade_rest, warm = simulate_from(model, u, rest, at=first)
    residual_rest = y - y_rest
    u_init = jax.lax.dynamic_slice(u, (first,), (n,))
    y_init = jax.lax.dynamic_slice(y, (first,), (n,))
    # the record's scale (a flat initialisation window has none of its own)
    scale = jnp.std(y) + jnp.finfo(dtype).eps * (1 + jnp.max(jnp.abs(y)))
    z_warm, unravel = ravel_pytree(_free(warm))

    def residual(z, args):
        state = _with_free(warm, unravel(z))
        return (simulate_from(model, u_init, state)[0] - y_init) / scale

    # the backlash output that gives the measured output at `first` with the effects'
    # contributions there from rest
    y_prev = y[first] - (y_rest[first] - y_cascade_rest[first])
    starts = _starts(model, warm, grid, y_prev)
    starts = jnp.stack([ravel_pytree(_free(s))[0] for s in starts])
    z, cost, status, _ = jax.vmap(
        lambda z0: least_squares(residual, z0, None, max_steps=max_steps)
    )(starts)
    best = jnp.argmin(jnp.where(jnp.isfinite(cost), cost, jnp.inf))
    state = _with_free(warm, unravel(z[best]))
    y_shifted = simulate_from(model, _shifted(u, first), state)[0]
    # the noise past before `first` is zero (nothing was simulated before it); the
    # scored samples' innovations use the residuals of the n samples (n >= the order)
    w_shifted = innovations_from(model, _shifted(y, first) - y_shifted, state.noise)
    return _Fit(
        state,
        cost[best] * scale**2,
        status[best],
        _unshifted(y_shifted, first),
        y_rest,
        _unshifted(w_shifted, first),
        innovations_from(model, residual_rest, rest.noise),
    )


@dataclasses.dataclass(frozen=True)
class Initialised:
    """Output of `initialise` (host side).

    - `state`: the fitted state before sample `first = start - n`.
    - `first`, `start`: the first initialisation sample and the first scored one (`start`
      raised to `n` where it was smaller).
    - `y`: the output simulated from `state` over `[first, T)` (NaN before `first`),
      `y_from_rest` the whole record's from rest; `innovations`, `innovations_from_rest`
      the noise model's one-step prediction errors of each (NaN before `first`).
    - `cost`: the mean squared output error over the `n` initialisation samples.
    """

    state: ModelState
    first: int
    start: int
    y: np.ndarray
    y_from_rest: np.ndarray
    innovations: np.ndarray
    innovations_from_rest: np.ndarray
    cost: float


def initialise(
    model: ExtendedModel,
    u,
    y,
    start: int,
    n: int = 50,
    *,
    grid: tuple[float, ...] = GRID,
    max_steps: int = MAX_STEPS,
) -> Initialised:
    """The state before sample `start - n` fitted to the measured output `y` over
    `[start - n, start)` (module docstring); the model's parameters are used, never
    changed. `u`, `y`: one record (1-D, equal lengths)."""
    # on the host, and onto the device padded (`device_put`: an eager `jnp.asarray`
    # compiles a program per shape)
    u = np.asarray(u, jax.dtypes.canonicalize_dtype(np.asarray(u).dtype))
    y = np.asarray(y, u.dtype)
    T = u.shape[0]
    if y.shape != u.shape or u.ndim != 1:
        raise ValueError(
            f"initialise: u and y must be 1-D of equal length, got {u.shape}, {y.shape}."
        )
    if not model.noise.order <= n < T or n < 1:
        raise ValueError(
            f"initialise: n must be at least 1 and the noise model's order "
            f"({model.noise.order}) and below the record's length ({T}), got {n}."
        )
    start = min(max(int(start), n), T)
    first = start - n
    u_padded = jax.device_put(pad(u))
    y_padded = jax.device_put(pad(y))
    # one program for every member of an effect's group in force (`_effects._choice`)
    chosen = choose(model)
    fit = _initialise(
        chosen,
        u_padded,
        y_padded,
        jax.device_put(np.int32(first)),
        n=int(n),
        grid=tuple(float(g) for g in grid),
        max_steps=int(max_steps),
    )
    host = {k: np.asarray(getattr(fit, k))[:T] for k in ("y", "y_from_rest", "innovations")}
    state = fit.state
    state = ModelState(state.cascade, unchoose_states(model, chosen, state.effects), state.noise)
    return Initialised(
        state=state,
        first=first,
        start=start,
        y=host["y"],
        y_from_rest=host["y_from_rest"],
        innovations=host["innovations"],
        innovations_from_rest=np.asarray(fit.innovations_from_rest)[:T],
        cost=float(fit.cost),
    )


@dataclasses.dataclass(frozen=True)
class Scored:
    """Output of `scored`: NRMSE over `[start, stop)` initialised (`error`) and from
    rest (`error_from_rest`), the one-step prediction error's NRMSE both ways
    (`prediction_error`, `prediction_error_from_rest`: the innovations' RMS over the
    measured output's standard deviation), and the fit (`initialised`: its outputs)."""

    start: int
    stop: int
    error: float
    error_from_rest: float
    prediction_error: float
    prediction_error_from_rest: float
    initialised: Initialised

    def to_dict(self) -> dict:
        names = ("start", "stop", "error", "error_from_rest")
        names += ("prediction_error", "prediction_error_from_rest")
        return {name: getattr(self, name) for name in names}


def scored(
    model: ExtendedModel, u, y, start: int, stop: int | None = None, n: int = 50, **options
) -> Scored:
    """Score `model` on `[start, stop)` of the record `(u, y)` initialised from the `n`
    samples before `start` and from rest (module docstring). `start` below `n` is
    raised to `n`; `stop` defaults to the record's end. `options` go to `initialise`."""
    y_host = np.asarray(y, float)
    stop = len(y_host) if stop is None else min(int(stop), len(y_host))
    fit = initialise(model, u, y, start, n, **options)
    start = fit.start
    if stop <= start:
        raise ValueError(f"scored: nothing to score in [{start}, {stop}).")
    window = slice(start, stop)
    measured = y_host[window]
    return Scored(
        start=start,
        stop=stop,
        error=score(measured, fit.y[window]),
        error_from_rest=score(measured, fit.y_from_rest[window]),
        prediction_error=score(measured, measured - fit.innovations[window]),
        prediction_error_from_rest=score(measured, measured - fit.innovations_from_rest[window]),
        initialised=fit,
    )
