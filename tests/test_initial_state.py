"""Initialised scoring (`_initial_state`): the state-carrying simulation from rest is the
package's simulation, continuing from a state read inside a record is the record's
continuation, and a state fitted on n samples recovers a record simulated from a state
other than rest; the parameters are never changed, and compilation is bounded."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcascade._compile import bucket_length as bucket
from jaxcascade._compile import filter_jit
from jaxcascade._measured._effects import (
    EFFECTS,
    BacklashFriction,
    BacklashFrictionContacts,
    CurvedBacklash,
    DahlFriction,
    DirectTerm,
    DynamicsOrder,
    ExtendedModel,
    InnerKink,
    InnerPolynomial,
    InputBacklash,
    InputDelay,
    NonlinearFeedback,
    OutputDrift,
    OutputDynamics,
    OutputFeedthrough,
    OutputFold,
    OutputOffset,
    OutputPolynomial,
    OutputSaturation,
    PrandtlIshlinskii,
    PwlSegment,
    SlackFriction,
    VelocityFriction,
    simulate_with_switches,
)
from jaxcascade._measured._initial_state import (
    initialise,
    innovations_from,
    rest_state,
    scored,
    simulate_from,
)
from jaxcascade._measured._noise import ARNoise
from jaxcascade._system._examples import example

# compiled once per model structure: called eagerly, every `lax.scan` in them compiles
# a program of its own at every call
_simulate_from = filter_jit(simulate_from)
_simulate_with_switches = filter_jit(simulate_with_switches)


def _a(*values):
    return tuple(jnp.asarray(v) for v in values)


# One instance of every registered effect (parameters in the range of the example's
# input, amplitude 2).
INSTANCES = {
    "output_offset": OutputOffset(*_a(0.3)),
    "input_delay": InputDelay(*_a(2.0)),
    "dynamics_order": DynamicsOrder(),
    "pwl_segment": PwlSegment(),
    "output_saturation": OutputSaturation(*_a(-1.0, 1.2)),
    "output_drift": OutputDrift(*_a(0.5)),
    "output_feedthrough": OutputFeedthrough(*_a(-0.5)),
    "slack_friction": SlackFriction(*_a(0.3, 0.4, 1.0, -0.8)),
    "backlash_friction": BacklashFriction(*_a(0.2, 5.0, 1.0, 0.8, 0.1)),
    "backlash_friction_contacts": BacklashFrictionContacts(*_a(0.2, 5.0, 1.0, 0.8, 0.1)),
    "prandtl_ishlinskii": PrandtlIshlinskii(
        jnp.array([0.1, 0.4]), jnp.array([0.5]), jnp.linspace(-1.0, 1.0, 6), jnp.asarray(0.2)
    ),
    "dahl_friction": DahlFriction(*_a(4.0, -0.7)),
    "input_backlash": InputBacklash(*_a(0.25)),
    "general_backlash": CurvedBacklash(jnp.array([0.0, 0.04]), jnp.array([0.0, 0.05])),
    "nonlinear_feedback": NonlinearFeedback(jnp.array([0.05, -0.08])),
    "direct_term": DirectTerm(jnp.array([0.6])),
    "velocity_friction": VelocityFriction(jnp.array([0.3, 0.4])),
    "output_polynomial": OutputPolynomial(jnp.array([0.0, 0.15, -0.08])),
    "output_fold": OutputFold(jnp.array([0.0, 1.0, 0.0, -0.4])),
    "output_dynamics": OutputDynamics(jnp.array([0.4]), jnp.array([-0.6]), jnp.asarray(0.1)),
    "inner_polynomial": InnerPolynomial(jnp.array([0.0, 0.15, -0.08])),
    "inner_kink": InnerKink(jnp.array([0.0, 0.5, 0.1])),
}


def _input(T, seed=0):
    # a smooth random walk, so that operators both slide and rest
    steps = np.random.default_rng(seed).normal(scale=0.15, size=T)
    return jnp.asarray(2.0 * np.tanh(np.cumsum(steps)))


def _model(*effects, noise=None):
    params = example(1).params()
    return ExtendedModel(params, effects, noise or ARNoise.white(params.mR.dtype))


def test_every_effect_has_an_instance_here():
    assert set(INSTANCES) == set(EFFECTS)


@pytest.mark.parametrize("name", [None, *EFFECTS])
def test_from_rest_is_the_package_simulation_and_a_state_continues_it(name):
    model = _model() if name is None else _model(INSTANCES[name])
    u = _input(300, seed=1)
    expected = _simulate_with_switches(model, u)
    got = _simulate_from(model, u, rest_state(model, u))
    # the same arithmetic but for the order of a few additions (the poles' forcing)
    for a, b in zip(expected, got[:3], strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)
    # the state read before sample k (inside a padded record: `at`) continues the record
    k = 137
    padded = jnp.concatenate([u, jnp.full((50,), u[-1])])
    state = _simulate_from(model, padded, rest_state(model, padded), jnp.asarray(k))[3]
    tail = _simulate_from(model, u[k:], state)[0]
    np.testing.assert_allclose(tail, expected[0][k:], rtol=1e-10, atol=1e-10)


def test_innovations_from_zero_past_are_the_noise_models():
    noise = ARNoise(jnp.array([0.5, -0.2]))
    e = _input(100)
    np.testing.assert_allclose(
        innovations_from(_model(noise=noise), e, jnp.zeros(2)), noise.innovations(e), atol=1e-14
    )


def _held_input(T, seed=3):
    """Small motion about 0.23 for 150 samples, then a random walk. The motion moves
    the backlash and the friction effects' rotor within their slack, never through
    it: the record remembers where it started, and its first samples show where."""
    t = np.arange(150)
    hold = 0.23 + 0.15 * np.sin(t / 5)
    steps = np.random.default_rng(seed).normal(scale=0.1, size=T - 150)
    return jnp.asarray(np.concatenate([hold, hold[-1] + 1.5 * np.tanh(np.cumsum(steps))]))


def _non_rest(model, u):
    """Ground truth: the model simulated from rest after a prefix of input the scorer
    never sees, a ramp up to 1.5 and back to `u(0)` (a state other than rest at the
    record's start: the backlash and the operators against their upper side)."""
    prefix = jnp.concatenate([jnp.linspace(0.0, 1.5, 100), jnp.linspace(1.5, float(u[0]), 100)])
    joined = jnp.concatenate([prefix, u])
    return _simulate_from(model, joined, rest_state(model, joined))[0][200:]


@pytest.mark.parametrize(
    "effects",
    [
        (),
        (INSTANCES["backlash_friction"],),
        (INSTANCES["input_backlash"],),
        (INSTANCES["general_backlash"],),
    ],
    ids=["cascade", "backlash_friction", "input_backlash", "general_backlash"],
)
def test_initialise_recovers_a_state_other_than_rest(effects):
    model = _model(*effects)
    u = _held_input(400)
    y = _non_rest(model, u)
    start, n = 50, 50  # the state is fitted at sample 0, where the record begins
    result = scored(model, u, y, start, n=n)
    fit = result.initialised
    assert fit.first == 0
    span = float(np.std(np.asarray(y)[start:]))
    # from rest the record's start is wrong (by a margin, else the test proves nothing)
    assert result.error_from_rest > 0.1
    # noise-free, the fitted state reproduces the record after `start` to the fit's
    # tolerances (1e-8 relative; the scored samples are beyond the fitted ones)
    np.testing.assert_allclose(fit.y[start:], np.asarray(y)[start:], atol=1e-4 * span)
    assert result.error < 1e-4
    # the parameters are the model's: the output is the model simulated from the state
    replay = _simulate_from(model, u, fit.state)[0]
    np.testing.assert_allclose(fit.y, replay, atol=1e-12 * span)


def test_initialise_inside_a_record_keeps_the_noise_past():
    # a clean record of the model with AR noise coefficients: the residual is zero, so
    # the innovations too, initialised (the past from the n samples) and from rest
    noise = ARNoise(jnp.array([0.6]))
    model = _model(INSTANCES["slack_friction"], noise=noise)
    u = _input(500, seed=4)
    y = _non_rest(model, u)
    result = scored(model, u, y, 300, 450, n=50)
    assert result.initialised.first == 250
    assert result.prediction_error < 1e-5
    assert np.all(np.isnan(result.initialised.y[:250]))
    # far from the record's start the from-rest run forgot its state: both agree
    assert result.error_from_rest < 1e-5


def test_start_below_n_is_raised_to_n():
    model = _model()
    u = _input(120)
    fit = initialise(model, u, _simulate_from(model, u, rest_state(model, u))[0], 10, 30)
    assert (fit.first, fit.start) == (0, 30)


def test_compilation_is_bounded_by_structure_and_bucket(monkeypatch):
    import jaxcascade._measured._initial_state as module

    # `_fit` runs once per trace of the module's compiled program; lengths of a bucket
    # used nowhere else make sure the first call here traces
    counted = eqx.debug.assert_max_traces(module._fit, max_traces=1)
    monkeypatch.setattr(module, "_fit", counted)
    model = _model(INSTANCES["dahl_friction"])
    lengths = [bucket(700) - d for d in (0, 5, 30)]
    assert len({bucket(t) for t in lengths}) == 1
    for T, start in zip(lengths, (60, 120, 250), strict=True):
        u = _input(T, seed=T)
        y = _simulate_from(model, u, rest_state(model, u))[0]
        scored(model, u, y, start, grid=(0.0, 1.0), max_steps=20)
    # another model of the same structure (other values) reuses it
    other = eqx.tree_at(lambda m: m.effects[0].sigma, model, jnp.asarray(2.0))
    u = _input(lengths[0])
    y = _simulate_from(other, u, rest_state(other, u))[0]
    scored(other, u, y, 80, grid=(0.0, 1.0), max_steps=20)
    assert eqx.debug.get_num_traces(counted) == 1
