"""Issues 40 and 33: where the default test run's time goes, by test file and by program.

    python benchmarks/default_run_profile.py [--out results/default_run_profile]
                                             [--workers 2] [PATH ...]

Runs the default test run (`-m 'not slow'`, as `.ci/run` selects it) with
`benchmarks/compile_profile_plugin.py`, which sums JAX's monitoring events per test and
per program name in every worker: programs compiled, seconds tracing, lowering and in
XLA's compile. Writes OUT.csv (per test file: tests' wall seconds, programs, trace,
lowering, compile), OUT_programs.csv (per program name: count and seconds; `jit(scan)`,
`jit(add)` and the like are eager calls outside `jit`, each compiled on its own) and
OUT.md with the totals, the commit, date, machine and load. The wall seconds per file
are the sum of its tests' (fixtures included); both workers' files are summed.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
HERE = pathlib.Path(__file__).resolve().parent
COLUMNS = ["wall_s", "compile_n", "trace_s", "lower_s", "compile_s"]


def is_eager(program: str) -> bool:
    """Whether a program is one operation called outside `jit` (`jit(add)`, `jit(scan)`):
    named after a `jax.lax` primitive, a `jax.numpy` function or a control-flow
    primitive. Programs of the package and of the tests have other names."""
    import re

    import jax
    import jax.numpy as jnp

    match = re.fullmatch(r"jit\(([a-z][a-z0-9_]*)\)", program)
    if match is None:
        return False
    name = match.group(1)
    return name in ("scan", "while", "cond") or hasattr(jax.lax, f"{name}_p") or hasattr(jnp, name)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/default_run_profile")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("paths", nargs="*", help="test files (default: the whole run)")
    args = parser.parse_args(argv)

    import pandas as pd
    from bench_history import commit
    from loop_speed import machine, markdown

    load = os.getloadavg()[0]
    began = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        env = dict(os.environ, JAXCASCADE_PROFILE_DIR=folder)
        # the plugin alone on the path: benchmarks/ there would shadow packages by its
        # scripts' names (nonlinear_benchmarks)
        shutil.copy(HERE / "compile_profile_plugin.py", folder)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [folder, env.get("PYTHONPATH")]))
        pytest = [sys.executable, "-m", "pytest", "-m", "not slow", "-q", "-p", "no:cacheprovider"]
        pytest += ["-n", str(args.workers), "-p", "compile_profile_plugin", *args.paths]
        status = subprocess.run(pytest, cwd=ROOT, env=env).returncode
        found = sorted(pathlib.Path(folder).glob("*.json"))
        parts = [json.loads(p.read_text()) for p in found]
    wall = time.perf_counter() - began
    tests = pd.DataFrame(
        [{"test": k, **v} for part in parts for k, v in part["tests"].items()],
        columns=["test", *COLUMNS],
    ).fillna(0.0)
    programs = pd.DataFrame(
        [{"program": k, **v} for part in parts for k, v in part["programs"].items()],
        columns=["program", *COLUMNS[1:]],
    ).fillna(0.0)
    for frame, columns in ((tests, COLUMNS), (programs, COLUMNS[1:])):
        for column in columns:
            if column not in frame:
                frame[column] = 0.0
    tests["file"] = tests.test.str.split("::").str[0]
    files = tests.groupby("file", as_index=False)[COLUMNS].sum()
    files = files.sort_values("wall_s", ascending=False).round(1)
    files["compile_n"] = files.compile_n.astype(int)
    programs = programs.groupby("program", as_index=False)[COLUMNS[1:]].sum()
    programs = programs.sort_values("compile_s", ascending=False).round(2)
    programs["compile_n"] = programs.compile_n.astype(int)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    files.to_csv(f"{out}.csv", index=False)
    programs.to_csv(f"{out}_programs.csv", index=False)
    eager = programs[programs.program.map(is_eager)]
    given = sys.argv[1:] if argv is None else argv
    command = "python benchmarks/default_run_profile.py " + " ".join(given)
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    totals = files[COLUMNS].sum()
    lines = [
        "# Where the default test run's time goes",
        "",
        f"`{command.strip()}`, commit {commit()}, {date}, {machine()}; load average "
        f"{load:.2f} at the start; pytest exit status {status}, {wall:.0f} s wall with "
        f"{args.workers} workers.",
        "",
        f"Summed over the workers: {totals.wall_s:.0f} s in tests, of which "
        f"{totals.compile_s:.0f} s in XLA's compile of {int(totals.compile_n)} programs, "
        f"{totals.trace_s:.0f} s tracing and {totals.lower_s:.0f} s lowering. Programs "
        "named after one operation (`jit(scan)`, `jit(add)`, ...: a `jax.lax` primitive or a "
        "`jax.numpy` function) are eager calls outside `jit`: "
        f"{int(eager.compile_n.sum())} of "
        f"them, {eager.compile_s.sum():.0f} s of compile.",
        "",
        "## By test file",
        "",
        markdown(files),
        "",
        "## The 30 programs with the most compile time",
        "",
        markdown(programs.head(30)),
        "",
    ]
    pathlib.Path(f"{out}.md").write_text("\n".join(lines))
    print("\n".join(lines[:7]))
    return status


if __name__ == "__main__":
    raise SystemExit(main())
