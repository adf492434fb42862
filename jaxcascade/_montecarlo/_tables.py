"""Result tables of Monte-Carlo sweeps (pandas): per realisation, per cell, comparisons.

**Realisation table**: one row per realisation with the spec fields (`system`,
`orders`, `input` (the design's kind), `amplitude` (`Spec.amplitude`: the design's
bound), `noise` (the noise's kind), `n`, `snr`, `estimator`, `seed`), `realisation` (its
index in the cell) and `key` (its PRNG key data as one uint64, enough to rerun it),
`status` (a `Status` name), `iterations`, `cost` (the estimator's final cost),
`nrmse` (validation NRMSE on a fresh record; `inf` for an inadmissible estimate),
`admissible`, `recovered` (every parameter within `TOLERANCE` of the truth, whatever the
status: a `cycled` fit at the statistical precision is recovered, and a status is a
statement about the algorithm, not the estimate), `cycle_amplitude` (with status
`cycled`, the largest spread of one parameter over the cycle; 0 otherwise),
`robust_path` (`Solution.path` by name: `only` for a one-path estimator, `adaptive` or
`multistart` for robust), one column
per parameter with the estimate, `crlb_<name>` with the record's own Cramér-Rao bound
on its standard deviation for the cell's noise (`_efficiency.crlb`: coloured for `ar`
and `arma` noise, the Gaussian bound of the noise's variance for white, Student-t and
outlier noise; 0 noise-free),
`true_<name>` with the
true value (the row's own for a family of systems), `input_rms` and `input_crest`
(the estimation record's root mean square and crest factor `max|u| / rms`), and the
timing columns
`fit_seconds` (compute seconds per fit of its chunk, compilation excluded; a host
function's own time on the row's record) and
`compile_seconds` (seconds its chunk spent compiling, 0 when cached); the timing
columns are the only ones that differ between two runs of one spec (`without_timing`).

**Summary**: one row per grid cell and parameter. The estimate statistics (mean,
bias, std, RMSE) use only the realisations whose estimate is finite and admissible and
that accepted at least one step (`used` says how many of `count`): an inadmissible
estimate is not a model, one blown-up realisation would otherwise swamp every moment,
and a fit that failed at its first step returns its initial values, which are no
estimate at all (they would drag the mean toward the initial guess). Failures are not hidden:
`count_<status>` counts every status, and the two rates use all realisations:
`converged_rate` (status converged) and `recovered_rate` (within `TOLERANCE`, whatever
the status); `cycle_amplitude_median` and `cycle_amplitude_max` describe the cycles of
the `cycled` realisations (NaN without any). Errors are taken against each row's truth,
so for a family of systems
`bias` is the mean of `estimate - truth`, `std` the standard deviation of that error
and `true`/`mean` the means of the truth and the estimates over the rows used; for a
fixed system these are the usual moments of the estimate. The input per cell:
`input_rms_mean` and `input_crest_median`. Timing per cell:
`fit_seconds_median`, `fit_seconds_mean` and `compile_seconds` (the largest compile
time of a chunk: one compilation). Each statistic has its Monte-Carlo standard error (`*_se`):
mean and bias `s / sqrt(m)`; std `s / sqrt(2 (m - 1))` (normal approximation);
RMSE by the delta method, `sd(e^2) / (2 RMSE sqrt(m))`; rates `sqrt(p (1 - p) / count)`.
Beside them, the output-error Cramér-Rao bound `crlb_std` (the realisation table's
`crlb_<name>` columns hold each record's own bound; the cell's is the root of their
mean square, `_efficiency`) and the efficiency `crlb_std^2 / std^2` (1: the estimator
extracts all the information in the records), each with its standard error. The
regression comparison (`compare_sweeps`) looks at bias and std only.
"""

from __future__ import annotations

import json
import pathlib
import sys
import warnings

import numpy as np
import pandas as pd

