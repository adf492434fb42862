"""The effect library: extensions of the cascade that the model-error loop can add.

An `Effect` is an `eqx.Module` whose fields are its parameters. It changes the input
before the cascade (`input`) or the output after it (`output`, which also sees the
linear block's output x), so the extended model is

    y = output_effects(cascade(input_effects(u)), x)

Structural effects (`DynamicsOrder`, `PwlSegment`) have no parameters of their own: they
change the cascade's orders. Every effect says how to start its parameters from a fitted
model and its residual (`starts`, host side) and which residual tests fail when it is
present but not modelled (`signature`, names from `ResidualTests.tests()`). Parameters
named in `fixed` are held during refinement (an integer delay), the rest are refined
with the cascade (`free_filter`, for `eqx.partition`). The noise model is its own type
(`_noise.ARNoise`): it changes no simulated output.

To add an effect: subclass `Effect` in a module of this package and add it to `EFFECTS`
(`_effects/__init__.py`).
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._compile import bucket_length, exported, pad
from ..._system._general_backlash import GeneralBacklash, general_signals
from ..._system._model import CascadeParams, Orders
from ..._system._simulate import backlash, general_backlash, pwl, signals
from .._noise import ARNoise
from ._recursion import linear_with_terms


class Effect(eqx.Module):
    """Base class: an effect that changes nothing. Subclasses set the class variables,
    declare their parameters as array fields, and override what they use."""

    name: ClassVar[str] = ""
    signature: ClassVar[tuple[str, ...]] = ()
    description: ClassVar[str] = ""
    fixed: ClassVar[tuple[str, ...]] = ()
    # Levenberg-Marquardt steps of the joint refit; effects whose starts are already
    # least-squares fits on the residual need few.
    refine_steps: ClassVar[int] = 150
    # Tried by the loop only when a test of its signature failed (the hysteresis
    # effects: never on a record whose hysteresis test passes).
    needs_signature: ClassVar[bool] = False
    # A parallel path linear in its weights for a fixed structure: fitted by ridge least
    # squares on the residual (`fit_records`), alternating with refits of the cascade
    # (`_loop.fit_parallel`), not by a Levenberg-Marquardt refit of the extended model.
    linear: ClassVar[bool] = False
    # The output chain's order is the order the effects were added in, except that an
    # `inner` map acts just before the first effect that is a `second_block` (a static
    # map added after the output dynamics goes between the two linear blocks: the
    # Wiener-Hammerstein sandwich, `_wiener`); `output_order`.
    inner: ClassVar[bool] = False
    second_block: ClassVar[bool] = False
    # The unit of each field in the records' units, `{field: kind}` (`_units`: e.g.
    # "output", "output_level", "input", "unitless", "output_power(k)", or a tuple of one
    # kind per entry): the schema writes the fields in the records' units with it
    # (`_units.record_units`). Every field must be declared (tests/test_workflow.py).
    units: ClassVar[dict[str, str | tuple[str, ...]]] = {}

    def input(self, u):
        return u

    def output(self, y, x):
        return y

    def parallel(self, u):
        """A path in parallel with the cascade: its output, added to the model's output,
        from the model's input `u`; `None` (the default) for an effect without one."""
        return None

    def recursion(self, v, x_prev, x_new):
        """A term added to the linear block's output `x(t)` inside its recursion, from
        the block's input `v(t)`, its output `x(t-1)` and the value `x(t)` has so far
        (the linear recursion's, plus the terms of the effects before this one): scalars
        of one sample; a feedback of the output into the dynamics (`_recursion`,
        `_feedback`). `None` (the default) for an effect that leaves the recursion
        alone."""
        return None

    # The effect's state (`_initial_state`): the state before a record's first sample
    # (`rest_state`, from the record's input `u`: `None` for an effect without state),
    # and the `*_with_state` forms of `input`, `output` and `parallel`, which continue
    # from `state` and also return the state before sample `at` (`at` <= T, traced: the
    # state at the end of a record, or before a later sample of a padded one). The
    # defaults pass the state through unchanged.

    def rest_state(self, u) -> EffectState | None:
        return None

    def input_with_state(self, u, state, at):
        return self.input(u), state

    def output_with_state(self, y, x, state, at):
        return self.output(y, x), state

    def parallel_with_state(self, u, state, at):
        return self.parallel(u), state

    def backlash(self, params: CascadeParams) -> GeneralBacklash | None:
        """The block that replaces the cascade's straight backlash (built on its `cL`,
        `mR`, `cR`), or `None` (the default) for an effect that leaves it alone."""
        return None

    def admissible(self, model: ExtendedModel, us) -> str | None:
        """Why a fitted `model` with this effect is not a model of its kind on the input
        records `us` (one phrase), or None (the default) where it is."""
        return None

    def state_range(self, state) -> tuple[Array, Array] | None:
        """Bounds `(low, high)` of `state.free` (an operator's admissible positions), for
        the starts of an initial-state fit; `None` where it has no free state."""
        return None

    def free_filter(self):
        """`eqx.partition` filter: True for the parameters refined with the cascade."""
        everything = jax.tree_util.tree_map(lambda _: True, self)
        if not self.fixed:
            return everything
        return eqx.tree_at(
            lambda e: tuple(getattr(e, f) for f in self.fixed),
            everything,
            replace=(False,) * len(self.fixed),
        )

    def parameters(self) -> dict[str, list | float]:
        """`{field: value}` of one (unbatched) effect, for reports."""
        return {
            field.name: np.asarray(getattr(self, field.name)).tolist()
            for field in dataclasses.fields(self)
        }

    @classmethod
    def starts(cls, model: ExtendedModel, u, y, residual) -> list[Start]:
        """Candidate starts for adding this effect to `model` (host side, numpy)."""
        raise NotImplementedError

    @classmethod
    def starts_records(cls, model: ExtendedModel, records) -> list[Start]:
        """Starts from several estimation records `[(u, y, residual), ...]`; by default
        `starts` on the records joined end to end."""
        u, y, residual = (np.concatenate([np.asarray(r[i]) for r in records]) for i in range(3))
        return cls.starts(model, u, y, residual)


