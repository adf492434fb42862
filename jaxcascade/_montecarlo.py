"""Monte-Carlo sweeps: batched realisations over an N x SNR x estimator grid (issue 3).

One realisation draws an input record (uniform in `(-A, A)`), simulates the cascade,
adds output noise at the cell's SNR, fits it with the cell's estimator, and scores the
estimate on a fresh record (fresh input and fresh noise): validation
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

**Memory.** Peak memory of a chunk grows as `chunk_size x N` (each realisation holds a
few `N x P` regression matrices and signals of length N); `chunk_memory` reports
XLA's buffer sizes for a cell and chunk size.
"""

from __future__ import annotations

import functools
import hashlib
import json
import pathlib
import shutil
import time

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from ._estimators import estimator, takes
from ._metrics import nrmse
from ._model import CascadeParams, is_admissible
from ._prior import random_system
from ._simulate import add_noise, simulate, uniform_input
from ._spec import FAMILIES, Cell, Spec
from ._tables import CELL_COLUMNS, realisation_frame, run_metadata, write_table


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
        },
        sort_keys=True,
    )


def cell_key(spec: Spec, cell: Cell):
    """`PRNGKey(seed)` folded with the 64-bit hash of `cell_identity` (two 32-bit words)."""
    key = jax.random.PRNGKey(np.uint32(spec.seed))
    for word in _hash_words(cell_identity(spec, cell)):
        key = jax.random.fold_in(key, word)
    return key


def _system_tag(family: str) -> np.uint32:
    return np.uint32(_hash_words(f"system:{family}")[0])


