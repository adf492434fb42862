"""Issue 68, item 5: isolated outliers as an effect of the loop, on synthetic records.

    python benchmarks/outliers.py [--seeds 500] [--spiked 10] [--out results/outliers]

Records: Example 1, white noise at SNR 25, an estimation record of 1,000 samples and a
validation record of 500 with independent inputs and noise (`PRNGKey(seed)` split in
two). The loop (`jc.loop_records`) runs with its defaults and `--max-effects 0` (the
outliers are found in the final model's residual: here the declared cascade's).

- False alarms, seeds 0 to S-1: a clean record with any isolated outlier named
  (estimation or validation record).
- Recovery, seeds 0 to K-1: the same estimation record with four spikes of 5 to 6 output
  standard deviations (samples 150, 300, 451, 820; signs alternating), run with the
  outliers left out (`--outliers auto`, the default) and kept (`--outliers keep`): the
  samples named, the largest difference of an estimate from the clean record's in its
  standard errors, and the validation NRMSE of each run.

Writes OUT.csv (one row per run) and OUT.md (the false-alarm rate with its Wilson 95 %
interval, and the recovery table), with the command, commit, date and machine.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import time

SPIKES = (150, 300, 451, 820)
SIZES = (6.0, -5.0, 5.0, -6.0)  # output standard deviations


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/outliers")
    parser.add_argument("--seeds", type=int, default=500)
    parser.add_argument("--spiked", type=int, default=10)
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import pandas as pd
    from bench_history import commit  # the short hash, "-dirty" with package changes
    from false_additions import wilson

    import jaxcascade as jc
    from jaxcascade._benchmark._timing import device_description

    ex = jc.example(1)

    def records(seed: int, spikes: bool):
        k_est, k_val = jax.random.split(jax.random.PRNGKey(seed))
        out = []
        for key, n in ((k_est, 1000), (k_val, 500)):
            key_u, key_e = jax.random.split(key)
            u = jc.uniform_input(key_u, n)
            y = np.array(jc.measure(key_e, ex.params(), u, 25.0)[0])
            out.append((np.asarray(u), y))
        (u, y), valid = out
        if spikes:
            y[list(SPIKES)] += np.asarray(SIZES) * np.std(y)
        train = jc.record_from_arrays(u, y, sample_period=0.01, source="train")
        valid = jc.record_from_arrays(*valid, sample_period=0.01, scaling=train.scaling)
        return train, valid

    def run(seed, spikes, outliers="auto"):
        began = time.perf_counter()
        result = jc.loop_records(
            *records(seed, spikes), max_effects=0, threads=1, outliers=outliers
        )
        model = result.to_dict()["model_after"]
        named = {row["role"]: row["samples"] for row in result.outliers}
        return {
            "seed": seed,
            "record": "spiked" if spikes else "clean",
            "outliers_option": outliers,
            "named_estimation": ",".join(map(str, named.get("estimation", []))),
            "named_validation": ",".join(map(str, named.get("validation", []))),
            "validation_nrmse": float(result.result.after.error),
            "estimates": model["estimates"],
            "std_errors": model["std_errors"],
            "seconds": time.perf_counter() - began,
        }

    started = time.perf_counter()
    rows = [run(seed, False) for seed in range(args.seeds)]
    clean = {row["seed"]: row for row in rows}
    for seed in range(args.spiked):
        for option in ("auto", "keep"):
            row = run(seed, True, option)
            reference = clean[seed]
            row["largest_shift_in_std_errors"] = max(
                abs(row["estimates"][k] - v) / reference["std_errors"][k]
                for k, v in reference["estimates"].items()
            )
            rows.append(row)
    table = pd.DataFrame(rows)
    out = pathlib.Path(args.out)
    table.drop(columns=["estimates", "std_errors"]).to_csv(out.with_suffix(".csv"), index=False)

    false = table[table["record"] == "clean"]
    alarms = int(((false["named_estimation"] != "") | (false["named_validation"] != "")).sum())
    low, high = wilson(alarms, len(false))
    command = (
        f"python benchmarks/outliers.py --seeds {args.seeds} --spiked {args.spiked} "
        f"--out {args.out}"
    )
    lines = [
        "# Isolated outliers in the loop (Example 1, SNR 25, N 1000 + 500, --max-effects 0)",
        "",
        f"Command: `{command}`; commit {commit()}, "
        f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, {device_description()}, "
        f"{time.perf_counter() - started:.0f} s.",
        "",
        f"False alarms on clean records, seeds 0-{args.seeds - 1}: {alarms} of {len(false)} "
        f"records had an outlier named (rate {alarms / len(false):.3f}, Wilson 95 % interval "
        f"{low:.3f} to {high:.3f}).",
        "",
        f"Recovery, seeds 0-{args.spiked - 1}: four spikes of 5 to 6 output standard "
        f"deviations at samples {', '.join(map(str, SPIKES))} of the estimation record. "
        "Largest shift: the largest difference of an estimate from the clean record's, in "
        "the clean fit's standard errors.",
        "",
        "| seed | outliers | named (estimation) | largest shift | validation NRMSE | "
        "clean record's |",
        "|---|---|---|---|---|---|",
    ]
    for _, row in table[table["record"] == "spiked"].iterrows():
        lines.append(
            f"| {row['seed']} | {row['outliers_option']} | {row['named_estimation'] or '-'} | "
            f"{row['largest_shift_in_std_errors']:.2f} | {row['validation_nrmse']:.4f} | "
            f"{clean[row['seed']]['validation_nrmse']:.4f} |"
        )
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