from .._status import Status, status_names
from .._version import __version__

CELL_COLUMNS = ["system", "n", "snr", "estimator"]
TIMING_COLUMNS = ["fit_seconds", "compile_seconds"]
TOLERANCE = 0.05
_METADATA_KEY = b"jaxcascade"


def true_column(name: str) -> str:
    return f"true_{name}"


def crlb_column(name: str) -> str:
    return f"crlb_{name}"


def parameter_names(table: pd.DataFrame) -> list[str]:
    """Parameter names of a realisation table, in column order."""
    prefix = true_column("")
    return [c[len(prefix) :] for c in table.columns if c.startswith(prefix)]


def without_timing(table: pd.DataFrame) -> pd.DataFrame:
    """`table` without the timing columns: what two runs of one spec must share exactly."""
    return table.drop(columns=[c for c in TIMING_COLUMNS if c in table.columns])


def realisation_frame(spec, cell, indices, outputs: dict) -> pd.DataFrame:
    """Rows of one chunk from the host arrays returned by the batched run."""

    names = spec.orders.names
    estimates = np.asarray(outputs["estimate"], dtype=np.float64)
    count = len(indices)
    if spec.family is not None or spec.change is not None:  # each row's own (final) truth
        truth = np.asarray(outputs["truth"], dtype=np.float64).reshape(count, len(names))
    else:
        values = spec.true_values()
        truth = np.tile(np.array([values[name] for name in names], np.float64), (count, 1))
    errors = np.abs(estimates - truth)
    status = np.asarray(outputs["status"])
    columns = {
        "system": [spec.system] * count,
        "orders": [str(spec.orders)] * count,
        "input": [spec.input] * count,
        "amplitude": np.full(count, spec.amplitude),
        "noise": [spec.noise] * count,
        "n": np.full(count, cell.n, dtype=np.int64),
        "snr": np.full(count, cell.snr, dtype=np.float64),
        "estimator": [cell.estimator] * count,
        "seed": np.full(count, spec.seed, dtype=np.int64),
        "realisation": np.asarray(indices, dtype=np.int64),
        "key": np.asarray(outputs["key"], dtype=np.uint64),
        "status": status_names(status).astype(str),
        "iterations": np.asarray(outputs["iterations"], dtype=np.int64),
        "cost": np.asarray(outputs["cost"], dtype=np.float64),
        "nrmse": np.asarray(outputs["nrmse"], dtype=np.float64),
        "admissible": np.asarray(outputs["admissible"], dtype=bool),
        "recovered": np.all(errors <= TOLERANCE, axis=1),
        "cycle_amplitude": np.asarray(outputs["cycle_amplitude"], dtype=np.float64),
    }
    if "path" in outputs:  # tables written before it have no such column
        columns["robust_path"] = _PATH_NAMES[np.clip(np.asarray(outputs["path"]), 0, 3)]
    for j, name in enumerate(names):
        columns[name] = estimates[:, j]
    for j, name in enumerate(names):
        columns[true_column(name)] = truth[:, j]
    if "crlb" in outputs:
        bounds = np.asarray(outputs["crlb"], dtype=np.float64).reshape(count, len(names))
        for j, name in enumerate(names):
            columns[crlb_column(name)] = bounds[:, j]
    for name in ("input_rms", "input_crest"):
        if name in outputs:
            columns[name] = np.asarray(outputs[name], dtype=np.float64)
    if "track" in outputs:
        columns.update(tracking_columns(spec, cell, outputs["track"]))
    for name in TIMING_COLUMNS:
        # one figure per chunk (batched estimators), or one per row (host functions)
        values = np.asarray(outputs.get(name, np.nan), dtype=np.float64)
        columns[name] = np.broadcast_to(values, (count,)).copy()
    return pd.DataFrame(columns)


