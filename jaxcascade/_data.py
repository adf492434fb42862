"""Measured records: read, check, decimate, scale and split input/output data (host side).

Records come as labs ship them: CSV or TSV files with any delimiter and a decimal point or
comma, Parquet files, and MATLAB MAT files (v4 to v7, and v7.3/HDF5 through h5py) that
hold several records side by side. A record spec, `FILE[:INPUT,OUTPUT[:START:STOP]]`
(`parse_record_spec`), names the signals and a range of samples in one
string, so every command that takes a record file takes a spec.

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

from . import _defaults
from ._system._validate import MAX_MAGNITUDE

_FORMATS = {
    ".csv": "csv",
    ".tsv": "csv",
    ".txt": "csv",
    ".dat": "csv",
    ".parquet": "parquet",
    ".pq": "parquet",
    ".mat": "mat",
}
_DETRENDS = ("none", "mean", "linear")
# Delimiters tried in this order (a decimal comma rules out the comma when a tab or a
# semicolon also splits every line); `None` is runs of whitespace.
_DELIMITERS = ("\t", ";", ",", "|", None)
# MATLAB classes that hold numbers (a `char`, `cell`, `struct` or `sparse` does not).
_MAT_NUMERIC = {
    "double", "single", "logical",
    *(f"{sign}int{bits}" for sign in ("", "u") for bits in (8, 16, 32, 64)),
}  # fmt: skip
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
        parameters of the cascade, whose NS passes through zero). The curved branches'
        terms `mL_i`, `mR_i` (`i >= 2`, a general backlash) multiply the `i`-th power of
        a signal in output units: they scale by `y_scale ** (1 - i)`.
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
            match = re.fullmatch(r"(MR|ML|DR|DL|a|b)\d*|(mR|cL|cR)|(?:mL|mR)(\d+)", name)
            if match is None:
                raise ValueError(
                    f"Unknown parameter name {name!r}; expected names such as MR1, DL1, a2, "
                    "b1, cL, mR, cR, mL2 (see Orders.names)."
                )
            if match.group(3) is not None:  # a curved branch's term of power i
                factor = self.y_scale ** (1 - int(match.group(3)))
            else:
                factor = factors[match.group(1) or match.group(2)]
            out[name] = np.asarray(value, dtype=np.float64) * factor
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
    - `source`: the file read, or `None` for arrays; a record spec
      (`FILE:INPUT,OUTPUT:START:STOP`, the range resolved) when the signals or a range
      were named in one, so that reports say which samples were used.
    - `input_column`, `output_column`, `time_column`: column (or MAT variable) names.
    - `decimation`: integer factor applied; `anti_alias`: the filter used, or `None`.
    - `start`: index of the first sample within the loaded (decimated) record; nonzero
      for the validation part of a split.
    - `input_unit`, `output_unit`: physical units, or `None` when not given.
    - `detrend`: `"none"`, `"mean"` or `"linear"`, removed from input and output (as
      MATLAB's `detrend`) before decimation and scaling.
    - `file_start`: index in the file as stored (before decimation) of the loaded
      record's first sample: START of the spec's range, else 0.
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
    input_unit: str | None = None
    output_unit: str | None = None
    detrend: str = "none"
    file_start: int = 0

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
            "file_start": self.file_start,
            "input_unit": self.input_unit,
            "output_unit": self.output_unit,
            "detrend": self.detrend,
            "scaling": self.scaling.to_dict(),
        }


# ---- reading --------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class RecordSpec:
    """A record named in one string, `FILE[:INPUT,OUTPUT[:START:STOP]]` (`parse_record_spec`).

    Fields: `path`; `input`, `output` (names or 0-based column indices as text, `None`
    when the spec names no signals); `start`, `stop` (the range as written, `None` for an
    empty bound or no range); `ranged` (whether a range was written); `text` (as given).
    """

    path: str
    input: str | None = None
    output: str | None = None
    start: int | None = None
    stop: int | None = None
    ranged: bool = False
    text: str = ""


def parse_record_spec(text: str | os.PathLike) -> RecordSpec:
    """Split a record spec `FILE[:INPUT,OUTPUT[:START:STOP]]` into its parts.

    - `FILE`: a CSV/TSV/text, Parquet or MAT file. A path that exists as given is a file
      even when it holds ':'; otherwise FILE is the longest prefix before a ':' that names
      an existing file (or, when none does, the part before `:INPUT,OUTPUT`, so that a
      missing file is reported by its name).
    - `INPUT,OUTPUT`: the signals, by name (a header, a MAT variable) or by 0-based
      column index; they override the `input_column`/`output_column` of `read_record`.
      `FILE::START:STOP` keeps those.
    - `START:STOP`: 0-based samples of the file as stored (before decimation), with
      Python's slice semantics (either may be empty, negative counts from the end):
      `DATAUNIF.MAT:u11,z11::300` is the first 300 samples.

    A `pathlib.Path` is a file, never a spec. Raises `ValueError` for signals that are
    not two names or a range that is not two integers.
    """
    if not isinstance(text, str):
        path = os.fspath(text)
        return RecordSpec(path, text=path)
    if ":" not in text or os.path.exists(text):
        return RecordSpec(text, text=text)
    cuts = [i for i, char in enumerate(text) if char == ":" and os.path.isfile(text[:i])]
    if cuts:
        cut = cuts[-1]
    else:
        match = re.fullmatch(r"(.+?):([^:]*,[^:]*)(?::.*)?", text, flags=re.DOTALL)
        if match is None:
            return RecordSpec(text, text=text)  # reported as a missing file
        cut = match.end(1)
    path, rest = text[:cut], text[cut + 1 :]
    signals, has_range, span = rest.partition(":")
    names = [name.strip() for name in signals.split(",")]
    if signals.strip() == "" and has_range:
        names = [None, None]
    elif len(names) != 2 or not all(names):
        raise ValueError(
            f"The record spec {text!r} names its signals as {signals!r}; give two, "
            f"INPUT,OUTPUT (names or 0-based column indices), as in {path}:u,y:0:1000."
        )
    start = stop = None
    if has_range:
        bounds = span.split(":")
        if len(bounds) != 2 or not all(re.fullmatch(r"\s*(-?\d+)?\s*", b) for b in bounds):
            raise ValueError(
                f"The record spec {text!r} has the range {span!r}; give START:STOP in samples "
                "of the file as stored (integers, either may be empty), e.g. 0:300 or :300."
            )
        start, stop = (int(b) if b.strip() else None for b in bounds)
    return RecordSpec(path, names[0], names[1], start, stop, bool(has_range), text)


def read_record(
    path: str | os.PathLike,
    input_column: str | int | None = None,
    output_column: str | int | None = None,
    *,
    time_column: str | int | None = None,
    format: str | None = None,
    sample_period: float | None = None,
    decimate: int = _defaults.DECIMATE,
    anti_alias: str = "fir",
    scaling: str | Scaling = _defaults.SCALING,
    orders=None,
    detrend: str = _defaults.DETREND,
    input_unit: str | None = None,
    output_unit: str | None = None,
) -> Record:
    """Read one input/output record from a CSV/TSV, Parquet or MAT file, or a record spec.

    Arguments:
    - `path`: a file, `.csv`/`.tsv`/`.txt`/`.dat` (the delimiter, a decimal comma and a
      missing header are detected: a first line of numbers is data, its columns named
      by index), `.parquet`/`.pq`, or `.mat` (MATLAB v4 to v7 through scipy, v7.3 through
      h5py; each signal a variable, a row or a column vector); `format` (`"csv"`,
      `"parquet"`, `"mat"`) overrides the suffix. A string may be a record spec,
      `FILE[:INPUT,OUTPUT[:START:STOP]]` (`parse_record_spec`): its signals override
      `input_column`/`output_column` and its range selects samples of the file as
      stored, before everything else.
    - `input_column`, `output_column`: signals u and y, by name (a column header, a MAT
      variable) or by 0-based column index; needed unless the spec names them.
    - `time_column`: optional column of sample times; it must increase evenly and fixes
      `sample_period` (if both are given they must agree within 1 %).
    - `sample_period`: the time between stored samples, for a file without time column.
    - `detrend`: `"none"`, `"mean"` or `"linear"`, removed from u and y as MATLAB's
      `detrend` does (`scipy.signal.detrend`), after the range and before decimation.
    - `decimate`: keep every `decimate`-th sample after a zero-phase anti-alias low-pass,
      `anti_alias="fir"` (Hamming-window FIR of order 20*decimate, cutoff at the new
      Nyquist frequency, the filter of `scipy.signal.decimate`, applied by
      `resample_poly` with odd-symmetric edge padding so the ends are not pulled to zero)
      or `"iir"` (`scipy.signal.decimate`'s order-8 Chebyshev I run forward and backward,
      in steps of at most 13).
    - `scaling`: `"auto"` (the default for measured data, `_defaults`), `"standard"`,
      `"scale"`, `"none"` (see `Scaling.from_data`, computed after decimation), or a
      `Scaling` to reuse, e.g. the estimation record's for a validation record.
    - `orders`: an `Orders`; the record must hold at least `orders.min_samples` samples.
    - `input_unit`, `output_unit`: physical units, kept on the `Record`.

    Returns a `Record` whose `source` is the file, or the spec with its range resolved.
    Raises `ValueError` for a missing file, an unknown format, missing columns or
    variables (naming those the file holds), a matrix where a signal is expected,
    non-numeric, NaN or infinite values, signals of different lengths, a bad, empty or
    outside range, uneven time, too few samples, a constant input or output, or a MAT
    v7.3 file without h5py.
    """
    spec = parse_record_spec(path)
    path = spec.path
    if not os.path.exists(path):
        raise ValueError(f"Data file {path!r} does not exist; check the path.")
    if not os.path.isfile(path):
        raise ValueError(f"Data path {path!r} is not a file; give a CSV, TSV, Parquet or MAT file.")
    if spec.input is not None:
        input_column, output_column = spec.input, spec.output
    if input_column is None or output_column is None:
        raise ValueError(
            f"No input and output signals named for {spec.text!r}; name them in the record "
            f"spec, {path}:INPUT,OUTPUT, or as the input and output columns (--input and "
            "--output on the command line)."
        )
    if detrend not in _DETRENDS:
        raise ValueError(f"Unknown detrend {detrend!r}; use one of {', '.join(_DETRENDS)}.")
    kind = _format_of(path, format)
    names = [str(input_column), str(output_column)]
    names += [str(time_column)] if time_column is not None else []
    if len(set(names)) != len(names):
        raise ValueError(f"Input, output and time columns must be different, got {names}.")
    resolved, columns = _read_signals(path, kind, names)
    if len(set(resolved)) != len(resolved):
        described = ", ".join(f"{n!r} is {r!r}" for n, r in zip(names, resolved, strict=True))
        raise ValueError(
            f"Input, output and time columns must be different, but in {path!r} {described}."
        )
    _check_equal_lengths(columns, path, "mat" if kind == "mat" else "table")
    first, last = _range(spec, len(next(iter(columns.values()))), path)
    columns = {name: values[first:last] for name, values in columns.items()}
    source = path
    if spec.input is not None or spec.ranged:
        source = f"{path}:{resolved[0]},{resolved[1]}"
        source += f":{first}:{last}" if spec.ranged else ""
    for name, values in columns.items():
        _check_finite(values, name, source, offset=first)
    return _build(
        columns[resolved[0]],
        columns[resolved[1]],
        columns[resolved[2]] if time_column is not None else None,
        source=source,
        input_column=resolved[0],
        output_column=resolved[1],
        time_column=resolved[2] if time_column is not None else None,
        sample_period=sample_period,
        decimate=decimate,
        anti_alias=anti_alias,
        scaling=scaling,
        orders=orders,
        detrend=detrend,
        input_unit=input_unit,
        output_unit=output_unit,
        file_start=first,
    )


def _range(spec: RecordSpec, length: int, path: str) -> tuple[int, int]:
    """The spec's range as `(first, last)` samples of the stored signals, checked."""
    if not spec.ranged:
        return 0, length
    first = 0 if spec.start is None else spec.start + (length if spec.start < 0 else 0)
    last = length if spec.stop is None else spec.stop + (length if spec.stop < 0 else 0)
    written = f"{'' if spec.start is None else spec.start}:{'' if spec.stop is None else spec.stop}"
    if not (0 <= first <= length and 0 <= last <= length):
        raise ValueError(
            f"The range {written} of {spec.text!r} lies outside the record, whose signals in "
            f"{path!r} hold {length} samples (0:{length}); choose samples within it."
        )
    if last <= first:
        raise ValueError(
            f"The range {written} of {spec.text!r} holds no samples; STOP must exceed START."
        )
    return first, last


