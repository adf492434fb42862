"""Estimators of the cascade and their registry.

An estimator is an `Estimator` (`_base.py`): an `eqx.Module` whose fields are its
settings, called as `estimator(u, y, orders, *, key=None, input_range=None)` on one
record and returning a `Solution`. Adding one is a new module here plus one line in
`ESTIMATORS`; the commands (`reproduce`, `fit`, `sweep`, `bench`) and spec files find it
by name, with its `summary` as help text and its fields as settings.
"""

from __future__ import annotations

from typing import Any

from ._base import Estimator
from ._literal import Literal
from ._recursive import Recursive
from ._robust import Robust
from ._solution import Solution, solution_table

ESTIMATORS: dict[str, type[Estimator]] = {cls.name: cls for cls in (Literal, Robust, Recursive)}


def estimator(name: str, **settings: Any) -> Estimator:
    """The estimator registered as `name` with `settings`; a `ValueError` naming what is
    known when the name or a setting is not."""
    if name not in ESTIMATORS:
        raise ValueError(f"Unknown estimator {name!r}; known estimators: {', '.join(ESTIMATORS)}.")
    cls = ESTIMATORS[name]
    known = cls.settings()
    unknown = sorted(set(settings) - set(known))
    if unknown:
        raise ValueError(
            f"Unknown setting {unknown[0]!r} for estimator {name!r}; known settings: "
            f"{', '.join(sorted(known))}."
        )
    return cls(**settings)


__all__ = ["ESTIMATORS", "Estimator", "Solution", "estimator", "solution_table"]
