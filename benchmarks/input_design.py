"""Issue 24: which input design identifies which parameter best.

    python benchmarks/input_design.py [--realisations 200] [--seed 0]
        [--data ../shared/data/brfd] [--out results/input_design]

Five input designs at equal power (rms 2/sqrt(3), the paper's uniform input in (-2, 2)),
the robust estimator, white noise at SNR 25, Example 1 (N 4000) and Example 2 (N 2000):

- `uniform`: independent samples in (-2, 2) (the paper's);
- `gaussian`: independent Gaussian samples, std 2/sqrt(3);
- `multisine`: random phases on every DFT line (the full band);
- `multilevel`: continuous random levels, switching with probability 0.2 (held five
  samples on average);
- `file`: random segments of the shared friction damper's measured displacement
  (Kocaeli earthquake, `earthquake_kocaeli_dbe.csv`, read from `--data`, never copied;
  decimated by 4 to 256 Hz, 6,835 samples), each segment centred and scaled to the
  same power (`normalise = "segment"`).

Each cell is one sweep (`OUT/exampleE_KIND.parquet` with its summary, resumable). Writes
`OUT.csv` (per example, design and parameter: RMSE, bias, std, recovered rate, each
with its Monte-Carlo SE, and the RMSE relative to the uniform input with its SE: the
designs' records are independent, so the ratio's SE is the delta method's
`R sqrt((se_k / rmse_k)^2 + (se_u / rmse_u)^2)`; and each design's share of power below
5% of Nyquist, over 32 records) and `OUT.md` (the ratios, the best design per
parameter, and the findings in words, all from the numbers).

200 realisations a cell take about 7 minutes on 2 cores (most of it the file input of
Example 1, whose failing records go through the robust estimator's multi-start).
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
import time

EXAMPLES = {1: 4000, 2: 2000}
SNR = 25.0
RMS = 2.0 / math.sqrt(3.0)
RECORD = ("earthquake_kocaeli_dbe.csv", "displacement_in", 4)
LOW = 0.05  # a fraction of Nyquist: "slow" below it
BLOCKS = {
    "static nonlinearity (MR, DR, ML, DL)": ("MR", "DR", "ML", "DL"),
    "linear dynamics (a, b)": ("a", "b"),
    "backlash (cL, mR, cR)": ("cL", "mR", "cR"),
}
COLUMNS = [
    "system", "n", "snr", "input", "parameter", "true", "used", "rmse", "rmse_se",
    "rmse_ratio", "rmse_ratio_se", "bias", "bias_se", "std", "std_se", "recovered_rate",
    "recovered_rate_se", "input_rms_mean", "input_crest_median", "low_share",
    "fit_seconds_median",
]  # fmt: skip


def designs(data: pathlib.Path) -> dict[str, tuple[str, dict]]:
    """`{label: (kind, settings)}`, every one at the paper's input power."""
    name, column, decimate = RECORD
    return {
        "uniform": ("uniform", {"rms": RMS}),
        "gaussian": ("gaussian", {"std": RMS}),
        "multisine": ("multisine", {"rms": RMS, "band": [0.0, 1.0]}),
        "multilevel": ("multilevel", {"rms": RMS, "switch_probability": 0.2}),
        "file": (
            "file",
            {
                "path": str(data / name),
                "column": column,
                "decimate": decimate,
                "normalise": "segment",
                "rms": RMS,
            },
        ),
    }


def relative(table):
    """Each design's RMSE over the uniform input's, per example and parameter, with SE."""
    import numpy as np

    base = table[table["input"] == "uniform"].set_index(["system", "parameter"])
    keys = list(zip(table["system"], table["parameter"], strict=True))
    rmse_u = base.loc[keys, "rmse"].to_numpy(float)
    se_u = base.loc[keys, "rmse_se"].to_numpy(float)
    ratio = table["rmse"].to_numpy(float) / rmse_u
    same = (table["input"] == "uniform").to_numpy()
    spread = np.sqrt((table["rmse_se"].to_numpy(float) / table["rmse"]) ** 2 + (se_u / rmse_u) ** 2)
    return table.assign(rmse_ratio=ratio, rmse_ratio_se=np.where(same, 0.0, ratio * spread))


