"""The FLOP floor of the benchmark workload: operations per fit and the machine's rate.

Counting convention: one flop is one floating-point add, subtract, multiply, divide or
comparison on one sample; a product with a 0/1 switching variable counts as a multiply,
as the paper writes it; shifts, negations and copies are free; random number generation
is not counted. Terms are counted for the algorithm, not for any one implementation:
the Gram matrix is symmetric (`N P (P + 1)`: P(P+1)/2 entries, a multiply and an add per
sample), the regression cost J that `voros` also reports is not needed for the estimate
and is left out (it would add `2 N P + 3 N` per step), and the solve is a Cholesky
factorisation with two triangular solves. Leaving work out makes the floor faster, so the
fraction of the floor reached is, if anything, understated.

A fit of `iterations` steps is one first step (paper: v ~ u, x ~ y, backlash held at its
initial values, only the P - 3 NS and LD columns) and `iterations - 1` full steps, as in
`voros(..., max_iterations=iterations)`.
"""

from __future__ import annotations

import time

import numpy as np

from .._system._model import Orders


def flops_per_fit(orders: Orders | None = None, n: int = 4000, iterations: int = 20) -> dict:
    """Floating-point operations of one fit, by term; `total` is their sum.

    `orders` defaults to the paper's (2, 2, 2, 2); `iterations` counts the first step.

    Per sample (N samples), with K = nR + nL segments and P = `orders.size`:

    - simulation, once: `pwl` 5K - 1 (per segment: difference, comparison, switch, slope,
      accumulate); `linear` 2(r + p) - 1 (the recursion); `backlash` 5 (both lines, two
      comparisons); `noise` 6 (mean, deviations, squares, sum; scale and add).
    - first step: `switches` 13 (g1: sum, difference, comparison; g2: mR x, difference,
      + C, comparison, 1 - g1 and product; yc: 1 - g2, product, times y(t-1), subtract);
      `regressors` 2K + (P - 3) + 1 (segment comparisons and products with u(t-1), times g1,
      and x g2; unit slopes make the breakpoint columns free); `target` 6 (the fixed
      backlash columns times their initial values, subtracted); `gram` (P-3)(P-2);
      `rhs` 2(P - 3); `solve` ((P-3)^3/3 + 5 (P-3)^2, once, not per sample).
    - each full step: `pwl` and `linear` as above; `switches` 13; `regressors`
      2K + (K - 2) + (P - 3) + 1 (as in the first step, plus the slopes in the breakpoint
      columns); `gram` P(P + 1); `rhs` 2P; `solve` (P^3/3 + 5 P^2).
    """
    o = orders or Orders()
    K, P, P1 = o.nR + o.nL, o.size, o.static_dynamic.stop
    pwl = (5 * K - 1) * n
    linear = (2 * (o.r + o.p) - 1) * n
    switches = 13 * n
    terms = {
        "simulation: pwl": pwl,
        "simulation: linear": linear,
        "simulation: backlash": 5 * n,
        "simulation: noise": 6 * n,
        "first step: switches": switches,
        "first step: regressors": (2 * K + P1 + 1) * n,
        "first step: target": 6 * n,
        "first step: gram": n * P1 * (P1 + 1),
        "first step: rhs": 2 * n * P1,
        "first step: solve": P1**3 // 3 + 5 * P1**2,
    }
    full = {
        "pwl": pwl,
        "linear": linear,
        "switches": switches,
        "regressors": (2 * K + (K - 2) + P1 + 1) * n,
        "gram": n * P * (P + 1),
        "rhs": 2 * n * P,
        "solve": P**3 // 3 + 5 * P**2,
    }
    steps = max(iterations - 1, 0)
    terms.update({f"full steps: {name}": steps * value for name, value in full.items()})
    terms["total"] = sum(terms.values())
    return terms


# The floor's count, in words (the JSON and CSV state it beside the figure).
FLOOR_COUNT = "iterations x (2 N P^2 + 2 N P)"


def normal_equations_flops(orders: Orders | None = None, n: int = 4000, iterations: int = 20):
    """The floor's count of a fit: `iterations x (2 N P^2 + 2 N P)`, the normal equations
    of every step as dense products (`phi^T phi` and `phi^T y`, P = `orders.size`).

    The standard count, independent of this package's algorithm: what a reader computes
    from the problem's size alone, and what issue 22 holds the benchmark to. It leaves
    out the simulation, the regressors, the solve and the first step's smaller system,
    and counts the whole Gram matrix where `flops_per_fit` counts its symmetric half:
    at the paper's orders it is about 1.3 times `flops_per_fit`'s total, so its floor
    is the slower, and the fraction of it reached the larger, of the two.
    """
    P = (orders or Orders()).size
    return iterations * (2 * n * P * P + 2 * n * P)


def _best_time(function, repeats: int) -> float:
    function()  # warm up (and compile)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def matmul_rates(size: int = 2048, repeats: int = 3) -> dict[str, float]:
    """Float64 dense matrix-product rate in flop/s (`2 size^3` per product, best of `repeats`).

    Measured with NumPy (BLAS) and with JAX on its default device; JAX is skipped when
    float64 is not enabled. Keys: `"numpy"`, `"jax"`.
    """
    import jax
    import jax.numpy as jnp

    flops = 2.0 * size**3
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((size, size)), rng.standard_normal((size, size))
    rates = {"numpy": flops / _best_time(lambda: a @ b, repeats)}
    if jnp.zeros((), jnp.float64).dtype == np.float64:
        ja, jb = jnp.asarray(a), jnp.asarray(b)
        product = jax.jit(jnp.matmul)
        rates["jax"] = flops / _best_time(lambda: product(ja, jb).block_until_ready(), repeats)
    return rates


def machine_rate(rates: dict[str, float]) -> tuple[str, float]:
    """The rate the floor uses: JAX's device rate on an accelerator, else the best CPU rate."""
    import jax

    if jax.default_backend() != "cpu" and "jax" in rates:
        return "jax", rates["jax"]
    name = max(rates, key=rates.get)
    return name, rates[name]


def floor_time(flops: float, rate: float) -> float:
    """Seconds per fit at the dense-matmul rate: `flops / rate`."""
    return flops / rate
