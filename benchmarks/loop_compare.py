"""The model-error loop's A/B: this checkout's `jaxcascade loop` against a reference
commit's, alternated in fresh processes on the same machine.

    python benchmarks/loop_compare.py REF [--runs 3] [--n 1024] [--damper DATA]
                                          [--cache off|cold|warm]

The loop runs with its default settings on `loop_speed.py`'s synthetic input-delay
records (`--n` samples each for estimation and validation: the declared cascade's
residual fails, so every candidate of the library is fitted and scored); with
`--damper DATA` (the damper's records, `../shared/data/brfd`) it runs `loop_speed.py`'s
damper run instead (`brfd_argv`: the 30 lb harmonic tests and Imperial Valley,
validated on Kocaeli, `--decimate 8`, the damper's effect list). `REF` is
checked out into a temporary `git worktree` (`bench_compare.checkout`) and imports its
own copy of the package; this checkout's runs with `PYTHONPATH` set to it. Each of
`--runs` rounds runs both, alternating which goes first, with JAX's persistent cache
(`--cache`): `off` (`JAXCASCADE_CACHE=off`, every program compiled, nothing written; the
default), `cold` (an empty cache folder for every run: a user's first run, compiling and
writing every program) or `warm` (each side's own folder, filled by one untimed run of
that side before the rounds: a user's later runs).

Prints each run's wall seconds (the whole process), programs compiled and effects
added, then:
- the ratio of this checkout's wall time to the reference's, pair by pair (min /
  median / max);
- whether every run added the same effects;
- the largest difference between the two of a candidate's validation NRMSE, over the
  candidates both scored: 0 up to rounding where the computation is the same,
  larger where a refit ends elsewhere.

Exit code 0 unless a loop failed (2).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

from bench_compare import ROOT, alternate, checkout, describe
from loop_speed import brfd_argv, records


def run_loop(folder: pathlib.Path, pythonpath: str, argv: list[str], cache: str = "off") -> dict:
    """One `jaxcascade ARGV` (a loop with `--json`) in a fresh process from `folder`, JAX's
    persistent cache in the folder `cache` (`off`: none)."""
    env = dict(os.environ, JAXCASCADE_CACHE=cache, PYTHONPATH=pythonpath)
    command = [sys.executable, "-m", "jaxcascade", *argv]
    start = time.perf_counter()
    done = subprocess.run(command, cwd=folder, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"the loop in {folder} failed: {done.stderr.strip()[-1000:]}")
    report = json.loads(done.stdout)
    return {
        "seconds": seconds,
        "programs": report["programs_compiled"],
        "effects": report["effect_added"],
        "errors": {(c["round"], c["variant"]): c["error"] for c in report["candidates"]},
        "load": os.getloadavg()[0],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("ref", help="a commit to compare with")
    parser.add_argument("--runs", type=int, default=3, help="rounds, each runs both (3)")
    parser.add_argument("--n", type=int, default=1024, help="samples of each record (1024)")
    parser.add_argument("--damper", metavar="DATA", help="the damper run on DATA instead")
    parser.add_argument(
        "--cache",
        choices=("off", "cold", "warm"),
        default="off",
        help="JAX's persistent cache: off (default), an empty folder per run, or each "
        "side's folder filled by an untimed run first",
    )
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    if args.damper and not pathlib.Path(args.damper, "characterization").is_dir():
        parser.error(f"--damper: {args.damper} does not hold the damper's records")
    with tempfile.TemporaryDirectory(prefix="loop_compare_") as scratch:
        if args.damper:
            loop = brfd_argv(str(pathlib.Path(args.damper).resolve()), pathlib.Path(scratch))
        else:
            est, val, _ = records(pathlib.Path(scratch), args.n)
            loop = ["loop", est, "--validate", val, "--input", "u", "--output", "y", "--json"]
        try:
            with checkout(args.ref) as reference:
                label = describe(reference)

                folders = {"this": ROOT, "reference": reference}
                kept = {w: pathlib.Path(scratch, f"cache-{w}") for w in folders}
                runs = itertools.count()

                def cache(which):
                    if args.cache == "off":
                        return "off"
                    if args.cache == "warm":
                        return str(kept[which])
                    return str(pathlib.Path(scratch, f"cache-{which}-{next(runs)}"))

                if args.cache == "warm":
                    for which, folder in folders.items():
                        run_loop(folder, str(folder), loop, cache(which))

                def run(which):
                    folder = folders[which]
                    return run_loop(folder, str(folder), loop, cache(which))

                def report(round_, figures):
                    this, ref = figures["this"], figures["reference"]
                    print(
                        f"round {round_ + 1}: this {this['seconds']:.1f} s, "
                        f"{this['programs']} programs, added {this['effects']}; reference "
                        f"{ref['seconds']:.1f} s, {ref['programs']} programs, added "
                        f"{ref['effects']}; ratio {this['seconds'] / ref['seconds']:.3f}",
                        flush=True,
                    )

                pairs = alternate(args.runs, run, report)
        except RuntimeError as error:
            print(f"loop_compare: {error}")
            return 2
    ratios = [p["this"]["seconds"] / p["reference"]["seconds"] for p in pairs]
    same = all(p["this"]["effects"] == p["reference"]["effects"] for p in pairs)
    shared = [k for k in pairs[0]["this"]["errors"] if k in pairs[0]["reference"]["errors"]]
    largest = max(
        (abs(p["this"]["errors"][k] - p["reference"]["errors"][k]) for p in pairs for k in shared),
        default=float("nan"),
    )
    print(
        f"this ({describe(ROOT)}) / reference ({label}): wall time ratio "
        f"{statistics.median(ratios):.3f} (median of {args.runs} pairs; min {min(ratios):.3f}, "
        f"max {max(ratios):.3f}); cache {args.cache}; load "
        f"{min(p[w]['load'] for p in pairs for w in p):.1f}-"
        f"{max(p[w]['load'] for p in pairs for w in p):.1f}"
    )
    print(
        f"the same effects added in every run: {same}; largest difference of a candidate's "
        f"validation NRMSE ({len(shared)} candidates in both): {largest:.3g}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
