"""`jaxcascade bench`: the performance benchmark (`_benchmark`), its text report
(`_benchmark._text`) printed or its summary as JSON, and its record written as CSV."""

from __future__ import annotations

import pathlib

from .._names import BENCH_SYSTEMS
from ._common import CLIError, examples, strict_json, writable_folder


def run_robust_bench(args) -> int:
    from .._benchmark import _robust as robust_bench
    from .._benchmark._text import robust_text, write_csv
    from .._system._model import Orders

    n = args.n if args.n is not None else robust_bench.system_defaults(args.system)[0]
    realisations = args.realisations if args.realisations is not None else 256
    baseline = args.baseline_realisations if args.baseline_realisations is not None else 8
    checks = {
        "--realisations": (realisations, 1),
        "--n": (n, Orders().min_samples),
        "--baseline-realisations": (baseline, 1),
        "--repeats": (args.repeats, 1),
    }
    for flag, (value, low) in checks.items():
        if value < low:
            raise CLIError(f"{flag} must be at least {low}, got {value}.")
    out = pathlib.Path(args.out) if args.out else None
    if out is not None:
        writable_folder(out.parent, "--out")
    record = robust_bench.run_benchmark(
        args.system, realisations, baseline, n, args.repeats, args.seed, args.estimator
    )
    if out is not None:
        write_csv(record, out)
    print(strict_json(robust_bench.summary(record)) if args.json else robust_text(record))
    return 0


def run_recursive_bench(args) -> int:
    from .._benchmark import _recursive as recursive_bench
    from .._benchmark._text import recursive_text, write_csv
    from .._system._examples import example as get_example

    ex = get_example(args.example)
    n = args.n if args.n is not None else ex.n_samples
    realisations = args.realisations if args.realisations is not None else 256
    baseline = args.baseline_realisations if args.baseline_realisations is not None else 2
    checks = {
        "--realisations": (realisations, 1),
        "--n": (n, ex.orders.min_samples),
        "--baseline-realisations": (baseline, 1),
        "--repeats": (args.repeats, 1),
    }
    for flag, (value, low) in checks.items():
        if value < low:
            raise CLIError(f"{flag} must be at least {low}, got {value}.")
    if baseline > realisations:
        raise CLIError(
            f"--baseline-realisations ({baseline}) cannot exceed --realisations ({realisations})."
        )
    if not args.sample_rate > 0:
        raise CLIError(f"--sample-rate must be positive, got {args.sample_rate}.")
    defaults = recursive_bench.default_first_samples()
    if n <= defaults:
        raise CLIError(f"--n must exceed the recursion's first iteration ({defaults} samples).")
    out = pathlib.Path(args.out) if args.out else None
    if out is not None:
        writable_folder(out.parent, "--out")
    record = recursive_bench.run_benchmark(
        realisations, n, args.example, baseline, args.repeats, args.seed, args.sample_rate
    )
    if out is not None:
        write_csv({k: v for k, v in record.items() if k != "settings"}, out)
    print(strict_json(recursive_bench.summary(record)) if args.json else recursive_text(record))
    return 0


