"""A loop that keeps its work (issue 38, point 3): every finished fit and round is
written to `REPORT/checkpoints/` as it finishes (`_loop_checkpoint`), `--resume`
continues from there with the decisions, estimates and errors of an uninterrupted run,
`--overwrite` starts afresh, anything else on a folder of checkpoints is one line and
exit 2; Ctrl-C writes a partial report and exits with 130.

The records are short (Example 1 with an undeclared output offset, 500 samples, SNR 20)
and the library two effects, so that a round holds two candidates. The in-process test
interrupts the loop at round 1's second candidate through a hook; the slow one kills a
real loop process with SIGKILL once a candidate's checkpoint is on disk.
"""

import json
import os
import signal
import subprocess
import sys
import time

import jax
import numpy as np
import pandas as pd
import pytest

from jaxcascade._cli import main
from jaxcascade._measured._loop_checkpoint import (
    Checkpoints,
    identity,
    model_from_dict,
    model_to_dict,
)
from jaxcascade._measured._testing import UNDECLARED, undeclared_record

N = 500
# the options that keep a loop short: two effects (two candidates in round 1), one round,
# no retries of the robust fit, scored from rest, no integration test
OPTIONS = ["--input", "u", "--output", "y", "--effects", "output_offset,output_drift"]
OPTIONS += ["--max-effects", "1", "--retries", "0", "--init-samples", "0", "--integrate", "no"]


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    folder = tmp_path_factory.mktemp("records")
    model, ar = UNDECLARED["output_offset"]()
    paths = []
    for name, seed in (("train", 1), ("valid", 2)):
        u, y = undeclared_record(model, jax.random.PRNGKey(seed), N, 20.0, ar)
        path = folder / f"{name}.csv"
        pd.DataFrame({"u": np.asarray(u), "y": np.asarray(y)}).to_csv(path, index=False)
        paths.append(str(path))
    return paths


def _argv(records, report, *extra):
    train, valid = records
    return ["loop", train, "--validate", valid, *OPTIONS, "--report", str(report), *extra]


def _same_results(a: dict, b: dict) -> None:
    """The decision, errors and estimates of two loops' reports: equal (a loaded fit is
    the fitted one bit for bit; 1e-12 relative only guards a last-digit difference)."""
    assert a["effect_added"] == b["effect_added"] and a["actions"] == b["actions"]
    for key in ("error_before", "error_after", "prediction_error_before", "prediction_error_after"):
        assert a[key] == pytest.approx(b[key], rel=1e-12, abs=0)
    for model in ("model_before", "model_after"):
        assert a[model].keys() == b[model].keys()
        assert a[model]["structure"] == b[model]["structure"]
        for key in ("estimates", "estimates_model_units", "std_errors_model_units"):
            assert a[model][key].keys() == b[model][key].keys()
            # a model without standard errors (the declared cascade's): None, NaN here
            values = [np.array(list(m[model][key].values()), float) for m in (a, b)]
            np.testing.assert_allclose(*values, rtol=1e-12)
        for x, y in zip(a[model]["effects"], b[model]["effects"], strict=True):
            assert x["name"] == y["name"]
            for field, value in x["parameters_model_units"].items():
                assert value == pytest.approx(y["parameters_model_units"][field], rel=1e-12)
    labels = ("round", "name", "variant", "action", "significant")
    assert [[c[k] for k in labels] for c in a["candidates"]] == [
        [c[k] for k in labels] for c in b["candidates"]
    ]
    for key in ("error", "t", "t_validation", "prediction_error"):
        values = [c[key] for c in a["candidates"]]
        assert values == pytest.approx([c[key] for c in b["candidates"]], rel=1e-12)


