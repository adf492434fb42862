"""The validation error: `nrmse` (traceable) and `score`, its host form every report uses."""

import math

import numpy as np
import pytest

from jaxcascade._compile import compile_count
from jaxcascade._metrics import fit_percent, nrmse, score


def _reference(measured, simulated):
    # the definition, term by term in Python floats (MATLAB's `compare` NRMSE)
    m, s = (np.asarray(a, float).tolist() for a in (measured, simulated))
    mean = sum(m) / len(m)
    spread = math.sqrt(sum((v - mean) ** 2 for v in m) / len(m))
    return math.sqrt(sum((a - b) ** 2 for a, b in zip(m, s, strict=True)) / len(m)) / spread


@pytest.mark.parametrize("n", [5, 257, 3585])
def test_score_is_nrmse_on_the_host(n):
    rng = np.random.default_rng(n)
    measured = 7.0 + 3.0 * rng.normal(size=n)
    simulated = measured + 0.2 * rng.normal(size=n)
    expected = _reference(measured, simulated)
    # a sum of n squares and a standard deviation: a few n * eps of relative rounding
    tolerance = 4 * n * np.finfo(float).eps
    assert score(measured, simulated) == pytest.approx(expected, rel=tolerance)
    assert float(nrmse(measured, simulated)) == pytest.approx(expected, rel=tolerance)
    assert fit_percent(score(measured, simulated)) == pytest.approx(100 * (1 - expected))


def test_score_compiles_nothing():
    # eager jax.numpy on the host compiled a program for every record length scored
    rng = np.random.default_rng(0)
    before = compile_count()
    for n in (311, 312, 313):
        score(rng.normal(size=n), rng.normal(size=n))
    assert compile_count() == before


def test_score_is_inf_where_the_error_is_not_finite():
    flat = np.ones(8)
    assert score(flat, flat) == math.inf  # no spread to normalise by: 0 / 0
    assert score(flat, np.zeros(8)) == math.inf
    assert score(np.arange(4.0), np.full(4, 1e308)) == math.inf  # an overflowed simulation
    assert score(np.arange(4.0), np.array([0.0, np.nan, 2.0, 3.0])) == math.inf
