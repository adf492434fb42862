"""Batching over realisations: `vmap` in cache-sized micro-batches.

A plain `vmap` over hundreds of realisations makes XLA materialise every intermediate
(regressor matrices, Gram products) for the whole batch at once, which runs from main
memory; measured on the 2-core CPU, one estimator step over 1000 realisations took
about 4x longer as one `vmap` than as `lax.map` over micro-batches of 25. This wraps a
one-realisation function accordingly (`chunked_vmap`), and spreads a batch over the
host's cores (`host_threads`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def chunked_vmap(fn, micro_batch: int, in_axes=0):
    """Like `jax.vmap(fn, in_axes)`, evaluated as `lax.map` over micro-batches.

    The batch is split into the fewest micro-batches of at most `micro_batch` elements,
    all of one size (one compilation), padded by repeating its last element (results
    for the padding are dropped): 300 elements in micro-batches of at most 256 run as 2
    of 150, not as 2 of 256.
    """
    batched = jax.vmap(fn, in_axes=in_axes)

    def wrapper(*args):
        axes = in_axes if isinstance(in_axes, tuple | list) else (in_axes,) * len(args)
        mapped = [a for a, axis in zip(args, axes, strict=True) if axis is not None]
        size = jax.tree_util.tree_leaves(mapped)[0].shape[0]
        count = -(-size // max(1, min(micro_batch, size)))
        chunk = -(-size // count)  # at most `micro_batch`, with the least padding
        pad = count * chunk - size

        def split(leaf):
            if pad:
                leaf = jnp.concatenate([leaf, jnp.repeat(leaf[-1:], pad, axis=0)])
            return leaf.reshape((count, chunk) + leaf.shape[1:])

        stacked = [
            jax.tree_util.tree_map(split, a) if axis is not None else None
            for a, axis in zip(args, axes, strict=True)
        ]

        def body(chunk_args):
            it = iter(chunk_args)
            full = [next(it) if axis is not None else a for a, axis in zip(args, axes, strict=True)]
            return batched(*full)

        out = jax.lax.map(body, [s for s in stacked if s is not None])
        return jax.tree_util.tree_map(
            lambda leaf: leaf.reshape((count * chunk,) + leaf.shape[2:])[:size], out
        )

    return wrapper


def host_workers() -> int:
    """The cores this process may run on (`os.sched_getaffinity`, else `os.cpu_count`)."""
    import os

    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def split_batch(batched, parts: int):
    """The leading axis of every leaf of `batched` split into `parts` parts of one size,
    padded by repeating the last element (as `chunked_vmap` pads): `(pieces, size)`."""
    leaves = jax.tree_util.tree_leaves(batched)
    size = leaves[0].shape[0]
    parts = max(1, min(parts, size))
    part = -(-size // parts)
    pad = parts * part - size

    def piece(leaf, i):
        if pad:
            leaf = jnp.concatenate([leaf, jnp.repeat(leaf[-1:], pad, axis=0)])
        return leaf[i * part : (i + 1) * part]

    pieces = [
        jax.tree_util.tree_map(lambda leaf, i=i: piece(leaf, i), batched) for i in range(parts)
    ]
    return pieces, size


def host_threads(fn, workers: int | None = None):
    """`fn(batched, *shared)` over the batch split into `workers` equal parts, each part
    run in its own host thread, the results concatenated in order (padding dropped).

    Why: XLA runs one program's sequential parts (`lax.scan` over time, the iteration's
    `while_loop`) in one thread, so a batched Monte-Carlo fit used about 1.25 of this
    machine's 2 cores. JAX releases the GIL while a compiled program runs, so parts
    dispatched from several threads run at once, one per core. `fn` is a jitted or
    AOT-compiled function of one part's shape (`split_batch` gives it). Each record's
    result does not depend on the other records, so the results equal one call over
    the whole batch: bit for bit where XLA sees the same shapes (a `chunked_vmap` whose
    micro-batches have the same size in a part as in the whole, as in the bench's 1000
    realisations in 4 or 2 x 2 micro-batches of 250), else to rounding (a batched
    matrix product may sum in another order for another batch size: 1e-12 measured on
    the bench's estimates at 600 realisations). Default `workers`: `host_workers()`.
    """
    from concurrent.futures import ThreadPoolExecutor

    workers = workers or host_workers()

    def wrapper(batched, *shared):
        pieces, size = split_batch(batched, workers)
        if len(pieces) == 1:
            return fn(pieces[0], *shared)
        with ThreadPoolExecutor(len(pieces)) as pool:
            outs = list(pool.map(lambda p: jax.block_until_ready(fn(p, *shared)), pieces))
        return jax.tree_util.tree_map(lambda *leaves: jnp.concatenate(leaves)[:size], *outs)

    return wrapper
