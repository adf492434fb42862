"""Isolated outliers of a measured output: spikes no model follows, found in the residual.

A spike of the measured output (a dropped bit, a glitch of the sensor's line) leaves the
simulated output alone, so it shows in the residual `r = y - y_model` as one sample far
from its neighbours. The model error around it is smooth (the simulation of a wrong
model drifts slowly), so each sample is compared with the mean of its two neighbours,

    d(t) = r(t) - (r(t-1) + r(t+1)) / 2,

which removes a smooth error and leaves a spike of size `s` as `d(t) = s` (its neighbours
get `-s/2`). The scale is robust, not the standard deviation (which the spikes inflate):
`sigma = 1.4826 * median(|d - median(d)|)`. A sample is an outlier when `|d(t)|` exceeds
`z * sigma`, `z` the two-sided normal quantile of `ALPHA / N` (Bonferroni over the `N`
samples: a record of white Gaussian noise has an outlier named with probability about
`ALPHA`) but at least `Z_MIN`; and it is large against the output, at least `MIN_SIZE`
of the output's standard deviation. Measured noise is heavier-tailed than Gaussian:
CED's velocity, counted from an encoder, departs from its neighbours in the final
model's residual by up to 12.1 robust scales (the Gaussian quantile at N = 100 is 3.9),
but by at most 0.27 of its output's standard deviation; a spike that pulls a fit or
dominates a score lies far beyond both. And it stands alone: the largest `|d|` of its
run of samples above the threshold, at least `PEAK_RATIO` times the others in that run
(a spike's neighbours sit at half its size), in a run of at most `MAX_RUN` samples (a
longer excursion is a burst or a step, a mechanism, not an outlier).

`find_outliers` returns them for one residual; `without` scores a record with them left
out; `impute` puts the model's output in their place, so that a refit on the record sees
no spike (an output-error fit leaves the sample out; the key-term regression, which uses
the measured output as a regressor, sees no spike either).
"""

from __future__ import annotations

import dataclasses
from statistics import NormalDist

import numpy as np

# the probability that a clean record of white Gaussian noise has an outlier named
ALPHA = 0.01
# the threshold in robust scales is at least this (heavy-tailed measured noise)
Z_MIN = 8.0
# and an outlier is at least this share of the output's standard deviation
MIN_SIZE = 0.5
# a spike's |d| against the others of its run above the threshold (its neighbours: half)
PEAK_RATIO = 1.5
# the longest run of samples above the threshold that still holds an isolated outlier
MAX_RUN = 3
# the consistency factor of the median absolute deviation for a normal sample
MAD_NORMAL = 1.4826


@dataclasses.dataclass(frozen=True)
class Outliers:
    """The isolated outliers of one residual: their `samples` (indices), `sizes` (the
    spike `d(t)`, in the residual's units), the robust `scale` of `d` and the
    `threshold` (`z * scale`)."""

    samples: tuple[int, ...]
    sizes: tuple[float, ...]
    scale: float
    threshold: float

    def __len__(self) -> int:
        return len(self.samples)

    def to_dict(self, unit_scale: float = 1.0) -> dict:
        """JSON-ready, the sizes, scale and threshold times `unit_scale` (a record's
        `Scaling.y_scale`: model units to the record's)."""
        return {
            "samples": list(self.samples),
            "sizes": [s * unit_scale for s in self.sizes],
            "scale": self.scale * unit_scale,
            "threshold": self.threshold * unit_scale,
        }


def threshold_z(n: int, alpha: float = ALPHA) -> float:
    """`z` of the module docstring: the two-sided normal quantile of `alpha / n`, at
    least `Z_MIN`."""
    return max(Z_MIN, NormalDist().inv_cdf(1.0 - alpha / (2.0 * max(int(n), 1))))


