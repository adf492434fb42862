"""`jaxcascade loop --benchmark NAME --data ROOT`: the split rule, the scored records' length
rule, one-line errors, and a run on CED's records as distributed (issue 32)."""

import json
import pathlib

import jax
import numpy as np
import pytest

import jaxcascade as jc
from jaxcascade._cli import main
from jaxcascade._measured._benchmark_protocol import (
    band_edge,
    benchmark_decimation,
    benchmark_split,
)

ROOT = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "nonlinear_benchmarks"
needs_data = pytest.mark.skipif(
    not (ROOT / "CED" / "DATAUNIF.MAT").exists(),
    reason="the benchmarks' files live in ../shared/data/nonlinear_benchmarks",
)


def _records(*lengths):
    return [
        (f"train {i + 1}", np.arange(n, dtype=float), np.arange(n, dtype=float))
        for i, n in enumerate(lengths)
    ]


def test_split_holds_out_the_last_quarter_of_the_last_training_record():
    parts = benchmark_split(_records(400, 400), max_samples=10000)
    assert [name for name, _, _ in parts["estimation"]] == ["train 1", "train 2 [0:300]"]
    name, u, _ = parts["validation"]
    assert name == "train 2 [300:400]" and u[0] == 300 and len(u) == 100
    # the estimation and validation parts cover the training data once
    assert sum(len(u) for _, u, _ in parts["estimation"]) + len(u) == 800


def test_split_of_a_long_record_keeps_the_latest_samples():
    parts = benchmark_split(_records(24841), max_samples=10000)
    ((name, u, _),) = parts["estimation"]
    v_name, v, _ = parts["validation"]
    assert v_name == "train 1 [22341:24841]" and len(v) == 2500
    assert name == "train 1 [12341:22341]" and len(u) == 10000 and u[-1] + 1 == v[0]


def test_a_long_narrow_band_record_is_decimated_as_far_as_its_band_allows():
    rng = np.random.default_rng(0)
    t = np.arange(24000)
    # input and output difference within 0.01 cycles per sample: up to 0.4/0.01 = 40
    slow = np.sin(2 * np.pi * 0.004 * t) + 0.5 * np.sin(2 * np.pi * 0.009 * t)
    records = [("train", slow, np.cumsum(slow))]
    # the budget alone asks for ceil(24000 / 5000) = 5, within the band's 40
    assert benchmark_decimation(records, 5000) == 5
    assert benchmark_decimation(records, 30000) == 1  # within the budget: none
    # a component at 0.05 cycles per sample bounds it at floor(0.4 / 0.05) = 8
    mixed = slow + np.sin(2 * np.pi * 0.05 * t)
    assert benchmark_decimation([("train", mixed, np.cumsum(slow))], 1000) == 8
    # white noise fills the band: not decimated, however long
    white = rng.normal(size=24000)
    assert benchmark_decimation([("train", white, np.cumsum(slow))], 1000) == 1
    assert band_edge(np.ones(100)) == 0.0


