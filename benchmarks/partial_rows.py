"""Rows of a long benchmark written as they finish, so that a run resumes after a crash.

A script opens `OUT.rows.jsonl` with `open_rows(out, settings, key, fresh)`: its first
line is the run's settings, every later line one finished row. A run started again
with the same settings gets the finished rows back (by `key(row)`); other settings, or
`fresh`, start the file over. `append` writes a row as it finishes; the script removes
the file once its tables are written.
"""

from __future__ import annotations

import json
import pathlib


def open_rows(out: pathlib.Path, settings: dict, key, fresh: bool = False):
    """`(done, partial)`: the finished rows of an earlier run with these settings, by
    `key(row)`, and the rows file (`out` with suffix `.rows.jsonl`)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_suffix(".rows.jsonl")
    done = {}
    if partial.exists() and not fresh:
        lines = [json.loads(line) for line in partial.read_text().splitlines() if line]
        if lines and lines[0] == settings:
            done = {key(row): row for row in lines[1:]}
            print(f"resuming: {len(done)} records from {partial}", flush=True)
    if not done:
        partial.write_text(json.dumps(settings) + "\n")
    return done, partial


def append(partial: pathlib.Path, row: dict) -> None:
    """Write one finished row (and print it)."""
    print(row, flush=True)
    with partial.open("a") as stream:
        stream.write(json.dumps(row) + "\n")