class EffectState(eqx.Module):
    """One effect's state before a sample: `free`, what the record's input does not
    determine (operator positions, a friction force: fitted by an initial-state fit),
    and `known`, what it does (past inputs, the sample's index: taken from the record)."""

    free: Float[Array, " F"]
    known: Float[Array, ...]


def recent(past, signal, at):
    """The `len(past)` values of `signal` before sample `at`, newest first, continuing
    into `past` (the values before `signal(0)`, newest first) where `at` is small."""
    count = past.shape[0]
    joined = jnp.concatenate([past[::-1].astype(signal.dtype), signal])
    return jax.lax.dynamic_slice(joined, (at,), (count,))[::-1]


@dataclasses.dataclass(frozen=True)
class Start:
    """Starting points of one candidate structure: `S` starts of equal shape.

    - `label`: the candidate's name in reports (`name` or `name:variant`).
    - `orders`: the cascade's orders with the effect (structural effects change them).
    - `vectors`: `(S, P')` cascade parameters in `orders.names` order.
    - `effect`: the effect with a leading axis `S` on every parameter.
    """

    label: str
    orders: Orders
    vectors: np.ndarray
    effect: Effect


def _repeat(model, count):
    return np.repeat(np.asarray(model.params.to_vector())[None], count, 0)


def _batched(effect_class, **values):
    # `device_put`, not `jnp.asarray`: an eager conversion compiles a program per shape
    return effect_class(**{k: jax.device_put(np.asarray(v, float)) for k, v in values.items()})