@needs_data
def test_emps_is_decimated_by_the_rule_unless_decimate_is_given():
    # EMPS: 24,841 training samples at 1 kHz, a position whose input's band ends far
    # below the Nyquist frequency; the rule's factor is ceil(24841 / 5000) = 5, and a
    # given --decimate (1 too) is taken as given
    from jaxcascade import benchmark_data
    from jaxcascade._measured._benchmark_protocol import benchmark_records

    bench = benchmark_data("EMPS", ROOT)
    for decimate, factor, estimation in ((None, 5, 3727), (1, 1, 5000)):
        records = benchmark_records(bench, decimate=decimate)
        assert records.decimation == factor
        assert records.decimation_rule.startswith("by the rule" if decimate is None else "--")
        assert sum(len(r.u) for r in records.estimation) == estimation
        found = [*records.estimation, *records.validation, *records.test]
        assert all(r.decimation == factor for r in found)
        assert records.init_samples == -(-bench.n_init // factor)
    # the command takes a given --decimate (1 too) as given, the rule without it
    from jaxcascade._cli import build_parser
    from jaxcascade._cli._loop_options import DefaultDecimation

    args = build_parser().parse_args(["loop", "--benchmark", "EMPS", "--data", str(ROOT)])
    assert type(args.decimate) is DefaultDecimation
    given = ["loop", "--benchmark", "EMPS", "--data", str(ROOT), "--decimate", "1"]
    assert type(build_parser().parse_args(given).decimate) is int


def test_split_drops_whole_early_records_past_the_budget():
    parts = benchmark_split(_records(5000, 5000, 8000), max_samples=8000)
    names = [name for name, _, _ in parts["estimation"]]
    assert names == ["train 2 [3000:5000]", "train 3 [0:6000]"]
    assert sum(len(u) for _, u, _ in parts["estimation"]) == 8000


def test_scored_records_need_only_their_initialisation_and_a_few_samples():
    from jaxcascade import Orders
    from jaxcascade._measured._loop import MIN_SCORED, check_lengths, check_scored_length

    check_scored_length(100, 10, "validation")  # CED's 100-sample records
    with pytest.raises(ValueError, match="fewer than the 30 a scored record needs"):
        check_scored_length(29, 10, "validation")
    assert MIN_SCORED == 20
    # estimation samples are counted over every record
    check_lengths([60, 60], Orders(2, 2, 2, 2))
    with pytest.raises(ValueError, match="2 estimation records have together 119 samples"):
        check_lengths([60, 59], Orders(2, 2, 2, 2))


@pytest.mark.parametrize(
    "argv, words",
    [
        (["loop"], "loop needs TRAIN, --validate, --input, --output"),
        (["loop", "--benchmark", "CED"], "--benchmark needs --data"),
        (["loop", "x.csv", "--benchmark", "CED", "--data", "."], "drop TRAIN"),
        (["loop", "--benchmark", "Nope", "--data", "."], "EMPS"),
        (["loop", "--benchmark", "CED", "--data", "/nonexistent"], "DATAUNIF.MAT"),
        (["loop", "--benchmark", "CED", "--data", ".", "--max-samples", "10"], "--max-samples"),
    ],
)
def test_benchmark_option_errors_are_one_line(capsys, argv, words):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert words in err, err


@needs_data
@pytest.mark.slow  # the whole loop with the defaults: about three minutes
def test_loop_on_ced_with_the_defaults_beats_the_linear_peer(capsys, tmp_path):
    argv = ["loop", "--benchmark", "CED", "--data", str(ROOT), "--json", "--quiet"]
    assert main(argv) == 0
    bench = json.loads(capsys.readouterr().out)["benchmark"]
    for test in bench["tests"]:
        assert test["test_rmse"] < test["arx_test_rmse"], test


@needs_data
def test_loop_on_ced_scores_every_test_set_in_its_unit(capsys, tmp_path):
    """The declared cascade alone (`--max-effects 0`): the benchmark's records, its split,
    its n_init and unit, the published baselines beside the figures."""
    argv = ["loop", "--benchmark", "CED", "--data", str(ROOT), "--max-effects", "0"]
    argv += ["--retries", "0", "--json", "--quiet", "--report", str(tmp_path), "--no-figures"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    bench = out["benchmark"]
    assert bench["name"] == "CED" and bench["unit"] == "ticks/s" and bench["n_init"] == 10
    assert [t["record"] for t in bench["tests"]] == ["test 1", "test 2"]
    for test in bench["tests"]:
        assert np.isfinite(test["test_rmse"]) and test["test_rmse"] > 0
        assert np.isfinite(test["arx_test_rmse"]) and test["arx_test_rmse"] > 0
        assert test["published"]["linear_state_space"] > 0
        assert test["best_linear_published"] == min(
            test["published"]["linear_state_space"], test["published"]["linear_arx"]
        )
    assert out["init_samples"] == 10
    # CED's short records at their band: not decimated, and the report says by which rule
    assert bench["decimation"] == 1 and bench["decimation_rule"].startswith("by the rule")
    full = json.loads((tmp_path / "report.json").read_text())
    estimation = [r["source"] for r in full["records"]["estimation"]]
    assert estimation == ["CED train 1", "CED train 2 [0:300]"]
    assert [v["source"] for v in full["records"]["validation"]] == ["CED train 2 [300:400]"]
    assert all(r["sample_period"] == 0.02 for r in full["records"]["test"])
    report = (tmp_path / "report.md").read_text()
    first = report.split("\n## ", 2)[1]
    assert first.startswith("CED: test RMSE (ticks/s)")
    assert "linear state space (published)" in first and "linear ARX peer" in first
    assert "decimation 1 (by the rule without --decimate: the largest factor d" in first


def test_an_integrating_output_is_scored_through_its_difference():
    from jaxcascade._measured._integrating import integrated, integrates

    rng = np.random.default_rng(0)
    u = rng.normal(size=400)
    y = np.concatenate([[0.0], np.cumsum(2 * u[1:])])  # y(t) = y(t-1) + 2 u(t)
    # a difference model that is exact: dy = 2 u
    rest, init = integrated(lambda v: 2 * v, lambda v, dy, start, n: (2 * v)[start:])
    np.testing.assert_allclose(rest(u), y, atol=1e-12)
    for start in (1, 10, 399):
        np.testing.assert_allclose(init(u, y, start, 10), y[start:], atol=1e-12)
    # a random walk driven by its input integrates; a stable filter of it does not
    walk = np.concatenate([[0.0], np.cumsum(2 * u[:-1])])  # y(t) = y(t-1) + 2 u(t-1)
    pole = integrates(u, walk + 0.01 * rng.normal(size=400))
    assert pole is not None and pole >= 0.999
    import scipy.signal

    assert integrates(u, scipy.signal.lfilter([0, 1], [1, -0.8], u)) is None
    # a slow pole that a zero nearly cancels (a friction force against a displacement,
    # the damper's Kocaeli record at 1 kHz: pole 0.9991) is no integrator: the ARX peer's
    # pole lies within 1e-3 of the unit circle, its gain at zero frequency is small
    u = rng.normal(size=2000)
    slow = scipy.signal.lfilter([0, 1, -0.998], [1, -0.9995], u) + 1e-3 * rng.normal(size=2000)
    from jaxcascade._measured._arx import best_arx
    from jaxcascade._measured._integrating import INTEGRATOR_GAIN, INTEGRATOR_POLE, static_gain

    arx = best_arx(u, slow)
    assert arx.largest_pole >= INTEGRATOR_POLE and static_gain(arx, u, slow) < INTEGRATOR_GAIN
    assert integrates(u, slow) is None


def test_an_integrator_whose_pole_friction_pulled_inside_is_chosen_by_validation():
    # An axis under proportional control with Coulomb friction (`axis_record`, seed 3):
    # the equation-error ARX fit's pole lies inside the unit circle (0.97), but its gain
    # at zero frequency is an integrator's (`leaky_integrator`), so `--integrate auto`
    # fits the declared cascade on the output and on its difference and keeps the
    # difference, which the validation record scores far better; with `no`, the output.
    from jaxcascade._measured._integrating import integration
    from jaxcascade._measured._testing import INTEGRATING, axis_record

    k_est, k_val = jax.random.split(jax.random.PRNGKey(3))
    records = [
        jc.record_from_arrays(*axis_record(k, 1025, 30.0, INTEGRATING["velocity_friction"]))
        for k in (k_est, k_val)
    ]
    assert integration(records[:1], "auto") is None  # no pole within 1e-3 of 1
    run = jc.loop_records(records[0], records[1], max_effects=0, outliers="keep")
    leaky = run.integrating["leaky"]
    assert run.integrating["option"] == "auto" and 0.95 <= run.integrating["largest_arx_pole"]
    assert leaky["difference_error"] < 0.5 * leaky["level_error"]
    assert run.result.before.error == pytest.approx(leaky["difference_error"], rel=1e-9)
    assert "declared cascade fitted on the output's difference" in run.integrating["sentence"]
    kept = jc.loop_records(records[0], records[1], max_effects=0, integrate="no", outliers="keep")
    assert kept.integrating is None
    assert kept.result.before.error == pytest.approx(leaky["level_error"], rel=1e-9)


@needs_data
@pytest.mark.slow  # the whole loop on EMPS and Silverbox with the defaults: tens of minutes
@pytest.mark.parametrize("name", ["EMPS", "Silverbox"])
def test_loop_on_the_long_benchmarks_runs_to_the_end(capsys, tmp_path, name):
    argv = ["loop", "--benchmark", name, "--data", str(ROOT), "--json", "--quiet"]
    argv += ["--report", str(tmp_path)]
    assert main(argv) == 0
    bench = json.loads(capsys.readouterr().out)["benchmark"]
    assert bench["tests"] and all(np.isfinite(t["test_rmse"]) for t in bench["tests"])
