"""Monte-Carlo engine: batching, keys, resumability, summaries, comparisons, specs.

Sizes are tiny (N = 300, a few realisations): these tests check the machinery, not the
estimator. Every spec shares N = 300 and chunk size 3 where it can, so most tests reuse
one compilation.
"""

import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest

import jaxcascade
from jaxcascade._cli import main
from jaxcascade._montecarlo._engine import (
    cell_identity,
    chunk_memory,
    run_chunk,
    run_realisation,
)
from jaxcascade._montecarlo._run import run, summary_path
from jaxcascade._montecarlo._spec import Cell, Spec
from jaxcascade._montecarlo._tables import (
    compare_sweeps,
    read_metadata,
    summarise,
    without_timing,
)

N = 300


def assert_same_table(got, want, spec=None, **columns):
    """Tables of the same records: bit for bit where the CPU forms each record's normal
    equations alone (the fused kernel) and runs the sequential scans; elsewhere (an
    accelerator, or XLA's normal equations) to rounding, since XLA may sum a batched
    product in another order for another batch shape (`_estimator._normal_equations`)."""
    from jaxcascade._montecarlo._engine import normal_equations_backend
    from jaxcascade._system import _scans

    spec = spec or small_spec()
    if normal_equations_backend(spec) == "fused" and not _scans.parallel():
        pd.testing.assert_frame_equal(got, want, check_exact=True)
    else:
        pd.testing.assert_frame_equal(got, want, check_exact=False, rtol=1e-9, atol=1e-12)


def small_spec(**changes) -> Spec:
    fields = dict(example=1, n=N, snr=[25.0], realisations=8, seed=0, chunk_size=3)
    return Spec(**{**fields, **changes})


# ---- batching and keys -------------------------------------------------------------------


def test_vmapped_chunk_equals_python_loop():
    spec = small_spec()
    cell = spec.cells()[0]
    table = run_chunk(spec, cell, [0, 1, 2])
    names = spec.orders.names
    for row, index in zip(table.itertuples(), [0, 1, 2], strict=True):
        one = run_realisation(spec, cell, index)
        # Same operations, batched or not; only XLA's fusion choices differ (float64).
        np.testing.assert_allclose(
            [getattr(row, name) for name in names], one["estimate"], rtol=1e-9, atol=1e-12
        )
        assert (
            row.status
            == ("converged", "max_iterations", "diverged", "singular", "left_domain", "failed")[
                int(one["status"])
            ]
        )
        assert row.iterations == int(one["iterations"])
        assert row.key == one["key"]
        np.testing.assert_allclose(row.nrmse, one["nrmse"], rtol=1e-9)


def test_table_independent_of_chunk_size_and_order():
    spec3 = small_spec(snr=[25.0, 50.0])
    spec7 = small_spec(snr=[25.0, 50.0], chunk_size=7)
    a = without_timing(run(spec3, progress=False))
    b = without_timing(run(spec7, progress=False))
    # The estimates are bit-identical; the Cramer-Rao bound is a batched matrix product,
    # whose summation order XLA picks by batch shape: equal to rounding.
    bound = [c for c in a.columns if c.startswith("crlb_")]
    assert bound
    assert_same_table(a.drop(columns=bound), b.drop(columns=bound))
    pd.testing.assert_frame_equal(a[bound], b[bound], check_exact=False, rtol=1e-12, atol=0)
    # Realisation 5 alone, in another batch position, gives the same row.
    cell = spec3.cells()[1]
    alone = without_timing(run_chunk(spec3, cell, [5]))
    row = a[(a["snr"] == cell.snr) & (a["realisation"] == 5)].reset_index(drop=True)
    assert_same_table(alone.drop(columns=bound), row.drop(columns=bound))
    pd.testing.assert_frame_equal(alone[bound], row[bound], check_exact=False, rtol=1e-12, atol=0)
    # Different cells and realisations get different records.
    assert a["key"].nunique() == len(a)
    assert set(a.columns) >= {"status", "iterations", "cost", "nrmse", "MR1", "true_MR1"}
    assert np.all(np.isfinite(a["nrmse"]) | (a["nrmse"] == np.inf))


