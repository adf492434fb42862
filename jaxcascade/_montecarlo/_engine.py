"""The Monte-Carlo engine: keys, one realisation, and chunks of realisations as one
compiled, batched call.

One realisation draws an input record (uniform in `(-A, A)`), simulates the cascade,
adds output noise at the cell's SNR, computes the record's output-error Cramér-Rao bound
(`_efficiency.crlb`), fits it with the cell's estimator, and scores the estimate on a
fresh record (fresh input and fresh noise): validation
`NRMSE = rms(y_val - simulate(estimate, u_val)) / std(y_val)`, `inf` when the estimate
is inadmissible (so a table never holds a NaN score).

A chunk of realisations of one cell runs as one jit-compiled, `vmap`-ed call
(`run_chunk`, a pure function of `(spec, cell, indices)`, so it can be shipped to a
worker). Chunks are padded to `spec.chunk_size`, so a cell compiles once.

**Keys.** Realisation `i` of a cell uses `fold_in(cell_key, i)`, where `cell_key` is
`PRNGKey(seed)` folded with a 64-bit hash of the cell's data identity: the true
parameters and orders, the input distribution, N and SNR. Nothing else enters: not the
chunking, not the order of execution, and not the estimator, so every estimator of a
sweep sees the same records (common random numbers: differences between estimators
are not Monte-Carlo noise). An estimator with random starts gets its own key folded
from the realisation key and its name. For a family of systems (`Spec.family`) the
cell identity names the family and orders instead of the true values, and realisation
`i` draws its true system from `fold_in(realisation_key, hash("system:FAMILY"))`: every
estimator of a sweep fits the same system and record, and the table stores each row's
truth (`true_<name>`).

**Timing.** Each chunk is compiled ahead of time (once per process and cell shape) and
then timed: `fit_seconds` is the wall time of the compiled batched call (with the
transfer of its results to the host) divided by the batch size (the padded rows are
computed too), and `compile_seconds` the time this chunk spent compiling (0 when the
executable was already there). Both vary from run to run; `TIMING_COLUMNS` names them,
and `without_timing` drops them to compare tables exactly.

**Systems that change** (`Spec.change`, `_changing`). The record comes from the
trajectory of true parameters (`simulate_changing`), the validation record from the
system at the end, and the estimator (`recursive`, keeping its estimate every `every`
samples) returns its trajectory: per realisation the error `estimate - truth(t)` at the
recorded samples (`tracking_samples`), and from it the tracking measures of
`_tracking` (samples to re-entry within 0.05 of the new truth, whether it settled, the
steady RMSE after re-entry, whether it was within the band before the change). The
change enters the cell identity, so its records differ from those of the unchanged
system (and a spec without a change keeps its keys). No Cramér-Rao bound is computed
for a changing system.

**Memory.** Peak memory of a chunk grows as `chunk_size x N` (each realisation holds a
few `N x P` regression matrices and signals of length N); `chunk_memory` reports
XLA's buffer sizes for a cell and chunk size.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._changing import Change, simulate_changing, trajectory_traced
from .._compile import compiler_options
from .._efficiency import crlb
from .._estimator import estimator
from .._metrics import nrmse
from .._model import CascadeParams, is_admissible
from .._normal_equations import resolve
from .._prior import random_system
from .._simulate import add_noise, simulate, uniform_input
from ._spec import Cell, Spec
from ._tables import realisation_frame


def _hash_words(text: str) -> np.ndarray:
    digest = hashlib.blake2b(text.encode(), digest_size=8).digest()
    return np.frombuffer(digest, dtype="<u4")


def cell_identity(spec: Spec, cell: Cell) -> str:
    """What a cell's records depend on, as canonical text (floats in exact hex form)."""
    if spec.family is not None:
        system = {"family": spec.family}
    else:
        system = {
            "values": {name: float(value).hex() for name, value in spec.true_values().items()}
        }
    return json.dumps(
        {
            "orders": str(spec.orders),
            **system,
            "input": spec.input,
            "amplitude": float(spec.amplitude).hex(),
            "n": int(cell.n),
            "snr": float(cell.snr).hex(),
            **({"change": _change_identity(spec.change)} if spec.change is not None else {}),
        },
        sort_keys=True,
    )


def _change_identity(change: Change) -> dict:
    out = {"parameter": change.parameter, "at": int(change.at)}
    for name in ("to", "drift"):
        value = getattr(change, name)
        if value is not None:
            out[name] = float(value).hex()
    return out


