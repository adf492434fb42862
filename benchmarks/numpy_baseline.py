"""Time the NumPy/SciPy baseline of the benchmark workload on its own.

    OPENBLAS_NUM_THREADS=1 python benchmarks/numpy_baseline.py [--realisations 20] [--n 4000]

The implementation is `jaxcascade._baseline` (shared with `jaxcascade bench` and tested
against `jaxcascade.voros` in tests/test_numpy_baseline.py). Also times the two backlash
variants on one record: the plain Python loop and the vectorised clamp scan.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from jaxcascade._benchmark import _baseline
from jaxcascade._benchmark._timing import _example_vector, run_baseline
from jaxcascade._system._examples import example


def _per_call(function, repeats=20) -> float:
    start = time.perf_counter()
    for _ in range(repeats):
        function()
    return (time.perf_counter() - start) / repeats


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realisations", type=int, default=20)
    parser.add_argument("--n", type=int, default=4000)
    parser.add_argument("--iterations", type=int, default=20)
    parser.add_argument("--example", type=int, default=1, choices=(1, 2))
    args = parser.parse_args(argv)

    ex, vector = example(args.example), _example_vector(args.example)
    u = np.random.default_rng(0).uniform(-ex.amplitude, ex.amplitude, args.n)
    p = _baseline.unpack(vector, ex.orders)
    x = _baseline.linear_block(vector, ex.orders, _baseline.pwl(vector, ex.orders, u))
    for name in ("loop", "scan"):
        run = getattr(_baseline, f"backlash_{name}")
        seconds = _per_call(lambda run=run: run(x, p.cL, p.mR, p.cR))
        print(f"backlash ({name}): {seconds * 1e3:.3f} ms per record of {args.n} samples")
    result = run_baseline(args.realisations, args.n, args.iterations, args.example)
    print(
        f"baseline: {result['baseline_fits_per_s']:.2f} fits/s ({args.realisations} "
        f"realisations, N = {args.n}, {args.iterations} iterations, "
        f"{result['baseline_s']:.2f} s)"
    )


if __name__ == "__main__":
    main()