def tracking_summary(table: pd.DataFrame) -> pd.DataFrame:
    """One row per cell of a sweep of a system that changes: the fraction within the
    band before the change, the fraction that re-entered and that settled (± binomial
    SE), the re-entry samples of those that re-entered (median; mean ± SE), and the
    steady RMSE after re-entry over all parameters and of the changed one (mean ± SE)."""
    rows = []
    for cell, group in table.groupby(CELL_COLUMNS, sort=False):
        reentry = group["reentry"].to_numpy(float)
        entered = np.isfinite(reentry)
        row = dict(zip(CELL_COLUMNS, cell, strict=True), count=len(group))
        for label, hits in (
            ("before_change", group["before_change"].to_numpy(bool)),
            ("reentered", entered),
            ("settled", group["settled"].to_numpy(bool)),
        ):
            row[f"{label}_rate"], row[f"{label}_rate_se"] = _rate(hits)
        row["reentry_median"] = float(np.median(reentry[entered])) if entered.any() else np.nan
        row["reentry_mean"], row["reentry_mean_se"] = _mean_se(reentry[entered])
        for name in ("steady_rmse", "steady_rmse_changed"):
            row[name], row[f"{name}_se"] = _mean_se(group[name].to_numpy(float)[entered])
        rows.append(row)
    return pd.DataFrame(rows)


def true_trajectory(spec) -> pd.DataFrame:
    """The true parameters of a sweep of a system that changes at the samples where the
    estimate is recorded (`_tracking.tracking_samples`), one row per N and sample."""
    from .._experiment._changing import trajectory
    from ._tracking import tracking_samples

    every = dict(spec.estimator_settings("recursive"))["every"]
    frames = []
    for n in spec.n:
        samples = tracking_samples(n, every)
        values = np.asarray(trajectory(spec.truth(), spec.change, n))[samples - 1]
        frame = pd.DataFrame(values, columns=list(spec.orders.names))
        frame.insert(0, "sample", samples)
        frame.insert(0, "n", n)
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def _mean_se(values: np.ndarray) -> tuple[float, float]:
    if values.size == 0:
        return float("nan"), float("nan")
    se = float(np.std(values, ddof=1) / np.sqrt(values.size)) if values.size > 1 else np.nan
    return float(np.mean(values)), se


def track_column(name: str) -> str:
    return f"track_{name}"


def tracking_columns(spec, cell, track) -> dict:
    """The tracking columns of a system that changes (`Spec.change`): the measures of
    `_tracking` per realisation, and `track_<name>`, the error trajectory of each
    parameter at the recorded samples (`_tracking.tracking_samples`), as lists."""
    from ._tracking import BAND, _measures, tracking_samples

    names = spec.orders.names
    track = np.asarray(track, dtype=np.float64)
    samples = tracking_samples(cell.n, dict(spec.estimator_settings(cell.estimator))["every"])
    columns = [names.index(name) for name in spec.change.parameters]
    reentry, settled, steady, changed, before = _measures(
        track, samples, spec.change.at, BAND, columns
    )
    columns = {
        "reentry": reentry,
        "settled": settled,
        "steady_rmse": steady,
        "steady_rmse_changed": changed,
        "before_change": before,
    }
    for j, name in enumerate(names):
        columns[track_column(name)] = list(track[:, :, j])
    return columns


# `Solution.path` codes (`_estimator._solution`) as names; 3: unknown
_PATH_NAMES = np.array(["only", "adaptive", "multistart", "unknown"])


# ---- summaries -------------------------------------------------------------------------


def _rate(hits: np.ndarray) -> tuple[float, float]:
    n = len(hits)
    p = float(np.mean(hits)) if n else float("nan")
    return p, float(np.sqrt(p * (1 - p) / n)) if n else float("nan")


def used_mask(table: pd.DataFrame) -> np.ndarray:
    """Rows whose estimate enters the moments: admissible and at least one step accepted."""
    return table["admissible"].to_numpy(bool) & (table["iterations"].to_numpy() > 0)


