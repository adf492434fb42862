"""A measured input: one column of the user's CSV or Parquet record, reused.

The column is read once (`_data.read_column`, decimated if asked), centred on its mean
and scaled as a whole, to a peak `amplitude` of |u| or an `rms` (default the paper's
input power), so that segments keep the record's own variations of level
(`normalise = "record"`); with `normalise = "segment"` every segment is centred and
scaled on its own instead, so every realisation has exactly the stated power. Each
realisation takes a random segment of `n` samples (`segment = "random"`, start uniform
over the record), or the whole record (`segment = "whole"`, `n` must be its length:
every realisation then has the same input and differs only in its noise). The samples
enter compiled code as an argument (a field of the design that is an array), never as
a constant, and the SHA-256 of the column is part of each cell's identity: a changed
file gives other records, and a resumed run notices.
"""

from __future__ import annotations

import functools
import hashlib
import os
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ..._data import read_column
from ._base import DEFAULT_RMS, InputDesign, one_scale, setting

SEGMENTS = ("random", "whole")
# the scale holds for the whole record, or for every segment (centred and scaled alone)
NORMALISE = ("record", "segment")


@functools.lru_cache(maxsize=8)
def _load(path: str, stamp: tuple, column: str, decimate: int) -> tuple[np.ndarray, str]:
    del stamp  # part of the cache key only: a rewritten file is read again
    values = read_column(path, column, decimate=decimate)
    return values, hashlib.sha256(values.tobytes()).hexdigest()


def load(path: str, column: str, decimate: int = 1) -> tuple[np.ndarray, str]:
    """`(values, sha256)` of a column (float64, read once per file version)."""
    path = os.path.abspath(os.fspath(path))
    if not os.path.isfile(path):
        raise ValueError(f"Input file {path!r} does not exist; check [input] path.")
    stat = os.stat(path)
    return _load(path, (stat.st_mtime_ns, stat.st_size), column, decimate)


class File(InputDesign):
    """Segments of one column of a CSV/Parquet file (`path`, `column`), centred and
    scaled as a whole; `decimate` as in `read_record`."""

    name: ClassVar[str] = "file"
    summary: ClassVar[str] = "random segments of a column of a CSV/Parquet record"

    path: str = setting("")
    column: str = setting("")
    segment: str = setting("random")
    decimate: int = setting(1)
    amplitude: float | None = setting(None)
    rms: float | None = setting(None)
    normalise: str = setting("record")
    sha256: str = setting("")
    record: np.ndarray = None  # the scaled samples: a leaf, passed to compiled code

    def __init__(
        self,
        path="",
        column="",
        segment="random",
        decimate=1,
        amplitude=None,
        rms=None,
        normalise="record",
    ):
        if not isinstance(path, str) or not path or not isinstance(column, str) or not column:
            raise ValueError('Input file needs path = "FILE.csv" and column = "NAME".')
        if segment not in SEGMENTS:
            raise ValueError(
                f"Input file: segment must be one of {', '.join(SEGMENTS)}, got {segment!r}."
            )
        if isinstance(decimate, bool) or not isinstance(decimate, int) or decimate < 1:
            raise ValueError(f"Input file: decimate must be a positive integer, got {decimate!r}.")
        one_scale("Input file", amplitude, rms)
        if normalise not in NORMALISE:
            raise ValueError(
                f"Input file: normalise must be one of {', '.join(NORMALISE)}, got {normalise!r}."
            )
        values, digest = load(path, column, decimate)
        centred = values - np.mean(values)
        if amplitude is not None:
            gain = float(amplitude) / np.max(np.abs(centred))
        else:
            gain = (float(rms) if rms is not None else DEFAULT_RMS) / np.sqrt(np.mean(centred**2))
        self.path = path
        self.column = column
        self.segment = segment
        self.decimate = decimate
        self.amplitude = None if amplitude is None else float(amplitude)
        self.rms = None if rms is None else float(rms)
        self.normalise = normalise
        self.sha256 = digest
        self.record = gain * centred

    @property
    def length(self) -> int:
        return int(np.shape(self.record)[0])

    @property
    def bound(self) -> float:
        if self.amplitude is not None:
            return self.amplitude
        return (self.rms if self.rms is not None else DEFAULT_RMS) * np.sqrt(3.0)

    def check(self, n):
        if self.segment == "whole" and n != self.length:
            raise ValueError(
                f'Input file: segment = "whole" uses the whole record of {self.length} '
                f"samples, so N must be {self.length}, got {n}."
            )
        if n > self.length:
            raise ValueError(
                f"Input file: N = {n} is longer than the record ({self.length} samples "
                f"after decimate = {self.decimate}); use a smaller N or decimate."
            )

    def __call__(self, key, n, dtype=None):
        dtype = dtype or jnp.result_type(float)
        record = jnp.asarray(self.record, dtype)
        if self.segment == "whole":
            u = record[:n]
        else:
            start = jax.random.randint(key, (), 0, self.length - n + 1)
            u = jax.lax.dynamic_slice_in_dim(record, start, n)
        if self.normalise == "record":
            return u
        u = u - jnp.mean(u)
        if self.amplitude is not None:
            return self.amplitude * u / jnp.max(jnp.abs(u))
        return (self.rms if self.rms is not None else DEFAULT_RMS) * u / jnp.sqrt(jnp.mean(u**2))

    def span(self, n):
        if self.normalise == "segment":  # a segment's own scale: its extremes vary
            return -self.bound, self.bound
        # a segment never leaves the whole record's range
        record = np.asarray(self.record)
        return float(np.min(record)), float(np.max(record))

    def settings(self):
        scale = (
            {"amplitude": self.amplitude}
            if self.amplitude is not None
            else {"rms": self.rms if self.rms is not None else DEFAULT_RMS}
        )
        return {
            "path": self.path,
            "column": self.column,
            "segment": self.segment,
            "decimate": self.decimate,
            "normalise": self.normalise,
            **scale,
        }

    def identity(self):
        # the file's contents, not its name, fix the records
        return {**{k: v for k, v in self.settings().items() if k != "path"}, "sha256": self.sha256}
