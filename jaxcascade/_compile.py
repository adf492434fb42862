"""How the package's large programs are compiled: XLA options that cut compile time.

The robust estimator's batched program (the literal iteration, three Levenberg-
Marquardt call sites over forward-sensitivity scans, the multi-start under a
`custom_vmap`) is about 10k lines of StableHLO, and XLA's CPU backend spends most of
its compile time generating and optimising machine code for the loop bodies. Two of
XLA's options trade little run time for much less of it:

- `xla_cpu_use_fusion_emitters = False`: the element-wise emitters instead of the
  MLIR fusion emitters;
- `xla_backend_optimization_level = 1` (LLVM's -O1 instead of -O2/-O3).

Their effect on the robust benchmark's program (cold compile in fresh processes,
alternated, both settings in one sitting) and on its fits per second is measured by
`benchmarks/compile_options.py` (`results/compile_options.md`, which names its machine).
Level 0 compiles faster still but runs about 4 times slower (the loop bodies are not
vectorised), so it is not used.

The options are passed per program (`jax.jit(..., compiler_options=...)`), never set
globally: importing the package changes nothing in JAX's configuration. They reach
XLA only through the outermost `jit`: an inner `jit` is inlined into its caller's
program, so every place that compiles a program holding an estimator passes them
(`compiler_options()`). An XLA that does not know them (another jaxlib, another
backend) compiles without them: `compiler_options()` asks once, on a tiny program.
"""

from __future__ import annotations

import functools
import hashlib
import os
import pathlib
import pickle
import threading

import equinox as eqx
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
    decorator (with or without keyword arguments): called on arrays, or under an eager
    `vmap` (which compiles the batched program as its own, `_own_program`). Inside
    another `jit`, a `scan` or a `grad` it is a plain `jax.jit`, inlined into the
    caller's program, which is compiled with the caller's options (JAX refuses options
    on a nested `jit`). The options are looked up at the first call, not at import."""
    if function is None:
        return functools.partial(jit, **kwargs)

    @functools.cache
    def compiled(top: bool):
        options = compiler_options() if top else {}
        return jax.jit(function, compiler_options=options or None, **kwargs)

    @functools.wraps(function)
    def call(*args, **kw):
        return compiled(_own_program((args, kw)))(*args, **kw)

    call.lower = lambda *args, **kw: compiled(_own_program((args, kw))).lower(*args, **kw)
    return call


def _own_program(arguments) -> bool:
    """Whether a `jit` called on `arguments` compiles a program of its own: its arguments
    are arrays, or tracers of eager `vmap`s only (JAX compiles the batched program as its
    own). Under any other transformation (`jit`, `scan`, `grad`, which stages the
    function into a traced program) it is inlined. JAX says which transformations are
    active only through internal functions: where they are missing or fail, tracers
    count as inside a program (no options)."""
    leaves = jax.tree_util.tree_leaves(arguments)
    if not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
        return True
    try:
        from jax._src import core

        stack = core.unsafe_get_trace_stack(core.trace_ctx.trace)
        return all(type(trace).__name__ in ("EvalTrace", "BatchTrace") for trace in stack)
    except Exception:  # another JAX: the safe answer
        return False


def filter_jit(function):
    """`equinox.filter_jit` with `compiler_options()` where it compiles a program of its
    own (as `jit`: inside another traced program it is a plain `filter_jit`, whose
    options would not reach XLA). For functions of modules with static fields (a model,
    an effect)."""

    @functools.cache
    def compiled(top: bool):
        options = compiler_options() if top else {}
        if options:
            return eqx.filter_jit(function, compiler_options=options)
        return eqx.filter_jit(function)

    first = _FirstCalls()

    @functools.wraps(function)
    def call(*args, **kw):
        top = _own_program((args, kw))
        if not top:
            return compiled(top)(*args, **kw)
        return first.run(_signature((args, kw)), compiled(top), *args, **kw)

    return call


def _signature(arguments):
    """What a `jit` keys its programs on: the arguments' static parts, their tree and
    the arrays' shapes and dtypes; None where a static part cannot be hashed."""
    dynamic, static = eqx.partition(arguments, eqx.is_array)
    leaves, tree = jax.tree_util.tree_flatten(dynamic)
    shapes = tuple(
        (tuple(leaf.shape), str(leaf.dtype), bool(getattr(leaf, "weak_type", False)))
        for leaf in leaves
    )
    parts, layout = jax.tree_util.tree_flatten(static)
    key = (tree, layout, tuple(parts), shapes)
    try:
        hash(key)
    except TypeError:
        return None
    return key


