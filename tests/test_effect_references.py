"""Every effect of `jc.EFFECTS` against its plain-NumPy reference (`oracle_effects.py`),
written from the documented definitions: `simulate_extended` of a model with the effect
on a fixed random input, sample for sample.

Tolerance: `10 N eps` times the output's scale, N = 400 samples. Each output sample is
a handful of floating-point operations on values carried by recursions of at most N
steps (the stop operators sum increments, the linear block's poles are stable, inside
radius 0.6), so the two implementations' roundings differ by at most about `N eps`
relative to the scale (worst case, every step's error adding up), the factor 10 for the
few operations per step; observed differences are ~1e-15. A difference above it is a
different definition, not rounding.
"""

import jax.numpy as jnp
import numpy as np
import oracle
import oracle_effects
import pytest

from jaxcascade._measured._effects import (
    EFFECTS,
    BacklashFriction,
    BacklashFrictionContacts,
    CurvedBacklash,
    DahlFriction,
    ExtendedModel,
    InnerKink,
    InnerPolynomial,
    InputBacklash,
    InputDelay,
    OutputDynamics,
    OutputFeedthrough,
    OutputOffset,
    OutputPolynomial,
    PrandtlIshlinskii,
    SlackFriction,
    VelocityFriction,
    plain,
    simulate_extended,
)
from jaxcascade._measured._noise import ARNoise
from jaxcascade._measured._testing import UNDECLARED
from jaxcascade._system._examples import example

N = 400
TOLERANCE = 10 * N * np.finfo(float).eps  # relative to the output's scale (docstring)


def _a(*values):
    return tuple(jnp.asarray(float(v)) for v in values)


def _with(*effects):
    return ExtendedModel(example(1).params(), effects, ARNoise.white())


# A model with each effect: the synthetic records' (`UNDECLARED`) where there is one,
# else Example 1 with the effect at sizes in the range of an input of amplitude 2.
MODELS = {
    **{name: (lambda name=name: UNDECLARED[name]()[0]) for name in UNDECLARED if name in EFFECTS},
    "slack_friction": lambda: _with(SlackFriction(*_a(0.3, 0.4, 1.0, -0.8))),
    "backlash_friction": lambda: _with(BacklashFriction(*_a(0.2, 5.0, 1.0, 0.8, 0.1))),
    "backlash_friction_contacts": lambda: _with(
        BacklashFrictionContacts(*_a(0.2, 5.0, 1.0, 0.8, 0.1))
    ),
    "prandtl_ishlinskii": lambda: _with(
        PrandtlIshlinskii(
            jnp.array([0.1, 0.4]), jnp.array([0.5]), jnp.linspace(-1.0, 1.0, 6), jnp.asarray(0.2)
        )
    ),
    "dahl_friction": lambda: _with(DahlFriction(*_a(4.0, 0.7))),
    "input_backlash": lambda: _with(InputBacklash(*_a(0.25))),
    # the note's general1: Example 1 with cubic terms on both branches
    "general_backlash": lambda: _with(
        CurvedBacklash(jnp.array([0.0, 0.04]), jnp.array([0.0, 0.05]))
    ),
    # Coulomb friction on Example 1's x taken as a velocity (`_testing.INTEGRATING`'s
    # forces)
    "velocity_friction": lambda: _with(VelocityFriction(jnp.array([0.3, 0.4]))),
    # added after the output dynamics, acting before them: the sandwich
    "inner_polynomial": lambda: _with(
        OutputDynamics(jnp.array([0.4]), jnp.array([-0.6]), jnp.asarray(0.0)),
        InnerPolynomial(jnp.array([0.0, 0.15, -0.08])),
    ),
    # a two-slope (diode-like) map between the two linear blocks
    "inner_kink": lambda: _with(
        OutputDynamics(jnp.array([0.4]), jnp.array([-0.6]), jnp.asarray(0.0)),
        InnerKink(jnp.array([0.0, 0.5, 0.1])),
    ),
}


