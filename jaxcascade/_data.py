"""Measured records: read, check, decimate, scale and split input/output data (host side).

Everything here is numpy/pandas/scipy on the host; a `Record` holds float64 numpy arrays
that the estimator converts to `jnp` arrays itself. Problems a user can fix (missing file,
wrong column, NaN, too few samples, a constant input) raise a plain `ValueError` with one
sentence saying what is wrong and what to do, before anything is computed or written.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import os
import re
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd
import scipy.signal

from ._validate import MAX_MAGNITUDE

_FORMATS = {".csv": "csv", ".txt": "csv", ".parquet": "parquet", ".pq": "parquet"}
_SCALINGS = ("none", "standard", "scale", "auto")
# `"auto"` scaling centres the input (and the output) when fewer than this fraction of
# the input's samples lie on one side of zero: the cascade's static block bends at zero,
# so zero must lie inside the record's operating range.
AUTO_SIDE_FRACTION = 0.05
_FILTERS = ("fir", "iir")
# Largest single IIR decimation step scipy recommends for its Chebyshev filter.
_MAX_IIR_STEP = 13
# Relative spread of the time steps tolerated before a record counts as unevenly sampled
# (CSV times are often rounded to a few digits: 1/1024 s written as 0.0009766).
_TIME_RTOL = 1e-2


@dataclasses.dataclass(frozen=True)
class Scaling:
    """Affine map between physical units and model units: `model = (physical - offset) / scale`.

    The model is fitted in model units. Because the cascade is not unique (eq. 12 fixes
    `mL = 1`, `a1 = 1`), a model fitted in model units is the same system in physical
    units, `y - y_offset = cascade(u - u_offset)`, with the parameters of
    `params_to_physical`: NS slopes times `y_scale / u_scale`, breakpoints times `u_scale`,
    backlash gaps times `y_scale`, and `a`, `b`, `mR` unchanged.

    Fields: `u_offset`, `u_scale`, `y_offset`, `y_scale` (scales > 0), and `method`, the
    rule that produced them (`"none"`, `"standard"`, `"scale"`, or `"given"`).
    """

    u_offset: float = 0.0
    u_scale: float = 1.0
    y_offset: float = 0.0
    y_scale: float = 1.0
    method: str = "none"

    def __post_init__(self):
        for name in ("u_offset", "u_scale", "y_offset", "y_scale"):
            value = float(getattr(self, name))
            if not np.isfinite(value):
                raise ValueError(f"Scaling {name} must be finite, got {value}.")
            object.__setattr__(self, name, value)
        for name in ("u_scale", "y_scale"):
            if getattr(self, name) <= 0:
                raise ValueError(f"Scaling {name} must be positive, got {getattr(self, name)}.")

    @classmethod
    def from_data(cls, u, y, method: str = "standard") -> Scaling:
        """Scaling chosen from physical data.

        - `"none"`: identity.
        - `"standard"`: subtract the mean and divide by the standard deviation.
        - `"scale"`: divide by the standard deviation only (zero stays zero).
        - `"auto"`: `"scale"` when the input has at least `AUTO_SIDE_FRACTION` (5 %) of its
          samples on each side of zero, `"standard"` otherwise (an input that never
          crosses zero, a positive voltage or a level, is centred, so that the static
          block's breakpoint at zero lies in the operating range). `method` records the
          rule chosen.
        """
        if method not in _SCALINGS:
            raise ValueError(f"Unknown scaling {method!r}; use one of {', '.join(_SCALINGS)}.")
        u, y = np.asarray(u, dtype=np.float64), np.asarray(y, dtype=np.float64)
        if method == "auto":
            side = min(np.mean(u > 0), np.mean(u < 0)) if u.size else 0.0
            method = "scale" if side >= AUTO_SIDE_FRACTION else "standard"
        if method == "none":
            return cls(method="none")
        centre = method == "standard"
        return cls(
            u_offset=float(np.mean(u)) if centre else 0.0,
            u_scale=float(np.std(u)),
            y_offset=float(np.mean(y)) if centre else 0.0,
            y_scale=float(np.std(y)),
            method=method,
        )

    def input_to_model(self, u):
        return (np.asarray(u, dtype=np.float64) - self.u_offset) / self.u_scale

    def output_to_model(self, y):
        return (np.asarray(y, dtype=np.float64) - self.y_offset) / self.y_scale

    def input_to_physical(self, u):
        return np.asarray(u, dtype=np.float64) * self.u_scale + self.u_offset

    def output_to_physical(self, y):
        return np.asarray(y, dtype=np.float64) * self.y_scale + self.y_offset

    def to_model(self, u, y) -> tuple[np.ndarray, np.ndarray]:
        """Physical `(u, y)` to model units."""
        return self.input_to_model(u), self.output_to_model(y)

    def to_physical(self, u, y) -> tuple[np.ndarray, np.ndarray]:
        """Model-unit `(u, y)` to physical units."""
        return self.input_to_physical(u), self.output_to_physical(y)

    def params_to_physical(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Map parameters named as in `Orders.names` from model to physical units.

        The physical model is `y - y_offset = cascade(u - u_offset)` (offsets are not
        parameters of the cascade, whose NS passes through zero).
        """
        factors = {
            "MR": self.y_scale / self.u_scale,
            "ML": self.y_scale / self.u_scale,
            "DR": self.u_scale,
            "DL": self.u_scale,
            "a": 1.0,
            "b": 1.0,
            "mR": 1.0,
            "cL": self.y_scale,
            "cR": self.y_scale,
        }
        out = {}
        for name, value in values.items():
            match = re.fullmatch(r"(MR|ML|DR|DL|a|b)\d*|(mR|cL|cR)", name)
            if match is None:
                raise ValueError(
                    f"Unknown parameter name {name!r}; expected names such as MR1, DL1, a2, "
                    "b1, cL, mR, cR (see Orders.names)."
                )
            key = match.group(1) or match.group(2)
            out[name] = np.asarray(value, dtype=np.float64) * factors[key]
            if np.ndim(out[name]) == 0:
                out[name] = float(out[name])
        return out

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True, eq=False)
class Record:
    """One measured input/output record, checked, optionally decimated, in model units.

    Fields:
    - `u`, `y`: `Float[np.ndarray, " T"]`, input and output in model units
      (`scaling.to_physical` maps them back).
    - `time`: `Float[np.ndarray, " T"]` in the file's time unit, or `None`.
    - `sample_period`: time between samples after decimation, or `None` if unknown.
    - `scaling`: the `Scaling` used.
    - `source`: the file read, or `None` for arrays.
    - `input_column`, `output_column`, `time_column`: column names.
    - `decimation`: integer factor applied; `anti_alias`: the filter used, or `None`.
    - `start`: index of the first sample within the loaded (decimated) record; nonzero
      for the validation part of a split.
    """

    u: np.ndarray
    y: np.ndarray
    time: np.ndarray | None
    sample_period: float | None
    scaling: Scaling
    source: str | None
    input_column: str
    output_column: str
    time_column: str | None = None
    decimation: int = 1
    anti_alias: str | None = None
    start: int = 0

    def __len__(self) -> int:
        return int(self.u.shape[0])

    @property
    def u_physical(self) -> np.ndarray:
        return self.scaling.input_to_physical(self.u)

    @property
    def y_physical(self) -> np.ndarray:
        return self.scaling.output_to_physical(self.y)

    def split(self, at: float | int, orders=None) -> tuple[Record, Record]:
        """Estimation and validation parts; see `split_record`."""
        return split_record(self, at, orders=orders)

    def to_dict(self) -> dict[str, Any]:
        """Metadata, JSON-serialisable (no arrays)."""
        return {
            "source": self.source,
            "input_column": self.input_column,
            "output_column": self.output_column,
            "time_column": self.time_column,
            "samples": len(self),
            "sample_period": self.sample_period,
            "decimation": self.decimation,
            "anti_alias": self.anti_alias,
            "start": self.start,
            "scaling": self.scaling.to_dict(),
        }