class ExtendedModel(eqx.Module):
    """A cascade plus effects and a noise model.

    - `params`: the cascade (its orders include structural effects).
    - `effects`: the added effects, in order.
    - `noise`: the output noise model (white: order 0).
    - `cascade`: False when an effect has replaced the cascade's path (the loop's
      replacement candidates): the output is then the effects' alone (a parallel path of
      the input, plus output effects), and `params` are not used.
    """

    params: CascadeParams
    effects: tuple[Effect, ...]
    noise: ARNoise
    cascade: bool = eqx.field(static=True, default=True)

    def with_(self, **changes) -> ExtendedModel:
        """A copy with some fields changed (the structure kept)."""
        return dataclasses.replace(self, **changes)

    def structure(self) -> str:
        """The model's structure as one line, e.g.
        `u -> input_delay -> pwl -> linear -> backlash -> + output_offset -> y`; effects
        inside the linear block's recursion as `linear(r,p) with nonlinear_feedback`."""
        inputs = [e.name for e in self.effects if type(e).input is not Effect.input]
        outputs = [e.name for e in self.effects if type(e).output is not Effect.output]
        paths = [e.name for e in self.effects if type(e).parallel is not Effect.parallel]
        inside = [e.name for e in self.effects if type(e).recursion is not Effect.recursion]
        chain = ["u", *inputs]
        if self.cascade:
            o = self.orders
            nd = backlash_of(self)
            block = "backlash" if nd is None else f"general_backlash({nd.degree})"
            linear = f"linear({o.r},{o.p})"
            if inside:  # terms inside the linear block's recursion (`_recursion`)
                linear = f"{linear} with {' and '.join(inside)}"
            chain += [f"pwl({o.nR},{o.nL})", linear, block]
            line = " -> ".join(chain)
            if paths:
                line = f"{line} (+ {' + '.join(f'{p}(u)' for p in paths)})"
        else:
            line = " -> ".join(chain + [" + ".join(paths) or "0"])
        for i in output_order(self.effects):
            if self.effects[i].name in outputs:
                line += f" -> {self.effects[i].name}"
        if self.noise.order:
            line += f" -> + AR({self.noise.order}) noise"
        return line + " -> y"

    @property
    def orders(self) -> Orders:
        return self.params.orders

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(effect.name for effect in self.effects)


def output_order(effects) -> list[int]:
    """The indices of `effects` in the order their outputs (and parallel paths) act: the
    order they were added in, with every `Effect.inner` map moved to just before the
    first `Effect.second_block` effect (none moves where there is none)."""
    order = list(range(len(effects)))
    block = next((i for i in order if type(effects[i]).second_block), None)
    if block is None:
        return order
    moved = [i for i in order if i > block and type(effects[i]).inner]
    rest = [i for i in order if i not in moved]
    at = rest.index(block)
    return rest[:at] + moved + rest[at:]


def backlash_of(model: ExtendedModel) -> GeneralBacklash | None:
    """The general backlash an effect of `model` puts in place of the cascade's straight
    one (`Effect.backlash`), or None: the cascade's own."""
    for effect in model.effects:
        nd = effect.backlash(model.params)
        if nd is not None:
            return nd
    return None


def plain(params: CascadeParams) -> ExtendedModel:
    """The declared cascade with no effect added and white noise."""
    return ExtendedModel(params, (), ARNoise.white(params.mR.dtype))


def simulate_extended(model: ExtendedModel, u):
    """Free-run simulation of the extended model."""
    return simulate_with_switches(model, u)[0]


def recursion_terms(model: ExtendedModel) -> list:
    """The `Effect.recursion` terms of `model`'s effects that have one, in order."""
    return [e.recursion for e in model.effects if type(e).recursion is not Effect.recursion]


def simulate_with_switches(model: ExtendedModel, u):
    """Simulated output and the backlash regime signals `(y, x, y_cascade)`. Without the
    cascade (`ExtendedModel.cascade` False) `x` is the input after the input effects and
    `y_cascade` is zero."""
    u_model = u
    for effect in model.effects:
        u = effect.input(u)
    terms = recursion_terms(model)
    if model.cascade and terms:  # a feedback inside the linear block (`_recursion`)
        nd = backlash_of(model)
        x = linear_with_terms(model.params, pwl(model.params, u), terms)
        y = backlash(model.params, x) if nd is None else general_backlash(nd, x)
    elif model.cascade:
        nd = backlash_of(model)
        inner = signals(model.params, u) if nd is None else general_signals(model.params, nd, u)
        x, y = inner.x, inner.y
    else:
        x, y = u, jnp.zeros_like(u)
    y_cascade = y
    for i in output_order(model.effects):
        effect = model.effects[i]
        y = effect.output(y, x)
        path = effect.parallel(u_model)
        if path is not None:
            y = y + path
    return y, x, y_cascade