class _PerKey:
    """A lock per key, made on first use: threads working on one key (tracing,
    compiling or loading one program) take turns; threads on other keys do not wait."""

    def __init__(self):
        self.locks: dict = {}
        self.guard = threading.Lock()

    def __call__(self, key) -> threading.Lock:
        with self.guard:
            return self.locks.setdefault(key, threading.Lock())


class _FirstCalls:
    """The first call of each signature runs alone: threads that call a program with
    the same signature meanwhile (the loop's candidates, `_loop._Workers`, several of
    one group of effects: `_effects._choice`) wait for it, then find it compiled,
    instead of tracing and compiling it again each. Later calls take no lock."""

    def __init__(self):
        self.done: set = set()
        self.lock = _PerKey()

    def run(self, key, function, *args, **kw):
        if key is None or key in self.done:
            return function(*args, **kw)
        with self.lock(key):
            out = function(*args, **kw)
            self.done.add(key)
        return out


def carried_like(reference, value):
    """`value` (a pytree of arrays), each leaf computed from `reference` (a `select` on a
    predicate that is always False; XLA folds it away): the start of a `while_loop`'s or
    a `scan`'s carry whose leaves would otherwise be constants. Under `vmap` each leaf is
    then batched wherever `reference` is, and JAX's batching rule for the loop, which
    traces the body again until it knows which elements of the carry are batched, finds
    that out at its first look: the loop's body is traced once less (the model-error
    loop's refit and initial-state tracing fell from 5.44 to 4.50 s and from 3.60 to
    2.85 s, summed over a cold run with one thread). The values and the compiled
    program's arithmetic are the same."""
    leaf = jax.tree_util.tree_leaves(reference)[0]
    never = jnp.zeros((), bool) & jnp.isnan(jnp.ravel(leaf)[0])
    return jax.tree_util.tree_map(lambda v: jnp.where(never, jnp.zeros_like(v), v), value)


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
_counting = threading.Lock()  # the loop fits candidates in threads (`_loop`)

# `bound`'s limits: programs compiled since the last release (a candidate of the loop
# compiles 20-60, each holding tens of memory mappings on the damper's records), and
# mappings of the process (a quarter of Linux's default `vm.max_map_count`, 65,530).
PROGRAMS = 400
MAPPINGS = 16_000


def _count(event: str, duration: float, **kwargs) -> None:
    global _compiles
    if event == _BACKEND_COMPILE:
        with _counting:
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
    trim()


def mappings() -> int | None:
    """The process's memory mappings (lines of `/proc/self/maps`), None where the
    system has no such file."""
    try:
        with open("/proc/self/maps", "rb") as maps:
            return maps.read().count(b"\n")  # one line a mapping
    except OSError:
        return None


@functools.cache
def _malloc_trim():
    """glibc's `malloc_trim`, or None where the C library has none (macOS, musl)."""
    import ctypes

    try:
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


def trim() -> None:
    """Hand the allocator's free memory back to the system (glibc's `malloc_trim`; a
    no-op where the C library has none). glibc keeps what a thread freed in that
    thread's arena: the programs `release` frees stay resident without it (the
    Wiener-Hammerstein stand-in's loop, two threads, warm cache: 2.1 GB at its end
    without, 1.6 GB with; a release then gives back about 1 GB instead of 40 MB)."""
    function = _malloc_trim()
    if function is not None:
        function(0)


def over_bound(programs: int = PROGRAMS, mapped: int = MAPPINGS) -> bool:
    """Whether more than `programs` programs were compiled since the last release, or
    the process holds more than `mapped` memory mappings (`bound` would release)."""
    count = mappings()
    return compile_count() - _released_at > programs or (count is not None and count > mapped)


def bound(programs: int = PROGRAMS, mapped: int = MAPPINGS) -> bool:
    """`release` when `over_bound`; True when it released. Called between the stages of
    a long host-side loop, it keeps what the stages share compiled and the process's
    programs under a fixed bound. Never while another thread is tracing, compiling or
    running a program: it frees what that thread is using."""
    if over_bound(programs, mapped):
        release()
        return True
    return False