def block_of(name: str) -> str:
    stem = name.rstrip("0123456789")
    return next(label for label, stems in BLOCKS.items() if stem in stems)


def markdown(table, header: str) -> str:
    import numpy as np

    lines = [header, ""]
    kinds = list(dict.fromkeys(table["input"]))
    for system, rows in table.groupby("system", sort=False):
        n = int(rows["n"].iloc[0])
        names = list(dict.fromkeys(rows["parameter"]))
        pivot = rows.set_index(["input", "parameter"])
        lines += [
            f"## {system}, N {n}, SNR {SNR:g}: RMSE relative to the uniform input (± MC SE)",
            "",
            "| parameter | uniform RMSE | " + " | ".join(kinds) + " | best |",
            "|---|---:|" + "---:|" * len(kinds) + "---|",
        ]
        best_of = {}
        for name in names:
            cells = []
            for kind in kinds:
                r = pivot.loc[(kind, name)]
                cells.append(f"{r['rmse_ratio']:.2f} ± {r['rmse_ratio_se']:.2f}")
            ratios = np.array([pivot.loc[(k, name), "rmse_ratio"] for k in kinds])
            best = kinds[int(np.nanargmin(ratios))]
            best_of[name] = best
            uniform = pivot.loc[("uniform", name)]
            lines.append(
                f"| {name} | {uniform['rmse']:.3g} ± {uniform['rmse_se']:.2g} | "
                + " | ".join(cells)
                + f" | {best} |"
            )
        lines += [
            "",
            f"| design | recovered rate | records' rms | crest factor (median) | power below "
            f"{LOW:g} of Nyquist |",
            "|---|---:|---:|---:|---:|",
        ]
        for kind in kinds:
            r = rows[rows["input"] == kind].iloc[0]
            lines.append(
                f"| {kind} | {r['recovered_rate']:.2f} ± {r['recovered_rate_se']:.2f} | "
                f"{r['input_rms_mean']:.3f} | {r['input_crest_median']:.2f} | "
                f"{r['low_share']:.1%} |"
            )
        lines += ["", f"**{system} in words.**", ""]
        lines += findings(rows, kinds, best_of)
        lines.append("")
    return "\n".join(lines) + "\n"


def findings(rows, kinds, best_of) -> list[str]:
    """Plain sentences from the numbers: per block, the design with the smallest median
    RMSE ratio and on which parameters a design beats the uniform input by more than
    twice the ratio's SE; which designs lose; the low-frequency share behind a loss."""
    import numpy as np

    out = []
    pivot = rows.set_index(["input", "parameter"])

    def clearly(kind, name, sign):
        r = pivot.loc[(kind, name)]
        return sign * (r["rmse_ratio"] - 1) > 2 * r["rmse_ratio_se"]

    for label in BLOCKS:
        names = [n for n in best_of if block_of(n) == label]
        if not names:
            continue
        medians = {
            k: float(np.median([pivot.loc[(k, n), "rmse_ratio"] for n in names])) for k in kinds
        }
        order = sorted(medians, key=medians.get)
        wins = [
            f"{n} ({k}, {pivot.loc[(k, n), 'rmse_ratio']:.2f} ± "
            f"{pivot.loc[(k, n), 'rmse_ratio_se']:.2f})"
            for n in names
            for k in [best_of[n]]
            if k != "uniform" and clearly(k, n, -1)
        ]
        verdict = (
            "clearly below the uniform input's on " + "; ".join(wins)
            if wins
            else "no design is below the uniform input by more than two SEs on any of them"
        )
        out.append(
            f"- The {label}: lowest median RMSE with the **{order[0]}** input "
            f"({medians[order[0]]:.2f} x the uniform input's over {', '.join(names)}), then "
            f"{order[1]} ({medians[order[1]]:.2f}), last {order[-1]} "
            f"({medians[order[-1]]:.2f}); {verdict}."
        )
    worse = []
    for kind in kinds:
        hurt = [n for n in best_of if kind != "uniform" and clearly(kind, n, +1)]
        if hurt:
            worse.append(f"{kind} on {len(hurt)} of {len(best_of)} ({', '.join(hurt)})")
    out.append(
        "- Worse than the uniform input by more than two SEs: "
        + ("; ".join(worse) if worse else "no design on any parameter")
        + "."
    )
    low = rows.drop_duplicates("input").set_index("input")
    slow = [k for k in kinds if low.loc[k, "low_share"] > 0.5]
    for kind in slow:
        ratios = [pivot.loc[(kind, n), "rmse_ratio"] for n in best_of]
        out.append(
            f"- The {kind} input puts {low.loc[kind, 'low_share']:.0%} of its power below "
            f"{LOW:g} of Nyquist (the uniform input {low.loc['uniform', 'low_share']:.0%}): "
            "it hardly excites the linear block's dynamics or reverses often enough to "
            "show the backlash: the robust fit's recovered rate is "
            f"{low.loc[kind, 'recovered_rate']:.2f}, and its RMSEs are {min(ratios):.0f} to "
            f"{max(ratios):.0f} times the uniform input's."
        )
    return out