def _one_line_exit_2(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    return err


def test_interrupted_loop_resumes_to_the_uninterrupted_result(records, tmp_path, capsys):
    from jaxcascade._measured import _loop

    # the uninterrupted run; its checkpoints are gone once its report is written
    whole = tmp_path / "whole"
    assert main(_argv(records, whole)) == 0
    capsys.readouterr()
    assert not (whole / "checkpoints").exists()
    expected = json.loads((whole / "report.json").read_text())
    assert expected["effect_added"] == ["output_offset"]

    # Ctrl-C at round 1's second candidate: a partial report, exit code 130
    fit, calls = _loop._fit_candidate, []

    def interrupted(*args, **kwargs):
        calls.append(args[0])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return fit(*args, **kwargs)

    report = tmp_path / "report"
    _loop._fit_candidate = interrupted
    try:
        assert main(_argv(records, report)) == 130
    finally:
        _loop._fit_candidate = fit
    err = capsys.readouterr().err
    where = "in round 1, at candidate 2 of 2 (output_drift)"
    assert where in err and "--resume" in err
    partial = (report / "report.md").read_text()
    assert where in partial and "--resume" in partial
    assert json.loads((report / "report.json").read_text())["stopped"]["candidate"] == (
        "output_drift"
    )
    kept = sorted(p.name for p in (report / "checkpoints").iterdir())
    assert kept == ["declared.json", "round-01-add-output_offset.json", "run.json"]

    # neither flag on a folder of checkpoints, or other options: one line, exit 2
    err = _one_line_exit_2(capsys, _argv(records, report))
    assert "checkpoints" in err and "--resume" in err and "--overwrite" in err
    err = _one_line_exit_2(capsys, _argv(records, report, "--min-gain", "0.05", "--resume"))
    assert "min_gain" in err and "--overwrite" in err
    other = [records[1], records[0]]  # other records, same options
    assert "records" in _one_line_exit_2(capsys, _argv(other, report, "--resume"))

    # --resume: the finished fits loaded, the rest fitted, the uninterrupted result;
    # --no-figures and --threads (not options of the computation: the runs above fit
    # their candidates in the CLI's default threads) leave the report's PNG files out
    # and fit one candidate at a time
    assert main(_argv(records, report, "--resume", "--no-figures", "--threads", "1")) == 0
    err = capsys.readouterr().err
    assert "the declared cascade's fit loaded from its checkpoint" in err
    assert "round 1, candidate 1 of 2: output_offset" in err and "loaded" in err
    assert "round 1, candidate 2 of 2: output_drift" in err
    _same_results(json.loads((report / "report.json").read_text()), expected)
    assert not (report / "checkpoints").exists()
    drawn_figures = sorted(str(p.relative_to(whole)) for p in whole.rglob("*.png"))
    assert drawn_figures == [
        "compare.png",
        "records/00-estimation.png",
        "records/01-validation.png",
        "residual_after_overview.png",
        "residual_before_overview.png",
    ]
    assert not list(report.rglob("*.png"))
    text, drawn = (report / "report.md").read_text(), (whole / "report.md").read_text()
    assert "![" in drawn and "![" not in text
    # the same score lines for every record, the figure links aside
    scores = [line for line in drawn.splitlines() if line.startswith("- estimation, ")]
    assert scores and all(line.rstrip() in text for line in scores)


def test_refusals_are_one_line(records, tmp_path, capsys):
    err = _one_line_exit_2(capsys, _argv(records, tmp_path, "--resume", "--overwrite"))
    assert "--resume" in err and "--overwrite" in err
    train, valid = records
    err = _one_line_exit_2(capsys, ["loop", train, "--validate", valid, *OPTIONS, "--resume"])
    assert "--report" in err
    # another run's checkpoints: refused without a flag, before anything is read
    Checkpoints(tmp_path / "checkpoints").start(identity([np.zeros(3)], {"other": 1}))
    err = _one_line_exit_2(capsys, _argv(records, tmp_path))
    assert "earlier loop" in err and "--resume" in err


def test_overwrite_starts_afresh(records, tmp_path, capsys):
    Checkpoints(tmp_path / "checkpoints").start(identity([np.zeros(3)], {"other": 1}))
    assert main(_argv(records, tmp_path, "--overwrite", "--max-effects", "0", "--no-figures")) == 0
    assert "resuming" not in capsys.readouterr().err
    assert not (tmp_path / "checkpoints").exists()
    assert json.loads((tmp_path / "report.json").read_text())["effect_added"] == []


def test_a_stored_model_is_the_fitted_one_bit_for_bit():
    from jaxcascade import example
    from jaxcascade._measured._effects import ExtendedModel, OutputOffset, PrandtlIshlinskii
    from jaxcascade._measured._noise import ARNoise

    params = example(1).params()
    path = PrandtlIshlinskii(*(jax.numpy.asarray(v) for v in ([0.1, 0.2], [0.5], [1 / 3], 0.7)))
    model = ExtendedModel(
        params, (OutputOffset(jax.numpy.asarray(np.pi)), path), ARNoise(np.array([0.3, -0.1]))
    )
    loaded = model_from_dict(json.loads(json.dumps(model_to_dict(model))))
    assert jax.tree_util.tree_structure(loaded) == jax.tree_util.tree_structure(model)
    leaves = jax.tree_util.tree_leaves(loaded), jax.tree_util.tree_leaves(model)
    for a, b in zip(*leaves, strict=True):
        assert type(a) is type(b) and a.dtype == b.dtype and a.shape == b.shape
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()
        assert getattr(a, "weak_type", False) == getattr(b, "weak_type", False)
    assert loaded.structure() == model.structure()


def _loop_process(records, report, *extra, cache):
    env = {**os.environ, "JAXCASCADE_CACHE": str(cache)}
    argv = [sys.executable, "-m", "jaxcascade", *_argv(records, report, *extra)]
    return subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


@pytest.mark.slow  # three loop processes, the first compiling everything: minutes
def test_a_loop_killed_with_sigkill_resumes_to_the_uninterrupted_result(records, tmp_path):
    # JAX's persistent cache is shared by the three processes (each compiles the same
    # programs); the killed one runs first, with the cache empty, so it is slow enough
    # to be killed mid-round.
    cache = tmp_path / "xla"
    report = tmp_path / "killed"
    killed = _loop_process(records, report, cache=cache)
    deadline = time.monotonic() + 600
    while not list((report / "checkpoints").glob("round-01-*.json")):
        assert killed.poll() is None, killed.communicate()[1].decode()[-2000:]
        assert time.monotonic() < deadline
        time.sleep(0.05)
    killed.send_signal(signal.SIGKILL)
    killed.communicate()  # waits, and closes its pipes
    assert killed.returncode == -signal.SIGKILL
    assert not (report / "report.json").exists()
    kept = {p.name for p in (report / "checkpoints").iterdir()}
    assert {"run.json", "declared.json"} <= kept

    resumed = _loop_process(records, report, "--resume", cache=cache)
    _, err = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, err.decode()[-2000:]
    assert "loaded from its checkpoint" in err.decode()

    whole = tmp_path / "whole"
    uninterrupted = _loop_process(records, whole, cache=cache)
    _, err = uninterrupted.communicate(timeout=600)
    assert uninterrupted.returncode == 0, err.decode()[-2000:]
    _same_results(
        json.loads((report / "report.json").read_text()),
        json.loads((whole / "report.json").read_text()),
    )