def run_bench(args) -> int:
    # imported here, not at the top: `--help` answers without importing JAX
    from .._benchmark._text import literal_text, write_csv
    from .._benchmark._timing import run_benchmark, summary
    from .._estimator import lookup
    from .._system._examples import example as get_example

    try:
        lookup(args.estimator)  # a user's estimator: registered or an entry point
    except ValueError as error:
        raise CLIError(f"--estimator: {error}") from None
    if args.workers is not None and args.estimator != "literal":
        raise CLIError("--workers applies to --estimator literal; leave it out for the others.")
    if args.estimator not in ("literal", "recursive"):
        return run_robust_bench(args)
    if args.estimator == "recursive":
        if args.system != "example1":
            raise CLIError("--system applies to --estimator robust (recursive: --example).")
        return run_recursive_bench(args)
    if args.system != "example1":
        raise CLIError("--system applies to --estimator robust (the literal bench is --example).")
    args.realisations = 1000 if args.realisations is None else args.realisations
    args.n = 4000 if args.n is None else args.n
    args.baseline_realisations = (
        20 if args.baseline_realisations is None else args.baseline_realisations
    )
    ex = get_example(args.example)
    checks = {
        "--realisations": (args.realisations, 1),
        "--n": (args.n, ex.orders.min_samples),
        "--iterations": (args.iterations, 1),
        "--baseline-realisations": (args.baseline_realisations, 1),
        "--matmul-size": (args.matmul_size, 1),
        "--repeats": (args.repeats, 1),
        "--baseline-threads": (args.baseline_threads, 1),
        "--workers": (args.workers if args.workers is not None else 1, 1),
    }
    for flag, (value, low) in checks.items():
        if value < low:
            raise CLIError(f"{flag} must be at least {low}, got {value}.")
    out = pathlib.Path(args.out) if args.out else None
    if out is not None:
        writable_folder(out.parent, "--out")
    record = run_benchmark(
        args.realisations,
        args.n,
        args.iterations,
        args.example,
        args.baseline_realisations,
        args.matmul_size,
        args.repeats,
        args.seed,
        args.baseline_threads,
        args.backend,
        args.workers,
    )
    if out is not None:
        write_csv(record, out)
    print(strict_json(summary(record)) if args.json else literal_text(record))
    return 0


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "bench",
        help="benchmark the batched fit against NumPy/SciPy and the FLOP floor",
        description=(
            "Time the Monte-Carlo workload (simulation, noise, a fixed number of Vörös "
            "iterations per realisation) with jaxcascade's batched path, a NumPy/SciPy "
            "baseline and the float64 FLOP floor of this machine."
        ),
        epilog=examples(
            "jaxcascade bench --realisations 200 --n 2000 --json --out results/bench.csv",
            "jaxcascade bench --estimator robust --system example2 --json",
            "jaxcascade bench --estimator recursive --json",
        ),
    )
    parser.add_argument(
        "--estimator",
        default="literal",
        metavar="NAME",
        help="literal (default): a fixed number of Vörös iterations; robust: `robust` at "
        "its defaults against a SciPy output-error multi-start; recursive: sample updates "
        "per second of the recursive estimator against a NumPy loop; pem, or a user's "
        "registered estimator (register_estimator, entry point group "
        "jaxcascade.estimators): the robust workload at its defaults",
    )
    parser.add_argument(
        "--system",
        default="example1",
        choices=BENCH_SYSTEMS,
        help="robust, pem, a user's estimator: the system (example1 N 4000 SNR 25, "
        "example2 N 2000 SNR 25, random: the random family, N 3000 SNR 30)",
    )
    parser.add_argument(
        "--realisations",
        type=int,
        default=None,
        metavar="R",
        help="default 1000; robust, recursive 256",
    )
    parser.add_argument(
        "--n",
        type=int,
        default=None,
        metavar="N",
        help="samples per record (default 4000; robust: the system's; recursive: the example's)",
    )
    parser.add_argument(
        "--iterations",
        type=int,
        default=20,
        metavar="K",
        help="literal: Vörös iterations per realisation, a fixed number (default 20)",
    )
    parser.add_argument(
        "--example",
        type=int,
        default=1,
        choices=(1, 2),
        help="literal: the paper example whose records are fitted (default 1)",
    )
    parser.add_argument(
        "--baseline-realisations",
        type=int,
        default=None,
        metavar="B",
        help="realisations timed with the baseline (default 20; robust 8; recursive 2)",
    )
    parser.add_argument(
        "--baseline-threads",
        type=int,
        default=1,
        help="BLAS threads of the baseline process (default 1: its problems are tiny)",
    )
    parser.add_argument(
        "--matmul-size", type=int, default=2048, help="size of the float64 matmul for the floor"
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="timed runs; the best counts (robust: 1 is enough)"
    )
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed of the records (default 0)")
    parser.add_argument(
        "--sample-rate",
        type=float,
        default=1000.0,
        metavar="HZ",
        help="recursive: the sample rate of each record's stream for the real-time factor "
        "(default 1000 Hz)",
    )
    parser.add_argument(
        "--backend",
        default="auto",
        choices=("auto", "xla", "fused"),
        help="how the normal equations are formed (default auto: the fused CPU kernel "
        "where it applies)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="W",
        help="literal: host threads the realisations are split over, one part each "
        "(default: the cores this process may use; 1: one call)",
    )
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--out", default=None, help="also write every figure to this CSV file")
    parser.set_defaults(func=run_bench)
