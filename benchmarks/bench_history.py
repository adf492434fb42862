"""Append a row to the bench's history: one per regeneration of `results/bench.json`.

    python benchmarks/bench_history.py [results/bench.json] [--out results/bench_history.csv]

Reads the JSON summary that `jaxcascade bench --json` wrote and appends commit (this
checkout's HEAD, `-dirty` when tracked files differ from it), date (UTC), machine (the
bench's device line: CPU model and cores), fits/s, the ratio to the NumPy/SciPy baseline,
the floor fraction with its count, compile seconds, the load average as the timed
runs started and the host threads the realisations were split over (`workers`; blank
in rows from before the split, which ran them as one call). The history is how a
figure gets compared with the one before it: a drop between two rows at a similar load
is a regression to look for with `benchmarks/bench_compare.py`.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import pathlib
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[1]
FIELDS = (
    "commit",
    "date",
    "machine",
    "fits_per_s",
    "ratio_to_baseline",
    "floor_fraction",
    "floor_count",
    "compile_s",
    "load",
    "workers",
)


def commit() -> str:
    def git(*arguments):
        return subprocess.run(["git", *arguments], cwd=ROOT, capture_output=True, text=True)

    head = git("rev-parse", "--short", "HEAD").stdout.strip() or "unknown"
    dirty = git("diff", "--quiet", "HEAD", "--", "jaxcascade").returncode != 0
    return head + ("-dirty" if dirty else "")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("summary", nargs="?", default=str(ROOT / "results" / "bench.json"))
    parser.add_argument("--out", default=str(ROOT / "results" / "bench_history.csv"))
    args = parser.parse_args(argv)
    figures = json.loads(pathlib.Path(args.summary).read_text())
    row = {
        "commit": commit(),
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "machine": figures["device"],
        "fits_per_s": round(figures["fits_per_s"], 1),
        "ratio_to_baseline": round(figures["ratio"], 1),
        "floor_fraction": round(figures["floor_fraction"], 3),
        "floor_count": figures.get("floor_count", ""),
        "compile_s": round(figures["compile_s"], 2),
        "load": round(figures["load"], 2) if "load" in figures else "",
        "workers": figures.get("workers", ""),
    }
    out = pathlib.Path(args.out)
    new = not out.exists()
    if not new:  # a history written before a column was added: rewritten with it, blank
        with open(out, newline="") as file:
            reader = csv.DictReader(file)
            old_fields, rows = reader.fieldnames or [], list(reader)
        if tuple(old_fields) != FIELDS:
            with open(out, "w", newline="") as file:
                writer = csv.DictWriter(file, fieldnames=FIELDS, restval="")
                writer.writeheader()
                writer.writerows({key: r.get(key, "") for key in FIELDS} for r in rows)
    with open(out, "a", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=FIELDS)
        if new:
            writer.writeheader()
        writer.writerow(row)
    print(", ".join(f"{key} {value}" for key, value in row.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
