"""Is one model's validation error smaller than another's? (host side, numpy/scipy)

The loop compares a candidate with the current model on the same validation record, so
the two error series are paired, and their loss difference `d(t) = e0(t)^2 - e1(t)^2` is
autocorrelated: both errors are smooth where the input is, and a free-run simulation
error carries its state from one sample to the next. A t statistic that treats `d` as
independent overstates the evidence; one that corrects only for the lag-1
autocorrelation (`N (1 - rho) / (1 + rho)` effective samples) understates it badly when
`d` is smooth but not persistent (on the measured damper rho is near 1 and that leaves
about nine samples of 1700). The Diebold-Mariano test (Diebold & Mariano 1995) estimates
the long-run variance of `d` from its autocovariances instead:

    DM = mean(d) / sqrt(S / N),   S = gamma(0) + 2 sum_{k=1}^{L} (1 - k / (L + 1)) gamma(k),

a Newey-West (1987) heteroskedasticity- and autocorrelation-consistent (HAC) variance
with Bartlett weights. The truncation lag `L` follows Andrews' (1991) rule for the
Bartlett kernel with an AR(1) plug-in: `L = floor(1.1447 (a N)^(1/3))`,
`a = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)`, `rho` the lag-1 autocorrelation of `d`
(at most `N - 1`; at least 1). Under no difference in expected loss `DM` is
asymptotically standard normal; the one-sided p-value is reported with it. With `L` a
sizeable fraction of `N` the normal reference is somewhat liberal (Kiefer & Vogelsang
2005), one reason the loop asks for `DM > 3` and a relative gain, not `p < 0.05`.

Over several records (`diebold_mariano_records`) the loss differences of each record,
scaled by that record's output variance (a squared NRMSE, so that no record weighs by
its units), are independent of the other records' and the long-run variances add:

    DM = sum_r N_r mean(d_r) / sqrt(sum_r N_r S_r),

each `S_r` with its own Andrews bandwidth. The loop uses it to weigh the evidence of
every record it has: the estimation records (in sample) and the validation record (out
of sample).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.stats

TEST_NAME = "Diebold-Mariano"
VARIANCE = "Newey-West HAC, Bartlett weights"
BANDWIDTH_RULE = "Andrews (1991) AR(1) plug-in: L = floor(1.1447 (a N)^(1/3))"


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A Diebold-Mariano comparison of two error series on one record.

    - `loss`: what was compared (`"simulation"`: free-run simulation error;
      `"prediction"`: one-step-ahead prediction error).
    - `statistic`: `DM`, positive when the second series has the smaller squared errors.
    - `bandwidth`: the truncation lag `L`; `rho`: lag-1 autocorrelation of `d`;
      `mean_difference`: `mean(d)`; `p_value`: one-sided, `P(Z > DM)`.
    """

    loss: str
    statistic: float
    bandwidth: int
    rho: float
    mean_difference: float
    p_value: float
    n: int

    def to_dict(self) -> dict:
        return {
            "test": TEST_NAME,
            "variance": VARIANCE,
            "bandwidth_rule": BANDWIDTH_RULE,
            **dataclasses.asdict(self),
        }


def andrews_bandwidth(d) -> tuple[int, float]:
    """Truncation lag `L` of the Bartlett kernel by Andrews' AR(1) plug-in rule, and the
    lag-1 autocorrelation `rho` it used."""
    d = np.asarray(d, dtype=np.float64)
    n = d.size
    dc = d - d.mean()
    denominator = float(dc @ dc)
    if n < 3 or denominator <= 0:
        return 1, 0.0
    rho = float(dc[1:] @ dc[:-1]) / denominator
    # |rho| -> 1 sends the rule to infinity; the cap N - 1 below takes over first.
    rho = min(max(rho, -0.999999), 0.999999)
    a = 4.0 * rho**2 / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    lag = int(math.floor(1.1447 * (a * n) ** (1.0 / 3.0)))
    return max(1, min(lag, n - 1)), rho


