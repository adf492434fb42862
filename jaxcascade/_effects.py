"""The effect library: extensions of the cascade that the model-error loop can add.

An `Effect` is a model extension with its own parameters, a way to start them from a
fitted model (its estimation hook), and a residual *signature*: the residual tests
(names from `ResidualTests.tests()`) that fail when the effect is present but not
modelled. The extended model is

    y = output_effects(cascade(input_effects(u)))

with structural effects (`dynamics_order`, `pwl_segment`) changing the cascade's orders
instead, and the noise model (`colored_noise`) acting on the residual only.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._model import CascadeParams, Orders
from ._simulate import signals


class ExtendedModel(eqx.Module):
    """A cascade plus effects.

    - `params`: the cascade (its orders include structural effects).
    - `effects`: names of the added effects, in order (static).
    - `free`: per effect, its continuous parameters (`Float[Array, " k"]`).
    - `fixed`: per effect, parameters held during refinement (e.g. an integer delay).
    - `noise`: AR coefficients `c` of the noise model `e(t) = w(t) + sum_i c_i e(t-i)`
      (empty without `colored_noise`).
    """

    params: CascadeParams
    free: tuple
    fixed: tuple
    noise: jax.Array
    effects: tuple[str, ...] = eqx.field(static=True)

    @property
    def orders(self) -> Orders:
        return self.params.orders


def plain(params: CascadeParams) -> ExtendedModel:
    """The declared cascade with no effect added."""
    return ExtendedModel(params, (), (), jnp.zeros((0,), params.mR.dtype), ())


def simulate_extended(model: ExtendedModel, u):
    """Free-run simulation of the extended model."""
    return simulate_with_switches(model, u)[0]


def simulate_with_switches(model: ExtendedModel, u):
    """Simulated output and the backlash regime signals `(y, x, y_cascade)`."""
    for name, free, fixed in zip(model.effects, model.free, model.fixed, strict=True):
        u = EFFECTS[name].input(u, free, fixed)
    inner = signals(model.params, u)
    y = inner.y
    for name, free, fixed in zip(model.effects, model.free, model.fixed, strict=True):
        y = EFFECTS[name].output(y, free, fixed, inner.x)
    return y, inner.x, inner.y


def whiten(model: ExtendedModel, residual):
    """The noise model's innovations `w(t) = e(t) - sum_i c_i e(t-i)` (identity without one)."""
    q = model.noise.shape[0]
    out = residual
    for i in range(1, q + 1):
        out = out - model.noise[i - 1] * jnp.concatenate(
            [jnp.zeros((i,), residual.dtype), residual[:-i]]
        )
    return out


@dataclasses.dataclass(frozen=True)
class Start:
    """Starting points of one candidate structure: a batch of `S` starts of equal shape."""

    label: str
    orders: Orders
    vectors: np.ndarray  # (S, P') cascade parameters in `Orders.names` order
    free: np.ndarray  # (S, k)
    fixed: np.ndarray  # (S, m)


class Effect:
    """Base class: an effect that changes nothing. Subclasses override what they use."""

    name: str = ""
    signature: tuple[str, ...] = ()
    description: str = ""
    noise_model: bool = False

    def input(self, u, free, fixed):
        return u

    def output(self, y, free, fixed, x):
        return y

    def starts(self, model: ExtendedModel, u, y, residual) -> list[Start]:
        """Candidate starts for adding this effect to `model` (host side, numpy)."""
        vector = np.asarray(model.params.to_vector())
        free, fixed = self.initial(u, y, residual)
        return [Start(self.name, model.orders, vector[None], free[None], fixed[None])]

    def initial(self, u, y, residual) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0), np.zeros(0)


class OutputOffset(Effect):
    """A constant added to the output. An offset `d` with `cL + d >= 0` and
    `cR - d / mR >= 0` is exactly a change of the backlash gaps (the output of a backlash
    plus `d` is the backlash with gaps `cL + d`, `cR - d / mR`), so only a larger offset
    is an effect the declared model cannot already represent."""

    name = "output_offset"
    signature = ("mean",)
    description = "constant offset added to the output: y + d"

    def output(self, y, free, fixed, x):
        return y + free[0]

    def initial(self, u, y, residual):
        return np.array([np.mean(residual)]), np.zeros(0)


