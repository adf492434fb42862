"""Where the robust estimator's time goes: each stage compiled and timed on its own.

    python benchmarks/profile_robust.py [--system example1] [--batch 32] [--n N]

Prints, per stage, compile seconds (lowering plus XLA, cold, with the package's XLA
options) and the best of three runs
in milliseconds per record, for a batch of `--batch` records of the system:

- `normal_equations`: one Levenberg-Marquardt evaluation (output, Jacobian by forward
  sensitivities, J^T J, J^T r) on the whole record: a step costs about this;
- `voros`: the literal iteration (30 iterations), the adaptive path's start;
- `adaptive`: step 1 (voros, Levenberg-Marquardt on the whole record, basin test);
- `multistart`: steps 2 and 3 for every record of the batch (what a fallback costs);
- `robust`: the whole estimator, batched (fallbacks gathered).

Timings are wall-clock: run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import functools
import time


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--system", default="example1")
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--n", type=int, default=None)
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    from jaxcascade._benchmark._robust import SYSTEMS, system_defaults
    from jaxcascade._compile import compiler_options
    from jaxcascade._estimator import _robust as R
    from jaxcascade._estimator._literal import voros
    from jaxcascade._estimator._refine import normal_equations, to_unconstrained
    from jaxcascade._system._examples import example
    from jaxcascade._system._model import Orders
    from jaxcascade._system._prior import random_system
    from jaxcascade._system._simulate import measure, uniform_input

    orders = Orders()
    n, snr = system_defaults(args.system)
    n = args.n or n
    number = SYSTEMS[args.system][0]
    keys = jax.random.split(jax.random.PRNGKey(0), args.batch)

    def draw(key):
        k0, k1, k2 = jax.random.split(key, 3)
        truth = random_system(k0, orders) if number is None else example(number).params()
        u = uniform_input(k1, n)
        return u, measure(k2, truth, u, snr)[0], truth

    u, y, truth = jax.jit(jax.vmap(draw))(keys)
    u_min, u_max = u.min(axis=1), u.max(axis=1)
    z = jax.vmap(to_unconstrained)(truth, u_min, u_max)
    stage_settings = dict(rtol=1e-6, atol=1e-9, steps=50, bound=5.0)
    multistart = functools.partial(
        R._multistart,
        orders=orders,
        n_starts=16,
        n_refine=3,
        subset=1000,
        max_steps=(30, 100),
        literal_start=True,
        rtol=1e-6,
        atol=1e-9,
    )
    stage = jax.jit(jax.vmap(lambda u, y: R._adaptive(u, y, orders, **stage_settings)))(u, y)
    stages = {
        "normal_equations": (
            jax.vmap(lambda z, u, y, a, b: normal_equations(z, orders, u, y, a, b)),
            (z, u, y, u_min, u_max),
        ),
        "voros": (jax.vmap(lambda u, y: voros(u, y, orders, max_iterations=30)), (u, y)),
        "adaptive": (jax.vmap(lambda u, y: R._adaptive(u, y, orders, **stage_settings)), (u, y)),
        "multistart": (jax.vmap(multistart), (u, y, keys, stage)),
        "robust": (jax.vmap(lambda u, y, k: R._robust(u, y, orders, k)), (u, y, keys)),
    }
    print(
        f"{args.system}: N = {n}, batch {args.batch}; adaptive path accepted "
        f"{int(stage.accepted.sum())} of {args.batch}"
    )
    for name, (function, arguments) in stages.items():
        start = time.perf_counter()
        compiled = jax.jit(function, compiler_options=compiler_options())
        compiled = compiled.lower(*arguments).compile()
        compile_s = time.perf_counter() - start
        best = float("inf")
        for _ in range(3):
            start = time.perf_counter()
            jax.block_until_ready(compiled(*arguments))
            best = min(best, time.perf_counter() - start)
        per_record = 1e3 * best / args.batch
        print(f"{name:>18}: compile {compile_s:6.1f} s, {per_record:8.2f} ms per record")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
