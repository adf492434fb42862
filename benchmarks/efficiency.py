"""Issue 13: statistical efficiency of the paper's iteration and of the robust estimator
against the output-error Cramér-Rao bound.

    python benchmarks/efficiency.py [--realisations 100] [--seed 0] [--out results/efficiency]

Example 1 and Example 2 over SNR 10, 25, 50 and N 500, 1000, 4000, each one
`jaxcascade sweep` with both estimators (`OUT/exampleE.parquet` and its summary; every
realisation carries its record's own bound). Writes `OUT.csv` (one row per system, N,
SNR, estimator and parameter: std, crlb_std, efficiency = crlb_std^2 / std^2, each with
its Monte-Carlo standard error), `OUT.md` (the efficiency per parameter at the paper's
SNR 25 and N 4000, the median over parameters in every cell) and `OUT.png` (efficiency
bars at SNR 25, N 4000, and the standard deviations against N with the bound).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

GRID = {"n": (500, 1000, 4000), "snr": (10.0, 25.0, 50.0)}
COLUMNS = [
    "system", "n", "snr", "estimator", "parameter", "used", "std", "std_se", "crlb_std",
    "crlb_std_se", "efficiency", "efficiency_se", "recovered_rate",
]  # fmt: skip


def markdown(table, header: str) -> str:
    import numpy as np

    lines = [header, ""]
    paper = table[(table["n"] == 4000) & (table["snr"] == 25.0)]
    names = list(dict.fromkeys(paper["parameter"]))
    lines += [
        "## Efficiency per parameter at N 4000, SNR 25 (± Monte-Carlo SE)",
        "",
        "| system | estimator | " + " | ".join(names) + " |",
        "|---|---|" + "---:|" * len(names),
    ]
    for (system, estimator), rows in paper.groupby(["system", "estimator"], sort=False):
        rows = rows.set_index("parameter")
        cells = [
            f"{rows.loc[n, 'efficiency']:.2f} ± {rows.loc[n, 'efficiency_se']:.2f}" for n in names
        ]
        lines.append(f"| {system} | {estimator} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Median and range of the efficiency over the parameters, every cell",
        "",
        "| system | estimator | N | SNR | used | median | min (parameter) | max (parameter) |",
        "|---|---|---:|---:|---:|---:|---|---|",
    ]
    keys = ["system", "estimator", "n", "snr"]
    for (system, estimator, n, snr), rows in table.groupby(keys, sort=False):
        e = rows["efficiency"].to_numpy(float)
        if not np.isfinite(e).any():
            continue
        low, high = int(np.nanargmin(e)), int(np.nanargmax(e))
        lines.append(
            f"| {system} | {estimator} | {n} | {snr:g} | {int(rows['used'].iloc[0])} "
            f"| {np.nanmedian(e):.2f} | {e[low]:.2f} ({rows['parameter'].iloc[low]}) "
            f"| {e[high]:.2f} ({rows['parameter'].iloc[high]}) |"
        )
    return "\n".join(lines) + "\n"


def figure(table, path) -> None:
    import numpy as np
    from matplotlib.figure import Figure

    systems = list(dict.fromkeys(table["system"]))
    fig = Figure(figsize=(13, 3.8 * len(systems)), layout="constrained")
    axes = fig.subplots(len(systems), 2, squeeze=False)
    for row, system in zip(axes, systems, strict=True):
        data = table[table["system"] == system]
        cell = data[(data["n"] == 4000) & (data["snr"] == 25.0)]
        names = list(dict.fromkeys(cell["parameter"]))
        estimators = list(dict.fromkeys(cell["estimator"]))
        width = 0.8 / len(estimators)
        x = np.arange(len(names))
        for k, estimator in enumerate(estimators):
            rows = cell[cell["estimator"] == estimator].set_index("parameter").reindex(names)
            row[0].bar(
                x + (k - (len(estimators) - 1) / 2) * width,
                rows["efficiency"],
                width,
                yerr=1.96 * rows["efficiency_se"],
                capsize=2,
                label=estimator,
            )
        row[0].axhline(1.0, color="k", lw=0.8, ls="--")
        row[0].set_xticks(x, names, fontsize=8)
        row[0].set_ylabel("efficiency")
        row[0].set_title(f"{system}, N 4000, SNR 25 (95% MC bars)", fontsize=10)
        row[0].legend(fontsize=8)
        # std against N at SNR 25 for a few parameters, with the bound
        snr25 = data[data["snr"] == 25.0]
        for name in names[:: max(1, len(names) // 4)]:
            for estimator, style in zip(estimators, ("o-", "s-"), strict=False):
                line = snr25[(snr25["parameter"] == name) & (snr25["estimator"] == estimator)]
                label = f"{name} {estimator}"
                row[1].loglog(line["n"], line["std"], style, ms=3, lw=1, label=label)
            bound = snr25[snr25["parameter"] == name].drop_duplicates("n").sort_values("n")
            row[1].loglog(bound["n"], bound["crlb_std"], "k--", lw=0.8)
        row[1].set_xlabel("N")
        row[1].set_ylabel("std (dashed: Cramér-Rao bound)")
        row[1].set_title(f"{system}, SNR 25", fontsize=10)
        row[1].legend(fontsize=6, ncol=2)
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realisations", type=int, default=100, help="per cell (100)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--chunk-size", type=int, default=50)
    parser.add_argument("--out", default="results/efficiency", help="output stem")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)

    from jaxcascade._cli import enable_float64

    enable_float64()

    import pandas as pd

    from jaxcascade._montecarlo._run import run, summary_path
    from jaxcascade._montecarlo._spec import Spec
    from jaxcascade._montecarlo._tables import summarise

    stem = pathlib.Path(args.out)
    folder = stem.parent / stem.name
    folder.mkdir(parents=True, exist_ok=True)
    command = ["python", "benchmarks/efficiency.py", *sys.argv[1:]]
    summaries = []
    for example in (1, 2):
        spec = Spec(
            example=example,
            n=GRID["n"],
            snr=GRID["snr"],
            realisations=args.realisations,
            seed=args.seed,
            estimators=("literal", "robust"),
            chunk_size=args.chunk_size,
        )
        out = folder / f"example{example}.parquet"
        start = time.perf_counter()
        table = run(spec, out, resume=True, progress=not args.quiet, command=command)
        summary = summarise(table)
        summary.to_csv(summary_path(out), index=False)
        summaries.append(summary)
        print(f"example {example}: {len(table)} fits in {time.perf_counter() - start:.1f} s")

    table = pd.concat(summaries, ignore_index=True)[COLUMNS]
    csv = stem.with_name(stem.name + ".csv")
    table.to_csv(csv, index=False)
    header = (
        f"# Efficiency against the output-error Cramér-Rao bound\n\n"
        f"{args.realisations} realisations per cell, seed {args.seed} "
        f"(`{' '.join(command)}`). Efficiency = crlb_std^2 / std^2, the bound's variance "
        "over the Monte-Carlo variance of the estimates (admissible ones); 1 means the "
        "estimator uses all the information in the record. The bound of a cell is the "
        "root mean square of its records' own bounds (jaxcascade._estimator._efficiency)."
    )
    stem.with_name(stem.name + ".md").write_text(markdown(table, header))
    figure(table, stem.with_name(stem.name + ".png"))
    print(f"written: {csv}, {stem}.md, {stem}.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
