"""Dask distributed backend of the Monte-Carlo engine (issue 7).

`jaxcascade sweep ... --scheduler tcp://HOST:PORT` (or `scheduler = "..."` in a spec
file) sends every chunk of realisations to the workers of a running Dask cluster. A
chunk is `run_chunk(spec, cell, indices)`, a pure function of its arguments, so where
it runs never changes its rows: the table equals the in-process run's exactly (only the
timing columns differ). Results are gathered with `as_completed` and handed back as they
arrive, so the engine writes each chunk to `OUT.partial/` at once and the run stays
resumable. When a worker dies, the scheduler recomputes its unfinished chunks on the
others; a chunk never arrives twice here (and a chunk file is written whole or not at
all, under a name fixed by the chunk, so a repeat would only rewrite it).

Workers compute in the caller's float dtype: the task sets `jax_enable_x64` itself
(a worker process does not run the CLI), and every chunk reports its dtype and a
fingerprint of the worker's jaxcascade source (version and a hash of its `.py` files,
taken when this module is imported), which must match the caller's: a worker started
from another version, or after the package was edited, would silently mix results.

An estimator registered in the caller's process (`register_estimator`, or an entry
point installed there only) travels with every chunk and is registered on the worker
before the chunk runs. A host function defined in a script or notebook goes by value
(Dask pickles what lives in `__main__` with cloudpickle); a function or `Estimator`
class defined in a module goes by reference (that module must be importable on the
workers). An `Estimator` class defined in the script itself is refused before anything
runs: an equinox class sent by value cannot be instantiated again (its fields are
frozen on the rebuilt class: equinox 0.13, cloudpickle 3.1).

This module is imported only when a scheduler is given; the package never needs Dask.
"""

from __future__ import annotations

import hashlib
import pathlib
import uuid
from collections.abc import Iterable, Iterator

import numpy as np
import pandas as pd

from .._version import __version__
from ._engine import run_chunk
from ._spec import Cell, Spec

_INSTALL = "install jaxcascade[distributed] (pip install 'jaxcascade[distributed]')"


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ValueError(
            f"--scheduler needs Dask distributed, which is missing: {_INSTALL}."
        ) from None
    return distributed


def _fingerprint() -> str:
    root = pathlib.Path(__file__).resolve().parent.parent  # the package
    digest = hashlib.blake2b(digest_size=8)
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return f"{__version__}+{digest.hexdigest()}"


# Taken at import, as close as we get to when the package's code was loaded.
FINGERPRINT = _fingerprint()


def outside_estimators(spec: Spec) -> dict:
    """The registry's entries for the spec's estimators that are not jaxcascade's own
    (module docstring; the spec's construction looked every name up already). A
    `ValueError` for an `Estimator` class defined in `__main__`."""
    from .._estimator import BUILTIN, ESTIMATORS

    out = {name: ESTIMATORS[name] for name in spec.estimators if name not in BUILTIN}
    for name, entry in out.items():
        if isinstance(entry, type) and entry.__module__ == "__main__":
            raise ValueError(
                f"Estimator {name!r} is an Estimator class defined in the running script; "
                "Dask workers cannot rebuild an equinox class sent by value: define it in "
                "a module the workers can import, or name it in the entry-point group "
                "jaxcascade.estimators."
            )
    return out


def chunk_task(
    spec: Spec, cell: Cell, indices: list[int], dtype: str, outside: dict | None = None
) -> tuple[str, str, pd.DataFrame]:
    """Run on a worker: one chunk in `dtype`, with the caller's `outside` estimators
    registered first; returns `(dtype, fingerprint, rows)`."""
    import jax
    import jax.numpy as jnp

    from .._estimator import ESTIMATORS

    ESTIMATORS.update(outside or {})
    jax.config.update("jax_enable_x64", dtype == "float64")
    frame = run_chunk(spec, cell, indices)
    return str(np.dtype(jnp.result_type(float))), FINGERPRINT, frame


def distributed_chunks(
    spec: Spec, chunks: Iterable[tuple[Cell, list[int]]], dtype, *, connect_timeout: float = 30.0
) -> Iterator[tuple[Cell, list[int], pd.DataFrame]]:
    """`(cell, indices, rows)` of every chunk, computed on `spec.scheduler`'s workers.

    Chunks arrive in the order they finish. Closing the iterator early (an error while
    writing, Ctrl-C) closes the client, which cancels the chunks not yet done.
    """
    distributed = _distributed()
    outside = outside_estimators(spec)
    dtype = str(np.dtype(dtype))
    try:
        client = distributed.Client(
            spec.scheduler, timeout=f"{connect_timeout}s", set_as_default=False
        )
    except (OSError, TimeoutError) as error:
        raise OSError(
            f"cannot reach the Dask scheduler at {spec.scheduler} ({error}); is "
            "'dask scheduler' running there?"
        ) from None
    with client:
        futures = {}
        for cell, indices in chunks:
            indices = [int(i) for i in indices]
            key = (
                f"jaxcascade-chunk-n{cell.n}-snr{cell.snr!r}-{cell.estimator}-"
                f"{indices[0]}-{uuid.uuid4().hex[:8]}"
            )
            future = client.submit(
                chunk_task, spec, cell, indices, dtype, outside, key=key, pure=False
            )
            futures[future] = (cell, indices)
        for future in distributed.as_completed(list(futures), loop=client.loop):
            cell, indices = futures.pop(future)
            worker_dtype, fingerprint, frame = future.result()
            future.release()
            if worker_dtype != dtype:
                raise RuntimeError(
                    f"A Dask worker computed in {worker_dtype}, this run in {dtype}."
                )
            if fingerprint != FINGERPRINT:
                raise RuntimeError(
                    f"A Dask worker runs other jaxcascade code ({fingerprint}) than this "
                    f"process ({FINGERPRINT}); install the same version on every machine "
                    "and restart the workers after changing the package."
                )
            yield cell, indices, frame
