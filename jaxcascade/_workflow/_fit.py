"""`fit_record`: fit the cascade to one record, as `jaxcascade fit` does.

The estimate, the free-run NRMSE on the record, the standard error of every parameter
(the output-error information at the estimate, white noise), the parameters the record
does not determine (`_efficiency.not_identifiable`) beside a status that stays the
estimator's, and the model in the package's schema (`_measured._schema`: the estimates
in the record's units and in model units).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from typing import Any

import numpy as np

from .. import _defaults
from .._data import Record, record_from_arrays
from .._status import Status
from .._system._model import Orders


def _orders(orders) -> Orders:
    return orders if isinstance(orders, Orders) else Orders.parse(str(orders))


@dataclasses.dataclass(frozen=True)
class FitResult:
    """What `fit_record` returns (`jaxcascade fit` prints it).

    - `estimator`, `status` (`Status`), `message` (the status's sentence, with the
      parameters the record does not determine), `iterations`, `solution` (the
      estimator's `Solution`, model units).
    - `estimates`, `std_errors`: the cascade's parameters and their standard errors in
      the record's units (`_measured._schema`; infinite: not determined by the record);
      `estimates_model_units`, `std_errors_model_units` in the units it was fitted in.
    - `not_identifiable`: `{name: why}` of the parameters the record does not determine.
    - `nrmse`: the free-run simulation's NRMSE on the record (inf where it blows up).
    - `record`: the record fitted; `model`: the fitted cascade as an `ExtendedModel`.
    - `failed`: the status is a failure the command exits with 3 for; `warnings`: the
      sentences the command prints beside the estimates.

    `to_dict()` is `jaxcascade fit --json`; `save(path)` writes a model file
    (`jaxcascade simulate` and `load_model` read it).
    """

    estimator: str
    status: Status
    message: str
    iterations: int
    nrmse: float
    not_identifiable: dict
    record: Record
    solution: Any
    model: Any
    std_errors_model_units: dict

    @functools.cached_property
    def schema(self) -> dict:
        """The fitted model in the package's schema (`_measured._schema`)."""
        from .._measured._schema import model_schema

        return model_schema(self.model, self.record.scaling, self.std_errors_model_units)

    @property
    def estimates(self) -> dict[str, float]:
        return self.schema["estimates"]

    @property
    def std_errors(self) -> dict[str, float]:
        return self.schema["std_errors"]

    @property
    def estimates_model_units(self) -> dict[str, float]:
        return self.schema["estimates_model_units"]

    @property
    def failed(self) -> bool:
        """A failed status, unless it is `on_edge` with the parameters it leaves
        undetermined named (the other estimates stand)."""
        return self.status.failure and not (self.status is Status.on_edge and self.not_identifiable)

    @property
    def warnings(self) -> list[str]:
        out = []
        if self.failed:
            out.append(f"failed: {self.status.message}")
        if self.not_identifiable:
            names = list(self.not_identifiable)
            out.append(
                f"not identifiable from this record: {_listed(names)}; the data do not "
                f"determine {'its value' if len(names) == 1 else 'their values'} (why: "
                "beside each estimate), the other estimates stand"
            )
        return out

    def to_dict(self) -> dict[str, Any]:
        """`jaxcascade fit --json`: the status and figures, and the model in the schema."""
        return {
            "estimator": self.estimator,
            "status": self.status.name,
            "message": self.message,
            "warnings": self.warnings,
            "not_identifiable": dict(self.not_identifiable),
            "nrmse": self.nrmse,  # inf (null in JSON) when the simulation blows up
            "iterations": self.iterations,
            "samples": len(self.record),
            "model": self.schema,
        }

    def saved_model(self, provenance: dict | None = None):
        """The fitted cascade as a `SavedModel` with the record's preprocessing."""
        from .._measured._model_file import SavedModel

        provenance = {"status": self.status.name, **(provenance or {})}
        return SavedModel.from_record(
            self.model,
            self.record,
            provenance=provenance,
            std_errors=self.std_errors_model_units,
        )

    def save(self, path: str | os.PathLike, provenance: dict | None = None):
        """Write the model file (`SavedModel.save`); returns its path."""
        return self.saved_model(provenance).save(path)

    def __repr__(self) -> str:
        shown = f"{self.nrmse:.4g}" if math.isfinite(self.nrmse) else "inf"
        warned = f"; {len(self.warnings)} warning(s)" if self.warnings else ""
        return (
            f"FitResult({self.estimator}: {self.status.name} after {self.iterations} "
            f"iterations; free-run NRMSE {shown} on {len(self.record)} samples; "
            f"{len(self.estimates)} estimates in the record's units{warned})"
        )


def fit_record(
    record,
    y=None,
    orders=_defaults.ORDERS,
    estimator: str = _defaults.ESTIMATOR,
    *,
    sample_period: float | None = None,
    scaling=_defaults.SCALING,
    detrend: str = _defaults.DETREND,
    decimate: int = _defaults.DECIMATE,
    input_unit: str | None = None,
    output_unit: str | None = None,
    **settings,
) -> FitResult:
    """Fit the cascade to one record with the registered estimator `estimator`, as
    `jaxcascade fit` does (the same defaults, `_defaults`).

    - `record`: a `Record` (`read_record`, `record_from_arrays`: its scaling kept), or
      the input array in its physical units with the output `y`; arrays are made a
      record by `record_from_arrays` with `sample_period`, `scaling`, `detrend`,
      `decimate` and the units.
    - `orders`: an `Orders` or `"nR,nL,r,p"`.
    - `settings`: the estimator's settings (`estimator(name, **settings)`).

    Returns a `FitResult`: the estimates and standard errors in the record's units, the
    status, the parameters the record does not determine, the free-run NRMSE.
    """
    import jax

    from .._estimator import estimator as make_estimator
    from .._estimator._efficiency import not_identifiable
    from .._measured._effects import plain
    from .._system._validate import record as checked

    orders = _orders(orders)
    fit = make_estimator(estimator, **settings)  # unknown names fail before any work
    if not isinstance(record, Record):
        if y is None:
            raise TypeError("fit_record: give a Record, or the input and output arrays.")
        record = record_from_arrays(
            record,
            y,
            sample_period=sample_period,
            scaling=scaling,
            detrend=detrend,
            decimate=decimate,
            orders=orders,
            input_unit=input_unit,
            output_unit=output_unit,
        )
    elif y is not None:
        raise TypeError("fit_record: a Record holds its output; give no y beside it.")
    u, y_model = checked(record.u, record.y, orders=orders, where="fit")
    solution = jax.device_get(fit(u, y_model, orders))
    _, error, errors = _after_fit()(solution.params, u, y_model)
    errors = dict(zip(orders.names, np.asarray(errors, float).tolist(), strict=True))
    error = float(error)  # `_metrics.score`'s guard: a simulation that blows up is inf
    status = Status(int(solution.status))
    # Which parameters the record does not determine: said beside the status (which the
    # estimator and the sweeps share, unchanged), in the message and the estimates. A
    # fit `on_edge` (a breakpoint at the end of the input's range: a sweep counts it a
    # failure) is such a fit: named, the other estimates stand.
    partial = status is Status.on_edge
    unknown = (
        not_identifiable(solution.params, errors, record.u) if not status.failure or partial else {}
    )
    message = status.message
    if unknown:
        message += f" {_listed(list(unknown))} {_are(unknown)} not identifiable from this record."
    return FitResult(
        estimator=estimator,
        status=status,
        message=message,
        iterations=int(solution.iterations),
        nrmse=error if math.isfinite(error) else math.inf,
        not_identifiable=unknown,
        record=record,
        solution=solution,
        model=plain(solution.params),
        std_errors_model_units=errors,
    )


@functools.cache
def _after_fit():
    """What `fit_record` computes from an estimate, as one program (one instead of about
    fifty small ones op by op; kept across runs with the fit's, `_compile.exported`):
    the free-run simulation, its NRMSE on the record (`_metrics.nrmse`) and the standard
    errors. Built on first use: importing this module imports no JAX."""
    from .._compile import exported
    from .._estimator._efficiency import standard_errors
    from .._metrics import nrmse
    from .._system._model import CascadeParams
    from .._system._simulate import simulate

    @exported
    def after_fit(params, u, y):
        orders = params.orders

        def simulate_vector(vector):
            return simulate(CascadeParams.from_vector(vector, orders, check=False), u)

        vector = params.to_vector().astype(u.dtype)
        y_sim = simulate_vector(vector)
        errors, _ = standard_errors(simulate_vector, vector, y)
        return y_sim, nrmse(y, y_sim), errors

    return after_fit


def _listed(names: list[str]) -> str:
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _are(names) -> str:
    return "is" if len(names) == 1 else "are"