def summarise(table: pd.DataFrame) -> pd.DataFrame:
    """Per grid cell and parameter: mean, bias, std, RMSE, rates, each with its MC error."""
    names = parameter_names(table)
    rows = []
    for cell, group in table.groupby(CELL_COLUMNS, sort=False, dropna=False):
        count = len(group)
        used = group[used_mask(group)]
        m = len(used)
        status = group["status"].to_numpy(str)
        converged, converged_se = _rate(status == Status.converged.name)
        recovered, recovered_se = _rate(group["recovered"].to_numpy(bool))
        per_cell = {
            "count": count,
            "used": m,
            "converged_rate": converged,
            "converged_rate_se": converged_se,
            "recovered_rate": recovered,
            "recovered_rate_se": recovered_se,
            "nrmse_median": float(np.median(group["nrmse"])) if count else float("nan"),
            **_input_statistics(group),
            **_cycles(group),
            **_timing(group),
            **{f"count_{s.name}": int(np.sum(status == s.name)) for s in Status},
        }
        for name in names:
            truths = group[true_column(name)].to_numpy(np.float64)
            estimate = used[name].to_numpy(np.float64)
            mean = float(np.mean(estimate)) if m else float("nan")
            if np.all(truths == truths[0]):  # one system: the moments of the estimate
                true = float(truths[0])
                error = estimate - true
                std = float(np.std(estimate, ddof=1)) if m > 1 else float("nan")
            else:  # a family: moments of the error against each row's truth
                true_used = used[true_column(name)].to_numpy(np.float64)
                error = estimate - true_used
                true = mean - float(np.mean(error)) if m else float("nan")
                std = float(np.std(error, ddof=1)) if m > 1 else float("nan")
            rmse = float(np.sqrt(np.mean(error**2))) if m else float("nan")
            if m > 1 and rmse > 0:
                rmse_se = float(np.std(error**2, ddof=1) / np.sqrt(m) / (2 * rmse))
            else:
                rmse_se = 0.0 if m > 1 else float("nan")
            mean_se = std / np.sqrt(m) if m > 1 else float("nan")
            rows.append(
                {
                    **dict(zip(CELL_COLUMNS, cell, strict=True)),
                    "parameter": name,
                    "true": true,
                    "mean": mean,
                    "mean_se": mean_se,
                    "bias": mean - true,
                    "bias_se": mean_se,
                    "std": std,
                    "std_se": std / np.sqrt(2 * (m - 1)) if m > 1 else float("nan"),
                    "rmse": rmse,
                    "rmse_se": rmse_se,
                    **_efficiency(group, name, std, m),
                    **per_cell,
                }
            )
    return pd.DataFrame(rows)


def _efficiency(group: pd.DataFrame, name: str, std: float, m: int) -> dict[str, float]:
    """The cell's Cramér-Rao bound (the average of its records' per-record bound
    variances, `_efficiency`) and the efficiency `crlb_std^2 / std^2`, each with its
    Monte-Carlo standard error (delta method: the bound's from the spread of the
    per-record bounds, the variance's `std^2 sqrt(2 / (m - 1))`). NaN where the table has
    no bounds (written before them), noise-free (bound 0) or without estimates."""
    nan = {"crlb_std": np.nan, "crlb_std_se": np.nan, "efficiency": np.nan, "efficiency_se": np.nan}
    column = crlb_column(name)
    if column not in group:
        return nan
    variances = group[column].to_numpy(np.float64) ** 2
    variances = variances[np.isfinite(variances)]
    if not variances.size:
        return nan
    bound_variance = float(np.mean(variances))
    bound_variance_se = (
        float(np.std(variances, ddof=1) / np.sqrt(variances.size)) if variances.size > 1 else 0.0
    )
    out = {
        "crlb_std": np.sqrt(bound_variance),
        "crlb_std_se": bound_variance_se / (2 * np.sqrt(bound_variance))
        if bound_variance > 0
        else 0.0,
        "efficiency": np.nan,
        "efficiency_se": np.nan,
    }
    if m > 1 and std > 0 and bound_variance > 0:
        efficiency = bound_variance / std**2
        relative = np.sqrt(2 / (m - 1) + (bound_variance_se / bound_variance) ** 2)
        out.update(efficiency=efficiency, efficiency_se=efficiency * relative)
    return out


