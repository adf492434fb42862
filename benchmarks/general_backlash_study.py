"""Issue 39, point 4: the general-backlash estimators under noise over SNR and N, side by
side: bias, spread, RMSE and efficiency against the Cramér-Rao bound, each with its
standard error, and the bias of the straight-backlash model when the truth is curved.

    python benchmarks/general_backlash_study.py [--examples general1,general2]
        [--snr 10,25,50] [--n 1000,4000] [--noise white | ar:POLE] [--records 50]
        [--seed 0] [--reference 25,4000] [--out results/general_backlash/study]

A cell is an example of `jaxcascade._system._general_backlash.GENERAL_EXAMPLES`, an SNR
and a record length N. Its input is uniform in `(-amplitude, amplitude)` from
`PRNGKey(seed)` (one input per N, the same for every realisation); realisation r adds
output noise at the SNR (the paper's amplitude SNR, `add_noise`) from
`PRNGKey(seed + 1 + r)`: white Gaussian, or `ar:POLE` AR(1) noise of that pole
(`_disturbance.AR`), the same keys in every cell. Four fits per realisation:

- `straight`: today's robust estimator with the straight backlash (the 2016 model, key
  `PRNGKey(10000 + r)`);
- `keyterm`: the note's key-term iteration from the paper's initial values
  (`key_term_general`), the general model's literal estimator;
- `robust`: `straight` refined with curved branches (`refine_general`, i.e.
  `robust_general`);
- `pem`: the prediction-error estimate with an AR noise model of order <= 4 chosen by
  BIC (`pem_general`), started from `robust`'s fit.

Per cell, estimator and parameter: the bias with its standard error (std / sqrt(used)),
the std, the RMSE and its standard error (delta method on the mean squared error), the
Cramér-Rao bound's std at the truth (`_efficiency.crlb(..., backlash=)`, with the noise's
poles for coloured noise) and the efficiency `CRB variance / MSE` with its standard
error; over the `converged` realisations (`used`; the straight model over all of them:
its bias is the question). Per cell and estimator: the median efficiency over the
parameters with a bootstrap standard error (200 resamples of the realisations, seed 0).
Writes OUT.csv (one row per cell, estimator and parameter), OUT_cells.csv (one row per
cell and estimator, statuses included) and OUT.md with the command, commit, date and
machine; OUT.md's per-parameter table is the `--reference` cell's (SNR,N).
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import sys
import time

PARAMETER_COLUMNS = ("truth", "bias", "bias_se", "std", "rmse", "rmse_se", "crb_std")


def _numbers(text: str, kind):
    return [kind(v) for v in text.split(",") if v.strip()]


def summarise(values, truth, bound, rng, resamples: int = 200):
    """Per-parameter statistics of `values` (R x P estimates) against `truth` and the
    bound `bound` (P), and the median efficiency over the parameters with its bootstrap
    standard error (`rng` draws the resamples of the realisations)."""
    import numpy as np

    used = len(values)
    if used < 2:
        nan = np.full(len(truth), np.nan)
        return dict.fromkeys(("bias", "bias_se", "std", "rmse", "rmse_se", "eff", "eff_se"), nan), (
            np.nan,
            np.nan,
        )
    error = values - truth
    mse = np.mean(error**2, 0)
    mse_se = np.std(error**2, 0, ddof=1) / np.sqrt(used)
    std = np.std(values, 0, ddof=1)
    rmse = np.sqrt(mse)
    eff = np.where(mse > 0, bound**2 / np.where(mse > 0, mse, 1.0), np.nan)
    stats = {
        "bias": np.mean(error, 0),
        "bias_se": std / np.sqrt(used),
        "std": std,
        "rmse": rmse,
        "rmse_se": np.where(rmse > 0, mse_se / (2 * np.where(rmse > 0, rmse, 1.0)), np.nan),
        "eff": eff,
        "eff_se": eff * mse_se / np.where(mse > 0, mse, np.nan),
    }
    draws = rng.integers(0, used, size=(resamples, used))
    medians = [np.nanmedian(bound**2 / np.mean(error[d] ** 2, 0)) for d in draws]
    return stats, (float(np.nanmedian(eff)), float(np.std(medians, ddof=1)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", default="general1,general2")
    parser.add_argument("--snr", default="10,25,50")
    parser.add_argument("--n", default="1000,4000")
    parser.add_argument("--noise", default="white", help="white, or ar:POLE")
    parser.add_argument("--records", type=int, default=50)
    parser.add_argument(
        "--reference", default="25,4000", help="SNR,N of the per-parameter table in OUT.md"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/general_backlash/study")
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import pandas as pd
    from bench_history import commit  # the short hash, "-dirty" with package changes
    from loop_speed import markdown  # a pipe table without an optional dependency

    import jaxcascade as jc
    from jaxcascade._benchmark._timing import device_description
    from jaxcascade._estimator._efficiency import crlb, noise_bound_options
    from jaxcascade._estimator._general_keyterm import key_term_general
    from jaxcascade._estimator._general_pem import pem_general
    from jaxcascade._estimator._general_refine import refine_general
    from jaxcascade._estimator._robust import Robust
    from jaxcascade._experiment._disturbance import disturbance
    from jaxcascade._status import Status
    from jaxcascade._system._general_backlash import (
        GeneralBacklash,
        general_example,
        simulate_general,
    )
    from jaxcascade._system._simulate import add_noise

    if args.noise == "white":
        noise = None
    elif args.noise.startswith("ar:"):
        noise = disturbance("ar", poles=(float(args.noise[3:]),))
    else:
        parser.error(f"--noise {args.noise!r}: give white or ar:POLE (e.g. ar:0.8).")
    bound_options = noise_bound_options(noise)

    def vector(fit):
        return np.concatenate([fit.params.to_vector(), fit.backlash.curveL, fit.backlash.curveR])

    started = time.perf_counter()
    rng = np.random.default_rng(0)
    rows, cells = [], []
    for name in args.examples.split(","):
        example = general_example(name)
        params, nd = example.params(), example.backlash()
        orders, degree = params.orders, nd.degree
        size = orders.size
        names = [*orders.names, *(f"mL{i}" for i in range(2, degree + 1))]
        names += [f"mR{i}" for i in range(2, degree + 1)]
        truth = np.concatenate([params.to_vector(), nd.curveL, nd.curveR])
        for n in _numbers(args.n, int):
            u = jc.uniform_input(jax.random.PRNGKey(args.seed), n, example.amplitude)
            y0 = simulate_general(params, nd, u)
            for snr in _numbers(args.snr, float):
                bound = np.asarray(crlb(params, u, snr=snr, backlash=nd, **bound_options))
                estimates = {k: [] for k in ("straight", "keyterm", "robust", "pem")}
                statuses = {k: [] for k in estimates}
                for r in range(args.records):
                    y = add_noise(jax.random.PRNGKey(args.seed + 1 + r), y0, snr, noise)
                    straight = Robust()(u, y, orders, key=jax.random.PRNGKey(10_000 + r))
                    sp = straight.params
                    estimates["straight"].append(np.asarray(sp.to_vector()))
                    statuses["straight"].append(Status(int(straight.status)).name)
                    fit = refine_general(sp, GeneralBacklash.straight(sp, degree), u, y)
                    estimates["robust"].append(vector(fit))
                    statuses["robust"].append(Status(int(fit.status)).name)
                    prediction = pem_general(u, y, orders, degree, start=fit)
                    estimates["pem"].append(vector(prediction))
                    statuses["pem"].append(Status(int(prediction.status)).name)
                    kt = key_term_general(u, y, orders, degree)
                    estimates["keyterm"].append(vector(kt))
                    statuses["keyterm"].append(Status(int(kt.status)).name)
                cell = {"example": name, "noise": args.noise, "snr": snr, "n": n}
                for estimator, values in estimates.items():
                    values = np.array(values)
                    if estimator == "straight":  # its bias over every realisation
                        keep = np.ones(len(values), bool)
                        reference, bounds, labels = truth[:size], bound[:size], names[:size]
                    else:
                        keep = np.array([s == "converged" for s in statuses[estimator]])
                        reference, bounds, labels = truth, bound, names
                    stats, (median, median_se) = summarise(values[keep], reference, bounds, rng)
                    counts = pd.Series(statuses[estimator]).value_counts()
                    cells.append(
                        cell
                        | {"estimator": estimator, "records": args.records}
                        | {"used": int(keep.sum())}
                        | {"median_efficiency": median, "median_efficiency_se": median_se}
                        | {
                            "median_abs_bias_over_crb": float(
                                np.median(np.abs(stats["bias"]) / bounds)
                            ),
                            "max_abs_bias_over_se": float(
                                np.max(np.abs(stats["bias"]) / stats["bias_se"])
                            ),
                        }
                        | {f"status_{k}": int(v) for k, v in counts.items()}
                    )
                    for i, label in enumerate(labels):
                        rows.append(
                            cell
                            | {"estimator": estimator, "parameter": label}
                            | {"used": int(keep.sum()), "truth": reference[i]}
                            | {k: float(stats[k][i]) for k in PARAMETER_COLUMNS[1:-1]}
                            | {"crb_std": float(bounds[i])}
                            | {"efficiency": float(stats["eff"][i])}
                            | {"efficiency_se": float(stats["eff_se"][i])}
                        )
                print(
                    f"{name} N {n} SNR {snr:g}: {time.perf_counter() - started:.0f} s", flush=True
                )
    table = pd.DataFrame(rows)
    cell_table = pd.DataFrame(cells)
    status_columns = sorted(c for c in cell_table.columns if c.startswith("status_"))
    cell_table[status_columns] = cell_table[status_columns].fillna(0).astype(int)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(f"{out}.csv", index=False)
    cell_table.to_csv(f"{out}_cells.csv", index=False)

    command = "python benchmarks/general_backlash_study.py " + " ".join(
        sys.argv[1:] if argv is None else argv
    )
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")

    def shown(frame, columns):
        frame = frame.copy()
        for column in columns:
            frame[column] = frame[column].map(lambda v: f"{v:.3g}")
        return frame

    general = cell_table[cell_table.estimator != "straight"]
    efficiency = general.assign(
        efficiency=[
            f"{m:.3g} ± {s:.2g} ({u}/{r})"
            for m, s, u, r in zip(
                general.median_efficiency,
                general.median_efficiency_se,
                general.used,
                general.records,
                strict=True,
            )
        ]
    ).pivot_table(
        index=["example", "noise", "snr", "n"],
        columns="estimator",
        values="efficiency",
        aggfunc="first",
    )
    efficiency = efficiency[["keyterm", "robust", "pem"]].reset_index()
    straight = cell_table[cell_table.estimator == "straight"][
        ["example", "noise", "snr", "n", "median_abs_bias_over_crb", "max_abs_bias_over_se"]
    ]
    snr_ref, n_ref = _numbers(args.reference, float)
    reference = table[(table.snr == snr_ref) & (table.n == int(n_ref))]
    if reference.empty:  # the reference cell is not in the grid: the first cell
        reference = table[(table.snr == table.snr.iloc[0]) & (table.n == table.n.iloc[0])]
    lines = [
        "# The general-backlash estimators under noise: bias, spread, efficiency over SNR and N",
        "",
        f"`{command.strip()}`, commit {commit()}, {date}, {device_description()}, "
        f"{time.perf_counter() - started:.0f} s. {args.records} realisations per cell, "
        f"noise `{args.noise}`; one input per N (`PRNGKey({args.seed})`), noise from "
        f"`PRNGKey({args.seed + 1})` on, the same keys in every cell.",
        "",
        "`straight`: today's robust estimator with the straight backlash, over every "
        "realisation (its bias when the truth is curved); `keyterm` (the note's key-term "
        "iteration), `robust` (robust, then refined with curved branches) and `pem` "
        "(prediction error with an AR noise model, from `robust`'s fit): over their "
        "`converged` realisations (`used`/`records`). The bound is the Cramér-Rao bound "
        "at the truth for the noise as added (its poles included); efficiency: bound "
        "variance / MSE.",
        "",
        "## Median efficiency over the parameters (± bootstrap standard error, used/records)",
        "",
        markdown(efficiency),
        "",
        "## The straight-backlash model when the truth is curved",
        "",
        "Its bias in units of the curved model's bound (median over the cascade's "
        "parameters) and the largest bias in units of its own standard error (a bias of "
        "the model, not of the noise: compare the cells).",
        "",
        markdown(shown(straight, ("median_abs_bias_over_crb", "max_abs_bias_over_se"))),
        "",
        "## Statuses",
        "",
        markdown(cell_table[["example", "noise", "snr", "n", "estimator", *status_columns]]),
        "",
        f"## Per parameter at SNR {reference.snr.iloc[0]:g}, N {reference.n.iloc[0]} "
        f"(every cell: `{out.name}.csv`)",
        "",
        markdown(
            shown(
                reference.drop(columns=["noise", "snr", "n"]),
                (*PARAMETER_COLUMNS, "efficiency", "efficiency_se"),
            )
        ),
        "",
    ]
    pathlib.Path(f"{out}.md").write_text("\n".join(lines))
    print(efficiency.to_string(index=False))
    print(straight.to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
