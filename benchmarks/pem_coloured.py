"""Issue 24: the prediction-error estimator's efficiency under AR(1) output noise, with
noise drawn here (the sweep's own noise kinds are another branch's).

    python benchmarks/pem_coloured.py [--pole 0.9] [--realisations 100] [--seed 0]
        [--estimators pem,robust] [--out results/pem_coloured]

Example 1 (N 4000) and Example 2 (N 2000), SNR 25 (`sqrt(var y / var e)` of the noise as
added), `e = w / (1 - pole q^-1)` started stationary. Every estimator fits the same
records (`vmap` over realisations, in chunks). Per parameter: bias, std, RMSE, the
coloured-noise Cramér-Rao bound (`crlb(..., poles=(pole,))`, each record's own, the root
of their mean square) and the efficiency `crlb^2 / std^2`, each with its Monte-Carlo SE
(`_montecarlo._tables`' formulas); per cell the recovered rate (converged, every
parameter within 0.05) and the median efficiency over the parameters. Writes `OUT.csv`
and `OUT.md`.
"""

from __future__ import annotations

import argparse
import pathlib
import time

N = {1: 4000, 2: 2000}
SNR = 25.0
TOLERANCE = 0.05


def ar_noise(key, n, pole, dtype):
    """Unit-variance stationary AR(1) noise."""
    import jax
    import jax.numpy as jnp

    w = jax.random.normal(key, (n,), dtype)
    first = w[0] / jnp.sqrt(1 - pole**2)

    def step(previous, value):
        e = pole * previous + value
        return e, e

    _, rest = jax.lax.scan(step, first, w[1:])
    return jnp.concatenate([first[None], rest]) * jnp.sqrt(1 - pole**2)


def records(number, pole, realisations, seed):
    import jax
    import jax.numpy as jnp

    from jaxcascade import crlb, example, simulate, uniform_input

    ex = example(number)
    truth = ex.params(jnp.float64)
    n = N[number]

    def one(key):
        key_u, key_e = jax.random.split(key)
        u = uniform_input(key_u, n, 2.0, jnp.float64)
        y0 = simulate(truth, u)
        y = y0 + jnp.std(y0) / SNR * ar_noise(key_e, n, pole, jnp.float64)
        return u, y, crlb(truth, u, snr=SNR, poles=(pole,)), crlb(truth, u, snr=SNR)

    keys = jax.random.split(jax.random.PRNGKey(seed + 1000 * number), realisations)
    return jax.jit(jax.vmap(one))(keys), keys, truth


def fit_all(name, u, y, keys, orders, chunk):
    import jax
    import numpy as np

    from jaxcascade import estimator

    fit = estimator(name)
    batched = jax.jit(jax.vmap(lambda u, y, k: fit(u, y, orders, key=k)))
    estimates, statuses = [], []
    start = time.perf_counter()
    for i in range(0, u.shape[0], chunk):
        solution = jax.device_get(batched(u[i : i + chunk], y[i : i + chunk], keys[i : i + chunk]))
        estimates.append(np.asarray(solution.params.to_vector()))
        statuses.append(np.asarray(solution.status))
    return np.concatenate(estimates), np.concatenate(statuses), time.perf_counter() - start


def rows(number, name, estimates, statuses, truth, bounds, white_bounds, seconds):
    import numpy as np

    m = len(estimates)
    error = estimates - truth[None]
    recovered = (statuses == 0) & np.all(np.abs(error) <= TOLERANCE, axis=1)
    out = []
    for j, parameter in enumerate(NAMES):
        std = float(np.std(estimates[:, j], ddof=1))
        variances = bounds[:, j] ** 2
        bound_variance = float(np.mean(variances))
        bound_se = float(np.std(variances, ddof=1) / np.sqrt(m))
        efficiency = bound_variance / std**2
        relative = np.sqrt(2 / (m - 1) + (bound_se / bound_variance) ** 2)
        rmse = float(np.sqrt(np.mean(error[:, j] ** 2)))
        out.append(
            {
                "system": f"example{number}",
                "n": N[number],
                "snr": SNR,
                "estimator": name,
                "parameter": parameter,
                "realisations": m,
                "bias": float(np.mean(error[:, j])),
                "bias_se": std / np.sqrt(m),
                "std": std,
                "std_se": std / np.sqrt(2 * (m - 1)),
                "rmse": rmse,
                "rmse_se": float(np.std(error[:, j] ** 2, ddof=1) / np.sqrt(m) / (2 * rmse)),
                "crlb_std": np.sqrt(bound_variance),
                "efficiency": efficiency,
                "efficiency_se": efficiency * relative,
                "white_crlb_std": float(np.sqrt(np.mean(white_bounds[:, j] ** 2))),
                "recovered_rate": float(np.mean(recovered)),
                "recovered_rate_se": float(np.sqrt(recovered.mean() * (1 - recovered.mean()) / m)),
                "seconds_per_fit": seconds / m,
            }
        )
    return out


NAMES: tuple[str, ...] = ()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pole", type=float, default=0.9)
    parser.add_argument("--realisations", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--estimators", default="pem,robust")
    parser.add_argument("--chunk", type=int, default=50)
    parser.add_argument("--out", default="results/pem_coloured")
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import pandas as pd

    from jaxcascade import example

    global NAMES
    table = []
    for number in (1, 2):
        ex = example(number)
        NAMES = ex.orders.names
        drawn, keys, truth = records(number, args.pole, args.realisations, args.seed)
        u, y, bounds, white = drawn
        for name in args.estimators.split(","):
            estimates, statuses, seconds = fit_all(name, u, y, keys, ex.orders, args.chunk)
            new = rows(
                number, name, estimates, statuses, np.asarray(truth.to_vector()),
                np.asarray(bounds), np.asarray(white), seconds,
            )  # fmt: skip
            table += new
            median = np.median([r["efficiency"] for r in new])
            rate = new[0]["recovered_rate"]
            print(f"example{number} {name}: median efficiency {median:.3f}, recovered {rate:.3f}")
    frame = pd.DataFrame(table)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(out.with_suffix(".csv"), index=False)
    lines = [
        f"# Efficiency under AR(1) output noise, pole {args.pole:g}, SNR {SNR:g}",
        "",
        f"`python benchmarks/pem_coloured.py --pole {args.pole:g} --realisations "
        f"{args.realisations} --seed {args.seed} --estimators {args.estimators} --out {args.out}`",
        "",
        "Efficiency = coloured-noise Cramér-Rao bound² / std² (± Monte-Carlo SE).",
        "",
        "| system | estimator | recovered | median efficiency | min | max | s/fit |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for (system, name), group in frame.groupby(["system", "estimator"], sort=False):
        e = group["efficiency"].to_numpy()
        lines.append(
            f"| {system} | {name} | {group['recovered_rate'].iloc[0]:.3f} | "
            f"{np.median(e):.3f} | {e.min():.2f} | {e.max():.2f} | "
            f"{group['seconds_per_fit'].iloc[0]:.2f} |"
        )
    lines += ["", "| system | estimator | parameter | bias | std | crlb | efficiency |",
              "|---|---|---|---:|---:|---:|---:|"]  # fmt: skip
    for r in table:
        lines.append(
            f"| {r['system']} | {r['estimator']} | {r['parameter']} | {r['bias']:.2e} ± "
            f"{r['bias_se']:.1e} | {r['std']:.2e} | {r['crlb_std']:.2e} | "
            f"{r['efficiency']:.2f} ± {r['efficiency_se']:.2f} |"
        )
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"written: {out.with_suffix('.csv')}, {out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
