"""Issue 25: tracking a system that changes with the recursive estimator.

    python benchmarks/recursive_tracking.py [--realisations 200] [--n 8000] [--snr 25]
        [--lams 0.99,0.995,0.999] [--every 10] [--seed 0] [--out results/recursive_tracking]

Example 1, input uniform in (-2, 2), output noise at SNR 25; at sample 4000 one
parameter steps: `cR` 0.3 -> 0.45 (the backlash's right gap widens, as in a wearing
drive train) and, separately, `b1` -0.2 -> -0.35 (a step of the same size in the linear
block; the block stays stable), and both gaps at once, `cL` 0.2 -> 0.3 with `cR` 0.3 ->
0.45 (the backlash widens on both sides; `[system.change]` with lists). One on-line pass
of `Recursive` per realisation with a constant forgetting factor after its start:
`lam_k = min(lam, 1 - 1/(10 + 0.1 k + 3e-4 k^2))`
(`_rls.forgetting`), lam in {0.99, 0.995, 0.999}, the estimate kept every `--every`
samples (`_montecarlo._tracking`). Per change x lam: the fraction within 0.05 of the
truth just before the change, the fraction that re-enters (every parameter back within
0.05 of the new truth), the re-entry time (samples after the change; mean and median
over those that re-enter, mean with its Monte-Carlo SE), the fraction that stays inside
from the re-entry on, and the steady-state RMSE after the re-entry (over all parameters,
and of the changed ones), mean ± SE. Writes OUT.csv, OUT.md and OUT.png (median of the
largest absolute error over the parameters, with 10-90% and 25-75% bands, per change
and lam).
"""

from __future__ import annotations

import argparse
import pathlib
import time

import numpy as np

CHANGES = (("cR", 0.45), ("b1", -0.35), (("cL", "cR"), (0.3, 0.45)))


def _label(parameter, to) -> tuple[str, str]:
    """`(parameters, values)` as table cells: `cL+cR`, `0.3/0.45`."""
    if isinstance(parameter, tuple):
        return "+".join(parameter), "/".join(f"{v:g}" for v in to)
    return parameter, f"{to:g}"


