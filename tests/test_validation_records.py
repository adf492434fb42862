"""Several validation records (`jaxcascade loop --validate A B`, `model_error_loop` with
lists): each simulated and initialised on its own, the scored parts pooled."""

import json

import jax
import numpy as np
import pandas as pd
import pytest

import jaxcascade as jc
from jaxcascade._cli import main
from jaxcascade._measured._effects import plain
from jaxcascade._measured._loop import evaluate, initialised_output, model_error_loop

ORDERS = jc.Orders(2, 2, 2, 2)


def _records(count, n=240, snr=25.0):
    ex = jc.example(1)
    out = []
    for k in range(count):
        key_u, key_e = jax.random.split(jax.random.PRNGKey(10 + k))
        u = jc.uniform_input(key_u, n)
        y, _ = jc.measure(key_e, ex.params(), u, snr)
        out.append((np.asarray(u), np.asarray(y)))
    return ex, out


def test_several_validation_records_are_scored_each_from_its_own_state_and_pooled():
    ex, records = _records(2)
    model = plain(ex.params())
    n = 20
    pooled = evaluate(model, [r[0] for r in records], [r[1] for r in records], init_samples=n)
    # the reference: each record initialised on its own first n samples, then joined
    residuals, scored = [], []
    for u, y in records:
        simulated = np.asarray(initialised_output(model, u, y, n, n))
        residuals.append(y[n:] - simulated)
        scored.append(y[n:])
    residual, y_scored = np.concatenate(residuals), np.concatenate(scored)
    np.testing.assert_allclose(pooled.residual, residual, rtol=0, atol=1e-12)
    expected = np.sqrt(np.mean(residual**2)) / np.std(y_scored)
    assert pooled.error == pytest.approx(expected, rel=1e-12)
    # the residual tests see every scored sample; a true model at SNR 25 passes them
    assert pooled.tests.ok
    # one record in a list is judged exactly as the record alone
    one = evaluate(model, records[0][0], records[0][1], init_samples=n)
    listed = evaluate(model, [records[0][0]], [records[0][1]], init_samples=n)
    assert one.error == listed.error
    np.testing.assert_array_equal(one.residual, listed.residual)


def test_an_integrating_loop_judges_the_output_integrated_back():
    # the records' outputs are differences (`_integrating`): the error is the NRMSE of
    # each scored part summed from its start, its level set from the measured output;
    # the residual and its tests stay on the difference
    ex, records = _records(2)
    model = plain(ex.params())
    n = 20
    us, ys = [r[0] for r in records], [r[1] for r in records]
    plain_error = evaluate(model, us, ys, init_samples=n)
    integrated = evaluate(model, us, ys, init_samples=n, integrating=True)
    np.testing.assert_array_equal(integrated.residual, plain_error.residual)
    levels, simulated_levels = [], []
    for u, y in records:
        simulated = np.asarray(initialised_output(model, u, y, n, n))
        levels.append(np.cumsum(y[n:]))
        simulated_levels.append(np.cumsum(simulated))
    level, simulated_level = np.concatenate(levels), np.concatenate(simulated_levels)
    expected = np.sqrt(np.mean((level - simulated_level) ** 2)) / np.std(level)
    assert integrated.error == pytest.approx(expected, rel=1e-12)
    assert integrated.error != pytest.approx(plain_error.error, rel=1e-3)


def test_a_window_applies_to_one_validation_record_only():
    ex, records = _records(3)
    (u, y), *validation = records
    with pytest.raises(ValueError, match="a window applies to one validation record"):
        model_error_loop(
            u,
            y,
            [v[0] for v in validation],
            [v[1] for v in validation],
            ORDERS,
            base=ex.params(),
            max_effects=0,
            window=(30, 90),
        )


def test_the_loop_pools_its_validation_records(tmp_path, capsys):
    """`--validate A B` on the command line: both records scored and reported."""
    ex, records = _records(3)
    paths = []
    for k, (u, y) in enumerate(records):
        path = tmp_path / f"r{k}.csv"
        pd.DataFrame({"u": u, "y": y}).to_csv(path, index=False)
        paths.append(str(path))
    argv = ["loop", paths[0], "--validate", paths[1], paths[2], "--input", "u"]
    argv += ["--output", "y", "--max-effects", "0", "--quiet", "--json"]
    argv += ["--report", str(tmp_path / "report"), "--no-figures"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    full = json.loads((tmp_path / "report" / "report.json").read_text())
    assert summary["error_after"] == full["error_after"]
    rows = [s for s in full["scores"] if s["role"] == "validation"]
    assert {r["record"] for r in rows} == {"r1.csv", "r2.csv"}
    finals = [r["error"] for r in rows if r["model"] == "final model"]
    assert full["error_after"] == pytest.approx(np.mean(finals), rel=1e-12)
    # the default initialisation window cut to a quarter of the shortest scored record
    assert full["init_samples"] == 50
    report = (tmp_path / "report" / "report.md").read_text()
    assert "2 validation records: the loop pooled them" in report
    # --window with two validation records: one sentence, exit code 2
    assert main([*argv, "--window", "10:100", "--overwrite"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--window scores one validation record" in err
