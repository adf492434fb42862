"""The checks every public entry point runs on a record before any work (host side).

`record(u, y, orders=..., where=...)` accepts lists, tuples, NumPy and JAX arrays and
returns JAX arrays, or raises a `ValueError` / `TypeError` whose sentence names the
entry point, the argument and what to do. The estimators and the simulator call it
first, so nothing reaches `jit`, the regression or the native kernel with a shape it
does not expect.

Under `jit` or `vmap` the arrays are tracers: their shapes and dtypes are still checked
(they are static), their values never are (a batched fit never raises on bad data; the
estimators report it through a status instead, `_estimator._solution.finite`).
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np

from ._model import Orders

# Squares of larger values overflow float64 (1e308): the regression and every variance
# would be inf. Real records in any unit are far below this; rescale the ones that are not.
MAX_MAGNITUDE = 1e100


def is_traced(value) -> bool:
    return isinstance(value, jax.core.Tracer)


# The estimators that fit curved backlash branches (`Orders.degree > 1`), for the message
# of the others.
CURVED_ESTIMATORS = "the registered estimators (Literal, Robust, Pem, Recursive)"


def record(
    u,
    y=None,
    *,
    orders: Orders | None = None,
    where: str = "the record",
    cast=True,
    curved: bool = False,
):
    """`(u, y)` checked and converted to JAX arrays (`y` is `None` when not given).

    - `u`, `y`: one record each, 1-D, real (floats or integers), of equal length; finite
      and with `|value| <= MAX_MAGNITUDE` when concrete.
    - `orders`: the record must hold at least `orders.min_samples` samples.
    - `where`: the entry point, for the message (e.g. `"voros"`).
    - `curved`: whether the entry point fits curved backlash branches; where not, orders
      of branch degree > 1 (`Orders.degree`) are refused.
    - `cast`: `True` converts to the default float dtype (`jnp.result_type(float)`:
      float64 with x64 enabled), what the estimators compute in; `False` keeps a float
      dtype (the simulator's output follows its input's) and converts integers only.
    """
    if orders is not None and not isinstance(orders, Orders):
        raise TypeError(
            f"{where}: orders must be an Orders, e.g. Orders(2, 2, 2, 2) or "
            f"Orders.parse('2,2,2,2'), got {type(orders).__name__} {orders!r}."
        )
    if orders is not None and orders.degree > 1 and not curved:
        raise ValueError(
            f"{where}: orders {orders} have curved backlash branches (degree "
            f"{orders.degree}) and {where} fits the straight backlash of the 2016 paper; "
            f"use degree 1, or {CURVED_ESTIMATORS} for the general backlash."
        )
    lost = []  # the float64 arrays computed in float32 (float64 off): one warning
    u = _array(u, "u", where, cast, lost)
    if y is not None:
        y = _array(y, "y", where, cast, lost)
        if y.shape != u.shape:
            raise ValueError(
                f"{where}: u and y must have the same length, got {u.shape[0]} and "
                f"{y.shape[0]} samples; pass the input and output of one record."
            )
        y = y.astype(u.dtype)
    if lost:
        warnings.warn(
            f"{where}: {' and '.join(lost)} {'is' if len(lost) == 1 else 'are'} float64 but "
            "JAX's float64 is off, so the record is computed in float32 (about 7 "
            "significant digits); enable float64 first with "
            "jax.config.update('jax_enable_x64', True).",
            UserWarning,
            stacklevel=3,
        )
    if orders is not None and u.shape[0] < orders.min_samples:
        raise ValueError(
            f"{where}: the record has {u.shape[0]} samples, fewer than the "
            f"{orders.min_samples} that orders {orders} need (Orders.min_samples); use a "
            "longer record or lower orders."
        )
    return u, y


def _array(value, name: str, where: str, cast: bool, lost: list):
    if not is_traced(value) and not isinstance(value, jax.Array | np.ndarray):
        try:
            value = np.asarray(value)
        except (TypeError, ValueError) as error:  # ragged nested lists and the like
            raise TypeError(
                f"{where}: {name} must be a 1-D array of numbers, got {type(value).__name__} "
                f"({str(error).splitlines()[0]})."
            ) from None
    dtype = np.dtype(value.dtype)
    if not (np.issubdtype(dtype, np.floating) or np.issubdtype(dtype, np.integer)):
        raise TypeError(
            f"{where}: {name} must hold real numbers (floats or integers), got dtype {dtype}."
        )
    if value.ndim != 1:
        raise ValueError(
            f"{where}: {name} must be one record, a 1-D array of samples, got shape "
            f"{tuple(value.shape)}; pass one record at a time (e.g. {name}.ravel() for a "
            "column) or map over a batch of records with jax.vmap."
        )
    if value.shape[0] == 0:
        raise ValueError(f"{where}: {name} is empty; pass a record with samples.")
    target = jnp.result_type(float) if cast or not np.issubdtype(dtype, np.floating) else dtype
    if is_traced(value):
        return value.astype(target)
    if dtype == np.float64 and np.dtype(target) == np.float32:
        lost.append(name)
    host = np.asarray(value)
    finite = np.isfinite(host)
    if not finite.all():
        first = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"{where}: {name} has {int((~finite).sum())} NaN or infinite values, the first "
            f"at index {first}; remove or fill them before fitting."
        )
    largest = float(np.max(np.abs(host))) if host.size else 0.0
    if largest > MAX_MAGNITUDE:
        raise ValueError(
            f"{where}: {name} reaches {largest:.3g}, beyond {MAX_MAGNITUDE:g} (squares "
            "would overflow); rescale the record, e.g. to unit standard deviation."
        )
    return jnp.asarray(host if isinstance(value, np.ndarray) else value, target)