# -- Traced programs kept across processes ---------------------------------------------
#
# `jax.export` of the loop's and the fit's large programs, so that a second run does not
# trace them again. JAX's persistent compilation cache (turned on by the CLI) keeps
# XLA's compiled code, but every process still traces and lowers every program before it
# can look the code up: on the model-error loop of two 1,024-sample records that is
# about half of a warm run (`benchmarks/loop_speed.py`, `results/loop_speed.md`).
# `exported(function)` keeps the lowered program itself (`jax.export`, serialised
# StableHLO) in `CACHE/exported/`, beside JAX's cache folder, keyed by
#
# - the function's module and name,
# - everything about the call that is not an array (`equinox.partition`: the orders, the
#   settings, a model's structure and static fields), pickled,
# - every array's shape and dtype,
# - the versions of JAX and jaxlib, float64 on or off, the XLA options
#   (`_compile.compiler_options`) and a digest of the package's source files, so that an
#   upgrade, or any change to the package's code, reads nothing an earlier version wrote.
#
# A later process deserialises the program and calls it (`Exported.call` under `jax.jit`
# with the package's XLA options): no tracing of the function, and XLA's compiled code is
# found in JAX's persistent cache as before. The program is the same StableHLO, so the
# results are the same (tested bit for bit).
#
# It is used only where it can help and cannot change a result: at the top level (not
# under `jit`, `vmap` or `grad`, where the caller's program is being traced anyway), and
# only while JAX's persistent cache is on (`jax_compilation_cache_dir` set: the CLI, not
# the library by default). A call whose non-array parts cannot be pickled, or a program
# that `jax.export` cannot serialise, runs the function's own `jit` as before (and is not
# tried again in the process); an unreadable or unwritable cache folder only costs the
# tracing.

# Bump when the layout of the cache's files changes.
FORMAT = 1
# Kept programs at most (each 50-100 kB): past it the oldest go. Every change to the
# package's code makes new keys, so a developer's folder would otherwise only grow.
MAX_KEPT = 2000
# jaxlib's own LAPACK kernels on the CPU (`lapack_<s|d|c|z><routine>_ffi`, the custom
# calls of `jnp.linalg` and lineax): `jax.export` asks that a custom call without its
# compatibility promise be named. A kept program is only ever read by the same jaxlib
# (its version is in the key), so the promise is not needed.
_LAPACK = tuple(
    f"lapack_{t}{routine}_ffi"
    for t in "sdcz"
    for routine in (
        "potrf geev syevd heevd gehrd orgqr ungqr ormqr unmqr getrf geqrf geqp3 gees "
        "gesdd gesvd trsm sytrd hetrd gtsv"
    ).split()
)