def find_outliers(residual, output=None, alpha: float = ALPHA) -> Outliers:
    """The isolated outliers of one residual (module docstring); `output`: the measured
    output, whose standard deviation bounds an outlier's size from below (`MIN_SIZE`;
    none without it)."""
    r = np.asarray(residual, float)
    if r.size < 5:
        return Outliers((), (), 0.0, 0.0)
    d = np.zeros_like(r)
    d[1:-1] = r[1:-1] - 0.5 * (r[:-2] + r[2:])
    inner = d[1:-1]
    scale = MAD_NORMAL * float(np.median(np.abs(inner - np.median(inner))))
    if not scale > 0:
        return Outliers((), (), 0.0, 0.0)
    limit = threshold_z(inner.size, alpha) * scale
    if output is not None:
        limit = max(limit, MIN_SIZE * float(np.std(np.asarray(output, float))))
    above = np.abs(d) > limit
    above[[0, -1]] = False
    samples, sizes = [], []
    t = 0
    while t < r.size:
        if not above[t]:
            t += 1
            continue
        stop = t
        while stop < r.size and above[stop]:
            stop += 1
        run = np.abs(d[t:stop])
        peak = t + int(np.argmax(run))
        others = np.delete(run, peak - t)
        isolated = stop - t <= MAX_RUN and (
            others.size == 0 or abs(d[peak]) >= PEAK_RATIO * float(others.max())
        )
        if isolated:
            samples.append(peak)
            sizes.append(float(d[peak]))
        t = stop
    return Outliers(tuple(samples), tuple(sizes), scale, limit)


def impute(y, model_output, outliers: Outliers) -> np.ndarray:
    """`y` with the model's output in place of the outliers' samples."""
    y = np.array(y, float, copy=True)
    index = list(outliers.samples)
    y[index] = np.asarray(model_output, float)[index]
    return y


def without(y, simulated, outliers: Outliers, offset: int = 0) -> float:
    """The NRMSE (`_metrics.score`) of `simulated` against `y` with the outliers' samples
    left out; `offset`: the record's sample of `y[0]` (a scored part after its
    initialisation window)."""
    from .._metrics import score

    y, simulated = np.asarray(y, float), np.asarray(simulated, float)
    keep = np.ones(y.shape[0], bool)
    index = [s - offset for s in outliers.samples if 0 <= s - offset < y.shape[0]]
    keep[index] = False
    return score(y[keep], simulated[keep])


def on_records(records, from_rest, initialised=None, init_samples: int = 0, found=None):
    """One row per record that has outliers: `{"record", "role", "samples", "sizes",
    "scale", "threshold", "error", "error_without"}`, sizes in the record's units.

    - `records`: `[(name, role, Record)]`, the records as measured (model units).
    - `from_rest(u)`, `initialised(u, y, start, n)`: the model's scoring functions
      (`_scoring`); its from-rest residual is searched (`find_outliers`).
    - `found`: per record (aligned with `records`), the `Outliers` already found (the
      samples the loop left out), or None where the record is searched here.
    - `error`, `error_without`: a validation or test record's initialised NRMSE on the
      samples after the first `init_samples`, with and without the outliers (None for an
      estimation record).
    """
    rows = []
    found = [None] * len(records) if found is None else list(found)
    for (name, role, record), outliers in zip(records, found, strict=True):
        if outliers is None:
            outliers = find_outliers(record.y - np.asarray(from_rest(record.u), float), record.y)
        if not len(outliers):
            continue
        error = error_without = None
        if role != "estimation" and initialised is not None:
            from .._metrics import score

            n = int(min(max(init_samples, 0), len(record) - 2))
            simulated = np.asarray(initialised(record.u, record.y, n, n), float)
            error = score(record.y[n:], simulated)
            error_without = without(record.y[n:], simulated, outliers, offset=n)
        rows.append(
            {
                "record": name,
                "role": role,
                **outliers.to_dict(record.scaling.y_scale),
                "error": error,
                "error_without": error_without,
            }
        )
    return rows


def sentences(rows: list[dict], left_out: bool) -> list[str]:
    """What the report says of the outliers `rows` (`on_records`): one sentence per
    record, its samples and sizes, and the error with and without them."""
    out = []
    for row in rows:
        shown = ", ".join(
            f"{s} ({v:+.3g})" for s, v in zip(row["samples"][:8], row["sizes"][:8], strict=False)
        )
        more = f" and {len(row['samples']) - 8} more" if len(row["samples"]) > 8 else ""
        sentence = (
            f"The {row['role']} record {row['record']} has {len(row['samples'])} isolated "
            f"outlier(s), samples (size) {shown}{more}, beyond {row['threshold']:.3g} (a robust "
            "scale of the residual's sample-to-neighbours difference)"
        )
        if row["role"] != "test" and left_out:
            sentence += "; the loop left them out of its fits and decisions"
        if row["error"] is not None:
            sentence += f"; NRMSE {row['error']:.4f} with them, {row['error_without']:.4f} without"
        out.append(sentence + ".")
    return out