# ---- reading --------------------------------------------------------------------------


def read_record(
    path: str | os.PathLike,
    input_column: str,
    output_column: str,
    *,
    time_column: str | None = None,
    format: str | None = None,
    sample_period: float | None = None,
    decimate: int = 1,
    anti_alias: str = "fir",
    scaling: str | Scaling = "standard",
    orders=None,
) -> Record:
    """Read one input/output record from a CSV or Parquet file.

    Arguments:
    - `path`: a `.csv` (or `.txt`) or `.parquet` (or `.pq`) file; `format` overrides the suffix.
    - `input_column`, `output_column`: column names of u and y.
    - `time_column`: optional column of sample times; it must increase evenly and fixes
      `sample_period` (if both are given they must agree).
    - `decimate`: keep every `decimate`-th sample after a zero-phase anti-alias low-pass,
      `anti_alias="fir"` (Hamming-window FIR of order 20*decimate, cutoff at the new
      Nyquist frequency, the filter of `scipy.signal.decimate`, applied by
      `resample_poly` with odd-symmetric edge padding so the ends are not pulled to zero)
      or `"iir"` (`scipy.signal.decimate`'s order-8 Chebyshev I run forward and backward,
      in steps of at most 13).
    - `scaling`: `"standard"`, `"scale"`, `"auto"`, `"none"` (see `Scaling.from_data`, computed
      after decimation), or a `Scaling` to reuse, e.g. the estimation record's for a
      validation record.
    - `orders`: an `Orders`; the record must hold at least `orders.min_samples` samples.

    Returns a `Record`. Raises `ValueError` for a missing file, an unknown format,
    missing columns, non-numeric, NaN or infinite values, columns of different lengths,
    uneven time, too few samples, or a constant input or output.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ValueError(f"Data file {path!r} does not exist; check the path.")
    if not os.path.isfile(path):
        raise ValueError(f"Data path {path!r} is not a file; give a CSV or Parquet file.")
    kind = _format_of(path, format)
    frame = _read_frame(path, kind)
    names = [input_column, output_column] + ([time_column] if time_column is not None else [])
    if len(set(names)) != len(names):
        raise ValueError(f"Input, output and time columns must be different, got {names}.")
    available = [str(c) for c in frame.columns]
    missing = [name for name in names if name not in available]
    if missing:
        lower = {c.lower(): c for c in available}
        hints = {
            name: [lower[m] for m in difflib.get_close_matches(name.lower(), list(lower), 1, 0.6)]
            for name in missing
        }
        hint = "".join(f" (did you mean {hints[m][0]!r} for {m!r}?)" for m in missing if hints[m])
        raise ValueError(
            f"Column(s) {', '.join(map(repr, missing))} not found in {path!r}; available "
            f"columns are {', '.join(map(repr, available))}{hint}."
        )
    frame.columns = available
    columns = {name: _numeric_column(frame[name], name, path) for name in names}
    _check_equal_lengths(columns, path)
    for name, values in columns.items():
        _check_finite(values, name, path)
    return _build(
        columns[input_column],
        columns[output_column],
        columns[time_column] if time_column is not None else None,
        source=path,
        input_column=input_column,
        output_column=output_column,
        time_column=time_column,
        sample_period=sample_period,
        decimate=decimate,
        anti_alias=anti_alias,
        scaling=scaling,
        orders=orders,
    )


def read_column(
    path: str | os.PathLike,
    column: str,
    *,
    format: str | None = None,
    decimate: int = 1,
    anti_alias: str = "fir",
) -> np.ndarray:
    """One numeric column of a CSV or Parquet file as float64 (e.g. a measured input to
    reuse in a simulated experiment), decimated as `read_record` does; the same checks
    (missing file or column, non-numeric, NaN or infinite values, a constant column) with
    the same sentences."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"Data file {path!r} does not exist; check the path.")
    if isinstance(decimate, bool) or not isinstance(decimate, int) or decimate < 1:
        raise ValueError(f"decimate must be a positive integer, got {decimate!r}.")
    if anti_alias not in _FILTERS:
        raise ValueError(f"Unknown anti-alias filter {anti_alias!r}; use 'fir' or 'iir'.")
    frame = _read_frame(path, _format_of(path, format))
    available = [str(c) for c in frame.columns]
    if column not in available:
        close = difflib.get_close_matches(column, available, 1, 0.6)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(
            f"Column {column!r} not found in {path!r}; available columns are "
            f"{', '.join(map(repr, available))}{hint}."
        )
    frame.columns = available
    values = _numeric_column(frame[column], column, path)
    _check_finite(values, column, path)
    if decimate > 1:
        values = _decimate(values, decimate, anti_alias)
    _check_not_constant(values, column, path, "input")
    return np.ascontiguousarray(values, dtype=np.float64)


