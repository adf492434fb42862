"""Issue 24: the estimators under coloured and heavy-tailed output noise.

    python benchmarks/noise_study.py [--realisations 200] [--seed 0] [--out results/noise_study]
        [--report-only]

Example 1 (N 4000) and Example 2 (N 2000), SNR 25 (`sqrt(var y / var e)` of the noise as
added); noise white, AR(1) with pole 0.5, 0.9 and 0.97, a resonance (AR(2) with the
conjugate poles 0.95 exp(+-0.6 i): `poles = [[0.95, 0.6]]`), Student-t with 3 degrees
of freedom, and 2 % outliers of 10 standard deviations (the sweep's noise kinds, `[noise]`
of a spec); estimators literal, robust and pem, which fit the same records in every cell
(common random numbers). One sweep per system and noise (`OUT/exampleE_NOISE.parquet`,
resumable). Writes `OUT.csv` (per system, noise, estimator and parameter: bias, std,
RMSE, recovered rate and the efficiency, each with its Monte-Carlo SE), `OUT.md` (the
median efficiency over the parameters per cell, the recovered rates, the largest
|bias| / SE, and the findings in words) and `OUT.png`; `--report-only` rewrites the
last two from `OUT.csv`.

**The bound.** Each record's Cramér-Rao bound is that of its noise: for AR noise the
coloured bound (`crlb(..., poles=...)`: the prediction-error Jacobian, whitened; it is
recomputed here from the cell's records, `_engine.records`, whatever bound the sweep
table holds); for white, Student-t and outlier noise the bound of Gaussian noise with
the noise's variance, the smallest covariance attainable from second-order statistics
(what least squares and pem attain). The exact bound of a heavy-tailed density is lower
by `sqrt(information_factor)` (Student-t 3 dof: variance halved; the outliers: a third);
`efficiency_exact` is the efficiency against it.
"""

from __future__ import annotations

import argparse
import pathlib
import time

SYSTEMS = {1: 4000, 2: 2000}
SNR = 25.0
ESTIMATORS = ("literal", "robust", "pem")
NOISES = {
    # label: (kind, settings)
    "white": ("white", {}),
    "ar0.5": ("ar", {"poles": [0.5]}),
    "ar0.9": ("ar", {"poles": [0.9]}),
    "ar0.97": ("ar", {"poles": [0.97]}),
    "resonance": ("ar", {"poles": [[0.95, 0.6]]}),
    "student_t3": ("student_t", {"dof": 3.0}),
    "outliers": ("outliers", {"fraction": 0.02, "size": 10.0}),
}
TARGET = 0.8  # pem's median efficiency at pole 0.9 (issue 24)


def spec_for(number: int, label: str, realisations: int, seed: int):
    from jaxcascade import Spec

    kind, settings = NOISES[label]
    return Spec(
        example=number,
        n=(SYSTEMS[number],),
        snr=(SNR,),
        realisations=realisations,
        seed=seed,
        estimators=ESTIMATORS,
        noise=kind,
        noise_settings=settings,
        chunk_size=50,
    )


def noise_bounds(spec, label: str):
    """Per realisation, the Cramér-Rao bound of the cell's noise (module docstring)."""
    import jax
    import numpy as np

    from jaxcascade import Cell, crlb
    from jaxcascade._montecarlo._engine import records

    kind, settings = NOISES[label]
    cell = Cell(spec.n[0], spec.snr[0], spec.estimators[0])
    u = records(spec, cell, range(spec.realisations))["u"]
    truth = spec.truth()
    poles = tuple(settings.get("poles", ())) if kind == "ar" else ()
    bound = jax.jit(jax.vmap(lambda u: crlb(truth, u, snr=SNR, poles=poles)))
    return np.concatenate([np.asarray(bound(u[i : i + 50])) for i in range(0, len(u), 50)])


def study(number: int, label: str, realisations: int, seed: int, out: pathlib.Path):
    import pandas as pd

    from jaxcascade import run, summarise
    from jaxcascade._estimator._efficiency import information_factor
    from jaxcascade._montecarlo._tables import crlb_column

    spec = spec_for(number, label, realisations, seed)
    path = out / f"example{number}_{label}.parquet"
    table = run(spec, path, resume=True, progress=False)
    bounds = noise_bounds(spec, label)
    names = spec.orders.names
    for estimator in ESTIMATORS:  # the rows of every estimator are the same records
        rows = (table["estimator"] == estimator).to_numpy()
        order = table.loc[rows, "realisation"].to_numpy()
        for j, name in enumerate(names):
            table.loc[rows, crlb_column(name)] = bounds[order, j]
    summary = summarise(table)
    kind, settings = NOISES[label]
    factor = information_factor(kind, **settings) if kind in ("student_t", "outliers") else 1.0
    summary.insert(1, "noise", label)
    summary["bound"] = "coloured" if kind == "ar" else "gaussian (second-order)"
    summary["efficiency_exact"] = summary["efficiency"] / factor
    summary["efficiency_exact_se"] = summary["efficiency_se"] / factor
    return pd.DataFrame(summary)


