"""Issue 32: the model-error loop on the community's nonlinear benchmarks, default settings.

    python benchmarks/nonlinear_benchmarks.py --data ../shared/data/nonlinear_benchmarks
        [--out results/nonlinear_benchmarks] [--only CED,EMPS] [--overwrite] [-- LOOP ARGS]

Each benchmark is `jaxcascade loop --benchmark NAME --data ROOT --report OUT/NAME --json`
in a fresh process with the loop's defaults (arguments after `--` are passed on to every
run and recorded), timed, its peak resident memory (`wait4`), its largest count of
memory mappings and the programs it compiled recorded (`brfd.run_loop`). The loop reads
the benchmark's official split (`jc.benchmark_data`, the `nonlinear-benchmarks` loader's),
cuts an estimation and a validation record from the training data by its one rule
(`jaxcascade loop --help`, `--max-samples`), and scores every official test record as
the collection does: free-run simulation, the state set on the first `n_init` samples
from the measured output, RMSE of `y[n_init:]` in the benchmark's unit.

Written as it goes: each finished run leaves OUT/NAME/report.json and resources.json, and
a later call skips it (`--overwrite` runs it again); OUT/summary.csv and OUT/README.md are
rebuilt from every finished run. The published baselines come from the reader
(Champneys et al. 2024); no figure is typed in here.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import subprocess
import sys

sys.path.insert(0, str(pathlib.Path(__file__).parent))

from brfd import run_loop  # noqa: E402

from jaxcascade._benchmark._timing import device_description  # noqa: E402

NAMES = ("CED", "EMPS", "Silverbox")
# Why the model class cannot follow a benchmark, where the final model misses the linear
# figures (the data README's "what each one asks of a cascade model"); the numbers beside
# each sentence come from the run.
# Why a final model misses a linear figure, where something beyond the system's
# mechanisms (`_benchmark_data.MECHANISMS`, which say what a model above the polynomial
# NARX lacks) is known: EMPS's from `emps_reference.py` (`emps_why`).
WHY: dict[str, str] = {}


REFERENCE = "emps_reference.csv"  # benchmarks/emps_reference.py, in OUT


def emps_why(out: pathlib.Path) -> str:
    """Why the loop's model misses EMPS's linear figures, with the figures of the models
    built for its drift (`benchmarks/emps_reference.py`'s OUT/emps_reference.csv)."""
    head = (
        "a position under feedback integrates its input, so the test error is the drift of "
        "the modelled velocity summed over the test record"
    )
    path = out / REFERENCE
    if not path.exists():
        return f"{head} (`python benchmarks/emps_reference.py` measures models built for it)"
    import numpy as np
    import pandas as pd

    table = pd.read_csv(path)
    if "span" not in table:  # written before the script fitted on two spans
        table["span"] = "whole"
    test = table.set_index(["span", "model", "criterion"])["test_rmse"]
    whole = {model: test.get(("whole", model, "position"), np.nan) for model in table["model"]}
    part = {model: test.get(("estimation", model, "position"), np.nan) for model in table["model"]}
    samples = table.loc[table["span"] == "estimation", "samples"]
    return (
        f"{head}. Models built for that drift (`{REFERENCE[:-4]}.md`: order 2 at 1 kHz, "
        "fitted on the position's error) reach, on the whole training record, "
        f"{whole.get('offset', np.nan):.3g} mm as a linear model with a constant force, "
        f"{whole.get('friction', np.nan):.3g} mm with Coulomb friction acting on the "
        f"model's own velocity and {whole.get('stribeck', np.nan):.3g} mm with a Stribeck "
        "term beside it; fitted on the span the loop estimates on (the training record's "
        + (f"first {int(samples.iloc[0])} samples" if len(samples) else "first three quarters")
        + f"), the same models score {part.get('offset', np.nan):.3g}, "
        f"{part.get('friction', np.nan):.3g} and {part.get('stribeck', np.nan):.3g} mm. "
        "The loop's library holds Coulomb friction on the velocity (`velocity_friction`), "
        "fitted on the velocity and polished on the position; over the short validation "
        "record (the training record's last quarter) the candidates' position errors do "
        f"not rank them as the test record does{_ranking(out)}, and the chosen model "
        "drifts about as far as the linear peers"
    )


def _ranking(out: pathlib.Path) -> str:
    """How EMPS's validation record ranked the loop's candidates against the test
    (`benchmarks/emps_candidates.py`'s OUT/emps_candidates.csv), in a parenthesis."""
    path = out / "emps_candidates.csv"
    if not path.exists():
        return " (each run's `candidates.csv`)"
    import pandas as pd
    from emps_candidates import ranking

    table, rho, whole = ranking(pd.read_csv(path))
    return (
        f" (`emps_candidates.md`: over the loop's {len(table)} candidates the validation "
        f"NRMSE's rank correlation with the test RMSE is {rho:.2f}, the whole training "
        f"record's free run's {whole:.2f}; their test RMSE runs from "
        f"{table['test_mm'].min():.3g} to {table['test_mm'].max():.3g} mm)"
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="../shared/data/nonlinear_benchmarks")
    parser.add_argument("--out", default="results/nonlinear_benchmarks")
    parser.add_argument("--only", default=None, help="NAME,NAME of the benchmarks to run")
    parser.add_argument("--overwrite", action="store_true", help="run finished ones again")
    parser.add_argument("extra", nargs="*", help="after --: passed on to jaxcascade loop")
    args = parser.parse_args(argv)
    names = NAMES if args.only is None else tuple(args.only.split(","))
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in names:
        report = out / name
        if (report / "resources.json").exists() and not args.overwrite:
            print(f"{name}: finished earlier ({report}); skipped", file=sys.stderr)
            continue
        run_benchmark(name, args.data, report, args.extra)
        write_summary(out)
    write_summary(out)
    return 0


def run_benchmark(name: str, data, report: pathlib.Path, extra=(), **recorded) -> None:
    """`jaxcascade loop --benchmark NAME --data DATA --report REPORT --json EXTRA` in a
    fresh process (`brfd.run_loop`); its resources, the command, `recorded`, the machine,
    the load before the run, the date and the commit in REPORT/resources.json."""
    report.mkdir(parents=True, exist_ok=True)
    loop = ["loop", "--benchmark", name, "--data", str(data), "--report", str(report)]
    loop += ["--json", *extra]
    print(f"{name}: jaxcascade {' '.join(loop)}", file=sys.stderr, flush=True)
    load = os.getloadavg()[0]
    measured = run_loop(loop)
    stdout = measured.pop("stdout")
    resources = {
        **measured,
        "command": "jaxcascade " + " ".join(loop),
        **recorded,
        "machine": device_description(),
        "load_before": load,
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "commit": _commit(),
    }
    if measured["returncode"] != 0:
        resources["error"] = stdout[-2000:]
    (report / "resources.json").write_text(json.dumps(resources, indent=1))


def _commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


TITLE = "The model-error loop on the nonlinear benchmarks (default settings)"
WRITTEN_BY = (
    "`python benchmarks/nonlinear_benchmarks.py --data ../shared/data/nonlinear_benchmarks`"
)
PUBLISHED = (
    " Published: Champneys et al. (2024), arXiv 2405.10779, the better of its linear "
    "state-space and linear ARX rows."
)


def write_summary(
    out: pathlib.Path,
    why: dict | None = None,
    title: str = TITLE,
    written_by: str = WRITTEN_BY,
    published: str = PUBLISHED,
) -> None:
    """OUT/summary.csv (one row per test set) and OUT/README.md from the finished runs;
    `why` (default `WHY`) says per benchmark why the model class misses a linear figure."""
    why = {**WHY, "EMPS": emps_why(out)} if why is None else why
    import pandas as pd

    rows, notes, covers = [], [], {}
    for folder in sorted(p for p in out.iterdir() if p.is_dir()):
        resources_path = folder / "resources.json"
        if not resources_path.exists():
            continue
        resources = json.loads(resources_path.read_text())
        report_path = folder / "report.json"
        if resources["returncode"] != 0 or not report_path.exists():
            notes.append(
                f"- {folder.name}: the run ended with exit code {resources['returncode']}: "
                f"{(resources.get('error') or '').strip().splitlines()[-1:]}"
            )
            continue
        report = json.loads(report_path.read_text())
        bench = report["benchmark"]
        covers[bench["name"]] = report.get("coverage", {}).get("sentences", [])
        for test in bench["tests"]:
            rows.append(
                {
                    "benchmark": bench["name"],
                    "test": test["record"],
                    "unit": bench["unit"],
                    "n_init": bench["n_init"],
                    "final_rmse": test["test_rmse"],
                    "final_nrmse": test["test_nrmse"],
                    "final_fit_percent": test["test_fit_percent"],
                    "declared_rmse": test["declared_test_rmse"],
                    "arx_rmse": test["arx_test_rmse"],
                    "oe_rmse": test.get("oe_test_rmse"),
                    "polynomial_narx_published": test.get("polynomial_narx_published"),
                    "missing_mechanism": test.get("missing_mechanism"),
                    "best_linear_published": test["best_linear_published"],
                    "beats_arx": test["beats_arx"],
                    "beats_best_linear": test["beats_best_linear"],
                    "structure": report["structure_after"],
                    "effects": ",".join(report["effect_added"]) or "none",
                    "seconds": round(resources["seconds"], 1),
                    "peak_rss_mb": round(resources["peak_rss_mb"]),
                    "programs_compiled": report["programs_compiled"],
                    "decimation": bench["decimation"],
                    "max_samples": bench["max_samples"],
                    "loader": bench["loader"],
                    "commit": resources["commit"],
                    "machine": resources["machine"],
                    "load_before": round(resources["load_before"], 2),
                    "date": resources["date"],
                    "command": resources["command"],
                }
            )
    table = pd.DataFrame(rows)
    table.to_csv(out / "summary.csv", index=False)
    lines = [
        f"# {title}",
        "",
        f"Written by {written_by} (each run's command, machine, load, date and "
        "commit in `summary.csv` and `NAME/resources.json`; each run's report in `NAME/`).",
        "Test RMSE in the benchmark's unit: free-run simulation, the state set from the "
        f"measured output on the first `n_init` samples, RMSE of `y[n_init:]`.{published}",
        "",
        "| benchmark | test | unit | final model | declared cascade | output-error peer "
        "(this run) | ARX peer (this run) | best linear (published) | polynomial NARX "
        "(published) | below every linear | effects | s | peak RSS MB | programs |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]

    def number(value):
        return "-" if value is None or value != value else f"{value:.4g}"

    for r in rows:
        # below the output-error and ARX peers and the published figure (where there is one)
        below = (
            r["beats_arx"]
            and r["beats_best_linear"] is not False
            and (r["oe_rmse"] is None or r["final_rmse"] <= r["oe_rmse"])
        )
        lines.append(
            f"| {r['benchmark']} | {r['test']} | {r['unit']} | {r['final_rmse']:.4g} | "
            f"{r['declared_rmse']:.4g} | {number(r['oe_rmse'])} | {r['arx_rmse']:.4g} | "
            f"{number(r['best_linear_published'])} | "
            f"{number(r['polynomial_narx_published'])} | {'yes' if below else 'no'} | "
            f"{r['effects']} | {r['seconds']} | {r['peak_rss_mb']} | {r['programs_compiled']} |"
        )
    missing = [r for r in rows if r.get("missing_mechanism")]
    if missing:
        lines += [
            "",
            "Where the final model stays above the published polynomial NARX, the mechanism "
            "its system has that the loop's library does not hold (`_benchmark_data."
            "MECHANISMS`, each run's report):",
            "",
        ]
        lines += [f"- {r['benchmark']} {r['missing_mechanism']}" for r in missing]
    misses = [
        r
        for r in rows
        if not (
            r["beats_arx"]
            and r["beats_best_linear"] is not False
            and (r["oe_rmse"] is None or r["final_rmse"] <= r["oe_rmse"])
        )
    ]
    if misses:
        from jaxcascade._measured._benchmark_data import MECHANISMS

        lines += ["", "Where the final model is not below every linear figure, and why:", ""]
        for r in misses:
            reason = why.get(r["benchmark"]) or (
                f"the system has {MECHANISMS[r['benchmark']]}"
                if r["benchmark"] in MECHANISMS
                else "not known"
            )
            lines.append(
                f"- {r['benchmark']} {r['test']}: {r['final_rmse']:.4g} {r['unit']} against "
                f"the output-error peer's {number(r['oe_rmse'])}, the ARX peer's "
                f"{r['arx_rmse']:.4g} and the best published linear "
                f"{number(r['best_linear_published'])}: {reason}."
            )
        # what the run's report says of its records' input coverage (`_measured._coverage`)
        for name in dict.fromkeys(r["benchmark"] for r in misses):
            if covers.get(name):
                lines += ["", f"The input coverage of {name}'s run (its report):", ""]
                lines += [f"- {sentence}" for sentence in covers[name]]
    if notes:
        lines += ["", "Runs that did not finish:", "", *notes]
    (out / "README.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(main())
