"""Issue 32, point 5: do the damper models carry over to records they were not fitted on?

    python benchmarks/brfd_amplitude.py --data ../shared/data/brfd --runs results/brfd \
        --out results/brfd/amplitude

Each run of `benchmarks/brfd.py` leaves its final model in `RUNS/<run>/model.json`
(`jaxcascade loop --report`). This applies every such model, as `jaxcascade simulate`
does, to every shared damper record the run did not estimate on: the harmonic tests at
the other band tension (36 lb: the runs estimate on the 30 lb tests), at every amplitude
(0.5, 1 and 1.5 in) and frequency, and the earthquakes it only validated or tested on.
Each record is read at the model's decimation and scaling, its state set from the
measured force on the model's initialisation window, and scored by NRMSE on the rest
(from rest beside). Writes OUT.csv (one row per run and record) and OUT.md: per run, the
validation figure the loop chose by, the held-out records' NRMSE by tension and amplitude
(median and worst), and each record's row.
"""

from __future__ import annotations

import argparse
import json
import pathlib

EARTHQUAKES = {
    "earthquake_imperialvalley_dbe.csv": "imperialvalley",
    "earthquake_kocaeli_dbe.csv": "kocaeli",
}


def records(data: pathlib.Path):
    """`(path, kind, tension_lb, amplitude_in, frequency_hz)` of every damper record."""
    import pandas as pd

    index = pd.read_csv(data / "characterization" / "index.csv")
    for row in index.itertuples():
        yield (
            data / "characterization" / row.file,
            "harmonic",
            int(row.band_tension_lb),
            float(row.amplitude_in),
            float(row.frequency_hz),
        )
    for name in EARTHQUAKES:
        yield data / name, "earthquake", None, None, None


def _used(report: dict) -> dict[str, str]:
    """The file names a run used, by role (estimation, validation, test)."""
    roles = {}
    recs = report.get("records", {})
    for role in ("estimation", "validation", "test"):
        entries = recs.get(role) or []
        if isinstance(entries, dict):
            entries = [entries]
        for entry in entries:
            name = pathlib.Path(str(entry.get("source", ""))).name.split(":")[0]
            roles.setdefault(name, role)
    return roles


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="../shared/data/brfd")
    parser.add_argument("--runs", default="results/brfd")
    parser.add_argument("--out", default="results/brfd/amplitude")
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import pandas as pd

    import jaxcascade as jc
    from jaxcascade._data import read_record

    data, runs = pathlib.Path(args.data), pathlib.Path(args.runs)
    folders = sorted(p.parent for p in runs.glob("*/model.json"))
    if not folders:
        raise SystemExit(f"no run with a model.json under {runs}: run benchmarks/brfd.py first")
    rows, validation = [], {}
    for folder in folders:
        saved = jc.load_model(folder / "model.json")
        report = json.loads((folder / "report.json").read_text())
        used = _used(report)
        validation[folder.name] = [
            (s["record"], s["window_error"], s["error"])
            for s in report["scores"]
            if s["role"] == "validation" and s["model"] == "final model"
        ]
        for path, kind, tension, amplitude, frequency in records(data):
            role = used.get(path.name, "held out")
            if role == "estimation":
                continue
            record = read_record(
                path,
                "displacement_in",
                "force_kip",
                time_column="time_s",
                decimate=saved.decimation,
                anti_alias=saved.anti_alias,
                detrend=saved.detrend,
                scaling=saved.scaling,
            )
            s = saved.compare(record).score
            rows.append(
                {
                    "run": folder.name,
                    "record": EARTHQUAKES.get(path.name, path.stem),
                    "kind": kind,
                    "tension_lb": tension,
                    "amplitude_in": amplitude,
                    "frequency_hz": frequency,
                    "role": role,
                    "structure": saved.model.structure(),
                    "nrmse": s.error,
                    "nrmse_from_rest": s.error_from_rest,
                    "rmse_kip": s.rmse,
                    "init_samples": s.init_samples,
                }
            )
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out.with_suffix(".csv"), index=False)
    command = (
        f"python benchmarks/brfd_amplitude.py --data {args.data} --runs {args.runs} "
        f"--out {args.out}"
    )
    lines = [
        "# The damper's models on records they were not estimated on",
        "",
        f"Command: `{command}`. Each run's final model (`model.json`) applied as "
        "`jaxcascade simulate` applies it: the record read at the model's decimation and "
        "scaling, the state set from the measured force on the model's initialisation "
        "window, NRMSE on the rest of the record (1 is the mean of the output; from rest "
        "beside). The runs estimate on the 30 lb harmonic tests (and one earthquake, or "
        "all 21 records in the `all21` run); the 36 lb tests are another band tension of "
        "the same device, at every amplitude.",
        "",
        "## Per run: the validation figure it was chosen by, and the held-out records",
        "",
        "| run | structure | validation window NRMSE | 36 lb tests: median NRMSE "
        "(0.5 / 1 / 1.5 in) | 36 lb tests: worst | earthquakes not estimated on |",
        "|---|---|---|---|---|---|",
    ]
    for run, group in table.groupby("run", sort=False):
        held = group[(group.kind == "harmonic") & (group.tension_lb == 36)]
        by_amplitude = " / ".join(
            f"{held[held.amplitude_in == a].nrmse.median():.3f}"
            if (held.amplitude_in == a).any()
            else "-"
            for a in (0.5, 1.0, 1.5)
        )
        quakes = "; ".join(
            f"{r.record} ({r.role}) {r.nrmse:.3f}"
            for r in group[group.kind == "earthquake"].itertuples()
        )
        valid = "; ".join(
            f"{name} {w:.3f}" if w is not None else f"{name} {e:.3f}"
            for name, w, e in validation[run]
        )
        worst = f"{held.nrmse.max():.3f}" if len(held) else "-"
        lines.append(
            f"| {run} | `{group.structure.iloc[0]}` | {valid} | {by_amplitude} | {worst} | "
            f"{quakes or '-'} |"
        )
    lines += [
        "",
        "## Every record",
        "",
        "| run | record | role | tension lb | amplitude in | Hz | NRMSE | NRMSE from rest | "
        "RMSE kip |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in table.itertuples():

        def f(value, fmt):
            return (
                "-"
                if value is None or (isinstance(value, float) and np.isnan(value))
                else (format(value, fmt))
            )

        lines.append(
            f"| {r.run} | {r.record} | {r.role} | {f(r.tension_lb, '.0f')} | "
            f"{f(r.amplitude_in, 'g')} | {f(r.frequency_hz, 'g')} | {r.nrmse:.3f} | "
            f"{r.nrmse_from_rest:.3f} | {r.rmse_kip:.3g} |"
        )
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
