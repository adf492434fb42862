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
import numpy as np

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


# -- Bounded compilation -------------------------------------------------------------
#
# Every compiled program stays in memory, and in the process's memory mappings (about
# three per program; Linux allows 65,530 per process), until JAX's caches release it.
# A long host-side loop over records of many lengths (the model-error loop) compiles
# one program per shape: record lengths are rounded up to a few buckets
# (`bucket_length`, `pad`), and `release` frees what a finished stage compiled;
# `bound` frees it only when the programs compiled since the last release, or the
# process's memory mappings, pass a limit, so that a later stage (the next candidate,
# the next record) reuses what an earlier one compiled.

_BACKEND_COMPILE = "/jax/core/compile/backend_compile_duration"
_compiles = 0
_listening = False
_released_at = 0

# `bound`'s limits: programs compiled since the last release (a candidate of the loop
# compiles 20-60, each holding tens of memory mappings on the damper's records), and
# mappings of the process (a quarter of Linux's default `vm.max_map_count`, 65,530).
PROGRAMS = 400
MAPPINGS = 16_000


def _count(event: str, duration: float, **kwargs) -> None:
    global _compiles
    if event == _BACKEND_COMPILE:
        _compiles += 1


def compile_count() -> int:
    """Programs XLA has compiled in this process since the first call (a listener on
    JAX's monitoring events, installed on that call)."""
    global _listening
    if not _listening:
        jax.monitoring.register_event_duration_secs_listener(_count)
        _listening = True
    return _compiles


def bucket_length(n: int, bits: int = 3) -> int:
    """`n` rounded up to a number with `bits` significant bits (at most `2^(1-bits)`
    longer: a quarter with 3 bits): lengths that differ a little share a bucket, and
    every octave holds `2^(bits-1)` of them."""
    n = int(n)
    if n <= 2**bits:
        return max(n, 1)
    step = 1 << (n.bit_length() - bits)
    return -(-n // step) * step


def pad(u, length: int | None = None):
    """A 1-D record padded at its end to `length` (default `bucket_length(len(u))`) by
    repeating its last sample, a NumPy array. Causal models simulated on it give the
    same output on the record's own samples; an operator driven by the increments of
    its input sees none in the padding."""
    u = np.asarray(u)
    length = bucket_length(u.shape[0]) if length is None else int(length)
    if length == u.shape[0]:
        return u
    return np.concatenate([u, np.full(length - u.shape[0], u[-1], u.dtype)])


def release() -> None:
    """Free every compiled program JAX holds (its caches): what a finished stage of a
    long host-side loop compiled. Later calls compile again what they need."""
    import gc

    global _released_at
    jax.clear_caches()
    gc.collect()
    _released_at = compile_count()


def mappings() -> int | None:
    """The process's memory mappings (lines of `/proc/self/maps`), None where the
    system has no such file."""
    try:
        with open("/proc/self/maps", "rb") as maps:
            return sum(1 for _ in maps)
    except OSError:
        return None


def bound(programs: int = PROGRAMS, mapped: int = MAPPINGS) -> bool:
    """`release` when more than `programs` programs were compiled since the last
    release, or the process holds more than `mapped` memory mappings; True when it
    released. Called between the stages of a long host-side loop, it keeps what the
    stages share compiled and the process's programs under a fixed bound."""
    count = mappings()
    if compile_count() - _released_at > programs or (count is not None and count > mapped):
        release()
        return True
    return False


def pack(us, ys, dtype=None) -> tuple:
    """Records grouped by length bucket (`_compile.bucket_length`): a tuple of `(U, Y, M)`
    per bucket, each `(R, L)`: inputs and outputs padded by their last sample, and a
    mask (1 on a record's own samples). A program over the groups is compiled once for
    any records of the same buckets, and simulates each group in one batched scan."""
    dtype = dtype or jnp.asarray(us[0]).dtype
    groups: dict[int, list] = {}
    for u, y in zip(us, ys, strict=True):
        groups.setdefault(bucket_length(np.shape(u)[0]), []).append((u, y))
    packed = []
    for length in sorted(groups):
        rows = groups[length]
        U = np.stack([pad(np.asarray(u, float), length) for u, _ in rows])
        Y = np.stack([pad(np.asarray(y, float), length) for _, y in rows])
        M = np.stack([np.arange(length) < np.shape(u)[0] for u, _ in rows])
        packed.append(tuple(jnp.asarray(a, dtype) for a in (U, Y, M)))
    return tuple(packed)
