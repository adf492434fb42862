"""The command line: results on good input, one-line errors (exit 2) on bad input."""

import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from jaxcascade._cli import main


def _one_line_error(capsys, argv):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert err.startswith("jaxcascade: error: ")
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize(
    "argv, words",
    [
        (["reproduce", "--example", "3"], "unknown example"),
        (["reproduce", "--example", "1", "--snr", "0"], "--snr must be positive"),
        (["reproduce", "--example", "1", "--snr", "-5"], "--snr must be positive"),
        (["reproduce", "--example", "1", "--snr", "abc"], "invalid float"),
        (["reproduce"], "required"),
        (["reproduce", "--example", "1", "--out", "/proc/forbidden"], "cannot write"),
        (["reproduce", "--example", "general1", "--estimator", "pem"], "general-backlash"),
        (["nonsense"], "invalid choice"),
        (["fit", "missing.csv", "--input", "u", "--output", "y"], "does not exist"),
        (["fit", "x.csv", "--input", "u", "--output", "y", "--orders", "2,2"], "--orders"),
        (["fit", "x.csv", "--input", "u", "--output", "y", "--estimator", "magic"], "magic"),
    ],
)
def test_bad_input_is_one_line_exit_2(capsys, argv, words):
    assert words in _one_line_error(capsys, argv)


