"""Issue 69: the package's Monte-Carlo workloads on a GPU and on the same machine's CPU,
in one sitting (`benchmarks/gpu.sh` runs it where a GPU is found).

    python benchmarks/gpu.py --probe            # exit 0 where JAX finds a GPU, else 1
    python benchmarks/gpu.py --out results/gpu  # writes OUT.csv and OUT.md

Per platform (`JAX_PLATFORMS=cuda`, then `JAX_PLATFORMS=cpu`), each workload in a fresh
process with JAX's persistent cache off (`JAXCASCADE_CACHE=off`: every compile cold,
and counted):

- literal: `jaxcascade bench --json --realisations R --repeats 2 --workers W` (Example
  1, N 4000, 20 iterations; R 20,000 on both; the CPU with one worker per core and
  the fused C++ kernel where it builds, the GPU as one device);
- robust: `jaxcascade bench --estimator robust --system example1` (1,024 realisations on
  the GPU, 256 on the CPU, as in the issue);
- recursive: `jaxcascade bench --estimator recursive --realisations R` (R 4,096 on the
  GPU, 1,024 on the CPU: sample updates per second);
- sweep: `jaxcascade sweep --example 1 --snr 10,25,50 --n 1000,4000 --estimator
  literal,robust`, 12 cells, its wall time with compiling (the process's start
  included); 1,000 realisations per cell on the GPU, fewer on the CPU
  (`--cpu-sweep-realisations`, with one chunk per core at once: `--workers`), where it
  would take many minutes: the rows say how many, and the figure compared is the fits
  per second.

Every row carries the device, the versions (Python, JAX, jaxlib, jaxcascade and its
commit: `git rev-parse` where this is a checkout, else `$JAXCASCADE_COMMIT`) and the
command. OUT.md holds the table and the issue's targets beside the GPU's figures.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import pathlib
import platform
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
PLATFORMS = {"gpu": "cuda", "cpu": "cpu"}
# Issue 69's targets on the GPU (fits/s; the sweep in seconds with compiling)
TARGETS = {
    "literal": (">=", 12983.0, "the 16 CPU cores' figure in the issue (moonshot 65,000)"),
    "robust": (">=", 1000.0, "issue 69"),
    "sweep": ("<=", 60.0, "12 cells of 1,000 realisations, with compiling"),
}


def probe() -> int:
    """0 where JAX finds a GPU, 1 where not (a line on stderr says which)."""
    try:
        import jax

        devices = jax.devices("gpu")
    except Exception as error:  # no CUDA jaxlib, or no device
        print(f"gpu.py: no GPU found ({type(error).__name__}: {error})", file=sys.stderr)
        return 1
    print(f"gpu.py: {len(devices)} GPU(s): {devices[0].device_kind}", file=sys.stderr)
    return 0


def _commit() -> str:
    try:
        done = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
        )
        if done.returncode == 0 and done.stdout.strip():
            return done.stdout.strip()
    except OSError:
        pass
    return os.environ.get("JAXCASCADE_COMMIT", "unknown")


def _environment(name: str) -> dict:
    env = dict(os.environ, JAX_PLATFORMS=PLATFORMS[name], JAXCASCADE_CACHE="off")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return env


def _versions(env) -> dict:
    code = (
        "import json, platform, jax, jaxlib, jaxcascade; "
        "from jaxcascade._benchmark._timing import device_description; "
        "print(json.dumps({'python': platform.python_version(), 'jax': jax.__version__, "
        "'jaxlib': jaxlib.__version__, 'jaxcascade': jaxcascade.__version__, "
        "'device': device_description()}))"
    )
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(done.stderr.strip()[-2000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def _run(arguments: list[str], env, log) -> tuple[float, str]:
    """`python -m jaxcascade ARGUMENTS` in a fresh process: (wall seconds, stdout)."""
    command = [sys.executable, "-m", "jaxcascade", *arguments]
    print("$ jaxcascade " + " ".join(arguments), file=log, flush=True)
    start = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - start
    log.write(done.stdout + done.stderr)
    log.flush()
    if done.returncode != 0:
        raise RuntimeError(f"jaxcascade {' '.join(arguments)}: {done.stderr.strip()[-2000:]}")
    return wall, done.stdout


def _bench_row(arguments, env, log, folder, name) -> dict:
    out = folder / f"{name}.csv"
    wall, _ = _run([*arguments, "--out", str(out)], env, log)
    with open(out) as file:
        record = next(csv.DictReader(file))
    rate = record.get("fits_per_s") or record.get("updates_per_s")
    return {
        "figure": float(rate),
        "unit": "updates/s" if "updates_per_s" in record else "fits/s",
        "compile_s": float(record["compile_s"]),
        "realisations": int(record["realisations"]),
        "wall_s": wall,
        "detail": {
            k: record[k]
            for k in ("backend", "workers", "recovered", "adaptive_fraction", "status_counts")
            if k in record
        },
    }


def _sweep_row(arguments, env, log, folder, realisations) -> dict:
    out = folder / "sweep.parquet"
    wall, _ = _run([*arguments, "--out", str(out)], env, log)
    import pandas as pd

    table = pd.read_parquet(out)
    fits = table.groupby(["n", "snr", "estimator"]).ngroups * realisations
    compile_s = (
        table.groupby(["n", "estimator"])["compile_seconds"].max().sum()
        if "compile_seconds" in table
        else float("nan")
    )
    return {
        "figure": wall,
        "unit": "s with compiling",
        "compile_s": float(compile_s),
        "realisations": realisations,
        "wall_s": wall,
        "detail": {"fits": int(fits), "fits_per_s": fits / wall},
    }


def workloads(name: str, args) -> list[tuple[str, list[str], str]]:
    """`(workload, jaxcascade arguments, kind)` for platform `name`."""
    gpu = name == "gpu"
    sweep_realisations = args.sweep_realisations if gpu else args.cpu_sweep_realisations
    sweep = [
        "sweep", "--example", "1", "--snr", "10,25,50", "--n", "1000,4000",
        "--realisations", str(sweep_realisations), "--estimator", "literal,robust",
    ]  # fmt: skip
    if not gpu:
        sweep += ["--workers", str(args.cpu_workers)]
    literal = ["bench", "--json", "--realisations", str(args.literal_realisations)]
    literal += ["--repeats", "2"]
    if gpu:
        literal += ["--workers", "1"]
    robust = [
        "bench", "--json", "--estimator", "robust", "--system", "example1", "--realisations",
        str(args.robust_realisations if gpu else args.cpu_robust_realisations),
        "--baseline-realisations", "4",
    ]  # fmt: skip
    recursive = ["bench", "--json", "--estimator", "recursive", "--realisations"]
    recursive += [str(4096 if gpu else args.cpu_recursive_realisations)]
    return [
        ("literal", literal, "bench"),
        ("robust", robust, "bench"),
        ("recursive", recursive, "bench"),
        ("sweep", sweep, "sweep"),
    ]


def run(args) -> list[dict]:
    rows = []
    commit = _commit()
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    log_path = args.log or os.devnull
    with open(log_path, "w") as log, tempfile.TemporaryDirectory() as tmp:
        for name in args.platforms.split(","):
            env = _environment(name)
            versions = _versions(env)
            for workload, arguments, kind in workloads(name, args):
                if args.only and workload not in args.only.split(","):
                    continue
                folder = pathlib.Path(tmp) / name
                folder.mkdir(exist_ok=True)
                if kind == "sweep":
                    realisations = int(arguments[arguments.index("--realisations") + 1])
                    result = _sweep_row(arguments, env, log, folder, realisations)
                else:
                    result = _bench_row(arguments, env, log, folder, workload)
                row = {
                    "platform": name,
                    "workload": workload,
                    **{k: result[k] for k in ("figure", "unit", "compile_s", "realisations")},
                    "wall_s": round(result["wall_s"], 2),
                    "detail": json.dumps(result["detail"], sort_keys=True),
                    "command": "jaxcascade " + " ".join(arguments),
                    **versions,
                    "commit": commit,
                    "host": platform.node(),
                    "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
                }
                rows.append(row)
                print(
                    f"{name:4s} {workload:9s} {row['figure']:12.4g} {row['unit']:17s} "
                    f"compile {row['compile_s']:6.1f} s  wall {row['wall_s']:6.1f} s",
                    flush=True,
                )
    return rows


def _fits_per_s(row) -> float:
    return json.loads(row["detail"])["fits_per_s"] if row["workload"] == "sweep" else row["figure"]


def markdown(rows, args) -> str:
    by = {(r["platform"], r["workload"]): r for r in rows}
    gpu_device = next((r["device"] for r in rows if r["platform"] == "gpu"), "-")
    cpu_device = next((r["device"] for r in rows if r["platform"] == "cpu"), "-")
    first = rows[0]
    lines = [
        "# The workloads on a GPU and on the same machine's CPU (issue 69)",
        "",
        f"`python benchmarks/gpu.py --out {args.out}` (run by `bash benchmarks/gpu.sh`), "
        f"commit {first['commit']}, {first['date']}, host {first['host']}; Python "
        f"{first['python']}, JAX {first['jax']}, jaxlib {first['jaxlib']}, jaxcascade "
        f"{first['jaxcascade']}; float64, JAX's persistent cache off (every compile cold).",
        f"GPU: {gpu_device}. CPU: {cpu_device}.",
        "",
        "| workload | GPU | CPU | GPU / CPU (per fit or update) | compile s (GPU / CPU) "
        "| target on the GPU |",
        "|---|---|---|---|---|---|",
    ]  # fmt: skip
    for workload in ("literal", "robust", "recursive", "sweep"):
        g, c = by.get(("gpu", workload)), by.get(("cpu", workload))
        if g is None and c is None:
            continue

        def cell(r):
            if r is None:
                return "-"
            text = f"{r['figure']:,.4g} {r['unit']} ({r['realisations']:,} realisations"
            if r["workload"] == "sweep":
                text += f" per cell, {json.loads(r['detail'])['fits_per_s']:,.1f} fits/s"
            return text + ")"

        ratio = f"{_fits_per_s(g) / _fits_per_s(c):.3g}" if g and c else "-"
        compile_s = " / ".join(f"{r['compile_s']:.1f}" if r else "-" for r in (g, c))
        target = "-"
        if workload in TARGETS and g is not None:
            sense, value, why = TARGETS[workload]
            met = g["figure"] >= value if sense == ">=" else g["figure"] <= value
            if workload == "sweep" and g["realisations"] != 1000:
                met = None
            verdict = "not comparable" if met is None else "met" if met else "**missed**"
            target = f"{sense} {value:,.0f} ({why}): {verdict}"
        lines.append(f"| {workload} | {cell(g)} | {cell(c)} | {ratio} | {compile_s} | {target} |")
    lines += ["", "Commands (each in a fresh process, `JAX_PLATFORMS` set per platform):", ""]
    lines += [f"- {r['platform']}: `{r['command']}`" for r in rows]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--probe", action="store_true", help="exit 0 where a GPU is found")
    parser.add_argument("--out", default="results/gpu", help="writes OUT.csv and OUT.md")
    parser.add_argument("--log", default=None, help="the commands' output (default: none)")
    parser.add_argument("--platforms", default="gpu,cpu")
    parser.add_argument("--only", default=None, help="comma-separated workloads (quick checks)")
    parser.add_argument("--literal-realisations", type=int, default=20000)
    parser.add_argument("--robust-realisations", type=int, default=1024)
    parser.add_argument("--cpu-robust-realisations", type=int, default=256)
    parser.add_argument("--cpu-recursive-realisations", type=int, default=1024)
    parser.add_argument("--sweep-realisations", type=int, default=1000)
    parser.add_argument("--cpu-sweep-realisations", type=int, default=100)
    parser.add_argument("--cpu-workers", type=int, default=4, help="CPU sweep: chunks at once")
    args = parser.parse_args(argv)
    if args.probe:
        return probe()
    rows = run(args)
    out = pathlib.Path(args.out)
    with open(f"{out}.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    text = markdown(rows, args)
    pathlib.Path(f"{out}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