def tracking_samples(n: int, every: int) -> np.ndarray:
    """The samples (1-based counts) after which `recursive` with `every` records its
    estimate on a record of `n` samples (the last row: the final estimate)."""
    return np.minimum(np.arange(1, -(-n // every) + 1) * every, n)


def cell_key(spec: Spec, cell: Cell):
    """`PRNGKey(seed)` folded with the 64-bit hash of `cell_identity` (two 32-bit words)."""
    key = jax.random.PRNGKey(np.uint32(spec.seed))
    for word in _hash_words(cell_identity(spec, cell)):
        key = jax.random.fold_in(key, word)
    return key


def _system_tag(family: str) -> np.uint32:
    return np.uint32(_hash_words(f"system:{family}")[0])


def _realisation(
    cell_key,
    index,
    truth_vector,
    snr,
    *,
    orders,
    n,
    amplitude,
    fit,
    fit_key_tag,
    family,
    change=None,
):
    """One record: input, noisy output, fit, validation on a fresh record.

    With a `family`, `truth_vector` only gives the dtype: the true system is drawn from
    the family's prior with a key folded from the realisation key.
    """
    dtype = truth_vector.dtype
    key = jax.random.fold_in(cell_key, index)
    if family is not None:
        system_key = jax.random.fold_in(key, _system_tag(family))
        truth_vector = random_system(system_key, orders, amplitude, dtype).to_vector()
    truth = CascadeParams.from_vector(truth_vector, orders, check=False)
    key_u, key_e, key_u_val, key_e_val = jax.random.split(key, 4)
    u = uniform_input(key_u, n, amplitude, dtype)
    if change is None:
        y = add_noise(key_e, simulate(truth, u), snr)
        # the record's own Cramér-Rao bound (noise-free: 0), for the efficiency columns
        bound = crlb(truth, u, snr=snr)
    else:
        truths = trajectory_traced(truth_vector, change, n, orders)
        y = add_noise(key_e, simulate_changing(truths, u, orders), snr)
        truth_vector = truths[-1]  # the system at the end: validation and true_<name>
        truth = CascadeParams.from_vector(truth_vector, orders, check=False)
    solution = fit(
        u,
        y,
        orders,
        key=jax.random.fold_in(key, fit_key_tag),
        input_range=(-amplitude, amplitude),
    )
    estimate = solution.params.to_vector().astype(dtype)

    u_val = uniform_input(key_u_val, n, amplitude, dtype)
    y_val = add_noise(key_e_val, simulate(truth, u_val), snr)
    admissible = is_admissible(
        CascadeParams.from_vector(estimate, orders, check=False), -amplitude, amplitude
    )
    # An inadmissible estimate (unstable, unsorted breakpoints, ...) is not simulated:
    # its score is inf, and the truth stands in so no NaN is ever computed.
    safe = CascadeParams.from_vector(
        jnp.where(admissible, estimate, truth_vector), orders, check=False
    )
    error = nrmse(y_val, simulate(safe, u_val))
    error = jnp.where(admissible & jnp.isfinite(error), error, jnp.inf)
    out = {
        "key": jax.random.key_data(key) if _is_typed(key) else key,
        "estimate": estimate,
        "status": solution.status.astype(jnp.int32),
        "iterations": solution.iterations.astype(jnp.int32),
        "cost": jnp.asarray(solution.cost, dtype),
        "cycle_amplitude": jnp.asarray(solution.cycle_amplitude, dtype),
        "path": solution.path.astype(jnp.int32),
        "nrmse": error,
        "admissible": admissible,
        "truth": truth_vector,
    }
    if change is None:
        out["crlb"] = bound
    else:
        samples = tracking_samples(n, fit.every)
        out["track"] = solution.history[1:].astype(dtype) - truths[samples - 1]
    return out


def _is_typed(key) -> bool:
    return jnp.issubdtype(key.dtype, jax.dtypes.prng_key)


@functools.lru_cache(maxsize=64)
def _compiled(orders, n, amplitude, name, settings, batched, family=None, change=None):
    """The jitted (optionally vmapped) realisation function of one cell shape."""
    one = functools.partial(
        _realisation,
        orders=orders,
        n=n,
        amplitude=amplitude,
        fit=estimator(name, **dict(settings)),
        fit_key_tag=np.uint32(_hash_words(f"estimator:{name}")[0]),
        family=family,
        change=change,
    )
    if batched:
        one = jax.vmap(one, in_axes=(None, 0, None, None))
    return jax.jit(one, compiler_options=compiler_options())


def _arguments(spec: Spec, cell: Cell, dtype=None):
    dtype = dtype or jnp.result_type(float)
    if spec.family is not None:  # drawn per realisation; only the shape and dtype matter
        truth = jnp.zeros((len(spec.orders.names),), dtype)
    else:
        truth = spec.truth(dtype).to_vector()
    return cell_key(spec, cell), truth, jnp.asarray(cell.snr, dtype)


def _function(spec: Spec, cell: Cell, batched: bool):
    settings = spec.estimator_settings(cell.estimator)
    return _compiled(
        spec.orders,
        cell.n,
        spec.amplitude,
        cell.estimator,
        settings,
        batched,
        spec.family,
        spec.change,
    )


# Ahead-of-time compiled chunk executables of this process, so that compiling is timed
# apart from computing. Keyed by everything the executable depends on.
_EXECUTABLES: dict = {}
_MAX_EXECUTABLES = 64


def _executable(spec: Spec, cell: Cell, arguments) -> tuple:
    """(compiled batched function, seconds spent compiling it now: 0 if cached)."""
    key, indices, truth, snr = arguments
    cache_key = (
        spec.orders,
        cell.n,
        spec.amplitude,
        cell.estimator,
        spec.estimator_settings(cell.estimator),
        spec.family,
        spec.change,
        indices.shape,
        str(truth.dtype),
        str(key.dtype),
        key.shape,
    )
    if cache_key in _EXECUTABLES:
        return _EXECUTABLES[cache_key], 0.0
    start = time.perf_counter()
    compiled = _function(spec, cell, batched=True).lower(*arguments).compile()
    seconds = time.perf_counter() - start
    if len(_EXECUTABLES) >= _MAX_EXECUTABLES:
        _EXECUTABLES.pop(next(iter(_EXECUTABLES)))
    _EXECUTABLES[cache_key] = compiled
    return compiled, seconds


def run_chunk(spec: Spec, cell: Cell, indices) -> pd.DataFrame:
    """Realisations `indices` of `cell`, batched in one compiled call; one row each
    (`frame.attrs["normal_equations"]` says how the normal equations were formed).

    A pure function of its arguments (and the default float dtype): the same indices
    give the same rows whatever the chunking. The batch is padded to
    `spec.chunk_size` so that every chunk of a cell reuses one compilation.
    """
    indices = np.asarray(indices, dtype=np.int64)
    if indices.ndim != 1 or indices.size == 0:
        raise ValueError("run_chunk needs a non-empty list of realisation indices.")
    if indices.min() < 0 or indices.max() >= 2**32:
        raise ValueError("Realisation indices must lie in [0, 2**32).")
    size = max(spec.chunk_size, indices.size)
    padded = np.concatenate([indices, np.full(size - indices.size, indices[-1])])
    key, truth, snr = _arguments(spec, cell)
    arguments = (key, jnp.asarray(padded.astype(np.uint32)), truth, snr)
    compiled, compile_seconds = _executable(spec, cell, arguments)
    start = time.perf_counter()
    outputs = jax.device_get(compiled(*arguments))
    seconds = time.perf_counter() - start
    outputs = {k: np.asarray(v)[: indices.size] for k, v in outputs.items()}
    outputs["key"] = _key_to_uint64(outputs["key"])
    outputs["fit_seconds"] = seconds / size
    outputs["compile_seconds"] = compile_seconds
    frame = realisation_frame(spec, cell, indices, outputs)
    frame.attrs["normal_equations"] = normal_equations_backend(spec)
    return frame


def normal_equations_backend(spec: Spec, dtype=None) -> str:
    """How this process forms the literal iteration's normal equations for `spec`
    (`fused` or `xla`: same estimates up to rounding), recorded with every chunk. Called
    after a chunk ran, so the native kernel was already built if it is used."""
    return resolve("auto", spec.orders, dtype or jnp.result_type(float))


def run_realisation(spec: Spec, cell: Cell, index: int) -> dict:
    """One realisation without `vmap` (to rerun a table row, and the batching oracle)."""
    key, truth, snr = _arguments(spec, cell)
    out = jax.device_get(_function(spec, cell, batched=False)(key, np.uint32(index), truth, snr))
    out = {k: np.asarray(v) for k, v in out.items()}
    out["key"] = _key_to_uint64(out["key"][None])[0]
    return out


def _key_to_uint64(words) -> np.ndarray:
    words = np.asarray(words).astype(np.uint64)
    return (words[:, 0] << np.uint64(32)) | words[:, 1]


def chunk_memory(spec: Spec, cell: Cell, chunk_size: int | None = None) -> dict[str, int]:
    """XLA's buffer sizes in bytes for one compiled chunk: temp, argument, output, total."""
    size = chunk_size or spec.chunk_size
    key, truth, snr = _arguments(spec, cell)
    indices = jnp.zeros((size,), jnp.uint32)
    compiled = _function(spec, cell, batched=True).lower(key, indices, truth, snr).compile()
    analysis = compiled.memory_analysis()
    sizes = {
        "temp": int(analysis.temp_size_in_bytes),
        "argument": int(analysis.argument_size_in_bytes),
        "output": int(analysis.output_size_in_bytes),
    }
    sizes["total"] = sum(sizes.values())
    return sizes