def test_unwritable_output_writes_nothing(capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    _one_line_error(capsys, ["reproduce", "--example", "1", "--out", str(blocker / "sub")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_fit_missing_column_names_the_columns(capsys, tmp_path):
    path = tmp_path / "data.csv"
    pd.DataFrame({"u": np.linspace(-1, 1, 200), "y": np.zeros(200)}).to_csv(path, index=False)
    err = _one_line_error(capsys, ["fit", str(path), "--input", "u", "--output", "force"])
    assert "'force'" in err and "'y'" in err


@pytest.mark.parametrize("number", [1, 2])
def test_reproduce_json_and_files(number, capsys, tmp_path):
    argv = ["reproduce", "--example", str(number), "--snr", "inf", "--out", str(tmp_path)]
    assert main([*argv, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["example"] == number and result["status"] == "converged"
    assert set(result) == {
        "example",
        "iterations",
        "status",
        "message",
        "settings",
        "cycle_amplitude",
        "estimates",
        "true",
    }
    # Noise-free, the paper's iteration (default estimator, "full" first step) recovers
    # every parameter of both examples, as the paper reports.
    for name, value in result["true"].items():
        assert abs(result["estimates"][name] - value) < 1e-6, name
    names = {p.name for p in tmp_path.iterdir()}
    stem = f"example{number}_snrinf_seed0"
    assert {f"{stem}_estimates.csv", f"{stem}_convergence.png"} <= names


def test_fit_json_on_a_simulated_record(capsys, tmp_path):
    import jax

    import jaxcascade as jc

    ex = jc.example(1)
    key_u, key_e = jax.random.split(jax.random.PRNGKey(0))
    u = jc.uniform_input(key_u, 1500)
    y, _ = jc.measure(key_e, ex.params(), u, 50.0)
    path = tmp_path / "record.csv"
    pd.DataFrame({"u": np.asarray(u), "y": np.asarray(y)}).to_csv(path, index=False)
    assert main(["fit", str(path), "--input", "u", "--output", "y", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    keys = {"estimator", "status", "message", "warnings", "nrmse", "iterations", "samples"}
    assert set(result) == keys | {"not_identifiable", "model"}
    assert result["estimator"] == "robust" and result["status"] == "converged"
    model = result["model"]  # the package's one schema (docs/models.md)
    # fitted in model units (the measured-data default `--scaling auto`), reported in the
    # record's
    assert model["scaling"]["method"] == "scale"  # the input crosses zero: not centred
    assert result["not_identifiable"] == {} and result["warnings"] == []
    # SNR 50: the noise floor of the NRMSE is 1/50; a correct fit sits near it.
    assert result["nrmse"] < 1.3 / 50
    truth = ex.params().to_dict()
    estimates = model["estimates"]
    assert max(abs(estimates[k] - v) for k, v in truth.items()) < 0.05
    # a standard error beside every estimate, of the size of the estimation error: at
    # SNR 50 and N 1500 between 1e-4 and 1e-2, and no error beyond 6 of them
    errors = model["std_errors"]
    assert set(errors) == set(truth)
    assert all(1e-4 < errors[k] < 1e-2 for k in truth)
    assert max(abs(estimates[k] - v) / errors[k] for k, v in truth.items()) < 6
    assert set(model["estimates_model_units"]) == set(truth)


def test_fit_says_which_parameters_the_record_does_not_determine(capsys, tmp_path):
    import jax

    import jaxcascade as jc

    # Example 1's breakpoints (DR1 = 1, DL1 = -0.9) outside the input's range (-0.8, 0.8):
    # the record holds no kink to place them by, nor the change of slope beyond them.
    ex = jc.example(1)
    key_u, key_e = jax.random.split(jax.random.PRNGKey(0))
    u = jc.uniform_input(key_u, 1500, 0.8)
    y, _ = jc.measure(key_e, ex.params(), u, 50.0)
    path = tmp_path / "record.csv"
    pd.DataFrame({"u": np.asarray(u), "y": np.asarray(y)}).to_csv(path, index=False)
    # in the paper's units, where Example 1's breakpoints lie outside the input's range
    argv = ["fit", str(path), "--input", "u", "--output", "y", "--scaling", "none"]
    # `on_edge` (DL1 at the end of the range), the parameters named, the others stand
    assert main([*argv, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "on_edge"
    unknown = set(result["not_identifiable"])
    assert {"DR1", "DL1"} <= unknown <= {"DR1", "MR2", "DL1", "ML2"}
    assert "not identifiable from this record" in result["message"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "not identifiable from this record: " in text
    rows = {line.split()[0]: line for line in text.splitlines() if " = " in line}
    assert {name for name, row in rows.items() if "not identifiable" in row} == unknown
    assert all("±" in rows[name] for name in set(rows) - unknown)


def test_no_traceback_from_the_installed_entry_point(tmp_path):
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    run = subprocess.run(
        [sys.executable, "-m", "jaxcascade", "reproduce", "--example", "7"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert run.returncode == 2
    assert run.stderr.strip().count("\n") == 0 and "Traceback" not in run.stderr


BRFD = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "brfd")


@pytest.mark.skipif(
    not os.path.isdir(BRFD),
    reason="the measured BRFD records live in ../shared/data/brfd, absent on this machine",
)
@pytest.mark.slow  # a joint loop on the measured records: minutes
def test_loop_runs_on_the_measured_friction_damper(capsys, tmp_path):
    data = os.path.join(BRFD, "earthquake_kocaeli_dbe.csv")
    valid = os.path.join(BRFD, "earthquake_imperialvalley_dbe.csv")
    argv = ["loop", data, "--validate", valid, "--input", "displacement_in"]
    argv += ["--output", "force_kip", "--time", "time_s", "--decimate", "32", "--max-effects", "1"]
    argv += ["--json", "--quiet", "--report", str(tmp_path)]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    assert np.isfinite(result["error_before"]) and np.isfinite(result["error_after"])
    # The loop only adds an effect that lowers the validation error.
    assert result["error_after"] <= result["error_before"]
    assert len(result["effect_added"]) <= 1
    assert {"report.json", "report.md", "compare.png"} <= {p.name for p in tmp_path.iterdir()}


def test_loop_on_several_records_with_a_window(capsys, tmp_path):
    import jax

    import jaxcascade as jc

    paths = []
    for seed in (1, 2, 3, 4):
        u = jc.uniform_input(jax.random.PRNGKey(seed), 600)
        y = jc.simulate(jc.example(1).params(), u)
        y = y + 0.05 * jax.random.normal(jax.random.PRNGKey(10 + seed), y.shape)
        path = tmp_path / f"r{seed}.csv"
        pd.DataFrame({"u": np.asarray(u), "y": np.asarray(y)}).to_csv(path, index=False)
        paths.append(str(path))
    argv = ["loop", paths[0], paths[1], "--validate", paths[2], "--input", "u", "--output", "y"]
    argv += ["--window", "100:400", "--max-effects", "0", "--json", "--quiet"]
    argv += ["--test", paths[3], "--test-window", "200:500"]
    argv += ["--report", str(tmp_path / "report"), "--no-figures"]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out)

    def at_the_floor(error, path, window=None):
        # the true cascade's NRMSE is the noise's, 0.05 over the scored output's standard
        # deviation (about 0.07); the noise's own RMS over 300 samples varies by about
        # 4 % (1 / sqrt(2 * 300)) and a fit on 1,200 samples adds a little: within
        # 0.85-1.25 of the floor (measured: 1.02-1.06)
        y = pd.read_csv(path)["y"].to_numpy()
        floor = 0.05 / np.std(y if window is None else y[slice(*window)])
        return 0.85 * floor < error < 1.25 * floor

    assert result["window_error_before"] == result["window_error_after"]
    assert at_the_floor(result["window_error_after"], paths[2], (100, 400))
    # issue 21: initialised and from-rest figures side by side, the test record apart
    assert result["init_samples"] == 50
    assert at_the_floor(result["window_error_after_from_rest"], paths[2], (100, 400))
    (test,) = result["test"]
    assert test["record"] == "r4.csv"
    assert at_the_floor(test["window_error"], paths[3], (200, 500))
    assert at_the_floor(test["window_error_from_rest"], paths[3], (200, 500))
    assert at_the_floor(test["error_from_rest"], paths[3])
    # a correct cascade beats the mean and the ARX peer: nothing to warn about
    assert result["verdict"] == []
    # records of one input distribution cover each other's range: no coverage sentence,
    # a row per record in its role (the estimation records first)
    cover = result["coverage"]
    assert cover["sentences"] == []
    roles = [(r["record"], r["role"]) for r in cover["records"]]
    assert roles == [("r1.csv", "estimation"), ("r2.csv", "estimation")] + [
        ("r3.csv", "validation"),
        ("r4.csv", "test"),
    ]
    assert all(
        r["span"] > 0.9 and r["outside"] <= 0.01 and r["beyond"] < 0.01 for r in cover["records"]
    )
    assert result["structure_after"] == "u -> pwl(2,2) -> linear(2,2) -> backlash -> y"
    full = json.loads((tmp_path / "report" / "report.json").read_text())
    assert len(full["records"]["estimation"]) == 2
    assert full["window"]["model_samples"] == [100, 400]
    # standard errors of the final model on both estimation records, one per parameter,
    # in the schema (the records' units and model units)
    model = result["model_after"]
    assert model == full["model_after"]
    for key in ("std_errors", "std_errors_model_units"):
        errors = model[key]
        assert set(errors) == set(jc.Orders().names) and all(e > 0 for e in errors.values())
    report = (tmp_path / "report" / "report.md").read_text()
    assert "better than the mean of the output" in report and "r4.csv | test" in report
    assert "Input coverage" in report and "| r3.csv | validation | 600 |" in report
    # A test window per test record, or a clear error.
    bad = argv + ["--test-window", "1:2", "3:4"]
    assert main(bad) == 2
    assert "--test-window" in capsys.readouterr().err
    # A window outside the validation record is one line, exit 2.
    argv[argv.index("100:400")] = "100:4000"
    assert main(argv) == 2
    assert "--window" in capsys.readouterr().err


def test_verdict_says_when_the_final_model_is_worse_than_a_trivial_one():
    from jaxcascade._measured._scoring import RecordScore, verdict

    def row(model, record, window_error):
        return RecordScore(model, record, "validation", 0.5, window_error, 0.6, 0.7, 50)

    final = [row("final model", "a.csv", 1.2), row("final model", "b.csv", 0.3)]
    arx = [row("linear ARX", "a.csv", 0.9), row("linear ARX", "b.csv", 0.4)]
    (sentence,) = verdict(final, arx)
    assert "a.csv" in sentence and "mean of the output" in sentence and "ARX" in sentence
    assert "try" in sentence
    assert verdict([row("final model", "b.csv", 0.3)], arx) == []
    worse_than_arx = verdict([row("final model", "b.csv", 0.5)], arx)
    assert len(worse_than_arx) == 1 and "mean" not in worse_than_arx[0]


def test_loop_effects_option_names_the_library(capsys, tmp_path):
    # An unknown name is one line, exit 2, before any fitting.
    rng = np.random.default_rng(0)
    path = tmp_path / "r.csv"
    pd.DataFrame({"u": rng.normal(size=300), "y": rng.normal(size=300)}).to_csv(path, index=False)
    argv = ["loop", str(path), "--validate", str(path), "--input", "u", "--output", "y"]
    argv += ["--effects", "output_offset,no_such_effect", "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--effects" in err and "no_such_effect" in err


def test_reproduce_a_general_backlash_example(capsys, tmp_path):
    # Issue 39, point 3: the note's examples through the same command, noise-free: the
    # key-term iteration from the paper's initial values (curvature 0) reaches the truth
    # of every parameter, the curvature terms included, and says converged.
    argv = ["reproduce", "--example", "general2", "--snr", "inf", "--out", str(tmp_path)]
    assert main([*argv, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["example"] == "general2" and result["status"] == "converged"
    assert {"mL_2", "mL_3", "mR_2", "mR_3"} <= set(result["true"])
    assert result["true"]["mL_2"] == -0.03 and result["true"]["mR_3"] == 0.02
    for name, value in result["true"].items():
        assert abs(result["estimates"][name] - value) < 1e-6, name
    stem = "general2_snrinf_seed0"
    names = {p.name for p in tmp_path.iterdir()}
    assert {f"{stem}_estimates.csv", f"{stem}_estimates.md", f"{stem}_convergence.png"} <= names
    table = pd.read_csv(tmp_path / f"{stem}_estimates.csv")
    assert list(table["parameter"])[-4:] == ["mL_2", "mL_3", "mR_2", "mR_3"]
