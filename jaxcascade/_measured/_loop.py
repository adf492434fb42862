"""The model-error loop: fit, read the residual, add the effect it points to, repeat.

1. Fit the declared cascade on the estimation record (robust estimator).
2. Simulate it free-run on the validation record; test the residual (`_diagnose`).
3. If every test passes, stop: nothing is invented.
4. Otherwise refit the model with each effect of the library added (`_effects`), from
   the current estimate, and score each on the validation record: its NRMSE, and a
   Diebold-Mariano test that its squared simulation errors are smaller than the
   current model's (`_significance`: Newey-West variance, Andrews' bandwidth), since
   the two error series are paired and autocorrelated. The test pools every record
   (`diebold_mariano_records`): the validation record, out of sample, and the
   estimation records, in sample, each record's differences as squared NRMSE. One
   validation record of a measured system carries few independent samples (its errors
   are smooth), and a current model caught in a wrong basin makes its statistic depend
   on that basin; the estimation records are independent experiments of the same
   system. An in-sample gain of `p` added parameters that explain nothing is about
   `sqrt(p) / 2` in the statistic, well under the threshold, and the relative gain is
   still asked of the validation record alone. An effect
   marked `needs_signature` (the hysteresis effects) is tried only when a test of its
   signature failed: never on a record whose hysteresis test passes. A parallel path
   linear in its weights (`Effect.linear`) is fitted by ridge least squares on the
   residual, alternating with refits of the cascade (`fit_parallel`); the others by an
   output-error Levenberg-Marquardt refit of the extended model (`refit`).
5. Among the significant candidates, those whose residual signature matches a failed
   test rank first, then by validation NRMSE; the best is added.
   The noise model cannot lower the simulation error, so it is judged on the one-step-
   ahead prediction error instead (the innovation `w` of `_noise.ARNoise`; before it,
   the simulation error itself): fitted on the estimation records' residuals, it is
   significant when the Diebold-Mariano test of the squared prediction errors on the
   validation record exceeds the same threshold with the same relative gain. A coloured
   residual that no deterministic effect explains gets it when it is significant and
   its whitened residual passes the whiteness and input tests; the residual tests after
   it see the whitened residual.
6. Repeat from 2 while an effect was added (at most `max_effects`).
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import functools
import inspect
import os
import time

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .. import _defaults
from .._compile import bound, compile_count, exported, filter_jit, over_bound, pack
from .._data import Record, Scaling
from .._estimator._efficiency import standard_errors
from .._estimator._levenberg import least_squares
from .._estimator._refine import from_unconstrained, to_unconstrained
from .._estimator._robust import Robust
from .._metrics import score
from .._system._general_backlash import general_switches
from .._system._model import CascadeParams, Orders
from .._system._simulate import backlash_switches
from .._system._validate import record
from ._diagnose import ResidualTests, regime_from_switches, residual_tests
from ._effects import (
    EFFECTS,
    REPLACEMENTS,
    STRUCTURAL,
    Effect,
    ExtendedModel,
    OutputOffset,
    Start,
    backlash_of,
    choose,
    grouping,
    linear_orders,
    padded,
    padded_to,
    plain,
    simulate_padded,
    simulate_with_switches,
    unchoose,
)
from ._effects._choice import choice
from ._initial_state import initialise
from ._loop_checkpoint import (
    Checkpoints,
    identity,
    model_from_dict,
    model_to_dict,
    params_from_dict,
    params_to_dict,
)
from ._noise import ARNoise
from ._oe import OE, cascade_vector, linear_floor
from ._schema import model_schema
from ._significance import (
    BANDWIDTH_RULE,
    TEST_NAME,
    VARIANCE,
    Comparison,
    diebold_mariano,
    diebold_mariano_records,
)

# Compiled once per model structure and record-length bucket (`_compile.bucket_length`:
# the loop simulates the same models on the same records many times, and a record of a
# new length would otherwise compile a new program).
_parallel_jit = filter_jit(lambda effect, u: effect.parallel(u))


def _simulate(model: ExtendedModel, u):
    """`simulate_padded` (one record on the host, padded to its bucket) by the program of
    `model`'s effects' groups (`_effects._choice`), shared by every member."""
    return simulate_padded(choose(model), u)


def simulated_output(model: ExtendedModel, u) -> np.ndarray:
    """The model's output simulated from rest on one record (NumPy)."""
    return _simulate(model, u)[0]


def initialised_output(model: ExtendedModel, u, y, start: int, n: int) -> np.ndarray:
    """The model's output on `[start, T)` of one record, its state before `start - n`
    fitted to the measured output `y` on `[start - n, start)` (`_initial_state.initialise`,
    the nonlinear benchmarks' convention); from rest where `n` is 0 or too short for
    the noise model's past."""
    n = min(int(n), int(start))
    if n < max(1, model.noise.order):
        return simulated_output(model, u)[start:]
    return initialise(model, np.asarray(u, float), np.asarray(y, float), start, n).y[start:]


def _parallel(effect: Effect, u) -> np.ndarray:
    """`effect.parallel(u)` of one record (host side, padded like `_simulate`)."""
    u = np.asarray(u)
    return np.asarray(_parallel_jit(effect, jax.device_put(padded(u))))[: u.shape[0]]


def _records(u, y):
    """`(u, y)` of one record, or sequences of several, as two tuples of arrays."""
    if isinstance(u, list | tuple):
        return tuple(u), tuple(y)
    return (u,), (y,)


def _errors(model: ExtendedModel, groups, integrated: bool = False) -> Array:
    """The one-step prediction errors of `model` on packed records (`pack`; the
    simulation errors for white noise), zero on the padding, one flat array. With
    `integrated` (a loop whose outputs are the differences of a measured output,
    `_integrating`) the errors of the output integrated back: each record's errors
    summed from its start (the measured output's own level there), the criterion the
    loop judges such a model by (`evaluate`)."""

    def one(u, y):
        return model.noise.innovations(simulate_with_switches(model, u)[0] - y)

    parts = [jax.vmap(one)(U, Y) * M for U, Y, M in groups]
    if integrated:
        parts = [jnp.cumsum(e, axis=1) * M for e, (_, _, M) in zip(parts, groups, strict=True)]
    return jnp.concatenate([e.reshape(-1) for e in parts])


# Whether the loop's refits fit the output integrated back (`_errors`): set by a loop
# whose outputs are differences (`integrated_fits`); threads see it in a copy of the
# context, as the groups.
_INTEGRATED = contextvars.ContextVar("jaxcascade_integrated_fits", default=False)


@contextlib.contextmanager
def integrated_fits(on: bool = True):
    """Within the block every refit (`refit_all`) minimises the error of the output
    integrated back (`_errors`): it fits the difference first, then polishes that fit on
    the integrated output."""
    token = _INTEGRATED.set(bool(on))
    try:
        yield
    finally:
        _INTEGRATED.reset(token)


# Input samples kept beyond the outermost breakpoints in a refit (at least this many, and
# 1 % of the samples): a segment fitted on a handful of samples at the record's edge is
# not determined by it (`fit`'s identifiability rule) and extrapolates wildly.
MIN_BEYOND = 10


