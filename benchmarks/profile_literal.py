"""Where the literal iteration's time goes: each stage of the bench workload compiled and
timed on its own, on the same batch.

    python benchmarks/profile_literal.py [--batch 250] [--rounds 10] [--backend auto]
                                         [--out results/profile_literal.md]

The workload is `jaxcascade bench`'s (Example 1, N 4000, SNR 25, 20 iterations; the
bench runs its 1000 realisations as 4 batches of 250). Each stage is one program
(`vmap` over the batch, the package's XLA options), timed round-robin with the others
(`--rounds` times, so a change in the machine's load touches every stage alike):

- `simulation`: input draw, simulation and output noise, once per fit;
- `first step`: the paper's first iteration (kernel and solve), once per fit;
- per full step (19 per fit): `normal equations` (the fused kernel, or the XLA
  regressors with `--backend xla`), `solve` (`solve_step`: both blocks' eliminations,
  the cost), `standard errors`, `stopping rule`, `cycle detection`;
- `iteration`: one whole step of the while loop, from `voros` with 20 and with 1
  iterations (their difference over 19); `bookkeeping` is what it costs beyond the
  stages above (classification, status, the carried history, `vmap`'s masking);
- `whole fit`: the bench's program for one batch (all of the above).

Per stage: the median wall time of a call in ms (medians: the rounds alternate the
stages, so each median sees the same load), the median process CPU time of a call (all
threads; the fused kernel runs two), and the wall ms per 1000 fits (calls per fit x
wall x 1000 / batch), with its share of the whole fit. A call's fixed cost (dispatch
of a compiled program, `empty`: one that returns its argument) is subtracted from every
stage. Per-step stages run at the iterate after 10 steps. Figures are wall-clock on a
shared machine: quote the shares and compare runs taken in one sitting. Run it from the
repository root with `PYTHONPATH=.` to profile the checkout, not an installed copy.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import subprocess
import time


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, default=250)
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--backend", default="auto", choices=("auto", "xla", "fused"))
    parser.add_argument("--out", default=None, help="also write the table (Markdown)")
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from jaxcascade._benchmark._timing import NO_EARLY_STOP, batched_fit, device_description
    from jaxcascade._compile import compiler_options
    from jaxcascade._estimator._literal import (
        _theta,
        cycle_detection,
        first_iteration,
        initial_guess,
        standard_errors,
        stopping_rule,
        voros,
    )
    from jaxcascade._examples import example
    from jaxcascade._model import CascadeParams
    from jaxcascade._normal_equations import normal_equations, resolve, solve_step
    from jaxcascade._simulate import measure, uniform_input

    ex = example(1)
    orders, n, iterations, batch = ex.orders, 4000, 20, args.batch
    dtype = jnp.float64
    backend = resolve(args.backend, orders, dtype)
    truth = ex.params(dtype)
    keys = jax.random.split(jax.random.PRNGKey(0), batch)
    settings = dict(NO_EARLY_STOP, backend=backend)

    def simulation(key):
        key_u, key_e = jax.random.split(key)
        u = uniform_input(key_u, n, ex.amplitude, dtype)
        return u, measure(key_e, truth, u, ex.snr)[0]

    def fit(u, y, steps):
        return voros(u, y, orders, max_iterations=steps, **settings)

    options = compiler_options() or None
    u, y = jax.jit(jax.vmap(simulation), compiler_options=options)(keys)
    at = 10  # the per-step stages run at iterate `at`
    solution = jax.jit(jax.vmap(lambda u, y: fit(u, y, at)), compiler_options=options)(u, y)
    vector, history = solution.params.to_vector(), solution.history
    k = jnp.full((batch,), at - 1)  # the step from iterate `at` - 1 to `at`
    params = CascadeParams.from_vector(vector, orders, check=False)
    ne = jax.vmap(lambda p, u, y: normal_equations(p, u, y, backend=backend))(params, u, y)
    theta, _, cost, inverse = jax.vmap(lambda e: solve_step(e, n))(ne)
    se = jax.vmap(lambda c, i: standard_errors(c, i, n, orders.size))(cost, inverse)
    thetas = _theta(history[:, : iterations + 1])
    thetas = jnp.concatenate(
        [thetas, jnp.broadcast_to(thetas[:, -1:], (batch, iterations + 1 - thetas.shape[1], 12))],
        axis=1,
    )
    tolerance = 1e-3 * se + 1e-8 * (1 + jnp.abs(theta))
    init = jax.vmap(lambda u: initial_guess(orders, jnp.min(u), jnp.max(u), dtype))(u)
    whole, _ = batched_fit(1, n, iterations, dtype, backend=backend, batch=batch)

    per_step = iterations - 1
    stages = {
        # name: (function, arguments, calls per fit)
        "empty": (lambda c: c, (cost,), 0),
        "simulation": (jax.vmap(simulation), (keys,), 1),
        "first step": (
            jax.vmap(lambda i, u, y: first_iteration(i, u, y, "full", backend)),
            (init, u, y),
            1,
        ),
        "normal equations": (
            jax.vmap(lambda p, u, y: normal_equations(p, u, y, backend=backend)),
            (params, u, y),
            per_step,
        ),
        "solve": (jax.vmap(lambda e: solve_step(e, n)), (ne,), per_step),
        "standard errors": (
            jax.vmap(lambda c, i: standard_errors(c, i, n, orders.size)),
            (cost, inverse),
            per_step,
        ),
        "stopping rule": (
            jax.vmap(
                lambda t, s, c: stopping_rule(t, _theta(vector[0]), s, c, c, 1e-8, 1e-3, -1.0)
            ),
            (theta, se, cost),
            per_step,
        ),
        "cycle detection": (
            jax.vmap(lambda t, h, k, tol: cycle_detection(t, h, k, tol, 16)),
            (theta, thetas, k, tolerance),
            per_step,
        ),
        "fit, 20 iterations": (jax.vmap(lambda u, y: fit(u, y, iterations)), (u, y), 0),
        "fit, 1 iteration": (jax.vmap(lambda u, y: fit(u, y, 1)), (u, y), 0),
        "whole fit": (whole, (keys, truth), 0),
    }
    compiled = {}
    for name, (function, arguments, _) in stages.items():
        program = function if name == "whole fit" else jax.jit(function, compiler_options=options)
        compiled[name] = program.lower(*arguments).compile()
        jax.block_until_ready(compiled[name](*arguments))
    wall = {name: [] for name in stages}
    cpu = {name: [] for name in stages}
    for _ in range(args.rounds):
        for name, (_, arguments, _) in stages.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            jax.block_until_ready(compiled[name](*arguments))
            wall[name].append(time.perf_counter() - start)
            cpu[name].append(time.process_time() - start_cpu)
    best = {name: statistics.median(times) for name, times in wall.items()}
    used = {name: statistics.median(times) for name, times in cpu.items()}
    empty = best["empty"]
    per_fit = 1e3 / batch  # batches per 1000 fits
    whole_ms = (best["whole fit"] - empty) * per_fit * 1e3
    iteration = (best["fit, 20 iterations"] - best["fit, 1 iteration"]) / per_step

    rows = []

    def row(name, seconds, cpu_seconds, calls):
        total = seconds * calls * per_fit * 1e3
        rows.append(
            f"| {name} | {seconds * 1e3:.3f} | {cpu_seconds * 1e3:.2f} | {calls} "
            f"| {total:.1f} | {total / whole_ms:.1%} |"
        )
        return total

    accounted = 0.0
    for name in ("simulation", "first step"):
        accounted += row(name, best[name] - empty, used[name], 1)
    step_stages = (
        "normal equations",
        "solve",
        "standard errors",
        "stopping rule",
        "cycle detection",
    )
    step_sum = 0.0
    for name in step_stages:
        step_sum += best[name] - empty
        accounted += row(name, best[name] - empty, used[name], per_step)
    accounted += row(
        "bookkeeping (iteration - stages)", iteration - step_sum, float("nan"), per_step
    )
    row("iteration (whole step)", iteration, float("nan"), per_step)
    row("whole fit (one batch)", best["whole fit"] - empty, used["whole fit"], 1)
    rows.append(
        f"| unaccounted (whole fit - stages) | | | | {whole_ms - accounted:.1f} "
        f"| {(whole_ms - accounted) / whole_ms:.1%} |"
    )
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    load = open("/proc/loadavg").read().split()[0] if platform.system() == "Linux" else "n/a"
    lines = [
        f"Literal iteration, per stage: Example 1, N {n}, {iterations} iterations, "
        f"batch {batch}, {backend} normal equations; {device_description()}; commit "
        f"{commit}; load {load}; dispatch of an empty program {empty * 1e3:.3f} ms "
        f"(subtracted); whole fit {1e3 / whole_ms * 1e3:.0f} fits/s.",
        "",
        "| stage | wall ms per call | CPU ms per call | calls per fit | wall ms per 1000 fits "
        "| share of the whole fit |",
        "|---|---|---|---|---|---|",
        *rows,
    ]
    text = "\n".join(lines)
    print(text)
    if args.out:
        with open(args.out, "w") as file:
            file.write(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
