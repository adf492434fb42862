"""Issue 32: how often the model-error loop adds an effect to a record that has none.

    python benchmarks/false_additions.py [--seeds 50] [--n 1024,2000]
        [--out results/false_additions]

Each record is Example 1 with no undeclared effect
(`jaxcascade._measured._testing.UNDECLARED[None]`,
white noise at SNR 20), estimation and validation records of N samples each with
independent inputs and noise, drawn from seeds 0 to S-1 (`PRNGKey(seed)` split in two,
as `benchmarks/effects_loop.py` draws its records). The loop runs with its defaults
(`jc.model_error_loop`: every effect of the library, Diebold-Mariano threshold 3, gain
2 %). A false addition is any effect added. Writes OUT.csv (one row per record: seed,
N, effects added, NRMSE before and after, residual tests before, seconds) and OUT.md
(per N: records, false additions, their rate with the Wilson 95 % interval, the records
whose residual tests failed at the declared cascade, so that candidates were tried),
with the command, commit, date and machine. Rows are appended to OUT.rows.jsonl as they
finish; a run started again with the same settings resumes from it.
"""

from __future__ import annotations

import argparse
import datetime
import math
import pathlib
import time


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion `k / n`."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/false_additions")
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--n", default="1024,2000", help="record lengths, comma-separated")
    parser.add_argument("--snr", type=float, default=20.0)
    parser.add_argument("--fresh", action="store_true", help="ignore an interrupted run's rows")
    args = parser.parse_args(argv)
    lengths = [int(n) for n in args.n.split(",")]

    import jax

    jax.config.update("jax_enable_x64", True)
    import pandas as pd
    from bench_history import commit  # the short hash, "-dirty" with package changes
    from partial_rows import append, open_rows

    import jaxcascade as jc
    from jaxcascade._benchmark._timing import device_description
    from jaxcascade._measured._testing import UNDECLARED, undeclared_record

    out = pathlib.Path(args.out)
    settings = {"seeds": args.seeds, "n": lengths, "snr": args.snr}
    done, partial = open_rows(out, settings, lambda row: (row["n"], row["seed"]), args.fresh)
    model, ar = UNDECLARED[None]()
    rows = []
    started = time.perf_counter()
    for n in lengths:
        for seed in range(args.seeds):
            if (n, seed) in done:
                rows.append(done[(n, seed)])
                continue
            k_est, k_val = jax.random.split(jax.random.PRNGKey(seed))
            u, y = undeclared_record(model, k_est, n, args.snr, ar)
            u_val, y_val = undeclared_record(model, k_val, n, args.snr, ar)
            began = time.perf_counter()
            result = jc.model_error_loop(u, y, u_val, y_val, jc.Orders(), init_samples=0)
            rows.append(
                {
                    "n": n,
                    "seed": seed,
                    "effects_added": ",".join(result.added) or "none",
                    "false_addition": bool(result.added),
                    "candidates_tried": bool(result.candidates),
                    "nrmse_before": float(result.before.error),
                    "nrmse_after": float(result.after.error),
                    "seconds": time.perf_counter() - began,
                }
            )
            append(partial, rows[-1])
    table = pd.DataFrame(rows)
    table.to_csv(out.with_suffix(".csv"), index=False)
    command = "python benchmarks/false_additions.py " + " ".join(
        f"--{k} {v}" for k, v in (("seeds", args.seeds), ("n", args.n), ("out", args.out))
    )
    lines = [
        f"# False additions of the model-error loop on clean records (Example 1, SNR "
        f"{args.snr:g}, white noise, seeds 0-{args.seeds - 1})",
        "",
        f"Command: `{command}`; commit {commit()}, "
        f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, "
        f"{device_description()}, "
        f"{time.perf_counter() - started:.0f} s for the records computed in this run.",
        "",
        "A false addition: the loop, with its defaults, adds any effect to a record that has "
        "none. Candidates tried: the declared cascade's residual failed a test, so the "
        "library was fitted and the significance test decided.",
        "",
        "| N (estimation = validation) | records | false additions | rate | Wilson 95 % "
        "interval | candidates tried | effects added |",
        "|---|---|---|---|---|---|---|",
    ]
    for n, group in table.groupby("n"):
        k, count = int(group["false_addition"].sum()), len(group)
        low, high = wilson(k, count)
        added = sorted({e for e in group["effects_added"] if e != "none"})
        lines.append(
            f"| {n} | {count} | {k} | {k / count:.3f} | {low:.3f} to {high:.3f} | "
            f"{int(group['candidates_tried'].sum())} | {', '.join(added) or 'none'} |"
        )
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    partial.unlink()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