def record_from_arrays(
    u,
    y,
    *,
    time=None,
    sample_period: float | None = None,
    decimate: int = 1,
    anti_alias: str = "fir",
    scaling: str | Scaling = "standard",
    orders=None,
    source: str | None = None,
    input_column: str = "u",
    output_column: str = "y",
) -> Record:
    """A `Record` from physical arrays, with the same checks as `read_record`."""
    arrays = {input_column: u, output_column: y}
    if time is not None:
        arrays["time"] = time
    columns = {}
    for name, value in arrays.items():
        value = np.asarray(value)
        if value.ndim != 1:
            raise ValueError(f"{name!r} must be a 1-D array, got shape {value.shape}.")
        if not np.issubdtype(value.dtype, np.number) or np.iscomplexobj(value):
            raise ValueError(f"{name!r} must hold real numbers, got dtype {value.dtype}.")
        columns[name] = value.astype(np.float64)
    where = source or "the arrays"
    lengths = {name: len(value) for name, value in columns.items()}
    if len(set(lengths.values())) > 1:
        described = ", ".join(f"{name!r} has {n}" for name, n in lengths.items())
        raise ValueError(
            f"Input, output and time lengths differ in {where} ({described} samples); "
            "pass arrays of equal length."
        )
    for name, value in columns.items():
        _check_finite(value, name, where)
    return _build(
        columns[input_column],
        columns[output_column],
        columns.get("time"),
        source=source,
        input_column=input_column,
        output_column=output_column,
        time_column="time" if time is not None else None,
        sample_period=sample_period,
        decimate=decimate,
        anti_alias=anti_alias,
        scaling=scaling,
        orders=orders,
    )


