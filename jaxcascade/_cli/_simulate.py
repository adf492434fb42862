"""`jaxcascade simulate`: apply a saved model (`_model_file`) to new records
(`_workflow._simulate.simulate_model`).

Each record is read as the model's estimation records were (the saved decimation,
detrending and scaling; its signals from the record spec, `--input`/`--output`, or the
saved names; its period from `--time`, the saved time column unless `--ts` is given, or
`--ts`, else the model's) and scored as the loop scores a test record: initialised on its first
`--init-samples` samples (default the saved number) and from rest. The table (stdout,
`--json`, and `simulate.json` / `simulate.md` under `--report DIR`) gives NRMSE, RMSE in
the record's unit and fit %; `--report` also draws one figure per record
(`simulate_<k>.png`: measured versus simulated against time in seconds).
"""

from __future__ import annotations

import argparse
import pathlib

from ._common import (
    RECORD_SPEC,
    CLIError,
    add_signal_arguments,
    examples,
    record_options,
    strict_json,
    writable_folder,
)


def run_simulate(args) -> int:
    # imported here, not at the top: `--help` answers without importing JAX
    from .._workflow._simulate import simulate_model

    if args.init_samples is not None and args.init_samples < 0:
        raise CLIError(f"--init-samples must be >= 0, got {args.init_samples}.")
    options = record_options(
        argparse.Namespace(
            input=args.input,
            output=args.output,
            time=args.time,
            ts=args.ts,
            units=args.units,
            detrend="none",  # not an option here: the model's own
            decimate=1,  # likewise
        )
    )
    folder = args.report
    if folder is not None:
        writable_folder(folder, "--report")
    simulation = simulate_model(
        args.model,
        args.records,
        init_samples=args.init_samples,
        input_column=options["input_column"],
        output_column=options["output_column"],
        time_column=options["time_column"],
        sample_period=options["sample_period"],
        input_unit=options["input_unit"],
        output_unit=options["output_unit"],
    )
    if folder is not None:
        simulation.report(folder)
    if args.json:
        print(strict_json(simulation.to_dict()))
    else:
        print(simulation.markdown(), end="")
        if folder is not None:
            print(f"report: {pathlib.Path(folder) / 'simulate.md'}")
    return 0


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="apply a saved model (loop's model.json, fit --save-model) to new records",
        description=(
            "Apply a saved model to records: each read with the model's decimation, "
            "detrending and scaling, simulated initialised (its state set from the "
            "measured output on the first --init-samples samples) and from rest, and "
            "compared with the measured output (NRMSE, RMSE in the record's unit, fit %). "
            "Signals (and the time column, unless --ts) default to the model's estimation "
            "records' names; a record sampled "
            "otherwise than the model is refused."
        ),
        epilog=examples(
            "jaxcascade simulate results/loop/model.json test.csv",
            "jaxcascade simulate model.json a.csv b.csv --input u --output y --time t "
            "--report results/simulate",
            "jaxcascade simulate results/ced/model.json "
            "CED/DATAUNIF.MAT:u11,z11:400: CED/DATAUNIF.MAT:u12,z12:400: --ts 0.02 --json",
        ),
    )
    parser.add_argument(
        "model",
        metavar="MODEL",
        help="a model file: model.json of 'jaxcascade loop --report DIR', or "
        "'jaxcascade fit --save-model PATH'",
    )
    parser.add_argument(
        "records", nargs="+", metavar="RECORD", help=f"record(s) to simulate, each {RECORD_SPEC}"
    )
    add_signal_arguments(parser)
    parser.add_argument(
        "--init-samples",
        type=int,
        default=None,
        help="N: the model's state is set from the measured output on the first N samples "
        "(after decimation), the rest scored (default: the model file's, the loop's "
        "--init-samples; 0 scores from rest only)",
    )
    parser.add_argument(
        "--report", default=None, help="folder for simulate.json, simulate.md and the figures"
    )
    parser.add_argument("--json", action="store_true", help="print the JSON result")
    parser.set_defaults(func=run_simulate)
