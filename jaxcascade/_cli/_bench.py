"""`jaxcascade bench`: the performance benchmark (`_benchmark`)."""

from __future__ import annotations

import csv
import json
import pathlib
import time

from .._names import BENCH_SYSTEMS
from ._common import CLIError, examples, strict_json, writable_folder


def _report(r: dict) -> str:
    return "\n".join(
        [
            f"workload: Example {r['example']}, N = {r['n']}, SNR {r['snr']:g}, "
            f"{r['iterations']} iterations, {r['realisations']} realisations ({r['dtype']})",
            f"device: {r['device']}",
            f"jaxcascade ({r['backend']} normal equations, {r['workers']} host thread(s)): "
            f"{r['fits_per_s']:.1f} fits/s "
            f"({r['run_s']:.3f} s per run; compile {r['compile_s']:.2f} s, kernel build "
            f"{r['kernel_build_s']:.2f} s; statuses {r['status_counts']})",
            f"numpy baseline: {r['baseline_fits_per_s']:.2f} fits/s "
            f"({r['baseline_realisations']} realisations in {r['baseline_s']:.2f} s, "
            f"{r['baseline_threads']} BLAS thread(s))",
            f"ratio to baseline: {r['ratio']:.1f}",
            f"floor: {r['flops_per_fit'] / 1e6:.2f} MFlop per fit ({r['floor_count']}) at "
            f"{r['matmul_gflops']:.1f} "
            f"GFlop/s ({r['matmul_backend']} float64 matmul, {r['matmul_size']}^3) = "
            f"{r['floor_fits_per_s']:.0f} fits/s; fraction reached {r['floor_fraction']:.3f}",
            f"peak memory: {r['peak_mem_mb']:.0f} MB (peak RSS after the batched run)",
            f"load average as the timed runs started: {r['load']:.2f}",
        ]
    )


def _write_csv(record: dict, path: pathlib.Path) -> None:
    row = {key: value for key, value in record.items() if key != "status_counts"}
    if "status_counts" in record:
        row["status_counts"] = json.dumps(record["status_counts"])
    row["jax_version"] = __import__("jax").__version__
    row["date"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    with open(path, "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(row))
        writer.writeheader()
        writer.writerow(row)


def _robust_report(r: dict) -> str:
    return "\n".join(
        [
            f"workload: {r['estimator']} on {r['system']}, N = {r['n']}, SNR {r['snr']:g}, "
            f"{r['realisations']} realisations",
            f"device: {r['device']}",
            f"jaxcascade: {r['fits_per_s']:.1f} fits/s ({r['run_s']:.2f} s per run; compile "
            f"{r['compile_s']:.2f} s); recovered {r['recovered']:.3f} (converged "
            f"{r['converged']:.3f}, adaptive path {r['adaptive_fraction']:.3f})",
            f"scipy baseline: {r['baseline_fits_per_s']:.3f} fits/s "
            f"({r['baseline_realisations']} realisations in {r['baseline_s']:.1f} s)",
            f"ratio to baseline: {r['ratio']:.1f}",
        ]
    )


def run_robust_bench(args) -> int:
    from .._benchmark import _robust as robust_bench
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
        _write_csv(record, out)
    print(strict_json(robust_bench.summary(record)) if args.json else _robust_report(record))
    return 0


def _recursive_report(r: dict) -> str:
    return "\n".join(
        [
            f"workload: recursive over Example {r['example']}, N = {r['n']}, SNR {r['snr']:g}, "
            f"{r['realisations']} records at once",
            f"device: {r['device']}",
            f"jaxcascade: {r['updates_per_s']:.3g} sample updates/s ({r['run_s']:.3f} s per "
            f"run; compile {r['compile_s']:.2f} s; statuses {r['status_counts']})",
            f"numpy loop: {r['baseline_updates_per_s']:.3g} sample updates/s "
            f"({r['baseline_realisations']} records in {r['baseline_s']:.2f} s; largest "
            f"difference of the estimates {r['baseline_max_difference']:.1e})",
            f"ratio to the numpy loop: {r['ratio']:.0f}",
            f"real-time factor at {r['sample_rate_hz']:g} Hz per record: "
            f"{r['real_time_factor']:.0f}",
        ]
    )


def run_recursive_bench(args) -> int:
    from .._benchmark import _recursive as recursive_bench
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
        _write_csv({k: v for k, v in record.items() if k != "settings"}, out)
    print(strict_json(recursive_bench.summary(record)) if args.json else _recursive_report(record))
    return 0


def run_bench(args) -> int:
    # imported here, not at the top: `--help` answers without importing JAX
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
        _write_csv(record, out)
    print(strict_json(summary(record)) if args.json else _report(record))
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
