"""Issue 5: the model-error loop on records with one undeclared effect each.

    python benchmarks/effects_loop.py [--out results/effects_loop] [--seed 1]

Each record is Example 1 with one effect of the library present but not declared
(`jaxcascade._measured._testing.UNDECLARED`), at SNR 20 (noise floor 1/SNR = 0.05), 2000
estimation and 2000 validation samples with independent inputs and noise; plus a record
with no extra effect; plus the force and position of an axis under proportional control
with Coulomb friction (`_testing.INTEGRATING`, `axis_record`: the loop models the
position's difference, `integrating=True`, and its NRMSE is the position's; its noise is
the position's, at SNR 20 of the velocity, so the floor is not 1/SNR there: `-` in the
floor column); plus the Wiener-Hammerstein sandwiches of the inner maps
(`_testing.SANDWICHES`: a static map between the cascade and a second linear block, two
effects, named when the loop adds the two, in either block's order). Writes OUT.csv and
OUT.md: the effect present, the effects the loop added, NRMSE before and after, the
ratio to the noise floor, and the runtime. Each record's row is appended to
OUT.rows.jsonl as it finishes, and a run started again with the same settings resumes
from it (`--fresh` starts over); the file is removed once the tables are written.
"""

from __future__ import annotations

import argparse
import pathlib
import time


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/effects_loop")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--snr", type=float, default=20.0)
    parser.add_argument("--n", type=int, default=2000)
    parser.add_argument(
        "--fresh", action="store_true", help="ignore OUT.rows.jsonl of an interrupted run"
    )
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import pandas as pd
    from partial_rows import append, open_rows

    import jaxcascade as jc
    from jaxcascade._measured._testing import (
        INTEGRATING,
        SANDWICHES,
        UNDECLARED,
        axis_record,
        undeclared_record,
    )

    out = pathlib.Path(args.out)
    settings = {"seed": args.seed, "snr": args.snr, "n": args.n}
    done, partial = open_rows(out, settings, lambda row: row["effect_present"], args.fresh)
    rows = []
    cases = [(name, "effect") for name in UNDECLARED]
    cases += [(name, "integrating") for name in INTEGRATING if name is not None]
    cases += [(name, "sandwich") for name in SANDWICHES]
    suffixes = {"effect": "", "integrating": " (integrating axis)", "sandwich": " (sandwich)"}
    for name, kind in cases:
        integrating, sandwich = kind == "integrating", kind == "sandwich"
        label = (name or "none") + suffixes[kind]
        if label in done:
            rows.append(done[label])
            continue
        key = jax.random.PRNGKey(args.seed)
        k_est, k_val = jax.random.split(key)
        if integrating:
            friction = INTEGRATING[name]
            u, y = axis_record(k_est, args.n + 1, args.snr, friction)
            u_val, y_val = axis_record(k_val, args.n + 1, args.snr, friction)
            u, y, u_val, y_val = u[1:], np.diff(y), u_val[1:], np.diff(y_val)
        else:
            model, ar = UNDECLARED[name]() if not sandwich else (SANDWICHES[name]()[0], None)
            u, y = undeclared_record(model, k_est, args.n, args.snr, ar)
            u_val, y_val = undeclared_record(model, k_val, args.n, args.snr, ar)
        start = time.perf_counter()
        result = jc.model_error_loop(
            u, y, u_val, y_val, jc.Orders(), integrating=integrating, init_samples=0
        )
        rows.append(
            {
                "effect_present": label,
                "effect_added": ",".join(result.added) or "none",
                "named": bool(
                    result.added in SANDWICHES[name]()[1]
                    if sandwich
                    else result.added == ([name] if name else [])
                ),
                "nrmse_before": float(result.before.error),
                "nrmse_after": float(result.after.error),
                "after_over_floor": None if integrating else float(result.after.error * args.snr),
                "residual_tests_pass_after": bool(result.after.tests.ok),
                "seconds": time.perf_counter() - start,
            }
        )
        append(partial, rows[-1])
    table = pd.DataFrame(rows)
    table.to_csv(out.with_suffix(".csv"), index=False)
    lines = [
        f"# Model-error loop on records with an undeclared effect (SNR {args.snr:g}, "
        f"noise floor {1 / args.snr:.3f}, N = {args.n} + {args.n}, seed {args.seed})",
        "",
        f"Command: `python benchmarks/effects_loop.py --out {args.out} --seed {args.seed}`",
        "",
        "| effect present | added by the loop | named | NRMSE before | NRMSE after | "
        "after / floor | tests pass after | s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['effect_present']} | {r['effect_added']} | {r['named']} | "
            f"{r['nrmse_before']:.4f} | {r['nrmse_after']:.4f} | "
            f"{'-' if r['after_over_floor'] is None else format(r['after_over_floor'], '.2f')} | "
            f"{r['residual_tests_pass_after']} | {r['seconds']:.0f} |"
        )
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    partial.unlink()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
