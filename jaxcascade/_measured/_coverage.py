"""Input coverage: how much of the estimation records' input range each scored record
covers, and how often it leaves it.

A model fitted on inputs in `[a, b]` (the estimation records' smallest and largest input)
is determined there only. Outside it, the static curve goes on along its outermost
segments and an operator beyond the states it was fitted in: a test record that leaves
`[a, b]` measures how the model extrapolates as much as how it fits. And a validation
record that spans a small part of `[a, b]` cannot tell apart candidates that differ
elsewhere, although the loop chooses by it. Neither is a fault of the model's
structure, which is what the loop's verdict against the ARX peer otherwise suggests.

`coverage` gives one row per record (estimation, validation, test), in the records' own
units: the input's range, the output's standard deviation, `outside` (the share of the
record's samples whose input lies outside `[a, b]`), `beyond` (how far the farthest of
them lies outside, as a share of `b - a`) and `span` (the share of `[a, b]` that the
record's input range overlaps). `sentences` says, for the report, where a
validation or test record leaves `[a, b]` on more than `OUTSIDE` of its samples and
where a validation record spans less than `SPAN` of it. Both limits are rules of thumb,
stated here and in the report, not fitted to any record.
"""

from __future__ import annotations

import dataclasses

import numpy as np

# a scored record leaves the estimation range on more than this share of its samples
OUTSIDE = 0.01
# a validation record spans less than this share of the estimation range
SPAN = 0.5


@dataclasses.dataclass(frozen=True)
class Coverage:
    """One record's input coverage (module docstring), in the records' units."""

    record: str
    role: str
    samples: int
    u_min: float
    u_max: float
    y_std: float
    outside: float
    beyond: float
    span: float

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def coverage(estimation, scored, u_map=None, y_scale: float = 1.0) -> list[Coverage]:
    """Rows for the estimation records `[(name, u, y), ...]` and the scored ones
    `[(name, role, u, y), ...]` (1-D arrays); `u_map` takes an input to the records'
    units (default: as given), `y_scale` the output's scale (a standard deviation is
    only scaled)."""
    to_units = (lambda u: np.asarray(u, float)) if u_map is None else u_map
    records = [(name, "estimation", u, y) for name, u, y in estimation] + list(scored)
    records = [(name, role, to_units(u), np.asarray(y, float)) for name, role, u, y in records]
    fitted = [u for _, role, u, _ in records if role == "estimation"]
    low, high = min(float(np.min(u)) for u in fitted), max(float(np.max(u)) for u in fitted)
    width = high - low
    rows = []
    for name, role, u, y in records:
        u_min, u_max = float(np.min(u)), float(np.max(u))
        overlap = max(0.0, min(u_max, high) - max(u_min, low))
        excess = max(0.0, low - u_min, u_max - high)
        rows.append(
            Coverage(
                record=name,
                role=role,
                samples=int(u.shape[0]),
                u_min=u_min,
                u_max=u_max,
                y_std=float(np.std(y)) * y_scale,
                outside=float(np.mean((u < low) | (u > high))),
                beyond=excess / width if width > 0 else float(excess > 0),
                span=overlap / width if width > 0 else 1.0,
            )
        )
    return rows


def _leaves(r: Coverage) -> bool:
    """Whether a scored record leaves the estimation range on more than `OUTSIDE`."""
    return r.role != "estimation" and r.outside > OUTSIDE


def _narrow(r: Coverage) -> bool:
    """Whether a validation record spans less than `SPAN` of the estimation range."""
    return r.role == "validation" and r.span < SPAN


def uncovered(rows: list[Coverage]) -> frozenset:
    """The `(record, role)` pairs that `sentences` flags."""
    return frozenset((r.record, r.role) for r in rows if _leaves(r) or _narrow(r))


def sentences(rows: list[Coverage]) -> list[str]:
    """What the report says of `rows` (module docstring): one sentence per validation or
    test record that leaves the estimation range on more than `OUTSIDE` of its samples,
    and per validation record that spans less than `SPAN` of it."""
    estimation = [r for r in rows if r.role == "estimation"]
    low, high = min(r.u_min for r in estimation), max(r.u_max for r in estimation)
    y_std = float(np.mean([r.y_std for r in estimation]))
    out = []
    for r in rows:
        if r.role == "estimation":
            continue
        if _leaves(r):
            out.append(
                f"{100 * r.outside:.1f} % of the {r.role} record {r.record}'s samples have an "
                f"input outside the estimation records' range [{low:.4g}, {high:.4g}] (its "
                f"input: {r.u_min:.4g} to {r.u_max:.4g}, at most {100 * r.beyond:.0f} % of "
                "the range's width beyond it): the model is extrapolated there, and its "
                "figure on that record says how it extrapolates as much as how it fits."
            )
        if _narrow(r):
            out.append(
                f"The validation record {r.record} spans {100 * r.span:.0f} % of the "
                f"estimation records' input range (its input: {r.u_min:.4g} to "
                f"{r.u_max:.4g}; its output's standard deviation {r.y_std:.3g} against "
                f"{y_std:.3g}): the loop chose among candidates that may differ most where "
                "it does not go; a validation record that covers the range tells them apart."
            )
    return out
