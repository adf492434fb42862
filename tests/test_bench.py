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

from jaxcascade import _fused
from jaxcascade._benchmark import _flops
from jaxcascade._benchmark._timing import SUMMARY_KEYS
from jaxcascade._cli import main
from jaxcascade._model import Orders

TINY = ["--realisations", "8", "--n", "300", "--iterations", "3"]
FAST = ["--baseline-realisations", "3", "--matmul-size", "128", "--repeats", "1"]
ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_bench_json_is_sane(capsys, tmp_path):
    out = tmp_path / "bench.csv"
    assert main(["bench", *TINY, *FAST, "--json", "--out", str(out)]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert tuple(figures) == SUMMARY_KEYS
    for key in SUMMARY_KEYS[:-1]:
        assert math.isfinite(figures[key]) and figures[key] > 0, key
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
    flops = _flops.flops_per_fit(Orders(), 300, 3)["total"]
    assert int(row["flops_per_fit"]) == flops


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
