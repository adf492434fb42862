"""Issue 40: a test set, run and recorded, so that its last result is committed: the
`slow` set, or the default run (its time against the project's budget of about 8
minutes on a 2-core machine).

    python benchmarks/slow_tests.py [--select slow|default] [--out results/slow_tests]
                                    [--workers 2]

Runs `python -m pytest -m slow -q -p no:cacheprovider -n WORKERS` (the default run's
`-m 'not slow'` replaced; the same float64 conftest), or with `--select default` the
default run's own selection (`-m 'not slow'`, as `.ci/run` runs it, without the docs
build), with a JUnit XML report in a temporary folder, and writes OUT.csv (one row per
test: its id, outcome, seconds and the first line of a failure's message) and OUT.md
(the command, commit, date, machine and its load, the counts by outcome, the slowest
test files and the table). Exits with pytest's status: a failing test is a failing run
of this step, and its row says which.
"""

from __future__ import annotations

import argparse
import datetime
import os
import pathlib
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ElementTree

ROOT = pathlib.Path(__file__).resolve().parents[1]


def cases(report: pathlib.Path) -> list[dict]:
    """The test cases of a JUnit XML report: id, outcome, seconds, message."""
    rows = []
    for case in ElementTree.parse(report).getroot().iter("testcase"):
        outcome, message = "passed", ""
        for kind in ("failure", "error", "skipped"):
            found = case.find(kind)
            if found is not None:
                outcome = {"failure": "failed"}.get(kind, kind)
                message = (found.get("message") or found.text or "").strip().splitlines()
                message = message[0][:200] if message else ""
                break
        module = case.get("classname", "").replace(".", "/")
        rows.append(
            {
                "test": f"{module}.py::{case.get('name')}",
                "outcome": outcome,
                "seconds": round(float(case.get("time", 0.0)), 1),
                "message": message,
            }
        )
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--select", choices=("slow", "default"), default="slow")
    parser.add_argument("--out", default="results/slow_tests")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)

    import pandas as pd
    from bench_history import commit
    from loop_speed import machine, markdown

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        report = pathlib.Path(folder) / "slow.xml"
        marker = "slow" if args.select == "slow" else "not slow"
        load = os.getloadavg()[0]
        pytest = [sys.executable, "-m", "pytest", "-m", marker, "-q", "-p", "no:cacheprovider"]
        pytest += ["-n", str(args.workers), f"--junitxml={report}"]
        status = subprocess.run(pytest, cwd=ROOT).returncode
        rows = cases(report) if report.exists() else []
    wall = time.perf_counter() - started
    table = pd.DataFrame(rows, columns=["test", "outcome", "seconds", "message"])
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(f"{out}.csv", index=False)
    counts = table.outcome.value_counts().to_dict()
    files = (
        table.assign(file=table.test.str.split("::").str[0])
        .groupby("file", as_index=False)
        .agg(tests=("test", "size"), seconds=("seconds", "sum"))
        .sort_values("seconds", ascending=False)
        .round(1)
    )
    command = "python benchmarks/slow_tests.py " + " ".join(sys.argv[1:] if argv is None else argv)
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    lines = [
        f"# The {'slow test set' if args.select == 'slow' else 'default test run'}, last run",
        "",
        f"`{command.strip()}`, commit {commit()}, {date}, {machine()}; "
        f"load average {load:.2f} at the start; "
        f"pytest exit status {status}, {wall:.0f} s wall with {args.workers} workers.",
        "",
        ", ".join(f"{count} {outcome}" for outcome, count in sorted(counts.items()))
        or "no test ran",
        "",
        "Seconds by test file (a file runs in one worker):",
        "",
        markdown(files),
        "",
        markdown(table.sort_values("seconds", ascending=False)),
        "",
    ]
    pathlib.Path(f"{out}.md").write_text("\n".join(lines))
    print("\n".join(lines[:5]))
    return status


if __name__ == "__main__":
    raise SystemExit(main())
