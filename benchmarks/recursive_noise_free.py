"""Issue 25: how close one on-line pass of the recursive estimator gets to the truth on
noise-free records of the paper's examples, at the paper's record lengths.

    python benchmarks/recursive_noise_free.py [--realisations 100] [--seed 0]
        [--out results/recursive_noise_free]

Realisation i is the record `jaxcascade reproduce --example E --seed SEED+i --snr inf`
draws (Example 1: N = 4000, Example 2: N = 2000). Variants of `recursive` (settings
otherwise the defaults: the on-line first iteration on 400 samples, projection on):

- `gradient, lam=0.93` / `0.95`: the gain's regressor the gradient of the key-term
  prediction (`gradient=True`, the recursive prediction-error form) at a constant
  factor (memory 14, 20 samples);
- `gradient, warm 1%, lam=0.99, delta=0.01`: the same from the truth perturbed by up
  to 1% (no first iteration), against the key-term regressor's `warm 1%` row below;
- `lam=0.98`, `0.95`, `0.93`: constant forgetting after the start (memory 50, 20, 14);
- `default`: the schedule that tends to 1, `lam_k = 1 - 1/(10 + 0.1 k + 3e-4 k^2)`;
- `warm 1%, lam=0.99, delta=0.01`: started at the truth perturbed by up to 1% per
  parameter, with no first iteration (the local contraction alone);
- `8 passes, lam=0.99`: the recursion run over the record 8 times: OFF-LINE (the
  estimate at t depends on later samples), shown for comparison, not on-line;
- `segments of 200, warm 1%`: not the recursion but the paper's batch iteration with one
  step per consecutive 200-sample segment (`_literal.voros_step`; signals from rest in
  each segment), from the same perturbed truth: whether the paper's fixed-point map
  contracts when each step sees only a short stretch of data, as an on-line recursion's
  memory does.

Per example x variant: the fractions whose largest parameter error is below 1e-6, 1e-3
and 0.05 (± binomial SE), its median, and that of the record `reproduce` draws at
seed 0. Writes OUT.csv and OUT.md.
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np

VARIANTS = {
    "gradient, lam=0.93": {"lam": 0.93, "gradient": True},
    "gradient, lam=0.95": {"lam": 0.95, "gradient": True},
    "gradient, warm 1%, lam=0.99, delta=0.01": {
        "lam": 0.99,
        "first_samples": 0,
        "delta": 0.01,
        "gradient": True,
    },
    "lam=0.98": {"lam": 0.98},
    "lam=0.95": {"lam": 0.95},
    "lam=0.93": {"lam": 0.93},
    "default": {},
    "warm 1%, lam=0.99, delta=0.01": {"lam": 0.99, "first_samples": 0, "delta": 0.01},
    "8 passes, lam=0.99 (off-line)": {"lam": 0.99, "passes": 8},
}


SEGMENTS = "segments of 200, warm 1% (batch steps)"


def segment_steps(U, Y, starts, orders, length):
    """The paper's iteration, one step per consecutive segment of `length` samples."""
    import jax
    import jax.numpy as jnp

    from jaxcascade._estimator._literal import voros_step
    from jaxcascade._system._model import CascadeParams

    def step(vector, u, y):
        params = CascadeParams.from_vector(vector, orders, check=False)
        new = voros_step(params, u, y, "xla")[0]
        # a step that blew up stays blown up (inf), never NaN in the table
        return jnp.where(jnp.all(jnp.isfinite(new)), new, jnp.inf)

    step = jax.jit(jax.vmap(step))
    vectors = starts
    for k in range(U.shape[1] // length):
        part = slice(k * length, (k + 1) * length)
        vectors = step(vectors, U[:, part], Y[:, part])
    return vectors


def summarise(number, n, label, estimates, truth, R, args) -> dict:
    largest = np.max(np.abs(np.asarray(estimates) - np.asarray(truth.to_vector())), axis=1)
    largest = np.where(np.isfinite(largest), largest, np.inf)
    row = {"example": number, "n": n, "variant": label}
    for tol in (1e-6, 1e-3, 0.05):
        rate = np.mean(largest < tol)
        row[f"below_{tol:g}"] = rate
        row[f"below_{tol:g}_se"] = np.sqrt(rate * (1 - rate) / R)
    row["median_largest_error"] = np.median(largest)
    row["reproduce_seed0_error"] = largest[0] if args.seed == 0 else np.nan
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realisations", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/recursive_noise_free")
    args = parser.parse_args(argv)

    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    import pandas as pd

    from jaxcascade._estimator._recursive import recursive
    from jaxcascade._system._examples import example
    from jaxcascade._system._model import CascadeParams
    from jaxcascade._system._simulate import measure, uniform_input

    R = args.realisations
    rows = []
    for number in (1, 2):
        ex = example(number)
        truth = ex.params()

        def draw(i, ex=ex, truth=truth):
            key_input, key_noise = jax.random.split(jax.random.PRNGKey(args.seed + i))
            u = uniform_input(key_input, ex.n_samples, ex.amplitude)
            return u, measure(key_noise, truth, u, jnp.inf)[0]

        U, Y = jax.jit(jax.vmap(draw))(np.arange(R))
        perturbation = 1 + 0.01 * jax.random.uniform(
            jax.random.PRNGKey(args.seed + 10_000), (R, ex.orders.size), minval=-1, maxval=1
        )
        starts = truth.to_vector() * perturbation
        for label, settings in [*VARIANTS.items(), (SEGMENTS, None)]:
            if settings is None:
                estimates = segment_steps(U, Y, starts, ex.orders, 200)
                rows.append(summarise(number, ex.n_samples, label, estimates, truth, R, args))
                print(rows[-1], flush=True)
                continue
            warm = settings.get("first_samples", 1) == 0

            def fit(u, y, start, settings=settings, warm=warm, ex=ex):
                init = CascadeParams.from_vector(start, ex.orders, check=False) if warm else None
                out = recursive(u, y, ex.orders, init, input_range=(-2.0, 2.0), **settings)
                return out.solution.params.to_vector()

            estimates = jax.jit(jax.vmap(fit))(U, Y, starts)
            rows.append(summarise(number, ex.n_samples, label, estimates, truth, R, args))
            print(rows[-1], flush=True)
    frame = pd.DataFrame(rows)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(out.with_suffix(".csv"), index=False)
    lines = [
        f"# Recursive estimator, noise-free, {R} records per example",
        "",
        f"Command: `python benchmarks/recursive_noise_free.py --realisations {R} --seed "
        f"{args.seed} --out {args.out}`. Largest absolute parameter error of the final "
        "estimate; record i as `jaxcascade reproduce --example E --seed i --snr inf` draws "
        "it (Example 1: N 4000; Example 2: N 2000). `gradient`: the gain's regressor the "
        "gradient of the key-term prediction (`Recursive(gradient=True)`); the others the "
        "key-term regressor. All on-line (one pass) except `8 passes`, which runs over "
        "the record 8 times; the last row is the paper's batch iteration with one step "
        "per 200-sample segment (the docstring says why).",
        "",
        "| example | variant | < 1e-6 | < 1e-3 | < 0.05 | median error "
        "| reproduce record (seed 0) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in frame.to_dict("records"):
        rates = " | ".join(
            f"{r[f'below_{tol:g}']:.2f} ± {r[f'below_{tol:g}_se']:.2f}"
            for tol in (1e-6, 1e-3, 0.05)
        )
        lines.append(
            f"| {r['example']} (N {r['n']}) | {r['variant']} | {rates} | "
            f"{r['median_largest_error']:.1e} | {r['reproduce_seed0_error']:.1e} |"
        )
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"written: {out}.csv, {out}.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
