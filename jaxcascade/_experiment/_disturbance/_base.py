"""The interface of an output disturbance: a unit-variance noise process drawn from a key.

A `Disturbance` is an `eqx.Module` whose fields are its settings (static: they fix what
is compiled), so a spec file's `[noise]` table is `Disturbance(**table)`. Calling it
draws `n` samples of a zero-mean process whose variance is 1 (the process's own
stationary variance, not a sample variance), traceable and `vmap`-able over keys;
`_simulate.add_noise` scales it by `std(y) / snr`, so the paper's SNR stays
`sqrt(var(y) / var(e))` of the noise as added, whatever its colour or tails.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import Any, ClassVar

import equinox as eqx
from jaxtyping import Array, Float, PRNGKeyArray


class Disturbance(eqx.Module):
    """Zero-mean, unit-variance output noise (subclasses: `name`, `summary`, `__call__`).

    Settings are checked once, at construction (`__check_init__`), with one sentence.
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""

    @abc.abstractmethod
    def __call__(self, key: PRNGKeyArray, n: int, dtype=None) -> Float[Array, " n"]:
        """`n` samples of the process (stationary from the first sample)."""

    def settings(self) -> dict[str, Any]:
        """The settings as plain values (tuples as lists), for tables and provenance."""

        def plain(value):
            return [plain(v) for v in value] if isinstance(value, tuple) else value

        return {
            f.name: plain(getattr(self, f.name))
            for f in dataclasses.fields(self)
            if f.metadata.get("static", False)
        }


def setting(default):
    """A field of a `Disturbance`: static (part of what is compiled), with a default."""
    return eqx.field(static=True, default=default)


def number(value, what: str, *, low=None, high=None, low_open=False, high_open=False) -> float:
    """`value` as a float inside the stated bounds; a `ValueError` naming `what` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{what} must be a number, got {value!r}.")
    value = float(value)
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and (value >= high if high_open else value > high)
    if too_low or too_high or value != value:
        left = "(" if low_open else "["
        right = ")" if high_open else "]"
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        span = f"{left}{lo}, {hi}{right}"
        raise ValueError(f"{what} must lie in {span}, got {value!r}.")
    return value