def _input():
    """200 samples uniform in (-2, 2) (every segment, every backlash regime, operators
    saturating), then 200 of a smooth random walk (operators sliding and at rest)."""
    rng = np.random.default_rng(2024)
    walk = 2.0 * np.tanh(np.cumsum(rng.normal(scale=0.15, size=N // 2)))
    return np.concatenate([rng.uniform(-2.0, 2.0, N // 2), walk])


def _compare(model, effective=None):
    u = _input()
    want = oracle_effects.simulate(model, u, effective)
    got = np.asarray(simulate_extended(model, jnp.asarray(u)))
    scale = float(np.max(np.abs(want)))
    np.testing.assert_allclose(got, want, rtol=0, atol=TOLERANCE * scale)


# Three effects keep a parameter off zero by a documented floor (`FLOOR` of the class:
# the slack's threshold, the Dahl level, the backlash friction's stiffness enter as
# |value| + FLOOR); the reference writes it out.
FLOORED = {
    "slack_friction": ("threshold", lambda v, f: abs(v) + f),
    "dahl_friction": ("level", lambda v, f: np.sign(v) * (abs(v) + f)),
    "backlash_friction": ("stiffness", lambda v, f: abs(v) + f),
    "backlash_friction_contacts": ("stiffness", lambda v, f: abs(v) + f),
}


def _floored(model):
    """The reference's effective values of the floored parameters of `model`."""
    effective = {}
    for effect in model.effects:
        if effect.name in FLOORED:
            field, value = FLOORED[effect.name]
            effective[effect.name] = {
                field: float(value(float(getattr(effect, field)), type(effect).FLOOR))
            }
    return effective


def test_every_effect_has_a_model_and_a_reference():
    assert set(MODELS) == set(EFFECTS)
    assert set(oracle_effects.KNOWN) == set(EFFECTS)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_effect_matches_its_documented_definition(name):
    model = MODELS[name]()
    _compare(model, _floored(model) or None)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_effect_changes_the_output(name):
    # the reference of every model differs from Example 1's plain cascade by a margin
    # (else the comparison above would not test the effect)
    u = _input()
    base = oracle_effects.simulate(plain(example(1).params()), u)
    with_effect = oracle_effects.simulate(MODELS[name](), u)
    assert np.max(np.abs(with_effect - base)) > 0.02 * np.max(np.abs(base))


# The documented sign conventions: "signs of the first four are immaterial" (backlash
# friction), a negative Dahl level is the force with the opposite sign; the floors as
# above.
SIGNS = {
    "slack_friction": SlackFriction(*_a(-0.3, 0.4, 1.0, -0.8)),
    "dahl_friction_negative_level": DahlFriction(*_a(4.0, -0.7)),
    "backlash_friction_signs": BacklashFriction(*_a(-0.2, -5.0, 1.0, -0.8, 0.1)),
    "backlash_friction_contacts": BacklashFrictionContacts(*_a(0.2, 5.0, 1.0, 0.8, 0.1)),
}


@pytest.mark.parametrize("case", list(SIGNS))
def test_effect_signs_as_documented(case):
    model = _with(SIGNS[case])
    _compare(model, _floored(model))


def test_effects_compose_in_order():
    # two input effects in their order (a delay, then a play operator), two output
    # effects and a parallel path: y = outputs(cascade(inputs(u)), x) + path(u)
    model = _with(
        InputDelay(*_a(2.0)),
        InputBacklash(*_a(0.25)),
        OutputOffset(*_a(0.6)),
        OutputFeedthrough(*_a(-0.5)),
        MODELS["prandtl_ishlinskii"]().effects[0],
    )
    _compare(model)
    # the order of the input effects matters here: the reference says so
    swapped = model.with_(effects=(model.effects[1], model.effects[0], *model.effects[2:]))
    u = _input()
    assert (
        np.max(np.abs(oracle_effects.simulate(swapped, u) - oracle_effects.simulate(model, u)))
        > 0.01
    )


def test_an_inner_map_acts_before_the_output_dynamics():
    # the same map added after output_dynamics: inner_polynomial goes between the two
    # linear blocks (as if added before them), output_polynomial after the second
    dynamics = OutputDynamics(jnp.array([0.4]), jnp.array([-0.6]), jnp.asarray(0.0))
    coefficients = jnp.array([0.0, 0.15, -0.08])
    inner = _with(dynamics, InnerPolynomial(coefficients))
    before = _with(OutputPolynomial(coefficients), dynamics)
    after = _with(dynamics, OutputPolynomial(coefficients))
    u = jnp.asarray(_input())
    np.testing.assert_allclose(
        simulate_extended(inner, u), simulate_extended(before, u), atol=1e-12
    )
    assert np.max(np.abs(simulate_extended(inner, u) - simulate_extended(after, u))) > 0.01
    assert inner.structure().endswith("backlash -> inner_polynomial -> output_dynamics -> y")
    _compare(inner)


def test_operators_of_the_reference_on_a_closed_form():
    # The reference's stop operator on a ramp up and down: it follows the increments
    # from 0, saturates at r, and leaves +r with the first decrement.
    u = np.r_[np.linspace(0.0, 1.0, 11), np.linspace(0.9, 0.0, 10)]
    s = oracle_effects.stop(u, 0.35)
    np.testing.assert_allclose(s[:4], u[:4], atol=1e-15)
    np.testing.assert_allclose(s[4:11], 0.35)
    np.testing.assert_allclose(s[11:], np.clip(0.35 - (1.0 - u[11:]), -0.35, 0.35), atol=1e-15)
    # the cascade part of the reference is `oracle.simulate` of the model's parameters
    P = oracle.unpack(
        {k: float(v) for k, v in example(1).params().to_dict().items()}, example(1).orders
    )
    np.testing.assert_array_equal(
        oracle_effects.simulate(plain(example(1).params()), _input()),
        oracle.simulate(P, _input())[2],
    )


@pytest.mark.parametrize("name", ["backlash_friction", "backlash_friction_contacts"])
def test_rotor_starts_match_the_documented_ones(name):
    # `_input` jumps onto a contact at its first samples, where every start of the rotor
    # gives the same force: here the input grows slowly from zero, so the rotor stays in
    # the slack for a while and the force there is the average over the documented starts
    # (evenly on the slack; against either side of it), which differ by a margin.
    model = MODELS[name]()
    t = np.arange(N)
    u = 0.6 * (t / N) * np.sin(2 * np.pi * t / 80)
    effective = _floored(model) or None
    want = oracle_effects.simulate(model, u, effective)
    got = np.asarray(simulate_extended(model, jnp.asarray(u)))
    np.testing.assert_allclose(got, want, rtol=0, atol=TOLERANCE * float(np.max(np.abs(want))))
    others = {**oracle_effects.ROTOR_STARTS}
    other = next(k for k in others if k != name)
    oracle_effects.ROTOR_STARTS[name], saved = others[other], others[name]
    try:
        changed = oracle_effects.simulate(model, u, effective)
    finally:
        oracle_effects.ROTOR_STARTS[name] = saved
    assert np.max(np.abs(changed - want)) > 1e-3 * float(np.max(np.abs(want)))
