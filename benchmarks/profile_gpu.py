"""Issue 69: where a batch of realisations spends its time on an accelerator, form by
form: the sequential scans the CPU keeps against their associative-scan forms
(`_system/_scans.py`), and one step of the literal iteration and of the robust
estimator's Levenberg-Marquardt (the output and its Jacobian) at a batch's width.

    python benchmarks/profile_gpu.py [--batch 4096] [--n 4000] [--repeats 5]

Each form is `vmap`ped over the batch, compiled ahead of time, and timed as the median
of `repeats` runs (`block_until_ready`); the table gives milliseconds per batch and
microseconds per realisation. Run on the device it profiles (on a CPU it times the
same programs there).
"""

from __future__ import annotations

import argparse
import statistics
import time


def _timed(function, *arguments, repeats: int):
    import jax

    start = time.perf_counter()
    compiled = jax.jit(function).lower(*arguments).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(*arguments))
    runs = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(compiled(*arguments))
        runs.append(time.perf_counter() - start)
    return statistics.median(runs), compile_s


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, default=4096)
    parser.add_argument("--n", type=int, default=4000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from jaxcascade._benchmark._timing import device_description
    from jaxcascade._estimator import _sensitivity
    from jaxcascade._estimator._normal_equations import from_regression, step_regression
    from jaxcascade._system import _scans, _simulate
    from jaxcascade._system._examples import example

    B, T = args.batch, args.n
    params = example(1).params()
    b = params.b
    key = jax.random.PRNGKey(0)
    w = jax.random.normal(key, (B, T))
    x = 2 * jnp.sin(0.05 * jnp.arange(T))[None, :] + 0.3 * w
    u = jax.random.uniform(key, (B, T), minval=-2.0, maxval=2.0)
    y = jax.vmap(lambda u: _simulate.simulate(params, u))(u)
    cL, mR, cR = params.cL, params.mR, params.cR
    forms = {
        "poles: sequential blocked scan (CPU form)": (
            jax.vmap(lambda w: _simulate._poles_blocked(b, w, 64)), w),
        "poles: doubling scan of every sample's map": (jax.vmap(lambda w: _scans.poles(b, w)), w),
        "poles: blocked 64, doubling scan of the blocks' maps": (
            jax.vmap(lambda w: _scans.poles_blocked(b, w, 64)), w),
        "poles: blocked 128": (jax.vmap(lambda w: _scans.poles_blocked(b, w, 128)), w),
        "poles: blocked 256": (jax.vmap(lambda w: _scans.poles_blocked(b, w, 256)), w),
        "backlash: sequential scan (CPU form)": (
            jax.vmap(lambda x: _simulate.backlash(params, x)), x),
        "backlash: doubling scan of clamp and threshold maps": (
            jax.vmap(lambda x: _scans.backlash(x, x + cL, mR * (x - cR), mR)), x),
        "output and Jacobian: sequential scan (CPU form)": (
            jax.vmap(lambda u: _sensitivity.output_jacobian(params, u)), u),
        "output and Jacobian: doubling scans": (
            jax.vmap(lambda u: _sensitivity.output_jacobian_parallel(params, u)), u),
        "literal step: regression and normal equations (this backend's forms)": (
            jax.vmap(lambda u, y: from_regression(step_regression(params, u, y), params.orders)),
            u, y),
    }  # fmt: skip
    print(f"device: {device_description()}; batch {B}, N {T}, float64")
    print(f"{'form':72s} {'ms/batch':>10s} {'us/real.':>9s} {'compile s':>9s}")
    for name, (function, *arguments) in forms.items():
        seconds, compile_s = _timed(function, *arguments, repeats=args.repeats)
        print(f"{name:72s} {1e3 * seconds:10.2f} {1e6 * seconds / B:9.2f} {compile_s:9.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
