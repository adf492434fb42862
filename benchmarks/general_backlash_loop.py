"""Issue 39, point 5: the model-error loop, default library, on records whose backlash
branches are curved and on the 2016 examples' records, whose branches are straight.

    python benchmarks/general_backlash_loop.py --seeds 10 --out results/general_backlash/loop

Records (`jaxcascade._measured._testing`): `general1` and `general2` (the note's examples, the
curvature as the loop's `general_backlash` effect, declared with straight branches and
their own orders) at an SNR where the curvature moves the output by more than twice the
noise (general1: 50, general2: 25; the table gives the ratio), and Examples 1 and 2 of
the 2016 paper at SNR 25 (nothing to add). Input uniform in (-2, 2), N estimation + N
validation samples, independent inputs and noise per seed (`PRNGKey(seed)` split in
two). What counts: on a curved record the loop adds exactly `general_backlash` and ends
within 15 % of the noise floor (1/SNR); on a straight one it adds nothing.

Writes OUT.csv and OUT.md (command, commit, date, machine). Each record's row is
appended to OUT.rows.jsonl as it finishes; a run started again with the same settings
resumes from it (`--fresh` starts over); the file is removed once the tables are written.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import sys
import time

# (record, SNR): the curved examples where their curvature is at least twice the noise
RECORDS = (("general1", 50.0), ("general2", 25.0), ("example1", 25.0), ("example2", 25.0))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/general_backlash/loop")
    parser.add_argument("--seeds", type=int, default=10, help="seeds 1..SEEDS per record")
    parser.add_argument("--n", type=int, default=2000)
    parser.add_argument("--fresh", action="store_true")
    args = parser.parse_args(argv)
    command = " ".join(["python benchmarks/general_backlash_loop.py", *sys.argv[1:]])

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import pandas as pd
    from bench_history import commit  # the short hash, "-dirty" with package changes
    from loop_speed import markdown  # a pipe table without an optional dependency
    from partial_rows import append, open_rows

    import jaxcascade as jc
    from jaxcascade._benchmark._timing import device_description
    from jaxcascade._measured._effects import backlash_of, plain, simulate_extended
    from jaxcascade._measured._testing import CURVED, undeclared_record

    def record_model(name):
        if name in CURVED:
            return CURVED[name]()
        ex = jc.example(int(name[-1]))
        return plain(ex.params()), ex.orders

    out = pathlib.Path(args.out)
    settings = {"seeds": args.seeds, "n": args.n, "records": [list(r) for r in RECORDS]}
    done, partial = open_rows(out, settings, lambda row: (row["record"], row["seed"]), args.fresh)
    started = time.perf_counter()
    rows = []
    for name, snr in RECORDS:
        model, orders = record_model(name)
        straight = model.with_(effects=())
        for seed in range(1, args.seeds + 1):
            if (name, seed) in done:
                rows.append(done[(name, seed)])
                continue
            k_est, k_val = jax.random.split(jax.random.PRNGKey(seed))
            u, y = undeclared_record(model, k_est, args.n, snr)
            u_val, y_val = undeclared_record(model, k_val, args.n, snr)
            clean = np.asarray(simulate_extended(model, u_val))
            curvature = float(
                np.std(clean - np.asarray(simulate_extended(straight, u_val))) / np.std(clean)
            )
            began = time.perf_counter()
            result = jc.model_error_loop(u, y, u_val, y_val, orders, init_samples=0)
            expected = ["general_backlash"] if name in CURVED else []
            nd = backlash_of(result.final)
            rows.append(
                {
                    "record": name,
                    "seed": seed,
                    "snr": snr,
                    "curvature_over_noise": curvature * snr,
                    "effect_added": ",".join(result.added) or "none",
                    "as_expected": bool(result.added == expected),
                    "degree": 1 if nd is None else nd.degree,
                    "nrmse_before": float(result.before.error),
                    "nrmse_after": float(result.after.error),
                    "after_over_floor": float(result.after.error * snr),
                    "seconds": time.perf_counter() - began,
                }
            )
            append(partial, rows[-1])
    table = pd.DataFrame(rows)
    table.to_csv(out.with_suffix(".csv"), index=False)
    shown = table.copy()
    for column in ("curvature_over_noise", "nrmse_before", "nrmse_after", "after_over_floor"):
        shown[column] = shown[column].map(lambda v: f"{v:.3g}")
    shown["seconds"] = shown["seconds"].map(lambda v: f"{v:.0f}")
    curved = table[table.record.isin(list(CURVED))]
    straight_rows = table[~table.record.isin(list(CURVED))]
    date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        "# The model-error loop on curved and straight backlash branches",
        "",
        f"`{command}`, commit {commit()}, {date}, {device_description()}, "
        f"{time.perf_counter() - started:.0f} s for the records computed in this run. "
        f"Default settings and library; N = {args.n} + {args.n}; seeds 1-{args.seeds}.",
        "",
        f"Curved records (general1, general2): `general_backlash` and nothing else added on "
        f"{int(curved.as_expected.sum())} of {len(curved)}, the final error within 15 % of "
        f"the noise floor on {int((curved.after_over_floor <= 1.15).sum())} of "
        f"{len(curved)} (largest ratio {curved.after_over_floor.max():.3g}). Straight "
        f"records (Examples 1, 2): nothing added on {int(straight_rows.as_expected.sum())} "
        f"of {len(straight_rows)}. `curvature_over_noise`: std of the curved output minus "
        "the straight one, over the noise std; `degree`: the final model's branch degree "
        "(1: straight); `seconds`: the loop's wall time in this process, compiling "
        "included (most of it on the first seed of a record, whose programs the later "
        "seeds reuse).",
        "",
        markdown(shown),
        "",
    ]
    out.with_suffix(".md").write_text("\n".join(lines))
    partial.unlink()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
