"""Running a sweep: every cell's realisations, chunk by chunk, written as they finish and
resumable after a crash.

With an output path every chunk is written to `OUT.partial/` as it finishes (atomically,
under a name fixed by the chunk) and merged into `OUT` with its provenance at the end; a
killed run continues from the chunks on disk. With `Spec.scheduler` the chunks run on a
Dask cluster (`_distributed`, imported only then).
"""

from __future__ import annotations

import json
import pathlib
import shutil
import warnings

import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._estimator import is_host
from ._engine import run_chunk
from ._spec import Spec
from ._tables import read_metadata, run_metadata, summarise, write_table


def _partial_folder(out: pathlib.Path) -> pathlib.Path:
    return out.with_name(out.name + ".partial")


def _identity(spec: Spec, dtype) -> dict:
    # What must match for a resumed run to continue the same experiment. The chunk size
    # may differ: it never changes a result. A file input adds its contents' hash.
    identity = {"spec": spec.to_dict(chunk_size=False), "dtype": str(np.dtype(dtype))}
    design = spec.input_design()
    if "sha256" in design.identity():
        identity["input_sha256"] = design.identity()["sha256"]
    return identity


def _normalised(identity: dict) -> dict:
    """A stored identity in today's layout: its spec read back through `Spec`, so that
    one written before input designs (`distribution = "uniform"`, no noise) matches."""
    if not isinstance(identity, dict) or not isinstance(identity.get("spec"), dict):
        return identity
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            spec = Spec.from_dict(identity["spec"]).to_dict(chunk_size=False)
    except (ValueError, TypeError):
        return identity
    return {**identity, "spec": spec}


def _check_same(stored: dict, expected: dict, where) -> None:
    stored = _normalised(json.loads(json.dumps(stored)))
    if stored != json.loads(json.dumps(expected)):
        raise ValueError(
            f"'{where}' was written by a different spec or dtype; use another --out "
            "or delete it to start afresh."
        )


def _same(stamp: pathlib.Path, identity: dict) -> bool:
    try:
        _check_same(json.loads(stamp.read_text()), identity, stamp)
    except (OSError, ValueError):
        return False
    return True


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
    spec: Spec,
    out=None,
    *,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool | None = None,
    command=None,
) -> pd.DataFrame:
    """Run every cell of `spec`; returns the realisation table (rows in `spec.cells()` order).

    With `out` (a `.parquet` path) every chunk is written to `OUT.partial/` as it
    finishes, and merged into `out` (with metadata) at the end. If `OUT.partial/` exists
    the run continues it (its spec and dtype must match); an existing complete `out` is
    an error unless `resume`, which reuses it, or `overwrite`, which deletes it (and an
    `OUT.partial/` of another spec) and runs afresh; an `OUT.partial/` of the same spec is
    continued either way. `progress=None` shows a bar on a terminal.

    With `out` the summary (`summarise`) is written beside it, `NAME.summary.csv`
    (`summary_path`), as `jaxcascade sweep` writes it.

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

    if resume and overwrite:
        raise ValueError("give either --resume or --overwrite, not both.")
    out = pathlib.Path(out)
    folder = _partial_folder(out)
    identity = _identity(spec, dtype)
    stamp = folder / "spec.json"
    if overwrite:
        out.unlink(missing_ok=True)
        if folder.exists() and not _same(stamp, identity):
            shutil.rmtree(folder)
    if folder.exists() and stamp.exists():
        _check_same(json.loads(stamp.read_text()), identity, folder)
    elif out.exists():
        if not resume:
            raise ValueError(
                f"'{out}' already exists; pass --resume to reuse it, --overwrite to replace "
                "it, or delete it."
            )
        meta = read_metadata(out)
        stored = {"spec": _without_chunk(meta.get("spec")), "dtype": meta.get("dtype")}
        if "input_sha256" in meta:
            stored["input_sha256"] = meta["input_sha256"]
        _check_same(stored, identity, out)
        table = pd.read_parquet(out)
        if not summary_path(out).exists():
            summarise(table).to_csv(summary_path(out), index=False)
        return table
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
            backend = frame.attrs.get("normal_equations")
            write_table(frame, folder / name, {"normal_equations": backend})
            bar.update(len(indices))

    table = _ordered(spec, _done(folder))
    if len(table) != total:  # never write a table with realisations missing
        raise RuntimeError(f"'{folder}' holds {len(table)} of {total} realisations.")
    metadata = run_metadata(spec, dtype, _backends(folder), command)
    if "input_sha256" in identity:
        metadata["input_sha256"] = identity["input_sha256"]
    write_table(table, out, metadata)
    shutil.rmtree(folder)
    table = pd.read_parquet(out)
    summarise(table).to_csv(summary_path(out), index=False)
    return table


def _backends(folder: pathlib.Path) -> str:
    """How the chunks in `folder` formed their normal equations (`fused`, `xla`, or both
    joined by `+` when a resumed run changed machines)."""
    found = {read_metadata(path).get("normal_equations") for path in folder.glob("chunk-*")}
    return "+".join(sorted(str(b) for b in found if b)) or "unknown"


def _results(spec: Spec, chunks: list, dtype):
    """`(cell, indices, frame)` for every chunk, in this process (`spec.workers` at once)
    or on the Dask cluster."""
    if spec.scheduler is not None:
        from ._distributed import distributed_chunks  # imports dask only when asked for

        return distributed_chunks(spec, chunks, dtype)
    if spec.workers > 1 and not any(is_host(spec.fit(cell.estimator)) for cell in spec.cells()):
        return _in_threads(spec, chunks, spec.workers)
    return ((cell, indices, run_chunk(spec, cell, indices)) for cell, indices in chunks)


def _in_threads(spec: Spec, chunks: list, workers: int):
    """`(cell, indices, frame)` as chunks finish, `workers` of them running at once, each
    in its own host thread (JAX releases the GIL while a compiled program runs). A
    chunk's rows do not depend on what runs beside it; a chunk that fails stops the run
    once the chunks already running have finished (those are yielded, so written)."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    pending = iter(chunks)
    with ThreadPoolExecutor(workers, thread_name_prefix="jaxcascade-chunk") as pool:
        running = {}

        def submit():
            for cell, indices in pending:
                running[pool.submit(run_chunk, spec, cell, indices)] = (cell, indices)
                return

        for _ in range(workers):
            submit()
        failed = None
        while running:
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                cell, indices = running.pop(future)
                if future.exception() is not None:
                    failed = failed or future.exception()
                    continue
                yield cell, indices, future.result()
                if failed is None:
                    submit()
        if failed is not None:
            raise failed


def _without_chunk(spec_dict):
    if not isinstance(spec_dict, dict):
        return spec_dict
    return {k: v for k, v in spec_dict.items() if k not in ("chunk_size", "workers", "scheduler")}


def _disable(progress):
    return None if progress is None else not progress


def summary_path(out) -> pathlib.Path:
    """`NAME.parquet` -> `NAME.summary.csv`."""
    out = pathlib.Path(out)
    return out.with_name(out.name.removesuffix(".parquet") + ".summary.csv")