def _input_statistics(group: pd.DataFrame) -> dict[str, float]:
    """The estimation records' mean rms and median crest factor (NaN in tables written
    before the input designs)."""
    if "input_rms" not in group or not len(group):
        return {"input_rms_mean": np.nan, "input_crest_median": np.nan}
    return {
        "input_rms_mean": float(np.mean(group["input_rms"].to_numpy(np.float64))),
        "input_crest_median": float(np.median(group["input_crest"].to_numpy(np.float64))),
    }


def _cycles(group: pd.DataFrame) -> dict[str, float]:
    if "cycle_amplitude" not in group:  # a table written before the cycled status
        amplitude = np.zeros(0)
    else:
        amplitude = group.loc[group["status"] == Status.cycled.name, "cycle_amplitude"]
        amplitude = amplitude.to_numpy(np.float64)
    if not amplitude.size:
        return {"cycle_amplitude_median": np.nan, "cycle_amplitude_max": np.nan}
    return {
        "cycle_amplitude_median": float(np.median(amplitude)),
        "cycle_amplitude_max": float(np.max(amplitude)),
    }


def _timing(group: pd.DataFrame) -> dict[str, float]:
    if "fit_seconds" not in group or not len(group):
        return {"fit_seconds_median": np.nan, "fit_seconds_mean": np.nan, "compile_seconds": np.nan}
    seconds = group["fit_seconds"].to_numpy(np.float64)
    return {
        "fit_seconds_median": float(np.median(seconds)),
        "fit_seconds_mean": float(np.mean(seconds)),
        "compile_seconds": float(np.max(group["compile_seconds"].to_numpy(np.float64))),
    }


def read_summary(path) -> pd.DataFrame:
    """A stored summary (CSV or Parquet); a realisation table is summarised first."""
    path = pathlib.Path(path)
    if not path.exists():
        raise ValueError(f"Baseline '{path}' does not exist.")
    frame = pd.read_csv(path) if path.suffix == ".csv" else pd.read_parquet(path)
    if "realisation" in frame.columns:
        return summarise(frame)
    missing = [
        c
        for c in [*CELL_COLUMNS, "parameter", "bias", "bias_se", "std", "std_se"]
        if c not in frame
    ]
    if missing:
        raise ValueError(f"'{path}' is not a sweep summary: it lacks column {missing[0]!r}.")
    return frame


def compare_sweeps(
    summary: pd.DataFrame, baseline: pd.DataFrame, threshold: float = 3.0
) -> pd.DataFrame:
    """Bias and std of every shared cell and parameter of a sweep's summary, against a
    baseline sweep's summary (`read_summary`; `jaxcascade sweep --compare BASELINE`).

    A statistic is `flagged` when `|now - baseline| > threshold * sqrt(se_now^2 + se_base^2)`,
    i.e. when the change is more than Monte-Carlo error explains (about 3 in 1000 rows at
    `threshold = 3` if nothing changed). Raises ValueError when no cell is shared.
    """
    keys = [*CELL_COLUMNS, "parameter"]
    left = summary.copy()
    right = baseline.copy()
    for frame in (left, right):
        frame["n"] = frame["n"].astype(np.int64)
        frame["snr"] = frame["snr"].astype(np.float64)
        for column in ("system", "estimator", "parameter"):
            frame[column] = frame[column].astype(str)
    merged = left.merge(right, on=keys, suffixes=("", "_baseline"))
    if merged.empty:
        raise ValueError("The baseline shares no grid cell and parameter with this run.")
    rows = []
    for statistic in ("bias", "std"):
        now, base = merged[statistic], merged[f"{statistic}_baseline"]
        se = np.sqrt(merged[f"{statistic}_se"] ** 2 + merged[f"{statistic}_se_baseline"] ** 2)
        diff = now - base
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(se > 0, np.abs(diff) / se, np.where(diff == 0, 0.0, np.inf))
        z = np.where(np.isnan(diff), np.where(now.isna() & base.isna(), 0.0, np.inf), z)
        rows.append(
            merged[keys].assign(
                statistic=statistic,
                value=now,
                baseline=base,
                diff=diff,
                se=se,
                z=z,
                flagged=z > threshold,
            )
        )
    return pd.concat(rows, ignore_index=True)