# One compiled program per model structure and record-length bucket for every host-side
# simulation of the loop (its scoring, the effects' starts): the same model simulated
# by two callers is one program, not two; kept across processes (`_compile.exported`).
_simulate_jit = exported(simulate_with_switches)


# The length every record is padded to within `padded_to` (0: each its own bucket).
_LENGTH = contextvars.ContextVar("padded_length", default=0)


@contextlib.contextmanager
def padded_to(lengths):
    """Within the block, `simulate_padded` pads every record no longer than the bucket of
    the longest of `lengths` (`_compile.bucket_length`) to that bucket: the records of
    one loop (its estimation and validation records, of many lengths on measured data)
    share one program per model structure instead of one per structure and length
    bucket. The simulation is causal, so the padding changes nothing on the record's own
    samples; the longer scan costs run time on the shorter records (a few milliseconds
    per record on the damper's), far less than a program's compile time, and a record
    far shorter than the longest keeps its own bucket (`SHARED_WITHIN`). A thread
    pool's tasks see it where they run in a copy of the context."""
    token = _LENGTH.set(bucket_length(max(int(n) for n in lengths)))
    try:
        yield
    finally:
        _LENGTH.reset(token)


def simulate_padded(model: ExtendedModel, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`simulate_with_switches` of one record on the host: the input padded to its
    length's bucket (`_compile.pad`), or to the common length of `padded_to`, the outputs
    `(y, x, y_cascade)` cut back, NumPy arrays."""
    u = np.asarray(u)
    out = _simulate_jit(model, jax.device_put(padded(u)))
    return tuple(np.asarray(a)[: u.shape[0]] for a in out)


# A record whose bucket is shorter than the common length by more than this factor keeps
# its own bucket: simulating it at the common length would cost more than a program.
SHARED_WITHIN = 8


def padded(u) -> np.ndarray:
    """A 1-D record padded (`_compile.pad`) to its length's bucket, or to the common
    length of `padded_to` where it is no longer and its bucket at least
    `1 / SHARED_WITHIN` of it (a short record beside a long one keeps its own)."""
    u = np.asarray(u)
    common, own = _LENGTH.get(), bucket_length(u.shape[0])
    shared = u.shape[0] <= common <= SHARED_WITHIN * own
    return pad(u, common if shared else own)


class OutputOffset(Effect):
    """A constant added to the output. An offset `d` with `cL + d >= 0` and
    `cR - d / mR >= 0` is exactly a change of the backlash gaps (the output of a backlash
    plus `d` is the backlash with gaps `cL + d`, `cR - d / mR`), so only a larger offset
    is an effect the declared model cannot already represent."""

    name: ClassVar[str] = "output_offset"
    signature: ClassVar[tuple[str, ...]] = ("mean",)
    description: ClassVar[str] = "constant offset added to the output: y + d"

    units: ClassVar[dict] = {"offset": "output"}

    offset: Float[Array, ""]

    def output(self, y, x):
        return y + self.offset

    @classmethod
    def starts(cls, model, u, y, residual):
        effect = _batched(cls, offset=[np.mean(residual)])
        return [Start(cls.name, model.orders, _repeat(model, 1), effect)]


class OutputDrift(Effect):
    name: ClassVar[str] = "output_drift"
    signature: ClassVar[tuple[str, ...]] = ("time",)
    description: ClassVar[str] = (
        "linear drift of the output over the record: y + d t / 1000 (t in samples)"
    )

    # per 1000 samples, in the output's units
    units: ClassVar[dict] = {"slope": "output"}

    slope: Float[Array, ""]

    def output(self, y, x):
        return y + self.slope * jnp.arange(y.shape[0], dtype=y.dtype) / 1000.0

    def rest_state(self, u):
        # the index of the record's first sample
        return EffectState(jnp.zeros((0,), u.dtype), jnp.zeros((), u.dtype))

    def output_with_state(self, y, x, state, at):
        t = state.known + jnp.arange(y.shape[0], dtype=y.dtype)
        return y + self.slope * t / 1000.0, EffectState(state.free, state.known + at)

    @classmethod
    def starts(cls, model, u, y, residual):
        t = np.arange(len(residual)) / 1000.0
        effect = _batched(cls, slope=[np.polyfit(t, residual, 1)[0]])
        return [Start(cls.name, model.orders, _repeat(model, 1), effect)]


class OutputSaturation(Effect):
    name: ClassVar[str] = "output_saturation"
    signature: ClassVar[tuple[str, ...]] = ("level", "regime", "u2_e", "u2_e2", "mean")
    description: ClassVar[str] = "output clipped to [lower, upper] (a sensor or actuator limit)"

    # levels of the record's output
    units: ClassVar[dict] = {"lower": "output_level", "upper": "output_level"}

    lower: Float[Array, ""]
    upper: Float[Array, ""]

    def output(self, y, x):
        return jnp.clip(y, self.lower, self.upper)

    @classmethod
    def starts(cls, model, u, y, residual):
        lower, upper = np.quantile(y, [0.005, 0.995])
        effect = _batched(cls, lower=[lower], upper=[upper])
        return [Start(cls.name, model.orders, _repeat(model, 1), effect)]


class OutputFeedthrough(Effect):
    """A parallel linear path from the linear block's output to the measured output.

    With `d = -1` and `mR = 1` the output `y - x` is minus the *stop* operator of `x`
    (elastic-plastic, or Coulomb friction with stiffness): the force of a friction
    element, where the cascade alone gives the *play* (the slack position).
    """

    name: ClassVar[str] = "output_feedthrough"
    signature: ClassVar[tuple[str, ...]] = ("cross_correlation", "level", "regime", "u2_e")
    description: ClassVar[str] = "parallel linear path from x to the output: y + d x"

    # x is in the output's units (the backlash gaps are)
    units: ClassVar[dict] = {"gain": "unitless"}

    gain: Float[Array, ""]

    def output(self, y, x):
        return y + self.gain * x

    @classmethod
    def starts(cls, model, u, y, residual):
        effect = _batched(cls, gain=[-1.0, -0.5, 0.5])
        return [Start(cls.name, model.orders, _repeat(model, 3), effect)]


class InputDelay(Effect):
    name: ClassVar[str] = "input_delay"
    signature: ClassVar[tuple[str, ...]] = ("cross_correlation", "autocorrelation")
    description: ClassVar[str] = "pure input delay of d samples: u(t - d)"
    fixed: ClassVar[tuple[str, ...]] = ("delay",)
    max_delay: ClassVar[int] = 5

    units: ClassVar[dict] = {"delay": "unitless"}  # samples

    delay: Float[Array, ""]  # an integer, held fixed; one start per value

    def input(self, u):
        index = jnp.arange(u.shape[0]) - self.delay.astype(jnp.int32)
        return jnp.where(index >= 0, u[jnp.clip(index, 0, None)], 0.0)

    def rest_state(self, u):
        # the past inputs u(-1), ..., u(-max_delay): zero before the record
        return EffectState(jnp.zeros((0,), u.dtype), jnp.zeros((self.max_delay,), u.dtype))

    def input_with_state(self, u, state, at):
        count = state.known.shape[0]
        joined = jnp.concatenate([state.known[::-1], u])
        index = jnp.arange(u.shape[0]) + count - self.delay.astype(jnp.int32)
        delayed = jnp.where(index >= 0, joined[jnp.clip(index, 0, None)], 0.0)
        return delayed, EffectState(state.free, recent(state.known, u, at))

    @classmethod
    def starts(cls, model, u, y, residual):
        delays = np.arange(1, cls.max_delay + 1, dtype=float)
        effect = _batched(cls, delay=delays)
        return [Start(cls.name, model.orders, _repeat(model, len(delays)), effect)]


def _embed(params: CascadeParams, orders: Orders, values: dict) -> np.ndarray:
    """Vector for `orders` from `params` plus new entries `values` (others from params)."""
    old = params.to_dict()
    return np.array([values.get(name, old.get(name, 0.0)) for name in orders.names])


# The orders `(zeros, poles)` of the linear output-error model the loop's validation
# records chose (`_loop.Floor`, `_oe.linear_floor`), set by a loop for its run
# (`linear_orders`): `DynamicsOrder` also proposes them.
_LINEAR_ORDERS = contextvars.ContextVar("jaxcascade_linear_orders", default=None)


@contextlib.contextmanager
def linear_orders(orders: tuple[int, int] | None):
    """Within the block, `DynamicsOrder` also proposes the linear block of `orders`
    `(r, p)` (where they exceed the model's): the orders the validation records support,
    reached in one round rather than a pole a round."""
    token = _LINEAR_ORDERS.set(None if orders is None else tuple(int(k) for k in orders))
    try:
        yield
    finally:
        _LINEAR_ORDERS.reset(token)


class DynamicsOrder(Effect):
    name: ClassVar[str] = "dynamics_order"
    signature: ClassVar[tuple[str, ...]] = ("autocorrelation", "cross_correlation", "spectrum")
    description: ClassVar[str] = (
        "more poles or zeros in the linear block: one more (p + 1, r + 1), or up to the "
        "orders of the linear model the validation records choose"
    )

    @classmethod
    def starts(cls, model, u, y, residual):
        o = model.orders
        starts = []
        # one more pole, or zero; or as many as the linear model of the validation
        # records' choice has (`linear_orders`), where that is more: reached in one
        # round, at the cost of no further structure (a candidate is a program each)
        r_chosen, p_chosen = _LINEAR_ORDERS.get() or (0, 0)
        variants = [
            ("pole", Orders(o.nR, o.nL, o.r, max(o.p + 1, p_chosen))),
            ("zero", Orders(o.nR, o.nL, max(o.r + 1, r_chosen), o.p)),
        ]
        for label, orders in variants:
            vector = _embed(model.params, orders, {})
            starts.append(Start(f"{cls.name}:{label}", orders, vector[None], cls()))
        return starts


class PwlSegment(Effect):
    name: ClassVar[str] = "pwl_segment"
    signature: ClassVar[tuple[str, ...]] = ("level", "u2_e", "u2_e2", "cross_correlation")
    description: ClassVar[str] = "one more breakpoint (segment) in the static input nonlinearity"
    quantiles: ClassVar[tuple[float, ...]] = (0.2, 0.4, 0.6, 0.8)
    # samples an input needs on one side of zero before a segment is tried there
    min_side: ClassVar[int] = 20

    @classmethod
    def starts(cls, model, u, y, residual):
        o = model.orders
        p = model.params.to_dict()
        u = np.asarray(u)
        starts = []
        for side, orders in (
            ("right", Orders(o.nR + 1, o.nL, o.r, o.p)),
            ("left", Orders(o.nR, o.nL + 1, o.r, o.p)),
        ):
            D_name, M_name = ("DR", "MR") if side == "right" else ("DL", "ML")
            n = o.nR if side == "right" else o.nL
            old_D = [p[f"{D_name}{i}"] for i in range(1, n)]
            old_M = [p[f"{M_name}{i}"] for i in range(1, n + 1)]
            part = u[u > 0] if side == "right" else -u[u < 0]
            if part.size < cls.min_side:
                # an input that (almost) never reaches this side of zero: a segment there
                # has no samples to be fitted on
                continue
            vectors = []
            for q in cls.quantiles:
                D = float(np.quantile(part, q)) * (1 if side == "right" else -1)
                key = (lambda d: d) if side == "right" else (lambda d: -d)
                j = sum(key(d) < key(D) for d in old_D)
                D_new = old_D[:j] + [D] + old_D[j:]
                M_new = old_M[: j + 1] + [0.0] + old_M[j + 1 :]
                values = {f"{D_name}{i + 1}": v for i, v in enumerate(D_new)}
                values.update({f"{M_name}{i + 1}": v for i, v in enumerate(M_new)})
                vectors.append(_embed(model.params, orders, values))
            starts.append(Start(f"{cls.name}:{side}", orders, np.array(vectors), cls()))
        return starts
