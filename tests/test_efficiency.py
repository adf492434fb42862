"""The output-error Cramér-Rao bound: against finite differences, its batch forms, its
limits, the estimated standard errors of a fit, and the sweep summary's columns."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcascade as jc
from jaxcascade._estimator._efficiency import (
    crlb,
    fisher_information,
    jacobian,
    not_identifiable,
    standard_errors,
)
from jaxcascade._montecarlo._tables import crlb_column, summarise

EX = jc.example(1)


def _input(seed, n=2000):
    return jc.uniform_input(jax.random.PRNGKey(seed), n)


def _finite_difference_jacobian(params, u, h=1e-6):
    vector = np.asarray(params.to_vector())
    columns = []
    for i in range(vector.size):
        up, down = vector.copy(), vector.copy()
        up[i] += h
        down[i] -= h
        simulate = [
            np.asarray(jc.simulate(jc.CascadeParams.from_vector(jnp.asarray(v), params.orders), u))
            for v in (up, down)
        ]
        columns.append((simulate[0] - simulate[1]) / (2 * h))
    return np.stack(columns, axis=1)


@pytest.mark.parametrize("number", [1, 2])
def test_bound_agrees_with_finite_differences(number):
    # Central differences of the simulator (step 1e-6: truncation ~1e-12, rounding
    # ~1e-10 relative; a switching instant moved by the step is a measure-zero event).
    ex = jc.example(number)
    u = _input(3)
    params = ex.params()
    J = _finite_difference_jacobian(params, u)
    sigma = np.std(np.asarray(jc.simulate(params, u))) / 25.0
    reference = sigma * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    bound = np.asarray(crlb(params, u, snr=25.0))
    np.testing.assert_allclose(bound, reference, rtol=1e-4)
    np.testing.assert_allclose(np.asarray(jacobian(params, u)), J, atol=1e-6)


def test_batch_forms_and_limits():
    params = EX.params()
    us = jnp.stack([_input(seed) for seed in range(3)])
    per_record = np.stack([np.asarray(crlb(params, u, snr=25.0)) for u in us])
    # the cell's bound: the root of the mean per-record variance
    np.testing.assert_allclose(
        crlb(params, us, snr=25.0), np.sqrt(np.mean(per_record**2, 0)), rtol=1e-12
    )
    informations = [np.asarray(fisher_information(params, u, snr=25.0)) for u in us]
    np.testing.assert_allclose(
        fisher_information(params, us, snr=25.0), np.mean(informations, 0), rtol=1e-12
    )
    # the average of per-record bounds is the larger valid bound (Jensen)
    average_information = np.sqrt(np.diag(np.linalg.inv(np.mean(informations, 0))))
    assert np.all(np.sqrt(np.mean(per_record**2, 0)) >= average_information * (1 - 1e-9))
    # sigma and SNR say the same; noise-free, the bound is 0; four times the data halves it
    u = us[0]
    sigma = float(jnp.std(jc.simulate(params, u))) / 25.0
    np.testing.assert_allclose(crlb(params, u, sigma=sigma), crlb(params, u, snr=25.0))
    assert np.all(np.asarray(crlb(params, u, snr=jnp.inf)) == 0.0)
    long = crlb(params, _input(4, n=8000), snr=25.0)
    ratio = np.asarray(long) / np.asarray(crlb(params, _input(5, n=2000), snr=25.0))
    np.testing.assert_allclose(ratio, 0.5, rtol=0.15)
    with pytest.raises(ValueError, match="exactly one"):
        crlb(params, u)


def test_a_segment_never_visited_is_not_bounded():
    # u > 0 never excites the left segments: their parameters are not determined
    u = jax.random.uniform(jax.random.PRNGKey(0), (2000,), minval=0.05, maxval=2.0)
    bound = dict(zip(EX.orders.names, np.asarray(crlb(EX.params(), u, snr=25.0)), strict=True))
    assert np.isinf(bound["ML1"]) and np.isinf(bound["DL1"])
    assert np.isfinite(bound["MR1"])


def test_standard_errors_of_a_fit_match_the_bound():
    # At the truth, the estimated standard errors use the residual's sigma: with 2000
    # samples sigma is known to ~1.6%, so they match the bound to a few percent.
    params, u = EX.params(), _input(6)
    y, clean = jc.measure(jax.random.PRNGKey(7), params, u, 25.0)
    vector = params.to_vector()

    def simulate_vector(v):
        return jc.simulate(jc.CascadeParams.from_vector(v, EX.orders, check=False), u)

    errors, sigma = standard_errors(simulate_vector, vector, y)
    true_sigma = float(jnp.std(clean)) / 25.0
    assert float(sigma) == pytest.approx(true_sigma, rel=0.06)
    np.testing.assert_allclose(errors, crlb(params, u, sigma=true_sigma), rtol=0.06)


def test_sweep_summary_reports_bound_and_efficiency():
    spec = jc.Spec(example=1, n=(400,), snr=(25.0,), realisations=6, chunk_size=6)
    table = jc.run(spec, progress=False)
    summary = summarise(table).set_index("parameter")
    for name in EX.orders.names:
        bounds = table[crlb_column(name)].to_numpy()
        assert np.all(np.isfinite(bounds)) and np.all(bounds > 0)
        row = summary.loc[name]
        assert row["crlb_std"] == pytest.approx(np.sqrt(np.mean(bounds**2)))
        assert row["efficiency"] == pytest.approx(row["crlb_std"] ** 2 / row["std"] ** 2)
        # the variance's Monte-Carlo error and (smaller) the bound's
        m = int(row["used"])
        assert row["efficiency_se"] >= row["efficiency"] * np.sqrt(2 / (m - 1))
        assert row["efficiency_se"] <= row["efficiency"] * np.sqrt(2 / (m - 1)) * 1.1


def test_not_identifiable_names_each_undetermined_parameter_with_its_reason():
    ex = jc.example(1)  # DR1 = 1.0, DL1 = -0.9; slopes MR2 = -1.4, ML2 = -0.8
    names = ex.orders.names
    errors = dict.fromkeys(names, 0.01)
    u = np.linspace(-2.0, 2.0, 401)
    assert not_identifiable(ex.params(), errors, u) == {}
    # DR1 beyond the input's largest value: it and the slope change at it
    narrow = np.linspace(-1.5, 0.95, 401)
    found = not_identifiable(ex.params(), errors, narrow)
    assert set(found) == {"DR1", "MR2"} and "0 input sample(s)" in found["DR1"]
    # an infinite standard error; a slope change within two standard errors of zero
    found = not_identifiable(ex.params(), {**errors, "a2": np.inf, "ML2": 0.5}, u)
    assert set(found) == {"a2", "DL1"}
    assert "infinite" in found["a2"] and "ML2" in found["DL1"]
