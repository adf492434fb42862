"""Issue 7: sweep throughput in-process versus on a local Dask cluster of 1 and 2 workers,
and in-process with chunks in host threads (`Spec.workers`, `jaxcascade sweep --workers`).

    python benchmarks/distributed_throughput.py [--realisations 2048] [--n 2000]
        [--chunk-size 64] [--workers 1,2] [--threads 2] [--out results/distributed_throughput.csv]

Fixed workload: the literal iteration on Example 1 at SNR 25 (`jaxcascade sweep`'s
engine, `_montecarlo.run`, without writing files), float64. Each mode is first warmed
up, so every process has compiled the chunk before the clock starts (`warmup_s`: the
time that took, compilation included); `seconds` then covers the whole sweep, shipping
the rows back and assembling the table included. The Dask cluster is a `LocalCluster`
of worker processes with one thread each on loopback; XLA uses every core of the
machine in each process, so on a small machine workers compete for the same cores.

Columns: mode (`in-process`, `in-process threads`: `--threads` chunks at once, or
`dask`), workers (Dask workers, or the threads), realisations, n, chunk_size, seconds,
realisations_per_s, speedup (over in-process), warmup_s, cpu_count, device.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import pathlib
import sys
import time


def _spec(realisations: int, n: int, chunk_size: int):
    from jaxcascade._montecarlo._spec import Spec

    return Spec(
        example=1,
        n=n,
        snr=25.0,
        realisations=realisations,
        estimators=("literal",),
        chunk_size=chunk_size,
    )


def in_process(spec, threads: int = 1) -> dict:
    from jaxcascade._montecarlo._engine import run_chunk
    from jaxcascade._montecarlo._run import run

    start = time.perf_counter()
    run_chunk(spec, spec.cells()[0], [0])
    warmup = time.perf_counter() - start
    start = time.perf_counter()
    table = run(dataclasses.replace(spec, workers=threads), progress=False)
    seconds = time.perf_counter() - start
    assert len(table) == spec.realisations
    if threads > 1:
        return {"mode": "in-process threads", "workers": threads, "seconds": seconds,
                "warmup_s": warmup}  # fmt: skip
    return {"mode": "in-process", "workers": 0, "seconds": seconds, "warmup_s": warmup}


def on_cluster(spec, workers: int) -> dict:
    import distributed

    from jaxcascade._montecarlo._distributed import chunk_task
    from jaxcascade._montecarlo._run import run

    with (
        distributed.LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        ) as cluster,
        distributed.Client(cluster, set_as_default=False) as client,
    ):
        client.wait_for_workers(workers, timeout=120)
        start = time.perf_counter()
        cell = spec.cells()[0]
        warm = [
            client.submit(chunk_task, spec, cell, [0], "float64", workers=[w], pure=False)
            for w in client.scheduler_info()["workers"]
        ]
        client.gather(warm)
        warmup = time.perf_counter() - start
        remote = dataclasses.replace(spec, scheduler=cluster.scheduler_address)
        start = time.perf_counter()
        table = run(remote, progress=False)
        seconds = time.perf_counter() - start
    assert len(table) == spec.realisations
    return {"mode": "dask", "workers": workers, "seconds": seconds, "warmup_s": warmup}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realisations", type=int, default=2048)
    parser.add_argument("--n", type=int, default=2000)
    parser.add_argument("--chunk-size", type=int, default=64)
    parser.add_argument("--workers", default="1,2", help="comma-separated worker counts")
    parser.add_argument(
        "--threads", type=int, default=2, help="in-process chunks at once (1: no such row)"
    )
    parser.add_argument("--out", default="results/distributed_throughput.csv")
    args = parser.parse_args(argv)

    from jaxcascade._cli import enable_float64

    enable_float64()

    import pandas as pd

    from jaxcascade._benchmark._timing import device_description

    spec = _spec(args.realisations, args.n, args.chunk_size)
    rows = [in_process(spec)]
    if args.threads > 1:
        rows.append(in_process(spec, args.threads))
    for workers in [int(w) for w in args.workers.split(",") if w.strip()]:
        rows.append(on_cluster(spec, workers))
    table = pd.DataFrame(rows)
    table.insert(2, "realisations", args.realisations)
    table.insert(3, "n", args.n)
    table.insert(4, "chunk_size", args.chunk_size)
    table["realisations_per_s"] = args.realisations / table["seconds"]
    table["speedup"] = table["realisations_per_s"] / table["realisations_per_s"].iloc[0]
    table["cpu_count"] = os.cpu_count()
    table["device"] = device_description()
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False)
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(f"written: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