def compare(summary: pd.DataFrame, baseline: pd.DataFrame, threshold: float = 3.0) -> pd.DataFrame:
    """Deprecated alias of `compare_sweeps`, kept for one release.

    Renamed because it compares two sweeps' summaries, where MATLAB's `compare` compares a
    model with measured data. Warns (`DeprecationWarning`) and returns what
    `compare_sweeps` returns.
    """
    warnings.warn(
        "jaxcascade.compare is deprecated and goes in the next release: use "
        "jaxcascade.compare_sweeps (it compares a sweep's summary with a baseline's).",
        DeprecationWarning,
        stacklevel=2,
    )
    return compare_sweeps(summary, baseline, threshold)


# ---- Parquet with metadata -------------------------------------------------------------


def run_metadata(spec, dtype, normal_equations: str, command: list[str] | None = None) -> dict:
    """Versions, dtype, how the literal iteration formed its normal equations (`fused` or
    `xla`, same estimates up to rounding, as the engine reports it), spec, every
    estimator's settings in full (defaults included: a default that changes between
    versions stays on record) and command line, stored in the Parquet schema metadata."""
    import jax

    from .._estimator import ESTIMATORS

    return {
        "jaxcascade": __version__,
        "jax": jax.__version__,
        "numpy": np.__version__,
        "pandas": pd.__version__,
        "python": sys.version.split()[0],
        "dtype": str(np.dtype(dtype)),
        "normal_equations": normal_equations,
        "spec": spec.to_dict(),
        "estimator_settings": {
            name: _plain({**ESTIMATORS[name].settings(), **dict(spec.estimator_settings(name))})
            for name in spec.estimators
        },
        "command": list(sys.argv if command is None else command),
    }


def _plain(settings: dict) -> dict:
    # JSON-safe: tuples as lists, anything else that JSON cannot hold as its repr
    def plain(value):
        if isinstance(value, (bool, int, float, str)) or value is None:
            return value
        if isinstance(value, (tuple, list)):
            return [plain(v) for v in value]
        return repr(value)

    return {key: plain(value) for key, value in settings.items()}


def write_table(table: pd.DataFrame, path, metadata: dict) -> None:
    """Write `table` to Parquet with `metadata` (JSON) under the key `jaxcascade`, atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = pathlib.Path(path)
    arrow = pa.Table.from_pandas(table, preserve_index=False)
    schema_metadata = dict(arrow.schema.metadata or {})
    schema_metadata[_METADATA_KEY] = json.dumps(metadata, sort_keys=True).encode()
    arrow = arrow.replace_schema_metadata(schema_metadata)
    partial = path.with_name(path.name + ".tmp")
    pq.write_table(arrow, partial)
    partial.replace(path)


def read_metadata(path) -> dict:
    """The `jaxcascade` metadata of a Parquet file written by `write_table` ({} if none)."""
    import pyarrow.parquet as pq

    metadata = pq.read_schema(path).metadata or {}
    return json.loads(metadata[_METADATA_KEY]) if _METADATA_KEY in metadata else {}
