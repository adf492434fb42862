"""Timing of the batched Monte-Carlo workload against a NumPy/SciPy baseline and the
float64 FLOP floor (`jaxcascade bench`).

The workload is a Monte-Carlo fit of a paper example: per realisation, draw a uniform
input, simulate, add output noise at the example's SNR and run `iterations` steps of the
literal Vörös iteration (`NO_EARLY_STOP`: negative tolerances, so every realisation
runs them all). Three figures come from one run on the same machine:

- jaxcascade's batched path: `vmap` over PRNG keys of simulation, noise and `voros`,
  compiled ahead of time (compile time reported separately), the realisations split
  over the host's cores (`workers` threads, `_batching.host_threads`), best of
  `repeats` runs;
  by default (`--backend auto`) each iteration's normal equations come from the fused
  CPU kernel (`_fused`), `--backend xla` times the pure-XLA path instead;
- the NumPy/SciPy baseline (`_baseline`), realisations one after another, on a subset,
  in a separate process with one BLAS thread by default (see `run_baseline_process`);
- the FLOP floor: flops per fit over the measured float64 matmul rate, with the
  standard count of the normal equations (`_flops.normal_equations_flops`,
  `iterations x (2 N P^2 + 2 N P)`, stated in the JSON as `floor_count`).

Peak memory is the peak resident set size of the process after the batched run (before
the baseline and the matmul measurement, which would otherwise set it). XLA allocates
outside Python's allocator, so tracemalloc would not see it.
"""

from __future__ import annotations

import json
import math
import os
import pathlib
import platform
import resource
import subprocess
import sys
import time

import numpy as np

from .._compile import compiler_options
from .._system._examples import example as get_example
from . import _baseline, _flops

# Settings of `voros` (and of the baseline's) that never stop early: a fixed workload.
NO_EARLY_STOP = {"tol": -1.0, "se_tol": -1.0, "cost_tol": -1.0}
# Realisations per batch on an accelerator (`batched_fit`).
ACCELERATOR_BATCH = 4096

SUMMARY_KEYS = (
    "fits_per_s",
    "baseline_fits_per_s",
    "ratio",
    "floor_fraction",
    "compile_s",
    "peak_mem_mb",
    "device",
    "floor_count",
    "load",
    "workers",
)


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, in MiB (Linux reports KiB)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024 * 1024) if platform.system() == "Darwin" else peak / 1024


def device_description() -> str:
    """The device JAX computes on, in words (with the CPU model and core count on CPU)."""
    import jax

    device = jax.devices()[0]
    if device.platform != "cpu":
        return f"{device.platform}: {device.device_kind}"
    model = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"cpu: {model} ({cores} cores)"


def batched_fit(
    example_number: int,
    n: int,
    iterations: int,
    dtype=None,
    *,
    backend: str = "auto",
    batch: int | None = None,
):
    """The jitted batched workload `(keys, params) -> (estimates, statuses)`.

    `vmap` of simulation, noise and `voros` over batches of `batch` realisations, the
    batches one after another (`_batching.chunked_vmap`). With the fused backend one
    kernel call per iteration forms the normal equations of a whole batch (threads over
    records inside the call), so batches are large (default 256: on the 2-core CPU, 250
    to 1000 ran at the same speed within noise, 128 about 15% slower); the XLA backend
    materialises an N x P regressor matrix per realisation, so its batches are kept
    cache-sized (default 16) on a CPU. On an accelerator (`_scans.parallel`: the
    recursions in time are associative scans) a batch is a few large kernels per
    iteration, so it is as wide as device memory comfortably allows
    (`ACCELERATOR_BATCH`, about 1.5 MB a realisation at N 4000): larger batches only
    bound memory, the batches running one after another.
    """
    import jax
    import jax.numpy as jnp

    from .._estimator._literal import voros
    from .._estimator._normal_equations import resolve
    from .._system import _scans
    from .._system._simulate import measure, uniform_input
    from ._batching import chunked_vmap

    ex = get_example(example_number)
    dtype = dtype or jnp.result_type(float)
    backend = resolve(backend, ex.orders, dtype)
    if batch is None:
        batch = 256 if backend == "fused" else ACCELERATOR_BATCH if _scans.parallel() else 16

    def one(key, params):
        key_u, key_e = jax.random.split(key)
        u = uniform_input(key_u, n, ex.amplitude, dtype)
        y, _ = measure(key_e, params, u, ex.snr)
        solution = voros(
            u, y, ex.orders, max_iterations=iterations, backend=backend, **NO_EARLY_STOP
        )
        return solution.params.to_vector(), solution.status

    return jax.jit(
        chunked_vmap(one, batch, in_axes=(0, None)), compiler_options=compiler_options()
    ), backend


