"""Issue 16: the robust estimator's throughput, compile time and recovery on the three
benchmark systems, against a SciPy output-error multi-start (`jaxcascade bench
--estimator robust`).

    python benchmarks/bench_robust.py [--realisations 256] [--baseline-realisations 8]
        [--systems example1,example2,random] [--n N] [--out results/bench_robust]

Writes `OUT.csv` (one row per system, every figure) and `OUT.json` (the summaries).
Each system is benchmarked in a fresh process, so its compile time is cold and one
system's caches do not speed up the next. `--n` replaces every system's N (for quick
checks only). Run it on a quiet machine: it reports wall-clock rates.
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib
import subprocess
import sys
import time

SYSTEMS = ("example1", "example2", "random")


def one_system(system, realisations, baseline_realisations, n, seed):
    code = (
        "import jax, json, sys; jax.config.update('jax_enable_x64', True); "
        "from jaxcascade._benchmark._robust import run_benchmark; "
        "a = json.loads(sys.argv[1]); print(json.dumps(run_benchmark(**a)))"
    )
    arguments = {
        "system": system,
        "realisations": realisations,
        "baseline_realisations": baseline_realisations,
        "n": n,
        "seed": seed,
    }
    done = subprocess.run(
        [sys.executable, "-c", code, json.dumps(arguments)], capture_output=True, text=True
    )
    if done.returncode != 0:
        raise RuntimeError(f"{system}: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realisations", type=int, default=256)
    parser.add_argument("--baseline-realisations", type=int, default=8)
    parser.add_argument("--systems", default=",".join(SYSTEMS))
    parser.add_argument("--n", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/bench_robust")
    args = parser.parse_args(argv)
    from jaxcascade._benchmark._robust import SUMMARY_KEYS

    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for system in args.systems.split(","):
        record = one_system(
            system, args.realisations, args.baseline_realisations, args.n, args.seed
        )
        record["date"] = time.strftime("%Y-%m-%dT%H:%M:%S")
        rows.append(record)
        print(json.dumps({key: record[key] for key in SUMMARY_KEYS}), flush=True)
    with open(out.with_suffix(".csv"), "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    with open(out.with_suffix(".json"), "w") as file:
        json.dump([{key: r[key] for key in SUMMARY_KEYS} for r in rows], file, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
