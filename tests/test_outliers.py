"""Isolated outliers as an effect of the loop (`_measured._outliers`, issue 68 item 5):
the detector's false alarms on clean residuals, spikes found where they are, and the loop
on a record with spikes: named, left out, the estimates as on the clean record."""

import jax
import numpy as np
import pytest
import scipy.signal

import jaxcascade as jc
from jaxcascade._measured._outliers import ALPHA, find_outliers, impute, without


def test_a_clean_residual_rarely_has_an_outlier():
    # white Gaussian noise and a smooth model error with coloured noise: the rule (at
    # least Z_MIN robust scales, else the Bonferroni quantile of ALPHA) names hardly any
    rng = np.random.default_rng(0)
    white = np.mean([len(find_outliers(rng.normal(size=1000))) > 0 for _ in range(400)])
    t = np.arange(1000)
    coloured = np.mean(
        [
            len(
                find_outliers(
                    0.3 * np.sin(2 * np.pi * t / 150 + k)
                    + scipy.signal.lfilter([0.05], [1, -0.8], rng.normal(size=t.size))
                )
            )
            > 0
            for k in range(400)
        ]
    )
    # 400 records: a rate of 0.01 gives 4 +- 2; at most 3 ALPHA with margin
    assert white <= 3 * ALPHA and coloured <= 3 * ALPHA


def test_spikes_are_found_where_they_are_with_their_size():
    rng = np.random.default_rng(1)
    residual = 0.02 * rng.normal(size=1000)  # threshold: 8 robust scales, about 0.2
    spikes = {120: 0.8, 400: -0.6, 401: 0.0, 777: 0.5}
    for t, s in spikes.items():
        residual[t] += s
    found = find_outliers(residual)
    assert found.samples == (120, 400, 777)
    np.testing.assert_allclose(found.sizes, [0.8, -0.6, 0.5], atol=0.1)
    # a step or a burst is a mechanism, not an outlier
    burst = 0.02 * rng.normal(size=1000)
    burst[500:520] += 1.0
    assert len(find_outliers(burst)) == 0
    # left out of a score; replaced by the model's output
    y, model = np.zeros(1000), np.zeros(1000)
    y[list(found.samples)] = 1.0
    assert without(y + residual, model + residual, found) == pytest.approx(0.0, abs=1e-12)
    assert impute(y, model, found)[list(found.samples)].tolist() == [0.0, 0.0, 0.0]


def _records(spikes: dict):
    """Example 1 at SNR 50: an estimation and a validation record, the estimation
    record's output with `spikes` (sample: size in output units) added."""
    ex = jc.example(1)
    out = []
    for k, n in enumerate((600, 300)):
        key_u, key_e = jax.random.split(jax.random.PRNGKey(k))
        u = jc.uniform_input(key_u, n)
        y, _ = jc.measure(key_e, ex.params(), u, 50.0)
        y = np.array(y)
        if k == 0:
            for t, s in spikes.items():
                y[t] += s
        out.append((np.asarray(u), y))
    train = jc.record_from_arrays(*out[0], sample_period=0.01, source="train.csv")
    valid = jc.record_from_arrays(*out[1], sample_period=0.01, scaling=train.scaling)
    return train, valid


def test_the_loop_names_spikes_leaves_them_out_and_estimates_the_truth():
    """Four spikes of 5 to 6 output standard deviations on the estimation record: named
    (samples, sizes), left out, and every estimate within three standard errors of the
    truth (the record is in the paper's units); `results/outliers.md` runs the clean and
    the spiked records side by side over seeds."""
    train, _ = _records({})
    y_std = float(np.std(train.y_physical))
    spikes = {150: 6 * y_std, 300: -5 * y_std, 451: 5 * y_std, 520: -6 * y_std}
    run = jc.loop_records(*_records(spikes), max_effects=0, threads=1)
    (row,) = run.outliers
    assert row["record"] == "train.csv" and row["role"] == "estimation"
    assert row["samples"] == sorted(spikes)
    np.testing.assert_allclose(row["sizes"], [spikes[t] for t in sorted(spikes)], rtol=0.1)
    (sentence,) = run.outlier_sentences
    assert "4 isolated outlier(s)" in sentence and "left them out" in sentence
    model = run.to_dict()["model_after"]
    truth = jc.example(1).params().to_dict()
    for name, value in truth.items():
        assert abs(model["estimates"][name] - value) <= 3 * model["std_errors"][name], name
    assert run.to_dict(brief=True)["outliers"]["records"] == run.outliers
