"""The Monte-Carlo engine: keys, one realisation, and chunks of realisations as one
compiled, batched call.

One realisation draws an input record from the spec's input design (`_inputs`; the
paper's is uniform in `(-A, A)`), simulates the cascade, adds the spec's output noise
(`_disturbance`; the paper's is white) at the cell's SNR, computes the record's
Cramér-Rao bound of that noise (`_efficiency.crlb`: for `ar` and `arma` noise the
coloured bound, the prediction-error Jacobian whitened; for white, Student-t and
outlier noise the bound of Gaussian noise of the same variance, the second-order bound
that least squares and `pem` can attain, `_efficiency.information_factor` saying how
much lower the heavy-tailed density's own is), fits it with the cell's estimator (given
the design's `input_range`), and scores the estimate on a fresh record (fresh input and
fresh noise of the same kinds): validation
`NRMSE = rms(y_val - simulate(estimate, u_val)) / std(y_val)`, `inf` when the estimate
is inadmissible (so a table never holds a NaN score).

A chunk of realisations of one cell runs as one jit-compiled, `vmap`-ed call
(`run_chunk`, a pure function of `(spec, cell, indices)`, so it can be shipped to a
worker). Chunks are padded to `spec.chunk_size`, so a cell compiles once.

**Keys.** Realisation `i` of a cell uses `fold_in(cell_key, i)`, where `cell_key` is
`PRNGKey(seed)` folded with a 64-bit hash of the cell's data identity: the true
parameters and orders, the input design, the noise, N and SNR (for the paper's uniform
input and white noise the text is the one written before input designs and noise kinds
existed, so the records of those sweeps are unchanged). Nothing else enters: not the
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
XLA's buffer sizes for a cell and chunk size. It does not grow with the number of
realisations, which run chunk after chunk: with the forms an accelerator compiles
(the parallel scans, XLA's normal equations; `Spec.chunk_size` 1000 there), a chunk of
1000 Example 1 records of N 4000 asks for 2.35 GiB (literal) and 2.43 GiB (robust), by
`chunk_memory` of those programs compiled for the CPU.
"""

from __future__ import annotations

import functools
import json
import threading
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._compile import compiler_options
from .._estimator import is_host
from .._estimator._efficiency import crlb, noise_bound_options
from .._estimator._normal_equations import resolve
from .._experiment._changing import simulate_changing, trajectory_traced
from .._metrics import nrmse
from .._system._model import CascadeParams, is_admissible
from .._system._prior import random_system
from .._system._simulate import add_noise, simulate
from ._spec import Cell, Spec, hash_words
from ._tables import realisation_frame
from ._tracking import tracking_samples


def cell_identity(spec: Spec, cell: Cell) -> str:
    """What a cell's records depend on (`Spec.cell_identity`)."""
    return spec.cell_identity(cell)


def cell_key(spec: Spec, cell: Cell):
    """The cell's key (`Spec.cell_key`): `PRNGKey(seed)` folded with the 64-bit hash of
    its identity."""
    return spec.cell_key(cell)


def _system_tag(family: str) -> np.uint32:
    return np.uint32(hash_words(f"system:{family}")[0])


