"""Per-realisation status codes: a batched fit never raises, it reports."""

from __future__ import annotations

import enum

import numpy as np


class Status(enum.IntEnum):
    """Outcome of one fit, carried as an int32 array through `vmap` and into result tables.

    - `converged`: the change in the estimate fell below the tolerance.
    - `max_iterations`: the iteration budget ran out before convergence.
    - `diverged`: the estimate became non-finite or grew without bound.
    - `singular`: the normal equations were (numerically) singular, e.g. a regime or a
      segment never visited, so some parameters are not identifiable from this record.
    - `left_domain`: an estimate left the model's domain (breakpoints unsorted or outside
      the input range, `mR <= 0`, unstable linear block); the iteration stops there.
    - `failed`: a numerical solver (e.g. output-error refinement) reported failure.
    """

    converged = 0
    max_iterations = 1
    diverged = 2
    singular = 3
    left_domain = 4
    failed = 5


def status_names(codes) -> np.ndarray:
    """Map an array of status codes to their names (host side, for tables)."""
    codes = np.asarray(codes)
    lookup = np.array([s.name for s in Status] + ["unknown"], dtype=object)
    index = np.where((codes >= 0) & (codes < len(Status)), codes, len(Status))
    return lookup[index]