def low_share(spec, n: int, records: int = 32) -> float:
    """The share of the input's power below `LOW` of Nyquist, over `records` records."""
    import jax
    import numpy as np

    design = spec.input_design()
    keys = jax.random.split(jax.random.PRNGKey(0), records)
    u = np.asarray(jax.vmap(lambda k: design(k, n))(keys))
    power = np.abs(np.fft.rfft(u - u.mean(axis=1, keepdims=True), axis=1)) ** 2
    fraction = np.arange(power.shape[1]) / (power.shape[1] - 1)
    return float(power[:, fraction < LOW].sum() / power.sum())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realisations", type=int, default=200, help="per cell (200)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--chunk-size", type=int, default=25)
    parser.add_argument(
        "--data", default="../shared/data/brfd", help="the damper records (read, never copied)"
    )
    parser.add_argument("--out", default="results/input_design", help="output stem")
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
    command = ["python", "benchmarks/input_design.py", *sys.argv[1:]]
    summaries = []
    total = time.perf_counter()
    for example, n in EXAMPLES.items():
        for label, (kind, settings) in designs(pathlib.Path(args.data)).items():
            spec = Spec(
                example=example,
                n=n,
                snr=SNR,
                realisations=args.realisations,
                seed=args.seed,
                estimators=("robust",),
                chunk_size=args.chunk_size,
                input=kind,
                input_settings=settings,
            )
            out = folder / f"example{example}_{label}.parquet"
            start = time.perf_counter()
            table = run(spec, out, resume=True, progress=not args.quiet, command=command)
            summary = summarise(table)
            summary.to_csv(summary_path(out), index=False)
            share = low_share(spec, n)
            summaries.append(summary.assign(input=label, low_share=share))
            print(f"example {example} {label}: {len(table)} fits in "
                  f"{time.perf_counter() - start:.1f} s", flush=True)  # fmt: skip

    table = relative(pd.concat(summaries, ignore_index=True))[COLUMNS]
    csv = stem.with_name(stem.name + ".csv")
    table.to_csv(csv, index=False)
    header = (
        "# Input designs at equal power: which identifies which parameter best\n\n"
        f"{args.realisations} realisations per cell, seed {args.seed}, robust estimator, "
        f"white noise at SNR {SNR:g}, every input at rms {RMS:.4f} (the paper's uniform "
        f"input in (-2, 2)); `{' '.join(command)}`, {time.perf_counter() - total:.0f} s "
        "on this machine. Designs: uniform (the paper's); gaussian; multisine (random "
        "phases, every DFT line); multilevel (continuous random levels, switching with "
        "probability 0.2); file (random segments of the shared friction damper's "
        f"Kocaeli displacement, decimated by {RECORD[2]}, each segment centred and scaled "
        "to the same power). A ratio below 1 is a smaller RMSE than the uniform input's; "
        "the SE is the delta method's on independent records. RMSE, bias and std use "
        "the admissible estimates (`used`); the recovered rate counts every record."
    )
    stem.with_name(stem.name + ".md").write_text(markdown(table, header))
    print(f"written: {csv}, {stem}.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