def _draw(
    cell_key,
    index,
    truth_vector,
    snr,
    design_arrays,
    *,
    orders,
    n,
    design_static,
    noise,
    family,
    change=None,
):
    """One realisation's records: the input from the design, the noisy output, the
    record's Cramér-Rao bound of the cell's noise, and the fresh validation record of the
    same design and noise (module docstring). With a `change`, the output comes from the
    trajectory of true systems (`truths`, returned in place of the bound) and the
    validation record and `truth` from the system at the end. With a `family`,
    `truth_vector` only gives the dtype: the true system is drawn from the family's
    prior with a key folded from the realisation key. The input design arrives in two
    parts: its arrays (a measured record) as an argument, the rest closed over
    (`eqx.partition`), so no large constant is compiled into the program."""
    dtype = truth_vector.dtype
    design = eqx.combine(design_arrays, design_static)
    key = jax.random.fold_in(cell_key, index)
    if family is not None:
        system_key = jax.random.fold_in(key, _system_tag(family))
        truth_vector = random_system(system_key, orders, design.bound, dtype).to_vector()
    truth = CascadeParams.from_vector(truth_vector, orders, check=False)
    key_u, key_e, key_u_val, key_e_val = jax.random.split(key, 4)
    u = design(key_u, n, dtype)
    if change is None:
        y = add_noise(key_e, simulate(truth, u), snr, noise)
    else:  # the record from the trajectory; validation and truth: the system at the end
        truths = trajectory_traced(truth_vector, change, n, orders)
        y = add_noise(key_e, simulate_changing(truths, u, orders), snr, noise)
        truth_vector = truths[-1]
        truth = CascadeParams.from_vector(truth_vector, orders, check=False)
    u_val = design(key_u_val, n, dtype)
    y_val = add_noise(key_e_val, simulate(truth, u_val), snr, noise)
    low, high = design.input_range(u)
    input_rms = jnp.sqrt(jnp.mean(u**2))
    drawn = {
        "key": key,
        "u": u,
        "y": y,
        "u_val": u_val,
        "y_val": y_val,
        "truth": truth_vector,
        "input_low": jnp.asarray(low, dtype),
        "input_high": jnp.asarray(high, dtype),
        "input_rms": input_rms,
        "input_crest": jnp.max(jnp.abs(u)) / input_rms,
    }
    if change is None:
        # the record's own Cramér-Rao bound of its noise (noise-free: 0): coloured for
        # ar/arma noise, the Gaussian one of the noise's variance for white, Student-t
        # and outliers (`_efficiency`); none for a system that changes
        drawn["crlb"] = crlb(truth, u, snr=snr, **noise_bound_options(noise))
    else:
        drawn["truths"] = truths
    return drawn


def _score(estimate, truth_vector, u_val, y_val, input_range, *, orders):
    """Validation NRMSE of an estimate on the fresh record and whether it is admissible."""
    admissible = is_admissible(
        CascadeParams.from_vector(estimate, orders, check=False), *input_range
    )
    # An inadmissible estimate (unstable, unsorted breakpoints, ...) is not simulated:
    # its score is inf, and the truth stands in so no NaN is ever computed.
    safe = CascadeParams.from_vector(
        jnp.where(admissible, estimate, truth_vector), orders, check=False
    )
    error = nrmse(y_val, simulate(safe, u_val))
    return jnp.where(admissible & jnp.isfinite(error), error, jnp.inf), admissible


def _outputs(drawn, solution, estimate, error, admissible, every=None):
    key = drawn["key"]
    dtype = drawn["truth"].dtype
    out = {
        "key": jax.random.key_data(key) if _is_typed(key) else key,
        "estimate": estimate,
        "status": jnp.asarray(solution.status).astype(jnp.int32),
        "iterations": jnp.asarray(solution.iterations).astype(jnp.int32),
        "cost": jnp.asarray(solution.cost, dtype),
        "cycle_amplitude": jnp.asarray(solution.cycle_amplitude, dtype),
        "path": jnp.asarray(solution.path).astype(jnp.int32),
        "nrmse": error,
        "admissible": admissible,
        "truth": drawn["truth"],
        "input_rms": drawn["input_rms"],
        "input_crest": drawn["input_crest"],
    }
    if "crlb" in drawn:
        out["crlb"] = drawn["crlb"]
    else:  # a system that changes: the error at the samples the estimator recorded
        truths = drawn["truths"]
        samples = tracking_samples(truths.shape[0], every)
        out["track"] = solution.history[1:].astype(dtype) - truths[samples - 1]
    return out


