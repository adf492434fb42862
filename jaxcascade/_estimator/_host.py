"""A user's plain host function as an estimator: `fn(u, y, orders) -> vector`.

Not every estimator worth benchmarking is written in JAX. A host function takes one
record as NumPy arrays and the model orders and returns the parameter vector in
`orders.names` order; a non-finite entry means the fit failed. Its keyword-only
parameters with defaults are its settings (validated and recorded like an
`Estimator`'s fields). It runs on the host, one record after another, over the records
the Monte-Carlo engine draws for every estimator of a sweep (`_montecarlo._engine`:
the draw and the validation are compiled and batched as usual, only the fit is a
Python loop), and its time per fit is measured per record.

`HostEstimator` is what the registry holds (the counterpart of an `Estimator` class:
`settings()`, `summary`, called with settings it gives a `HostFit`); a `HostFit` is
called like an `Estimator` and returns a `Solution` (host arrays): the vector, or a
finite stand-in (zeros) with status `failed` where it is not finite. A finite vector's
status is the package's word, not the function's: `converged` only where its
simulation error passes the validity tests every output-error estimator here must pass
(`_basin.claim`, `robust`'s bound), else `left_domain` (outside the model's domain,
`is_admissible`), `local_minimum` or `on_edge` (a host function
that returns its best local fit is not thereby "converged": the SciPy example of
`docs/examples/own_estimators.py` returned 87 of 300 noise-free random-family and
example estimates more than 0.05 from the truth, `results/status_honesty.md`). `cost`
is the mean squared simulation error of the estimate, `iterations` 1 (0 when failed).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .._status import Status
from .._system._model import CascadeParams, Orders, is_admissible
from ._base import _describe, _matches, keyword_defaults
from ._basin import claim
from ._robust import DEFAULTS as ROBUST
from ._solution import PATH_ONLY, Solution


class HostEstimator:
    """A registered host function (module docstring)."""

    host = True

    def __init__(self, name: str, function: Callable, summary: str | None = None):
        if not callable(function):
            raise ValueError(f"Estimator {name!r} must be an Estimator class or a function.")
        parameters = inspect.signature(function).parameters.values()
        positional = [
            p
            for p in parameters
            if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty
        ]
        if len(positional) != 3:
            raise ValueError(
                f"Estimator function {name!r} must take (u, y, orders) and keyword-only "
                f"settings with defaults; it takes {len(positional)} positional argument(s)."
            )
        missing = [p.name for p in parameters if p.kind is p.KEYWORD_ONLY and p.default is p.empty]
        if missing:
            raise ValueError(f"Setting {missing[0]!r} of estimator {name!r} needs a default.")
        self.name = name
        self.function = function
        doc = inspect.getdoc(function) or ""
        self.summary = summary or (doc.splitlines()[0] if doc else f"host function {name}")

    def settings(self) -> dict[str, Any]:
        return keyword_defaults(self.function)

    def __call__(self, **settings) -> HostFit:
        defaults = self.settings()
        for key, value in settings.items():
            kind = type(defaults[key])
            kind = float if kind is int and isinstance(value, float) else kind
            if defaults[key] is not None and not _matches(value, kind):
                raise ValueError(
                    f"Setting {key!r} of estimator {self.name!r} must be {_describe(kind)}, "
                    f"got {value!r}."
                )
        return HostFit(self.name, self.function, {**defaults, **settings})

    def __repr__(self) -> str:
        return f"HostEstimator({self.name!r}, {self.function.__module__}.{self.function.__name__})"


@jax.jit
def _claim(params, residual, u, y):
    from ._sensitivity import output_jacobian

    inside = is_admissible(params, jnp.min(u), jnp.max(u))
    status = jnp.where(inside, Status.converged, Status.left_domain)
    _, jacobian = output_jacobian(params, u)
    return claim(status, params, residual, u, y, ROBUST["threshold"], jacobian=jacobian)


class HostFit:
    """A host function with its settings, called like an `Estimator` on one record."""

    host = True

    def __init__(self, name: str, function: Callable, settings: dict):
        self.name, self.function, self.settings = name, function, dict(settings)

    def vector(self, u, y, orders: Orders) -> np.ndarray:
        """The function's parameter vector for one record (float64, NaN where it failed);
        a `ValueError` for one of the wrong length."""
        out = np.asarray(
            self.function(np.asarray(u), np.asarray(y), orders, **self.settings), float
        ).reshape(-1)
        if out.size != len(orders.names):
            raise ValueError(
                f"Estimator {self.name!r} returned {out.size} values; orders {orders} have "
                f"{len(orders.names)} parameters ({', '.join(orders.names)})."
            )
        return out

    def solution(self, vector: np.ndarray, u, y, orders: Orders) -> Solution:
        """The `Solution` of a returned vector (module docstring)."""
        from .._system._simulate import simulate

        ok = bool(np.all(np.isfinite(vector)))
        safe = np.where(ok, vector, 0.0)
        params = CascadeParams.from_vector(np.asarray(safe), orders, check=False)
        cost, status = np.inf, Status.failed
        if ok:
            residual = np.asarray(simulate(params, np.asarray(u))) - y
            cost = float(np.mean(residual**2))
            status = int(_claim(params, residual, np.asarray(u), np.asarray(y)))
        return Solution(
            params=params,
            history=np.asarray(safe)[None],
            iterations=np.asarray(int(ok), np.int32),
            cost=np.asarray(cost if np.isfinite(cost) else np.inf),
            status=np.asarray(status, np.int32),
            cycle_amplitude=np.asarray(0.0),
            path=np.asarray(PATH_ONLY, np.int32),
        )

    def __call__(self, u, y, orders: Orders, *, key=None, input_range=None) -> Solution:
        del key, input_range  # a host function sees the record and the orders only
        u, y = np.asarray(u, float), np.asarray(y, float)
        return self.solution(self.vector(u, y, orders), u, y, orders)
