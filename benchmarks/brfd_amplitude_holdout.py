"""Issue 32, point 5: would a rule that prefers what carries over in amplitude choose
another hysteresis candidate on the damper?

    python benchmarks/brfd_amplitude_holdout.py --data ../shared/data/brfd \
        --out results/brfd/amplitude_holdout [--decimate 16] [--jobs 2]

The issue's suggestion is to score the loop's significant candidates on estimation
records held out at another amplitude. This measures what such a rule would see. For
each direction (estimated on earthquake A, validated on earthquake B's strong-motion
window, as `benchmarks/brfd.py`'s `harmonics+A_to_B` runs) and for each hysteresis effect
of the damper's library alone (`--effects H,output_offset,colored_noise`, at most two
effects), `jaxcascade loop` is run with the 30 lb harmonic tests **below the largest
amplitude** (0.5 and 1 in) as estimation records beside A, and scored on tests it never
saw:

- the 30 lb tests at the largest amplitude (1.5 in): the same device setting, 50 % beyond
  the estimation records' amplitude (what an amplitude hold-out scores);
- the 36 lb tests at 1.5 in: another band tension at that amplitude.

Each test record's state is set from the measured force on the first `--init-samples`
samples (the loop's convention) and its NRMSE taken on the rest. Writes OUT.csv (one row
per direction, effect and scored record) and OUT.md: per direction and effect, the
structure the loop ended with, the validation NRMSE it chooses by (and the window's),
and the medians on both groups of tests; and per direction the rank correlation between
the validation NRMSE and the 30 lb 1.5 in median: a hold-out rule changes the loop's
choice only where they disagree and the hold-out tells the candidates apart.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import datetime
import json
import pathlib
import sys

from brfd import FILES, HYSTERESIS, WINDOWS, run_loop


def designs(data: pathlib.Path):
    """`(estimation harmonic files, 30 lb tests at the largest amplitude, 36 lb tests at
    that amplitude)`, read from the records' index."""
    import pandas as pd

    folder = data / "characterization"
    index = pd.read_csv(folder / "index.csv")
    largest = index.amplitude_in.max()
    at30 = index[index.band_tension_lb == 30]
    estimation = [folder / f for f in at30[at30.amplitude_in < largest].file]
    held30 = [folder / f for f in at30[at30.amplitude_in == largest].file]
    at36 = index[(index.band_tension_lb == 36) & (index.amplitude_in == largest)]
    return estimation, held30, [folder / f for f in at36.file], float(largest)


def argv(data, out, estimation, tests, train, valid, effect, args) -> list[str]:
    window = WINDOWS[valid]
    report = out / f"{train}_to_{valid}" / effect
    report.mkdir(parents=True, exist_ok=True)
    loop = ["loop", *map(str, estimation), str(data / FILES[train])]
    loop += ["--validate", str(data / FILES[valid]), "--window", f"{window[0]}:{window[1]}"]
    loop += ["--input", "displacement_in", "--output", "force_kip", "--time", "time_s"]
    loop += ["--decimate", str(args.decimate), "--init-samples", str(args.init_samples)]
    loop += ["--max-effects", "2", "--effects", f"{effect},output_offset,colored_noise"]
    loop += ["--test", *map(str, tests), "--json", "--report", str(report), "--no-figures"]
    loop += ["--overwrite"]
    return loop