class OutputDrift(Effect):
    name = "output_drift"
    signature = ("time",)
    description = "linear drift of the output over the record: y + d t / 1000 (t in samples)"

    def output(self, y, free, fixed, x):
        return y + free[0] * jnp.arange(y.shape[0], dtype=y.dtype) / 1000.0

    def initial(self, u, y, residual):
        t = np.arange(len(residual)) / 1000.0
        slope = np.polyfit(t, residual, 1)[0]
        return np.array([slope]), np.zeros(0)


class OutputSaturation(Effect):
    name = "output_saturation"
    signature = ("level", "regime", "u2_e", "u2_e2", "mean")
    description = "output clipped to [lower, upper] (a sensor or actuator limit)"

    def output(self, y, free, fixed, x):
        return jnp.clip(y, free[0], free[1])

    def initial(self, u, y, residual):
        return np.quantile(y, [0.005, 0.995]), np.zeros(0)


class OutputFeedthrough(Effect):
    """A parallel linear path from the linear block's output to the measured output.

    With `d = -1` and `mR = 1` the output `y - x` is minus the *stop* operator of `x`
    (elastic-plastic, or Coulomb friction with stiffness): the force of a friction
    element, where the cascade alone gives the *play* (the slack position).
    """

    name = "output_feedthrough"
    signature = ("cross_correlation", "level", "regime", "u2_e")
    description = "parallel linear path from x to the output: y + d x"

    def output(self, y, free, fixed, x):
        return y + free[0] * x

    def starts(self, model, u, y, residual):
        vector = np.asarray(model.params.to_vector())
        free = np.array([[-1.0], [-0.5], [0.5]])
        return [
            Start(self.name, model.orders, np.repeat(vector[None], 3, 0), free, np.zeros((3, 0)))
        ]


class InputDelay(Effect):
    name = "input_delay"
    signature = ("cross_correlation", "autocorrelation")
    description = "pure input delay of d samples: u(t - d)"
    max_delay = 5

    def input(self, u, free, fixed):
        d = fixed[0].astype(jnp.int32)
        index = jnp.arange(u.shape[0]) - d
        return jnp.where(index >= 0, u[jnp.clip(index, 0, None)], 0.0)

    def starts(self, model, u, y, residual):
        vector = np.asarray(model.params.to_vector())
        delays = np.arange(1, self.max_delay + 1, dtype=float)
        count = len(delays)
        return [
            Start(
                self.name,
                model.orders,
                np.repeat(vector[None], count, 0),
                np.zeros((count, 0)),
                delays[:, None],
            )
        ]


def _embed(params: CascadeParams, orders: Orders, values: dict) -> np.ndarray:
    """Vector for `orders` from `params` plus new entries `values` (others from params)."""
    old = params.to_dict()
    return np.array([values.get(name, old.get(name, 0.0)) for name in orders.names])


class DynamicsOrder(Effect):
    name = "dynamics_order"
    signature = ("autocorrelation", "cross_correlation", "spectrum")
    description = "one more pole (p + 1) or zero (r + 1) in the linear block"

    def starts(self, model, u, y, residual):
        o = model.orders
        starts = []
        for label, orders in (
            ("pole", Orders(o.nR, o.nL, o.r, o.p + 1)),
            ("zero", Orders(o.nR, o.nL, o.r + 1, o.p)),
        ):
            vector = _embed(model.params, orders, {})
            starts.append(
                Start(
                    f"{self.name}:{label}", orders, vector[None], np.zeros((1, 0)), np.zeros((1, 0))
                )
            )
        return starts


class PwlSegment(Effect):
    name = "pwl_segment"
    signature = ("level", "u2_e", "u2_e2", "cross_correlation")
    description = "one more breakpoint (segment) in the static input nonlinearity"
    quantiles = (0.2, 0.4, 0.6, 0.8)

    def starts(self, model, u, y, residual):
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
            vectors = []
            for q in self.quantiles:
                D = float(np.quantile(part, q)) * (1 if side == "right" else -1)
                key = (lambda d: d) if side == "right" else (lambda d: -d)
                j = sum(key(d) < key(D) for d in old_D)
                D_new = old_D[:j] + [D] + old_D[j:]
                M_new = old_M[: j + 1] + [0.0] + old_M[j + 1 :]
                values = {f"{D_name}{i + 1}": v for i, v in enumerate(D_new)}
                values.update({f"{M_name}{i + 1}": v for i, v in enumerate(M_new)})
                vectors.append(_embed(model.params, orders, values))
            count = len(vectors)
            starts.append(
                Start(
                    f"{self.name}:{side}",
                    orders,
                    np.array(vectors),
                    np.zeros((count, 0)),
                    np.zeros((count, 0)),
                )
            )
        return starts


