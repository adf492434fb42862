"""Issue 4: the literal Vörös iteration versus the robust estimator, on one grid.

    python benchmarks/robust_vs_literal.py [--realisations 200]
        [--out results/robust_vs_literal] [--estimators literal,robust]
        [--n N] [--chunk-size 64] [--seed 0] [--scheduler tcp://HOST:PORT]

Systems (input uniform in (-2, 2)): Example 1 at N = 4000 and Example 2 at N = 2000,
each at SNR 10, 25 and 50, and the random family (`--system random`: every realisation
draws its own system from the documented prior) at N = 3000, SNR 30. Every system is one
`jaxcascade sweep` run (`jaxcascade.run`) written to `OUT/SYSTEM.parquet`
with its summary; a killed run continues where it stopped when started again. The
comparison, one row per system x SNR x estimator, goes to `OUT.csv` and `OUT.md`:

- `converged_rate` (status converged) and `recovered_rate` (every parameter within
  0.05 of its truth, whatever the status), each with its Monte-Carlo standard error;
- `max_abs_bias` over the parameters (and which), `mean_std` (mean over the
  parameters), both over the estimates the summary uses (admissible, >= 1 step); for
  the random family the errors are taken against each row's own truth;
- `fit_ms_median`, `fit_ms_mean`: compute time per fit (a compiled chunk's wall time
  over its batch size, compilation excluded), and `compile_s` (one compilation);
- `count_<status>` for every status.

`--n` replaces every system's N (for quick checks only); `--scheduler` sends the chunks
to a Dask cluster (`docs/distributed.md`).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

from jaxcascade._status import Status  # noqa: E402  (light: no JAX)

STATUS_NAMES = tuple(s.name for s in Status)

# (label, spec fields): the issue-4 grid.
SYSTEMS = (
    ("example1", {"example": 1, "n": 4000, "snr": (10.0, 25.0, 50.0)}),
    ("example2", {"example": 2, "n": 2000, "snr": (10.0, 25.0, 50.0)}),
    ("random", {"family": "random", "n": 3000, "snr": (30.0,)}),
)


def specs(realisations: int, estimators, n=None, chunk_size=64, seed=0, scheduler=None):
    """The `Spec` of every system of the comparison, as `(label, spec)` pairs."""
    from jaxcascade._montecarlo._spec import Spec

    out = []
    for label, fields in SYSTEMS:
        fields = {**fields, "n": fields["n"] if n is None else n}
        extra = {} if scheduler is None else {"scheduler": scheduler}
        spec = Spec(
            **fields,
            realisations=realisations,
            estimators=tuple(estimators),
            chunk_size=chunk_size,
            seed=seed,
            **extra,
        )
        out.append((label, spec))
    return out


def comparison(summary):
    """One row per grid cell of a sweep summary (one row per cell and parameter)."""
    import numpy as np
    import pandas as pd

    rows = []
    keys = ["system", "n", "snr", "estimator"]
    for cell, group in summary.groupby(keys, sort=False):
        first = group.iloc[0]
        bias = group["bias"].abs().to_numpy(np.float64)
        worst = int(np.nanargmax(bias)) if np.isfinite(bias).any() else 0
        rows.append(
            {
                **dict(zip(keys, cell, strict=True)),
                "count": int(first["count"]),
                "used": int(first["used"]),
                "converged_rate": first["converged_rate"],
                "converged_rate_se": first["converged_rate_se"],
                "recovered_rate": first["recovered_rate"],
                "recovered_rate_se": first["recovered_rate_se"],
                "max_abs_bias": float(bias[worst]),
                "max_abs_bias_parameter": group["parameter"].iloc[worst],
                "mean_std": float(group["std"].mean()),
                "nrmse_median": first["nrmse_median"],
                "fit_ms_median": 1e3 * first["fit_seconds_median"],
                "fit_ms_mean": 1e3 * first["fit_seconds_mean"],
                "compile_s": first["compile_seconds"],
                **{f"count_{s}": int(first.get(f"count_{s}", 0)) for s in STATUS_NAMES},
            }
        )
    return pd.DataFrame(rows)


def markdown(table, header: str) -> str:
    """The comparison as a Markdown table (rates with their Monte-Carlo SE)."""

    def rate(value, se):
        return f"{value:.3f} ± {se:.3f}"

    lines = [
        header,
        "",
        "| system | N | SNR | estimator | n | converged | recovered | max abs bias "
        "| mean std | median ms/fit | mean ms/fit | compile s | failures by status |",
        "|---|---:|---:|---|---:|---|---|---|---:|---:|---:|---:|---|",
    ]
    for row in table.itertuples():
        failures = ", ".join(
            f"{s} {getattr(row, f'count_{s}')}"
            for s in STATUS_NAMES
            if s != "converged" and getattr(row, f"count_{s}")
        )
        lines.append(
            f"| {row.system} | {row.n} | {row.snr:g} | {row.estimator} | {row.count} "
            f"| {rate(row.converged_rate, row.converged_rate_se)} "
            f"| {rate(row.recovered_rate, row.recovered_rate_se)} "
            f"| {row.max_abs_bias:.4f} ({row.max_abs_bias_parameter}) | {row.mean_std:.4f} "
            f"| {row.fit_ms_median:.3g} | {row.fit_ms_mean:.3g} | {row.compile_s:.1f} "
            f"| {failures or '-'} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realisations", type=int, default=200, help="per cell (200)")
    parser.add_argument("--out", default="results/robust_vs_literal", help="output stem")
    parser.add_argument("--estimators", default="literal,robust")
    parser.add_argument("--n", type=int, help="replace every system's N (quick checks only)")
    parser.add_argument("--chunk-size", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scheduler", help="Dask scheduler address, tcp://HOST:PORT")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)

    from jaxcascade._cli import enable_float64

    enable_float64()  # like the CLI: float64, recorded in every table's metadata

    import pandas as pd

    from jaxcascade._montecarlo._run import run, summary_path
    from jaxcascade._montecarlo._tables import summarise

    stem = pathlib.Path(args.out)
    folder = stem.parent / stem.name
    folder.mkdir(parents=True, exist_ok=True)
    estimators = [e.strip() for e in args.estimators.split(",") if e.strip()]
    command = ["python", "benchmarks/robust_vs_literal.py", *sys.argv[1:]]
    summaries = []
    for label, spec in specs(
        args.realisations, estimators, args.n, args.chunk_size, args.seed, args.scheduler
    ):
        out = folder / f"{label}.parquet"
        start = time.perf_counter()
        table = run(spec, out, resume=True, progress=not args.quiet, command=command)
        summary = summarise(table)
        summary.to_csv(summary_path(out), index=False)
        summaries.append(summary)
        print(f"{label}: {len(table)} fits in {time.perf_counter() - start:.1f} s -> {out}")

    table = comparison(pd.concat(summaries, ignore_index=True))
    csv, md = stem.with_name(stem.name + ".csv"), stem.with_name(stem.name + ".md")
    table.to_csv(csv, index=False)
    header = (
        f"Literal versus robust, {args.realisations} realisations per cell, seed {args.seed} "
        f"(`{' '.join(command)}`). Recovered: every parameter within 0.05 of its truth, "
        "whatever the status. Bias and std over the admissible estimates; random family: "
        "against each realisation's own system. Time per fit: compiled chunk wall time / "
        "batch size."
    )
    md.write_text(markdown(table, header))
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(f"written: {csv}, {md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
