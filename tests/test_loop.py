"""The model-error loop on data with an effect the declared model lacks (issue 5).

Each record is Example 1 (orders 2,2,2,2 declared) with one effect of the library
present but undeclared, at SNR 20 (noise floor 1/SNR = 0.05), 2000 estimation and 2000
validation samples. The loop must name the effect and bring the validation NRMSE
within 1.5 times the noise floor; on a record without an extra effect it must add
nothing. Effect sizes are chosen to be identifiable: e.g. an output offset smaller than
the backlash gaps is *exactly* a gap change (y + d is a backlash with cL + d and
cR - d / mR), so the offset used here exceeds what the gaps can absorb.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

import jaxcascade as jc
from jaxcascade._effects import EFFECTS, ExtendedModel, OutputOffset, simulate_extended
from jaxcascade._loop import model_error_loop, paired_improvement
from jaxcascade._noise import ARNoise
from jaxcascade._testing import UNDECLARED, undeclared_record

SNR = 20.0
N = 2000
TRUTH = jc.example(1).params


@pytest.mark.parametrize("effect", list(UNDECLARED), ids=lambda e: str(e))
def test_loop_names_the_undeclared_effect(effect):
    model, ar = UNDECLARED[effect]()
    u, y = undeclared_record(model, jax.random.PRNGKey(1), N, SNR, ar)
    u_val, y_val = undeclared_record(model, jax.random.PRNGKey(2), N, SNR, ar)
    result = model_error_loop(u, y, u_val, y_val, jc.Orders())
    expected = [] if effect is None else [effect]
    assert result.added == expected
    # 1.5 times the noise floor, the criterion; the floor is 1/SNR.
    assert result.after.error <= 1.5 / SNR
    if effect is not None and effect != "colored_noise":
        assert result.before.error > result.after.error
    assert result.after.tests.ok
    report = result.to_dict()
    assert report["effect_added"] == expected
    assert all(np.isfinite(c["error"]) for c in report["candidates"])


def test_every_effect_declares_a_signature():
    tests = {
        "autocorrelation",
        "cross_correlation",
        "e_eu",
        "u2_e",
        "u2_e2",
        "spectrum",
        "mean",
        "regime",
        "level",
        "time",
    }
    for effect in EFFECTS.values():
        assert effect.signature and set(effect.signature) <= tests, effect.name


def test_offset_within_the_gaps_is_a_gap_change():
    # The identifiability fact the offset test relies on: exact equality of outputs.
    p = TRUTH()
    d = 0.1
    u = jc.uniform_input(jax.random.PRNGKey(0), 500)
    v = p.to_dict()
    v.update(cL=v["cL"] + d, cR=v["cR"] - d / v["mR"])
    shifted = jc.simulate(jc.CascadeParams.from_dict(v), u)
    # Both backlash states start at y = 0, so compare after the first move has
    # settled the state on a line.
    offset = ExtendedModel(p, (OutputOffset(jnp.asarray(d)),), ARNoise.white())
    with_offset = simulate_extended(offset, u)
    start = int(np.argmax(np.abs(np.diff(np.asarray(shifted))) > 0)) + 5
    np.testing.assert_allclose(shifted[start:], with_offset[start:], atol=1e-12)


def test_innovations_invert_an_ar_filter():
    e = np.asarray(jax.random.normal(jax.random.PRNGKey(3), (1000,)))
    coloured = scipy.signal.lfilter([1.0], [1.0, -0.7, 0.2], e)
    noise = ARNoise(jnp.array([0.7, -0.2]))
    np.testing.assert_allclose(noise.innovations(jnp.asarray(coloured)), e, atol=1e-12)


def test_paired_improvement_sign():
    rng = np.random.default_rng(0)
    noise = rng.normal(size=2000)
    assert paired_improvement(noise + 0.5, noise) > 10
    assert paired_improvement(noise, noise + 0.5) < -10
    assert abs(paired_improvement(noise, rng.normal(size=2000))) < 4


def test_every_effect_of_the_library_has_an_undeclared_record():
    library = {*EFFECTS, ARNoise.name}
    assert library == {name for name in UNDECLARED if name is not None}