class ColoredNoise(Effect):
    """Autoregressive output noise: explains a coloured residual that the input cannot.

    It changes no simulated output; it is fitted to the residual by least squares
    (order by BIC up to `max_order`) and whitens the residual the tests see.
    """

    name = "colored_noise"
    signature = ("autocorrelation", "spectrum")
    description = "autoregressive output noise e(t) = w(t) + c1 e(t-1) + ... + cq e(t-q)"
    noise_model = True
    max_order = 4

    def fit(self, residual) -> tuple[np.ndarray, float]:
        """AR coefficients by least squares with the order chosen by BIC, and the p-value
        of the likelihood-ratio test against white noise."""
        import scipy.stats

        e = np.asarray(residual, dtype=float)
        n = len(e)
        best = (n * np.log(np.mean(e**2)), np.zeros(0), np.mean(e**2))
        for q in range(1, self.max_order + 1):
            X = np.stack([e[q - i : n - i] for i in range(1, q + 1)], axis=1)
            c, *_ = np.linalg.lstsq(X, e[q:], rcond=None)
            variance = np.mean((e[q:] - X @ c) ** 2)
            bic = n * np.log(variance) + q * np.log(n)
            if bic < best[0]:
                best = (bic, c, variance)
        q = len(best[1])
        if q == 0:
            return best[1], 1.0
        statistic = n * np.log(np.mean(e**2) / best[2])
        return best[1], float(scipy.stats.chi2.sf(statistic, q))


EFFECTS: dict[str, Effect] = {
    effect.name: effect
    for effect in (
        OutputOffset(),
        InputDelay(),
        DynamicsOrder(),
        PwlSegment(),
        OutputSaturation(),
        ColoredNoise(),
        OutputDrift(),
        OutputFeedthrough(),
    )
}


# ---- records with an undeclared effect (tests and benchmarks/effects_loop.py) ----------


def _example1():
    from ._examples import example

    return example(1).params()


def _with_effect(name, free, fixed=()):
    return ExtendedModel(
        _example1(),
        (jnp.asarray(free, float),),
        (jnp.asarray(fixed, float),),
        jnp.zeros((0,)),
        (name,),
    )


def _changed(**values):
    v = _example1().to_dict()
    v.update(values)
    return plain(CascadeParams.from_dict(v))


def _extra_pole():
    b = np.real(np.poly([0.5, 0.3 + 0.4j, 0.3 - 0.4j]))[1:]
    return _changed(b1=b[0], b2=b[1], b3=b[2])


# Example 1 (declared orders 2,2,2,2) with one effect present, and the AR coefficient of
# the output noise (None: white). Sizes are identifiable: an output offset within the
# backlash gaps is exactly a gap change (y + d is a backlash with cL + d, cR - d / mR),
# so the offset here exceeds what the gaps can absorb.
UNDECLARED = {
    "output_offset": lambda: (_with_effect("output_offset", [0.6]), None),
    "input_delay": lambda: (_with_effect("input_delay", [], [2]), None),
    "dynamics_order": lambda: (_extra_pole(), None),
    "pwl_segment": lambda: (_changed(DR2=1.5, MR3=1.5), None),
    "output_saturation": lambda: (_with_effect("output_saturation", [-0.7, 0.9]), None),
    "colored_noise": lambda: (plain(_example1()), 0.8),
    "output_drift": lambda: (_with_effect("output_drift", [0.2]), None),
    "output_feedthrough": lambda: (_with_effect("output_feedthrough", [-0.5]), None),
    None: lambda: (plain(_example1()), None),
}


def undeclared_record(model: ExtendedModel, key, n: int, snr: float, ar=None):
    """Input uniform in (-2, 2) and the model's output plus noise at amplitude SNR `snr`
    (white, or AR(1) with coefficient `ar`, scaled to the same variance)."""
    import scipy.signal

    from ._simulate import uniform_input

    k_input, k_noise = jax.random.split(key)
    u = uniform_input(k_input, n)
    y = simulate_extended(model, u)
    e = np.asarray(jax.random.normal(k_noise, (n,)))
    if ar is not None:
        e = scipy.signal.lfilter([1.0], [1.0, -ar], e)
    e = e / np.std(e) * float(jnp.std(y)) / snr
    return u, y + jnp.asarray(e, y.dtype)
