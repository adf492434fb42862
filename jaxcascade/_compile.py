"""How the package's large programs are compiled: XLA options that cut compile time.

The robust estimator's batched program (the literal iteration, three Levenberg-
Marquardt call sites over forward-sensitivity scans, the multi-start under a
`custom_vmap`) is about 10k lines of StableHLO, and XLA's CPU backend spends most of
its compile time generating and optimising machine code for the loop bodies. Two of
XLA's options trade little run time for much less of it:

- `xla_cpu_use_fusion_emitters = False`: the element-wise emitters instead of the
  MLIR fusion emitters;
- `xla_backend_optimization_level = 1` (LLVM's -O1 instead of -O2/-O3).

Measured on the robust benchmark's program (256 records, 2-core AMD EPYC, float64,
cold compile in fresh processes, alternated; `benchmarks/compile_options.py`,
`results/compile_options.md`): compile 8.3-11.0 s instead of 14.2-18.0 s over the three
benchmark systems, 8-19% fewer fits per second. The literal iteration's program: 1.8 s
instead of 3.3 s, no slower. Level 0 compiles faster still but runs about 4 times slower
(the loop bodies are not vectorised), so it is not used.

The options are passed per program (`jax.jit(..., compiler_options=...)`), never set
globally: importing the package changes nothing in JAX's configuration. They reach
XLA only through the outermost `jit`: an inner `jit` is inlined into its caller's
program, so every place that compiles a program holding an estimator passes them
(`compiler_options()`). An XLA that does not know them (another jaxlib, another
backend) compiles without them: `compiler_options()` asks once, on a tiny program.
"""

from __future__ import annotations

import functools
import os

import jax
import jax.numpy as jnp

OPTIONS = {
    "xla_cpu_use_fusion_emitters": False,
    "xla_backend_optimization_level": 1,
}


@functools.cache
def _supported(backend: str) -> bool:
    # `backend` (the default one) keys the cache
    try:
        jax.jit(jnp.sin, compiler_options=OPTIONS).lower(1.0).compile()
    except Exception:  # an XLA without these options: compile with its defaults
        return False
    return True


def compiler_options() -> dict:
    """The options for the default backend's programs (`{}` where XLA does not know
    them, or where `JAXCASCADE_COMPILE=default` asks for XLA's defaults)."""
    if os.environ.get("JAXCASCADE_COMPILE", "").lower() == "default":
        return {}
    backend = jax.default_backend()
    return dict(OPTIONS) if backend == "cpu" and _supported(backend) else {}


def jit(function=None, **kwargs):
    """`jax.jit` with `compiler_options()` where it compiles a program of its own, as a
    decorator (with or without keyword arguments). Called on tracers (inside another
    `jit`, `vmap` or `grad`) it is a plain `jax.jit`, whose options would not reach XLA
    (the caller's program is compiled with the caller's options). The options are
    looked up at the first call, not at import."""
    if function is None:
        return functools.partial(jit, **kwargs)

    @functools.cache
    def compiled(top: bool):
        options = compiler_options() if top else {}
        return jax.jit(function, compiler_options=options or None, **kwargs)

    def top(args, kw) -> bool:
        leaves = jax.tree_util.tree_leaves((args, kw))
        return not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)

    @functools.wraps(function)
    def call(*args, **kw):
        return compiled(top(args, kw))(*args, **kw)

    call.lower = lambda *args, **kw: compiled(top(args, kw)).lower(*args, **kw)
    return call
