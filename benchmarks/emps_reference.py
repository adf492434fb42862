"""Issue 32: what EMPS's test error asks of a model, by models outside the loop.

    python benchmarks/emps_reference.py [--data ../shared/data/nonlinear_benchmarks]
        [--out results/nonlinear_benchmarks/emps_reference]

EMPS's output is a position that integrates the modelled velocity, so its test RMSE is
the drift of that velocity summed over 24,841 samples. The loop's final model misses the
published linear state-space figure (`results/nonlinear_benchmarks/README.md`); this
script measures how far models built for exactly that drift get, on the same official
split and scoring (`jc.benchmark_data("EMPS")`: train DATA_EMPS, test DATA_EMPS_PULSES,
position in mm, RMSE of `y[n_init:]`), at the full 1 kHz rate. Each model is a velocity
difference equation integrated to a position:

    v(t) = a1 v(t-1) + a2 v(t-2) + b1 u(t-1) + b2 u(t-2) - F(v(t-1)) + c
    F(v) = (fc + fs exp(-(v / vs)^2)) tanh(v / eps)
    y(t) = y(t-1) + v(t)

- `linear`: fc = c = 0 (a linear output-error model of the velocity; the loop's cascade
  contains it);
- `offset`: c free (a constant force: the drive's offset or an average friction);
- `friction`: fc and c free (Coulomb friction acting on the model's *own* velocity, a
  feedback of the output, smoothed over `eps` = 2e-6 m per sample = 2 mm/s);
- `stribeck`: fc, fs and c free (friction that falls from fc + fs at rest to fc in
  motion over `vs` = 2e-5 m per sample = 20 mm/s: the Stribeck curve).

Each is fitted on one of two spans of the training record, by least squares (SciPy's trust-region
reflective method, exact Jacobians from JAX, a fixed grid of starts, the lowest cost
kept) on one of two criteria: `velocity` (the simulated velocity's error, as the loop
fits the output's difference) or `position` (the integrated position's error, the
benchmark's own measure). Spans: `whole` (all 24,841 samples) or `estimation` (the
samples the loop estimates on, `_benchmark_protocol.benchmark_split` at the loop's
default MAX and decimation: the first three quarters; the loop holds the last quarter
back for validation). Scoring: the model simulated from rest over the whole test
record (it starts at rest), its position set to the measured one at sample n_init - 1,
RMSE of samples n_init onwards in mm; the training record is scored the same way.

Writes OUT.csv and OUT.md with the command, machine, commit and date. About a minute.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).parent))
import bench_history  # noqa: E402
import loop_speed  # noqa: E402

# The velocity's unit inside the fit (m per sample): the parameters are of order one.
VELOCITY_UNIT = 1e-4
# The smoothing of the Coulomb friction's sign, in VELOCITY_UNIT (2e-6 m per sample).
EPS = 0.02
# The Stribeck velocity, in VELOCITY_UNIT (2e-5 m per sample).
VS = 0.2
MODELS = {  # name: (friction free, offset free, Stribeck term free)
    "linear": (False, False, False),
    "offset": (False, True, False),
    "friction": (True, True, False),
    "stribeck": (True, True, True),
}
SPANS = ("whole", "estimation")
# parameter vector: a1, a2, b1, b2, fc, c, fs (VELOCITY_UNIT per sample)
LOWER = np.array([0.0, -1.0, -10.0, -10.0, 0.0, -10.0, -10.0])
UPPER = np.array([0.99999, 1.0, 10.0, 10.0, 10.0, 10.0, 10.0])
STARTS = [(a, fc) for a in (0.9, 0.98) for fc in (0.0, 0.05)]


def simulator():
    import jax
    import jax.numpy as jnp

    @jax.jit
    def velocity(theta, u):
        a1, a2, b1, b2, fc, c, fs = theta

        def step(carry, u_t):
            v1, v2, u1, u2 = carry
            friction = (fc + fs * jnp.exp(-((v1 / VS) ** 2))) * jnp.tanh(v1 / EPS)
            v = a1 * v1 + a2 * v2 + b1 * u1 + b2 * u2 - friction + c
            return (v, v1, u_t, u1), v

        zero = jnp.zeros((), u.dtype)
        _, v = jax.lax.scan(step, (zero, zero, zero, zero), u)
        return v * VELOCITY_UNIT

    return velocity


def fit(velocity, u, y, model: str, criterion: str, factor: float):
    """The lowest-cost fit of `model` on one record by `criterion`; returns
    (theta, in-sample RMSE of the criterion in the benchmark's unit, starts, seconds)."""
    import jax
    import jax.numpy as jnp
    import scipy.optimize as so

    friction, offset, stribeck = MODELS[model]
    free = np.array([True, True, True, True, friction, offset, stribeck])
    u_j, y_j = jnp.asarray(u), jnp.asarray(y)
    dy = jnp.diff(y_j, prepend=y_j[:1])

    def full(z):
        return jnp.zeros(7, z.dtype).at[np.flatnonzero(free)].set(z)

    def residual(z):
        v = velocity(full(z), u_j)
        if criterion == "velocity":
            return (dy - v) * factor
        return (y_j - (y_j[0] + jnp.cumsum(v) - v[0])) * factor

    residual_j = jax.jit(residual)
    jacobian_j = jax.jit(jax.jacfwd(residual))

    def safe(z):
        return np.nan_to_num(np.asarray(residual_j(z)), nan=1e6, posinf=1e6, neginf=-1e6)

    def safe_jacobian(z):
        return np.nan_to_num(np.asarray(jacobian_j(z)))

    began = time.perf_counter()
    best = None
    starts = [(a, fc) for a, fc in STARTS if friction or fc == 0.0]
    for a, fc in starts:
        start = np.array([a, 0.0, 1.0 - a, 0.0, fc, 0.0, 0.0])[free]
        result = so.least_squares(
            safe, start, jac=safe_jacobian, bounds=(LOWER[free], UPPER[free]), max_nfev=300
        )
        if best is None or result.cost < best.cost:
            best = result
    rmse = float(np.sqrt(2 * best.cost / len(u)))
    return np.asarray(full(jnp.asarray(best.x))), rmse, len(starts), time.perf_counter() - began


def estimation_samples(train) -> int:
    """The number of leading training samples (at 1 kHz) the loop estimates on with its
    defaults: `benchmark_split` at the default MAX and the benchmark's decimation."""
    from jaxcascade import _defaults
    from jaxcascade._measured._benchmark_protocol import benchmark_decimation, benchmark_split

    records = [("train", np.asarray(train.u), np.asarray(train.y))]
    most = _defaults.MAX_SAMPLES
    decimation = benchmark_decimation(records, most)
    split = benchmark_split(records, most * decimation)
    return len(split["estimation"][-1][1])


def test_rmse(velocity, theta, u, y, n_init: int, factor: float) -> float:
    """The benchmark's test RMSE: simulated from rest, the position set to the measured
    one at sample n_init - 1, RMSE of samples n_init onwards."""
    v = np.asarray(velocity(theta, np.asarray(u)))
    position = np.cumsum(v)
    position = position - position[n_init - 1] + y[n_init - 1]
    return float(np.sqrt(np.mean(((y[n_init:] - position[n_init:]) * factor) ** 2)))


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    import pandas as pd

    import jaxcascade as jc
    from jaxcascade._benchmark._timing import device_description

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="../shared/data/nonlinear_benchmarks")
    parser.add_argument("--out", default="results/nonlinear_benchmarks/emps_reference")
    args = parser.parse_args(argv)
    bench = jc.benchmark_data("EMPS", args.data)
    train, test = bench.train[0], bench.test[0]
    factor, n_init = bench.unit_factor, bench.n_init
    cut = estimation_samples(train)
    velocity = simulator()
    rows = []
    for span, model, criterion in itertools.product(SPANS, MODELS, ("velocity", "position")):
        kept = slice(None) if span == "whole" else slice(0, cut)
        u, y = np.asarray(train.u)[kept], np.asarray(train.y)[kept]
        theta, rmse, starts, seconds = fit(velocity, u, y, model, criterion, factor)
        a = np.array([1.0, -theta[0], -theta[1]])
        rows.append(
            {
                "span": span,
                "samples": len(u),
                "model": model,
                "criterion": criterion,
                "fit_rmse": rmse,
                "train_rmse": test_rmse(velocity, theta, train.u, train.y, n_init, factor),
                "test_rmse": test_rmse(velocity, theta, test.u, test.y, n_init, factor),
                "largest_pole": float(np.max(np.abs(np.roots(a)))),
                "friction": float(theta[4] * VELOCITY_UNIT),
                "stribeck": float(theta[6] * VELOCITY_UNIT),
                "offset": float(theta[5] * VELOCITY_UNIT),
                "starts": starts,
                "seconds": round(seconds, 1),
            }
        )
        print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out.with_suffix(".csv"), index=False)
    commit = bench_history.commit()  # "-dirty" where the package differs from HEAD
    published = bench.published.get("test", {})
    shown = table.copy()
    for column in ("fit_rmse", "train_rmse", "test_rmse", "largest_pole"):
        shown[column] = shown[column].map(lambda v: f"{v:.4g}")
    for column in ("friction", "offset", "stribeck"):
        shown[column] = shown[column].map(lambda v: f"{v:.3g}")
    best = table.loc[table["test_rmse"].idxmin()]
    estimation = table[table["span"] == "estimation"]
    on_estimation = estimation.loc[estimation["test_rmse"].idxmin()]
    linear = min(v for k, v in published.items() if k.startswith("linear"))
    lines = [
        "# EMPS: what its test error asks of a model (models outside the loop)",
        "",
        f"`python benchmarks/emps_reference.py --data {args.data}`, commit {commit}, "
        f"{datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds')}, "
        f"{device_description()}.",
        "",
        "Velocity difference equations of order 2 integrated to the position, fitted at "
        f"1 kHz on the whole training record or on its first {cut} samples (the span the "
        "loop estimates on) and scored on the official test record as the "
        f"collection scores it (RMSE in {bench.unit} of samples n_init = {n_init} onwards, "
        "the position set at sample n_init - 1; the script's docstring has the models "
        "and the criteria). `fit_rmse`: the criterion's in-sample RMSE (mm per sample "
        "for the velocity criterion, mm for the position); `friction`, `offset`, "
        "`stribeck`: fc, c and fs in m per sample.",
        "",
        loop_speed.markdown(shown),
        "",
        "Published (Champneys et al. 2024, this split): "
        + ", ".join(f"{k} {v:g}" for k, v in published.items())
        + f" {bench.unit}.",
        "",
        f"The lowest test RMSE here: {best['test_rmse']:.3g} {bench.unit} "
        f"(`{best['model']}`, {best['criterion']} criterion, {best['span']} span), "
        + ("below" if best["test_rmse"] < linear else "not below")
        + f" the best published linear figure ({linear:g} {bench.unit}); on the span the "
        f"loop estimates on, the lowest is {on_estimation['test_rmse']:.3g} {bench.unit} "
        f"(`{on_estimation['model']}`, {on_estimation['criterion']} criterion).",
    ]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
