"""`jaxcascade simulate`: apply a saved model (`_model_file`) to new records.

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
    import pathlib

    from .._data import read_record
    from .._measured._model_file import load_model
    from ._loop import _name

    if args.init_samples is not None and args.init_samples < 0:
        raise CLIError(f"--init-samples must be >= 0, got {args.init_samples}.")
    saved = load_model(args.model)
    options = record_options(
        argparse.Namespace(
            input=args.input or saved.input_column,
            output=args.output or saved.output_column,
            # the model's time column unless --ts gives the period of records without one
            time=args.time or (saved.time_column if args.ts is None else None),
            ts=args.ts,
            units=args.units,
            detrend=saved.detrend,
            decimate=saved.decimation,
        )
    )
    if options["sample_period"] is None and options["time_column"] is None and saved.sample_period:
        # a record without time column or --ts: taken at the model's period
        options["sample_period"] = saved.sample_period / saved.decimation
    options["input_unit"] = options["input_unit"] or saved.input_unit
    options["output_unit"] = options["output_unit"] or saved.output_unit
    records = [
        read_record(spec, **options, anti_alias=saved.anti_alias, scaling=saved.scaling)
        for spec in args.records
    ]
    for record in records:  # all refused before any work
        saved.check_period(record)
    folder = pathlib.Path(args.report) if args.report else None
    if folder is not None:
        writable_folder(folder, "--report")
    comparisons = [saved.compare(r, args.init_samples, name=_name(r)) for r in records]
    unit = records[0].output_unit or "output unit"
    result = {
        "model": str(args.model),
        "structure": saved.model.structure(),
        "sample_period": saved.sample_period,
        "decimation": saved.decimation,
        "unit": records[0].output_unit,
        "records": [c.to_dict() for c in comparisons],
    }
    if folder is not None:
        from .._plot._comparison import plot_comparison

        (folder / "simulate.json").write_text(strict_json(result, indent=1))
        (folder / "simulate.md").write_text(_markdown(result, unit))
        for k, c in enumerate(comparisons, 1):
            plot_comparison(
                c,
                folder / f"simulate_{k}.png",
                title=f"{c.score.record}: measured vs {result['structure']}",
                units=unit,
            )
    if args.json:
        print(strict_json(result))
    else:
        print(_markdown(result, unit), end="")
        if folder is not None:
            print(f"report: {folder / 'simulate.md'}")
    return 0


def _f(value, digits: int = 4) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _markdown(result: dict, unit: str) -> str:
    rows = result["records"]
    lines = [
        f"model: `{result['structure']}` ({result['model']})",
        "",
        "| record | samples | init samples | NRMSE | fit % | RMSE "
        f"({unit}) | NRMSE, from rest | fit %, from rest | RMSE, from rest |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['record']} | {r['samples']} | {r['init_samples']} | {_f(r['error'])} | "
            f"{_f(r['fit_percent'], 1)} | {r['rmse']:.4g} | {_f(r['error_from_rest'])} | "
            f"{_f(r['fit_percent_from_rest'], 1)} | {r['rmse_from_rest']:.4g} |"
        )
    lines += [
        "",
        "Initialised: the state set from the measured output on the first init samples, "
        "scored after them; from rest: the whole record simulated from rest. NRMSE is "
        "normalised by the output's standard deviation (1 is the mean).",
    ]
    return "\n".join(lines) + "\n"


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
