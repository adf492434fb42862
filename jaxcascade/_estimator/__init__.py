"""Estimators of the cascade and their registry.

An estimator is an `Estimator` (`_base.py`): an `eqx.Module` whose fields are its
settings, called as `estimator(u, y, orders, *, key=None, input_range=None)` on one
record and returning a `Solution`. Adding one is a new module here plus one line in
`ESTIMATORS`; the commands (`reproduce`, `fit`, `sweep`, `bench`) and spec files find it
by name, with its `summary` as help text and its fields as settings.

An estimator from outside the package joins the registry with `register_estimator(name,
estimator)`, or through the entry-point group `jaxcascade.estimators` of its
distribution (read on the first look-up of a name not registered, never at import, so
`--help` stays fast): an `Estimator` subclass (traceable, batched like ours), or a
plain host function `fn(u, y, orders) -> vector` (`_host.HostEstimator`).
"""

from __future__ import annotations

import inspect
from typing import Any

from ._base import CURVED_FORMS, Estimator
from ._general_keyterm import key_term_solution
from ._general_pem import curved_pem_solution
from ._general_refine import curved_solution
from ._host import HostEstimator, HostFit
from ._literal import Literal
from ._pem import Pem
from ._recursive import Recursive
from ._robust import Robust
from ._solution import Solution, solution_table

ESTIMATORS: dict[str, type[Estimator] | HostEstimator] = {
    cls.name: cls for cls in (Literal, Robust, Pem, Recursive)
}
# their forms for curved backlash branches (`_base.CURVED_FORMS`; `recursive` takes them
# in its own regression)
CURVED_FORMS.update(literal=key_term_solution, robust=curved_solution, pem=curved_pem_solution)
# the package's own, in `ESTIMATORS`' order (`_names.ESTIMATORS` lists them for --help)
BUILTIN = tuple(ESTIMATORS)
ENTRY_POINT_GROUP = "jaxcascade.estimators"
_entry_points_read = False


def register_estimator(name: str, estimator, *, summary: str | None = None):
    """Make `estimator` known as `name` to `estimator(name, ...)`, spec files, `sweep
    --estimator NAME`, `fit` and `bench`.

    - an `Estimator` subclass: its fields are its settings; it must be traceable and
      `vmap`-able (it runs batched inside the sweep's compiled chunks, like ours);
    - a function `fn(u, y, orders, *, setting=default, ...) -> np.ndarray`: the parameter
      vector in `orders.names` order (non-finite: the fit failed), run on the host one
      record at a time (`_host`); its keyword-only parameters are its settings.

    `summary` (default: the class's `summary`, or the first line of the function's
    docstring) is its one-line description. A name of the package's own estimators is
    refused; registering a name again replaces the earlier one. Returns the registered
    entry (the class, or a `HostEstimator`).
    """
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"An estimator's name must be an identifier, got {name!r}.")
    if name in BUILTIN:
        raise ValueError(f"Estimator {name!r} is one of jaxcascade's own; choose another name.")
    if inspect.isclass(estimator) and issubclass(estimator, Estimator):
        if summary is not None or not estimator.summary:
            text = summary or (inspect.getdoc(estimator) or name).splitlines()[0]
            estimator = type(estimator.__name__, (estimator,), {"summary": text})
        entry = estimator
    elif isinstance(estimator, Estimator):
        raise ValueError(
            f"Register the class of estimator {name!r} ({type(estimator).__name__}), not an "
            "instance: its settings come from spec files and command lines."
        )
    else:
        entry = HostEstimator(name, estimator, summary)
    ESTIMATORS[name] = entry
    return entry


def _read_entry_points() -> None:
    """Register the estimators of the entry-point group `jaxcascade.estimators`, once."""
    global _entry_points_read
    if _entry_points_read:
        return
    _entry_points_read = True
    from importlib.metadata import entry_points

    for point in entry_points(group=ENTRY_POINT_GROUP):
        if point.name not in ESTIMATORS:
            register_estimator(point.name, point.load())


def lookup(name: str):
    """The registry's entry for `name` (entry points read if needed); a `ValueError`
    naming the known estimators."""
    if name not in ESTIMATORS:
        _read_entry_points()
    if name not in ESTIMATORS:
        raise ValueError(f"Unknown estimator {name!r}; known estimators: {', '.join(ESTIMATORS)}.")
    return ESTIMATORS[name]


def is_host(fit) -> bool:
    """Whether `fit` (an estimator with its settings) runs on the host (`HostFit`)."""
    return isinstance(fit, HostFit)


def estimator(name: str, **settings: Any) -> Estimator | HostFit:
    """The estimator registered as `name` with `settings`; a `ValueError` naming what is
    known when the name or a setting is not."""
    cls = lookup(name)
    known = cls.settings()
    unknown = sorted(set(settings) - set(known))
    if unknown:
        raise ValueError(
            f"Unknown setting {unknown[0]!r} for estimator {name!r}; known settings: "
            f"{', '.join(sorted(known))}."
        )
    return cls(**settings)


__all__ = [
    "ESTIMATORS",
    "Estimator",
    "Solution",
    "estimator",
    "register_estimator",
    "solution_table",
]
