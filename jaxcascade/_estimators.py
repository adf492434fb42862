"""Registry of estimators that the Monte-Carlo engine can run by name.

Every entry is a callable `fit(u, y, orders, **settings) -> Solution` for one record:
traceable, `vmap`-able, and it never raises on bad data (it reports a `Status`). Two
optional keyword arguments are filled in by the engine when a fit declares them:

- `input_range`: `(u_min, u_max)`, the nominal range of the input distribution (the
  engine passes `(-amplitude, amplitude)`), for initial values that must not depend
  on the sample extremes of one record;
- `key`: a PRNG key of the realisation, for estimators with random starts.

Other keyword arguments are the estimator's settings (`[estimator.NAME]` in a spec
file); they must be hashable (they are static under `jit`).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._estimate import Solution, initial_guess, voros
from ._estimator._robust import robust
from ._model import Orders

# Keyword arguments the engine supplies itself; never user settings.
ENGINE_ARGUMENTS = ("input_range", "key")


def literal(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    *,
    input_range: tuple[float, float] | None = None,
    max_iterations: int = 50,
    tol: float = 1e-10,
    divergence_bound: float = 1e6,
) -> Solution:
    """The paper's iteration (`voros`) from the paper's initial values.

    With `input_range = (-2, 2)` the initial breakpoints are exactly the paper's
    DR1 = 1.0, DL1 = -1.0 (`initial_guess`); without it they follow the sample range
    of `u`, which is slightly narrower and differs between realisations.
    """
    if input_range is None:
        u_min, u_max = jnp.min(u), jnp.max(u)
    else:
        u_min, u_max = input_range
    init = initial_guess(orders, u_min, u_max, u.dtype)
    return voros(
        u,
        y,
        orders,
        init,
        max_iterations=max_iterations,
        tol=tol,
        divergence_bound=divergence_bound,
    )


ESTIMATORS: dict[str, Callable[..., Solution]] = {"literal": literal, "robust": robust}


def estimator(name: str) -> Callable[..., Solution]:
    """The fit registered as `name`; ValueError naming the known ones otherwise."""
    if name not in ESTIMATORS:
        raise ValueError(f"Unknown estimator {name!r}; known estimators: {', '.join(ESTIMATORS)}.")
    return ESTIMATORS[name]


def accepted_settings(name: str) -> tuple[set[str], bool]:
    """Keyword settings the fit `name` takes, and whether it takes any (`**kwargs`)."""
    parameters = inspect.signature(estimator(name)).parameters.values()
    any_keyword = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters)
    names = {
        p.name
        for p in parameters
        if p.kind in (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    }
    return names - {"u", "y", "orders", *ENGINE_ARGUMENTS}, any_keyword


def takes(name: str, argument: str) -> bool:
    """Whether the fit `name` declares the keyword `argument` (e.g. `key`, `input_range`)."""
    return argument in inspect.signature(estimator(name)).parameters