def test_chunks_in_threads_give_the_same_table_and_lose_nothing_on_a_failure(tmp_path, monkeypatch):
    # `workers` chunks at once in host threads: every chunk keeps its shape, so the table
    # equals the one-at-a-time run exactly (the bound included)
    one = without_timing(run(small_spec(snr=[25.0, 50.0]), progress=False))
    two = without_timing(run(small_spec(snr=[25.0, 50.0], workers=2), progress=False))
    assert_same_table(two, one)

    # a chunk that fails stops the run after the chunks beside it finished and were
    # written; the resumed run (one worker: not part of the identity) completes the table
    from jaxcascade._montecarlo import _run

    def failing(spec, cell, indices):
        if cell.snr == 50.0 and 3 in indices:
            raise RuntimeError("a chunk failed")
        return run_chunk(spec, cell, indices)

    out = tmp_path / "threads.parquet"
    monkeypatch.setattr(_run, "run_chunk", failing)
    with pytest.raises(RuntimeError, match="a chunk failed"):
        run(small_spec(snr=[25.0, 50.0], workers=2), out, progress=False)
    written = list((tmp_path / "threads.parquet.partial").glob("chunk-*.parquet"))
    assert len(written) >= 4 and not out.exists()  # the SNR 25 cell (3 chunks) at least
    monkeypatch.undo()
    table = run(small_spec(snr=[25.0, 50.0]), out, progress=False)
    assert_same_table(without_timing(table), one)


def test_estimators_see_the_same_records():
    # The data key leaves out the estimator (common random numbers), so the key column
    # of a cell is the same whatever the estimator; the seed changes it.
    spec = small_spec(realisations=3)
    other = small_spec(realisations=3, seed=1)
    cell = spec.cells()[0]
    a, b = run_chunk(spec, cell, [0, 1, 2]), run_chunk(other, cell, [0, 1, 2])
    assert not np.any(a["key"].to_numpy() == b["key"].to_numpy())


# ---- summaries ---------------------------------------------------------------------------


def synthetic_table() -> pd.DataFrame:
    # One cell: 4 admissible estimates 1, 2, 3, 4 of a parameter whose truth is 2, plus
    # one inadmissible realisation and one that accepted no step (its estimate is the
    # initial guess); neither enters the moments, both count in the rates.
    estimates = [1.0, 2.0, 3.0, 4.0, 1e9, 0.0]
    return pd.DataFrame(
        {
            "system": "example1",
            "n": 300,
            "snr": 25.0,
            "estimator": "literal",
            "status": [
                "converged",
                "converged",
                "max_iterations",
                "converged",
                "diverged",
                "singular",
            ],
            "iterations": [5, 6, 50, 7, 3, 0],
            "admissible": [True, True, True, True, False, True],
            "recovered": [False, True, False, False, False, False],
            "nrmse": [0.1, 0.2, 0.3, 0.4, np.inf, 1.0],
            "X": estimates,
            "true_X": 2.0,
        }
    )


def test_summary_statistics_and_standard_errors():
    row = summarise(synthetic_table()).iloc[0]
    s = np.std([1, 2, 3, 4], ddof=1)
    assert (row["count"], row["used"]) == (6, 4)
    assert row["mean"] == pytest.approx(2.5)
    assert row["bias"] == pytest.approx(0.5)
    assert row["bias_se"] == pytest.approx(s / 2)
    assert row["std"] == pytest.approx(s)
    assert row["std_se"] == pytest.approx(s / np.sqrt(6))
    squared = np.array([1.0, 0.0, 1.0, 4.0])
    assert row["rmse"] == pytest.approx(np.sqrt(1.5))
    assert row["rmse_se"] == pytest.approx(np.std(squared, ddof=1) / 2 / (2 * np.sqrt(1.5)))
    assert row["converged_rate"] == pytest.approx(0.5)
    assert row["converged_rate_se"] == pytest.approx(np.sqrt(0.5 * 0.5 / 6))
    assert row["recovered_rate"] == pytest.approx(1 / 6)
    assert row["recovered_rate_se"] == pytest.approx(np.sqrt(1 / 6 * 5 / 6 / 6))
    counts = [row[f"count_{s}"] for s in ("converged", "max_iterations", "diverged", "singular")]
    assert counts == [3, 1, 1, 1]
    assert row["nrmse_median"] == pytest.approx(0.35)