def main(argv_=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="../shared/data/brfd")
    parser.add_argument("--out", default="results/brfd/amplitude_holdout")
    parser.add_argument("--decimate", type=int, default=16)
    parser.add_argument("--init-samples", type=int, default=50)
    parser.add_argument("--jobs", type=int, default=1, help="loops run at once")
    parser.add_argument(
        "--runs", default="runs/brfd_amplitude_holdout", help="the loops' reports (git-ignored)"
    )
    args = parser.parse_args(argv_)

    import numpy as np
    import pandas as pd
    from bench_history import commit
    from loop_speed import machine
    from scipy.stats import spearmanr

    data = pathlib.Path(args.data)
    out = pathlib.Path(args.out)
    runs_dir = pathlib.Path(args.runs)
    estimation, held30, held36, largest = designs(data)
    tests = held30 + held36
    work = [
        (train, valid, effect)
        for train, valid in (("kocaeli", "imperialvalley"), ("imperialvalley", "kocaeli"))
        for effect in HYSTERESIS.split(",")
    ]

    def one(item):
        train, valid, effect = item
        loop = argv(data, runs_dir, estimation, tests, train, valid, effect, args)
        print(f"{train}_to_{valid} {effect}: jaxcascade {' '.join(loop)}", file=sys.stderr)
        result = run_loop(loop)
        if result["returncode"] != 0:
            raise SystemExit(f"{train}_to_{valid} {effect}: the loop failed")
        return item, json.loads(result["stdout"]), result["seconds"]

    with concurrent.futures.ThreadPoolExecutor(max(args.jobs, 1)) as pool:
        done = list(pool.map(one, work))

    rows = []
    for (train, valid, effect), report, seconds in done:
        common = {
            "direction": f"{train}_to_{valid}",
            "effect": effect,
            "structure": report["structure_after"],
            "validation_nrmse": report["error_after"],
            "validation_window_nrmse": report["window_error_after"],
            "seconds": round(seconds, 1),
        }
        for scored in report["test"]:
            name = pathlib.Path(scored["record"]).name
            group = "30lb" if name in {p.name for p in held30} else "36lb"
            rows.append({**common, "record": name, "group": group, "nrmse": scored["error"]})
    table = pd.DataFrame(rows)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out.with_suffix(".csv"), index=False)

    keys = ["direction", "effect", "structure", "validation_nrmse", "validation_window_nrmse"]
    medians = table.pivot_table(index=keys, columns="group", values="nrmse", aggfunc="median")
    summary = medians.reset_index().rename(
        columns={"30lb": "median_30lb_largest", "36lb": "median_36lb_largest"}
    )
    header = (
        f"| direction | effect | structure | validation NRMSE (window) | 30 lb at {largest:g} in: "
        f"median NRMSE | 36 lb at {largest:g} in: median NRMSE |"
    )
    lines = [
        "# Would an amplitude hold-out choose another damper model?",
        "",
        f"Command: `python benchmarks/brfd_amplitude_holdout.py --data {args.data} --out "
        f"{args.out} --decimate {args.decimate} --jobs {args.jobs}`, commit {commit()}, "
        f"{datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds')}, {machine()}.",
        "",
        "Each row is `jaxcascade loop` with one hysteresis effect of the damper's library "
        f"(beside `output_offset` and `colored_noise`), estimated on the 30 lb harmonic "
        f"tests below {largest:g} in and earthquake A, validated on earthquake B (the "
        "NRMSE the loop chooses by, the strong-motion window's in brackets), and scored on "
        f"the harmonic tests at {largest:g} in it never saw, at 30 lb (an amplitude "
        "hold-out) and at 36 lb (another band tension). Per-run reports in "
        f"`{args.runs}/` (git-ignored).",
        "",
        header,
        "|---|---|---|---|---|---|",
    ]
    for r in summary.itertuples():
        lines.append(
            f"| {r.direction} | {r.effect} | `{r.structure}` | {r.validation_nrmse:.3f} "
            f"({r.validation_window_nrmse:.3f}) | {r.median_30lb_largest:.3f} | "
            f"{r.median_36lb_largest:.3f} |"
        )
    lines += ["", "## Per direction", ""]
    lines += [
        "| direction | chosen by validation | chosen by the 30 lb hold-out | hold-out medians: "
        "range | rank correlation, validation vs hold-out (Spearman) |",
        "|---|---|---|---|---|",
    ]
    for direction, part in summary.groupby("direction"):
        by_validation = part.loc[part.validation_nrmse.idxmin()]
        by_holdout = part.loc[part.median_30lb_largest.idxmin()]
        rho = spearmanr(part.validation_nrmse, part.median_30lb_largest).statistic
        spread = part.median_30lb_largest
        lines.append(
            f"| {direction} | {by_validation.effect} ({by_validation.median_30lb_largest:.3f}"
            f" on the hold-out) | {by_holdout.effect} ({by_holdout.validation_nrmse:.3f} on "
            f"validation) | {np.min(spread):.3f} to {np.max(spread):.3f} | {rho:.2f} |"
        )
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