def run_jax(
    realisations: int,
    n: int,
    iterations: int,
    example_number=1,
    repeats=3,
    seed=0,
    backend="auto",
    batch=None,
    workers=None,
):
    """Compile and time the batched path; returns a dict of figures.

    The realisations are split over `workers` host threads (default: the cores this
    process may use, `_batching.host_workers`; on an accelerator 1, the device being
    one), one compiled program of one part's shape (`_batching.host_threads`);
    `workers=1` runs them as one call."""
    import jax
    import jax.numpy as jnp

    from .._estimator._normal_equations import resolve
    from .._system import _scans
    from ._batching import host_threads, host_workers, split_batch

    dtype = jnp.result_type(float)
    params = get_example(example_number).params(dtype)
    keys = jax.random.split(jax.random.PRNGKey(seed), realisations)
    # The fused kernel is built once per machine (then loaded from its disk cache): timed
    # apart from XLA's compilation.
    start = time.perf_counter()
    backend = resolve(backend, get_example(example_number).orders, dtype)
    build_s = time.perf_counter() - start
    start = time.perf_counter()
    fit, backend = batched_fit(example_number, n, iterations, dtype, backend=backend, batch=batch)
    workers = workers or (1 if _scans.parallel() else host_workers())
    pieces, _ = split_batch(keys, workers)
    compiled = host_threads(fit.lower(pieces[0], params).compile(), len(pieces))
    compile_s = time.perf_counter() - start
    # the machine's load (1-minute average) as the timed runs start: on a shared machine
    # the figures are only comparable at a similar load
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    best = math.inf
    for _ in range(max(repeats, 1)):
        start = time.perf_counter()
        estimates, statuses = jax.block_until_ready(compiled(keys, params))
        best = min(best, time.perf_counter() - start)
    codes_counts = np.unique(np.asarray(statuses), return_counts=True)
    return {
        "fits_per_s": realisations / best,
        "run_s": best,
        "load": load,
        "compile_s": compile_s,
        "kernel_build_s": build_s,
        "peak_mem_mb": peak_rss_mb(),
        "finite_fraction": float(np.mean(np.all(np.isfinite(np.asarray(estimates)), axis=1))),
        "status_counts": dict(zip(*(a.tolist() for a in codes_counts), strict=True)),
        "dtype": str(np.dtype(dtype)),
        "backend": backend,
        "workers": len(pieces),
    }


def _example_vector(example_number: int) -> np.ndarray:
    ex = get_example(example_number)
    return np.array([ex.values[name] for name in ex.orders.names], dtype=float)


def run_baseline(realisations: int, n: int, iterations: int, example_number=1, seed=0):
    """Time the NumPy/SciPy baseline on `realisations` records, one after another."""
    ex = get_example(example_number)
    vector = _example_vector(example_number)
    _baseline.run(1, vector, ex.orders, n, ex.snr, 1, seed=seed)  # warm up imports and caches
    _, seconds = _baseline.run(realisations, vector, ex.orders, n, ex.snr, iterations, seed=seed)
    return {"baseline_fits_per_s": realisations / seconds, "baseline_s": seconds}


_BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def run_baseline_process(
    realisations: int, n: int, iterations: int, example_number=1, seed=0, threads=1
):
    """`run_baseline` in a fresh process with `threads` BLAS threads.

    The baseline's least-squares problems are tiny (N x P with P ~ 13): extra BLAS threads
    only add synchronisation, and on a busy machine they slow it down many times over. The
    thread count must be set before NumPy loads, hence the subprocess.
    """
    env = dict(os.environ, **{name: str(threads) for name in _BLAS_THREADS})
    code = (
        "import json, sys; from jaxcascade._benchmark._timing import run_baseline; "
        "print(json.dumps(run_baseline(*map(int, sys.argv[1:]))))"
    )
    arguments = [str(a) for a in (realisations, n, iterations, example_number, seed)]
    done = subprocess.run(
        [sys.executable, "-c", code, *arguments], env=env, capture_output=True, text=True
    )
    if done.returncode != 0:
        raise RuntimeError(f"the baseline process failed: {done.stderr.strip()[-2000:]}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    result["baseline_threads"] = threads
    return result


def run_floor(n: int, iterations: int, example_number=1, matmul_size=2048, repeats=3):
    """Flops per fit, the matmul rate and the floor in fits per second.

    The floor counts `_flops.FLOOR_COUNT` (`normal_equations_flops`: the standard count
    of the normal equations, issue 22's); `flops_per_fit_detailed` is `flops_per_fit`'s
    term-by-term count of this workload, for reference."""
    orders = get_example(example_number).orders
    flops = _flops.normal_equations_flops(orders, n, iterations)
    rates = _flops.matmul_rates(matmul_size, repeats)
    backend, rate = _flops.machine_rate(rates)
    return {
        "flops_per_fit": flops,
        "floor_count": _flops.FLOOR_COUNT,
        "flops_per_fit_detailed": _flops.flops_per_fit(orders, n, iterations)["total"],
        "matmul_gflops": rate / 1e9,
        "matmul_backend": backend,
        "matmul_size": matmul_size,
        "floor_fits_per_s": 1.0 / _flops.floor_time(flops, rate),
    }


def run_benchmark(
    realisations=1000,
    n=4000,
    iterations=20,
    example_number=1,
    baseline_realisations=20,
    matmul_size=2048,
    repeats=3,
    seed=0,
    baseline_threads=1,
    backend="auto",
    workers=None,
) -> dict:
    """The full benchmark; returns every figure (the `SUMMARY_KEYS` and the details)."""
    record = {
        "example": example_number,
        "n": n,
        "snr": get_example(example_number).snr,
        "iterations": iterations,
        "realisations": realisations,
        "baseline_realisations": baseline_realisations,
        "device": device_description(),
    }
    record.update(
        run_jax(
            realisations,
            n,
            iterations,
            example_number,
            repeats,
            seed,
            backend=backend,
            workers=workers,
        )
    )
    record.update(
        run_baseline_process(
            baseline_realisations, n, iterations, example_number, seed, baseline_threads
        )
    )
    record.update(run_floor(n, iterations, example_number, matmul_size, repeats))
    record["ratio"] = record["fits_per_s"] / record["baseline_fits_per_s"]
    record["floor_fraction"] = record["fits_per_s"] / record["floor_fits_per_s"]
    return record


def summary(record: dict) -> dict:
    return {key: record[key] for key in SUMMARY_KEYS}
