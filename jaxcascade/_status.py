"""Per-realisation status codes: a batched fit never raises, it reports."""

from __future__ import annotations

import enum

import numpy as np


class Status(enum.IntEnum):
    """Outcome of one fit, carried as an int32 array through `vmap` and into result tables.
    `Status.X.message` says what it means in a sentence; `failure` whether the estimate
    should not be used.

    - `converged`, `cycled`: the estimate can be used (not a `failure`).
    - `max_iterations`, `diverged`, `singular`, `left_domain`, `failed`: the algorithm
      stopped without a usable estimate (see each `message`).
    - `no_improvement`: a fit that ended where it started, or whose simulation explains
      less than the output's mean does (robust).
    - `tracking`: an on-line estimate (recursive) that had not settled at the noise level
      when the record ended; it follows the data but is not yet an estimate of a fixed
      system, so it counts as a failure.
    - `local_minimum`, `on_edge`: an output-error fit (robust, pem, a host function)
      that settled where the data do not say it is their estimate: its residual is not
      measurement noise, or a breakpoint sits on the edge of the input's range
      (`_estimator._basin.claim`). Failures. (Codes never change: a new status gets the
      next number.)
    """

    converged = 0
    max_iterations = 1
    diverged = 2
    singular = 3
    left_domain = 4
    failed = 5
    cycled = 6
    no_improvement = 7
    tracking = 8
    local_minimum = 9
    on_edge = 10

    @property
    def message(self) -> str:
        return _MESSAGES[self]

    @property
    def failure(self) -> bool:
        return self not in (Status.converged, Status.cycled)


_MESSAGES = {
    Status.converged: (
        "the estimate stopped changing (within its tolerance; an on-line estimate, also "
        "with its prediction error at the noise level it estimates)"
    ),
    Status.max_iterations: "the iteration budget ran out before the estimate settled",
    Status.diverged: "the estimate became non-finite or grew without bound",
    Status.singular: (
        "the normal equations were singular: a regime or segment the record never visits "
        "leaves some parameters unidentifiable"
    ),
    Status.left_domain: (
        "the estimate is outside the model's domain (breakpoints unsorted or outside the "
        "input range, mR <= 0, or an unstable linear block)"
    ),
    Status.failed: "a numerical solver reported failure",
    Status.no_improvement: (
        "the fit explains none of the output: its simulation error is not below the "
        "output's variance (NRMSE >= 1), or the estimate never moved from a start that "
        "was no estimate itself"
    ),
    Status.tracking: (
        "the on-line estimate had not settled when the record ended: over its last "
        "window it still moved by more than its standard errors allow, or its prediction "
        "error stayed above the noise level it estimates (0 where the output rests "
        "exactly, as noise-free) or above a fifth of the output's spread"
    ),
    Status.local_minimum: (
        "the fit settled, but its simulation error (whitened by an AR model) is not "
        "measurement noise: correlated with itself, with the input or with products of "
        "the two (Billings and Voon's tests), after every start and retry; a local "
        "minimum of the cost or a record the model cannot describe"
    ),
    Status.on_edge: (
        "the fit settled with a breakpoint on the edge of the input's range (within 1 % "
        "of its half-range from 0 or from the end): the segment beyond holds almost no "
        "samples, so the data do not determine its slope"
    ),
    Status.cycled: (
        "the paper's iteration settled into a short cycle between neighbouring estimates "
        "(its amplitude is reported); not a failure"
    ),
}


def status_names(codes) -> np.ndarray:
    """Map an array of status codes to their names (host side, for tables)."""
    codes = np.asarray(codes)
    lookup = np.array([s.name for s in Status] + ["unknown"], dtype=object)
    index = np.where((codes >= 0) & (codes < len(Status)), codes, len(Status))
    return lookup[index]
