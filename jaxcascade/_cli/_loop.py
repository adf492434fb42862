"""`jaxcascade loop`: the model-error loop on measured records, with its report.

The command parses its options (`_loop_options`) into one `LoopSettings` (`_settings`),
calls `_workflow._loop.loop_command` with it (the settings checked, the record specs or
the benchmark read, the loop run on them as `loop_records` runs it) and prints what it
returns: the summary lines or `--json` (`LoopRun.to_dict(brief=True)`), then the
verdict and coverage sentences. `--report DIR` writes the report (`LoopRun.report`:
`report.json`, `report.md`, `scores.csv`, `candidates.csv`, `model.json` and the
figures; `--no-figures` leaves the PNG files out). While the loop runs, every finished
fit and round is kept in `DIR/checkpoints/` (`_loop_resume`: `--resume`, `--overwrite`,
Ctrl-C).
"""

from __future__ import annotations

import sys

from ._common import (
    CLIError,
    record_options,
    strict_json,
    writable_folder,
)
from ._loop_options import DefaultDecimation


def _check(args) -> None:
    """The options that do not go together, refused in one line before anything is
    read."""
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


def _settings(args, checkpoints):
    """The command line as one `LoopSettings` (`_workflow._loop`); its values were
    parsed as argparse read them (`--orders` as `Orders`, the windows as
    `(start, stop)`, `--effects` as names) and checked against each other (`_check`)."""
    from .._workflow._loop import LoopSettings

    def say(message):
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)

    given = type(args.decimate) is not DefaultDecimation
    return LoopSettings(
        train=tuple(args.train),
        validate=tuple(args.validate or ()),
        test=tuple(args.test or ()),
        read=None if args.benchmark else record_options(args),
        scaling=args.scaling,
        benchmark=args.benchmark,
        data=args.data,
        max_samples=args.max_samples,
        decimate=args.decimate if given else None,
        window=args.window,
        test_windows=tuple(args.test_window) if args.test_window else None,
        max_effects=args.max_effects,
        effects=None if args.effects is None else tuple(args.effects),
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
        orders=args.orders,
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
    from .._workflow._loop import loop_command

    _check(args)
    if args.report:
        writable_folder(args.report, "--report")
    settings = _settings(args, checkpoints)
    run = loop_command(settings)
    if args.report:
        run.report(args.report, figures=args.figures)
    if args.json:
        print(strict_json(run.to_dict(brief=True)))
    else:
        print(summary(run.to_dict(), args.report))
    for sentence in [*run.warnings, *run.coverage_sentences, *run.outlier_sentences]:
        print(sentence, file=sys.stderr if args.json else sys.stdout)
    return 0


def add_parser(subparsers) -> None:
    from ._loop_options import add_parser as add

    add(subparsers, run_loop)