def test_compare_sweeps_flags_a_shifted_bias_and_passes_an_identical_baseline():
    summary = summarise(synthetic_table())
    assert not compare_sweeps(summary, summary)["flagged"].any()
    shifted = summary.copy()
    shifted["bias"] += 4 * np.sqrt(2) * shifted["bias_se"]  # 4 combined SEs away
    result = compare_sweeps(summary, shifted)
    flagged = result[result["flagged"]]
    assert list(flagged["statistic"]) == ["bias"] and list(flagged["parameter"]) == ["X"]
    nudged = summary.copy()
    nudged["bias"] += 1 * nudged["bias_se"]  # within Monte-Carlo error
    assert not compare_sweeps(summary, nudged)["flagged"].any()
    elsewhere = summary.assign(n=999)
    with pytest.raises(ValueError, match="shares no grid cell"):
        compare_sweeps(summary, elsewhere)


def test_compare_is_a_deprecated_alias_of_compare_sweeps():
    # `compare` compared two sweeps; MATLAB's `compare` compares a model with data: renamed,
    # the old name kept one release, warning
    summary = summarise(synthetic_table())
    shifted = summary.copy()
    shifted["bias"] += 4 * np.sqrt(2) * shifted["bias_se"]
    with pytest.warns(DeprecationWarning, match="compare_sweeps"):
        old = jaxcascade.compare(summary, shifted)
    pd.testing.assert_frame_equal(old, compare_sweeps(summary, shifted))


# ---- specs -------------------------------------------------------------------------------


