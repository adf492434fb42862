"""`jaxcascade sweep`: a Monte-Carlo sweep from a TOML spec or from options."""

from __future__ import annotations

import pathlib
import sys
import warnings

from .._names import FAMILIES, INPUTS, NOISES
from ._common import (
    CLIError,
    estimator_help,
    examples,
    kind_help,
    kind_with_settings,
    name_list,
    number_list,
    parse_orders,
    writable_folder,
)


def spec_from_args(args):
    """The spec (`Spec`) of a `sweep` command line: a TOML file, overridden by the
    options given."""
    from .._montecarlo._spec import InputRangeWarning, Spec, read_toml

    data = {}
    if args.spec is not None:
        data = read_toml(args.spec)
    elif args.example is None and args.system is None:
        raise CLIError("give a spec file, --example or --system (see 'jaxcascade sweep --help').")
    if args.example is not None and args.system is not None:
        raise CLIError("give either --example or --system, not both.")
    if args.example is not None:
        system = data.pop("system", None)
        if isinstance(system, dict) and "change" in system:
            data["system"] = {"change": system["change"]}  # the change stays
        data["example"] = args.example
    if args.system is not None:
        data.pop("example", None)
        data["system"] = {"family": args.system}
    if args.orders is not None:
        if "example" in data:
            raise CLIError("--orders needs a family or explicit system; an example has its own.")
        system = data.get("system", {})
        system = {"family": system} if isinstance(system, str) else dict(system)
        data["system"] = {**system, "orders": str(parse_orders(args.orders))}
    for field, value in (
        ("n", args.n),
        ("snr", args.snr),
        ("realisations", args.realisations),
        ("seed", args.seed),
        ("estimators", args.estimator),
        ("chunk_size", args.chunk_size),
        ("workers", args.workers),
        ("scheduler", args.scheduler),
    ):
        if value is not None:
            data[field] = value
    if args.input_kind is not None:  # a kind replaces the file's whole [input] table
        kind, settings = args.input_kind
        data["input"] = {"kind": kind, **settings}
    if args.noise is not None:
        kind, settings = args.noise
        data["noise"] = {"kind": kind, **settings}
    if args.amplitude is not None:
        table = data.get("input", {})
        table = {"kind": table} if isinstance(table, str) else dict(table)
        table.pop("rms", None)
        data["input"] = {**table, "amplitude": args.amplitude}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", InputRangeWarning)
        spec = Spec.from_dict(data)
    for warning in caught:  # one line each, as the errors
        if issubclass(warning.category, InputRangeWarning):
            print(f"jaxcascade: warning: {warning.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(
                warning.message, warning.category, warning.filename, warning.lineno
            )
    return spec


def check_baseline(spec, baseline, path) -> None:
    """Refuse, before the sweep runs, a `--compare` baseline that shares no grid cell
    (system, N, SNR, estimator) and parameter with the sweep `spec` will run."""
    planned = {(spec.system, int(c.n), float(c.snr), c.estimator) for c in spec.cells()}
    stored = set(
        zip(
            baseline["system"].astype(str),
            baseline["n"].astype("int64"),
            baseline["snr"].astype("float64"),
            baseline["estimator"].astype(str),
            strict=True,
        )
    )
    shared = planned & stored
    names = set(baseline["parameter"].astype(str)) & set(spec.orders.names)
    if shared and names:
        return

    def listed(cells):
        cells = sorted(cells)
        shown = ", ".join(
            f"{system} N={n} SNR={snr:g} {name}" for system, n, snr, name in cells[:3]
        )
        return shown + (f" and {len(cells) - 3} more" if len(cells) > 3 else "")

    what = (
        f"no grid cell: it holds {listed(stored)}, the sweep runs {listed(planned)}"
        if not shared
        else f"no parameter: it holds {', '.join(sorted(set(baseline['parameter'].astype(str))))}"
    )
    raise CLIError(f"--compare: baseline '{path}' shares {what}; compare with a matching summary.")


def _print_cells(summary) -> None:
    from .._montecarlo._tables import CELL_COLUMNS

    cells = summary.drop_duplicates(CELL_COLUMNS)
    columns = [*CELL_COLUMNS, "count", "used", "converged_rate", "recovered_rate", "nrmse_median"]
    print(cells[columns].to_string(index=False, float_format=lambda v: f"{v:.4g}"))


