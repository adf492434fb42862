"""Residual diagnostics of a fitted model on validation data (host side, numpy/scipy).

Each test returns its statistic, its 95% (or `1 - alpha`) confidence bound, one p-value and
`passed = p_value >= alpha`. A test that looks at many lags or groups reduces them to one
p-value by Bonferroni, so `alpha` is the false-alarm rate of the test as a whole, not of
each lag: at 95% about one lag in twenty of a white residual lies outside `1.96/sqrt(N)`,
and that alone does not fail a test.

- Correlation tests (residual autocorrelation, input-residual cross-correlation and the
  higher-order tests of Billings & Voon 1986): a portmanteau statistic (Ljung-Box for
  the autocorrelation; `N r' R^-1 r` with `R` the autocorrelation matrix of the other
  signal for cross-correlations, Ljung 1999 sec. 16.6, since a coloured input makes
  neighbouring lags correlated) at level `alpha/2`, and the largest lag against a
  Sidak-corrected bound at level `alpha/2`. The first catches effects spread over many
  lags, the second a single strong lag.
- Conditioned means (overall, per backlash regime, per input-level bin, over time): t-tests
  of mean zero per group and an F-test of equal means, with standard errors corrected
  for residual autocorrelation (Newey-West, Bartlett weights), so that a coloured
  residual fails the whiteness tests rather than the mean tests. Over time, the drift
  test is the slope of a straight-line fit, with a Newey-West standard error.
- Spectrum: Welch PSD for display; the flatness test is Bartlett's cumulative periodogram
  test (Kolmogorov-Smirnov against a straight line, exact for Gaussian white noise).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import scipy.linalg
import scipy.signal
import scipy.stats

REGIME_NAMES = {0: "holding", 1: "moving left (g1)", 2: "moving right (g2)"}
# Eigenvalues of the lag-covariance matrix below this fraction of the largest are treated
# as zero: a strongly coloured input makes that matrix nearly singular.
_RCOND = 1e-3


def _json(value):
    if isinstance(value, np.ndarray):
        return [_json(v) for v in value.tolist()]
    if isinstance(value, list | tuple):
        return [_json(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _json(v) for k, v in value.items()}
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    return value


class _Serialisable:
    def to_dict(self, arrays: bool = True) -> dict[str, Any]:
        """JSON-serialisable fields (NaN as `None`); `arrays=False` keeps scalars only."""
        out = {}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, _Serialisable):
                out[field.name] = value.to_dict(arrays)
            elif arrays or not isinstance(value, np.ndarray | tuple | list):
                out[field.name] = _json(value)
        return out


@dataclasses.dataclass(frozen=True, eq=False)
class CorrelationTest(_Serialisable):
    """Normalised correlation `values[i]` at `lags[i]`, with its bounds and decision.

    `bound` is the pointwise 95% bound `1.96/sqrt(N)`; `simultaneous_bound` the bound on
    the largest lag at level `alpha/2` over all tested lags; `n_outside` counts tested lags
    outside `bound`. `statistic` is the portmanteau statistic with `dof` degrees of freedom.
    """

    name: str
    label: str
    lags: np.ndarray
    values: np.ndarray
    bound: float
    simultaneous_bound: float
    n_outside: int
    statistic: float
    dof: int
    p_portmanteau: float
    p_max: float
    p_value: float
    passed: bool


@dataclasses.dataclass(frozen=True, eq=False)
class GroupTest(_Serialisable):
    """Residual statistics per group (regime, input-level bin or time block).

    Per group: `labels`, `positions` (for plotting: regime code, mean input in the bin,
    centre sample of the block), `counts`, `means`, `stds`, `standard_errors`
    (autocorrelation-corrected), `t`, `p` (t-test of mean zero). `p_zero`: Bonferroni over
    groups of the per-group t-tests; `p_equal`: F-test that all group means are equal.
    """

    name: str
    labels: tuple[str, ...]
    positions: np.ndarray
    counts: np.ndarray
    means: np.ndarray
    stds: np.ndarray
    standard_errors: np.ndarray
    t: np.ndarray
    p: np.ndarray
    p_zero: float
    p_equal: float
    p_value: float
    passed: bool


@dataclasses.dataclass(frozen=True, eq=False)
class MeanTest(_Serialisable):
    """t-test that the residual mean is zero (autocorrelation-corrected standard error)."""

    name: str
    mean: float
    std: float
    standard_error: float
    t: float
    p_value: float
    passed: bool


@dataclasses.dataclass(frozen=True, eq=False)
class DriftTest(_Serialisable):
    """Residual over time: straight-line fit `e ~ intercept + slope * t/N` and block means.

    `slope` is the change over the whole record, `slope_se` its Newey-West standard error,
    `p_slope` its two-sided p-value; `blocks` the means in consecutive blocks (a
    `GroupTest`). `p_value = min(1, 2 min(p_slope, blocks.p_equal))`.
    """

    name: str
    slope: float
    slope_se: float
    intercept: float
    p_slope: float
    blocks: GroupTest
    p_value: float
    passed: bool


@dataclasses.dataclass(frozen=True, eq=False)
class SpectrumTest(_Serialisable):
    """Welch PSD of the residual and Bartlett's cumulative periodogram flatness test.

    `frequency`, `psd`: Welch estimate (`psd_level`: its mean, the flat level). `flatness`:
    geometric over arithmetic mean of the Welch PSD (1 for a flat spectrum).
    `cumulative_frequency`, `cumulative`: normalised cumulative periodogram, a straight
    line from 0 to 1 for white noise; `ks_statistic` its largest distance from that line,
    `ks_bound` the `1 - alpha` bound.
    """

    name: str
    frequency: np.ndarray
    psd: np.ndarray
    psd_level: float
    flatness: float
    cumulative_frequency: np.ndarray
    cumulative: np.ndarray
    ks_statistic: float
    ks_bound: float
    p_value: float
    passed: bool


@dataclasses.dataclass(frozen=True, eq=False)
class HysteresisTest(_Serialisable):
    """Does the residual depend on the input's history beyond its present value?

    - `direction`: residual means (cubic in the input projected out, as below) when the
      input increases and when it decreases (a
      `GroupTest`; a sample with zero increment keeps the last direction).
    - Stop-operator test: for each threshold `thresholds[k]` (a grid of fractions of the
      input span), the partial correlation `values[k]` of the residual with the stop
      operator's output, both with a cubic polynomial of the input projected out (so a
      static error is not read as hysteresis), and its t statistic with a Newey-West
      standard error; `bounds[k]` is the simultaneous `1 - alpha/2` bound on the
      correlation (Bonferroni over thresholds), `p_stop` the smallest p-value times the
      number of thresholds.
    - `p_value = min(1, 2 min(p_stop, direction.p_value))`.
    """

    name: str
    direction: GroupTest
    thresholds: np.ndarray
    values: np.ndarray
    t: np.ndarray
    bounds: np.ndarray
    p_stop: float
    p_value: float
    passed: bool


def stop_outputs(u, thresholds) -> np.ndarray:
    """Stop operators of `u` (`_effects._operators.stop_operators` in NumPy): `(N, K)`."""
    u = np.asarray(u, dtype=np.float64)
    thresholds = np.asarray(thresholds, dtype=np.float64)
    out = np.empty((u.size, thresholds.size))
    state = np.zeros(thresholds.size)
    du = np.diff(u, prepend=u[:1])
    for t in range(u.size):
        state = np.minimum(np.maximum(state + du[t], -thresholds), thresholds)
        out[t] = state
    return out


def hysteresis_test(
    u, e, n_thresholds: int = 12, alpha: float = 0.05, hac_lags: int | None = None
) -> HysteresisTest:
    """The residual against the direction of motion and against stop operators of the
    input (`HysteresisTest`)."""
    u = np.asarray(u, dtype=np.float64)
    e = np.asarray(e, dtype=np.float64)
    n = e.size
    lags = hac_lags or _hac_lags(n)
    du = np.diff(u, prepend=u[:1])
    moving = np.flatnonzero(du != 0)
    last = np.maximum.accumulate(np.where(du != 0, np.arange(n), -1))
    rising = np.where(
        last >= 0, du[np.maximum(last, 0)] > 0, du[moving[0]] > 0 if moving.size else True
    )
    span = float(np.quantile(u, 0.995) - np.quantile(u, 0.005)) or 1.0
    thresholds = np.geomspace(0.01 * span, 0.5 * span, n_thresholds)
    z = stop_outputs(u, thresholds)
    scale = np.std(u) or 1.0
    basis = np.stack([np.ones(n)] + [(u / scale) ** k for k in (1, 2, 3)], 1)
    q, _ = np.linalg.qr(basis)
    e_part = e - q @ (q.T @ e)
    z_part = z - q @ (q.T @ z)
    direction = group_test(
        "direction",
        e_part,
        np.where(rising, 0, 1),
        ("increasing", "decreasing"),
        [1.0, -1.0],
        alpha,
        lags,
    )
    values = np.zeros(n_thresholds)
    t = np.zeros(n_thresholds)
    scales = np.full(n_thresholds, np.inf)  # standard error of each correlation
    for k in range(n_thresholds):
        zk = z_part[:, k]
        denominator = math.sqrt(float(zk @ zk) * float(e_part @ e_part))
        product = zk * e_part
        if denominator <= 0 or not np.any(product):
            continue
        values[k] = float(np.sum(product)) / denominator
        # Newey-West variance of sum z e: the residual and the operator are both smooth.
        variance = _long_run_factor(product - product.mean(), lags) * float(
            np.sum((product - product.mean()) ** 2)
        )
        scales[k] = math.sqrt(variance) / denominator
        t[k] = values[k] / scales[k]
    p_each = 2.0 * scipy.stats.norm.sf(np.abs(t))
    p_stop = min(1.0, n_thresholds * float(np.min(p_each)))
    critical = scipy.stats.norm.isf(alpha / (4.0 * n_thresholds))
    bounds = critical * scales
    p_value = min(1.0, 2.0 * min(p_stop, direction.p_value))
    return HysteresisTest(
        name="hysteresis",
        direction=direction,
        thresholds=thresholds,
        values=values,
        t=t,
        bounds=bounds,
        p_stop=float(p_stop),
        p_value=float(p_value),
        passed=bool(p_value >= alpha),
    )


_WHITENESS = ("autocorrelation", "spectrum")
_INDEPENDENCE = ("cross_correlation", "e_eu", "u2_e", "u2_e2")
_CONDITIONAL = ("mean", "regime", "branch", "level", "time")
_HYSTERESIS = ("hysteresis",)


@dataclasses.dataclass(frozen=True, eq=False)
class ResidualTests(_Serialisable):
    """All residual tests of one validation record.

    Tests: `autocorrelation` (phi_ee), `cross_correlation` (phi_ue), `e_eu` (phi_e(eu)),
    `u2_e` (phi_u2'e), `u2_e2` (phi_u2'e2), `spectrum`, `mean`, `regime` (`None` without a
    regime array), `branch` (`None` without the regime and the model's backlash output),
    `level`, `time`. Each has `passed` at level `alpha`. The summaries
    `whiteness_ok` (autocorrelation, spectrum), `independence_ok` (the four input
    correlation tests) and `conditional_ok` (mean, regime, level, time) are Bonferroni
    over their group, so each has a false-alarm rate of at most `alpha`; so is `ok`, over
    all tests. `failed` lists the tests that fail on their own at level `alpha`.
    """

    n: int
    alpha: float
    max_lag: int
    autocorrelation: CorrelationTest
    cross_correlation: CorrelationTest
    e_eu: CorrelationTest
    u2_e: CorrelationTest
    u2_e2: CorrelationTest
    spectrum: SpectrumTest
    mean: MeanTest
    regime: GroupTest | None
    level: GroupTest
    time: DriftTest
    hysteresis: HysteresisTest | None = None
    branch: GroupTest | None = None

    def tests(self) -> dict[str, Any]:
        """Every test present, by name."""
        names = _WHITENESS + _INDEPENDENCE + _CONDITIONAL + _HYSTERESIS
        return {name: getattr(self, name) for name in names if getattr(self, name) is not None}

    def _group_ok(self, names) -> bool:
        tests = [getattr(self, name) for name in names if getattr(self, name) is not None]
        return all(test.p_value >= self.alpha / len(tests) for test in tests)

    @property
    def whiteness_ok(self) -> bool:
        return self._group_ok(_WHITENESS)

    @property
    def independence_ok(self) -> bool:
        return self._group_ok(_INDEPENDENCE)

    @property
    def conditional_ok(self) -> bool:
        return self._group_ok(_CONDITIONAL)

    @property
    def ok(self) -> bool:
        """Every test passes at family-wise level `alpha` (Bonferroni over all tests)."""
        return self._group_ok(tuple(self.tests()))

    @property
    def failed(self) -> tuple[str, ...]:
        """Names of the tests that fail at level `alpha`."""
        return tuple(name for name, test in self.tests().items() if not test.passed)

    def to_dict(self, arrays: bool = True) -> dict[str, Any]:
        out = super().to_dict(arrays)
        out.update(
            whiteness_ok=self.whiteness_ok,
            independence_ok=self.independence_ok,
            conditional_ok=self.conditional_ok,
            ok=self.ok,
            failed=list(self.failed),
        )
        return out


# ---- correlation tests ----------------------------------------------------------------------


def correlation(a, b, lags) -> np.ndarray:
    """Normalised cross-correlation `r_ab(k) = sum_t a'(t) b'(t+k) / sqrt(sum a'^2 sum b'^2)`.

    `a'`, `b'` are mean-removed; sums run over the overlap (the biased estimator, whose
    lag matrices are positive semi-definite). Positive `k`: `a` leads `b`.
    """
    a = np.asarray(a, dtype=np.float64) - np.mean(a)
    b = np.asarray(b, dtype=np.float64) - np.mean(b)
    n = a.size
    scale = math.sqrt(float(a @ a) * float(b @ b))
    out = np.empty(len(lags))
    for i, k in enumerate(lags):
        k = int(k)
        out[i] = (a[: n - k] @ b[k:] if k >= 0 else a[-k:] @ b[: n + k]) if abs(k) < n else 0.0
    return out / scale if scale > 0 else np.full(len(lags), np.nan)


def _max_test(values: np.ndarray, n: int, alpha: float) -> tuple[float, float]:
    m = values.size
    p_lag = 2.0 * scipy.stats.norm.sf(np.max(np.abs(values)) * math.sqrt(n))
    p_max = -math.expm1(m * math.log1p(-min(p_lag, 1.0 - 1e-300)))  # Sidak: 1 - (1 - p)^m
    level = alpha / 2.0
    per_lag = -math.expm1(math.log1p(-level) / m)  # 1 - (1 - level)^(1/m)
    bound = scipy.stats.norm.isf(per_lag / 2.0) / math.sqrt(n)
    return float(p_max), float(bound)


def _finish_correlation(name, label, lags, values, tested, statistic, dof, p_port, n, alpha):
    p_max, simultaneous = _max_test(values[tested], n, alpha)
    p_value = min(1.0, 2.0 * min(p_port, p_max))
    bound = 1.96 / math.sqrt(n)
    return CorrelationTest(
        name=name,
        label=label,
        lags=np.asarray(lags),
        values=values,
        bound=bound,
        simultaneous_bound=simultaneous,
        n_outside=int(np.sum(np.abs(values[tested]) > bound)),
        statistic=float(statistic),
        dof=int(dof),
        p_portmanteau=float(p_port),
        p_max=p_max,
        p_value=float(p_value),
        passed=bool(p_value >= alpha),
    )


def autocorrelation_test(e, max_lag: int = 20, alpha: float = 0.05) -> CorrelationTest:
    """Residual autocorrelation phi_ee(k), k = 0..L; whiteness by Ljung-Box over 1..L."""
    e = np.asarray(e, dtype=np.float64)
    n = e.size
    lags = np.arange(max_lag + 1)
    values = correlation(e, e, lags)
    k = lags[1:]
    q = n * (n + 2) * float(np.sum(values[1:] ** 2 / (n - k)))
    p_port = float(scipy.stats.chi2.sf(q, max_lag))
    tested = lags >= 1
    return _finish_correlation(
        "autocorrelation", "phi_ee(k)", lags, values, tested, q, max_lag, p_port, n, alpha
    )


def _cross_test(name, label, a, b, lags, alpha, shown_lags=None) -> CorrelationTest:
    # Under H0, b is white and independent of a, so Cov(r(k), r(j)) = rho_a(k - j) / N.
    n = a.size
    values = correlation(a, b, lags)
    span = int(np.max(lags) - np.min(lags))
    rho_a = correlation(a, a, np.arange(span + 1))
    index = np.asarray(lags) - np.min(lags)
    cov = scipy.linalg.toeplitz(rho_a)[np.ix_(index, index)]
    eigval, eigvec = scipy.linalg.eigh(cov)
    keep = eigval > _RCOND * eigval[-1]
    proj = eigvec[:, keep].T @ values
    q = n * float(np.sum(proj**2 / eigval[keep]))
    dof = int(keep.sum())
    p_port = float(scipy.stats.chi2.sf(q, dof))
    tested = np.ones(len(lags), dtype=bool)
    shown = np.asarray(lags if shown_lags is None else shown_lags)
    return _finish_correlation(name, label, shown, values, tested, q, dof, p_port, n, alpha)


def cross_correlation_test(u, e, max_lag: int = 20, alpha: float = 0.05) -> CorrelationTest:
    """Input-residual cross-correlation phi_ue(k) = corr(u(t), e(t+k)), k = -L..L."""
    u, e = np.asarray(u, dtype=np.float64), np.asarray(e, dtype=np.float64)
    lags = np.arange(-max_lag, max_lag + 1)
    return _cross_test("cross_correlation", "phi_ue(k)", u, e, lags, alpha)


def higher_order_tests(
    u, e, max_lag: int = 20, alpha: float = 0.05
) -> tuple[CorrelationTest, CorrelationTest, CorrelationTest]:
    """The higher-order correlation tests of Billings & Voon (1986) for nonlinear models.

    - phi_e(eu)(k) = corr(e(t), e(t-1-k) u(t-1-k)), k = 0..L-1;
    - phi_u2'e(k) = corr(u^2'(t), e(t+k)), k = -L..L, with `u^2' = u^2 - mean(u^2)`;
    - phi_u2'e2(k) = corr(u^2'(t), e^2(t+k)), k = -L..L.

    The residual is mean-removed first (an offset is the mean test's business).
    """
    u = np.asarray(u, dtype=np.float64)
    e = np.asarray(e, dtype=np.float64)
    e = e - e.mean()
    z = e * u
    u2 = u**2 - np.mean(u**2)
    e_eu = _cross_test(
        "e_eu",
        "phi_e(eu)(k)",
        z,
        e,
        np.arange(1, max_lag + 1),
        alpha,
        shown_lags=np.arange(max_lag),
    )
    lags = np.arange(-max_lag, max_lag + 1)
    u2_e = _cross_test("u2_e", "phi_u2'e(k)", u2, e, lags, alpha)
    u2_e2 = _cross_test("u2_e2", "phi_u2'e2(k)", u2, e**2, lags, alpha)
    return e_eu, u2_e, u2_e2


# ---- conditioned means ----------------------------------------------------------------------


def _hac_lags(n: int) -> int:
    return max(1, int(4 * (n / 100.0) ** (2.0 / 9.0)))  # Newey-West rule of thumb


def _long_run_factor(d: np.ndarray, lags: int) -> float:
    """Long-run over short-run variance of a zero-mean series (Bartlett weights)."""
    gamma0 = float(d @ d)
    if gamma0 <= 0:
        return 1.0
    total = gamma0
    for k in range(1, min(lags, d.size - 1) + 1):
        total += 2.0 * (1.0 - k / (lags + 1.0)) * float(d[:-k] @ d[k:])
    return max(total / gamma0, 1e-3)


def group_test(
    name: str, e, groups, labels, positions, alpha: float = 0.05, hac_lags: int | None = None
) -> GroupTest:
    """Residual mean per group: t-test of zero per group and an F-test of equal means.

    - `groups`: `Int[np.ndarray, " N"]` with values `0..G-1`; `labels`, `positions`:
      length `G`. Groups with fewer than two samples get NaN and are not tested.
    """
    e = np.asarray(e, dtype=np.float64)
    groups = np.asarray(groups)
    count = len(labels)
    counts = np.bincount(groups, minlength=count)[:count]
    sums = np.bincount(groups, weights=e, minlength=count)[:count]
    means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    d = e - np.nan_to_num(means)[groups]
    kappa = _long_run_factor(d, hac_lags or _hac_lags(e.size))
    sq = np.bincount(groups, weights=d**2, minlength=count)[:count]
    valid = counts >= 2
    stds = np.where(valid, np.sqrt(sq / np.maximum(counts - 1, 1)), np.nan)
    se = np.where(valid, stds * np.sqrt(kappa / np.maximum(counts, 1)), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(valid & (se > 0), means / se, np.nan)
    p = np.where(valid, 2.0 * scipy.stats.t.sf(np.abs(t), np.maximum(counts - 1, 1)), np.nan)
    p = np.where(valid & (se == 0) & (means != 0), 0.0, p)
    tested = int(valid.sum())
    p_zero = min(1.0, tested * float(np.nanmin(p))) if tested else 1.0
    if tested >= 2:
        grand = float(np.sum(means[valid] * counts[valid]) / counts[valid].sum())
        n_valid = int(counts[valid].sum())
        between = float(np.sum(counts[valid] * (means[valid] - grand) ** 2)) / (tested - 1)
        within = float(np.sum(sq[valid])) / max(n_valid - tested, 1)
        if within > 0:
            f = between / (kappa * within)
            p_equal = float(scipy.stats.f.sf(f, tested - 1, max(n_valid - tested, 1)))
        else:
            p_equal = 0.0 if between > 0 else 1.0
    else:
        p_equal = 1.0
    p_value = min(1.0, 2.0 * min(p_zero, p_equal))
    return GroupTest(
        name=name,
        labels=tuple(labels),
        positions=np.asarray(positions, dtype=np.float64),
        counts=counts,
        means=means,
        stds=stds,
        standard_errors=se,
        t=t,
        p=p,
        p_zero=float(p_zero),
        p_equal=float(p_equal),
        p_value=float(p_value),
        passed=bool(p_value >= alpha),
    )


def mean_test(e, alpha: float = 0.05, hac_lags: int | None = None) -> MeanTest:
    """t-test that the residual mean is zero."""
    g = group_test("mean", e, np.zeros(np.size(e), dtype=int), ("all",), [0.0], alpha, hac_lags)
    p_value = float(g.p[0])
    return MeanTest(
        name="mean",
        mean=float(g.means[0]),
        std=float(g.stds[0]),
        standard_error=float(g.standard_errors[0]),
        t=float(g.t[0]),
        p_value=p_value,
        passed=bool(p_value >= alpha),
    )


def regime_test(e, regime, alpha: float = 0.05, hac_lags: int | None = None) -> GroupTest:
    """Residual per backlash regime: 0 holding, 1 moving left (g1), 2 moving right (g2)."""
    regime = np.asarray(regime)
    labels = tuple(REGIME_NAMES.values())
    return group_test("regime", e, regime.astype(int), labels, [0, 1, 2], alpha, hac_lags)


BRANCH_BINS = 5


def branch_test(
    e, regime, level, n_bins: int = BRANCH_BINS, alpha: float = 0.05, hac_lags=None
) -> GroupTest | None:
    """Residual per level of the model's output along each moving branch of the backlash:
    the samples pushed down onto the left branch (regime 1) and pushed up onto the right
    one (regime 2), each branch's in `n_bins` bins between quantiles of the model's
    backlash output `level` there; held samples are not tested (None where neither
    branch holds `2 n_bins` samples). A straight line through a curved branch leaves a
    residual mean that changes with the level along it (the signature of the general
    backlash, `_effects._curved`)."""
    e, level, regime = (np.asarray(a) for a in (e, level, regime))
    if level.shape != e.shape:
        raise ValueError(f"Level has shape {level.shape} but the residual {e.shape}; align them.")
    groups = np.full(e.shape, -1)
    labels, positions = [], []
    for code, side in ((1, "left"), (2, "right")):
        on = np.flatnonzero(regime == code)
        if on.size < 2 * n_bins:
            continue  # a branch the record hardly moves along
        edges = np.unique(np.quantile(level[on], np.linspace(0.0, 1.0, n_bins + 1)))
        count = max(edges.size - 1, 1)
        bins = np.clip(np.searchsorted(edges, level[on], side="right") - 1, 0, count - 1)
        groups[on] = len(labels) + bins
        for i in range(count):
            hi = edges[min(i + 1, edges.size - 1)]
            labels.append(f"{side} [{edges[i]:.3g}, {hi:.3g}]")
            inside = level[on][bins == i]
            positions.append(float(np.mean(inside)) if inside.size else float(edges[i]))
    moving = groups >= 0
    if not labels:
        return None
    return group_test(
        "branch", e[moving], groups[moving], tuple(labels), positions, alpha, hac_lags
    )


def level_test(
    u, e, n_bins: int = 10, alpha: float = 0.05, hac_lags: int | None = None
) -> GroupTest:
    """Residual per input level, in bins between quantiles of `u`."""
    u = np.asarray(u, dtype=np.float64)
    edges = np.unique(np.quantile(u, np.linspace(0.0, 1.0, n_bins + 1)))
    bins = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, max(edges.size - 2, 0))
    count = max(edges.size - 1, 1)
    labels = tuple(f"[{edges[i]:.3g}, {edges[i + 1]:.3g}]" for i in range(count))
    if edges.size < 2:
        labels = (f"{edges[0]:.3g}",)
    counts = np.bincount(bins, minlength=count)
    positions = np.bincount(bins, weights=u, minlength=count) / np.maximum(counts, 1)
    return group_test("level", e, bins, labels, positions, alpha, hac_lags)


def drift_test(
    e, n_blocks: int = 10, alpha: float = 0.05, hac_lags: int | None = None
) -> DriftTest:
    """Residual over time: block means and the slope of a straight-line fit."""
    e = np.asarray(e, dtype=np.float64)
    n = e.size
    lags = hac_lags or _hac_lags(n)
    blocks_of = np.minimum((np.arange(n) * n_blocks) // n, n_blocks - 1)
    starts = np.searchsorted(blocks_of, np.arange(n_blocks))
    ends = np.append(starts[1:], n)
    labels = tuple(f"{s}-{t - 1}" for s, t in zip(starts, ends, strict=True))
    blocks = group_test("time", e, blocks_of, labels, (starts + ends - 1) / 2.0, alpha, lags)
    x = np.arange(n) / n
    x = x - x.mean()
    sxx = float(x @ x)
    slope = float(x @ (e - e.mean())) / sxx
    intercept = float(e.mean() - slope * (np.arange(n) / n).mean())
    w = x * (e - e.mean() - slope * x)
    # Newey-West variance of sum_t x_t eps_t
    meat = _long_run_factor(w, lags) * float(w @ w)
    slope_se = math.sqrt(meat) / sxx
    p_slope = float(2.0 * scipy.stats.t.sf(abs(slope) / slope_se, n - 2)) if slope_se > 0 else 0.0
    p_value = min(1.0, 2.0 * min(p_slope, blocks.p_equal))
    return DriftTest(
        name="time",
        slope=slope,
        slope_se=float(slope_se),
        intercept=intercept,
        p_slope=p_slope,
        blocks=blocks,
        p_value=float(p_value),
        passed=bool(p_value >= alpha),
    )


# ---- spectrum -------------------------------------------------------------------------------


def spectrum_test(
    e, sample_period: float = 1.0, alpha: float = 0.05, nperseg: int | None = None
) -> SpectrumTest:
    """Welch PSD (for display) and Bartlett's cumulative periodogram test of flatness.

    For Gaussian white noise the periodogram ordinates at the Fourier frequencies
    `j/N, j = 1..m` (`m = (N-1)//2`) are iid exponential, so the normalised cumulative sums
    at `j = 1..m-1` are uniform order statistics: a one-sample Kolmogorov-Smirnov test.
    """
    e = np.asarray(e, dtype=np.float64)
    n = e.size
    fs = 1.0 / float(sample_period)
    nperseg = int(nperseg or min(n, 256))
    frequency, psd = scipy.signal.welch(e, fs=fs, nperseg=nperseg, detrend="constant")
    positive = psd[1:]
    level = float(np.mean(positive))
    flatness = float(np.exp(np.mean(np.log(positive))) / level) if np.all(positive > 0) else 0.0
    m = (n - 1) // 2
    periodogram = np.abs(np.fft.rfft(e - e.mean()))[1 : m + 1] ** 2
    total = float(periodogram.sum())
    cumulative = np.cumsum(periodogram) / total if total > 0 else np.linspace(1 / m, 1, m)
    ks = scipy.stats.kstest(cumulative[:-1], "uniform")
    bound = float(scipy.stats.kstwo.isf(alpha, m - 1))
    return SpectrumTest(
        name="spectrum",
        frequency=frequency,
        psd=psd,
        psd_level=level,
        flatness=flatness,
        cumulative_frequency=np.arange(1, m + 1) * fs / n,
        cumulative=cumulative,
        ks_statistic=float(ks.statistic),
        ks_bound=bound,
        p_value=float(ks.pvalue),
        passed=bool(ks.pvalue >= alpha),
    )


# ---- everything -----------------------------------------------------------------------------


def regime_from_switches(g1, g2) -> np.ndarray:
    """Backlash regime code from the switching indicators: 1 if g1, 2 if g2, else 0."""
    g1, g2 = np.asarray(g1) > 0.5, np.asarray(g2) > 0.5
    return np.where(g1, 1, np.where(g2, 2, 0)).astype(np.int64)


def residual_tests(
    u,
    e,
    regime=None,
    *,
    max_lag: int = 20,
    alpha: float = 0.05,
    n_bins: int = 10,
    n_blocks: int = 10,
    sample_period: float = 1.0,
    hac_lags: int | None = None,
    hysteresis: bool = True,
    level=None,
) -> ResidualTests:
    """Every residual test of a fitted model on one validation record.

    Arguments:
    - `u`: `Float[np.ndarray, " N"]`, the input; `e`: `Float[np.ndarray, " N"]`, the
      residual (measured minus simulated output).
    - `regime`: optional `Int[np.ndarray, " N"]`, 0 holding, 1 moving left (g1), 2 moving
      right (g2), e.g. `regime_from_switches(g1, g2)` of the simulated backlash.
    - `max_lag`: lags of the correlation tests; `alpha`: level of each test;
      `n_bins`: input-level bins; `n_blocks`: time blocks; `sample_period`: for the
      spectrum's frequency axis; `hac_lags`: Newey-West lags (default `4 (N/100)^(2/9)`);
      `hysteresis`: also run `hysteresis_test`; `level`: optional
      `Float[np.ndarray, " N"]`, the model's backlash output, for `branch_test` (with
      `regime`).
    """
    u = np.asarray(u, dtype=np.float64)
    e = np.asarray(e, dtype=np.float64)
    if u.ndim != 1 or e.ndim != 1:
        raise ValueError(f"Input and residual must be 1-D, got shapes {u.shape} and {e.shape}.")
    if u.size != e.size:
        raise ValueError(f"Input has {u.size} samples but the residual {e.size}; align them.")
    n = e.size
    if isinstance(max_lag, bool) or not isinstance(max_lag, int | np.integer) or max_lag < 1:
        raise ValueError(f"max_lag must be an integer >= 1, got {max_lag!r}.")
    needed = max(4 * max_lag, 2 * n_bins, 2 * n_blocks, 16)
    if n < needed:
        raise ValueError(
            f"Residual tests need at least {needed} samples for max_lag={max_lag}, "
            f"n_bins={n_bins}, n_blocks={n_blocks}; got {n}."
        )
    for name, values in (("input", u), ("residual", e)):
        if not np.all(np.isfinite(values)):
            raise ValueError(
                f"The {name} has {int(np.sum(~np.isfinite(values)))} NaN or infinite values; "
                "a diverged simulation cannot be diagnosed."
            )
        if np.all(values == values[0]):
            raise ValueError(f"The {name} is constant; its correlations are undefined.")
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must lie between 0 and 1, got {alpha}.")
    if regime is not None:
        regime = np.asarray(regime)
        if regime.shape != e.shape:
            raise ValueError(
                f"Regime has shape {regime.shape} but the residual {e.shape}; align them."
            )
        if not np.all(np.isin(regime, (0, 1, 2))):
            raise ValueError("Regime values must be 0 (holding), 1 (g1) or 2 (g2).")
    e_eu, u2_e, u2_e2 = higher_order_tests(u, e, max_lag, alpha)
    return ResidualTests(
        n=n,
        alpha=alpha,
        max_lag=max_lag,
        autocorrelation=autocorrelation_test(e, max_lag, alpha),
        cross_correlation=cross_correlation_test(u, e, max_lag, alpha),
        e_eu=e_eu,
        u2_e=u2_e,
        u2_e2=u2_e2,
        spectrum=spectrum_test(e, sample_period, alpha),
        mean=mean_test(e, alpha, hac_lags),
        regime=None if regime is None else regime_test(e, regime, alpha, hac_lags),
        level=level_test(u, e, n_bins, alpha, hac_lags),
        time=drift_test(e, n_blocks, alpha, hac_lags),
        hysteresis=hysteresis_test(u, e, alpha=alpha, hac_lags=hac_lags) if hysteresis else None,
        branch=(
            None
            if regime is None or level is None
            else branch_test(e, regime, level, alpha=alpha, hac_lags=hac_lags)
        ),
    )