@functools.cache
def _source_digest() -> str:
    """A digest of every source file of the package (its bytes): any change to the code
    makes a new key."""
    root = pathlib.Path(__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def exported_folder() -> pathlib.Path | None:
    """`CACHE/exported`, `CACHE` JAX's persistent cache folder; None while it is off."""
    cache = jax.config.jax_compilation_cache_dir
    return None if not cache else pathlib.Path(cache) / "exported"


def _key(name: str, static, tree, leaves) -> str:
    import jaxlib

    from ._version import __version__

    shapes = [(tuple(leaf.shape), str(leaf.dtype)) for leaf in leaves]
    environment = (
        FORMAT,
        jax.__version__,
        jaxlib.__version__,
        __version__,
        _source_digest(),
        bool(jax.config.jax_enable_x64),
        sorted(compiler_options().items()),
        jax.default_backend(),
    )
    text = pickle.dumps((name, environment, static, tree, shapes), protocol=4)
    return hashlib.sha256(text).hexdigest()


def _tracing(leaves) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def exported(function=None, *, custom_calls: tuple[str, ...] = (), prepare=None):
    """Decorator: `function` (traceable, taking and returning pytrees of arrays and
    static parts, like an `equinox.filter_jit` function) run through its kept program
    (the comment above); `function.jitted` is what runs where that does not apply,
    `filter_jit` with the package's XLA options. `custom_calls`: the package's own
    custom-call targets the program may hold (its compiled kernel: `jax.export` refuses
    them unless named, as it cannot promise their compatibility; the source digest in
    the key does), and `prepare()`, called before a kept program runs, registers them."""
    if function is None:
        return functools.partial(exported, custom_calls=custom_calls, prepare=prepare)
    jitted = filter_jit(function)
    name = f"{function.__module__}.{function.__qualname__}"
    loaded: dict = {}  # key -> the kept program, arrays in, the function's output out
    refused: set = set()  # keys whose export or pickling failed in this process
    lock = _PerKey()  # one thread loads or exports a key; others with it wait
    targets = (*_LAPACK, *custom_calls)
    checks = tuple(jax.export.DisabledSafetyCheck.custom_call(t) for t in targets)

    @functools.wraps(function)
    def call(*args, **kwargs):
        where = exported_folder()
        if where is None:
            return jitted(*args, **kwargs)
        dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
        leaves, tree = jax.tree_util.tree_flatten(dynamic)
        if _tracing(leaves):
            return jitted(*args, **kwargs)
        try:
            key = _key(name, static, tree, leaves)
        except Exception:  # a static part that cannot be pickled
            return jitted(*args, **kwargs)
        if key in refused:
            return jitted(*args, **kwargs)
        entry = loaded.get(key)
        if entry is None:
            with lock(key):
                entry = loaded.get(key)
                if entry is None and key not in refused:
                    if prepare is not None:
                        prepare()
                    entry = _load(where, key) or _export(
                        function, static, tree, leaves, where, key, checks
                    )
                    if entry is None:
                        refused.add(key)
                    else:
                        loaded[key] = entry
            if entry is None:
                return jitted(*args, **kwargs)
        return entry(*leaves)

    call.jitted = jitted
    return call


class _Slot:
    """Where the `i`-th array output of a kept program goes in its output's template (a
    pickled copy of the output with every array replaced by a slot)."""

    def __init__(self, i: int):
        self.i = i


def _runner(exported_program, template):
    options = compiler_options()

    def run_kept(*leaves):
        return exported_program.call(*leaves)

    # named after the kept function (`jit(_refit)` in JAX's compile log), not `call`
    run_kept.__name__ = run_kept.__qualname__ = exported_program.fun_name
    run = jax.jit(run_kept, compiler_options=options or None)
    parts, tree = jax.tree_util.tree_flatten(template, is_leaf=lambda x: isinstance(x, _Slot))

    def program(*leaves):
        arrays = run(*leaves)
        filled = [arrays[p.i] if isinstance(p, _Slot) else p for p in parts]
        return jax.tree_util.tree_unflatten(tree, filled)

    return program


def _load(where: pathlib.Path, key: str):
    path = where / f"{key}.bin"
    try:
        payload = pickle.loads(path.read_bytes())
        program = jax.export.deserialize(bytearray(payload["program"]))
        return _runner(program, payload["template"])
    except Exception:  # missing, partly written or from another build: trace again
        return None


def _export(function, static, tree, leaves, where: pathlib.Path, key: str, checks=()):
    kept = {}

    def flat(*arrays):
        args, kwargs = eqx.combine(jax.tree_util.tree_unflatten(tree, arrays), static)
        out_leaves, out_tree = jax.tree_util.tree_flatten(function(*args, **kwargs))
        outputs, template = [], []
        for leaf in out_leaves:
            if eqx.is_array(leaf):
                template.append(_Slot(len(outputs)))
                outputs.append(leaf)
            else:
                template.append(leaf)
        kept["template"] = jax.tree_util.tree_unflatten(out_tree, template)
        return outputs

    # the program keeps the function's name (`Exported.fun_name`, JAX's compile log)
    flat.__name__ = flat.__qualname__ = getattr(function, "__name__", "flat")
    specs = [jax.ShapeDtypeStruct(leaf.shape, leaf.dtype) for leaf in leaves]
    try:
        program = jax.export.export(jax.jit(flat), disabled_checks=checks)(*specs)
        payload = {"program": bytes(program.serialize()), "template": kept["template"]}
        blob = pickle.dumps(payload, protocol=4)
    except Exception:  # not exportable (a host callback) or its output not picklable
        return None
    try:
        where.mkdir(parents=True, exist_ok=True)
        # one partial file per process and thread (the loop fits candidates in threads)
        partial = where / f"{key}.{os.getpid()}.{threading.get_ident()}.partial"
        partial.write_bytes(blob)
        partial.replace(where / f"{key}.bin")  # atomic: a reader sees all or nothing
        kept_files = list(where.glob("*.bin"))
        if len(kept_files) > MAX_KEPT:
            kept_files.sort(key=lambda path: path.stat().st_mtime)
            for path in kept_files[: len(kept_files) - MAX_KEPT]:
                path.unlink(missing_ok=True)
    except OSError:
        pass  # an unwritable cache only costs the tracing next time
    return _runner(program, kept["template"])


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