def split_record(record: Record, at: float | int, *, orders=None) -> tuple[Record, Record]:
    """Split a record into an estimation part (first) and a validation part (second).

    - `at`: a fraction in (0, 1) of the samples that go to estimation (a float), or the
      index of the first validation sample (an int).
    - `orders`: if given, each part must hold at least `orders.min_samples` samples.

    Both parts keep the record's scaling, so estimates from the first apply to the second.
    """
    n = len(record)
    if isinstance(at, bool) or not isinstance(at, int | float | np.integer | np.floating):
        raise ValueError(f"Split point must be a fraction or an index, got {at!r}.")
    if isinstance(at, float | np.floating):
        if not 0.0 < at < 1.0:
            raise ValueError(f"Split fraction must lie strictly between 0 and 1, got {at}.")
        index = int(round(at * n))
    else:
        index = int(at)
    if not 0 < index < n:
        raise ValueError(
            f"Split index must lie between 1 and {n - 1} for a record of {n} samples, got {index}."
        )
    if orders is not None:
        shortest = min(index, n - index)
        if shortest < orders.min_samples:
            raise ValueError(
                f"Splitting {n} samples at {index} leaves a part of {shortest} samples, "
                f"fewer than the {orders.min_samples} that orders {orders} need; use a "
                "longer record or move the split point."
            )

    def part(sl: slice, start: int) -> Record:
        return dataclasses.replace(
            record,
            u=record.u[sl].copy(),
            y=record.y[sl].copy(),
            time=None if record.time is None else record.time[sl].copy(),
            start=record.start + start,
        )

    return part(slice(0, index), 0), part(slice(index, n), index)


# ---- checks and building blocks ---------------------------------------------------------


def _format_of(path: str, format: str | None) -> str:
    if format is not None:
        kind = str(format).lower().lstrip(".")
        if kind not in ("csv", "parquet"):
            raise ValueError(f"Unknown data format {format!r}; use 'csv' or 'parquet'.")
        return kind
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in _FORMATS:
        raise ValueError(
            f"Unknown data format {suffix or '(no suffix)'!r} for {path!r}; use a .csv or "
            ".parquet file, or name the format explicitly (format='csv' or 'parquet')."
        )
    return _FORMATS[suffix]


