"""`jaxcascade fit`: fit the cascade to one measured or simulated record
(`_workflow._fit.fit_record`), printed or as JSON (`FitResult.to_dict`).

Exit codes: 0 when the fit's status is usable (`converged`, `cycled`), `FAILED` (3) when
it is a failure (`Status.failure`; the result is printed all the same), 2 for a bad
request (one line on stderr, nothing fitted). Parameters the record does not determine
(`_efficiency.not_identifiable`) are named in the message and the table, beside a status
that stays the estimator's.
"""

from __future__ import annotations

import math
import sys

from .. import _defaults
from ._common import (
    RECORD_SPEC,
    CLIError,
    add_record_arguments,
    estimator_help,
    examples,
    record_options,
    strict_json,
)

FAILED = 3  # exit code of a fit whose status is a failure


def run_fit(args) -> int:
    from .._native import build_in_background

    # the robust fit needs the native kernel: on a machine's first run it compiles
    # on another core while this command imports and reads its records (`_native`)
    build_in_background()
    # imported here, not at the top: `--help` answers without importing JAX
    from .._data import read_record
    from .._estimator import estimator
    from .._metrics import fit_percent
    from .._workflow._fit import fit_record

    orders = args.orders  # parsed as the option was read (`orders_option`)
    if args.decimate < 1:
        raise CLIError(f"--decimate must be an integer >= 1, got {args.decimate}.")
    estimator(args.estimator)  # unknown names fail here, before reading data
    record = read_record(args.data, **record_options(args), scaling=args.scaling, orders=orders)
    result = fit_record(record, orders=orders, estimator=args.estimator)
    output = result.to_dict()
    if args.save_model:
        command = "jaxcascade fit " + " ".join(sys.argv[2:])
        result.save(args.save_model, provenance={"command": command})
        output["model_file"] = str(args.save_model)
    code = FAILED if result.failed else 0
    if args.json:
        print(strict_json(output))
        return code
    print(f"{args.estimator} estimator: {result.status.name} after {result.iterations} iterations")
    for warning in result.warnings:
        print(warning)
    error = result.nrmse
    shown = f"{error:.4g} (fit {fit_percent(error):.1f} %)" if math.isfinite(error) else "inf"
    print(f"free-run NRMSE {shown} on {len(record)} samples")
    if args.scaling != "none":
        sc = record.scaling
        print(
            f"estimates in the record's units (fitted with --scaling {args.scaling}: "
            f"{sc.method}, input offset {sc.u_offset:.4g} scale {sc.u_scale:.4g}, output "
            f"offset {sc.y_offset:.4g} scale {sc.y_scale:.4g}; the model is "
            "y - y_offset = cascade(u - u_offset))"
        )
    unknown = result.not_identifiable
    for name, value in result.estimates.items():
        if name in unknown:
            print(f"  {name:>4} = {value: .6f}   not identifiable: {unknown[name]}")
        else:
            print(f"  {name:>4} = {value: .6f} ± {result.std_errors[name]:.2g}")
    return code


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
    add_record_arguments(parser, "fit")
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
