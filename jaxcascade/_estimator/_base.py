"""The estimator interface: settings are fields, a call fits one record."""

from __future__ import annotations

import abc
import dataclasses
import inspect
import typing
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
from jaxtyping import Array, Float, PRNGKeyArray

from .._system._model import Orders
from ._solution import Solution

# The registered estimators' forms for curved backlash branches (`Orders.degree > 1`), by
# estimator name: `form(u, y, orders, key, **settings) -> Solution`, traceable. The general
# backlash's estimators build on the straight ones, so their modules sit above them; the
# package's `__init__` enters them here, and a straight estimator's `__call__` looks its
# curved form up (`curved_form`) instead of importing upwards.
CURVED_FORMS: dict[str, Callable[..., Solution]] = {}


def curved_form(name: str) -> Callable[..., Solution]:
    """The curved-branch form of the registered estimator `name` (`CURVED_FORMS`)."""
    return CURVED_FORMS[name]


class Estimator(eqx.Module):
    """An estimator of the cascade. Its settings are its fields (static: they fix what is
    compiled), so a spec file's `[estimator.NAME]` table is `Estimator(**table)`; calling
    it fits one record. A bad record is refused eagerly (`_validate.record`: a
    `ValueError` or `TypeError`, before anything is compiled); bad values inside traced
    code never raise: the `Solution` carries a `Status` and a finite estimate
    (`_solution.finite`). Every call is traceable and `vmap`-able over records.

    Subclasses set `name` (the registry key, `_estimator.ESTIMATORS`) and `summary` (one
    line for `--help`), declare their settings as fields with defaults and implement
    `__call__`, whose first line checks the record (`u, y = record(u, y, orders=orders,
    where=NAME)`).
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""

    @abc.abstractmethod
    def __call__(
        self,
        u: Float[Array, " T"],
        y: Float[Array, " T"],
        orders: Orders,
        *,
        key: PRNGKeyArray | None = None,
        input_range: tuple[float, float] | None = None,
    ) -> Solution:
        """Fit one record.

        - `u`, `y`: input and measured output.
        - `orders`: static model orders.
        - `key`: a PRNG key for estimators with random starts (the Monte-Carlo engine
          passes one per realisation; `None`: a fixed default, deterministic).
        - `input_range`: `(u_min, u_max)`, the nominal range of the input distribution,
          for initial values that must not depend on one record's sample extremes;
          `None`: the record's own range.
        """

    def __check_init__(self):
        # Settings come from TOML files and command lines: check their types here, so a
        # bad value is a sentence, not a trace-time error.
        hints = typing.get_type_hints(type(self))
        for field in dataclasses.fields(self):
            value, kind = getattr(self, field.name), hints.get(field.name)
            if not _matches(value, kind):
                raise ValueError(
                    f"Setting {field.name!r} of estimator {self.name!r} must be "
                    f"{_describe(kind)}, got {value!r}."
                )

    @classmethod
    def settings(cls) -> dict[str, Any]:
        """Setting names and their defaults."""
        return {f.name: f.default for f in dataclasses.fields(cls)}


def keyword_defaults(function) -> dict[str, Any]:
    """The keyword-only parameters of `function` and their defaults: an estimator's
    functional form (`voros`, `robust`) is the one place its settings' defaults are
    written, and its class reads them from there."""
    return {
        name: parameter.default
        for name, parameter in inspect.signature(function).parameters.items()
        if parameter.kind is inspect.Parameter.KEYWORD_ONLY
    }


def setting(default):
    """A field of an `Estimator`: static (part of what is compiled), with a default."""
    return eqx.field(static=True, default=default)


def _matches(value, kind) -> bool:
    if kind is bool:
        return isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if kind is str:
        return isinstance(value, str)
    origin = typing.get_origin(kind)
    if origin is tuple:
        args = typing.get_args(kind)
        return (
            isinstance(value, tuple)
            and len(value) == len(args)
            and all(_matches(v, a) for v, a in zip(value, args, strict=True))
        )
    return True


def _describe(kind) -> str:
    if typing.get_origin(kind) is tuple:
        return "a list of " + ", ".join(_describe(a) for a in typing.get_args(kind))
    return {bool: "true or false", int: "an integer", float: "a number", str: "a string"}.get(
        kind, str(kind)
    )