def _experiment_line(spec, summary) -> str:
    """The input design and noise in one line, with the records' rms and crest factor
    (settings as the TOML lists they were, not the tuples they are frozen as)."""
    from .._montecarlo._spec import _listed

    settings = ", ".join(f"{k} = {v}" for k, v in _listed(spec.input_settings).items())
    noise = ", ".join(f"{k} = {v}" for k, v in _listed(spec.noise_settings).items())
    first = summary.iloc[0]
    return (
        f"input: {spec.input} ({settings}); records' rms {first['input_rms_mean']:.4g}, "
        f"crest factor median {first['input_crest_median']:.3g}; noise: {spec.noise}"
        + (f" ({noise})" if noise else "")
    )


def _tracking(spec, table, out, plots) -> None:
    """A system that changes: the tracking summary (`OUT.tracking.csv`), the true
    parameters at the recorded samples (`OUT.trajectory.csv`) and, with `--plots`, the
    median error trajectories with quantile bands."""
    from .._montecarlo._tables import tracking_summary, true_trajectory

    summary = tracking_summary(table)
    path = out.with_name(out.name.removesuffix(".parquet") + ".tracking.csv")
    summary.to_csv(path, index=False)
    truth = true_trajectory(spec)
    truth_path = out.with_name(out.name.removesuffix(".parquet") + ".trajectory.csv")
    truth.to_csv(truth_path, index=False)
    columns = ["n", "snr", "before_change_rate", "reentered_rate", "settled_rate"]
    columns += ["reentry_median", "steady_rmse", "steady_rmse_changed"]
    print(summary[columns].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(f"written: {path}, {truth_path}")
    if plots:
        from .._plot._tracking import tracking_figures

        stem = out.name.removesuffix(".parquet")
        paths = tracking_figures(spec, table, plots, stem)
        print(f"plots: {', '.join(str(p) for p in paths)}")


def sweep(args) -> int:
    # imported here, not at the top: `--help` answers without importing JAX
    from .._montecarlo._run import run, summary_path
    from .._montecarlo._tables import CELL_COLUMNS, compare_sweeps, read_summary, summarise
    from .._plot._sweep import plot_sweep, sweep_figures

    spec = spec_from_args(args)
    if args.out is None:
        if args.spec is None:
            raise CLIError("--out is required without a spec file (e.g. results/NAME.parquet).")
        args.out = str(pathlib.Path("results") / (pathlib.Path(args.spec).stem + ".parquet"))
    out = pathlib.Path(args.out)
    if out.suffix != ".parquet":
        raise CLIError(f"--out must name a .parquet file, got '{out}'.")
    baseline = None
    if args.compare:
        try:
            baseline = read_summary(args.compare)
        except ValueError as error:
            raise CLIError(f"--compare: {error}") from None
        check_baseline(spec, baseline, args.compare)
    writable_folder(out.parent)
    if args.plots:
        writable_folder(args.plots, "--plots")

    if args.resume and args.overwrite:
        raise CLIError("give either --resume or --overwrite, not both.")
    if args.overwrite and out.exists():
        print(f"--overwrite: replacing the previous '{out}' and its summary and plots.")
    table = run(
        spec,
        out,
        resume=args.resume,
        overwrite=args.overwrite,
        progress=None,
        command=["jaxcascade", *sys.argv[1:]],
    )
    summary = summarise(table)  # `run` wrote it beside `out`, `summary_path(out)`
    _print_cells(summary)
    if spec.input != "uniform" or spec.noise != "white":
        print(_experiment_line(spec, summary))
    print(f"written: {out}, {summary_path(out)}")
    if spec.change is not None:
        _tracking(spec, table, out, args.plots)
    if args.plots:
        stem = out.name.removesuffix(".parquet")
        old = set(sweep_figures(args.plots, stem))
        paths = plot_sweep(summary, table, args.plots, stem)
        if args.overwrite:  # figures of an earlier sweep of another shape would mislead
            for path in old - set(paths):
                path.unlink(missing_ok=True)
        print(f"plots: {', '.join(str(p) for p in paths)}")
    if baseline is not None:
        result = compare_sweeps(summary, baseline, args.threshold)
        flagged = result[result["flagged"]]
        checked = len(result)
        if flagged.empty:
            print(f"compare: no bias or std moved beyond Monte-Carlo error ({checked} checked).")
            return 0
        print(f"compare: {len(flagged)} of {checked} statistics moved beyond Monte-Carlo error:")
        columns = [*CELL_COLUMNS, "parameter", "statistic", "value", "baseline", "diff", "se", "z"]
        print(flagged[columns].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
        return 1
    return 0


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "sweep",
        help="Monte-Carlo sweep over SNR x N x estimator with bias/std/convergence tables",
        description=(
            "Run a Monte-Carlo sweep from a TOML spec or from options (options override "
            "the spec file). Writes OUT (one row per realisation, Parquet) and "
            "OUT.summary.csv; a killed run continues when started again."
        ),
        epilog=examples(
            "jaxcascade sweep --example 1 --snr 25 --n 4000 --realisations 100 "
            "--estimator literal,robust --out runs/quickstart.parquet --plots runs/quickstart "
            "--overwrite",
            "jaxcascade sweep --example 1 --snr 10,25,50 --n 1000,4000 --realisations 100 "
            "--out results/ex1.parquet",
            "jaxcascade sweep --example 1 --input-kind multisine --noise 'ar:poles = [0.9]' "
            "--realisations 100 --estimator robust --out runs/ar.parquet",
            "jaxcascade sweep spec.toml --out results/b.parquet --compare results/a.summary.csv",
        ),
    )
    parser.add_argument("spec", nargs="?", help="TOML spec file (see jaxcascade.Spec)")
    parser.add_argument(
        "--example",
        type=_example,
        help="paper example, 1 or 2, or general1 / general2 (the general backlash's, curved "
        "branches of degree 3)",
    )
    parser.add_argument(
        "--system",
        choices=FAMILIES,
        help="a family of systems: 'random' draws each realisation's system from the "
        "documented prior (default N 3000, SNR 30)",
    )
    parser.add_argument(
        "--orders", help="nR,nL,r,p of a family (default 2,2,2,2; at most 8,8,16,16)"
    )
    parser.add_argument(
        "--snr", type=number_list(float, "--snr"), help="e.g. 10,25,50 (inf = noise-free)"
    )
    parser.add_argument(
        "--n", type=number_list(int, "--n"), help="sample sizes, e.g. 500,1000,4000"
    )
    parser.add_argument("--realisations", type=int, help="records per grid cell")
    parser.add_argument("--seed", type=int, help="sweep seed (default 0)")
    parser.add_argument(
        "--estimator", type=name_list, help=f"e.g. literal or literal,robust ({estimator_help()})"
    )
    parser.add_argument(
        "--input-kind",
        metavar="KIND[:SETTINGS]",
        type=kind_with_settings("--input-kind"),
        help="the input design, replacing a spec file's [input] table; SETTINGS as in "
        "TOML, e.g. 'multisine:band = [0, 0.5], rms = 1' (default uniform; each kind "
        "scaled by amplitude or rms, default the paper's input power): " + kind_help(INPUTS),
    )
    parser.add_argument(
        "--amplitude",
        type=float,
        help="the input's amplitude: uniform in (-A, A) (default 2), or the bound of "
        "another kind that has one",
    )
    parser.add_argument(
        "--noise",
        metavar="KIND[:SETTINGS]",
        type=kind_with_settings("--noise"),
        help="the output noise, replacing a spec file's [noise] table, e.g. "
        "'ar:poles = [0.9]', 'student_t:dof = 3', 'outliers:fraction = 0.02, size = 10' "
        "(default white; scaled to the SNR as added): " + kind_help(NOISES),
    )
    parser.add_argument(
        "--chunk-size",
        type=int,
        help="realisations per compiled batch (default 64 on a CPU, 1000 on a GPU)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        metavar="W",
        help="chunks run at once in this process, one host thread each (default 1): "
        "more throughput on several cores, the same rows, W chunks' memory; the "
        "timing columns then include the chunks' contention",
    )
    parser.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="run the chunks on this Dask scheduler's workers (pip install "
        "'jaxcascade[distributed]'); the default runs them in this process",
    )
    parser.add_argument("--out", help="results/NAME.parquet (default results/SPEC.parquet)")
    parser.add_argument(
        "--resume", action="store_true", help="reuse a finished OUT (a killed run continues anyway)"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a finished OUT, its summary and its plots (without --resume or "
        "--overwrite an existing OUT is refused)",
    )
    parser.add_argument("--compare", metavar="BASELINE", help="baseline summary to compare with")
    parser.add_argument(
        "--threshold", type=float, default=3.0, help="flag |diff| > T * combined MC error (3)"
    )
    parser.add_argument(
        "--plots",
        metavar="DIR",
        help="write the figures that fit the sweep's shape to DIR (one cell: distributions "
        "with the truth and the Cramér-Rao bound, rates, efficiency; a grid: also bias, "
        "RMSE and std versus SNR and N)",
    )
    parser.set_defaults(func=sweep)


def _example(text: str) -> int | str:
    """`--example`: a paper example's number, or a general-backlash example's name."""
    return int(text) if text.strip().lstrip("-").isdigit() else text.strip()
