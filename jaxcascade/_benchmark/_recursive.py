"""Speed of the recursive estimator (`jaxcascade bench --estimator recursive`): sample
updates per second of `vmap(recursive)` over a batch of records, against the plain NumPy
loop of the same recursion (`_recursive_baseline`), and the real-time factor.

The records (a paper example at its SNR) are simulated first and not timed: the figure
is the recursion alone, one `lax.scan` over time of the whole batch, compiled ahead of
time (compile time reported apart), best of `repeats` runs. The baseline runs a few
records one after another in this process. The real-time factor is how many times
faster than real time the batch is processed when each record is a stream sampled at
`sample_rate` Hz: `updates_per_s / (realisations * sample_rate)`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .._compile import compiler_options
from .._system._examples import example as get_example
from . import _recursive_baseline
from ._timing import device_description, peak_rss_mb

SUMMARY_KEYS = (
    "updates_per_s",
    "baseline_updates_per_s",
    "ratio",
    "real_time_factor",
    "sample_rate_hz",
    "realisations",
    "n",
    "compile_s",
    "device",
)


def records(example_number: int, realisations: int, n: int, seed: int = 0):
    """`(u, y)`, each `(realisations, n)`: inputs and noisy outputs of the example, drawn as
    `jaxcascade reproduce` draws one (input and noise keys the halves of one key)."""
    import jax

    from .._system._simulate import measure, uniform_input

    ex = get_example(example_number)
    truth = ex.params()

    def one(key):
        key_u, key_e = jax.random.split(key)
        u = uniform_input(key_u, n, ex.amplitude)
        return u, measure(key_e, truth, u, ex.snr)[0]

    return jax.jit(jax.vmap(one))(jax.random.split(jax.random.PRNGKey(seed), realisations))


def run_benchmark(
    realisations: int = 256,
    n: int = 4000,
    example_number: int = 1,
    baseline_realisations: int = 2,
    repeats: int = 3,
    seed: int = 0,
    sample_rate: float = 1000.0,
    settings: dict | None = None,
) -> dict:
    """Every figure of the benchmark as a dict (`SUMMARY_KEYS` and the details)."""
    import jax

    from .._estimator import estimator

    ex = get_example(example_number)
    fit = estimator("recursive", **(settings or {}))
    u, y = records(example_number, realisations, n, seed)
    bounds = (-ex.amplitude, ex.amplitude)

    def batch(u, y):
        solution = jax.vmap(lambda u, y: fit(u, y, ex.orders, input_range=bounds))(u, y)
        return solution.params.to_vector(), solution.status

    start = time.perf_counter()
    compiled = jax.jit(batch, compiler_options=compiler_options()).lower(u, y).compile()
    compile_s = time.perf_counter() - start
    best = math.inf
    for _ in range(max(repeats, 1)):
        start = time.perf_counter()
        estimates, statuses = jax.block_until_ready(compiled(u, y))
        best = min(best, time.perf_counter() - start)
    peak = peak_rss_mb()

    u_np, y_np = np.asarray(u[:baseline_realisations]), np.asarray(y[:baseline_realisations])
    options = {name: getattr(fit, name) for name in _BASELINE_SETTINGS}
    start = time.perf_counter()
    baseline = np.array(
        [
            _recursive_baseline.recursive(a, b, ex.orders, input_range=bounds, **options)
            for a, b in zip(u_np, y_np, strict=True)
        ]
    )
    baseline_s = time.perf_counter() - start
    difference = float(np.max(np.abs(baseline - np.asarray(estimates[:baseline_realisations]))))
    updates = realisations * n * fit.passes
    codes, counts = np.unique(np.asarray(statuses), return_counts=True)
    record = {
        "example": example_number,
        "n": n,
        "snr": ex.snr,
        "realisations": realisations,
        "device": device_description(),
        "updates_per_s": updates / best,
        "run_s": best,
        "compile_s": compile_s,
        "peak_mem_mb": peak,
        "status_counts": dict(zip(codes.tolist(), counts.tolist(), strict=True)),
        "baseline_realisations": baseline_realisations,
        "baseline_s": baseline_s,
        "baseline_updates_per_s": baseline_realisations * n / baseline_s,
        "baseline_max_difference": difference,
        "sample_rate_hz": sample_rate,
        "settings": {name: getattr(fit, name) for name in fit.settings()},
    }
    record["ratio"] = record["updates_per_s"] / record["baseline_updates_per_s"]
    record["real_time_factor"] = record["updates_per_s"] / (realisations * sample_rate)
    return record


# The settings the NumPy loop shares with `Recursive` (one pass, no trajectory).
_BASELINE_SETTINGS = (
    "lam",
    "memory0",
    "growth",
    "acceleration",
    "first_samples",
    "anti_windup",
    "delta",
    "project",
)


def default_first_samples() -> int:
    """The first iteration's length in `Recursive`'s defaults (a record must be longer)."""
    from .._estimator import ESTIMATORS

    return ESTIMATORS["recursive"].settings()["first_samples"]


def summary(record: dict) -> dict:
    return {key: record[key] for key in SUMMARY_KEYS}
