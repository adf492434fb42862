"""`jaxcascade bench` runs end to end on a tiny workload and its figures are consistent.

A benchmark, not a timed test: nothing here asserts a speed.
"""

import csv
import json
import math
import pathlib
import subprocess
import sys

import pytest

from jaxcascade._benchmark import _flops
from jaxcascade._benchmark._timing import SUMMARY_KEYS
from jaxcascade._cli import main
from jaxcascade._estimator import _fused
from jaxcascade._system._model import Orders

TINY = ["--realisations", "8", "--n", "300", "--iterations", "3"]
FAST = ["--baseline-realisations", "3", "--matmul-size", "128", "--repeats", "1"]
ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_bench_json_is_sane(capsys, tmp_path):
    out = tmp_path / "bench.csv"
    assert main(["bench", *TINY, *FAST, "--json", "--out", str(out)]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert tuple(figures) == SUMMARY_KEYS
    for key in SUMMARY_KEYS[: SUMMARY_KEYS.index("device")]:
        assert math.isfinite(figures[key]) and figures[key] > 0, key
    assert figures["floor_count"] == _flops.FLOOR_COUNT
    assert figures["load"] >= 0
    assert figures["workers"] >= 1  # host threads the realisations were split over
    assert figures["ratio"] == pytest.approx(
        figures["fits_per_s"] / figures["baseline_fits_per_s"], rel=1e-12
    )
    assert figures["floor_fraction"] < 1  # a tiny run cannot beat the floor
    assert figures["peak_mem_mb"] > 50  # RSS, in MB, of a process that imported JAX
    assert isinstance(figures["device"], str) and figures["device"]
    with open(out) as file:
        (row,) = list(csv.DictReader(file))
    assert float(row["fits_per_s"]) == pytest.approx(figures["fits_per_s"])
    assert row["dtype"] == "float64"
    assert row["backend"] == ("fused" if _fused.available() else "xla")
    assert (int(row["n"]), int(row["realisations"]), int(row["iterations"])) == (300, 8, 3)
    # the floor's count is the standard one, 3 x (2 N P^2 + 2 N P) for 3 iterations
    assert int(row["flops_per_fit"]) == 3 * (2 * 300 * 12**2 + 2 * 300 * 12)
    assert int(row["flops_per_fit_detailed"]) == _flops.flops_per_fit(Orders(), 300, 3)["total"]


def test_bench_xla_backend_runs(capsys, tmp_path):
    # the reference path stays benchmarkable next to the fused kernel
    out = tmp_path / "bench.csv"
    assert main(["bench", *TINY, *FAST, "--backend", "xla", "--out", str(out)]) == 0
    assert "xla normal equations" in capsys.readouterr().out
    with open(out) as file:
        (row,) = list(csv.DictReader(file))
    assert row["backend"] == "xla" and float(row["fits_per_s"]) > 0


def test_bench_rejects_bad_values(capsys):
    assert main(["bench", "--n", "10"]) == 2
    assert "--n must be at least" in capsys.readouterr().err


def test_flop_count_of_the_workload():
    terms = _flops.flops_per_fit(Orders(2, 2, 2, 2), n=4000, iterations=20)
    n, P = 4000, 12
    assert terms["full steps: gram"] == 19 * n * P * (P + 1)  # symmetric Gram, 19 full steps
    assert terms["first step: gram"] == n * (P - 3) * (P - 2)
    assert terms["total"] == sum(v for k, v in terms.items() if k != "total")
    assert 0.6 < terms["full steps: gram"] / terms["total"] < 0.7  # the Gram matrix dominates
    # linear in N and, past the first step, in the iterations
    double = _flops.flops_per_fit(Orders(), n=8000, iterations=20)["total"]
    assert abs(double - 2 * terms["total"]) < 100_000


def test_scaling_runner_on_tiny_sizes(tmp_path):
    out, figure = tmp_path / "scaling.csv", tmp_path / "scaling.png"
    command = [sys.executable, str(ROOT / "benchmarks" / "scaling.py")]
    command += ["--realisations", "4,8", "--n", "200", "--fixed-n", "200"]
    command += ["--fixed-realisations", "4", "--iterations", "2", "--repeats", "1"]
    command += ["--out", str(out), "--plot", str(figure)]
    subprocess.run(command, check=True, capture_output=True, timeout=600)
    with open(out) as file:
        rows = list(csv.DictReader(file))
    assert [(r["sweep"], r["realisations"], r["n"]) for r in rows] == [
        ("realisations", "4", "200"),
        ("realisations", "8", "200"),
        ("n", "4", "200"),
    ]
    for row in rows:
        assert row["error"] == ""
        assert float(row["peak_mem_mb"]) >= float(row["base_mem_mb"]) > 0
        assert float(row["fits_per_s"]) > 0
    assert figure.stat().st_size > 0


def test_bench_robust_json_keys(capsys):
    from jaxcascade._benchmark._robust import SUMMARY_KEYS as ROBUST_KEYS

    argv = ["bench", "--estimator", "robust", "--system", "random", "--realisations", "2"]
    argv += ["--n", "300", "--baseline-realisations", "1", "--repeats", "1", "--json"]
    assert main(argv) == 0
    figures = json.loads(capsys.readouterr().out)
    assert tuple(figures) == ROBUST_KEYS
    assert (figures["estimator"], figures["system"]) == ("robust", "random")
    for key in ("fits_per_s", "compile_s", "baseline_fits_per_s", "ratio"):
        assert math.isfinite(figures[key]) and figures[key] > 0, key
    assert 0 <= figures["recovered"] <= 1
    assert figures["ratio"] == pytest.approx(
        figures["fits_per_s"] / figures["baseline_fits_per_s"], rel=1e-12
    )


def test_bench_history_appends_a_row_per_summary(tmp_path):
    # results/bench_history.csv: one row per regeneration, the header written once
    summary = tmp_path / "bench.json"
    history = tmp_path / "history.csv"
    figures = {
        "fits_per_s": 1234.5,
        "ratio": 40.0,
        "floor_fraction": 0.3,
        "compile_s": 1.0,
        "device": "cpu: some CPU (2 cores)",
        "floor_count": _flops.FLOOR_COUNT,
        "load": 1.5,
    }
    summary.write_text(json.dumps(figures))
    command = [sys.executable, str(ROOT / "benchmarks" / "bench_history.py"), str(summary)]
    for _ in range(2):
        subprocess.run([*command, "--out", str(history)], check=True, capture_output=True)
    with open(history) as file:
        rows = list(csv.DictReader(file))
    assert len(rows) == 2
    assert rows[0]["machine"] == figures["device"] and float(rows[0]["fits_per_s"]) == 1234.5
    assert rows[0]["floor_count"] == _flops.FLOOR_COUNT and float(rows[0]["load"]) == 1.5
    assert rows[0]["commit"]  # this checkout's HEAD


def test_bench_splits_the_realisations_over_the_workers_asked_for(capsys):
    assert main(["bench", *TINY, *FAST, "--workers", "2", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["workers"] == 2 and figures["fits_per_s"] > 0


@pytest.mark.parametrize(
    "arguments, says",
    [
        (["--workers", "0"], "--workers must be at least 1"),
        (["--workers", "2", "--estimator", "robust"], "--workers applies to --estimator literal"),
    ],
)
def test_bench_workers_refused_cleanly(capsys, arguments, says):
    assert main(["bench", *TINY, *FAST, *arguments]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err and "Traceback" not in err