def long_run_variance(d, lags: int) -> float:
    """Newey-West long-run variance of `d` (mean removed) with `lags` Bartlett lags."""
    dc = np.asarray(d, dtype=np.float64) - np.mean(d)
    n = dc.size
    lags = min(int(lags), n - 1)
    # All autocovariances at once (FFT), the biased estimator sum / N.
    size = 1 << int(2 * n - 1).bit_length()
    spectrum = np.fft.rfft(dc, size)
    gamma = np.fft.irfft(spectrum * np.conj(spectrum), size)[: lags + 1] / n
    weights = 1.0 - np.arange(1, lags + 1) / (lags + 1.0)
    return float(gamma[0] + 2.0 * np.sum(weights * gamma[1:]))


def diebold_mariano(e0, e1, loss: str = "simulation", lags: int | None = None) -> Comparison:
    """Is `e1` smaller than `e0` in squared error? (module docstring)

    **Arguments:**

    - `e0`, `e1`: `Float[np.ndarray, " N"]`, the current and the candidate model's errors
      on the same samples.
    - `loss`: a label for the report; `lags`: the truncation lag (default: Andrews' rule).
    """
    e0 = np.asarray(e0, dtype=np.float64)
    e1 = np.asarray(e1, dtype=np.float64)
    if e0.shape != e1.shape or e0.ndim != 1:
        raise ValueError(f"diebold_mariano: errors of shapes {e0.shape} and {e1.shape}.")
    with np.errstate(over="ignore", invalid="ignore"):
        d = e0**2 - e1**2
    n = d.size
    if not np.all(np.isfinite(d)):
        # A candidate whose simulation blew up is worse; a current model that did, better.
        worse = not np.all(np.isfinite(e1))
        statistic = -math.inf if worse else math.inf
        return Comparison(loss, statistic, 0, math.nan, statistic, 1.0 if worse else 0.0, n)
    rule, rho = andrews_bandwidth(d)
    bandwidth = rule if lags is None else max(0, min(int(lags), n - 1))
    mean = float(np.mean(d))
    variance = long_run_variance(d, bandwidth) if n > 1 else 0.0
    if not variance > 0:
        statistic = 0.0 if mean == 0 else math.copysign(math.inf, mean)
    else:
        statistic = mean / math.sqrt(variance / n)
    p_value = float(scipy.stats.norm.sf(statistic))
    return Comparison(loss, float(statistic), int(bandwidth), rho, mean, p_value, n)


def diebold_mariano_records(e0s, e1s, scales=None, loss: str = "simulation") -> Comparison:
    """The Diebold-Mariano statistic pooled over independent records (module docstring):
    `e0s[r]`, `e1s[r]` the current and the candidate model's errors on record `r`, each
    record's loss difference divided by `scales[r]` (default 1). `bandwidth` is the
    largest record's lag, `rho` the sample-weighted lag-1 autocorrelation,
    `mean_difference` the pooled mean of the scaled differences."""
    e0s, e1s = list(e0s), list(e1s)
    scales = [1.0] * len(e0s) if scales is None else [float(s) for s in scales]
    if not (len(e0s) == len(e1s) == len(scales)) or not e0s:
        raise ValueError("diebold_mariano_records: as many error series and scales, at least one.")
    total, variance, n, rhos, lags = 0.0, 0.0, 0, 0.0, 0
    for e0, e1, scale in zip(e0s, e1s, scales, strict=True):
        e0 = np.asarray(e0, dtype=np.float64)
        e1 = np.asarray(e1, dtype=np.float64)
        if e0.shape != e1.shape or e0.ndim != 1:
            raise ValueError(
                f"diebold_mariano_records: errors of shapes {e0.shape} and {e1.shape}."
            )
        with np.errstate(over="ignore", invalid="ignore"):
            d = (e0**2 - e1**2) / (scale if scale > 0 else 1.0)
        if not np.all(np.isfinite(d)):
            worse = not np.all(np.isfinite(e1))
            statistic = -math.inf if worse else math.inf
            return Comparison(
                loss, statistic, 0, math.nan, statistic, 1.0 if worse else 0.0, d.size
            )
        lag, rho = andrews_bandwidth(d)
        total += float(np.sum(d))
        variance += d.size * (long_run_variance(d, lag) if d.size > 1 else 0.0)
        n += d.size
        rhos += rho * d.size
        lags = max(lags, lag)
    if not variance > 0:
        statistic = 0.0 if total == 0 else math.copysign(math.inf, total)
    else:
        statistic = total / math.sqrt(variance)
    p_value = float(scipy.stats.norm.sf(statistic))
    return Comparison(loss, float(statistic), int(lags), rhos / n, total / n, p_value, n)