def _realisation(
    cell_key,
    index,
    truth_vector,
    snr,
    design_arrays,
    *,
    orders,
    n,
    design_static,
    noise,
    fit,
    fit_key_tag,
    family,
    change=None,
):
    """One record: input, noisy output, fit, validation on a fresh record (`_draw`, the
    estimator, `_score`)."""
    drawn = _draw(
        cell_key,
        index,
        truth_vector,
        snr,
        design_arrays,
        orders=orders,
        n=n,
        design_static=design_static,
        noise=noise,
        family=family,
        change=change,
    )
    design = eqx.combine(design_arrays, design_static)
    input_range = design.input_range(drawn["u"])
    solution = fit(
        drawn["u"],
        drawn["y"],
        orders,
        key=jax.random.fold_in(drawn["key"], fit_key_tag),
        input_range=input_range,
    )
    estimate = solution.params.to_vector().astype(drawn["truth"].dtype)
    error, admissible = _score(
        estimate, drawn["truth"], drawn["u_val"], drawn["y_val"], input_range, orders=orders
    )
    every = None if change is None else fit.every
    return _outputs(drawn, solution, estimate, error, admissible, every)


def _is_typed(key) -> bool:
    return jnp.issubdtype(key.dtype, jax.dtypes.prng_key)


def _split(design):
    """An input design as (arrays, the rest): the arrays travel as arguments."""
    return eqx.partition(design, eqx.is_array)


@functools.lru_cache(maxsize=64)
def _compiled(orders, n, experiment, name, fit, batched, family=None, change=None):
    """The jitted (optionally vmapped) realisation function of one cell shape;
    `experiment` is `Spec.experiment` (input and noise, hashable), `fit` the estimator
    `name` with its settings (`Spec.fit`)."""
    design, noise = _parts(experiment, str(jnp.result_type(float)))
    one = functools.partial(
        _realisation,
        orders=orders,
        n=n,
        design_static=_split(design)[1],
        noise=noise,
        fit=fit,
        fit_key_tag=np.uint32(hash_words(f"estimator:{name}")[0]),
        family=family,
        change=change,
    )
    if batched:
        one = jax.vmap(one, in_axes=(None, 0, None, None, None))
    return jax.jit(one, compiler_options=compiler_options())


@functools.lru_cache(maxsize=16)
def _parts(experiment: tuple, dtype: str):
    """The input design and the noise of `Spec.experiment`, built in the default float
    `dtype` (a design's arrays are made in it). A file input rewritten since the spec
    read it is refused: its records would not be those of the cell's identity."""
    spec_input, input_settings, spec_noise, noise_settings, identity = experiment
    from .._experiment._disturbance import disturbance
    from .._experiment._inputs import input_design

    design = input_design(spec_input, **dict(input_settings))
    if json.dumps(design.identity(), sort_keys=True, default=str) != identity:
        raise ValueError(
            f"The {spec_input} input changed since the spec was made (its file was "
            "rewritten): make the spec again to run on the new file."
        )
    return design, disturbance(spec_noise, **dict(noise_settings))


def _arguments(spec: Spec, cell: Cell, dtype=None):
    dtype = dtype or jnp.result_type(float)
    arrays = _split(_parts(spec.experiment, str(jnp.result_type(float)))[0])[0]
    return spec.cell_key(cell), spec.true_vector(dtype), jnp.asarray(cell.snr, dtype), arrays


def _function(spec: Spec, cell: Cell, batched: bool):
    return _compiled(
        spec.orders,
        cell.n,
        spec.experiment,
        cell.estimator,
        spec.fit(cell.estimator),
        batched,
        spec.family,
        spec.change,
    )


# Ahead-of-time compiled chunk executables of this process, so that compiling is timed
# apart from computing. Keyed by everything the executable depends on.
_EXECUTABLES: dict = {}
_MAX_EXECUTABLES = 64
# Chunks running at once in threads (`Spec.workers`) compile a cell's program once: the
# second waits for the first's and finds it cached.
_COMPILING = threading.Lock()


