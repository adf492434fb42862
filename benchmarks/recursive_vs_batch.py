"""Issue 25: the recursive estimator's final estimate against the batch literal
iteration, on the same records.

    python benchmarks/recursive_vs_batch.py [--realisations 200] [--snr 25] [--n 4000]
        [--seed 0] [--out results/recursive_vs_batch]

Example 1 (input uniform in (-2, 2)); realisation i is the record `jaxcascade reproduce
--example 1 --seed SEED+i --snr SNR` draws (input and noise keys the halves of
`PRNGKey(SEED + i)`). Each record is fitted by

- `literal`: the paper's iteration (eqs. 19-28) from its initial values, at its defaults;
- `recursive`: one on-line pass of `Recursive` at its defaults: the forgetting factor
  `lam_k = 1 - 1 / (10 + 0.1 k + 3e-4 k^2)` tends to 1 (the memory starts at 10 samples
  after the on-line first iteration, whose information is kept, and grows slowly, then
  like k^2: early regressors, built from poor estimates, fade, and the later record
  tends to equal weights; `_rls.forgetting`);
- `recursive_gradient`: the same schedule, the gain's regressor the gradient of the
  key-term prediction (`gradient=True`, the recursive prediction-error form);
- `recursive_linear`: the previous default, a memory that grows linearly only,
  `lam_k = 1 - 1 / (10 + 0.25 k)` (sample s weighs `(s / k)^4` at time k).

The defaults were chosen on records 0..63 (`--seed 0`); the committed table uses
`--seed 1000` (records 1000..1199), records the choice never saw.

Per estimator and parameter: the RMSE of the final estimate over all realisations
(whatever the status), its Monte-Carlo standard error (delta method:
`sd(e^2) / (2 RMSE sqrt(R))`), the ratio to the literal RMSE with a paired bootstrap
standard error (2000 resamples of the realisations), and the fraction recovered (every
parameter within 0.05 of the truth). Writes OUT.csv and OUT.md.
"""

from __future__ import annotations

import argparse
import pathlib
import time

import numpy as np

VARIANTS = {
    "literal": ("literal", {}),
    "recursive": ("recursive", {}),
    "recursive_gradient": ("recursive", {"gradient": True}),
    "recursive_linear": ("recursive", {"growth": 0.25, "acceleration": 0.0}),
}


def records(number, realisations, snr, n, seed):
    import jax

    from jaxcascade._system._examples import example
    from jaxcascade._system._simulate import measure, uniform_input

    ex = example(number)

    def one(i):
        key_input, key_noise = jax.random.split(jax.random.PRNGKey(seed + i))
        u = uniform_input(key_input, n, ex.amplitude)
        return u, measure(key_noise, ex.params(), u, snr)[0]

    return jax.jit(jax.vmap(one))(np.arange(realisations))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realisations", type=int, default=200)
    parser.add_argument("--snr", type=float, default=25.0)
    parser.add_argument("--n", type=int, default=4000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/recursive_vs_batch")
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import pandas as pd

    from jaxcascade._estimator import estimator
    from jaxcascade._status import Status
    from jaxcascade._system._examples import example

    ex = example(1)
    truth = np.asarray(ex.params().to_vector())
    U, Y = records(1, args.realisations, args.snr, args.n, args.seed)
    errors, rows = {}, []
    for label, (name, settings) in VARIANTS.items():
        fit = estimator(name, **settings)
        start = time.perf_counter()
        solution = jax.jit(
            jax.vmap(lambda u, y, fit=fit: fit(u, y, ex.orders, input_range=(-2.0, 2.0)))
        )(U, Y)
        wall = time.perf_counter() - start
        errors[label] = np.asarray(solution.params.to_vector()) - truth
        statuses = np.asarray(solution.status)
        counts = {s.name: int(np.sum(statuses == s)) for s in Status if np.any(statuses == s)}
        print(f"{label}: {wall:.1f} s (with compilation), statuses {counts}", flush=True)
        rows.append((label, counts))

    rng = np.random.default_rng(args.seed)
    R = args.realisations
    boot = rng.integers(0, R, size=(2000, R))
    base = errors["literal"]
    table = []
    for label, counts in rows:
        e = errors[label]
        rmse = np.sqrt(np.mean(e**2, axis=0))
        se = np.std(e**2, axis=0, ddof=1) / (2 * rmse * np.sqrt(R))
        ratio = rmse / np.sqrt(np.mean(base**2, axis=0))
        boot_ratio = np.sqrt(np.mean(e[boot] ** 2, axis=1)) / np.sqrt(
            np.mean(base[boot] ** 2, axis=1)
        )
        recovered = np.all(np.abs(e) <= 0.05, axis=1)
        for j, parameter in enumerate(ex.orders.names):
            table.append(
                {
                    "estimator": label,
                    "parameter": parameter,
                    "rmse": rmse[j],
                    "rmse_se": se[j],
                    "ratio_to_literal": ratio[j],
                    "ratio_se": np.std(boot_ratio[:, j], ddof=1),
                    "recovered_rate": recovered.mean(),
                    "recovered_se": np.sqrt(recovered.mean() * (1 - recovered.mean()) / R),
                    "statuses": " ".join(f"{k}:{v}" for k, v in counts.items()),
                }
            )
    frame = pd.DataFrame(table)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(out.with_suffix(".csv"), index=False)
    out.with_suffix(".md").write_text(markdown(frame, args))
    print(f"written: {out}.csv, {out}.md")
    return 0


def markdown(frame, args) -> str:
    labels = list(VARIANTS)
    wide = frame.pivot(index="parameter", columns="estimator")
    names = list(dict.fromkeys(frame["parameter"]))
    lines = [
        f"# Recursive vs batch: Example 1, SNR {args.snr:g}, N {args.n}, "
        f"{args.realisations} realisations",
        "",
        f"Command: `python benchmarks/recursive_vs_batch.py --realisations {args.realisations} "
        f"--snr {args.snr:g} --n {args.n} --seed {args.seed} --out {args.out}`. "
        "RMSE of the final estimate over all realisations (± Monte-Carlo standard error); "
        "ratio to the literal iteration's RMSE on the same records (± paired bootstrap "
        "SE). `recursive`: one on-line pass at the defaults, forgetting factor "
        "`lam_k = 1 - 1/(10 + 0.1 k + 3e-4 k^2)`, which tends to 1; `recursive_gradient`: "
        "the same with the gain's regressor the gradient of the key-term prediction "
        "(`gradient=True`); `recursive_linear`: the previous default schedule "
        "`lam_k = 1 - 1/(10 + 0.25 k)`. The schedule was chosen on records 0..63; these "
        "are records the choice never saw when SEED is 1000.",
        "",
        "| parameter | "
        + " | ".join(f"{label} RMSE" for label in labels)
        + " | "
        + " | ".join(f"{label} / literal" for label in labels[1:])
        + " |",
        "|---|" + "---|" * (2 * len(labels) - 1),
    ]
    for name in names:
        cells = [
            f"{wide.loc[name, ('rmse', label)]:.4f} ± {wide.loc[name, ('rmse_se', label)]:.4f}"
            for label in labels
        ]
        cells += [
            f"{wide.loc[name, ('ratio_to_literal', label)]:.2f} ± "
            f"{wide.loc[name, ('ratio_se', label)]:.2f}"
            for label in labels[1:]
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "| estimator | recovered (all within 0.05) | statuses |", "|---|---|---|"]
    for label in labels:
        row = frame[frame["estimator"] == label].iloc[0]
        lines.append(
            f"| {label} | {row.recovered_rate:.3f} ± {row.recovered_se:.3f} | {row.statuses} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
