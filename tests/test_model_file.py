"""Models to reuse (`_model_file`, `jaxcascade simulate`): the loop saves its final model,
`simulate` on the loop's test record gives the loop's own test figures, the file reads
back to the same model, and a bad file or a record sampled otherwise is one line, exit 2.
"""

import contextlib
import io
import json
import pathlib

import jax
import numpy as np
import pandas as pd
import pytest

import jaxcascade as jc
from jaxcascade._cli import main

PERIOD = 0.01  # seconds, written as a time column
SCORED = ("error", "window_error", "error_from_rest", "window_error_from_rest")


def _record(path, seed, n, offset=0.0, period=PERIOD):
    """Example 1 with an output offset the declared cascade lacks, small white noise."""
    u = jc.uniform_input(jax.random.PRNGKey(seed), n)
    y = jc.simulate(jc.example(1).params(), u) + offset
    y = y + 0.03 * jax.random.normal(jax.random.PRNGKey(100 + seed), y.shape)
    frame = pd.DataFrame({"t": np.arange(n) * period, "u": np.asarray(u), "y": np.asarray(y)})
    frame.to_csv(path, index=False)
    return str(path)


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    """The loop (`--max-effects 0`: the file, not the loop, is under test here) on an
    estimation and a validation record with one test record; its JSON and folder."""
    folder = tmp_path_factory.mktemp("loop")
    train = _record(folder / "train.csv", 1, 300)
    valid = _record(folder / "valid.csv", 2, 300)
    test = _record(folder / "test.csv", 3, 300)
    argv = ["loop", train, "--validate", valid, "--test", test]
    argv += ["--input", "u", "--output", "y", "--time", "t", "--units", "V,mm"]
    argv += ["--max-effects", "0", "--init-samples", "30"]
    argv += ["--report", str(folder / "report"), "--json", "--quiet"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(argv) == 0
    return folder, test, json.loads(out.getvalue())


def result_model(folder):
    return json.loads((folder / "report" / "report.json").read_text())["model_after"]


def test_simulate_reproduces_the_loops_test_figures(loop, capsys):
    folder, test, result = loop
    model = folder / "report" / "model.json"
    saved = json.loads(model.read_text())
    # the model in the one schema of report.json and --json (issue 68), with a format
    # version
    assert saved["format_version"] == 2
    assert saved["model"]["structure"] == result["structure_after"]
    assert saved["model"] == result_model(folder) == result["model_after"]
    assert saved["data"]["sample_period"] == pytest.approx(PERIOD)
    assert saved["data"]["output"]["unit"] == "mm"
    assert saved["scoring"]["init_samples"] == 30
    # the signals' names, the time column and the init window all come from the file
    assert main(["simulate", str(model), test, "--json", "--report", str(folder / "sim")]) == 0
    (row,) = json.loads(capsys.readouterr().out)["records"]
    (expected,) = result["test"]
    assert row["record"] == expected["record"]
    for key in SCORED:
        if expected[key] is None:
            assert row[key] is None
        else:
            assert row[key] == pytest.approx(expected[key], rel=1e-9, abs=1e-12), key
    # RMSE in the record's unit, as the loop's scores table gives it
    (loop_row,) = [
        s
        for s in json.loads((folder / "report" / "report.json").read_text())["scores"]
        if s["role"] == "test" and s["model"] == "final model"
    ]
    assert row["rmse"] == pytest.approx(loop_row["rmse"], rel=1e-9)
    assert row["fit_percent"] == pytest.approx(jc.fit_percent(expected["error"]), rel=1e-9)
    assert (folder / "sim" / "simulate_1.png").stat().st_size > 0
    assert "mm" in (folder / "sim" / "simulate.md").read_text()


def test_the_file_reads_back_to_the_same_model(loop, tmp_path):
    folder, test, _ = loop
    path = folder / "report" / "model.json"
    saved = jc.load_model(path)
    again = jc.load_model(saved.save(tmp_path / "again.json"))
    assert again.to_dict() == saved.to_dict() == json.loads(path.read_text())
    leaves = jax.tree_util.tree_leaves(saved.model)
    for a, b in zip(leaves, jax.tree_util.tree_leaves(again.model), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # The API on physical arrays: the from-rest simulation and the scores of the CLI.
    frame = pd.read_csv(test)
    y = saved.simulate(frame["u"].to_numpy())
    score = saved.score(frame["u"].to_numpy(), frame["y"].to_numpy())
    expected = jc.nrmse(frame["y"].to_numpy(), y)
    assert score.error_from_rest == pytest.approx(float(expected), rel=1e-9)
    assert score.init_samples == 30 and 0 < score.error < 0.2


def test_bad_model_file_and_other_sample_period_are_one_line_exit_2(loop, capsys, tmp_path):
    folder, test, _ = loop
    model = folder / "report" / "model.json"

    def one_line(argv, *words):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert err.startswith("jaxcascade: error: ")
        for word in words:
            assert word in err, err

    one_line(["simulate", str(tmp_path / "missing.json"), test], "does not exist")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    one_line(["simulate", str(bad), test], "not JSON")
    bad.write_text(json.dumps({"format": "something else"}))
    one_line(["simulate", str(bad), test], "not a jaxcascade model file")
    data = json.loads(model.read_text())
    data["format_version"] = 99
    bad.write_text(json.dumps(data))
    one_line(["simulate", str(bad), test], "format version 99")
    data = json.loads(model.read_text())
    data["model"]["effects"] = [{"name": "no_such_effect", "parameters_model_units": {}}]
    bad.write_text(json.dumps(data))
    one_line(["simulate", str(bad), test], "no_such_effect")
    data = json.loads(model.read_text())
    del data["model"]["estimates_model_units"]["MR1"]
    bad.write_text(json.dumps(data))
    one_line(["simulate", str(bad), test], "MR1")
    slow = _record(tmp_path / "slow.csv", 3, 300, period=2 * PERIOD)
    one_line(["simulate", str(model), slow], "sample period")
    one_line(["simulate", str(model), test, "--init-samples", "-1"], "--init-samples")


def test_fit_saves_a_model_that_simulate_applies(loop, tmp_path, capsys):
    # the loop's estimation record: the robust fit's programs are compiled already
    record = str(loop[0] / "train.csv")
    path = tmp_path / "fit.json"
    argv = ["fit", record, "--input", "u", "--output", "y", "--ts", str(PERIOD)]
    assert main([*argv, "--save-model", str(path), "--json"]) == 0
    fitted = json.loads(capsys.readouterr().out)
    saved = jc.load_model(path)
    assert saved.model.params.to_dict() == fitted["model"]["estimates_model_units"]
    assert saved.to_dict()["model"] == fitted["model"]  # one schema, the file's and fit's
    assert saved.sample_period == pytest.approx(PERIOD) and saved.model.effects == ()
    # the record the cascade was fitted on, from rest: fit's own free-run NRMSE
    assert main(["simulate", str(path), record, "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)["records"]
    assert row["error_from_rest"] == pytest.approx(fitted["nrmse"], rel=1e-9)


def test_effects_and_noise_round_trip(tmp_path):
    # Every field of an added effect, a replaced cascade and the noise model survive the
    # file, and the loaded model simulates as the saved one.
    from jaxcascade._measured._effects import ExtendedModel, InputDelay, OutputOffset, SlackFriction
    from jaxcascade._measured._model_file import SavedModel

    f = jax.numpy.asarray
    params = jc.example(1).params()
    friction = SlackFriction(f(0.1), f(0.05), f(0.3), f(-0.2))
    models = [
        ExtendedModel(params, (InputDelay(f(2.0)), OutputOffset(f(0.6))), jc.ARNoise(f([0.5]))),
        ExtendedModel(params, (friction, OutputOffset(f(0.1))), jc.ARNoise(f([])), cascade=False),
    ]
    u = np.asarray(jc.uniform_input(jax.random.PRNGKey(5), 200))
    scaling = jc.Scaling(0.1, 2.0, -0.3, 0.5, "standard")
    for k, model in enumerate(models):
        saved = SavedModel(model, scaling=scaling, sample_period=0.5, init_samples=20)
        loaded = jc.load_model(saved.save(tmp_path / f"m{k}.json"))
        assert loaded.model.structure() == model.structure()
        assert loaded.to_dict() == saved.to_dict()
        np.testing.assert_array_equal(loaded.simulate(u), saved.simulate(u))
        direct = jc.simulate_extended(model, jax.numpy.asarray(scaling.input_to_model(u)))
        np.testing.assert_allclose(
            loaded.simulate(u), scaling.output_to_physical(direct), rtol=1e-12, atol=1e-12
        )


# the shared data beside the checkout, as tests/test_benchmark_data.py finds it
CED = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "nonlinear_benchmarks"


@pytest.mark.slow  # the loop on CED and the simulation: about a minute and a half
@pytest.mark.skipif(not (CED / "CED" / "DATAUNIF.MAT").is_file(), reason="CED data not here")
def test_simulate_reproduces_the_ced_test_figures(tmp_path):
    # The benchmark's official test records, named as record specs (the loop cuts them
    # at sample 400 of each file, _benchmark_data._ced), give the loop's test figures.
    argv = ["loop", "--benchmark", "CED", "--data", str(CED), "--max-effects", "0"]
    argv += ["--report", str(tmp_path / "ced"), "--json", "--quiet"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(argv) == 0
    result = json.loads(out.getvalue())
    mat = CED / "CED" / "DATAUNIF.MAT"
    specs = [f"{mat}:u11,z11:400:", f"{mat}:u12,z12:400:"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["simulate", str(tmp_path / "ced" / "model.json"), *specs, "--json"]) == 0
    rows = json.loads(out.getvalue())["records"]
    tests = result["benchmark"]["tests"]
    for row, expected, bench in zip(rows, result["test"], tests, strict=True):
        for key in ("error", "error_from_rest"):
            assert row[key] == pytest.approx(expected[key], rel=1e-9), key
        assert row["rmse"] == pytest.approx(bench["test_rmse"], rel=1e-9)


def test_the_loop_report_draws_every_record_in_its_unit_against_seconds(loop):
    # issue 38.5: estimation, validation and test records, each measured against the
    # final model in the record's unit (mm) against time in seconds, listed in report.md
    folder, _, _ = loop
    report = folder / "report"
    figures = sorted((report / "records").glob("*.png"))
    assert [f.name for f in figures] == ["00-estimation.png", "01-validation.png", "02-test.png"]
    text = (report / "report.md").read_text()
    for figure in figures:
        assert f"(records/{figure.name})" in text and figure.stat().st_size > 0
    rows = [line for line in text.splitlines() if line.startswith("- ") and " mm, " in line]
    assert len(rows) == 3 and all("period 0.01 s" in row for row in rows)
    # the final model's equations and every estimate with its standard error, in the
    # model's units and the records' (issue 38.5)
    full = json.loads((report / "report.json").read_text())
    model = full["model_after"]
    assert set(model["std_errors"]) == set(model["estimates"]) == set(jc.Orders().names)
    section = text.split("## The final model", 1)[1].split("## ", 1)[0]
    assert all(f"\n- {block} (" in section for block in ("NS", "LD", "ND"))
    assert "x(t) = v(t-1) " in section  # a1 = 1, the paper's normalisation
    for name, value in model["estimates"].items():  # in the records' units first
        assert f"| {name} | {value:.6g} |" in section
    # the figure's axes: the unit and seconds
    from jaxcascade._plot._comparison import plot_comparison

    saved = jc.load_model(report / "model.json")
    frame = pd.read_csv(folder / "test.csv")
    comparison = saved.compare(saved.record(frame["u"].to_numpy(), frame["y"].to_numpy()))
    ax, zoom, res, acf = plot_comparison(comparison, report / "check.png", units="mm").axes
    assert ax.get_xlabel() == "time (s)" and ax.get_ylabel() == "mm"
    assert ax.get_xlim()[1] == pytest.approx(299 * PERIOD, rel=0.1)
    # the legend gives fit %, NRMSE and RMSE in the record's unit
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("% fit" in t and "NRMSE" in t and "RMSE" in t and " mm)" in t for t in legend)
    # a zoomed window, stated in its title, in the same units
    assert zoom.get_xlabel() == "time (s)" and zoom.get_ylabel() == "mm"
    assert zoom.get_title().startswith("zoom: samples ")
    # the residual in the unit, its autocorrelation with the 99 % band of white noise
    assert res.get_ylabel() == "residual (mm)" and res.get_xlabel() == "time (s)"
    assert acf.get_xlabel() == "lag (samples)"
    band = [t.get_text() for t in acf.get_legend().get_texts()]
    assert band == ["99 % band of white noise"]
