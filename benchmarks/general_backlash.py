"""Issue 39, step 1: the general-backlash examples of `../shared/GENERAL_BACKLASH.md` on
their records: the branches on the record's range of x, the size of the curvature
against the noise, and degree 1 against today's backlash.

    python benchmarks/general_backlash.py [--seed 0] [--out results/general_backlash]

For `general1` and `general2` (`jaxcascade._system._general_backlash.GENERAL_EXAMPLES`), one
record of the example's N samples, input uniform in (-amplitude, amplitude) from
`PRNGKey(seed)`, noise-free: the range of the LD output x, each branch's smallest slope
there and the smallest dead band fL - fR (`branch_report`: negative where the branches
cross), and `curvature`: std(y - y_straight) / std(y), the output the curved branches
move against the straight backlash of the same cL, mR, cR, beside the noise level of the
example's SNR (1 / SNR of std(y)). And for the paper's two examples, whether the general
backlash of degree 1 simulates today's output bit for bit. Writes OUT/examples.csv and
OUT/examples.md.

Then the output-error estimate on the same noise-free records
(`_estimator._general_refine.robust_general`, robust key `PRNGKey(seed + 1)`): the
straight model's robust fit, its status and largest parameter error, and the curved
refinement from it with curvature 0: status, steps, largest error over every parameter
(cascade and curvature), mean squared simulation error, seconds (compile included).
Writes OUT/estimates.csv and OUT/estimates.md.

Then the key-term iteration (`_estimator._general_keyterm.key_term_general`, from the
paper's initial values) on `--records` noise-free records per example (inputs from
`PRNGKey(seed + k)`, k = 0..records-1): general1 and general2 at degree 3, and the 2016
Examples 1 and 2 at degree 1 (the iteration on a straight backlash, for its iteration
counts): records per status, iterations (median, range) and the largest parameter error
among the converged records. Writes OUT/keyterm.csv and OUT/keyterm.md. Every file
carries the command, commit and date.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import sys
import time


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--records", type=int, default=20)
    parser.add_argument("--out", default="results/general_backlash")
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np
    import pandas as pd
    from bench_history import commit  # the short hash, "-dirty" with package changes
    from loop_speed import markdown  # a pipe table without an optional dependency

    import jaxcascade as jc
    from jaxcascade._benchmark._timing import device_description
    from jaxcascade._estimator._general_keyterm import key_term_general
    from jaxcascade._estimator._general_refine import refine_general
    from jaxcascade._estimator._robust import Robust
    from jaxcascade._status import Status
    from jaxcascade._system._general_backlash import (
        GENERAL_EXAMPLES,
        GeneralBacklash,
        branch_report,
        general_signals,
        simulate_general,
    )
    from jaxcascade._system._simulate import backlash

    rows = []
    for name, example in GENERAL_EXAMPLES.items():
        params, nd = example.params(), example.backlash()
        u = jc.uniform_input(jax.random.PRNGKey(args.seed), example.n_samples, example.amplitude)
        s = general_signals(params, nd, u)
        y = np.asarray(s.y)
        straight = np.asarray(backlash(params, s.x))
        report = branch_report(nd, np.asarray(s.x))
        rows.append(
            {
                "example": name,
                "orders": str(example.orders),
                "degree": nd.degree,
                "cL": float(nd.cL),
                "mR": float(nd.mR),
                "cR": float(nd.cR),
                "curveL": " ".join(f"{c:g}" for c in example.curveL),
                "curveR": " ".join(f"{c:g}" for c in example.curveR),
                "n": example.n_samples,
                "snr": example.snr,
                **{k: round(v, 4) for k, v in report.items()},
                "increasing": report["min_slope_left"] > 0 and report["min_slope_right"] > 0,
                "dead_band": report["min_dead_band"] > 0,
                "curvature": round(float(np.std(y - straight) / np.std(y)), 4),
                "noise": round(1 / example.snr, 4),
            }
        )
    table = pd.DataFrame(rows)
    identity = []
    for number in (1, 2):
        params = jc.example(number).params()
        u = jc.uniform_input(jax.random.PRNGKey(args.seed), jc.example(number).n_samples)
        same = bool(
            jnp.all(
                simulate_general(params, GeneralBacklash.straight(params), u)
                == jc.simulate(params, u)
            )
        )
        identity.append({"example": number, "degree_1_bit_for_bit": same})

    estimates = []
    for name, example in GENERAL_EXAMPLES.items():
        params, nd = example.params(), example.backlash()
        u = jc.uniform_input(jax.random.PRNGKey(args.seed), example.n_samples, example.amplitude)
        y = simulate_general(params, nd, u)
        key = jax.random.PRNGKey(args.seed + 1)
        started = time.perf_counter()
        straight = Robust()(u, y, params.orders, key=key)
        fit = refine_general(
            straight.params, GeneralBacklash.straight(straight.params, nd.degree), u, y
        )
        seconds = time.perf_counter() - started
        truth = np.concatenate([params.to_vector(), nd.curveL, nd.curveR])
        found = np.concatenate([fit.params.to_vector(), fit.backlash.curveL, fit.backlash.curveR])
        straight_error = np.abs(
            np.asarray(straight.params.to_vector()) - truth[: params.orders.size]
        )
        estimates.append(
            {
                "example": name,
                "straight_status": Status(int(straight.status)).name,
                "straight_max_error": f"{straight_error.max():.3g}",
                "status": Status(int(fit.status)).name,
                "steps": int(fit.steps),
                "max_error": f"{np.abs(found - truth).max():.3g}",
                "cost": f"{float(fit.cost):.3g}",
                "increasing": fit.increasing,
                "seconds": round(seconds, 1),
            }
        )

    keyterm = []
    cases = [
        (name, e.params(), e.backlash(), e.n_samples, e.amplitude)
        for name, e in GENERAL_EXAMPLES.items()
    ]
    for number in (1, 2):
        example = jc.example(number)
        p = example.params()
        cases.append((f"example{number}", p, GeneralBacklash.straight(p), example.n_samples, 2.0))
    for name, params, nd, n, amplitude in cases:
        truth = np.concatenate([params.to_vector(), nd.curveL, nd.curveR])
        statuses, iterations, errors = [], [], []
        for k in range(args.records):
            u = jc.uniform_input(jax.random.PRNGKey(args.seed + k), n, amplitude)
            fit = key_term_general(u, simulate_general(params, nd, u), params.orders, nd.degree)
            found = np.concatenate(
                [fit.params.to_vector(), fit.backlash.curveL, fit.backlash.curveR]
            )
            statuses.append(Status(int(fit.status)).name)
            iterations.append(int(fit.iterations))
            if statuses[-1] == "converged":
                errors.append(float(np.abs(found - truth).max()))
        counts = pd.Series(statuses).value_counts()
        keyterm.append(
            {
                "example": name,
                "degree": nd.degree,
                "records": args.records,
                **{
                    status: int(counts.get(status, 0))
                    for status in ("converged", "max_iterations", "singular", "diverged")
                },
                "iterations_median": float(np.median(iterations)),
                "iterations_min": min(iterations),
                "iterations_max": max(iterations),
                "converged_max_error": f"{max(errors):.3g}" if errors else "-",
            }
        )

    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / "examples.csv", index=False)
    command = "python benchmarks/general_backlash.py " + " ".join(
        sys.argv[1:] if argv is None else argv
    )
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    lines = [
        "# General-backlash examples on their records",
        "",
        f"`{command.strip()}`, commit {commit()}, {date}. Seed {args.seed}, noise-free.",
        "",
        "Branches fL(x) = (x + cL) + sum mL_i (x + cL)^i and fR(x) = mR (x - cR) + "
        "sum mR_i (x - cR)^i, i = 2..q (`curveL` = mL_2..mL_q, `curveR` = mR_2..mR_q). "
        "`x_low`, `x_high`: the range of the LD output x on the record; `min_slope_*`: each "
        "branch's smallest slope there; `min_dead_band`: the smallest fL - fR there "
        "(negative where the branches cross); `curvature`: std(y - y_straight) / std(y), "
        "y_straight the straight backlash of the same cL, mR, cR on the same x; `noise`: "
        "the noise level of the example's SNR, 1 / SNR of std(y).",
        "",
        markdown(table),
        "",
        "Degree 1 (`GeneralBacklash.straight`) against `jc.simulate` on the paper's examples "
        "(same input, compiled the same way):",
        "",
        markdown(pd.DataFrame(identity)),
        "",
    ]
    (out / "examples.md").write_text("\n".join(lines))
    frame = pd.DataFrame(estimates)
    frame.to_csv(out / "estimates.csv", index=False)
    (out / "estimates.md").write_text(
        "\n".join(
            [
                "# Output-error estimates with curved branches, noise-free",
                "",
                f"`{command.strip()}`, commit {commit()}, {date}, {device_description()}. "
                f"Records as in `examples.md` (seed {args.seed}), robust key "
                f"`PRNGKey({args.seed + 1})`.",
                "",
                "`straight_*`: the robust estimator's fit of the straight-backlash cascade "
                "(largest error over the cascade's parameters); then `refine_general` from "
                "it with curvature 0: its status, Levenberg-Marquardt steps, largest error "
                "over every parameter (cascade and curvature terms), mean squared "
                "simulation error, whether both fitted branches increase on the record's "
                "range, and seconds for both fits (compile included).",
                "",
                markdown(frame),
                "",
            ]
        )
    )
    frame = pd.DataFrame(keyterm)
    frame.to_csv(out / "keyterm.csv", index=False)
    (out / "keyterm.md").write_text(
        "\n".join(
            [
                "# The key-term iteration with curved branches, noise-free",
                "",
                f"`{command.strip()}`, commit {commit()}, {date}. {args.records} records per "
                f"example, inputs from `PRNGKey({args.seed})` on; from the paper's initial "
                "values (curvature 0), at most 200 steps, stopped by `Literal`'s rules and "
                "settings (`_literal.stopping_rule`, `_literal.cycle_detection`).",
                "",
                "general1 and general2 at degree 3; the 2016 Examples 1 and 2 at degree 1 "
                "(their straight backlash), for the iteration counts. Records per status, "
                "iterations (the first iteration counted), and the largest parameter error "
                "among the converged records.",
                "",
                markdown(frame),
                "",
            ]
        )
    )
    print(table.to_string(index=False))
    return 0 if all(r["degree_1_bit_for_bit"] for r in identity) else 1


if __name__ == "__main__":
    raise SystemExit(main())