def _read_frame(path: str, kind: str) -> pd.DataFrame:
    _check_unique_header(path, kind)
    try:
        if kind == "csv":
            return pd.read_csv(path)
        return pd.read_parquet(path)
    except Exception as error:  # pandas/pyarrow raise many types; keep one line
        first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise ValueError(
            f"Could not read {path!r} as {kind.upper()} ({first}); check the file and its format."
        ) from error


def _check_unique_header(path: str, kind: str) -> None:
    # pandas renames a repeated CSV column ('y', 'y' -> 'y', 'y.1') and reads on: the
    # header is read here first, so the user learns which column is meant twice.
    try:
        if kind == "csv":
            with open(path, newline="", encoding="utf-8-sig", errors="replace") as file:
                names = next(csv.reader(file), [])
        else:
            import pyarrow.parquet

            names = pyarrow.parquet.read_schema(path).names
    except Exception:  # an unreadable file: pandas reports it with its own sentence
        return
    # unnamed columns (an index written without a name) are pandas' to number
    repeated = sorted({name for name in names if name and names.count(name) > 1})
    if repeated:
        raise ValueError(
            f"{path!r} has repeated column names: {', '.join(map(repr, repeated))} (columns "
            f"{', '.join(map(repr, names))}); give every column its own name."
        )


def _numeric_column(series: pd.Series, name: str, path: str) -> np.ndarray:
    numeric = pd.to_numeric(series, errors="coerce")
    bad = numeric.isna().to_numpy() & series.notna().to_numpy()
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"Column {name!r} in {path!r} has {int(bad.sum())} non-numeric values, the first "
            f"at data row {first} ({series.iloc[first]!r}); clean the file before loading."
        )
    return numeric.to_numpy(dtype=np.float64, na_value=np.nan)


def _check_equal_lengths(columns: Mapping[str, np.ndarray], where: str) -> None:
    # A CSV column that ends early reads as trailing NaN: report it as a length mismatch.
    lengths = {}
    for name, values in columns.items():
        valid = np.flatnonzero(~np.isnan(values))
        last = int(valid[-1]) + 1 if valid.size else 0
        lengths[name] = last if not np.isnan(values[:last]).any() else len(values)
    if len(set(lengths.values())) > 1:
        described = ", ".join(f"{name!r} has {n}" for name, n in lengths.items())
        raise ValueError(
            f"Columns of {where!r} have different lengths ({described} values); trim the "
            "file so every column has the same number of rows."
        )


def _check_finite(values: np.ndarray, name: str, where: str) -> None:
    bad = ~np.isfinite(values)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name!r} in {where!r} has {int(bad.sum())} NaN or infinite values, the first at "
            f"row {first} (counting data rows from 0); remove or fill them before loading."
        )
    huge = np.abs(values) > MAX_MAGNITUDE
    if huge.any():
        first = int(np.flatnonzero(huge)[0])
        raise ValueError(
            f"{name!r} in {where!r} reaches {float(np.max(np.abs(values))):.3g} (first beyond "
            f"{MAX_MAGNITUDE:g} at row {first}), where squares overflow; rescale the record, "
            "e.g. to other units."
        )


def _check_not_constant(values: np.ndarray, name: str, where: str, role: str) -> None:
    if values.size and np.all(values == values[0]):
        raise ValueError(
            f"The {role} {name!r} in {where!r} is constant ({values[0]:g} throughout); a "
            f"constant {role} cannot identify the model, choose another column or record."
        )


def _sample_period(time: np.ndarray | None, given: float | None, where: str) -> float | None:
    if given is not None:
        given = float(given)
        if not (np.isfinite(given) and given > 0):
            raise ValueError(f"Sample period must be a positive number, got {given}.")
    if time is None or time.size < 2:
        return given
    steps = np.diff(time)
    if np.any(steps <= 0):
        first = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise ValueError(
            f"Time in {where!r} must increase strictly, but row {first} does not; sort the "
            "record or drop duplicated rows."
        )
    # The mean step over the whole record is exact to the rounding of two values only.
    period = float((time[-1] - time[0]) / (time.size - 1))
    uneven = np.abs(steps - period) > _TIME_RTOL * period
    if uneven.any():
        first = int(np.flatnonzero(uneven)[0]) + 1
        raise ValueError(
            f"Time in {where!r} is not evenly sampled (step {steps[first - 1]:g} at row {first} "
            f"against a typical {period:g}); resample the record to a constant period."
        )
    if given is not None and abs(given - period) > _TIME_RTOL * period:
        raise ValueError(
            f"Sample period {given:g} disagrees with the time column's step {period:g}; "
            "give one or the other."
        )
    return period


