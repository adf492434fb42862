"""Time and peak memory of jaxcascade's batched fit versus realisations and versus N.

    python benchmarks/scaling.py [--realisations 100,300,1000,3000,10000]
        [--n 500,1000,2000,4000,8000,16000] [--fixed-n 4000] [--fixed-realisations 1000]
        [--iterations 20] [--out results/scaling.csv] [--plot results/scaling.png]

Two sweeps of the benchmark workload (Example 1, SNR 25, fixed iterations, simulation
included): realisations at N = --fixed-n, and N at --fixed-realisations realisations.
Each point runs in a fresh process, so its peak RSS is its own; `base_mem_mb` is that
process's RSS after imports, before any compilation. A point that fails (out of memory,
timeout) is recorded with its error instead of stopping the sweep.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys

_POINT = """
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
from jaxcascade._benchmark._timing import device_description, peak_rss_mb, run_jax
base = peak_rss_mb()
realisations, n, iterations, repeats = map(int, sys.argv[1:])
result = run_jax(realisations, n, iterations, repeats=repeats)
result.update(base_mem_mb=base, device=device_description())
print(json.dumps(result))
"""

COLUMNS = [
    "sweep",
    "realisations",
    "n",
    "iterations",
    "fits_per_s",
    "run_s",
    "compile_s",
    "peak_mem_mb",
    "base_mem_mb",
    "device",
    "error",
]


def _ints(text: str) -> list[int]:
    return [int(part) for part in text.split(",") if part.strip()]


def run_point(realisations: int, n: int, iterations: int, repeats: int, timeout: float) -> dict:
    """One point in a fresh Python process; returns its figures or `{"error": ...}`."""
    command = [sys.executable, "-c", _POINT, str(realisations), str(n), str(iterations)]
    try:
        done = subprocess.run(
            command + [str(repeats)], capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        return {"error": f"timeout after {timeout:g} s"}
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines() or [f"exit code {done.returncode}"]
        return {"error": f"exit code {done.returncode}: {lines[-1]}"}
    return json.loads(done.stdout.strip().splitlines()[-1])


def sweep(args) -> list[dict]:
    points = [("realisations", r, args.fixed_n) for r in _ints(args.realisations)]
    points += [("n", args.fixed_realisations, n) for n in _ints(args.n)]
    cache, rows = {}, []
    for name, realisations, n in points:
        if (realisations, n) not in cache:  # the two sweeps share a point
            cache[realisations, n] = run_point(
                realisations, n, args.iterations, args.repeats, args.timeout
            )
            result = cache[realisations, n]
            print(
                f"realisations {realisations:>6}, N {n:>6}: "
                + (
                    f"{result['run_s']:.3f} s, {result['fits_per_s']:.1f} fits/s, "
                    f"peak {result['peak_mem_mb']:.0f} MB"
                    if "error" not in result
                    else result["error"]
                ),
                flush=True,
            )
        row = dict(sweep=name, realisations=realisations, n=n, iterations=args.iterations)
        row.update(cache[realisations, n])
        rows.append({column: row.get(column, "") for column in COLUMNS})
    return rows


def plot(table, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(2, 2, figsize=(10, 7), constrained_layout=True)
    for column, (name, label) in enumerate((("realisations", "realisations"), ("n", "N"))):
        points = table[(table.sweep == name) & table.error.isna()]
        points = points.sort_values(name)
        x = points[name].to_numpy(float)
        time_axis, memory_axis = axes[0, column], axes[1, column]
        time_axis.loglog(x, points.run_s, "o-", label="measured")
        if len(x):
            time_axis.loglog(x, points.run_s.iloc[-1] * x / x[-1], "k:", label="linear")
        time_axis.set(xlabel=label, ylabel="run time (s)", title=f"time vs {label}")
        time_axis.legend()
        memory_axis.semilogx(x, points.peak_mem_mb, "o-", label="peak RSS")
        memory_axis.semilogx(x, points.base_mem_mb, "k.:", label="RSS after imports")
        memory_axis.set(xlabel=label, ylabel="memory (MB)", title=f"peak memory vs {label}")
        memory_axis.legend()
    device = next((d for d in table.device if isinstance(d, str) and d), "")
    figure.suptitle(f"jaxcascade batched fit, {table.iterations.iloc[0]} iterations; {device}")
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realisations", default="100,300,1000,3000,10000")
    parser.add_argument("--n", default="500,1000,2000,4000,8000,16000")
    parser.add_argument("--fixed-n", type=int, default=4000)
    parser.add_argument("--fixed-realisations", type=int, default=1000)
    parser.add_argument("--iterations", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=2, help="timed runs; the best counts")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per point")
    parser.add_argument("--out", default="results/scaling.csv")
    parser.add_argument("--plot", default="results/scaling.png")
    args = parser.parse_args(argv)

    import pandas as pd

    out, figure = pathlib.Path(args.out), pathlib.Path(args.plot)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.parent.mkdir(parents=True, exist_ok=True)
    table = pd.DataFrame(sweep(args), columns=COLUMNS)
    table.to_csv(out, index=False)
    table = pd.read_csv(out)  # numeric columns as numbers, missing errors as NaN
    plot(table, figure)
    print(f"wrote {out} and {figure}")


if __name__ == "__main__":
    main()