COLUMNS = [
    "system", "noise", "estimator", "parameter", "count", "used", "true", "bias", "bias_se",
    "std", "std_se", "rmse", "rmse_se", "recovered_rate", "recovered_rate_se", "crlb_std",
    "efficiency", "efficiency_se", "bound", "efficiency_exact", "efficiency_exact_se",
    "fit_seconds_mean",
]  # fmt: skip


def cells(table):
    """One row per system, noise and estimator: the median efficiency over the parameters,
    the recovered rate and the largest |bias| in Monte-Carlo SEs."""
    import numpy as np
    import pandas as pd

    rows = []
    for (system, noise, estimator), group in table.groupby(
        ["system", "noise", "estimator"], sort=False
    ):
        t = np.abs(group["bias"] / group["bias_se"]).to_numpy(float)
        worst = int(np.nanargmax(t)) if np.isfinite(t).any() else 0
        rows.append(
            {
                "system": system,
                "noise": noise,
                "estimator": estimator,
                "median_efficiency": float(np.nanmedian(group["efficiency"])),
                "median_efficiency_exact": float(np.nanmedian(group["efficiency_exact"])),
                "recovered_rate": float(group["recovered_rate"].iloc[0]),
                "recovered_rate_se": float(group["recovered_rate_se"].iloc[0]),
                "max_bias_over_se": float(t[worst]) if t.size else float("nan"),
                "max_bias_parameter": group["parameter"].iloc[worst],
                "bound": group["bound"].iloc[0],
            }
        )
    return pd.DataFrame(rows)


def findings(per_cell) -> list[str]:
    """The findings in words, from the numbers (nothing here is written by hand)."""
    lines = []
    for system, group in per_cell.groupby("system", sort=False):
        g = group.set_index(["noise", "estimator"])
        unbiased = [
            f"{e} under {n}"
            for (n, e), r in g.iterrows()
            if r["max_bias_over_se"] <= 3 and r["recovered_rate"] >= 0.95
        ]
        biased = [
            f"{e} under {n} ({r['max_bias_parameter']}: {r['max_bias_over_se']:.1f} SE)"
            for (n, e), r in g.iterrows()
            if r["max_bias_over_se"] > 3
        ]
        broken = [
            f"{n} ({r['recovered_rate']:.2f})"
            for (n, e), r in g.iterrows()
            if e == "literal" and r["recovered_rate"] < 0.9
        ]
        losing = [
            f"{e} under {n} ({r['median_efficiency']:.2f})"
            for (n, e), r in g.iterrows()
            if r["median_efficiency"] < 0.5 and e != "literal"
        ]
        literal = g.xs("literal", level="estimator")["median_efficiency"]
        same = [
            n
            for n in g.index.get_level_values("noise").unique()
            if abs(
                g.loc[(n, "pem"), "median_efficiency"] - g.loc[(n, "robust"), "median_efficiency"]
            )
            <= 0.02
        ]
        pem = g.loc[("ar0.9", "pem"), "median_efficiency"] if ("ar0.9", "pem") in g.index else None
        lines += [
            f"### {system}",
            "",
            "- No bias beyond 3 Monte-Carlo SEs on any parameter and recovered in 95 % or "
            f"more of the records: {', '.join(unbiased) or 'none'}.",
            f"- Biased (largest |bias| / SE): {', '.join(biased) or 'none'}.",
            f"- Where the paper's iteration breaks (recovered below 0.9): "
            f"{', '.join(broken) or 'nowhere in this study'}.",
            "- robust or pem with an efficiency below 0.5 against the bound of the noise "
            f"(median over the parameters): {', '.join(losing) or 'none'}; the paper's "
            f"iteration's median efficiency is {literal.min():.2g}-{literal.max():.2g} "
            "under every noise.",
            "- pem gives robust's efficiency (within 0.02) where its noise model adds "
            f"nothing: {', '.join(same) or 'nowhere'}.",
        ]
        if pem is not None:
            verdict = "meets" if pem >= TARGET else "misses"
            lines.append(
                f"- pem at pole 0.9: median efficiency {pem:.2f}, {verdict} the target {TARGET}."
            )
        lines.append("")
    return lines