def _executable(spec: Spec, cell: Cell, arguments) -> tuple:
    """(compiled batched function, seconds spent compiling it now: 0 if cached)."""
    key, indices, truth, snr, arrays = arguments
    cache_key = (
        spec.orders,
        cell.n,
        spec.experiment,
        cell.estimator,
        spec.fit(cell.estimator),
        spec.family,
        spec.change,
        indices.shape,
        str(truth.dtype),
        str(key.dtype),
        key.shape,
    )
    with _COMPILING:
        if cache_key in _EXECUTABLES:
            return _EXECUTABLES[cache_key], 0.0
        start = time.perf_counter()
        compiled = _function(spec, cell, batched=True).lower(*arguments).compile()
        seconds = time.perf_counter() - start
        if len(_EXECUTABLES) >= _MAX_EXECUTABLES:
            _EXECUTABLES.pop(next(iter(_EXECUTABLES)))
        _EXECUTABLES[cache_key] = compiled
    return compiled, seconds


@functools.lru_cache(maxsize=16)
def _host_programs(orders, n, experiment, family, change=None):
    """The batched draw and score of a cell shape whose estimator runs on the host (or
    whose records `records` returns)."""
    design, noise = _parts(experiment, str(jnp.result_type(float)))
    draw = functools.partial(
        _draw,
        orders=orders,
        n=n,
        design_static=_split(design)[1],
        noise=noise,
        family=family,
        change=change,
    )
    score = functools.partial(_score, orders=orders)
    options = compiler_options()
    return (
        jax.jit(jax.vmap(draw, in_axes=(None, 0, None, None, None)), compiler_options=options),
        jax.jit(jax.vmap(score), compiler_options=options),
    )


def _host_chunk(spec: Spec, cell: Cell, fit, indices: np.ndarray, size: int) -> dict:
    """Realisations `indices` with a host estimator (`_estimator._host`): the records are
    drawn and the estimates scored in compiled, batched calls (padded to `size`, so a
    cell compiles once), the fits run one record after another on the host, each timed
    (`fit_seconds` per row)."""
    experiment = spec.experiment
    draw, score = _host_programs(spec.orders, cell.n, experiment, spec.family, spec.change)
    padded = np.concatenate([indices, np.full(size - indices.size, indices[-1])])
    key, truth, snr, arrays = _arguments(spec, cell)
    arguments = (key, jnp.asarray(padded.astype(np.uint32)), truth, snr, arrays)
    shape = (spec.orders, cell.n, experiment, spec.family, spec.change, size)
    cache_key = ("host", *shape, str(truth.dtype))
    compile_seconds = 0.0
    if cache_key not in _EXECUTABLES:
        start = time.perf_counter()
        shapes = jax.eval_shape(draw, *arguments)
        estimate = jax.ShapeDtypeStruct(shapes["truth"].shape, truth.dtype)
        bounds = (shapes["input_low"], shapes["input_high"])
        _EXECUTABLES[cache_key] = (
            draw.lower(*arguments).compile(),
            score.lower(
                estimate, shapes["truth"], shapes["u_val"], shapes["y_val"], bounds
            ).compile(),
        )
        compile_seconds = time.perf_counter() - start
    draw, score = _EXECUTABLES[cache_key]
    drawn = {k: np.asarray(v) for k, v in jax.device_get(draw(*arguments)).items()}
    count = indices.size
    kinds = {"status": np.int32, "iterations": np.int32, "cost": float, "cycle_amplitude": float}
    fields = {name: np.zeros(count, kind) for name, kind in {**kinds, "path": np.int32}.items()}
    estimates = drawn["truth"].copy()  # padded rows: the truth stands in, never read
    seconds = np.zeros(count)
    for i in range(count):
        u, y = np.array(drawn["u"][i]), np.array(drawn["y"][i])  # the function's own copies
        start = time.perf_counter()
        vector = fit.vector(u, y, spec.orders)
        seconds[i] = time.perf_counter() - start
        solution = fit.solution(vector, drawn["u"][i], drawn["y"][i], spec.orders)
        estimates[i] = np.asarray(solution.params.to_vector(), np.float64)
        for name in fields:
            fields[name][i] = np.asarray(getattr(solution, name))
    bounds = (drawn["input_low"], drawn["input_high"])
    errors, admissible = jax.device_get(
        score(
            jnp.asarray(estimates, truth.dtype),
            drawn["truth"],
            drawn["u_val"],
            drawn["y_val"],
            bounds,
        )
    )
    key_data = drawn["key"] if drawn["key"].ndim == 2 else np.asarray(drawn["key"])
    return {
        "key": key_data[:count],
        "estimate": estimates[:count],
        **{name: values for name, values in fields.items()},
        "nrmse": np.asarray(errors)[:count],
        "admissible": np.asarray(admissible)[:count],
        "truth": drawn["truth"][:count],
        "crlb": drawn["crlb"][:count],
        "input_rms": drawn["input_rms"][:count],
        "input_crest": drawn["input_crest"][:count],
        "fit_seconds": seconds,
        "compile_seconds": compile_seconds,
    }