def breakpoint_bounds(us) -> np.ndarray:
    """`[low, high]`: the range the cascade's breakpoints may take in a refit on the
    records `us`, `MIN_BEYOND` samples (or 1 %) inside the input's extremes; the
    extremes themselves where that side of zero holds too few samples."""
    u = np.sort(np.concatenate([np.asarray(v, float).ravel() for v in us]))
    k = min(max(MIN_BEYOND, u.size // 100), u.size // 4)
    low, high = u[k], u[-k - 1]
    return np.array([low if low < 0 else u[0], high if high > 0 else u[-1]])


def tame_edges(params: CascadeParams, bounds) -> tuple[CascadeParams, list[str]]:
    """`params` with every breakpoint outside `bounds` (`breakpoint_bounds`: too few
    input samples beyond it to determine the segment there) moved just inside and its
    slope change set to zero, so that the segment starts as its neighbour's
    continuation; and the names of the breakpoints moved."""
    values = params.to_dict()
    o = params.orders
    moved = []
    for side, n, limit in (("R", o.nR, float(bounds[1])), ("L", o.nL, float(bounds[0]))):
        outer = [i for i in range(1, n) if abs(values[f"D{side}{i}"]) >= abs(limit)]
        for rank, i in enumerate(outer):
            # spread inside the bound, in order, the outermost nearest it
            values[f"D{side}{i}"] = limit * (1 - 0.01 * (len(outer) - rank))
            values[f"M{side}{i + 1}"] = 0.0
            moved.append(f"D{side}{i}")
    if not moved:
        return params, moved
    vector = jnp.asarray([values[name] for name in o.names], params.mR.dtype)
    return CascadeParams.from_vector(vector, o, check=False), moved


@exported
def _refit(
    vectors,
    new: Effect,
    current: ExtendedModel,
    groups,
    orders: Orders,
    max_steps: int,
    bounds,
    integrated: bool = False,
):
    """Output-error refit of the current model with `new` added, from a batch of starts
    (`vmap` over `vectors` and the leading axis of `new`'s parameters), on the packed
    records `groups` (`pack`), each simulated from its own initial state. The cascade
    is refined in its admissible parameterisation (`_estimator._refine`; breakpoints
    within `bounds`, `breakpoint_bounds`), every effect's
    free parameters alongside; fixed ones (`Effect.fixed`) are held. Without the cascade
    (`ExtendedModel.cascade` False) only the effects are refined."""
    dtype = groups[0][0].dtype
    u_min, u_max = bounds[0].astype(dtype), bounds[1].astype(dtype)
    size = orders.size if current.cascade else 0

    def one(vector, effect):
        effects = current.effects + (effect,)
        free, fixed = eqx.partition(effects, tuple(e.free_filter() for e in effects))
        flat, unravel = jax.flatten_util.ravel_pytree(free)
        params = CascadeParams.from_vector(vector, orders, check=False)
        cascade = to_unconstrained(params, u_min, u_max)[:size]
        z0 = jnp.concatenate([cascade, flat.astype(dtype)])

        def unpack(z):
            fitted = from_unconstrained(z[:size], orders, u_min, u_max) if size else params
            effects = eqx.combine(unravel(z[size:]), fixed)
            return current.with_(params=fitted, effects=tuple(effects))

        def residual(z, integrate):
            # With a noise model the fit minimises the one-step prediction error (its
            # innovation; the simulation error itself for white noise).
            return _errors(unpack(z), groups, integrate)

        z, cost, status, _ = least_squares(residual, z0, False, max_steps=max_steps)
        if integrated:
            # the output integrated back: its errors sum every earlier sample's, a
            # criterion far from quadratic away from its minimum, so it is polished from
            # the fit of the difference, which starts it in the right basin
            z, cost, status, _ = least_squares(residual, z, True, max_steps=max_steps)
        return unpack(z), cost, status

    # every parameter of `new` has the starts' leading axis; a scalar (a `Choice`'s
    # index) is shared by them, so that only its member's branch runs
    axes = jax.tree_util.tree_map(lambda leaf: 0 if jnp.ndim(leaf) else None, new)
    return eqx.filter_vmap(one, in_axes=(0, axes))(vectors, new)


def refit_all(model: ExtendedModel, start: Start, u, y, max_steps: int = 150):
    """Add `start.effect` to `model` from each of the starts `start`. `u`, `y`: one
    record, or sequences of records fitted jointly. Returns `(models, costs, status)`
    batched over the starts, `costs` on the host with `inf` where not finite, and the
    starts' indices from the lowest cost up (`order`, stable: the first of equal
    costs first) as a fourth element."""
    us, ys = _records(u, y)
    groups = pack(us, ys)
    dtype = groups[0][0].dtype
    effect = jax.tree_util.tree_map(lambda leaf: jnp.asarray(leaf, dtype), start.effect)
    bounds = jax.device_put(breakpoint_bounds(us).astype(dtype))
    # one program for every member of the effects' groups in force (`_effects._choice`)
    models, costs, status = _refit(
        jax.device_put(np.asarray(start.vectors, dtype)),
        choice(effect),
        model,
        groups,
        start.orders,
        max_steps,
        bounds,
        _INTEGRATED.get(),
    )
    models = unchoose(models)
    costs = np.asarray(costs)
    costs = np.where(np.isfinite(costs), costs, np.inf)
    return models, costs, np.asarray(status), np.argsort(costs, kind="stable")


def one_start(models, index: int):
    """Start `index`'s model of `refit_all`'s batch, indexed on the host (an eager
    `leaf[index]` compiles a program per leaf shape)."""
    return jax.tree_util.tree_map(lambda leaf: jax.device_put(np.asarray(leaf)[index]), models)


def refit(model: ExtendedModel, start: Start, u, y, max_steps: int = 150):
    """Add `start.effect` to `model` from the starts `start`; the best start wins (host
    side). `u`, `y`: one record, or sequences of records fitted jointly. Returns
    `(model, cost, status)`."""
    models, costs, status, order = refit_all(model, start, u, y, max_steps)
    best = int(order[0])
    return one_start(models, best), float(costs[best]), int(status[best])


def refined(model: ExtendedModel, u, y, max_steps: int = 150) -> ExtendedModel:
    """`model` refitted from its own estimates, its structure kept (`refit` with a start
    that adds nothing, `_no_effect`)."""
    refitted, _, _ = refit(model, _no_effect(model.params), u, y, max_steps)
    return refitted.with_(effects=refitted.effects[:-1])


def fit_parallel(model: ExtendedModel, effect_class, u, y, alternations: int = 1):
    """Add a parallel path linear in its weights (`Effect.linear`) to `model`: its
    weights by ridge least squares on the residual of the current model (structure by
    cross-validation over the records, `effect_class.fit_records`), then `alternations`
    times a refit of the model (cascade and earlier effects) on the output minus the
    path, and a new ridge fit on the new residual. `u`, `y`: one record or sequences of
    records. Returns `(model, cost, label)`, `cost` the mean squared error over the
    records."""
    us, ys = _records(u, y)
    us = tuple(np.asarray(v, float) for v in us)
    ys = tuple(np.asarray(v, float) for v in ys)
    current = model

    def residuals(current):
        return [(v, w, w - _simulate(current, v)[0]) for v, w in zip(us, ys, strict=True)]

    effect, label = effect_class.fit_records(current, residuals(current))
    for _ in range(alternations):
        targets = tuple(w - _parallel(effect, v) for v, w in zip(us, ys, strict=True))
        if not current.cascade and not current.effects:
            break  # nothing to refit under the path
        current = refined(current, us, targets)
        effect, label = effect_class.fit_records(current, residuals(current))
    final = current.with_(effects=(*current.effects, effect))
    errors = np.concatenate([w - _simulate(final, v)[0] for v, w in zip(us, ys, strict=True)])
    return final, float(np.mean(errors**2)), label


@exported
def _standard_errors(model: ExtendedModel, groups):
    """`_efficiency.standard_errors` of `model` on packed records (`pack`): the masked
    simulation of every group, each record whitened apart."""
    effects = model.effects
    free, fixed = eqx.partition(effects, tuple(e.free_filter() for e in effects))
    flat, unravel = jax.flatten_util.ravel_pytree(free)
    size = model.orders.size if model.cascade else 0
    dtype = groups[0][0].dtype
    theta = jnp.concatenate([model.params.to_vector().astype(dtype)[:size], flat.astype(dtype)])
    lengths = [int(M.shape[1]) for _, _, M in groups]
    rows = [int(M.shape[0]) for _, _, M in groups]

    def simulate_theta(theta):
        params = (
            CascadeParams.from_vector(theta[:size], model.orders, check=False)
            if size
            else model.params
        )
        effects = tuple(eqx.combine(unravel(theta[size:]), fixed))
        extended = model.with_(params=params, effects=effects)
        out = [
            jax.vmap(lambda u: simulate_with_switches(extended, u)[0])(U) * M for U, _, M in groups
        ]
        return jnp.concatenate([o.reshape(-1) for o in out])

    def whiten(residual):
        parts, at = [], 0
        for count, length in zip(rows, lengths, strict=True):
            block = residual[at : at + count * length].reshape(count, length)
            parts.append(jax.vmap(model.noise.innovations)(block).reshape(-1))
            at += count * length
        return jnp.concatenate(parts)

    y = jnp.concatenate([(Y * M).reshape(-1) for _, Y, M in groups])
    return standard_errors(simulate_theta, theta, y, whiten=whiten)[0]


def model_standard_errors(model: ExtendedModel, u, y) -> dict[str, float]:
    """Estimated standard errors of every estimated parameter of `model` on the record
    `(u, y)`, or on several records (sequences of arrays, each simulated from its own
    initial state and whitened apart): the cascade's (`Orders.names`) and each effect's
    free parameters (`EFFECT.field`), from the output-error information at the estimate
    with the noise model's whitening (`_efficiency.standard_errors`). A parameter the
    records do not determine has an infinite error."""
    us, ys = _records(u, y)
    groups = pack(us, ys)
    errors = np.asarray(_standard_errors(model, groups), float)
    # `standard_errors` divides by N - P with N counting the padding (zeros in the
    # residual and the Jacobian): rescale to the records' own samples.
    padded = sum(int(M.size) for _, _, M in groups)
    own = sum(int(np.shape(v)[0]) for v in us)
    errors = errors * np.sqrt(max(padded - errors.size, 1) / max(own - errors.size, 1))
    return dict(zip(model_estimates(model), np.asarray(errors, float).tolist(), strict=True))


def model_estimates(model: ExtendedModel) -> dict[str, float]:
    """Every estimated parameter of `model` by the names of `model_standard_errors`: the
    cascade's (`Orders.names`) and each effect's free parameters (`EFFECT.field`, an
    array's entries `EFFECT.field[i]`)."""
    values = dict(model.params.to_dict()) if model.cascade else {}
    values = {k: float(v) for k, v in values.items()}
    for effect in model.effects:
        for field in dataclasses.fields(effect):
            if field.name not in effect.fixed:
                value = np.ravel(np.asarray(getattr(effect, field.name), float))
                suffixes = [""] if value.size == 1 else [f"[{i}]" for i in range(value.size)]
                for k, v in zip(suffixes, value, strict=True):
                    values[f"{effect.name}.{field.name}{k}"] = float(v)
    return values


@dataclasses.dataclass
class Evaluation:
    """A model on the validation record: the simulation residual and its NRMSE (`error`),
    the one-step-ahead prediction error (`innovation`, the residual whitened by the
    model's noise model; the residual itself with white noise) and its NRMSE
    (`prediction_error`), and the residual tests (on the innovation)."""

    residual: np.ndarray
    simulated: np.ndarray
    error: float
    tests: ResidualTests
    window_error: float | None = None
    innovation: np.ndarray | None = None
    prediction_error: float | None = None
    # where the outputs are differences of the measured output (`integrating`): the
    # residual of the output integrated back, each scored part summed from its start
    integrated_residual: np.ndarray | None = None


def evaluate(
    model: ExtendedModel,
    u,
    y,
    sample_period: float = 1.0,
    window: tuple[int, int] | None = None,
    init_samples: int = 0,
    integrating: bool = False,
) -> Evaluation:
    """The model on the validation record. With `init_samples = n > 0` the model's
    state is set from the measured output on the first `n` samples (`initialised_output`)
    and everything is judged on the samples after them (the window: its state set on the
    `n` samples before it); from rest otherwise. `simulated` is the from-rest output.

    `u`, `y` may be lists of several validation records: each is simulated and
    initialised on its own, and the scored parts are joined end to end for the pooled
    NRMSE (normalised by the variance of the joined output), the residual tests (whose
    correlations then also span the joins: `max_lag` of the record's total length) and
    the significance test; `window` then applies to none (a `ValueError` otherwise).
    One record is judged exactly as before.

    `integrating`: the records' outputs are differences of the measured output
    (`_integrating`), and `error` and `window_error` are the NRMSE of the output
    integrated back (each scored part summed from its start, where its level is set
    from the measured output): the figure the model is scored by, so that an effect is
    kept only where it lowers the error of the measured output, not only of its
    difference. The residual, its tests and the prediction error stay on the
    difference."""
    us, ys = _records(u, y)
    if len(us) > 1 and window is not None:
        raise ValueError("evaluate: a window applies to one validation record, not several.")
    n = int(init_samples)
    parts = []
    for u_r, y_r in zip(us, ys, strict=True):
        y_sim, x, y_cascade = _simulate(model, u_r)
        u_r, y_r = np.asarray(u_r), np.asarray(y_r)
        p = model.params
        previous = np.concatenate([np.zeros(1, y_cascade.dtype), y_cascade[:-1]])
        nd = backlash_of(model)
        if nd is None:
            g1, g2 = backlash_switches(x, previous, float(p.cL), float(p.mR), float(p.cR))
        else:
            g1, g2 = general_switches(nd, jnp.asarray(x), jnp.asarray(previous))
        regime = regime_from_switches(np.asarray(g1), np.asarray(g2))
        window_sim = None
        if n > 0:
            scored = initialised_output(model, u_r, y_r, n, n)
            if window is not None:
                start, stop = window
                window_sim = initialised_output(model, u_r, y_r, start, n)[: stop - start]
        else:
            scored = y_sim
            window_sim = None if window is None else y_sim[slice(*window)]
        residual = y_r[n:] - scored
        parts.append(
            (u_r[n:], y_r[n:], residual, regime[n:], y_sim, window_sim, scored, y_cascade[n:])
        )
    join = (lambda arrays: arrays[0]) if len(parts) == 1 else np.concatenate
    u_s, y_s, residual, regime, y_sim = (join([q[k] for q in parts]) for k in range(5))
    scored = join([q[6] for q in parts])
    level = join([q[7] for q in parts])
    innovations = join([innovations_np(model.noise, q[2]) for q in parts])
    integrated_residual = None
    if integrating:
        measured = join([np.cumsum(q[1]) for q in parts])
        integrated = join([np.cumsum(q[6]) for q in parts])
        error = score(measured, integrated)
        integrated_residual = measured - integrated
    else:
        error = score(y_s, scored)
    tests = residual_tests(
        u_s,
        innovations,
        regime,
        sample_period=sample_period,
        level=level if model.cascade else None,
        **test_sizes(len(residual)),
    )
    window_error = None
    if window is not None:
        as_scored = np.cumsum if integrating else np.asarray
        window_error = score(as_scored(np.asarray(ys[0])[slice(*window)]), as_scored(parts[0][5]))
    prediction_error = score(y_s, y_s - innovations)
    return Evaluation(
        residual,
        y_sim,
        error,
        tests,
        window_error,
        innovations,
        prediction_error,
        integrated_residual,
    )


def test_sizes(n: int) -> dict:
    """The residual tests' lags, input-level bins and time blocks for `n` scored samples:
    20 lags and 10 bins and blocks (`residual_tests`' defaults) from 80 samples on, fewer
    on a shorter record (a quarter of it in lags, half in bins and blocks), so that a
    benchmark's short test record is still diagnosed; `ResidualTests.max_lag` says which."""
    return {
        "max_lag": int(max(1, min(20, n // 4))),
        "n_bins": int(max(2, min(10, n // 2))),
        "n_blocks": int(max(2, min(10, n // 2))),
    }


def innovations_np(noise: ARNoise, residual) -> np.ndarray:
    """`ARNoise.innovations` on the host (NumPy), for records of any length."""
    residual = np.asarray(residual, float)
    out = residual.copy()
    for i, c in enumerate(np.asarray(noise.coefficients, float), start=1):
        out[i:] -= c * residual[:-i]
    return out


def paired_improvement(current: np.ndarray, new: np.ndarray) -> float:
    """Diebold-Mariano statistic that `new` has smaller squared errors than `current`
    (`_significance.diebold_mariano`: Newey-West variance, Andrews' bandwidth)."""
    return diebold_mariano(current, new).statistic


@dataclasses.dataclass
class Candidate:
    """One effect tried in one round. `t` is the Diebold-Mariano statistic of
    `comparison` (simulation loss for an effect, prediction loss for the noise model)."""

    round: int
    name: str
    label: str
    error: float
    t: float
    significant: bool
    signature_match: bool
    model: ExtendedModel | None = None
    evaluation: Evaluation | None = None
    comparison: Comparison | None = None
    action: str = "add"  # or "replace": the effect replaces the cascade
    # an effect's Diebold-Mariano statistic on the validation record alone (`t` pools it
    # with the estimation records' in-sample differences); the noise model's `t` is this
    t_validation: float | None = None

    def to_dict(self) -> dict:
        e, c = self.evaluation, self.comparison
        return {
            "round": self.round,
            "name": self.name,
            "action": self.action,
            "structure": None if self.model is None else self.model.structure(),
            "variant": self.label,
            "error": self.error,
            "prediction_error": None if e is None else e.prediction_error,
            "t": self.t,
            "t_validation": self.t if self.t_validation is None else self.t_validation,
            "loss": None if c is None else c.loss,
            "bandwidth": None if c is None else c.bandwidth,
            "p_value": None if c is None else c.p_value,
            "significant": self.significant,
            "signature_match": self.signature_match,
            "window_error": None if e is None else e.window_error,
        }


@dataclasses.dataclass
class LoopResult:
    """What `model_error_loop` returns: the declared cascade and the final model, each
    judged on the validation record, and what every round tried.

    - `before`, `after`: the declared cascade's and the final model's `Evaluation` on the
      validation record(s): the simulation residual and NRMSE (`error`, initialised on
      `init_samples` samples where they are > 0), the one-step prediction NRMSE, the
      residual tests.
    - `base`, `final`: the declared cascade (as fitted) and the final model
      (`ExtendedModel`, model units); `added`: the effects added, in order; `actions`:
      what each round did (`{"effect", "action" ("add" or "replace"), "round"}`), then
      each effect the backward step took out (`"remove"`, `_prune`) and the linear
      floor's replacement (`"floor"`).
    - `candidates`: every `Candidate` tried, with its score and significance test;
      `steps`: `(label, model, evaluation)` of each step on the validation record.
    - `t_threshold`, `min_gain`: the significance rule the loop applied.
    - `standard_errors`: the final model's standard errors on the estimation records
      (`model_standard_errors`, model units).
    - `programs_compiled`: programs XLA compiled during the loop.
    - `scaling`: the records' units (`_data.Scaling`; the identity for arrays), in which
      `to_dict` writes the models (`_schema`).

    `warnings` says when the final model is worse than the mean of the output on the
    validation record; `to_dict()` is the loop's part of the command's JSON.
    """

    before: Evaluation
    after: Evaluation
    base: ExtendedModel
    final: ExtendedModel
    added: list[str]
    candidates: list[Candidate]
    steps: list[tuple[str, ExtendedModel, Evaluation]] = dataclasses.field(default_factory=list)
    t_threshold: float = _defaults.DM_THRESHOLD
    min_gain: float = _defaults.MIN_GAIN
    # the final model's estimated standard errors on the estimation records
    # (`model_standard_errors`)
    standard_errors: dict[str, float] = dataclasses.field(default_factory=dict)
    # programs XLA compiled during the loop (`_compile.compile_count`)
    programs_compiled: int = 0
    # what each round did: `{"effect", "action" ("add" or "replace"), "round"}`
    actions: list[dict] = dataclasses.field(default_factory=list)
    # the linear output-error model of the loop's records (`Floor`), or None
    floor: Floor | None = None
    scaling: Scaling = dataclasses.field(default_factory=Scaling)

    @property
    def warnings(self) -> list[str]:
        """One sentence where the final model is worse than the mean of the output
        (NRMSE above 1) on the validation record(s), else none (the command's verdict
        against the ARX peer as well: `loop_records`)."""
        if not self.after.error > 1.0:
            return []
        return [
            f"The final model is worse than the mean of the output (NRMSE 1) on the "
            f"validation record (NRMSE {self.after.error:.3f}): its structure does not "
            "describe this system, or the records do not cover the input where it was "
            "scored."
        ]

    def __repr__(self) -> str:
        added = ", ".join(self.added) or "nothing"
        rounds = max((c.round for c in self.candidates), default=0)
        warned = f"; {len(self.warnings)} warning(s)" if self.warnings else ""
        return (
            f"LoopResult({self.final.structure()!r}; added {added}; validation NRMSE "
            f"{self.before.error:.4g} -> {self.after.error:.4g}; {len(self.candidates)} "
            f"candidates in {rounds} round(s){warned})"
        )

    def to_dict(self) -> dict:
        """The loop's figures, decisions, candidates and residual tests; the declared
        cascade (`model_before`) and the final model with its standard errors
        (`model_after`) in the schema (`_schema.model_schema`, the records' units)."""
        return {
            "error_before": self.before.error,
            "error_after": self.after.error,
            "prediction_error_before": self.before.prediction_error,
            "prediction_error_after": self.after.prediction_error,
            "window_error_before": self.before.window_error,
            "window_error_after": self.after.window_error,
            "effect_added": list(self.added),
            "actions": list(self.actions),
            "structure_before": self.base.structure(),
            "structure_after": self.final.structure(),
            "significance": {
                "test": TEST_NAME,
                "statistic": (
                    "DM = sum_r N_r mean(d_r) / sqrt(sum_r N_r S_r), d_r = (e_current^2 -"
                    " e_candidate^2) / var(y_r), pooled over the validation record and the"
                    " estimation records (in sample) for an effect; the validation record's"
                    " prediction error alone for the noise model"
                ),
                "variance": VARIANCE,
                "bandwidth_rule": BANDWIDTH_RULE,
                "threshold": self.t_threshold,
                "min_gain": self.min_gain,
                "loss": {"effects": "simulation", ARNoise.name: "prediction"},
            },
            "steps": [
                {
                    "model": label,
                    "error": e.error,
                    "prediction_error": e.prediction_error,
                    "window_error": e.window_error,
                }
                for label, _, e in self.steps
            ],
            "candidates": [
                {"name": c.name, "error": c.error, **c.to_dict()} for c in self.candidates
            ],
            "residual_tests": {
                "before": self.before.tests.to_dict(arrays=False),
                "after": self.after.tests.to_dict(arrays=False),
            },
            "model_before": model_schema(self.base, self.scaling),
            "model_after": model_schema(self.final, self.scaling, self.standard_errors),
            "programs_compiled": self.programs_compiled,
            "linear_floor": None
            if self.floor is None
            else {
                "model": self.floor.label,
                "orders": {"nb": self.floor.oe.orders[0], "nf": self.floor.oe.orders[1]},
                "b": np.asarray(self.floor.oe.b).tolist(),
                "f": np.asarray(self.floor.oe.f).tolist(),
                "offset": float(self.floor.oe.c),
                "validation_error_from_rest": self.floor.host_error,
            },
        }


# The loop's name for the linear output-error model (`_oe`) as a candidate in place of
# the cascade, and in its reports.
LINEAR_FLOOR = "linear_floor"
# The linear model is scored by the loop's programs (as a start of the declared fit, a
# candidate, the floor under the final model) only where its host-side validation error
# (`_oe.validation_error`, from rest) is below this factor times the current model's:
# elsewhere it cannot be the better model, and costs no program.
FLOOR_MARGIN = 1.05


@dataclasses.dataclass(frozen=True)
class Floor:
    """The loop's linear floor: the output-error model (`_oe.OE`), its host-side
    validation error (from rest), and its cascade form (`ExtendedModel`: one input
    segment a side of equal slopes, no backlash gap, an output offset)."""

    oe: OE
    host_error: float
    model: ExtendedModel

    @property
    def label(self) -> str:
        nb, nf = self.oe.orders
        return f"{LINEAR_FLOOR}:OE({nb},{nf})"


def floor_model(oe: OE, dtype=None) -> ExtendedModel:
    """The output-error model `oe` as an `ExtendedModel`: the cascade of orders
    `(1, 1, nb, nf)` of `_oe.cascade_vector` plus its offset (`OutputOffset`)."""
    dtype = dtype or jnp.result_type(float)
    orders = Orders(1, 1, *oe.orders)
    vector = np.asarray(cascade_vector(oe, orders), dtype)
    params = jax.tree_util.tree_map(
        jax.device_put, CascadeParams.from_vector(vector, orders, check=False)
    )
    offset = OutputOffset(jax.device_put(np.asarray(oe.c, dtype)))
    return ExtendedModel(params, (offset,), ARNoise.white(dtype))


def _floor(us, ys, u_vals, y_vals, init_samples, integrating) -> Floor | None:
    """The linear floor of a loop's records (`_oe.linear_floor`), or None where no stable
    output-error model fits them or none has the cascade's form (no gain at lag 1)."""
    try:
        oe, error = linear_floor(
            [np.asarray(u, float) for u in us],
            [np.asarray(y, float) for y in ys],
            [np.asarray(u, float) for u in u_vals],
            [np.asarray(y, float) for y in y_vals],
            skip=int(init_samples),
            integrating=integrating,
        )
    except (ValueError, np.linalg.LinAlgError):
        return None
    if cascade_vector(oe, Orders(1, 1, *oe.orders)) is None:
        return None
    return Floor(oe, float(error), floor_model(oe, np.asarray(us[0]).dtype))


def _host_error(model: ExtendedModel, u_vals, y_vals, init_samples, integrating) -> float:
    """`model`'s free-run validation NRMSE from rest, the first `init_samples` of each
    record left out (as `_oe.validation_error` scores the linear floor)."""
    sims, meas = [], []
    n = int(init_samples)
    for u, y in zip(u_vals, y_vals, strict=True):
        s, y = simulated_output(model, u), np.asarray(y, float)
        if integrating:
            s, y = np.cumsum(s), np.cumsum(y)
        sims.append(s[n:])
        meas.append(y[n:])
    s, y = np.concatenate(sims), np.concatenate(meas)
    return float(np.sqrt(np.mean((s - y) ** 2)) / (np.std(y) + 1e-300))


def _is_records(value) -> bool:
    """A `Record` or a non-empty list or tuple of them."""
    if isinstance(value, Record):
        return True
    return (
        isinstance(value, list | tuple)
        and bool(value)
        and all(isinstance(v, Record) for v in value)
    )


def _arrays_of(args: tuple, kwargs: dict) -> tuple[tuple, dict]:
    """`model_error_loop(estimation, validation, orders, ...)` with `Record`s as its
    array form `(u_est, y_est, u_val, y_val, orders, ...)`: the records' arrays (model
    units), their scaling for the result and, unless given, their sample period."""
    if not args or not _is_records(args[0]):
        return args, kwargs
    estimation, validation, *rest = args
    if not _is_records(validation):
        raise ValueError(
            "model_error_loop: with estimation Records, the validation record(s) must be "
            "Records too (model_error_loop(estimation, validation, orders))."
        )
    train = [estimation] if isinstance(estimation, Record) else list(estimation)
    valid = [validation] if isinstance(validation, Record) else list(validation)
    scalings = {r.scaling for r in (*train, *valid)}
    if len(scalings) > 1:
        raise ValueError(
            "model_error_loop: the records are in different scalings; read the validation "
            "records with scaling=estimation.scaling (read_record, record_from_arrays)."
        )
    orders = rest[0] if rest else kwargs.pop("orders", Orders.parse(_defaults.ORDERS))
    kwargs.setdefault("scaling", train[0].scaling)
    period = next((r.sample_period for r in valid if r.sample_period), None)
    if period is not None:
        kwargs.setdefault("sample_period", period)

    def arrays(records):
        if len(records) == 1:
            return records[0].u, records[0].y
        return [r.u for r in records], [r.y for r in records]

    return (*arrays(train), *arrays(valid), orders, *rest[1:]), kwargs


def _grouped(loop):
    """`loop` with the groups of the effects it may try in force (`_effects._choice`):
    members of one group are fitted and scored by one program; and its records'
    simulations padded to one length (`_effects.padded_to`): one program per structure
    for every record. `Record`s given in place of arrays are taken apart first
    (`_arrays_of`)."""

    signature = inspect.signature(loop)

    @functools.wraps(loop)
    def run(*args, effects: tuple[str, ...] | None = None, **kwargs):
        args, kwargs = _arrays_of(args, kwargs)
        names = tuple(effects or EFFECTS)
        # every record of the loop simulated by one program per structure (`padded_to`)
        given = signature.bind_partial(*args, **kwargs).arguments
        records = (
            *_records(given["u_est"], given["y_est"])[0],
            *_records(given["u_val"], given["y_val"])[0],
        )
        # a record that is not 1-D is refused by the loop's own checks, with its name
        lengths = [np.shape(u)[0] for u in records if np.ndim(u) == 1]
        with (
            grouping([EFFECTS[name] for name in names if name in EFFECTS], EFFECTS.values()),
            padded_to(lengths),
            integrated_fits(bool(given.get("integrating", False))),
        ):
            return loop(*args, effects=effects, **kwargs)

    return run


@_grouped
def model_error_loop(
    u_est,
    y_est,
    u_val,
    y_val,
    orders: Orders | None = None,
    *,
    base: CascadeParams | None = None,
    max_effects: int = _defaults.MAX_EFFECTS,
    t_threshold: float = _defaults.DM_THRESHOLD,
    min_gain: float = _defaults.MIN_GAIN,
    noise_alpha: float = 1e-3,
    sample_period: float = 1.0,
    effects: tuple[str, ...] | None = None,
    window: tuple[int, int] | None = None,
    progress=None,
    robust: Robust | None = None,
    key=None,
    init_samples: int | None = None,
    integrating: bool = False,
    checkpoints: Checkpoints | None = None,
    threads: int | None = None,
    scaling: Scaling | None = None,
) -> LoopResult:
    """Run the loop (module docstring) on estimation and validation records; the
    defaults are the command's (`_defaults`, docs/defaults.md).

    Two forms: `model_error_loop(estimation, validation, orders=None, ...)` with `Record`s
    (one or a list each, in one scaling: `read_record`, `record_from_arrays`; their
    arrays are in model units, their sample period and scaling taken along), or
    `model_error_loop(u_est, y_est, u_val, y_val, orders=None, ...)` with arrays.
    `loop_records` runs the whole command (the ARX peer, scoring, test records, the
    report) on records.

    **Arguments:**

    - `u_est`, `y_est`, `u_val`, `y_val`: 1-D arrays (model units); the estimation
      records together at least `orders.min_samples` long (`check_lengths`), the
      validation record `init_samples + MIN_SCORED` (`check_scored_length`: it is
      simulated, not fitted); a `ValueError` otherwise. `u_est`,
      `y_est` may be lists of several estimation records, estimated jointly (each
      simulated from its own initial state; the declared cascade's first fit is on the
      records joined end to end, then refined on each). `u_val`, `y_val` may be lists
      of several validation records, each scored on its own and pooled (`evaluate`).
    - `orders`: declared orders of the cascade (default `_defaults.ORDERS`, 2,2,2,2).
    - `base`: a fitted cascade to start from; by default the robust estimator fits one.
    - `t_threshold`, `min_gain`: a candidate is significant when its Diebold-Mariano
      statistic (`_significance`; an effect's pooled over the validation and the
      estimation records) exceeds `t_threshold` and it lowers the validation NRMSE by at
      least `min_gain` (relative): the simulation NRMSE for an effect, the one-step
      prediction NRMSE for the noise model.
    - `noise_alpha`: level of the likelihood-ratio test of the noise model against white
      noise on the estimation records (a further condition for it).
    - `effects`: names of the library to consider (default: all).
    - `window`: `(start, stop)` samples of the validation record also scored
      (`Evaluation.window_error`).
    - `init_samples`: with `n > 0` every model is judged on the validation record with
      its state set from the measured output on the first `n` samples (`evaluate`), the
      nonlinear benchmarks' convention, and on the samples after them; 0 from rest;
      None (the default) the command's rule, `_defaults.init_samples` of the validation
      records' lengths (50, at most a quarter of the shortest).
    - `integrating`: the records' outputs are differences of a measured output that
      integrates its input (`_integrating`): every validation NRMSE, and so every
      decision, is of the output integrated back (`evaluate`).
    - `robust`, `key`: the estimator of the declared cascade (default `Robust()`) and its
      PRNG key (the multi-start's draws; default `PRNGKey(0)`).
    - `checkpoints`: where the loop keeps its work (`_loop_checkpoint.Checkpoints`): every
      finished fit and round is written there as it finishes, and a resumed run loads
      the finished fits instead of refitting them (same decisions, estimates and
      errors); it also keeps where the loop is (`Checkpoints.where`) for an interrupted
      run's report. Progress (`progress`) says the round, the candidate, the time
      elapsed and an estimate of the round's remaining time.
    - `threads`: candidates of a round fitted at once (`_Workers`); the results are the
      same for any number (default `default_threads()`, as the command).
    - `scaling`: the records' units (`_data.Scaling`), in which `LoopResult.to_dict`
      writes the models; the `Record`s' own where given, else the identity.
    """
    if orders is None:
        orders = Orders.parse(_defaults.ORDERS)
    if threads is None:
        threads = default_threads()
    scaling = Scaling() if scaling is None else scaling
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"model_error_loop: threads must be an integer >= 1, got {threads!r}.")
    say = progress or (lambda message: None)
    store = Checkpoints() if checkpoints is None else checkpoints
    started = time.monotonic()
    compiled_before = compile_count()
    us, ys = _records(u_est, y_est)
    if len(us) != len(ys):
        raise ValueError(f"model_error_loop: {len(us)} input records but {len(ys)} outputs.")
    pairs = [
        record(u, y, where=f"model_error_loop (estimation record {i + 1})")
        for i, (u, y) in enumerate(zip(us, ys, strict=True))
    ]
    us, ys = tuple(p[0] for p in pairs), tuple(p[1] for p in pairs)
    check_lengths([int(u.shape[0]) for u in us], orders, where="model_error_loop")
    u_vals, y_vals = _records(u_val, y_val)
    if len(u_vals) != len(y_vals):
        raise ValueError(
            f"model_error_loop: {len(u_vals)} validation inputs but {len(y_vals)} outputs."
        )
    several = len(u_vals) > 1
    checked = [
        record(
            u,
            y,
            where=f"model_error_loop (validation record {i + 1})"
            if several
            else "model_error_loop (validation)",
        )
        for i, (u, y) in enumerate(zip(u_vals, y_vals, strict=True))
    ]
    if init_samples is None:  # the command's default window (`_defaults.init_samples`)
        init_samples = _defaults.init_samples(int(u.shape[0]) for u, _ in checked)
    for i, (u, _) in enumerate(checked):
        where = f"validation record {i + 1}" if several else "validation"
        check_scored_length(int(u.shape[0]), init_samples, f"model_error_loop ({where})")
    if several and window is not None:
        raise ValueError(
            "model_error_loop: a window applies to one validation record, not several."
        )
    u_val_np = [np.asarray(u, float) for u, _ in checked]
    y_val_np = [np.asarray(y, float) for _, y in checked]
    if not several:
        u_val_np, y_val_np = u_val_np[0], y_val_np[0]
    # the scored samples of every validation record, joined (the pooled NRMSE's scale)
    scored_val = np.concatenate([y[int(init_samples) :] for _, y in checked])

    def assess(model):
        return evaluate(model, u_val_np, y_val_np, sample_period, window, init_samples, integrating)

    names = tuple(effects or (*EFFECTS, ARNoise.name))
    options = {
        "orders": str(orders),
        "base": None if base is None else np.asarray(base.to_vector()).tolist(),
        "max_effects": int(max_effects),
        "t_threshold": float(t_threshold),
        "min_gain": float(min_gain),
        "noise_alpha": float(noise_alpha),
        "sample_period": float(sample_period),
        "effects": list(names),
        "window": None if window is None else [int(w) for w in window],
        "init_samples": int(init_samples),
        "robust": _settings(Robust() if robust is None else robust),
        "key": None if key is None else _key_data(key),
        "records": len(us),
    }
    if several:  # a single record's identity as before (its checkpoints stay valid)
        options["validation_records"] = len(checked)
    if integrating:  # likewise: only a loop that integrates names it
        options["integrating"] = True
    found = store.start(identity([*us, *ys, *(a for pair in checked for a in pair)], options))
    if found:
        say(f"resuming from '{store.folder}': {found} finished fit(s) and round(s) kept there")
    stored = store.load("declared")
    if stored is not None:
        base = params_from_dict(stored["params"])
        say("the declared cascade's fit loaded from its checkpoint")
    elif base is None:
        store.at("declared")
        say("fitting the declared cascade (robust estimator)")
        estimator = Robust() if robust is None else robust
        fitted = estimator(jnp.concatenate(us), jnp.concatenate(ys), orders, key=key)
        base = jax.device_get(fitted.params)
        bound()  # the robust estimator's program is the largest of the loop: past the bound
        # A breakpoint among the input's last few samples fits a segment on them alone
        # (a slope change of 15 on Silverbox's 10 largest inputs): moved inside, and the
        # cascade refined from there.
        base, moved = tame_edges(base, breakpoint_bounds(us))
        if moved:
            say(
                f"breakpoint(s) {', '.join(moved)} had fewer than {MIN_BEYOND} input samples "
                "(or 1 %) beyond them: moved inside, segment refitted"
            )
        if len(us) > 1 or moved or integrating:
            # (an integrating loop's refits fit the output integrated back, `_errors`:
            # the declared cascade too, so that a candidate's gain is its effect's)
            say("refining it on every estimation record")
            base = refit(plain(base), _no_effect(base), us, ys)[0].params
    # The linear floor (`_oe`): the output-error model of the orders the validation
    # records support, host side.
    floor = _floor(us, ys, *_records(u_val_np, y_val_np), init_samples, integrating)
    if floor is not None:
        say(f"linear floor: {floor.label}, validation NRMSE from rest {floor.host_error:.4g}")
    if stored is None and floor is not None:
        # the linear model as a start of the declared fit, where it fits inside the
        # declared orders and is the better model on the validation records
        vector = cascade_vector(floor.oe, orders, base.to_dict())
        declared = _host_error(
            plain(base), *_records(u_val_np, y_val_np), init_samples, integrating
        )
        if vector is not None and floor.host_error < FLOOR_MARGIN * declared:
            say("refining the declared cascade from the linear floor as well")
            start = Start(
                "declared", orders, np.stack([np.asarray(base.to_vector()), vector]), Effect()
            )
            base = refit(plain(base), start, us, ys)[0].params
    if stored is None:
        store.save("declared", {"params": params_to_dict(base)})
    model = plain(base)
    current = assess(model)
    before = current
    steps = [("declared cascade", model, current)]
    added: list[str] = []
    actions: list[dict] = []
    candidates: list[Candidate] = []
    fit_seconds: list[float] = []  # of the candidates fitted (not loaded) by this run
    for round_ in range(1, max_effects + 1):
        if current.tests.ok:
            say(f"round {round_}: every residual test passes; nothing to add")
            store.save(f"round-{round_:02d}", {"round": round_, "outcome": "every test passes"})
            break
        failed = set(current.tests.failed)
        say(f"round {round_}: failed tests {sorted(failed)}; error {current.error:.4g}")
        records = [
            (np.asarray(u), np.asarray(y), np.asarray(y) - _simulate(model, u)[0])
            for u, y in zip(us, ys, strict=True)
        ]
        round_candidates = []
        # Effects marked `needs_signature` (the hysteresis effects) only when a test of
        # their signature failed, unless the current model is worse than the mean on the
        # validation record: its residual is then the model's own excursion (a drift, a
        # wrong basin) and no test's signature can be trusted to point anywhere.
        tried = [n for n in names if n not in added and n not in model.names and n in EFFECTS]
        trusted = current.error <= 1.0
        tried = [
            n
            for n in tried
            if not EFFECTS[n].needs_signature or failed & set(EFFECTS[n].signature) or not trusted
        ]
        if not model.cascade:  # no cascade left whose orders a structural effect changes
            tried = [n for n in tried if n not in STRUCTURAL]
        if not integrating:  # friction on a velocity: only where the output is one
            tried = [n for n in tried if not getattr(EFFECTS[n], "integrating_only", False)]
        # A hysteresis path may also replace the cascade (the declared structure may be
        # the wrong one, not only incomplete): tried where it would be added.
        replacing = [n for n in tried if model.cascade and n in REPLACEMENTS]
        # what every candidate of this round is fitted and judged against
        fit_against = (model, current, failed, round_, us, ys, records, assess)
        judged_by = {
            "t_threshold": t_threshold,
            "min_gain": min_gain,
            "validation_scale": float(np.var(scored_val)),
        }
        todo = [(n, "add") for n in tried] + [(n, "replace") for n in replacing]
        noise_tried = ARNoise.name in names and ARNoise.name not in added
        count = len(todo) + noise_tried

        def announce(k, name, loaded, round_=round_, count=count):
            store.at("candidate", round=round_, k=k, n=count, candidate=name)
            say(_progress_line(round_, k, count, name, loaded, started, fit_seconds, threads))

        tasks = [(k, name, action) for k, (name, action) in enumerate(todo, start=1)]
        if noise_tried:
            tasks.append((count, ARNoise.name, "noise"))
        # the orders the validation records chose for a linear model (`DynamicsOrder`)
        linear = None if floor is None else floor.oe.orders
        context = (fit_against, judged_by, noise_alpha, linear)
        # Up to `threads` candidates are fitted and scored at once (`_Workers`); each is
        # announced, saved and reported here, in order. Programs are freed past the bound
        # (`bound`: each candidate compiles programs of its own structure, about a hundred
        # memory mappings each on the damper) only with no candidate in flight, so that a
        # later candidate or loop of the same structure reuses them.
        with _Workers(threads) as workers:
            pending, queue, drain = [], iter(tasks), False
            while True:
                while not drain and workers.unfinished(f for *_, f in pending) < workers.ahead:
                    task = next(queue, None)
                    if task is None:
                        break
                    k, name, action = task
                    kind = "add" if action == "noise" else action
                    item = f"round-{round_:02d}-{kind}-{name}"
                    saved = store.load(item)
                    future = workers.submit(_candidate_work, name, action, saved, context)
                    pending.append((task, item, saved, future))
                if not pending:
                    if drain:  # the bound's release waited for the candidates in flight
                        bound()
                        drain = False
                        continue
                    break
                if not drain and workers.wait(pending[0][3], (f for *_, f in pending)):
                    continue  # another candidate finished first: keep the threads busy
                (k, name, action), item, saved, future = pending.pop(0)
                announce(k, name, saved is not None)
                c, seconds, p_value = future.result()
                if seconds is not None:
                    fit_seconds.append(seconds)
                if action == "noise":
                    if saved is None:
                        store.save(item, {**_candidate_checkpoint(c), "p_value": p_value})
                    round_candidates.append(c)
                    say(
                        f"  {c.label:<24} prediction error "
                        f"{c.evaluation.prediction_error:.4g}  t {c.t:7.2f}  "
                        f"{'significant' if c.significant else ''}"
                    )
                    continue
                if c is None:
                    store.save(
                        item, {"round": round_, "name": name, "action": action, "model": None}
                    )
                    say(
                        f"  {name:<24} no start on these records, or no fit of its kind "
                        "(Effect.admissible); not scored"
                    )
                    continue
                if saved is None:
                    store.save(item, _candidate_checkpoint(c))
                round_candidates.append(c)
                drain = drain or over_bound()
                if drain and not pending:
                    bound()
                    drain = False
                say(
                    f"  {c.label:<24} error {c.error:.4g}  t {c.t:7.2f}  "
                    f"{'significant' if c.significant else ''}"
                )
        # the linear floor in place of the current model, where it may be the better one:
        # better than the current model and than every candidate of the round
        best_error = min([current.error, *(c.error for c in round_candidates)])
        if (
            floor is not None
            and model is not floor.model
            and floor.host_error < FLOOR_MARGIN * best_error
        ):
            c = _score_candidate(
                LINEAR_FLOOR, floor.label, floor.model, *fit_against, **judged_by, action="replace"
            )
            round_candidates.append(c)
            say(
                f"  {c.label:<24} error {c.error:.4g}  t {c.t:7.2f}  "
                f"{'significant' if c.significant else ''}"
            )
        candidates += round_candidates
        store.at("round", round=round_)
        deterministic = [c for c in round_candidates if c.significant and c.name != ARNoise.name]
        if deterministic:
            # the residual's signature ranks first only where it can be trusted (above)
            chosen = min(deterministic, key=lambda c: (trusted and not c.signature_match, c.error))
        else:
            # A coloured residual inflates the variance of its cross-correlation with the
            # input, so the input tests are judged on the whitened residual.
            noise_candidates = [
                c
                for c in round_candidates
                if c.name == ARNoise.name
                and c.significant
                and c.signature_match
                and c.evaluation.tests.whiteness_ok
                and c.evaluation.tests.independence_ok
            ]
            if not noise_candidates:
                say(f"round {round_}: no candidate explains the residual significantly; stop")
                store.save(f"round-{round_:02d}", {"round": round_, "outcome": "nothing added"})
                break
            chosen = noise_candidates[0]
        verb = "replacing the cascade by" if chosen.action == "replace" else "adding"
        say(f"round {round_}: {verb} {chosen.label} (error {chosen.error:.4g})")
        added.append(chosen.name)
        actions.append({"effect": chosen.name, "action": chosen.action, "round": round_})
        model, current = chosen.model, chosen.evaluation
        prefix = "replaces the cascade: " if chosen.action == "replace" else "+ "
        steps.append((f"{prefix}{chosen.label}", model, current))
        outcome = {"effect": chosen.name, "action": chosen.action, "label": chosen.label}
        store.save(f"round-{round_:02d}", {"round": round_, "outcome": "added", **outcome})
        # The round's candidates compiled programs of their own structures (each
        # stays mapped in memory until released): freed past the bound.
        bound()
    # The backward step: an effect that a later one made unnecessary goes (`_prune`).
    if len(model.effects) > 1 and model.cascade:
        rounds = max((a["round"] for a in actions if a["round"] is not None), default=0)
        for name, reduced, evaluation in _prune(model, current, us, ys, assess, min_gain):
            say(
                f"backward step: {name} is no longer needed (validation error without it "
                f"{evaluation.error:.4g}); it goes"
            )
            model, current = reduced, evaluation
            if name in added:  # (every effect of a cascade's model was added by a round)
                added.remove(name)
            actions.append({"effect": name, "action": "remove", "round": rounds + 1})
            steps.append((f"- {name} (a later effect made it unnecessary)", model, current))
    # never worse on the validation records than the linear floor
    if (
        floor is not None
        and model is not floor.model
        and floor.host_error < FLOOR_MARGIN * current.error
    ):
        floor_evaluation = assess(floor.model)
        if floor_evaluation.error < current.error:
            say(
                f"the final model (error {current.error:.4g}) is worse on the validation "
                f"records than the linear floor {floor.label} ({floor_evaluation.error:.4g}): "
                "the linear model replaces it"
            )
            added.append(LINEAR_FLOOR)
            actions.append({"effect": LINEAR_FLOOR, "action": "floor", "round": None})
            model, current = floor.model, floor_evaluation
            steps.append((f"replaced by the {floor.label}", model, current))
    stored = store.load("standard-errors")
    if stored is None:
        store.at("standard_errors")
        say("standard errors of the final model on the estimation records")
        errors = model_standard_errors(model, us, ys)
        store.save("standard-errors", {"errors": errors})
    else:
        errors = stored["errors"]
    store.at("report")
    return LoopResult(
        before,
        current,
        plain(base),
        model,
        added,
        candidates,
        steps,
        t_threshold,
        min_gain,
        errors,
        compile_count() - compiled_before,
        actions,
        floor,
        scaling,
    )


# A scored record (validation, test) is simulated, not fitted: it needs the state
# initialisation window and this many scored samples after it.
MIN_SCORED = 20


def _prune(model: ExtendedModel, current: Evaluation, us, ys, assess, min_gain: float):
    """The backward step of a stepwise selection (forward, then backward): each effect of
    `model` but its last, earliest first, is taken out and the rest refitted from the
    current estimates; the effect goes where the model without it is within `min_gain`
    of the model with it on the validation records (`1 - error_with / error_without <=
    min_gain`: the loop would not add it there, whatever the significance test says), as
    when a curved backlash explained a little of a residual whose cause a later effect
    (the inner polynomial of a Wiener-Hammerstein sandwich) then explained in full.
    Structural effects (orders: their marker in `model.effects`) and the noise model are
    not taken out. `current`: the model's evaluation. Yields `(name, model, evaluation)`
    of each effect that goes, with the model without it."""
    k = 0
    while k < len(model.effects) - 1:
        name = model.effects[k].name
        if name in STRUCTURAL:
            k += 1
            continue
        reduced = refined(model.with_(effects=model.effects[:k] + model.effects[k + 1 :]), us, ys)
        evaluation = assess(reduced)
        if not evaluation.error * (1 - min_gain) <= current.error:
            k += 1  # the effect still earns its place (or the model without it failed)
            continue
        model, current = reduced, evaluation
        yield name, model, current


def check_lengths(lengths: list[int], orders: Orders, where: str = "the loop") -> None:
    """The estimation records' lengths: together at least `orders.min_samples` (10 per
    parameter, counted over every estimation record), each longer than the linear
    block's lags; a one-sentence `ValueError` otherwise (also for orders with a branch
    degree: the loop declares the straight backlash and adds curved branches itself)."""
    if orders.degree > 1:
        raise ValueError(
            f"{where}: orders {orders} have a branch degree; the loop declares the straight "
            "backlash (four orders) and adds curved branches itself where the residual "
            "asks for them (its effect general_backlash)."
        )
    total = sum(lengths)
    if total < orders.min_samples:
        which = (
            "the estimation record has"
            if len(lengths) == 1
            else (f"the {len(lengths)} estimation records have together")
        )
        raise ValueError(
            f"{where}: {which} {total} samples, fewer than the {orders.min_samples} that "
            f"orders {orders} need (Orders.min_samples, counted over every estimation "
            "record); use longer or more records or lower orders."
        )
    shortest = min(lengths)
    lags = max(orders.r, orders.p) + 2
    if shortest < lags:
        raise ValueError(
            f"{where}: an estimation record has {shortest} samples, fewer than the {lags} "
            f"that the linear block's lags (orders {orders}) need; drop it or join it to "
            "another."
        )


def check_scored_length(length: int, init_samples: int, where: str) -> None:
    """A scored record needs its initialisation window and `MIN_SCORED` samples after."""
    needed = int(init_samples) + MIN_SCORED
    if length < needed:
        raise ValueError(
            f"{where}: the record has {length} samples, fewer than the {needed} a scored "
            f"record needs ({int(init_samples)} to set the state and {MIN_SCORED} scored); "
            "use a longer record or fewer --init-samples."
        )


def default_threads() -> int:
    """The loop's threads by default (`model_error_loop`'s `threads`): 2 where this
    process may use two or more cores, else 1. Two, not more: each candidate's programs
    are mostly compiled and run on one core, and more candidates at once hold more
    programs in memory."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity on this system
        cores = os.cpu_count() or 1
    return 2 if cores >= 2 else 1


def _candidate_work(name, action, saved, context):
    """One candidate of a round: its fit (or `saved`, its checkpoint) and its score, in
    any thread (`_Workers`). `action`: "add", "replace" or "noise" (the noise model).
    Returns `(Candidate or None, seconds of the fit or None where loaded, the noise
    model's p-value or None)`."""
    fit_against, judged_by, noise_alpha, linear = context
    model, current, failed, round_, us, ys, records, assess = fit_against
    began = time.monotonic()
    if action == "noise":
        if saved is None:
            noise_model, p_value = _fit_noise(model, us, ys, records)
        else:
            noise_model, p_value = model_from_dict(saved["model"]), saved["p_value"]
        seconds = time.monotonic() - began if saved is None else None
        options = {**judged_by, "noise_alpha": noise_alpha}
        c = _score_noise(noise_model, p_value, current, failed, round_, assess, **options)
        return c, seconds, p_value
    if saved is None:
        with linear_orders(linear):
            fit = _fit_candidate(name, model, us, ys, records, action)
    else:
        fit = None if saved["model"] is None else (model_from_dict(saved["model"]), saved["label"])
    seconds = time.monotonic() - began if saved is None else None
    if fit is None:
        return None, seconds, None
    c = _score_candidate(name, fit[1], fit[0], *fit_against, **judged_by, action=action)
    return c, seconds, None


class _Deferred:
    """A task of `_Workers(1)`: run when its result is asked for."""

    def __init__(self, function, args):
        self.function, self.args = function, args

    def result(self):
        return self.function(*self.args)


class _Workers:
    """Where a round's candidates run: with `threads` 1 each in the calling thread when
    its result is asked for (in order, as before threads); with more, in a pool of that
    many threads. Candidates are independent given the current model, and each runs the
    same programs on the same arrays either way, so the results are the same bit for
    bit; XLA compiles and runs programs outside Python's lock, so on a machine with
    several cores one candidate's compiling and running overlaps another's. Leaving
    the block (also on an error or Ctrl-C) waits for the candidates already running."""

    def __init__(self, threads: int):
        self.size = int(threads)
        # candidates queued or running at most: two more than the threads; finished ones
        # waiting to be reported in order do not count, so that a long one (reported
        # before the others) leaves no thread idle behind it
        self.ahead = self.size + 2 if self.size > 1 else 1
        self.pool = None
        if self.size > 1:
            import concurrent.futures

            self.pool = concurrent.futures.ThreadPoolExecutor(
                self.size, thread_name_prefix="jaxcascade-candidate"
            )

    def unfinished(self, futures) -> int:
        """How many of `futures` (this pool's) are queued or running."""
        if self.pool is None:
            return sum(1 for _ in futures)
        return sum(1 for f in futures if not f.done())

    def wait(self, head, futures) -> bool:
        """Wait until `head` or another of `futures` finishes; True where `head` has
        not (a later candidate finished first, and its thread may take a new one).
        Reporting stays in order; only the submitting does not wait for the head."""
        if self.pool is None or head.done():
            return False
        import concurrent.futures

        running = [f for f in futures if not f.done()]
        concurrent.futures.wait(running, return_when=concurrent.futures.FIRST_COMPLETED)
        return not head.done()

    def submit(self, function, *args):
        if self.pool is None:
            return _Deferred(function, args)
        # in the caller's context: the groups in force (`_effects._choice.grouping`)
        return self.pool.submit(contextvars.copy_context().run, function, *args)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
        return False


def _fit_candidate(name, model, us, ys, records, action="add"):
    """The effect `name` fitted added to `model` (`action="add"`), or in place of its
    cascade (`action="replace"`: the effect's path from the input plus a fitted output
    offset, the model's other effects kept): `(fitted model, label)`, or None where the
    effect has no start on these records or no fit that `Effect.admissible` accepts."""
    effect = EFFECTS[name]
    if action == "replace":
        offset = float(np.mean(np.concatenate([np.asarray(y) for y in ys])))
        alone = model.with_(
            cascade=False, effects=(*model.effects, OutputOffset(jnp.asarray(offset)))
        )
        fitted, _, label = fit_parallel(alone, effect, us, ys)
        return fitted, f"replace:{label}"
    if effect.linear:
        fitted, _, label = fit_parallel(model, effect, us, ys)
        return fitted, label
    best = None
    samples = sum(np.shape(u)[0] for u in us)
    for start in effect.starts_records(model, records):
        models, costs, _, order = refit_all(model, start, us, ys, effect.refine_steps)
        # the start of lowest cost whose fit is a model of its kind on these records (not
        # a curved backlash whose branch turns: `Effect.admissible`); none: the next
        # structure
        for index in order:
            fitted, cost = one_start(models, int(index)), float(costs[index])
            if not fitted.effects or fitted.effects[-1].admissible(fitted, us) is None:
                break
        else:
            continue
        # Starts of one effect with more parameters (a higher branch degree) win only
        # where they lower the cost by more than their parameters are worth (BIC); among
        # starts of one size this is the smallest cost.
        size = start.vectors.shape[1] + sum(
            int(np.size(leaf)) // start.vectors.shape[0]
            for leaf in jax.tree_util.tree_leaves(start.effect)
        )
        criterion = (
            samples * np.log(max(cost, 1e-300) / samples) + size * np.log(samples)
            if np.isfinite(cost)
            else np.inf
        )
        if best is None or criterion < best[1]:
            best = (fitted, criterion, start.label)
    if best is None:
        # no start on these records (a segment where the input never goes), or no
        # admissible fit (curved branches that turn on the records' range)
        return None
    return best[0], best[2]


def _score_candidate(
    name, label, fitted, model, current, failed, round_, us, ys, records, assess, **options
):
    """The score of a fitted candidate: the fitted model on the validation record, and the
    Diebold-Mariano test against the current model (deterministic: a resumed loop scores
    a loaded fit again, `_loop_checkpoint`)."""
    t_threshold, min_gain = options.get("t_threshold", 3.0), options.get("min_gain", 0.02)
    action = options.get("action", "add")
    # the linear floor has no signature of its own: it stands for every test
    signature = set(failed) if name == LINEAR_FLOOR else set(EFFECTS[name].signature)
    evaluation = assess(fitted)
    # The evidence of every record: the validation record out of sample and the
    # estimation records in sample, each a squared NRMSE difference (module docstring).
    # (an output integrated back, `_integrating`, is tested on its difference: the
    # integrated errors are persistent, a random walk's, and their long-run variance is
    # not the Newey-West estimate's; its error, and so the gain asked, is the integrated
    # output's)
    validation = diebold_mariano(current.residual, evaluation.residual, "simulation")
    in_sample = [np.asarray(y) - simulated_output(fitted, u) for u, y in zip(us, ys, strict=True)]
    comparison = diebold_mariano_records(
        [current.residual, *(r[2] for r in records)],
        [evaluation.residual, *in_sample],
        [options.get("validation_scale", 1.0), *(float(np.var(r[1])) for r in records)],
        "simulation",
    )
    gain = 1 - evaluation.error / current.error
    return Candidate(
        round_,
        name,
        label,
        evaluation.error,
        comparison.statistic,
        bool(comparison.statistic > t_threshold and gain > min_gain),
        bool(failed & signature),
        fitted,
        evaluation,
        comparison,
        action,
        validation.statistic,
    )


def _fit_noise(model, us, ys, records):
    """The autoregressive noise model fitted on the estimation records' residuals of
    `model`, the model then refitted on the prediction error it defines (an output-error
    fit is biased by coloured noise, and the whitened residual shows that bias to the
    input tests): `(model with the noise model, p-value of the likelihood-ratio test
    against white noise)`. It is judged on the validation record's one-step-ahead
    prediction error (`_score_noise`)."""
    noise, p_value = ARNoise.fit_records([r[2] for r in records])
    noise_model = model.with_(noise=noise)
    if noise.order and (model.cascade or model.effects):
        noise_model = refined(noise_model, us, ys).with_(noise=noise)
    return noise_model, float(p_value)


def _score_noise(noise_model, p_value, current, failed, round_, assess, **options):
    """The score of the noise model's candidate (`_fit_noise`)."""
    noise = noise_model.noise
    evaluation = assess(noise_model)
    comparison = diebold_mariano(current.innovation, evaluation.innovation, "prediction")
    gain = 1 - evaluation.prediction_error / current.prediction_error
    significant = (
        noise.order > 0
        and p_value < options["noise_alpha"]
        and comparison.statistic > options["t_threshold"]
        and gain > options["min_gain"]
    )
    return Candidate(
        round_,
        ARNoise.name,
        f"{ARNoise.name}:AR({noise.order})",
        evaluation.error,
        comparison.statistic,
        bool(significant),
        bool(failed & set(ARNoise.signature)),
        noise_model,
        evaluation,
        comparison,
    )


def _candidate_checkpoint(c: Candidate) -> dict:
    """A finished candidate as `_loop_checkpoint` keeps it: its fit in full, its scores
    for the reader (a resumed run scores the fit again)."""
    return {
        "round": c.round,
        "name": c.name,
        "action": c.action,
        "label": c.label,
        "model": model_to_dict(c.model),
        "scores": {"error": c.error, "t": c.t, "significant": c.significant},
    }


def _settings(module) -> dict:
    """An estimator's settings (its fields) as strings, for a run's identity."""
    return {f.name: repr(getattr(module, f.name)) for f in dataclasses.fields(module)}


def _key_data(key) -> list:
    """A PRNG key's bits as a list (a typed key's data, or a raw `uint32` key)."""
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.key_data(key)
    return np.asarray(key).tolist()


def _progress_line(round_, k, n, name, loaded, started, fit_seconds, threads=1) -> str:
    """`round R, candidate k of n: NAME (elapsed, estimate of the round's remaining time:
    the mean time of this run's fits so far times the candidates left, over the threads
    that fit them)`."""
    line = f"round {round_}, candidate {k} of {n}: {name} ({_duration(time.monotonic() - started)}"
    if loaded:
        return f"{line} elapsed; its fit loaded from its checkpoint)"
    if fit_seconds:
        left = float(np.mean(fit_seconds)) * (n - k + 1) / max(1, min(threads, n - k + 1))
        return f"{line} elapsed, about {_duration(left)} left in this round)"
    return f"{line} elapsed)"


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60} min {seconds % 60:02d} s" if seconds >= 60 else f"{seconds} s"


def _no_effect(params: CascadeParams) -> Start:
    """A start that adds nothing: refines the cascade alone."""
    vector = np.asarray(params.to_vector())[None]
    return Start("declared", params.orders, vector, Effect())
