"""Issue 16: what the package's XLA options (`jaxcascade/_compile.py`) buy, A/B against
XLA's defaults, on the robust benchmark's batched program (the workload of
`jaxcascade bench --estimator robust`: simulate, add noise, fit, 256 records).

    python benchmarks/compile_options.py [--realisations 256] [--repeats 2]
        [--systems example1,example2,random] [--out results/compile_options]

For each system and each setting (`package`: the options; `xla-default`:
`JAXCASCADE_COMPILE=default`) a fresh process traces, compiles (cold: no persistent
cache) and runs the program; the settings alternate within each repeat, so a change of
the machine's speed hits both alike. Writes `OUT.csv` (every run) and `OUT.md` (the
medians). Run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

import pandas as pd

SETTINGS = {"package": "", "xla-default": "default"}
CODE = """
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
from jaxcascade._benchmark._robust import batched_fit, system_defaults
from jaxcascade._compile import compiler_options
system, realisations = sys.argv[1], int(sys.argv[2])
n, snr = system_defaults(system)
keys = jax.random.split(jax.random.PRNGKey(0), realisations)
start = time.perf_counter()
traced = batched_fit(system, n, snr).trace(keys)
lowered = traced.lower()
middle = time.perf_counter()
compiled = lowered.compile()
end = time.perf_counter()
jax.block_until_ready(compiled(keys))  # first run: allocations, the fused kernel's load
again = time.perf_counter()
jax.block_until_ready(compiled(keys))
done = time.perf_counter()
print(json.dumps({"trace_lower_s": middle - start, "xla_s": end - middle,
                  "compile_s": end - start, "run_s": done - again,
                  "fits_per_s": realisations / (done - again),
                  "options": json.dumps(compiler_options())}))
"""


def one(system: str, setting: str, realisations: int) -> dict:
    env = {**os.environ, "JAXCASCADE_CACHE": "off", "JAXCASCADE_COMPILE": SETTINGS[setting]}
    done = subprocess.run(
        [sys.executable, "-c", CODE, system, str(realisations)],
        capture_output=True,
        text=True,
        env=env,
    )
    if done.returncode != 0:
        raise RuntimeError(f"{system}/{setting}: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realisations", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--systems", default="example1,example2,random")
    parser.add_argument("--out", default="results/compile_options")
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for repeat in range(args.repeats):
        for system in args.systems.split(","):
            order = list(SETTINGS) if repeat % 2 == 0 else list(SETTINGS)[::-1]
            for setting in order:
                row = {"system": system, "setting": setting, "repeat": repeat}
                row.update(one(system, setting, args.realisations))
                row["date"] = time.strftime("%Y-%m-%dT%H:%M:%S")
                rows.append(row)
                print(json.dumps(row), flush=True)
    frame = pd.DataFrame(rows)
    frame.to_csv(out.with_suffix(".csv"), index=False)
    columns = ["trace_lower_s", "xla_s", "compile_s", "fits_per_s"]
    medians = frame.groupby(["system", "setting"])[columns].median().round(2).reset_index()
    command = "python benchmarks/compile_options.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    options = next(r["options"] for r in rows if r["setting"] == "package")
    lines = [
        "# XLA compile options of the robust program: the package's against XLA's defaults",
        "",
        f"Command: `{command.strip()}`",
        "",
        f"{args.realisations} records per batch, cold compile in a fresh process, medians of "
        f"{args.repeats} alternated repeats; `package`: {options}.",
        "",
        "| system | setting | trace + lower s | XLA s | compile s | fits/s |",
        "|---|---|---|---|---|---|",
    ]
    for r in medians.itertuples():
        lines.append(
            f"| {r.system} | {r.setting} | {r.trace_lower_s} | {r.xla_s} | {r.compile_s} | "
            f"{r.fits_per_s} |"
        )
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
