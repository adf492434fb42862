"""The Diebold-Mariano test of the model-error loop: formula against a direct loop,
calibration on paired autocorrelated errors with no difference, power where the old
lag-1 effective-sample correction had none."""

import math

import numpy as np
import pytest
import scipy.signal
import scipy.stats

from jaxcascade._measured._significance import (
    andrews_bandwidth,
    diebold_mariano,
    diebold_mariano_records,
    long_run_variance,
)


def _coloured(rng, pole, shape):
    return scipy.signal.lfilter([1.0], [1.0, -pole], rng.standard_normal(shape), axis=-1)


def test_long_run_variance_matches_a_direct_sum():
    rng = np.random.default_rng(0)
    d = _coloured(rng, 0.7, 300)
    dc = d - d.mean()
    lags = 9
    direct = dc @ dc / d.size + 2 * sum(
        (1 - k / (lags + 1)) * (dc[:-k] @ dc[k:]) / d.size for k in range(1, lags + 1)
    )
    assert long_run_variance(d, lags) == pytest.approx(direct, rel=1e-10)


def test_statistic_with_no_lags_is_the_paired_z():
    rng = np.random.default_rng(1)
    e0, e1 = rng.normal(size=500) + 0.3, rng.normal(size=500)
    d = e0**2 - e1**2
    expected = d.mean() / (d.std() / math.sqrt(d.size))  # variance with divisor N
    result = diebold_mariano(e0, e1, lags=0)
    assert result.statistic == pytest.approx(expected, rel=1e-10)
    assert result.p_value == pytest.approx(scipy.stats.norm.sf(expected), rel=1e-10)
    assert result.bandwidth == 0


def test_andrews_bandwidth_grows_with_persistence():
    rng = np.random.default_rng(2)
    assert andrews_bandwidth(rng.normal(size=2000))[0] <= 3
    lag, rho = andrews_bandwidth(_coloured(rng, 0.9, 2000))
    assert rho == pytest.approx(0.9, abs=0.05)
    # 1.1447 (a N)^(1/3), a = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)
    a = 4 * rho**2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    assert lag == math.floor(1.1447 * (a * 2000) ** (1 / 3))


@pytest.mark.parametrize("pole", [0.0, 0.9, 0.99])
def test_false_positive_rate_on_paired_coloured_errors(pole):
    # Two models that differ by independent coloured parts of equal size: no difference
    # in expected loss. The loop's threshold is DM > 3 (one-sided 0.13 % for a normal
    # statistic): 0.39 of 300 pairs expected above it, and 4 or more with probability
    # below 0.001 (binomial), so at most 3 (1 %) may be; a test liberal enough to
    # exceed it at 3 % (9 expected) fails. Measured: 1, 0 and 0 of 300 for the three
    # poles. At the 5 % level, with a bandwidth a sizeable fraction of N, the normal
    # reference is liberal (3.3, 7 and 9.3 % measured): at most 12 %.
    rng = np.random.default_rng(3)
    trials, n = 300, 2000
    common = _coloured(rng, pole, (trials, n))
    own = 0.3 * _coloured(rng, pole, (2, trials, n))
    pairs = zip(common + own[0], common + own[1], strict=True)
    statistics = np.array([diebold_mariano(e0, e1).statistic for e0, e1 in pairs])
    assert np.sum(statistics > 3.0) <= 3
    assert np.mean(statistics > scipy.stats.norm.isf(0.05)) <= 0.12


def test_smooth_systematic_improvement_is_significant():
    # The damper's situation: the current model's error exceeds the candidate's
    # everywhere, by a smooth oscillating amount. The loss difference has lag-1
    # correlation above 0.99, so `N (1 - rho) / (1 + rho)` effective samples (rho capped
    # at 0.99, the loop's former test) leave about ten and little evidence; its
    # autocovariances cancel over a period, which the HAC variance sees.
    rng = np.random.default_rng(4)
    n = 2000
    e1 = 0.03 * _coloured(rng, 0.99, n)
    e0 = e1 + 0.5 * np.sin(2 * np.pi * np.arange(n) / 200)
    d = e0**2 - e1**2
    dc = d - d.mean()
    rho = (dc[1:] @ dc[:-1]) / (dc @ dc)
    assert rho > 0.99
    n_eff = n * (1 - 0.99) / (1 + 0.99)
    old = d.mean() / (d.std() / math.sqrt(n_eff))
    new = diebold_mariano(e0, e1)
    assert old < 3.0 < new.statistic
    assert diebold_mariano(e1, e0).statistic < -3.0


def test_a_diverged_candidate_is_worse():
    e = np.ones(50)
    bad = e.copy()
    bad[10] = np.inf
    assert diebold_mariano(e, bad).statistic == -math.inf
    assert diebold_mariano(bad, e).statistic == math.inf
    with pytest.raises(ValueError, match="shapes"):
        diebold_mariano(e, e[:-1])


def test_pooled_statistic_of_one_record_is_the_record_statistic():
    # Issue 21: pooled over one record (any scale), the statistic is that record's.
    rng = np.random.default_rng(3)
    e0, e1 = rng.normal(size=500), 0.9 * rng.normal(size=500)
    one = diebold_mariano(e0, e1)
    pooled = diebold_mariano_records([e0], [e1], [4.0])
    assert math.isclose(pooled.statistic, one.statistic, rel_tol=1e-12)
    assert pooled.bandwidth == one.bandwidth and pooled.n == one.n


def test_pooled_statistic_adds_the_evidence_of_independent_records():
    # Independent records of the same improvement: the pooled statistic grows like the
    # square root of the number of records, and scaling a record by its output variance
    # makes it weigh the same in any units.
    rng = np.random.default_rng(4)
    pairs = [(rng.normal(size=400), 0.95 * rng.normal(size=400)) for _ in range(9)]
    singles = [diebold_mariano(e0, e1).statistic for e0, e1 in pairs]
    pooled = diebold_mariano_records([p[0] for p in pairs], [p[1] for p in pairs])
    assert pooled.statistic > 2 * np.mean(singles)
    scaled = diebold_mariano_records(
        [p[0] * (10.0 if i == 0 else 1.0) for i, p in enumerate(pairs)],
        [p[1] * (10.0 if i == 0 else 1.0) for i, p in enumerate(pairs)],
        [100.0] + [1.0] * 8,
    )
    assert math.isclose(scaled.statistic, pooled.statistic, rel_tol=1e-9)


def test_pooled_statistic_of_a_diverged_candidate_is_minus_infinity():
    e0 = np.ones(50)
    e1 = np.ones(50)
    e1[10] = np.inf
    assert diebold_mariano_records([e0, e0], [e0, e1]).statistic == -math.inf
