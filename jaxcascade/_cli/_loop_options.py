"""The options of `jaxcascade loop` (`_loop` runs it): the records (TRAIN, `--validate`,
`--test`, or `--benchmark NAME --data ROOT`), the windows, the loop's settings with the
measured-data defaults (`_defaults`), the report and resuming (`_loop_resume`)."""

from __future__ import annotations

import argparse

from .._names import EFFECTS, NOISE_MODEL, NOISE_MODEL_DESCRIPTION
from ._common import (
    RECORD_SPEC,
    add_record_arguments,
    examples,
    kind_help,
    name_list,
    span_option,
)
from ._loop_resume import add_arguments as add_resume_arguments


class DefaultDecimation(int):
    """`--decimate`'s default in `loop`: the measured-data default's value, told apart
    from the same factor given, which `--benchmark` takes as given."""


def add_parser(subparsers, run) -> None:
    """`jaxcascade loop` and its options; `run(args)` runs it (`_loop.run_loop`)."""
    from .. import _defaults as d

    parser = subparsers.add_parser(
        "loop",
        help="fit, test the residual, add the missing effect, report before/after",
        description=(
            "The model-error loop: fit the declared cascade on TRAIN, test its residual "
            "on the validation record, add the effect the residual points to, repeat."
        ),
        epilog=examples(
            "jaxcascade loop train.csv --validate valid.csv --input u --output y "
            "--time t --decimate 4 --report results/loop",
            "jaxcascade loop a.csv b.parquet --validate c.csv --window 3072:7680 --test d.csv "
            "--test-window 6144:14336 --input u --output y --decimate 8 --json",
            "jaxcascade loop --benchmark CED --data ../shared/data/nonlinear_benchmarks "
            "--report results/ced --json",
            "jaxcascade loop train.csv --validate valid.csv --input u --output y "
            "--report results/loop --resume",
        ),
    )
    add = parser.add_argument
    add(
        "train",
        nargs="*",
        metavar="TRAIN",
        help=f"estimation record(s), estimated jointly; each a record spec, {RECORD_SPEC}",
    )
    add(
        "--validate",
        nargs="+",
        action="extend",
        metavar="SPEC",
        help="validation record spec(s), as TRAIN (required with TRAIN): simulated, "
        "never fitted, to choose among the candidates; several are scored each from its "
        "own initial state and pooled (the loop's NRMSE, residual tests and significance "
        "test on their scored samples joined; the report's validation figures the mean "
        "over them)",
    )
    add(
        "--benchmark",
        metavar="NAME",
        help="a nonlinear system-identification benchmark read from --data: EMPS, CED, "
        "Silverbox, Cascaded_Tanks, WienerHammerBenchMark (its official split; estimation "
        "and validation records cut from its training data by one rule; its test records "
        "scored with its n_init, RMSE in its unit)",
    )
    add("--data", metavar="ROOT", help="with --benchmark: the folder holding NAME/ as distributed")
    add(
        "--max-samples",
        type=int,
        default=d.MAX_SAMPLES,
        help="with --benchmark: at most this many estimation samples (the latest of the "
        f"training data) and a quarter of it for validation (default {d.MAX_SAMPLES})",
    )
    add_record_arguments(parser, "loop", required=False)
    # the measured-data default (1), or with --benchmark the benchmarks' rule
    parser.set_defaults(decimate=DefaultDecimation(d.DECIMATE))
    parser._option_string_actions["--decimate"].help = (
        f"anti-aliased decimation factor (default {d.DECIMATE}; with --benchmark, the largest "
        "factor that brings the training data within --max-samples and that the signals' "
        "band allows: see the report)"
    )
    add(
        "--max-effects",
        type=int,
        default=d.MAX_EFFECTS,
        help=f"at most this many effects are added, one per round (default {d.MAX_EFFECTS}; "
        "0: fit and test only)",
    )
    add(
        "--window",
        type=span_option("--window"),
        help="START:STOP: also score the validation record on these samples of the file "
        "as stored (before decimation)",
    )
    add(
        "--effects",
        type=name_list,
        help="NAME,NAME: the effects of the library the loop considers (default: all): "
        + kind_help({**EFFECTS, NOISE_MODEL: NOISE_MODEL_DESCRIPTION}),
    )
    add(
        "--test",
        nargs="+",
        metavar="SPEC",
        help="test record spec(s), as TRAIN: scored with the final model only, used neither "
        "for fitting nor for choosing candidates (the only out-of-sample figures when the "
        "validation record chose the model)",
    )
    add(
        "--test-window",
        nargs="+",
        metavar="START:STOP",
        type=span_option("--test-window"),
        help="one scoring window per --test record, in samples of the file as stored",
    )
    add(
        "--init-samples",
        type=int,
        help="N: on every scored record the model's state (never its parameters) is set "
        "from the measured output on the N samples (after decimation) before the scored "
        "ones, the nonlinear benchmarks' convention; from-rest figures are reported beside "
        f"(default {d.INIT_SAMPLES}, at most {d.INIT_FRACTION:g} of the shortest validation "
        "or test record after decimation, said when it is cut; with --benchmark the "
        "benchmark's n_init; 0 scores from rest only)",
    )
    add(
        "--dm-threshold",
        type=float,
        default=d.DM_THRESHOLD,
        help="a candidate counts when its Diebold-Mariano statistic against the current "
        f"model exceeds this (default {d.DM_THRESHOLD:g}: with about ten candidates a round, "
        "a one-sided level near 0.001 each)",
    )
    add(
        "--min-gain",
        type=float,
        default=d.MIN_GAIN,
        help="... and it lowers the validation NRMSE by at least this fraction; when "
        "the loop stops, an effect whose removal costs less than this goes (the "
        f"backward step) (default {d.MIN_GAIN:g})",
    )
    add(
        "--seed",
        type=int,
        default=d.SEED,
        help="PRNG seed of the declared cascade's robust fit (its multi-start draws; "
        f"default {d.SEED})",
    )
    add(
        "--retries",
        type=int,
        default=d.RETRIES,
        help="repeats of the robust fit's multi-start from fresh draws while its estimate "
        f"fails the residual test (default {d.RETRIES})",
    )
    add(
        "--threads",
        type=int,
        help="candidates of a round fitted at once, in threads: the same results for any "
        "number (default: 2 where the process may use two or more cores, else 1)",
    )
    add(
        "--integrate",
        default=d.INTEGRATE,
        choices=("auto", "yes", "no"),
        help="model the output through its difference y(t) - y(t-1), integrated back for "
        "scoring: auto (the default) when no stable linear ARX model fits the estimation "
        "records (an output that integrates its input, a position under feedback)",
    )
    add(
        "--outliers",
        default=d.OUTLIERS,
        choices=("auto", "keep"),
        help="auto (the default): find isolated outliers (spikes) of the output in the "
        "final model's residual, leave those of the estimation and validation records out "
        "and run the loop again without them; the report names every record's with the "
        "error with and without them. keep: none looked for",
    )
    add(
        "--report",
        metavar="DIR",
        help="folder for the report and figures; the loop keeps its finished fits in "
        "DIR/checkpoints/ while it runs (see --resume)",
    )
    add(
        "--figures",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="draw the report's figures (default); --no-figures writes the report's "
        "tables and text without the PNG files, faster",
    )
    add_resume_arguments(parser)
    add("--json", action="store_true", help="print the JSON summary")
    add("--quiet", action="store_true", help="no progress on stderr")
    parser.set_defaults(func=run)
