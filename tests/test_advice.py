"""Advice from the evidence (`_measured._advice`, issue 68 item 4): one synthetic record
per kind of advice, the advice found on it and not on the clean record, and the verdict
saying it in place of the generic options."""

import jax
import numpy as np
import pytest

import jaxcascade as jc
from jaxcascade._measured import _advice
from jaxcascade._measured._integrating import integration
from jaxcascade._measured._scoring import RecordScore, verdict


def _output(seed: int = 0, n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """Example 1 on a uniform input: an output that crosses zero, neither clipped nor
    quantised nor folded."""
    u = np.asarray(jc.uniform_input(jax.random.PRNGKey(seed), n))
    return u, np.asarray(jc.simulate(jc.example(1).params(), u))


def test_a_clean_record_gets_no_advice():
    _, y = _output()
    assert _advice.advise([y]) == []
    assert _advice.advise([y], failed=["whiteness"])[0].kind == "missing_effect"


def test_a_clipped_output_is_named_with_output_saturation():
    _, y = _output()
    limit = np.quantile(y, 0.95)
    (advice,) = _advice.advise([np.minimum(y, limit)])
    assert advice.kind == "clipped" and "largest value" in advice.evidence
    assert "output_saturation" in advice.option
    assert "5.0 %" in advice.evidence  # the share of samples at the limit


def test_a_quantised_output_is_named_with_its_floor():
    _, y = _output()
    step = np.ptp(y) / 20
    (advice,) = _advice.advise([np.round(y / step) * step])
    assert advice.kind == "quantised"
    floor = step / np.sqrt(12) / np.std(np.round(y / step) * step)
    assert f"{floor:.3g}" in advice.evidence
    # a fine grid (more levels than QUANTISED_LEVELS) is no quantisation worth a word
    fine = np.ptp(y) / 1000
    assert _advice.quantised(np.round(y / fine) * fine) is None


def test_a_sign_blind_output_is_named_with_output_fold():
    _, y = _output()
    folded = 0.3 + np.abs(y - np.median(y))  # a sensor reading |x| around an offset
    (advice,) = _advice.advise([folded])
    assert advice.kind == "sign_blind" and "output_fold" in advice.option
    assert "never goes below 0.3" in advice.evidence
    # an output clipped at its floor is flat there, not folded: named clipped instead
    (clipped,) = _advice.advise([np.maximum(y, np.quantile(y, 0.1))])
    assert clipped.kind == "clipped" and "smallest value" in clipped.evidence


def test_an_integrating_output_names_what_integrate_did():
    u, _ = _output()
    rng = np.random.default_rng(0)
    u = np.convolve(u, np.ones(20) / 20, mode="same")  # a slow force
    y = np.cumsum(u) + 0.01 * rng.normal(size=u.size)  # its position
    record = jc.record_from_arrays(u, y, sample_period=0.001)
    found = integration([record], "auto")
    assert found is not None  # the loop would model the difference
    (advice,) = _advice.advise([record.y_physical], integration=found)
    assert advice.kind == "integrating"
    assert "--integrate auto" in advice.evidence and "velocity_friction" in advice.option
    # with --integrate no: the peer's pole on the unit circle, and the option to use
    (advice,) = _advice.advise([record.y_physical], unstable_pole=1.0003)
    assert "|z| = 1.0003" in advice.evidence and "--integrate" in advice.option
    _, clean = _output()
    clean_record = jc.record_from_arrays(_output()[0], clean, sample_period=0.001)
    assert integration([clean_record], "auto") is None


def test_an_integrator_whose_pole_friction_pulled_inside_is_named_with_integrate_yes():
    # an axis under proportional control with Coulomb friction (`axis_record`, seed 3):
    # the equation-error fit's pole lies inside the unit circle, so `--integrate auto`
    # leaves the record to a stable model; its gain at zero frequency is an integrator's
    from jaxcascade._measured._arx import best_arx
    from jaxcascade._measured._integrating import INTEGRATOR_GAIN, leaky_integrator
    from jaxcascade._measured._testing import INTEGRATING, axis_record

    key, _ = jax.random.split(jax.random.PRNGKey(3))
    u, y = axis_record(key, 1025, 30.0, INTEGRATING["velocity_friction"])
    record = jc.record_from_arrays(u, y, sample_period=0.001)
    assert integration([record], "auto") is None
    leaky = leaky_integrator(best_arx(record.u, record.y), record.u, record.y)
    assert leaky is not None and 0.95 <= leaky[0] < 0.999 and leaky[1] >= INTEGRATOR_GAIN
    (advice,) = _advice.advise([record.y_physical], leaky=leaky)
    assert advice.kind == "integrating" and f"|z| = {leaky[0]:.4f}" in advice.evidence
    assert "--integrate yes" in advice.option and "velocity_friction" in advice.option
    # a cascade on a broadband input: no slow pole with an integrator's gain
    u, y = _output()
    assert leaky_integrator(best_arx(u, y), u, y) is None


def test_a_record_leaving_the_estimation_range_is_named():
    # the coverage of the input (`_coverage`) flags it; the advice names the record
    u, y = _output()
    from jaxcascade._measured import _coverage

    rows = _coverage.coverage([("train.csv", u, y)], [("test.csv", "test", 2.0 * u, y)])
    uncovered = sorted({name for name, _ in _coverage.uncovered(rows)})
    assert uncovered == ["test.csv"]
    (advice,) = _advice.advise([y], uncovered=uncovered)
    assert advice.kind == "range" and advice.evidence.startswith("test.csv leaves")


def test_residual_tests_that_still_fail_name_a_missing_mechanism():
    _, y = _output()
    (advice,) = _advice.advise([y], failed=["hysteresis", "level"])
    assert advice.kind == "missing_effect"
    assert "hysteresis, level tests" in advice.evidence and "lacks" in advice.option
    # explained evidence comes first: a clipped output is not called a missing mechanism
    limit = np.quantile(y, 0.95)
    kinds = [a.kind for a in _advice.advise([np.minimum(y, limit)], failed=["level"])]
    assert kinds == ["clipped"]


@pytest.mark.parametrize("with_advice", [False, True])
def test_the_verdict_says_the_advice_in_place_of_the_generic_options(with_advice):
    def row(model, error):
        return RecordScore(model, "valid.csv", "validation", error, None, error, None, 50)

    _, y = _output()
    advice = _advice.advise([np.minimum(y, np.quantile(y, 0.95))]) if with_advice else []
    (sentence,) = verdict([row("final model", 1.2)], [row("linear ARX", 0.9)], advice=advice)
    assert sentence.startswith("The final model is worse than the mean of the output")
    if with_advice:
        assert "output_saturation" in sentence and "try the hysteresis" not in sentence
    else:
        assert "try the hysteresis effects" in sentence
