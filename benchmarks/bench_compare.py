"""The throughput-regression guard: this checkout's `jaxcascade bench` against a reference,
alternated in fresh processes on the same machine.

    python benchmarks/bench_compare.py REF [--runs 5] [-- BENCH ARGUMENTS]
    python benchmarks/bench_compare.py --installed [--runs 5] [-- BENCH ARGUMENTS]

`REF` is a commit (anything `git rev-parse` reads: `main`, `51babbd`, `HEAD~3`); it is
checked out into a temporary `git worktree` (removed afterwards), and its bench runs
from that worktree's root, so it imports its own copy of the package. `--installed`
compares with the installed package instead (run from a temporary folder, so that the
import finds the installed copy, not this checkout). This checkout's bench runs from its
root with `PYTHONPATH` set to it. Each of `--runs` rounds runs both, `python -m
jaxcascade bench --json` plus the BENCH ARGUMENTS (default: the bench's own workload),
each in a fresh process with JAX's persistent compilation cache off (every run
compiles), alternating which goes first (A B, B A, ...) so that a drift in the
machine's load touches both alike.

Prints each run's fits/s (sample updates/s with `-- --estimator recursive`), compile
seconds and load average, then the ratio of this checkout's rate to the reference's and
of its compile time to the reference's, pair by pair: min / median / max. A compile
time whose median ratio exceeds `COMPILE_WARNING` (1.25) is flagged on its own line, so
that a change that lengthens it is noticed even where the rate holds. On a machine
shared with other work, quote the median with its spread, never one run. `--json`
prints the same as JSON. Exit code 0 unless a bench failed (2).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
# a median compile-time ratio above this is flagged (issue 33: compile time is a budget)
COMPILE_WARNING = 1.25


def run_bench(folder: pathlib.Path, pythonpath: str | None, arguments: list[str]) -> dict:
    """One `python -m jaxcascade bench --json` in a fresh process from `folder`."""
    # JAX's persistent cache off: the compile time compared is XLA's own, not a load of
    # the executable the other checkout (or an earlier run) left in the cache
    env = dict(os.environ, JAXCASCADE_CACHE="off")
    env.pop("PYTHONPATH", None)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    done = subprocess.run(
        [sys.executable, "-m", "jaxcascade", "bench", "--json", *arguments],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise RuntimeError(f"the bench in {folder} failed: {done.stderr.strip()[-1000:]}")
    record = json.loads(done.stdout.strip().splitlines()[-1])
    record.setdefault("load", os.getloadavg()[0])  # a reference without the field
    # the throughput compared: fits/s, or sample updates/s (`--estimator recursive`)
    unit = "fits_per_s" if "fits_per_s" in record else "updates_per_s"
    record["rate"], record["unit"] = record[unit], unit.replace("_per_s", "/s")
    return record


def describe(folder: pathlib.Path) -> str:
    done = subprocess.run(
        ["git", "log", "-1", "--format=%h %s"], cwd=folder, capture_output=True, text=True
    )
    return done.stdout.strip()[:72] if done.returncode == 0 else str(folder)


@contextlib.contextmanager
def checkout(ref: str):
    """A temporary `git worktree` of commit `ref` (removed afterwards); a `RuntimeError`
    where git cannot check it out."""
    with tempfile.TemporaryDirectory(prefix="compare_") as scratch:
        folder = pathlib.Path(scratch) / "reference"
        added = subprocess.run(
            ["git", "worktree", "add", "--detach", str(folder), ref],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
        if added.returncode != 0:
            raise RuntimeError(f"cannot check out {ref}: {added.stderr.strip()}")
        try:
            yield folder
        finally:
            subprocess.run(
                ["git", "worktree", "remove", "--force", str(folder)], cwd=ROOT, capture_output=True
            )


def alternate(runs: int, run, report=None) -> list[dict]:
    """`runs` rounds of `run("this")` and `run("reference")`, alternating which goes
    first (A B, B A, ...); `report(round, figures)` after each. The rounds' figures."""
    pairs = []
    for round_ in range(runs):
        order = ["this", "reference"] if round_ % 2 == 0 else ["reference", "this"]
        figures = {which: run(which) for which in order}
        pairs.append(figures)
        if report is not None:
            report(round_, figures)
    return pairs


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    bench_arguments = []
    if "--" in argv:
        at = argv.index("--")
        argv, bench_arguments = argv[:at], argv[at + 1 :]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("ref", nargs="?", help="a commit to compare with")
    parser.add_argument(
        "--installed", action="store_true", help="compare with the installed package"
    )
    parser.add_argument("--runs", type=int, default=5, help="rounds, each runs both (5)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    if (args.ref is None) == (not args.installed):
        parser.error("give either REF or --installed")
    if args.runs < 1:
        parser.error("--runs must be at least 1")

    with contextlib.ExitStack() as stack:
        if args.installed:
            reference = pathlib.Path(stack.enter_context(tempfile.TemporaryDirectory()))
            reference_path, label = None, "installed package"
        else:
            try:
                reference = stack.enter_context(checkout(args.ref))
            except RuntimeError as error:
                print(f"bench_compare: {error}")
                return 2
            reference_path, label = str(reference), describe(reference)

        def run(which):
            if which == "this":
                return run_bench(ROOT, str(ROOT), bench_arguments)
            return run_bench(reference, reference_path, bench_arguments)

        def report(round_, figures):
            this, ref = figures["this"], figures["reference"]
            print(
                f"round {round_ + 1}: this {this['rate']:.4g} {this['unit']} (compile "
                f"{this['compile_s']:.1f} s, load {this['load']:.2f}), reference "
                f"{ref['rate']:.4g} {ref['unit']} (compile {ref['compile_s']:.1f} s, "
                f"load {ref['load']:.2f}), ratio {this['rate'] / ref['rate']:.3f}",
                flush=True,
            )

        try:
            pairs = alternate(args.runs, run, None if args.json else report)
        except RuntimeError as error:
            print(f"bench_compare: {error}")
            return 2
    ratios = [p["this"]["rate"] / p["reference"]["rate"] for p in pairs]
    compiles = [p["this"]["compile_s"] / p["reference"]["compile_s"] for p in pairs]
    unit = pairs[0]["this"]["unit"]
    summary = {
        "this": describe(ROOT),
        "reference": label,
        "runs": args.runs,
        "bench_arguments": bench_arguments,
        "ratio_min": min(ratios),
        "ratio_median": statistics.median(ratios),
        "ratio_max": max(ratios),
        "unit": unit,
        "compile_ratio_min": min(compiles),
        "compile_ratio_median": statistics.median(compiles),
        "compile_ratio_max": max(compiles),
        "this_compile_s": [p["this"]["compile_s"] for p in pairs],
        "reference_compile_s": [p["reference"]["compile_s"] for p in pairs],
        "this_rate": [p["this"]["rate"] for p in pairs],
        "reference_rate": [p["reference"]["rate"] for p in pairs],
        "load": [p["this"]["load"] for p in pairs] + [p["reference"]["load"] for p in pairs],
        "device": pairs[0]["this"]["device"],
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"this ({summary['this']}) / reference ({label}): ratio of {unit} "
            f"{summary['ratio_median']:.3f} (median of {args.runs} pairs; min "
            f"{summary['ratio_min']:.3f}, max {summary['ratio_max']:.3f}); "
            f"{summary['device']}; load {min(summary['load']):.1f}-{max(summary['load']):.1f}"
        )
        print(
            f"compile time this / reference: {summary['compile_ratio_median']:.3f} (min "
            f"{summary['compile_ratio_min']:.3f}, max {summary['compile_ratio_max']:.3f})"
        )
        if summary["compile_ratio_median"] > COMPILE_WARNING:
            print(
                f"bench_compare: compile time up {summary['compile_ratio_median']:.2f}x "
                f"(median), above the {COMPILE_WARNING}x this guard flags"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
