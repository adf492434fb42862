"""`jaxcascade fit`: fit the cascade to one measured or simulated record.

Exit codes: 0 when the fit's status is usable (`converged`, `cycled`), `FAILED` (3) when
it is a failure (`Status.failure`; the result is printed all the same), 2 for a bad
request (one line on stderr, nothing fitted). Parameters the record does not determine
(`_efficiency.not_identifiable`) are named in the message and the table, beside a status
that stays the estimator's.
"""

from __future__ import annotations

import functools
import math
import sys

from .. import _defaults
from ._common import (
    RECORD_SPEC,
    CLIError,
    add_record_arguments,
    estimator_help,
    examples,
    parse_orders,
    record_options,
    strict_json,
)

FAILED = 3  # exit code of a fit whose status is a failure


def fit_record(u, y, orders, name: str = _defaults.ESTIMATOR, **settings):
    """Fit one record with the registered estimator `name`.

    Returns `(solution, error, errors)`: `error` is the NRMSE of the free-run simulation
    of the estimate on the same record (inf when the estimate is inadmissible), `errors`
    the estimated standard error of every parameter (`_efficiency.standard_errors`: the
    output-error information at the estimate, sigma from the residual, white noise).
    """
    import jax
    import numpy as np

    from .._estimator import estimator
    from .._system._validate import record as checked

    u, y = checked(u, y, orders=orders, where="fit")
    solution = jax.device_get(estimator(name, **settings)(u, y, orders))
    y_sim, error, errors = _after_fit()(solution.params, u, y)
    errors = dict(zip(orders.names, np.asarray(errors, float).tolist(), strict=True))
    error = float(error)  # `_metrics.score`'s guard: a simulation that blows up is inf
    return solution, error if math.isfinite(error) else math.inf, errors


@functools.cache
def _after_fit():
    """What `fit_record` computes from an estimate, as one program (one instead of about
    fifty small ones op by op; kept across runs with the fit's, `_compile.exported`):
    the free-run simulation, its NRMSE on the record (`_metrics.nrmse`) and the standard
    errors. Built on first use: the command line's module imports no JAX."""
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


def run_fit(args) -> int:
    from .._native import build_in_background

    # the robust fit needs the native kernel: on a machine's first run it compiles
    # on another core while this command imports and reads its records (`_native`)
    build_in_background()
    # imported here, not at the top: `--help` answers without importing JAX
    from .._data import read_record
    from .._estimator import estimator
    from .._estimator._efficiency import not_identifiable
    from .._metrics import fit_percent
    from .._status import Status

    orders = parse_orders(args.orders, "fit")
    if args.decimate < 1:
        raise CLIError(f"--decimate must be an integer >= 1, got {args.decimate}.")
    estimator(args.estimator)  # unknown names fail here, before reading data
    record = read_record(args.data, **record_options(args), scaling=args.scaling, orders=orders)
    solution, error, errors = fit_record(record.u, record.y, orders, args.estimator)
    status = Status(int(solution.status))
    estimates = solution.params.to_dict()
    # Which parameters the record does not determine: said beside the status (which the
    # estimator and the sweeps share, unchanged), in the message and in the table. A fit
    # `on_edge` (a breakpoint at the end of the input's range: a sweep counts it a
    # failure) is such a fit: named, the other estimates stand (exit code 0).
    partial = status is Status.on_edge
    unknown = (
        not_identifiable(solution.params, errors, record.u) if not status.failure or partial else {}
    )
    message = status.message
    if unknown:
        message += f" {_listed(list(unknown))} {_are(unknown)} not identifiable from this record."
    result = {
        "estimator": args.estimator,
        "status": status.name,
        "message": message,
        "estimates": estimates,
        "std_errors": errors,
        "not_identifiable": unknown,
        "nrmse": error,  # inf (null in JSON) when the estimate's simulation blows up
        "iterations": int(solution.iterations),
    }
    if args.scaling != "none":
        # the standard errors are in model units, beside `estimates`
        result["estimates_physical"] = record.scaling.params_to_physical(estimates)
        # the map is a scale factor per parameter: a standard error maps with it
        result["std_errors_physical"] = {
            k: abs(v) for k, v in record.scaling.params_to_physical(errors).items()
        }
        result["scaling"] = record.scaling.to_dict()
    code = FAILED if status.failure and not (partial and unknown) else 0
    if args.save_model:
        from .._measured._effects import plain
        from .._measured._model_file import SavedModel

        fitted = plain(solution.params)
        provenance = {"command": "jaxcascade fit " + " ".join(sys.argv[2:]), "status": status.name}
        SavedModel.from_record(fitted, record, provenance=provenance).save(args.save_model)
        result["model_file"] = str(args.save_model)
    if args.json:
        print(strict_json(result))
        return code
    print(f"{args.estimator} estimator: {status.name} after {result['iterations']} iterations")
    if status.failure and code:
        print(f"failed: {status.message}")
    if unknown:
        print(
            f"not identifiable from this record: {_listed(list(unknown))}; the data do not "
            f"determine {'its value' if len(unknown) == 1 else 'their values'} (why: below), "
            "the other estimates stand"
        )
    shown = f"{error:.4g} (fit {fit_percent(error):.1f} %)" if math.isfinite(error) else "inf"
    print(f"free-run NRMSE {shown} on {len(record)} samples")
    values, value_errors = estimates, errors
    if "estimates_physical" in result:
        # fitted in model units (`--scaling`): shown in the record's own units
        values, value_errors = result["estimates_physical"], result["std_errors_physical"]
        sc = record.scaling
        print(
            f"estimates in the record's units (fitted with --scaling {args.scaling}: "
            f"{sc.method}, input offset {sc.u_offset:.4g} scale {sc.u_scale:.4g}, output "
            f"offset {sc.y_offset:.4g} scale {sc.y_scale:.4g}; the model is "
            "y - y_offset = cascade(u - u_offset))"
        )
    for name, value in values.items():
        if name in unknown:
            print(f"  {name:>4} = {value: .6f}   not identifiable: {unknown[name]}")
        else:
            print(f"  {name:>4} = {value: .6f} ± {value_errors[name]:.2g}")
    return code


def _listed(names: list[str]) -> str:
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _are(names) -> str:
    return "is" if len(names) == 1 else "are"


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "fit",
        help="fit the cascade to a measured record (CSV, TSV, Parquet or MAT)",
        description=(
            "Fit the cascade to one record and print the estimates, the status and the "
            "free-run NRMSE. Exit code 0 when the status is usable (converged, cycled), "
            f"{FAILED} when it is a failure (the result is printed all the same), 2 for a "
            "bad request."
        ),
        epilog=examples(
            "jaxcascade fit record.csv --input u --output y",
            "jaxcascade fit record.parquet --input u --output y --orders 3,2,2,1 "
            "--estimator literal --json",
            "jaxcascade fit DATAUNIF.MAT:u11,z11:0:400 --ts 0.02 --units V,V --detrend mean",
        ),
    )
    parser.add_argument("data", metavar="DATA", help=f"the record, {RECORD_SPEC}")
    add_record_arguments(parser)
    parser.add_argument(
        "--estimator",
        default=_defaults.ESTIMATOR,
        metavar="NAME",
        help=f"default {_defaults.ESTIMATOR}; {estimator_help()}",
    )
    parser.add_argument(
        "--save-model",
        default=None,
        metavar="PATH",
        help="write the fitted cascade as a model file (JSON, docs/models.md), which "
        "'jaxcascade simulate PATH RECORD' applies to new records",
    )
    parser.add_argument("--json", action="store_true", help="print a JSON result")
    parser.set_defaults(func=run_fit)