def records(spec: Spec, cell: Cell, indices) -> dict[str, np.ndarray]:
    """The records realisations `indices` of `cell` fit (`u`, `y`, one row each) and
    their validation records (`u_val`, `y_val`): the same for every estimator of a
    sweep, for checking a table's rows against direct fits."""
    indices = np.asarray(indices, np.int64)
    draw, _ = _host_programs(spec.orders, cell.n, spec.experiment, spec.family, spec.change)
    key, truth, snr, arrays = _arguments(spec, cell)
    drawn = jax.device_get(draw(key, jnp.asarray(indices.astype(np.uint32)), truth, snr, arrays))
    return {name: np.asarray(drawn[name]) for name in ("u", "y", "u_val", "y_val")}


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
    fit = spec.fit(cell.estimator)
    if is_host(fit):
        outputs = _host_chunk(spec, cell, fit, indices, size)
        outputs["key"] = _key_to_uint64(outputs["key"])
        frame = realisation_frame(spec, cell, indices, outputs)
        frame.attrs["normal_equations"] = normal_equations_backend(spec)
        return frame
    padded = np.concatenate([indices, np.full(size - indices.size, indices[-1])])
    key, truth, snr, arrays = _arguments(spec, cell)
    arguments = (key, jnp.asarray(padded.astype(np.uint32)), truth, snr, arrays)
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
    if is_host(spec.fit(cell.estimator)):
        out = _host_chunk(spec, cell, spec.fit(cell.estimator), np.asarray([index], np.int64), 1)
        out["key"] = _key_to_uint64(out["key"])
        return {k: np.asarray(v)[0] if np.ndim(v) else np.asarray(v) for k, v in out.items()}
    key, truth, snr, arrays = _arguments(spec, cell)
    function = _function(spec, cell, batched=False)
    out = jax.device_get(function(key, np.uint32(index), truth, snr, arrays))
    out = {k: np.asarray(v) for k, v in out.items()}
    out["key"] = _key_to_uint64(out["key"][None])[0]
    return out


def _key_to_uint64(words) -> np.ndarray:
    words = np.asarray(words).astype(np.uint64)
    return (words[:, 0] << np.uint64(32)) | words[:, 1]


def chunk_memory(spec: Spec, cell: Cell, chunk_size: int | None = None) -> dict[str, int]:
    """XLA's buffer sizes in bytes for one compiled chunk: temp, argument, output, total."""
    size = chunk_size or spec.chunk_size
    key, truth, snr, arrays = _arguments(spec, cell)
    indices = jnp.zeros((size,), jnp.uint32)
    if is_host(spec.fit(cell.estimator)):  # the compiled part is the draw (and the small score)
        experiment = spec.experiment
        program = _host_programs(spec.orders, cell.n, experiment, spec.family, spec.change)[0]
    else:
        program = _function(spec, cell, batched=True)
    compiled = program.lower(key, indices, truth, snr, arrays).compile()
    analysis = compiled.memory_analysis()
    sizes = {
        "temp": int(analysis.temp_size_in_bytes),
        "argument": int(analysis.argument_size_in_bytes),
        "output": int(analysis.output_size_in_bytes),
    }
    sizes["total"] = sum(sizes.values())
    return sizes
