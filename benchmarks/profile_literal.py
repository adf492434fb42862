"""Where the literal iteration's time goes: each stage of the bench workload compiled and
timed on its own, on the same batch.

    python benchmarks/profile_literal.py [--batch 250] [--rounds 10] [--backend auto]
                                         [--commit REF] [--out results/profile_literal.md]

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

Per stage: the best wall time of a call in ms (the least disturbed of the rounds) and
the median process CPU time of a call (all threads: the fused kernel runs two, so its
CPU time is up to twice its wall time; CPU time is what another process's load changes
least), both less the fixed cost of a call (dispatch of a compiled program, `empty`:
one that doubles a number per record), then per 1000 fits (calls per fit x 1000 / batch), with
each stage's share of the whole fit's CPU time. `bookkeeping` is the whole step less
its stages; `unaccounted` the whole fit less every stage (the batches' loop, the
results). A stage that costs less than that fixed cost (the standard errors, the
stopping rule: a few operations per record) reads slightly negative: next to nothing.
Per-step stages run at the iterate after 10 steps. Compare runs taken in one
sitting. Run it from the repository root with `PYTHONPATH=.` to profile the checkout,
not an installed copy.

`--commit REF` profiles an older commit's package with this script: REF is checked out
into a temporary `git worktree` (`git worktree add --detach`, removed afterwards), and
this file runs there, from the worktree's root with `PYTHONPATH` set to it (so the
table's commit is REF's). Issue 22's before / after pair, in one sitting:

    python benchmarks/profile_literal.py --rounds 10 --commit 71498f6 \
        --out results/profile_literal_before.md
    PYTHONPATH=. python benchmarks/profile_literal.py --rounds 10 \
        --out results/profile_literal_after.md
"""

from __future__ import annotations

import argparse
import os
import pathlib
import platform
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]

STEP_STAGES = ("normal equations", "solve", "standard errors", "stopping rule", "cycle detection")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, default=250)
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--backend", default="auto", choices=("auto", "xla", "fused"))
    parser.add_argument("--out", default=None, help="also write the table (Markdown)")
    parser.add_argument(
        "--commit",
        default=None,
        help="profile this commit's package (this script, run in a temporary worktree at it)",
    )
    args = parser.parse_args(argv)
    if args.commit:
        return at_commit(args)

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

    # modules that issue 34's layout (f8d2198) moved: the `--commit` baseline has the old
    layout = _layout("_normal_equations", "_estimator._normal_equations")
    normal_equations, resolve, solve_step = (
        layout.normal_equations,
        layout.resolve,
        layout.solve_step,
    )
    example = _layout("_examples", "_system._examples").example
    CascadeParams = _layout("_model", "_system._model").CascadeParams
    simulate = _layout("_simulate", "_system._simulate")
    measure, uniform_input = simulate.measure, simulate.uniform_input

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
        "empty": (lambda c: 2.0 * c, (cost,), 0),
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
    # best (least disturbed) wall time, median CPU time; a call's fixed cost subtracted
    wall_s = {name: min(times) - min(wall["empty"]) for name, times in wall.items()}
    cpu_s = {
        name: statistics.median(t) - statistics.median(cpu["empty"]) for name, t in cpu.items()
    }
    per_fit = 1e3 / batch  # batches per 1000 fits
    for figures in (wall_s, cpu_s):
        figures["iteration"] = (
            figures["fit, 20 iterations"] - figures["fit, 1 iteration"]
        ) / per_step
        figures["bookkeeping"] = figures["iteration"] - sum(figures[name] for name in STEP_STAGES)
    whole_ms = wall_s["whole fit"] * per_fit * 1e3
    whole_cpu_ms = cpu_s["whole fit"] * per_fit * 1e3

    rows = []
    shown = [(name, 1) for name in ("simulation", "first step")]
    shown += [(name, per_step) for name in (*STEP_STAGES, "bookkeeping")]
    for name, calls in shown + [("iteration", per_step), ("whole fit", 1)]:
        ms, cpu_ms = (figures[name] * calls * per_fit * 1e3 for figures in (wall_s, cpu_s))
        rows.append(
            f"| {name} | {wall_s[name] * 1e3:.3f} | {cpu_s[name] * 1e3:.3f} | {calls} "
            f"| {ms:.1f} | {cpu_ms:.1f} | {cpu_ms / whole_cpu_ms:.1%} |"
        )
    accounted = sum(cpu_s[name] * calls for name, calls in shown) * per_fit * 1e3
    rows.append(
        f"| unaccounted (whole fit - stages) | | | | | {whole_cpu_ms - accounted:.1f} "
        f"| {(whole_cpu_ms - accounted) / whole_cpu_ms:.1%} |"
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
        f"{commit}; load {load}; dispatch of an empty program "
        f"{min(wall['empty']) * 1e3:.3f} ms (subtracted); whole fit "
        f"{1e3 / whole_ms * 1e3:.0f} fits/s (best wall), {whole_cpu_ms:.0f} CPU ms per "
        "1000 fits.",
        "",
        "| stage | wall ms per call | CPU ms per call | calls per fit | wall ms per 1000 fits "
        "| CPU ms per 1000 fits | share of the CPU time |",
        "|---|---|---|---|---|---|---|",
        *rows,
    ]
    text = "\n".join(lines)
    print(text)
    if args.out:
        with open(args.out, "w") as file:
            file.write(text + "\n")
    return 0


def _layout(old: str, new: str):
    """The module `jaxcascade.OLD` where the profiled package has it (the `--commit`
    baseline, before issue 34's layout moved it), else `jaxcascade.NEW`. The old name
    first, and only a file of the profiled package's own folder: an editable install of
    today's package would otherwise lend the baseline its new modules."""
    import importlib

    import jaxcascade

    folder = pathlib.Path(jaxcascade.__file__).resolve().parent
    for name in (old, new):
        try:
            module = importlib.import_module(f"jaxcascade.{name}")
        except ModuleNotFoundError:
            continue
        if folder in pathlib.Path(module.__file__).resolve().parents:
            return module
    raise ModuleNotFoundError(f"neither jaxcascade.{old} nor jaxcascade.{new} in {folder}")


def at_commit(args) -> int:
    """This script on `args.commit`'s package: a temporary worktree at the commit (removed
    afterwards), this file run from its root with `PYTHONPATH` set to it; the same options,
    `--out` relative to the current folder."""
    forwarded = ["--batch", str(args.batch), "--rounds", str(args.rounds)]
    forwarded += ["--backend", args.backend]
    if args.out:
        forwarded += ["--out", str(pathlib.Path(args.out).resolve())]
    with tempfile.TemporaryDirectory(prefix="profile_literal_") as scratch:
        tree = pathlib.Path(scratch) / "tree"
        added = subprocess.run(
            ["git", "worktree", "add", "--detach", str(tree), args.commit],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
        if added.returncode != 0:
            print(f"profile_literal: cannot check out {args.commit}: {added.stderr.strip()}")
            return 2
        try:
            env = dict(os.environ, PYTHONPATH=str(tree))
            script = pathlib.Path(__file__).resolve()
            return subprocess.run(
                [sys.executable, str(script), *forwarded], cwd=tree, env=env
            ).returncode
        finally:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(tree)],
                cwd=ROOT,
                capture_output=True,
            )


if __name__ == "__main__":
    raise SystemExit(main())
