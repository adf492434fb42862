"""Scoring a model on a measured record: from rest, and with its state set from the
measured output before the scored samples.

The convention of the nonlinear system-identification benchmarks (the
`nonlinear_benchmarks` package's `state_initialization_window_length`) and of MATLAB's
`compare`: a model may use a scored record's input throughout and its measured output on
the `n` samples before the scored ones to set its state, never its parameters. Scored
samples:

- the full record: `[n, T)`, the state set on `[0, n)`;
- a window `[start, stop)`: the state set on `[start - n, start)` (`start < n`: on
  `[0, start)`).

Beside every initialised figure the from-rest one (the whole record simulated from rest,
scored on `[0, T)` and on the window). NRMSE is `_metrics.score` (standard-deviation
normalised: 1 is the mean of the output). A model is *worse than a trivial one* on a
record when its NRMSE there exceeds 1 (the mean) or the linear ARX peer's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from .._metrics import score

# `initialised(u, y, start, n) -> simulated output on [start, T)`, the state set from `y`
# on `[start - n, start)`; `from_rest(u) -> simulated output on [0, T)`.
Initialised = Callable[[np.ndarray, np.ndarray, int, int], np.ndarray]
FromRest = Callable[[np.ndarray], np.ndarray]


@dataclasses.dataclass(frozen=True)
class RecordScore:
    """One model on one scored record (module docstring). `window_error*` are None
    without a window."""

    model: str
    record: str
    role: str  # "validation" or "test"
    error: float
    window_error: float | None
    error_from_rest: float
    window_error_from_rest: float | None
    init_samples: int
    # root-mean-square error of the initialised simulation on `[n, T)`, in the record's
    # units (the benchmarks' figure; model units where the record is scaled)
    rmse: float = float("nan")

    @property
    def headline(self) -> float:
        """The figure a reader compares: the initialised window NRMSE, else the full."""
        return self.error if self.window_error is None else self.window_error

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def score_record(
    model: str,
    record: str,
    role: str,
    u,
    y,
    from_rest: FromRest,
    initialised: Initialised,
    window: tuple[int, int] | None,
    n: int,
) -> RecordScore:
    """Score one model on one record (module docstring)."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    T = y.shape[0]
    n = int(min(max(n, 0), T - 2))
    rest = np.asarray(from_rest(u), float)
    full = np.asarray(initialised(u, y, n, n), float)
    window_error = window_rest = None
    if window is not None:
        start, stop = window
        simulated = np.asarray(initialised(u, y, start, min(n, start)), float)
        window_error = score(y[start:stop], simulated[: stop - start])
        window_rest = score(y[start:stop], rest[start:stop])
    return RecordScore(
        model,
        record,
        role,
        score(y[n:], full),
        window_error,
        score(y, rest),
        window_rest,
        n,
        _rmse(y[n:], full),
    )


def _rmse(y, simulated) -> float:
    with np.errstate(over="ignore", invalid="ignore"):
        value = float(np.sqrt(np.mean((y - simulated) ** 2)))
    return value if np.isfinite(value) else float("inf")


def verdict(
    final: list[RecordScore],
    arx: list[RecordScore],
    uncovered: frozenset = frozenset(),
    advice=(),
) -> list[str]:
    """One sentence per scored record on which the final model is worse than the mean
    (NRMSE 1) or than the ARX peer, with what the user can try; empty when it is better
    than both everywhere. `uncovered`: the `(record, role)` pairs whose input the
    estimation records do not cover (`_coverage.sentences` flags them): there the miss
    may be the records', not the structure's, and the sentence says so. `advice`: what
    the records and the residual show (`_advice.advise`), said in place of the generic
    options where there is any."""
    peers = {(s.record, s.role): s for s in arx}
    sentences = []
    for s in final:
        peer = peers.get((s.record, s.role))
        worse = []
        if s.headline > 1.0:
            worse.append("the mean of the output (NRMSE 1)")
        if peer is not None and s.headline > peer.headline:
            worse.append(f"the linear ARX peer ({peer.headline:.3f})")
        if not worse:
            continue
        where = "window" if s.window_error is not None else "record"
        head = (
            f"The final model is worse than {' and '.join(worse)} on the {s.role} "
            f"{where} {s.record} (NRMSE {s.headline:.3f})"
        )
        if advice:
            sentences.append(f"{head}. " + " ".join(f"{a.sentence}." for a in advice))
            continue
        cause = (
            "its structure does not describe this system, or the records do not cover "
            "the input where it was scored (the report's input coverage)"
            if (s.record, s.role) in uncovered
            else "its structure does not describe this system"
        )
        sentences.append(
            f"{head}: {cause}; try the hysteresis effects (--effects), other --orders, more "
            "varied estimation records, or another --decimate."
        )
    return sentences


def mean_score(scores: list[RecordScore]) -> RecordScore:
    """One model's validation figures: its one record's score, or the mean over several
    (a window applies to one record only; RMSE the root of the mean square)."""
    if len(scores) == 1:
        return scores[0]
    first = scores[0]
    return RecordScore(
        first.model,
        "mean over the validation records",
        "validation",
        float(np.mean([s.error for s in scores])),
        None,
        float(np.mean([s.error_from_rest for s in scores])),
        None,
        first.init_samples,
        float(np.sqrt(np.mean([s.rmse**2 for s in scores]))),
    )


def stored_window(
    window: tuple[int, int] | None, record, name: str = "window"
) -> tuple[int, int] | None:
    """A scoring window `(start, stop)` in samples of the file as stored (before
    decimation; a ranged record spec's `Record.file_start` counts from the file's first
    sample) as samples of the decimated `record`, or None; a `ValueError` naming `name`
    (the option that gave it) where it leaves the record or holds fewer than 2 samples
    after decimation."""
    if window is None:
        return None
    decimate, length, offset = record.decimation, len(record), record.file_start
    start, stop = (int(w) - offset for w in window)
    first, last = start // decimate, -(-stop // decimate)
    text = f"{int(window[0])}:{int(window[1])}"
    if not 0 <= start < stop or last > length:
        raise ValueError(
            f"{name} {text}: needs START < STOP within the scored record (file samples "
            f"{offset} to {offset + length * decimate} as stored)."
        )
    if last - first < 2:
        raise ValueError(f"{name} {text}: fewer than 2 samples after decimation by {decimate}.")
    return first, last