def markdown(table, per_cell, command: str) -> str:
    lines = [
        "# Estimators under coloured and heavy-tailed output noise (issue 24)",
        "",
        f"`{command}`",
        "",
        f"Example 1 (N {SYSTEMS[1]}) and Example 2 (N {SYSTEMS[2]}), SNR {SNR:g}; "
        f"{int(table['count'].iloc[0])} realisations a cell, the same records for every "
        "estimator. Efficiency = bound² / std² against the bound of the cell's noise: "
        "coloured (AR: the whitened prediction-error Jacobian) or, for white, Student-t "
        "and outlier noise, the Gaussian bound of the noise's variance (the second-order "
        "bound least squares and pem can attain); `exact`: against the heavy-tailed "
        "density's own bound (lower by sqrt(information_factor)). Per-parameter figures "
        "with their SEs: the CSV.",
        "",
        "## Findings",
        "",
        *findings(per_cell),
        "## Per cell",
        "",
        "| system | noise | estimator | median efficiency | (exact) | recovered | "
        "largest abs(bias)/SE |",
        "|---|---|---|---:|---:|---:|---|",
    ]
    for _, r in per_cell.iterrows():
        lines.append(
            f"| {r['system']} | {r['noise']} | {r['estimator']} | "
            f"{r['median_efficiency']:.2f} | {r['median_efficiency_exact']:.2f} | "
            f"{r['recovered_rate']:.3f} ± {r['recovered_rate_se']:.3f} | "
            f"{r['max_bias_over_se']:.1f} ({r['max_bias_parameter']}) |"
        )
    return "\n".join(lines) + "\n"


def figure(per_cell, path: pathlib.Path) -> None:
    import numpy as np
    from matplotlib.figure import Figure

    systems = list(dict.fromkeys(per_cell["system"]))
    fig = Figure(figsize=(11, 4), layout="constrained")
    axes = fig.subplots(1, len(systems), sharey=True)
    labels = list(NOISES)
    width = 0.8 / len(ESTIMATORS)
    for ax, system in zip(np.atleast_1d(axes), systems, strict=True):
        group = per_cell[per_cell["system"] == system].set_index(["noise", "estimator"])
        for k, estimator in enumerate(ESTIMATORS):
            values = [group["median_efficiency"].get((n, estimator), np.nan) for n in labels]
            ax.bar(np.arange(len(labels)) + k * width, values, width, label=estimator)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.axhline(TARGET, color="k", lw=0.8, ls=":")
        ax.set_xticks(np.arange(len(labels)) + width, labels, rotation=30)
        ax.set_yscale("log")
        ax.set_title(f"{system}, SNR {SNR:g}")
    np.atleast_1d(axes)[0].set_ylabel("median efficiency over the parameters")
    np.atleast_1d(axes)[0].legend(loc="lower left")
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realisations", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/noise_study")
    parser.add_argument("--report-only", action="store_true", help="rewrite OUT.md, OUT.png")
    args = parser.parse_args(argv)
    command = (
        f"python benchmarks/noise_study.py --realisations {args.realisations} "
        f"--seed {args.seed} --out {args.out}"
    )
    if args.report_only:
        import pandas as pd

        out = pathlib.Path(args.out)
        table = pd.read_csv(out.with_suffix(".csv"))
        per_cell = cells(table)
        out.with_suffix(".md").write_text(markdown(table, per_cell, command))
        figure(per_cell, out.with_suffix(".png"))
        return 0

    import jax

    jax.config.update("jax_enable_x64", True)
    import pandas as pd

    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tables = []
    for number in SYSTEMS:
        for label in NOISES:
            start = time.perf_counter()
            tables.append(study(number, label, args.realisations, args.seed, out))
            print(f"example{number} {label}: {time.perf_counter() - start:.0f} s", flush=True)
    table = pd.concat(tables, ignore_index=True)[COLUMNS]
    table.to_csv(out.with_suffix(".csv"), index=False)
    per_cell = cells(table)
    out.with_suffix(".md").write_text(markdown(table, per_cell, command))
    figure(per_cell, out.with_suffix(".png"))
    print(per_cell.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    written = ", ".join(str(out.with_suffix(s)) for s in (".csv", ".md", ".png"))
    print(f"written: {written}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