def check_sample_periods(records) -> None:
    """Refuse records whose sample periods lie more than 1 % apart (records without a
    period, `None`, are not compared): the records of one command share one model, whose
    dynamics are per sample."""
    known = [r for r in records if r.sample_period is not None]
    for record in known[1:]:
        a, b = known[0].sample_period, record.sample_period
        if abs(a - b) > _TIME_RTOL * min(a, b):
            raise ValueError(
                f"The records {known[0].source!r} (sample period {a:g}) and {record.source!r} "
                f"(sample period {b:g}) are sampled differently; the records of one command "
                "must share a sample period, so resample one of them or correct its time "
                "column or sample period."
            )


def in_scaling(record: Record, scaling: Scaling) -> Record:
    """`record` in `scaling`, mapped through its physical units (itself where it is in
    that scaling already)."""
    if record.scaling == scaling:
        return record
    return dataclasses.replace(
        record,
        u=scaling.input_to_model(record.u_physical),
        y=scaling.output_to_model(record.y_physical),
        scaling=scaling,
    )


def joint_scaling(records, method: str = _defaults.SCALING) -> list[Record]:
    """`records` (estimated jointly) in one scaling, `Scaling.from_data` of their
    physical input and output joined end to end by `method`."""
    scaling = Scaling.from_data(
        np.concatenate([r.u_physical for r in records]),
        np.concatenate([r.y_physical for r in records]),
        method,
    )
    return [in_scaling(r, scaling) for r in records]


