"""The interface of an input design: how one realisation's input record is drawn.

An `InputDesign` is an `eqx.Module` whose settings are static fields, so a spec file's
`[input]` table is `Design(**table)`. Calling it draws one record of `n` samples from a
key, traceable and `vmap`-able over keys. Every design is scaled to a stated size:
`amplitude` (a bound on |u|, where the kind has one) or `rms` (the root of the input's
power); with neither, the power of the paper's input, uniform in (-2, 2)
(`DEFAULT_RMS = 2 / sqrt(3)`), so that designs compare at equal power by default.

Besides the record, a design says which range the estimators get (`input_range`: the
designed bounds where there are some, else the record's own), which interval the input
covers (`span`: a true breakpoint outside it cannot be identified, and the spec warns),
and the amplitude of the uniform input of the same scale (`bound`), which the random
family's prior draws breakpoints inside.
"""

from __future__ import annotations

import abc
import dataclasses
import math
import statistics
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

# The power of the paper's input (uniform in (-2, 2)), as its root mean square.
DEFAULT_RMS = 2.0 / math.sqrt(3.0)


class InputDesign(eqx.Module):
    """One kind of input record (subclasses: `name`, `summary`, `__call__`, `bound`)."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""

    @abc.abstractmethod
    def __call__(self, key: PRNGKeyArray, n: int, dtype=None) -> Float[Array, " n"]:
        """One input record of `n` samples."""

    @property
    @abc.abstractmethod
    def bound(self) -> float:
        """The amplitude of the design, or of the uniform input of the same power."""

    def input_range(self, u: Float[Array, " n"]) -> tuple:
        """`(u_min, u_max)` handed to the estimators: by default the record's own range."""
        return jnp.min(u), jnp.max(u)

    def span(self, n: int) -> tuple[float, float]:
        """The interval a record of `n` samples covers (host floats)."""
        return -self.bound, self.bound

    def check(self, n: int) -> None:
        """A `ValueError` (one sentence) when the design cannot draw `n` samples."""

    def settings(self) -> dict[str, Any]:
        """The settings as plain values (scale resolved, tuples as lists, no `None`)."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not f.metadata.get("static", False) or value is None:
                continue
            out[f.name] = list(value) if isinstance(value, tuple) else value
        return out

    def identity(self) -> dict[str, Any]:
        """What a record depends on (the settings; a file's contents too)."""
        return self.settings()


def setting(default):
    """A field of an `InputDesign`: static (part of what is compiled), with a default."""
    return eqx.field(static=True, default=default)


def positive(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value < math.inf:
        raise ValueError(f"{what} must be a positive, finite number, got {value!r}.")
    return float(value)


def one_scale(where: str, amplitude, rms) -> None:
    if amplitude is not None and rms is not None:
        raise ValueError(f"{where}: give the scale as amplitude or rms, not both.")
    if amplitude is not None:
        positive(amplitude, f"{where}: amplitude")
    if rms is not None:
        positive(rms, f"{where}: rms")


def gaussian_reach(n: int) -> float:
    """How many standard deviations a Gaussian record of `n` samples reaches: the level
    that one sample in `n` exceeds on either side, `Phi^-1(1 - 1/n)`."""
    return statistics.NormalDist().inv_cdf(1.0 - 1.0 / max(n, 2))