def test_spec_toml_round_trip(tmp_path):
    text = """
example = 2
n = [300, 600]
snr = [10, inf]
realisations = 4
seed = 3
estimators = ["literal"]
chunk_size = 2
workers = 2
[input]
amplitude = 2.0
[estimator.literal]
max_iterations = 20
"""
    path = tmp_path / "spec.toml"
    path.write_text(text)
    spec = Spec.load(path)
    assert spec.n == (300, 600) and spec.snr == (10.0, np.inf) and spec.workers == 2
    # how the sweep runs is not what it computes: a resumed run may change it
    assert "workers" not in spec.to_dict(chunk_size=False)
    assert spec.settings == {"literal": {"max_iterations": 20}}
    assert Spec.from_dict(spec.to_dict()) == spec
    assert [c.n for c in spec.cells()] == [300, 300, 600, 600]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--n", "20"], "too small for orders"),
        (["--snr", "0"], "SNR must be positive"),
        (["--snr", "25,-1"], "SNR must be positive"),
        (["--realisations", "0"], "'realisations' must be an integer >= 1"),
        (["--workers", "0"], "'workers' must be an integer >= 1"),
        (["--estimator", "nonsense"], "Unknown estimator 'nonsense'"),
        (["--example", "3"], "Unknown example 3"),
    ],
)
def test_bad_specs_fail_before_any_file_is_written(tmp_path, capsys, extra, message):
    out = tmp_path / "run" / "r.parquet"
    argv = ["sweep", "--example", "1", "--n", "300", "--snr", "25", "--realisations", "2"]
    assert main([*argv, *extra, "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("example = 1\nrealisation = 5\n", "Unknown spec field 'realisation'"),
        ("example = 1\n[input]\namp = 2\n", "Unknown field 'amp' in [input]"),
        ("example = 1\n[estimator.literal]\nmax_iter = 5\n", "Unknown setting 'max_iter'"),
        (
            "[system]\nparams = {MR1 = 1.0, ML1 = 1.0, cL = 0.1, mR = 1.0, cR = 0.1}\n",
            "needs the sample sizes",
        ),
        ("example = 1\nn = 300\nsnr = [25, 25]\n", "repeats a value"),
        # a plain value where a table belongs: the message names the key likely meant
        ('example = 1\nn = 300\nestimator = "robust"\n', 'estimators = ["robust"]'),
        (
            'example = 1\nn = 300\nestimator = ["literal", "robust"]\n',
            'estimators = ["literal", "robust"]',
        ),
        ("example = 1\nn = 300\ninput = 3.0\n", "[input] amplitude = 3.0"),
        ('example = 1\nn = 300\ninput = "uniform"\n', '[input] kind = "uniform"'),
        ('example = 1\nn = 300\nnoise = "ar"\n', '[noise] kind = "ar"'),
        ('example = 1\nn = 300\n[input]\nkind = "sine"\n', "Unknown input kind 'sine'"),
        ('example = 1\nn = 300\n[noise]\nkind = "ar"\npole = 0.9\n', "Unknown field 'pole'"),
        ('example = 1\nn = 300\n[noise]\nkind = "ar"\npoles = [1.0]\n', "every pole"),
        ('example = 1\nn = 300\n[input]\nkind = "gaussian"\namplitude = 2\n', "'amplitude'"),
    ],
)
def test_bad_spec_files(tmp_path, capsys, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "run" / "r.parquet"
    assert main(["sweep", str(path), "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_explicit_system_spec():
    values = {"MR1": 1.0, "ML1": 0.5, "b1": -0.3, "cL": 0.1, "mR": 1.1, "cR": 0.2}
    spec = Spec(params=values, n=[300], realisations=2)
    assert str(spec.orders) == "1,1,1,1" and spec.system == "custom"
    assert spec.true_values() == values


# ---- command line, resumability, comparison ----------------------------------------------


def sweep_argv(out, *extra):
    return [
        "sweep", "--example", "1", "--n", str(N), "--snr", "25,50", "--realisations", "30",
        "--seed", "0", "--chunk-size", "3", "--out", str(out), *extra,
    ]  # fmt: skip


def test_killed_run_resumes_to_an_identical_table(tmp_path, capsys):
    reference = tmp_path / "reference.parquet"
    assert main(sweep_argv(reference)) == 0
    expected = without_timing(pd.read_parquet(reference))
    assert len(expected) == 60 and not (tmp_path / "reference.parquet.partial").exists()
    meta = read_metadata(reference)
    assert meta["dtype"] == "float64" and meta["spec"]["snr"] == [25.0, 50.0]
    assert {"jaxcascade", "jax", "numpy", "command"} <= set(meta)
    assert meta["normal_equations"] in ("fused", "xla")
    # every setting of the estimator is on record, defaults included
    from jaxcascade._estimator import ESTIMATORS

    assert set(meta["estimator_settings"]) == {"literal"}
    assert set(meta["estimator_settings"]["literal"]) == set(ESTIMATORS["literal"].settings())
    assert meta["estimator_settings"]["literal"]["cycle_period"] == 16

    out = tmp_path / "killed.parquet"
    partial = tmp_path / "killed.parquet.partial"
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    command = [sys.executable, "-m", "jaxcascade", *sweep_argv(out)]
    process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not list(partial.glob("chunk-*.parquet")):
        assert process.poll() is None, process.stderr.read().decode()
        assert time.monotonic() < deadline, "no chunk written within 120 s"
        time.sleep(0.005)
    process.send_signal(signal.SIGKILL)
    process.wait()
    process.stderr.close()
    written = len(list(partial.glob("chunk-*.parquet")))
    assert not out.exists() and 1 <= written < 20, written  # killed part-way

    # A different spec may not continue it.
    assert main([*sweep_argv(out), "--seed", "1"]) == 2
    assert "different spec" in capsys.readouterr().err

    assert main([*sweep_argv(out), "--resume"]) == 0
    assert_same_table(without_timing(pd.read_parquet(out)), expected)
    assert not partial.exists()

    # A finished run is reused only on request.
    assert main(sweep_argv(out)) == 2
    assert "already exists" in capsys.readouterr().err

    # --compare: the same summary passes; a baseline with a shifted bias fails (exit 1).
    baseline = summary_path(reference)
    assert main([*sweep_argv(out), "--resume", "--compare", str(baseline)]) == 0
    shifted = pd.read_csv(baseline)
    pick = (shifted["parameter"] == "cR") & (shifted["snr"] == 50.0)
    shifted.loc[pick, "bias"] += 10 * shifted.loc[pick, "bias_se"] + 1e-3
    shifted_path = tmp_path / "shifted.summary.csv"
    shifted.to_csv(shifted_path, index=False)
    capsys.readouterr()
    assert main([*sweep_argv(out), "--resume", "--compare", str(shifted_path)]) == 1
    report = capsys.readouterr().out
    assert "1 of" in report and " cR " in report


def test_overwrite_replaces_a_finished_run_and_says_so(tmp_path, capsys):
    out = tmp_path / "runs" / "q.parquet"
    argv = [
        "sweep", "--example", "1", "--n", str(N), "--snr", "25", "--realisations", "3",
        "--seed", "0", "--chunk-size", "3", "--out", str(out), "--overwrite",
    ]  # fmt: skip
    assert main(argv) == 0
    first = capsys.readouterr().out
    assert "replacing" not in first  # nothing to replace yet
    table = without_timing(pd.read_parquet(out))
    assert main(argv) == 0
    assert f"replacing the previous '{out}'" in capsys.readouterr().out
    pd.testing.assert_frame_equal(without_timing(pd.read_parquet(out)), table)
    # neither flag: refused, naming both; both flags: refused
    plain = [a for a in argv if a != "--overwrite"]
    assert main(plain) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main([*argv, "--resume"]) == 2
    assert "not both" in capsys.readouterr().err
    # a partial folder of another spec is cleared, not continued or refused
    other = [*plain[:8], "4", *plain[9:]]  # 4 realisations
    (out.parent / "q.parquet.partial").mkdir()
    (out.parent / "q.parquet.partial" / "spec.json").write_text("{}")
    assert main([*other, "--overwrite"]) == 0
    assert len(pd.read_parquet(out)) == 4
    assert not (out.parent / "q.parquet.partial").exists()


def test_chunk_memory_is_reported():
    spec = small_spec()
    sizes = chunk_memory(spec, spec.cells()[0])
    assert sizes["total"] >= sizes["temp"] > 0


@pytest.mark.slow
def test_chunk_memory_grows_linearly_in_chunk_size_and_n():
    spec = small_spec()
    totals = {
        (c, n): chunk_memory(spec, Cell(n, 25.0, "literal"), c)["temp"]
        for c in (4, 8)
        for n in (300, 600)
    }
    # Doubling either the chunk or N at most doubles XLA's temporary buffers (+ slack).
    assert totals[(8, 300)] <= 2.1 * totals[(4, 300)]
    assert totals[(4, 600)] <= 2.1 * totals[(4, 300)]


def test_plots_are_written(tmp_path):
    table = run(small_spec(snr=[25.0, 50.0]), progress=False)
    from jaxcascade._plot._sweep import plot_sweep

    paths = plot_sweep(summarise(table), table, tmp_path, "demo")
    names = sorted(pathlib.Path(p).name for p in paths)
    # two SNRs at one N: versus SNR, never versus N (tests/test_plot_sweep.py: each shape)
    want = [f"demo_{k}_vs_snr.png" for k in ("bias", "rmse", "std")]
    want += ["demo_convergence_rate.png", "demo_distributions.png", "demo_efficiency.png"]
    assert names == sorted(want)
    assert all(pathlib.Path(p).stat().st_size > 10_000 for p in paths)


# ---- input designs and noise kinds -------------------------------------------------------

COLOURED = """
example = 1
n = 300
snr = 25
realisations = 6
seed = 0
chunk_size = 3
[input]
kind = "multisine"
band = [0.0, 0.8]
[noise]
kind = "ar"
poles = [0.9]
"""


def test_multisine_input_with_ar_noise_runs_and_resumes_to_an_identical_table(
    tmp_path, capsys, monkeypatch
):
    import jaxcascade._montecarlo._run as run_module

    path = tmp_path / "coloured.toml"
    path.write_text(COLOURED)
    reference = tmp_path / "reference.parquet"
    assert main(["sweep", str(path), "--out", str(reference)]) == 0
    assert "input: multisine" in capsys.readouterr().out
    expected = without_timing(pd.read_parquet(reference))
    assert set(expected["input"]) == {"multisine"} and set(expected["noise"]) == {"ar"}
    np.testing.assert_allclose(expected["input_rms"], 2 / np.sqrt(3), rtol=1e-12)
    meta = read_metadata(reference)
    assert meta["spec"]["noise"] == {"kind": "ar", "poles": [0.9]}
    assert meta["spec"]["input"]["kind"] == "multisine"

    # a run that dies after its first chunk, then resumes from the chunk on disk
    out = tmp_path / "crashed.parquet"
    calls = []

    def dying(spec, cell, indices):
        if calls:
            raise KeyboardInterrupt
        calls.append(indices)
        return run_chunk(spec, cell, indices)

    monkeypatch.setattr(run_module, "run_chunk", dying)
    assert main(["sweep", str(path), "--out", str(out)]) == 130
    assert len(list((tmp_path / "crashed.parquet.partial").glob("chunk-*"))) == 1
    monkeypatch.undo()
    capsys.readouterr()
    # other noise settings may not continue it: the noise is part of the identity
    assert main(["sweep", str(path), "--noise", "ar:poles = [0.5]", "--out", str(out)]) == 2
    assert "different spec" in capsys.readouterr().err
    assert main(["sweep", str(path), "--out", str(out)]) == 0
    assert_same_table(without_timing(pd.read_parquet(out)), expected)

    # the same records under the command line's options instead of the file's tables
    options = tmp_path / "options.parquet"
    argv = ["sweep", "--example", "1", "--n", "300", "--realisations", "6", "--chunk-size", "3"]
    kinds = ["--input-kind", "multisine:band = [0.0, 0.8]", "--noise", "ar:poles = [0.9]"]
    assert main([*argv, *kinds, "--out", str(options)]) == 0
    table = without_timing(pd.read_parquet(options))
    assert_same_table(table, expected)


def test_noise_and_input_enter_the_cell_keys_and_the_papers_keys_stay():
    from jaxcascade._montecarlo._engine import cell_identity

    paper = small_spec()
    cell = paper.cells()[0]
    # the identity text written before input designs and noise kinds existed
    values = {
        "DL1": "-0x1.ccccccccccccdp-1", "DR1": "0x1.0000000000000p+0",
        "ML1": "0x1.6666666666666p-1", "ML2": "-0x1.999999999999ap-1",
        "MR1": "0x1.3333333333333p+0", "MR2": "-0x1.6666666666666p+0",
        "a2": "0x1.3333333333333p-3", "b1": "-0x1.999999999999ap-3",
        "b2": "0x1.6666666666666p-2", "cL": "0x1.999999999999ap-3",
        "cR": "0x1.3333333333333p-2", "mR": "0x1.3333333333333p+0",
    }  # fmt: skip
    before = {
        "amplitude": "0x1.0000000000000p+1", "input": "uniform", "n": 300,
        "orders": "2,2,2,2", "snr": "0x1.9000000000000p+4", "values": values,
    }  # fmt: skip
    assert cell_identity(paper, cell) == json.dumps(before, sort_keys=True)
    identities = {
        cell_identity(small_spec(**changes), cell)
        for changes in (
            {},
            {"noise": "ar", "noise_settings": {"poles": [0.9]}},
            {"noise": "ar", "noise_settings": {"poles": [0.5]}},
            {"noise": "student_t"},
            {"input": "multisine"},
            {"input": "multisine", "input_settings": {"band": [0, 0.5]}},
        )
    }
    assert len(identities) == 6


def test_a_resonant_noise_runs_with_its_own_bound(tmp_path, capsys):
    # a [radius, angle] pole pair from the command line: a cell of its own, its
    # provenance as written, and the Cramér-Rao bound of that noise (not of white noise)
    argv = ["sweep", "--example", "1", "--n", "300", "--realisations", "2", "--seed", "0"]
    out = tmp_path / "resonant.parquet"
    assert main([*argv, "--noise", "ar:poles = [[0.95, 0.6]]", "--out", str(out)]) == 0
    assert "noise: ar (poles = [[0.95, 0.6]])" in capsys.readouterr().out
    assert read_metadata(out)["spec"]["noise"] == {"kind": "ar", "poles": [[0.95, 0.6]]}
    spec = Spec.from_dict(read_metadata(out)["spec"])
    assert Spec.from_dict(spec.to_dict()) == spec
    assert spec.disturbance().coefficients()[0].shape == (2,)
    summary = pd.read_csv(tmp_path / "resonant.summary.csv")
    assert np.all(np.isfinite(summary["crlb_std"])) and np.all(summary["crlb_std"] > 0)
    # against white noise of the same SNR: other keys, and a bound several times lower
    # (the resonant noise's innovations have 1/16.8 of its variance: most of it is
    # predictable from its past, which the whitened Jacobian's information uses)
    resonant = small_spec(noise="ar", noise_settings={"poles": [[0.95, 0.6]]})
    white = small_spec()
    cell = white.cells()[0]
    assert cell_identity(resonant, cell) != cell_identity(white, cell)
    one, other = run_realisation(resonant, cell, 0), run_realisation(white, cell, 0)
    assert np.all(np.isfinite(one["crlb"])) and np.all(one["crlb"] < 0.5 * other["crlb"])