def read_jointly(
    estimation, validation=(), test=(), *, scaling=_defaults.SCALING, **options
) -> tuple[list[Record], list[Record], list[Record]]:
    """Estimation, validation and test records of one model from record specs
    (`read_record`, `options` its settings), all in the estimation records' joint
    scaling (`joint_scaling`), of one sample period (`check_sample_periods`)."""
    raw = [read_record(spec, **options, scaling="none") for spec in estimation]
    training = joint_scaling(raw, scaling)
    common = training[0].scaling
    validations = [read_record(spec, **options, scaling=common) for spec in validation]
    tests = [read_record(spec, **options, scaling=common) for spec in test]
    check_sample_periods([*training, *validations, *tests])
    return training, validations, tests


def read_column(
    path: str | os.PathLike,
    column: str,
    *,
    format: str | None = None,
    decimate: int = _defaults.DECIMATE,
    anti_alias: str = "fir",
) -> np.ndarray:
    """One numeric column of a CSV/TSV, Parquet or MAT file (a header, a 0-based column
    index or a MAT variable) as float64 (e.g. a measured input to reuse in a simulated
    experiment), decimated as `read_record` does; the same checks (missing file or
    column, non-numeric, NaN or infinite values, a constant column) with the same
    sentences."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"Data file {path!r} does not exist; check the path.")
    if isinstance(decimate, bool) or not isinstance(decimate, int) or decimate < 1:
        raise ValueError(f"decimate must be a positive integer, got {decimate!r}.")
    if anti_alias not in _FILTERS:
        raise ValueError(f"Unknown anti-alias filter {anti_alias!r}; use 'fir' or 'iir'.")
    (column,), columns = _read_signals(path, _format_of(path, format), [str(column)])
    values = columns[column]
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
    decimate: int = _defaults.DECIMATE,
    anti_alias: str = "fir",
    scaling: str | Scaling = _defaults.SCALING,
    orders=None,
    source: str | None = None,
    input_column: str = "u",
    output_column: str = "y",
    detrend: str = _defaults.DETREND,
    input_unit: str | None = None,
    output_unit: str | None = None,
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
        detrend=detrend,
        input_unit=input_unit,
        output_unit=output_unit,
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
        kind = {"tsv": "csv", "txt": "csv", "pq": "parquet"}.get(kind, kind)
        if kind not in ("csv", "parquet", "mat"):
            raise ValueError(f"Unknown data format {format!r}; use 'csv', 'parquet' or 'mat'.")
        return kind
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in _FORMATS:
        raise ValueError(
            f"Unknown data format {suffix or '(no suffix)'!r} for {path!r}; use a .csv, .tsv, "
            ".txt, .parquet or .mat file, or name the format explicitly (format='csv', "
            "'parquet' or 'mat')."
        )
    return _FORMATS[suffix]


def _read_signals(path: str, kind: str, names: list[str]) -> tuple[list[str], dict]:
    """The signals `names` of a file as float64 arrays: the names they resolve to (a
    column index becomes its header) and `{resolved: values}`."""
    if kind == "mat":
        return _mat_signals(path, names)
    frame = _read_frame(path, kind)
    available = [str(c) for c in frame.columns]
    frame.columns = available
    resolved = []
    for name in names:
        if name not in available and re.fullmatch(r"\d+", name) and int(name) < len(available):
            name = available[int(name)]  # a 0-based column index
        resolved.append(name)
    missing = [name for name in resolved if name not in available]
    if missing:
        raise ValueError(
            _not_found(missing, available, path, "Column(s)", "columns")
            + f", or their 0-based indices 0 to {len(available) - 1}."
        )
    return resolved, {name: _numeric_column(frame[name], name, path) for name in resolved}


def _not_found(missing: list[str], available: list[str], path: str, what: str, noun: str) -> str:
    lower = {c.lower(): c for c in available}
    hints = {
        name: [lower[m] for m in difflib.get_close_matches(name.lower(), list(lower), 1, 0.6)]
        for name in missing
    }
    hint = "".join(f" (did you mean {hints[m][0]!r} for {m!r}?)" for m in missing if hints[m])
    return (
        f"{what} {', '.join(map(repr, missing))} not found in {path!r}; available {noun} are "
        f"{', '.join(map(repr, available)) or 'none'}{hint}"
    )


def _read_frame(path: str, kind: str) -> pd.DataFrame:
    if kind == "csv":
        sep, decimal, header = _sniff_csv(path)
        options = dict(sep=r"\s+" if sep is None else sep, decimal=decimal)
        options["header"] = 0 if header else None
    else:
        header, sep, options = True, ",", {}
    if header:
        _check_unique_header(path, kind, sep)
    try:
        if kind == "csv":
            frame = pd.read_csv(path, **options)
            if not header:
                frame.columns = [str(i) for i in range(frame.shape[1])]
            return frame
        return pd.read_parquet(path)
    except Exception as error:  # pandas/pyarrow raise many types; keep one line
        raise _unreadable(path, kind, error) from error


def _unreadable(path: str, kind: str, error: Exception) -> ValueError:
    first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
    return ValueError(
        f"Could not read {path!r} as {kind.upper()} ({first}); check the file and its format."
    )


def _sniff_csv(path: str) -> tuple[str | None, str, bool]:
    """Delimiter (`None`: whitespace), decimal mark and whether the first line is a header,
    from the file's first lines. The delimiter is the first of `_DELIMITERS` that splits
    the first line in two or more fields and nine lines in ten the same way (a tab or a
    semicolon wins over a decimal comma); the decimal mark is a comma when the delimiter
    is not and numbers are written `1,5`; a first line of numbers only is data."""
    try:
        with open(path, newline="", encoding="utf-8-sig", errors="replace") as file:
            sample = file.read(1 << 16)
            cut = bool(file.read(1))
    except OSError:
        return ",", ".", True  # pandas reports the problem in its own words
    lines = sample.splitlines()[:-1] if cut else sample.splitlines()
    lines = [line for line in lines if line.strip()][:100]
    if not lines:
        return ",", ".", True
    sep, rows = ",", None
    for candidate in _DELIMITERS:
        split = [_fields(line, candidate) for line in lines]
        width = len(split[0])
        if width > 1 and sum(len(row) == width for row in split) >= 0.9 * len(split):
            sep, rows = candidate, split
            break
    if rows is None:
        return ",", ".", True
    fields = [field.strip() for row in rows for field in row]
    decimal = "."
    number = r"[+-]?(\d+{0}\d*|{0}\d+)([eE][+-]?\d+)?"
    if sep != ",":
        comma = any(re.fullmatch(number.format(","), field) for field in fields)
        point = any(re.fullmatch(number.format(r"\."), field) for field in fields)
        decimal = "," if comma and not point else "."
    header = not all(_is_number(field.replace(decimal, ".")) for field in rows[0])
    return sep, decimal, header


def _fields(line: str, sep: str | None) -> list[str]:
    if sep is None:
        return line.split()
    return next(csv.reader([line], delimiter=sep), [])


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _check_unique_header(path: str, kind: str, sep: str | None = ",") -> None:
    # pandas renames a repeated CSV column ('y', 'y' -> 'y', 'y.1') and reads on: the
    # header is read here first, so the user learns which column is meant twice.
    try:
        if kind == "csv":
            with open(path, newline="", encoding="utf-8-sig", errors="replace") as file:
                names = _fields(file.readline().rstrip("\r\n"), sep)
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


def _mat_signals(path: str, names: list[str]) -> tuple[list[str], dict]:
    """Variables `names` of a MAT file as float64 vectors (a 1 x N row or an N x 1
    column), `(names, {name: values})`; v4 to v7 through scipy, v7.3 (HDF5) through h5py."""
    if _is_hdf5(path):
        return names, _hdf5_mat_signals(path, names)
    import scipy.io

    try:
        listing = {name: (shape, kind) for name, shape, kind in scipy.io.whosmat(path)}
    except Exception as error:  # scipy raises ValueError, IndexError, ... on a bad file
        raise _unreadable(path, "mat", error) from error
    _check_variables(names, list(listing), path)
    for name in names:
        shape, kind = listing[name]
        if kind not in _MAT_NUMERIC:
            raise ValueError(
                f"Variable {name!r} in {path!r} is a MATLAB {kind}, not numbers; name a "
                "numeric signal."
            )
        _check_vector_shape(shape, name, path)
    try:
        data = scipy.io.loadmat(path, variable_names=names)
    except Exception as error:
        raise _unreadable(path, "mat", error) from error
    return names, {name: _mat_vector(data[name], name, path) for name in names}


def _is_hdf5(path: str) -> bool:
    # HDF5's signature sits at 0 or a power-of-two offset from 512; MATLAB's v7.3 files
    # put it at 512, after their 128-byte text header.
    with open(path, "rb") as file:
        head = file.read(2056)
    return any(head[at : at + 8] == b"\x89HDF\r\n\x1a\n" for at in (0, 512, 1024, 2048))


def _hdf5_mat_signals(path: str, names: list[str]) -> dict:
    try:
        import h5py
    except ImportError:
        raise ValueError(
            f"{path!r} is a MATLAB v7.3 (HDF5) file, which needs the h5py package; install "
            "it (pip install h5py) or save the file with MATLAB's save -v7."
        ) from None
    try:
        with h5py.File(path, "r") as file:
            available = [key for key in file if not key.startswith("#")]
            _check_variables(names, available, path)
            out = {}
            for name in names:
                item = file[name]
                kind = item.attrs.get("MATLAB_class", b"double")
                kind = kind.decode() if isinstance(kind, bytes) else str(kind)
                if not isinstance(item, h5py.Dataset) or kind not in _MAT_NUMERIC:
                    what = kind if isinstance(item, h5py.Dataset) else "struct or cell"
                    raise ValueError(
                        f"Variable {name!r} in {path!r} is a MATLAB {what}, not numbers; name "
                        "a numeric signal."
                    )
                if item.attrs.get("MATLAB_empty", 0):
                    out[name] = np.zeros(0)  # an empty array stores its dimensions
                    continue
                # MATLAB writes column-major: an N x 1 column reads as 1 x N, and back
                _check_vector_shape(item.shape[::-1], name, path)
                out[name] = _mat_vector(item[()], name, path)
    except ValueError:
        raise
    except Exception as error:  # h5py raises OSError, KeyError, ... on a bad file
        raise _unreadable(path, "mat", error) from error
    return out


def _check_variables(names: list[str], available: list[str], path: str) -> None:
    missing = [name for name in names if name not in available]
    if missing:
        raise ValueError(_not_found(missing, available, path, "Variable(s)", "variables") + ".")


def _check_vector_shape(shape, name: str, path: str) -> None:
    if sum(size != 1 for size in shape) > 1:
        raise ValueError(
            f"Variable {name!r} in {path!r} is a {' x '.join(map(str, shape))} matrix, not one "
            "signal; name a variable that holds one signal, a row or a column vector."
        )


def _mat_vector(value, name: str, path: str) -> np.ndarray:
    value = np.asarray(value)
    numeric = np.issubdtype(value.dtype, np.number) or value.dtype == np.bool_
    if not numeric or np.iscomplexobj(value):
        raise ValueError(
            f"Variable {name!r} in {path!r} holds {value.dtype} values, not real numbers; "
            "name a real numeric signal."
        )
    _check_vector_shape(value.shape, name, path)
    return value.reshape(-1).astype(np.float64)


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


def _check_equal_lengths(
    columns: Mapping[str, np.ndarray], where: str, kind: str = "table"
) -> None:
    # A CSV column that ends early reads as trailing NaN: report it as a length mismatch.
    lengths = {}
    for name, values in columns.items():
        valid = np.flatnonzero(~np.isnan(values))
        last = int(valid[-1]) + 1 if valid.size else 0
        ragged = kind == "table" and not np.isnan(values[:last]).any()
        lengths[name] = last if ragged else len(values)
    if len(set(lengths.values())) > 1:
        described = ", ".join(f"{name!r} has {n}" for name, n in lengths.items())
        fix = (
            "trim the file so every column has the same number of rows"
            if kind == "table"
            else "name the signals of one record, which share their length"
        )
        what = "Columns" if kind == "table" else "Variables"
        raise ValueError(f"{what} of {where!r} have different lengths ({described} values); {fix}.")


def _check_finite(values: np.ndarray, name: str, where: str, offset: int = 0) -> None:
    # `offset`: the row of the file as stored of `values[0]`, so the row named is the file's
    bad = ~np.isfinite(values)
    if bad.any():
        first = int(np.flatnonzero(bad)[0]) + offset
        raise ValueError(
            f"{name!r} in {where!r} has {int(bad.sum())} NaN or infinite values, the first at "
            f"row {first} (counting data rows from 0); remove or fill them before loading."
        )
    huge = np.abs(values) > MAX_MAGNITUDE
    if huge.any():
        first = int(np.flatnonzero(huge)[0]) + offset
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
            f"Sample period {given:g} disagrees with the time column's step {period:g} in "
            f"{where!r} by more than 1 %; give one or the other."
        )
    return period


def _decimate(values: np.ndarray, factor: int, anti_alias: str) -> np.ndarray:
    import scipy.signal  # here, not at the top: it takes a second to import

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
    detrend: str = _defaults.DETREND,
    input_unit: str | None = None,
    output_unit: str | None = None,
    file_start: int = 0,
) -> Record:
    where = source or "the arrays"
    if detrend not in _DETRENDS:
        raise ValueError(f"Unknown detrend {detrend!r}; use one of {', '.join(_DETRENDS)}.")
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
    if detrend != "none":
        # MATLAB's detrend: 'constant' removes the mean, 'linear' the least-squares line
        import scipy.signal

        kind = "constant" if detrend == "mean" else "linear"
        u, y = scipy.signal.detrend(u, type=kind), scipy.signal.detrend(y, type=kind)
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
        input_unit=input_unit,
        output_unit=output_unit,
        detrend=detrend,
        file_start=file_start,
    )
