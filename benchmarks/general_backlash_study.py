"""Issue 39, point 4 (a first, small study): the general-backlash estimators under noise,
their bias, spread and efficiency against the Cramér-Rao bound, and the bias of the
straight-backlash model when the truth is curved.

    python benchmarks/general_backlash_study.py [--records 50] [--snr 25] [--seed 0]
        [--out results/general_backlash/study]

For each example of `jaxcascade._system._general_backlash.GENERAL_EXAMPLES` (N samples of the
example, input uniform in (-amplitude, amplitude) from `PRNGKey(seed)`, the same input
for every realisation), R realisations of white output noise at the SNR (the paper's
amplitude SNR, `add_noise` with `PRNGKey(seed + 1 + r)`), three fits per realisation:

- `straight`: today's robust estimator with the straight backlash (the 2016 model);
- `keyterm`: the note's key-term iteration (`key_term_general`, from the paper's
  initial values);
- `robust_general`: the robust straight fit refined with curved branches.

Per example, estimator and parameter: the mean estimate's bias with its standard error
(std / sqrt(R)), the std, the RMSE, the Cramér-Rao bound's std at the truth (white
noise of the realised level, the output-error Fisher information `J^T J / sigma^2`, `J`
the simulated output's Jacobian by `jax.jacfwd`) and the efficiency `CRB variance / MSE`;
over the converged realisations only, with their count (the straight model over all of
them: its bias is the question). Writes OUT.csv (one row per example, estimator and
parameter), OUT_statuses.csv and OUT.md with the command, commit, date and machine.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import sys
import time


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--records", type=int, default=50)
    parser.add_argument("--snr", type=float, default=25.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/general_backlash/study")
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
        simulate_general,
    )
    from jaxcascade._system._simulate import add_noise

    started = time.perf_counter()
    rows, status_rows = [], []
    for name, example in GENERAL_EXAMPLES.items():
        params, nd = example.params(), example.backlash()
        orders, degree = params.orders, nd.degree
        size = orders.size
        names = [*orders.names, *(f"mL{i}" for i in range(2, degree + 1))]
        names += [f"mR{i}" for i in range(2, degree + 1)]
        truth = np.concatenate([params.to_vector(), nd.curveL, nd.curveR])
        u = jc.uniform_input(jax.random.PRNGKey(args.seed), example.n_samples, example.amplitude)
        y0 = simulate_general(params, nd, u)

        def simulate_theta(theta, u=u, orders=orders, size=size, q1=degree - 1):
            p = jc.CascadeParams.from_vector(theta[:size], orders, check=False)
            curved = GeneralBacklash(p.cL, p.mR, p.cR, theta[size : size + q1], theta[size + q1 :])
            return simulate_general(p, curved, u)

        J = np.asarray(jax.jacfwd(simulate_theta)(jnp.asarray(truth)))
        sigma = float(np.std(np.asarray(y0))) / args.snr
        crb = np.sqrt(np.diag(np.linalg.pinv(J.T @ J)) * sigma**2)

        estimates = {"straight": [], "keyterm": [], "robust_general": []}
        statuses = {k: [] for k in estimates}
        for r in range(args.records):
            y = add_noise(jax.random.PRNGKey(args.seed + 1 + r), y0, args.snr)
            straight = Robust()(u, y, orders, key=jax.random.PRNGKey(10_000 + r))
            sp = straight.params
            estimates["straight"].append(np.asarray(sp.to_vector()))
            statuses["straight"].append(Status(int(straight.status)).name)
            fit = refine_general(sp, GeneralBacklash.straight(sp, degree), u, y)
            estimates["robust_general"].append(
                np.concatenate([fit.params.to_vector(), fit.backlash.curveL, fit.backlash.curveR])
            )
            statuses["robust_general"].append(Status(int(fit.status)).name)
            kt = key_term_general(u, y, orders, degree)
            estimates["keyterm"].append(
                np.concatenate([kt.params.to_vector(), kt.backlash.curveL, kt.backlash.curveR])
            )
            statuses["keyterm"].append(Status(int(kt.status)).name)
        for estimator, values in estimates.items():
            values = np.array(values)
            counts = pd.Series(statuses[estimator]).value_counts()
            status_rows.append(
                {"example": name, "estimator": estimator, "records": args.records}
                | {k: int(v) for k, v in counts.items()}
            )
            if estimator == "straight":
                keep = np.ones(len(values), bool)
                reference, bound, labels = truth[:size], crb[:size], names[:size]
            else:
                keep = np.array([s == "converged" for s in statuses[estimator]])
                reference, bound, labels = truth, crb, names
            kept = values[keep]
            for i, label in enumerate(labels):
                column = kept[:, i] if len(kept) else np.array([np.nan])
                error = column - reference[i]
                mse = float(np.mean(error**2))
                rows.append(
                    {
                        "example": name,
                        "estimator": estimator,
                        "parameter": label,
                        "used": int(keep.sum()),
                        "truth": reference[i],
                        "bias": float(np.mean(error)),
                        "bias_se": float(np.std(column, ddof=1) / np.sqrt(len(column)))
                        if len(column) > 1
                        else np.nan,
                        "std": float(np.std(column, ddof=1)) if len(column) > 1 else np.nan,
                        "rmse": float(np.sqrt(mse)),
                        "crb_std": float(bound[i]),
                        "efficiency": float(bound[i] ** 2 / mse) if mse > 0 else np.nan,
                    }
                )
    table = pd.DataFrame(rows)
    status_table = pd.DataFrame(status_rows).fillna(0)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(f"{out}.csv", index=False)
    status_table.to_csv(f"{out}_statuses.csv", index=False)
    command = "python benchmarks/general_backlash_study.py " + " ".join(
        sys.argv[1:] if argv is None else argv
    )
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    shown = table.copy()
    for column in ("truth", "bias", "bias_se", "std", "rmse", "crb_std", "efficiency"):
        shown[column] = shown[column].map(lambda v: f"{v:.3g}")
    summary = (
        table[table.estimator != "straight"]
        .groupby(["example", "estimator"])["efficiency"]
        .median()
        .map(lambda v: f"{v:.3g}")
        .reset_index()
        .rename(columns={"efficiency": "median_efficiency"})
    )
    lines = [
        "# The general-backlash estimators under noise: bias, spread, efficiency",
        "",
        f"`{command.strip()}`, commit {commit()}, {date}, {device_description()}, "
        f"{time.perf_counter() - started:.0f} s. {args.records} realisations per example at "
        f"SNR {args.snr:g}, one input (`PRNGKey({args.seed})`) for all, noise from "
        f"`PRNGKey({args.seed + 1})` on.",
        "",
        "`straight`: today's robust estimator with the straight backlash, over every "
        "realisation (its bias when the truth is curved); `keyterm` and `robust_general`: "
        "over their `converged` realisations (`used`). `crb_std`: the Cramér-Rao bound's "
        "std at the truth for white noise of the realised level; `efficiency`: CRB "
        "variance / MSE. `bias_se`: std / sqrt(used).",
        "",
        "## Statuses",
        "",
        markdown(status_table),
        "",
        "## Median efficiency over the parameters",
        "",
        markdown(summary),
        "",
        "## Per parameter",
        "",
        markdown(shown),
        "",
    ]
    pathlib.Path(f"{out}.md").write_text("\n".join(lines))
    print(status_table.to_string(index=False))
    print(summary.to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