AT = 4000


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realisations", type=int, default=200)
    parser.add_argument("--n", type=int, default=8000)
    parser.add_argument("--snr", type=float, default=25.0)
    parser.add_argument("--lams", default="0.99,0.995,0.999")
    parser.add_argument("--every", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/recursive_tracking")
    args = parser.parse_args(argv)
    lams = [float(x) for x in args.lams.split(",")]

    import jax

    jax.config.update("jax_enable_x64", True)
    import pandas as pd

    from jaxcascade._experiment._changing import Change
    from jaxcascade._montecarlo._tracking import tracking
    from jaxcascade._system._examples import example

    truth = example(1).params()
    rows, curves = [], {}
    R = args.realisations
    for parameter, to in CHANGES:
        change = Change(parameter, AT, to=to)
        parameter, to = _label(parameter, to)
        for lam in lams:
            start = time.perf_counter()
            result = tracking(
                truth,
                change,
                n=args.n,
                snr=args.snr,
                realisations=R,
                seed=args.seed,
                every=args.every,
                lam=lam,
            )
            wall = time.perf_counter() - start
            reentered = np.isfinite(result.reentry)
            times = result.reentry[reentered]
            steady = result.steady_rmse[reentered]
            changed = result.steady_rmse_changed[reentered]
            m = max(int(reentered.sum()), 1)
            rows.append(
                {
                    "parameter": parameter,
                    "to": to,
                    "lam": lam,
                    "memory": 1 / (1 - lam),
                    "within_before": result.before.mean(),
                    "reentered": reentered.mean(),
                    "reentered_se": np.sqrt(reentered.mean() * (1 - reentered.mean()) / R),
                    "reentry_mean": times.mean() if times.size else np.nan,
                    "reentry_se": times.std(ddof=1) / np.sqrt(m) if times.size > 1 else np.nan,
                    "reentry_median": np.median(times) if times.size else np.nan,
                    "settled": result.settled.mean(),
                    "steady_rmse": steady.mean() if steady.size else np.nan,
                    "steady_rmse_se": steady.std(ddof=1) / np.sqrt(m)
                    if steady.size > 1
                    else np.nan,
                    "steady_rmse_changed": changed.mean() if changed.size else np.nan,
                    "steady_rmse_changed_se": (
                        changed.std(ddof=1) / np.sqrt(m) if changed.size > 1 else np.nan
                    ),
                    "wall_s": wall,
                }
            )
            largest = np.max(np.abs(result.errors), axis=2)
            curves[parameter, lam] = (
                result.samples,
                np.quantile(largest, [0.1, 0.25, 0.5, 0.75, 0.9], axis=0),
            )
            print(
                f"{parameter} lam {lam}: {wall:.1f} s, re-entered {reentered.mean():.2f}, "
                f"median re-entry {rows[-1]['reentry_median']}, "
                f"steady {rows[-1]['steady_rmse']:.4f}",
                flush=True,
            )
    frame = pd.DataFrame(rows)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(out.with_suffix(".csv"), index=False)
    plot(curves, lams, out.with_suffix(".png"), args)
    out.with_suffix(".md").write_text(markdown(frame, args))
    print(f"written: {out}.csv, {out}.md, {out}.png")
    return 0


def plot(curves, lams, path, args) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        len(CHANGES),
        len(lams),
        figsize=(4 * len(lams), 3.4 * len(CHANGES)),
        sharex=True,
        sharey=True,
    )
    for i, (parameter, to) in enumerate(CHANGES):
        parameter, _ = _label(parameter, to)
        for j, lam in enumerate(lams):
            ax = axes[i, j]
            samples, q = curves[parameter, lam]
            ax.fill_between(samples, q[0], q[4], color="C0", alpha=0.2, label="10-90%")
            ax.fill_between(samples, q[1], q[3], color="C0", alpha=0.4, label="25-75%")
            ax.plot(samples, q[2], color="C0", lw=1, label="median")
            ax.axvline(AT, color="k", lw=0.8, ls=":")
            ax.axhline(0.05, color="C3", lw=0.8, ls="--", label="band 0.05")
            ax.set_yscale("log")
            ax.set_ylim(1e-3, 3)
            ax.set_title(f"{parameter} step at {AT}, lam = {lam}", fontsize=9)
            if i == len(CHANGES) - 1:
                ax.set_xlabel("sample")
            if j == 0:
                ax.set_ylabel("largest |estimate - truth|")
    axes[0, 0].legend(fontsize=7, loc="upper right")
    fig.suptitle(
        f"Recursive estimator tracking Example 1 (SNR {args.snr:g}, {args.realisations} "
        "realisations): median and quantile bands of the largest parameter error",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(frame, args) -> str:
    lines = [
        f"# Tracking a step with the recursive estimator: Example 1, SNR {args.snr:g}, "
        f"N {args.n}, {args.realisations} realisations",
        "",
        f"Command: `python benchmarks/recursive_tracking.py --realisations {args.realisations} "
        f"--n {args.n} --snr {args.snr:g} --lams {args.lams} --every {args.every} "
        f"--seed {args.seed} --out {args.out}`. A step at sample {AT} in one parameter "
        "(cR 0.3 -> 0.45; b1 -0.2 -> -0.35) or in both gaps (cL 0.2 -> 0.3 with cR 0.3 -> "
        "0.45). Re-entry: samples after the step until every "
        "parameter is first back within 0.05 of the new truth (estimates recorded every "
        f"{args.every} samples); settled: stays inside from then on; steady RMSE: over the "
        "recorded samples after the re-entry. Means ± Monte-Carlo SE over the realisations "
        "that re-enter.",
        "",
        "| step | lam (memory) | within 0.05 before | re-entered | re-entry mean ± SE | "
        "re-entry median | settled | steady RMSE (all) | steady RMSE (changed) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in frame.itertuples():
        lines.append(
            f"| {row.parameter} -> {row.to} | {row.lam:g} ({row.memory:.0f}) | "
            f"{row.within_before:.2f} | {row.reentered:.2f} ± {row.reentered_se:.2f} | "
            f"{row.reentry_mean:.0f} ± {row.reentry_se:.0f} | {row.reentry_median:.0f} | "
            f"{row.settled:.2f} | {row.steady_rmse:.4f} ± {row.steady_rmse_se:.4f} | "
            f"{row.steady_rmse_changed:.4f} ± {row.steady_rmse_changed_se:.4f} |"
        )
    lines += ["", "## Trade-off", ""]
    for parameter, group in frame.groupby("parameter", sort=False):
        fast = group.loc[group["reentry_median"].idxmin()]
        quiet = group.loc[group["steady_rmse"].idxmin()]
        most = group.loc[group["reentered"].idxmax()]
        lines.append(
            f"- {parameter} step: fastest median re-entry lam {fast.lam:g} "
            f"({fast.reentry_median:.0f} samples); lowest steady RMSE lam {quiet.lam:g} "
            f"({quiet.steady_rmse:.4f}); most realisations re-entering lam {most.lam:g} "
            f"({most.reentered:.2f})."
        )
    lines += [
        "",
        "The forgetting factor trades reaction for noise: a short memory re-enters "
        "soonest but its estimate is noisy at this SNR (it seldom stays inside the band: "
        "the settled column); a long memory is quiet once it has forgotten the old "
        "system, but that takes thousands of samples, and not every realisation gets "
        "there before the record ends. Column 3 is the fraction within 0.05 just before "
        "the step: with a short memory the noise alone keeps part of the realisations "
        "outside the band, change or not.",
    ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
