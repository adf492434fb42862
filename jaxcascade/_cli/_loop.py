"""`jaxcascade loop`: the model-error loop on measured records, with its report.

The command parses its options (`_loop_options`), reads the record specs (or names a
benchmark), calls `_workflow._loop.loop_records` (`loop_benchmark`) and prints what it
returns: the summary lines or `--json` (`LoopRun.to_dict(brief=True)`), then the
verdict and coverage sentences. `--report DIR` writes the report (`LoopRun.report`:
`report.json`, `report.md`, `scores.csv`, `candidates.csv`, `model.json` and the
figures; `--no-figures` leaves the PNG files out). While the loop runs, every finished
fit and round is kept in `DIR/checkpoints/` (`_loop_resume`: `--resume`, `--overwrite`,
Ctrl-C).
"""

from __future__ import annotations

import sys

from ._common import CLIError, name_list, parse_orders, strict_json, writable_folder
from ._loop_options import DefaultDecimation


def _span(text: str | None, option: str) -> tuple[int, int] | None:
    """`START:STOP` as two integers (samples of the file as stored), or None."""
    if text is None:
        return None
    try:
        start, stop = (int(part) for part in text.split(":"))
    except ValueError:
        raise CLIError(f"{option} takes START:STOP in samples, got {text!r}.") from None
    return start, stop


def _check(args) -> None:
    """The options, refused in one line before anything is read."""
    from .._workflow._loop import check_settings

    check_settings(
        args.max_effects,
        args.dm_threshold,
        args.min_gain,
        args.retries,
        args.threads,
        args.init_samples,
        args.decimate,
    )
    if args.benchmark and (args.train or args.validate or args.test):
        raise CLIError(
            "--benchmark takes its records from the benchmark's files: drop TRAIN, "
            "--validate and --test."
        )
    if args.benchmark and not args.data:
        raise CLIError("--benchmark needs --data ROOT, the folder that holds NAME/ as distributed.")
    if args.benchmark and (args.window or args.test_window):
        raise CLIError("--window and --test-window do not apply with --benchmark.")
    if args.test_window and len(args.test_window) != len(args.test or []):
        raise CLIError(
            f"--test-window takes one START:STOP per --test record ({len(args.test or [])}), "
            f"got {len(args.test_window)}."
        )
    if args.window and len(args.validate or []) > 1:
        raise CLIError(
            f"--window scores one validation record; {len(args.validate)} were given to "
            "--validate: drop --window or give one."
        )


def run_loop(args) -> int:
    from ._loop_resume import run_kept

    return run_kept(args, _run_loop)


def _run_loop(args, checkpoints) -> int:
    from .._native import build_in_background

    # the declared cascade's robust fit needs the native kernel: on a machine's first
    # run it compiles on another core while this command imports and reads its records
    # (`_native`)
    build_in_background()
    # imported here, not at the top: `--help` answers without importing JAX
    from .._measured._report import summary
    from .._workflow._loop import loop_benchmark, loop_records

    orders = parse_orders(args.orders, "loop")
    _check(args)

    def say(message):
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)

    options = dict(
        orders=orders,
        max_effects=args.max_effects,
        effects=None if args.effects is None else name_list(args.effects),
        init_samples=args.init_samples,
        dm_threshold=args.dm_threshold,
        min_gain=args.min_gain,
        seed=args.seed,
        retries=args.retries,
        threads=args.threads,
        integrate=args.integrate,
        outliers=args.outliers,
        checkpoints=checkpoints,
        progress=say,
        command="jaxcascade loop " + " ".join(sys.argv[2:]),
    )
    if args.benchmark:
        if args.report:
            writable_folder(args.report, "--report")
        given = type(args.decimate) is not DefaultDecimation
        run = loop_benchmark(
            args.benchmark,
            args.data,
            max_samples=args.max_samples,
            decimate=args.decimate if given else None,
            scaling=args.scaling,
            **options,
        )
    else:
        training, validations, tests = _file_records(args)
        if args.report:
            writable_folder(args.report, "--report")
        run = loop_records(
            training,
            validations,
            tests,
            window=_span(args.window, "--window"),
            test_windows=[_span(t, "--test-window") for t in args.test_window or []] or None,
            **options,
        )
    if args.report:
        run.report(args.report, figures=args.figures)
    if args.json:
        print(strict_json(run.to_dict(brief=True)))
    else:
        print(summary(run.to_dict(), args.report))
    for sentence in [*run.warnings, *run.coverage_sentences, *run.outlier_sentences]:
        print(sentence, file=sys.stderr if args.json else sys.stdout)
    return 0


def _file_records(args):
    """Estimation, validation and test records read from the record specs on the command
    line (`RECORD_SPEC`), all in the estimation records' joint scaling."""
    from .._data import parse_record_spec, read_jointly
    from ._common import record_options

    specs = [*args.train, *(args.validate or []), *(args.test or [])]
    named = bool(specs) and all(parse_record_spec(spec).input is not None for spec in specs)
    needed = (
        ("TRAIN", args.train),
        ("--validate", args.validate),
        ("--input", args.input or named),
        ("--output", args.output or named),
    )
    missing = [option for option, value in needed if not value]
    if missing:
        raise CLIError(
            f"loop needs {', '.join(missing)} (or --benchmark NAME --data ROOT); see "
            "jaxcascade loop --help."
        )
    # Lengths are checked by the loop: the estimation records together, a scored record
    # against its initialisation window.
    options = record_options(args)
    return read_jointly(args.train, args.validate, args.test or (), **options, scaling=args.scaling)


def add_parser(subparsers) -> None:
    from ._loop_options import add_parser as add

    add(subparsers, run_loop)