def _decimate(values: np.ndarray, factor: int, anti_alias: str) -> np.ndarray:
    if anti_alias == "fir":
        taps = scipy.signal.firwin(20 * factor + 1, 1.0 / factor, window="hamming")
        return scipy.signal.resample_poly(values, 1, factor, window=taps, padtype="antireflect")
    out = values
    for step in _factor_steps(factor):
        out = scipy.signal.decimate(out, step, ftype="iir", zero_phase=True)
    return out


def _factor_steps(factor: int) -> list[int]:
    # Prime factors, merged greedily into steps of at most 13 (scipy's advice for its IIR).
    primes, rest, p = [], factor, 2
    while rest > 1:
        while rest % p == 0:
            primes.append(p)
            rest //= p
        p += 1
    steps: list[int] = []
    for prime in sorted(primes, reverse=True):
        for i, step in enumerate(steps):
            if step * prime <= _MAX_IIR_STEP:
                steps[i] *= prime
                break
        else:
            steps.append(prime)
    return steps


def _build(
    u: np.ndarray,
    y: np.ndarray,
    time: np.ndarray | None,
    *,
    source: str | None,
    input_column: str,
    output_column: str,
    time_column: str | None,
    sample_period: float | None,
    decimate: int,
    anti_alias: str,
    scaling: str | Scaling,
    orders,
) -> Record:
    where = source or "the arrays"
    if isinstance(decimate, bool) or not isinstance(decimate, int | np.integer) or decimate < 1:
        raise ValueError(f"Decimation factor must be an integer >= 1, got {decimate!r}.")
    decimate = int(decimate)
    if anti_alias not in _FILTERS:
        raise ValueError(f"Unknown anti-alias filter {anti_alias!r}; use 'fir' or 'iir'.")
    if not isinstance(scaling, Scaling) and scaling not in _SCALINGS:
        raise ValueError(
            f"Unknown scaling {scaling!r}; use one of {', '.join(_SCALINGS)} or a Scaling."
        )
    period = _sample_period(time, sample_period, where)
    _check_not_constant(u, input_column, where, "input")
    _check_not_constant(y, output_column, where, "output")
    kept = -(-len(u) // decimate)
    needed = orders.min_samples if orders is not None else 2
    if kept < needed:
        after = f" after decimation by {decimate}" if decimate > 1 else ""
        what = f"orders {orders} need" if orders is not None else "a record needs"
        raise ValueError(
            f"{where!r} has {kept} samples{after}, fewer than the {needed} that {what}; "
            "use a longer record, a smaller decimation factor or lower orders."
        )
    if decimate > 1:
        # Filtering needs a few filter lengths of data to mean anything.
        if len(u) < 3 * (20 * decimate + 1):
            raise ValueError(
                f"{where!r} has {len(u)} samples, too few to decimate by {decimate} (the "
                f"anti-alias filter spans {20 * decimate + 1}); lower the factor."
            )
        u, y = _decimate(u, decimate, anti_alias), _decimate(y, decimate, anti_alias)
        time = None if time is None else time[::decimate].copy()
        period = None if period is None else period * decimate
        _check_not_constant(u, input_column, where, "input")
    if not isinstance(scaling, Scaling):
        scaling = Scaling.from_data(u, y, scaling)
    u, y = scaling.to_model(u, y)
    return Record(
        u=u,
        y=y,
        time=time,
        sample_period=period,
        scaling=scaling,
        source=source,
        input_column=input_column,
        output_column=output_column,
        time_column=time_column,
        decimation=decimate,
        anti_alias=anti_alias if decimate > 1 else None,
        start=0,
    )