def _realisation(
    cell_key, index, truth_vector, snr, *, orders, n, amplitude, fit, fit_key_tag, family
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
    y = add_noise(key_e, simulate(truth, u), snr)
    kwargs = {} if fit_key_tag is None else {"key": jax.random.fold_in(key, fit_key_tag)}
    solution = fit(u, y, orders, **kwargs)
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
    return {
        "key": jax.random.key_data(key) if _is_typed(key) else key,
        "estimate": estimate,
        "status": solution.status.astype(jnp.int32),
        "iterations": solution.iterations.astype(jnp.int32),
        "cost": jnp.asarray(solution.cost, dtype),
        "nrmse": error,
        "admissible": admissible,
        "truth": truth_vector,
    }


def _is_typed(key) -> bool:
    return jnp.issubdtype(key.dtype, jax.dtypes.prng_key)


@functools.lru_cache(maxsize=64)
def _compiled(orders, n, amplitude, name, settings, batched, family=None):
    """The jitted (optionally vmapped) realisation function of one cell shape."""
    fit = functools.partial(estimator(name), **dict(settings))
    if takes(name, "input_range"):
        fit = functools.partial(fit, input_range=(-amplitude, amplitude))
    tag = np.uint32(_hash_words(f"estimator:{name}")[0]) if takes(name, "key") else None
    one = functools.partial(
        _realisation,
        orders=orders,
        n=n,
        amplitude=amplitude,
        fit=fit,
        fit_key_tag=tag,
        family=family,
    )
    if batched:
        one = jax.vmap(one, in_axes=(None, 0, None, None))
    return jax.jit(one)


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
        spec.orders, cell.n, spec.amplitude, cell.estimator, settings, batched, spec.family
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
    """Realisations `indices` of `cell`, batched in one compiled call; one row each.

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
    return realisation_frame(spec, cell, indices, outputs)


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


# ---- resumable runs ---------------------------------------------------------------------


def _partial_folder(out: pathlib.Path) -> pathlib.Path:
    return out.with_name(out.name + ".partial")


def _identity(spec: Spec, dtype) -> dict:
    # What must match for a resumed run to continue the same experiment. The chunk size
    # may differ: it never changes a result.
    return {"spec": spec.to_dict(chunk_size=False), "dtype": str(np.dtype(dtype))}


def _check_same(stored: dict, expected: dict, where) -> None:
    if json.loads(json.dumps(stored)) != json.loads(json.dumps(expected)):
        raise ValueError(
            f"'{where}' was written by a different spec or dtype; use another --out "
            "or delete it to start afresh."
        )


def _done(folder: pathlib.Path) -> pd.DataFrame | None:
    files = sorted(folder.glob("chunk-*.parquet"))
    if not files:
        return None
    return pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)


def _ordered(spec: Spec, table: pd.DataFrame) -> pd.DataFrame:
    order = {(c.n, c.snr, c.estimator): i for i, c in enumerate(spec.cells())}
    rank = [order[k] for k in zip(table["n"], table["snr"], table["estimator"], strict=True)]
    table = table.assign(_cell=rank).drop_duplicates(["_cell", "realisation"])
    table = table.sort_values(["_cell", "realisation"], kind="stable").drop(columns="_cell")
    return table.reset_index(drop=True)


def _chunks(spec: Spec, done: pd.DataFrame | None):
    """(cell, indices) for every realisation not yet in `done`, in table order."""
    for cell in spec.cells():
        have = set()
        if done is not None:
            mask = (
                (done["n"] == cell.n)
                & (done["snr"] == cell.snr)
                & (done["estimator"] == cell.estimator)
            )
            have = set(done.loc[mask, "realisation"].tolist())
        missing = [i for i in range(spec.realisations) if i not in have]
        for start in range(0, len(missing), spec.chunk_size):
            yield cell, missing[start : start + spec.chunk_size]


def run(
    spec: Spec, out=None, *, resume: bool = False, progress: bool | None = None, command=None
) -> pd.DataFrame:
    """Run every cell of `spec`; returns the realisation table (rows in `spec.cells()` order).

    With `out` (a `.parquet` path) every chunk is written to `OUT.partial/` as it
    finishes, and merged into `out` (with metadata) at the end. If `OUT.partial/` exists
    the run continues it (its spec and dtype must match); an existing complete `out` is
    an error unless `resume`, which reuses it. `progress=None` shows a bar on a terminal.

    With `spec.scheduler` the chunks run on that Dask cluster (`_distributed`), arriving
    in any order; the table is the same as in this process.
    """
    from tqdm.auto import tqdm

    dtype = jnp.result_type(float)
    total = spec.realisations * len(spec.cells())
    if out is None:
        chunks = list(_chunks(spec, None))
        with tqdm(total=total, unit="realisation", disable=_disable(progress)) as bar:
            frames = []
            for _, indices, frame in _results(spec, chunks, dtype):
                frames.append(frame)
                bar.update(len(indices))
        return _ordered(spec, pd.concat(frames, ignore_index=True))

    from ._tables import read_metadata

    out = pathlib.Path(out)
    folder = _partial_folder(out)
    identity = _identity(spec, dtype)
    stamp = folder / "spec.json"
    if folder.exists() and stamp.exists():
        _check_same(json.loads(stamp.read_text()), identity, folder)
    elif out.exists():
        if not resume:
            raise ValueError(f"'{out}' already exists; pass --resume to reuse it or delete it.")
        meta = read_metadata(out)
        _check_same(
            {"spec": _without_chunk(meta.get("spec")), "dtype": meta.get("dtype")}, identity, out
        )
        return pd.read_parquet(out)
    else:
        folder.mkdir(parents=True, exist_ok=True)
        temporary = stamp.with_suffix(".tmp")
        temporary.write_text(json.dumps(identity, sort_keys=True))
        temporary.replace(stamp)

    done = _done(folder)
    initial = 0 if done is None else len(done)
    with tqdm(total=total, initial=initial, unit="realisation", disable=_disable(progress)) as bar:
        for cell, indices, frame in _results(spec, list(_chunks(spec, done)), dtype):
            # repr(snr) is exact, so two SNRs never share a file name.
            name = f"chunk-n{cell.n}-snr{cell.snr!r}-{cell.estimator}-{indices[0]:09d}.parquet"
            write_table(frame, folder / name, {})
            bar.update(len(indices))

    table = _ordered(spec, _done(folder))
    if len(table) != total:  # never write a table with realisations missing
        raise RuntimeError(f"'{folder}' holds {len(table)} of {total} realisations.")
    write_table(table, out, run_metadata(spec, dtype, command))
    shutil.rmtree(folder)
    return pd.read_parquet(out)


def _results(spec: Spec, chunks: list, dtype):
    """`(cell, indices, frame)` for every chunk, in this process or on the Dask cluster."""
    if spec.scheduler is None:
        return ((cell, indices, run_chunk(spec, cell, indices)) for cell, indices in chunks)
    from ._distributed import distributed_chunks  # imports dask only when asked for

    return distributed_chunks(spec, chunks, dtype)


def _without_chunk(spec_dict):
    if not isinstance(spec_dict, dict):
        return spec_dict
    return {k: v for k, v in spec_dict.items() if k not in ("chunk_size", "scheduler")}


def _disable(progress):
    return None if progress is None else not progress


def summary_path(out) -> pathlib.Path:
    """`NAME.parquet` -> `NAME.summary.csv`."""
    out = pathlib.Path(out)
    return out.with_name(out.name.removesuffix(".parquet") + ".summary.csv")


# ---- command line -----------------------------------------------------------------------


def _list(kind, option):
    def parse(text: str):
        from ._cli import CLIError

        try:
            values = [kind(part) for part in text.split(",") if part.strip()]
        except ValueError:
            raise CLIError(f"{option} takes comma-separated numbers, got {text!r}.") from None
        if not values:
            raise CLIError(f"{option} needs at least one value.")
        return values

    return parse


def _names(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def spec_from_args(args) -> Spec:
    """The spec of a `sweep` command line: a TOML file, overridden by the options given."""
    from ._cli import CLIError

    data = {}
    if args.spec is not None:
        path = pathlib.Path(args.spec)
        if not path.is_file():
            raise CLIError(f"spec file '{path}' does not exist.")
        import tomllib

        try:
            data = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as error:
            raise ValueError(f"Spec file '{path}' is not valid TOML: {error}.") from None
    elif args.example is None and args.system is None:
        raise CLIError("give a spec file, --example or --system (see 'jaxcascade sweep --help').")
    if args.example is not None and args.system is not None:
        raise CLIError("give either --example or --system, not both.")
    if args.example is not None:
        data.pop("system", None)
        data["example"] = args.example
    if args.system is not None:
        data.pop("example", None)
        data["system"] = {"family": args.system}
    if args.orders is not None:
        if "example" in data:
            raise CLIError("--orders needs a family or explicit system; an example has its own.")
        system = data.get("system", {})
        system = {"family": system} if isinstance(system, str) else dict(system)
        data["system"] = {**system, "orders": args.orders}
    for field, value in (
        ("n", args.n),
        ("snr", args.snr),
        ("realisations", args.realisations),
        ("seed", args.seed),
        ("estimators", args.estimator),
        ("chunk_size", args.chunk_size),
        ("scheduler", args.scheduler),
    ):
        if value is not None:
            data[field] = value
    if args.amplitude is not None:
        data.setdefault("input", {})
        data["input"] = {**data["input"], "amplitude": args.amplitude}
    return Spec.from_dict(data)


def _print_cells(summary: pd.DataFrame) -> None:
    cells = summary.drop_duplicates(CELL_COLUMNS)
    columns = [*CELL_COLUMNS, "count", "used", "converged_rate", "recovered_rate", "nrmse_median"]
    print(cells[columns].to_string(index=False, float_format=lambda v: f"{v:.4g}"))


def sweep(args) -> int:
    from ._cli import CLIError, writable_folder
    from ._tables import compare, read_summary, summarise

    spec = spec_from_args(args)
    if args.out is None:
        if args.spec is None:
            raise CLIError("--out is required without a spec file (e.g. results/NAME.parquet).")
        args.out = str(pathlib.Path("results") / (pathlib.Path(args.spec).stem + ".parquet"))
    out = pathlib.Path(args.out)
    if out.suffix != ".parquet":
        raise CLIError(f"--out must name a .parquet file, got '{out}'.")
    baseline = read_summary(args.compare) if args.compare else None
    writable_folder(out.parent)
    if args.plots:
        writable_folder(args.plots)

    import sys

    table = run(spec, out, resume=args.resume, progress=None, command=["jaxcascade", *sys.argv[1:]])
    summary = summarise(table)
    summary.to_csv(summary_path(out), index=False)
    _print_cells(summary)
    print(f"written: {out}, {summary_path(out)}")
    if args.plots:
        from ._plot import plot_sweep

        paths = plot_sweep(summary, table, args.plots, out.name.removesuffix(".parquet"))
        print(f"plots: {', '.join(str(p) for p in paths)}")
    if baseline is not None:
        result = compare(summary, baseline, args.threshold)
        flagged = result[result["flagged"]]
        checked = len(result)
        if flagged.empty:
            print(f"compare: no bias or std moved beyond Monte-Carlo error ({checked} checked).")
            return 0
        print(f"compare: {len(flagged)} of {checked} statistics moved beyond Monte-Carlo error:")
        columns = [*CELL_COLUMNS, "parameter", "statistic", "value", "baseline", "diff", "se", "z"]
        print(flagged[columns].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
        return 1
    return 0


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "sweep",
        help="Monte-Carlo sweep over SNR x N x estimator with bias/std/convergence tables",
        description=(
            "Run a Monte-Carlo sweep from a TOML spec or from options (options override "
            "the spec file). Writes OUT (one row per realisation, Parquet) and "
            "OUT.summary.csv; a killed run continues when started again."
        ),
    )
    parser.add_argument("spec", nargs="?", help="TOML spec file (see jaxcascade._spec)")
    parser.add_argument("--example", type=int, help="paper example, 1 or 2")
    parser.add_argument(
        "--system",
        choices=FAMILIES,
        help="a family of systems: 'random' draws each realisation's system from the "
        "documented prior (default N 3000, SNR 30)",
    )
    parser.add_argument("--orders", help="nR,nL,r,p of a family (default 2,2,2,2)")
    parser.add_argument(
        "--snr", type=_list(float, "--snr"), help="e.g. 10,25,50 (inf = noise-free)"
    )
    parser.add_argument("--n", type=_list(int, "--n"), help="sample sizes, e.g. 500,1000,4000")
    parser.add_argument("--realisations", type=int, help="records per grid cell")
    parser.add_argument("--seed", type=int, help="sweep seed (default 0)")
    parser.add_argument("--estimator", type=_names, help="e.g. literal or literal,robust")
    parser.add_argument("--amplitude", type=float, help="input uniform in (-A, A) (default 2)")
    parser.add_argument("--chunk-size", type=int, help="realisations per compiled batch")
    parser.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="run the chunks on this Dask scheduler's workers (pip install "
        "'jaxcascade[distributed]'); the default runs them in this process",
    )
    parser.add_argument("--out", help="results/NAME.parquet (default results/SPEC.parquet)")
    parser.add_argument(
        "--resume", action="store_true", help="reuse a finished OUT (a killed run continues anyway)"
    )
    parser.add_argument("--compare", metavar="BASELINE", help="baseline summary to compare with")
    parser.add_argument(
        "--threshold", type=float, default=3.0, help="flag |diff| > T * combined MC error (3)"
    )
    parser.add_argument("--plots", metavar="DIR", help="write bias/RMSE/rate plots to DIR")
    parser.set_defaults(func=sweep)
