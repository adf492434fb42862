"""Timing of the robust estimator's Monte-Carlo workload (`jaxcascade bench --estimator
robust --system ...`) against a SciPy output-error multi-start; the same workload for
any other registered estimator (`pem`, or a user's: `bench --estimator NAME`), batched
and compiled for an `Estimator`, one record after another for a host function.

Per realisation: draw a uniform input in (-2, 2), the system (a paper example, or for
`random` a fresh draw from the prior, `_prior.py`), simulate, add output noise at the
system's SNR and fit with `robust` at its defaults. jaxcascade's figure is the batched,
compiled path (`vmap` over PRNG keys, compiled ahead of time and timed apart, best of
`repeats` runs); `recovered` is the fraction of fits that converged with every
parameter within 0.05 of its truth.

The baseline is what a careful user would write with SciPy: the simulator of
`_baseline` (NumPy, `lfilter`, the clamp prefix scan of the backlash) and
`scipy.optimize.least_squares` (trust-region reflective, finite-difference Jacobian,
the parameters boxed into the admissible ranges) from `n_starts` draws of the prior
plus the paper's initial values, on the first `subset` samples, then the best
`n_refine` on the whole record: records one after another, timed on a few.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .._compile import compiler_options
from .._system._examples import example as get_example
from .._system._model import Orders
from . import _baseline
from ._timing import device_description, peak_rss_mb

SYSTEMS = {
    # name: (example number or None for the random family, N, SNR)
    "example1": (1, 4000, 25.0),
    "example2": (2, 2000, 25.0),
    "random": (None, 3000, 30.0),
}
SUMMARY_KEYS = (
    "estimator",
    "system",
    "fits_per_s",
    "compile_s",
    "recovered",
    "baseline_fits_per_s",
    "ratio",
    "device",
)
TOLERANCE = 0.05
AMPLITUDE = 2.0


def system_defaults(system: str) -> tuple[int, float]:
    """`(N, SNR)` of a benchmark system."""
    if system not in SYSTEMS:
        raise ValueError(f"Unknown system {system!r}; known: {', '.join(SYSTEMS)}.")
    return SYSTEMS[system][1:]


def _record(system: str, n: int, snr: float):
    """`key -> (u, y, truth vector, fit key)`: one record of the workload."""
    import jax

    from .._system._prior import random_system
    from .._system._simulate import measure, uniform_input

    number = SYSTEMS[system][0]
    orders = Orders()

    def one(key):
        key_system, key_u, key_e, key_fit = jax.random.split(key, 4)
        u = uniform_input(key_u, n, AMPLITUDE)
        if number is None:
            truth = random_system(key_system, orders, AMPLITUDE, u.dtype)
        else:
            truth = get_example(number).params(u.dtype)
        y, _ = measure(key_e, truth, u, snr)
        return u, y, truth.to_vector(), key_fit

    return one


def batched_fit(
    system: str, n: int, snr: float, settings: dict | None = None, name: str = "robust"
):
    """The jitted batched workload `keys -> (estimates, truths, statuses, paths)` of the
    registered estimator `name` (an `Estimator`) with `settings`."""
    import jax

    from .._estimator import estimator

    fit = estimator(name, **(settings or {}))
    record = _record(system, n, snr)

    def one(key):
        u, y, truth, key_fit = record(key)
        solution = fit(u, y, Orders(), key=key_fit)
        return solution.params.to_vector(), truth, solution.status, solution.path

    return jax.jit(jax.vmap(one), compiler_options=compiler_options())


def _host_run(system, name, settings, keys, n, snr):
    """A host estimator over the workload's records, one after another: the outputs of
    `batched_fit`, the compile time of the draw and the seconds of the fits."""
    import jax

    from .._estimator import estimator

    fit = estimator(name, **(settings or {}))
    start = time.perf_counter()
    draw = jax.jit(jax.vmap(_record(system, n, snr))).lower(keys).compile()
    compile_s = time.perf_counter() - start
    u, y, truths, _ = (np.asarray(a) for a in jax.device_get(draw(keys)))
    solutions = []
    start = time.perf_counter()
    for i in range(len(keys)):
        solutions.append(fit(u[i], y[i], Orders()))
    seconds = time.perf_counter() - start
    estimates = np.stack([np.asarray(s.params.to_vector()) for s in solutions])
    statuses = np.array([int(s.status) for s in solutions])
    paths = np.array([int(s.path) for s in solutions])
    return (estimates, truths, statuses, paths), compile_s, seconds


def run_jax(
    system, realisations=256, n=None, snr=None, repeats=1, seed=0, settings=None, name="robust"
):
    import jax

    from .._estimator import estimator, is_host
    from .._status import Status

    n_default, snr_default = system_defaults(system)
    n, snr = n or n_default, snr or snr_default
    keys = jax.random.split(jax.random.PRNGKey(seed), realisations)
    if is_host(estimator(name, **(settings or {}))):
        out, compile_s, best = _host_run(system, name, settings, keys, n, snr)
    else:
        start = time.perf_counter()
        compiled = batched_fit(system, n, snr, settings, name).lower(keys).compile()
        compile_s = time.perf_counter() - start
        best = math.inf
        for _ in range(max(repeats, 1)):
            start = time.perf_counter()
            out = jax.block_until_ready(compiled(keys))
            best = min(best, time.perf_counter() - start)
    estimates, truths, statuses, paths = (np.asarray(a) for a in out)
    close = np.all(np.abs(estimates - truths) <= TOLERANCE, axis=1)
    return {
        "n": n,
        "snr": snr,
        "realisations": realisations,
        "fits_per_s": realisations / best,
        "run_s": best,
        "compile_s": compile_s,
        "recovered": float(np.mean(close & (statuses == Status.converged))),
        "recovered_any_status": float(np.mean(close)),
        "converged": float(np.mean(statuses == Status.converged)),
        "adaptive_fraction": float(np.mean(paths == 1)),
        "peak_mem_mb": peak_rss_mb(),
    }


def _bounds(orders: Orders, u_min: float, u_max: float):
    low = np.full(orders.size, -np.inf)
    high = np.full(orders.size, np.inf)
    s = orders.slices
    low[s["DR"]], high[s["DR"]] = 0.0, u_max
    low[s["DL"]], high[s["DL"]] = u_min, 0.0
    low[s["b"]], high[s["b"]] = -2.0, 2.0
    low[s["cL"]], low[s["mR"]], low[s["cR"]] = 0.0, 1e-3, 0.0
    return low, high


def _prior_draw(rng: np.random.Generator, orders: Orders, u_max: float) -> np.ndarray:
    # the prior of `_prior.py`, in NumPy
    def slopes(k):
        return rng.choice([-1.0, 1.0], k) * rng.uniform(0.2, 1.5, k)

    radius = rng.uniform(0.0, 0.7, orders.p // 2)
    angle = rng.uniform(0.0, np.pi, orders.p // 2)
    pairs = radius * np.exp(1j * angle)
    roots = np.concatenate([pairs, np.conj(pairs), rng.uniform(-0.7, 0.7, orders.p % 2)])
    return np.concatenate(
        [
            slopes(orders.nR),
            np.sort(rng.uniform(0.15, 0.75, orders.nR - 1)) * u_max,
            slopes(orders.nL),
            -np.sort(rng.uniform(0.15, 0.75, orders.nL - 1)) * u_max,
            rng.uniform(-0.4, 0.4, orders.r - 1),
            np.real(np.poly(roots))[1:],
            rng.uniform(0.05, 0.5, 1),
            rng.uniform(0.6, 1.5, 1),
            rng.uniform(0.05, 0.5, 1),
        ]
    )


def baseline_fit(rng, orders: Orders, u, y, n_starts=16, n_refine=3, subset=1000):
    """The SciPy multi-start (module docstring) on one record: the estimate."""
    from scipy.optimize import least_squares

    u_min, u_max = float(u.min()), float(u.max())
    low, high = _bounds(orders, u_min, u_max)
    starts = [_baseline.initial_guess(orders, u_min, u_max)]
    starts += [_prior_draw(rng, orders, 0.5 * (u_max - u_min)) for _ in range(n_starts)]
    m = min(subset, len(u))

    def residual(vector, u, y):
        # an unstable linear block overflows: a large finite residual keeps SciPy going
        with np.errstate(all="ignore"):
            error = _baseline.simulate(vector, orders, u) - y
        return np.clip(np.nan_to_num(error, nan=1e6), -1e6, 1e6)

    def fit(x0, u, y, nfev):
        x0 = np.clip(x0, low + 1e-9, high - 1e-9)
        return least_squares(residual, x0, bounds=(low, high), args=(u, y), max_nfev=nfev)

    first = [fit(x0, u[:m], y[:m], 60 * (orders.size + 1)) for x0 in starts]
    full = [np.mean(residual(f.x, u, y) ** 2) for f in first]
    chosen = np.argsort(np.where(np.isfinite(full), full, np.inf))[:n_refine]
    second = [fit(first[i].x, u, y, 150 * (orders.size + 1)) for i in chosen]
    return min(second, key=lambda f: f.cost).x


def run_baseline(system, realisations=8, n=None, snr=None, seed=0):
    """Time the SciPy multi-start on `realisations` records, one after another."""
    n_default, snr_default = system_defaults(system)
    n, snr = n or n_default, snr or snr_default
    number = SYSTEMS[system][0]
    orders = Orders()
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    for _ in range(realisations):
        if number is None:
            truth = _prior_draw(rng, orders, AMPLITUDE)
        else:
            ex = get_example(number)
            truth = np.array([ex.values[name] for name in orders.names])
        u, y = _baseline.measure(rng, truth, orders, n, snr, AMPLITUDE)
        baseline_fit(rng, orders, u, y)
    seconds = time.perf_counter() - start
    return {
        "baseline_fits_per_s": realisations / seconds,
        "baseline_s": seconds,
        "baseline_realisations": realisations,
    }


def run_benchmark(
    system="example1",
    realisations=256,
    baseline_realisations=8,
    n=None,
    repeats=1,
    seed=0,
    name="robust",
) -> dict:
    """Every figure of the benchmark of estimator `name` (the `SUMMARY_KEYS` and the
    details)."""
    record = {"estimator": name, "system": system, "device": device_description()}
    record.update(run_jax(system, realisations, n, repeats=repeats, seed=seed, name=name))
    record.update(run_baseline(system, baseline_realisations, n, seed=seed))
    record["ratio"] = record["fits_per_s"] / record["baseline_fits_per_s"]
    return record


def summary(record: dict) -> dict:
    return {key: record[key] for key in SUMMARY_KEYS}
