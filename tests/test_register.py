"""A user's own estimator (issue 24): `register_estimator` and the entry-point group make
an outside estimator of either kind (an `Estimator`, a host function) usable in sweeps,
spec files, `fit` and `bench`; its sweep rows equal direct calls on the same records."""

import dataclasses
import importlib.util
import json
import pathlib
import sys
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

import jaxcascade as jc
from jaxcascade import _estimator
from jaxcascade._cli import main
from jaxcascade._montecarlo._engine import records
from jaxcascade._montecarlo._run import run
from jaxcascade._montecarlo._spec import Cell, Spec
from jaxcascade._status import status_names

ROOT = pathlib.Path(__file__).parents[1]
EXAMPLE = ROOT / "docs" / "examples" / "own_estimators.py"


def _docs_example():
    spec = importlib.util.spec_from_file_location("own_estimators", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class Moments(jc.Estimator):
    """An outside traceable estimator, cheap to compile: the paper's initial values with
    the right-hand slopes from the output's moments (a function of the record)."""

    name: ClassVar[str] = "moments"
    summary: ClassVar[str] = "initial values scaled by the output's moments"

    scale: float = eqx.field(static=True, default=1.0)

    def __call__(self, u, y, orders, *, key=None, input_range=None):
        init = jc.initial_guess(orders, jnp.min(u), jnp.max(u), u.dtype)
        vector = init.to_vector().at[orders.slices["MR"]].set(self.scale * jnp.std(y))
        params = jc.CascadeParams.from_vector(vector, orders, check=False)
        return jc.Solution(
            params=params,
            history=vector[None],
            iterations=jnp.ones((), jnp.int32),
            cost=jnp.mean((jc.simulate(params, u) - y) ** 2),
            status=jnp.zeros((), jnp.int32),
            cycle_amplitude=jnp.zeros((), u.dtype),
            path=jnp.zeros((), jnp.int32),
        )


def mean_host(u, y, orders, *, shift: float = 0.0):
    """A host function: the paper's initial values, MR1 from the output's mean."""
    vector = np.array(jc.initial_guess(orders, u.min(), u.max()).to_vector(), float)
    vector[0] = np.mean(y) + shift
    return vector


@pytest.fixture
def registry():
    """Registrations of a test are undone after it."""
    saved = dict(_estimator.ESTIMATORS)
    yield
    _estimator.ESTIMATORS.clear()
    _estimator.ESTIMATORS.update(saved)


def _spec(name, **settings):
    return Spec(
        example=1,
        n=(300,),
        snr=(25.0,),
        realisations=3,
        estimators=(name,),
        settings={name: settings} if settings else {},
        chunk_size=2,
    )


def _direct(spec, vector):
    """`vector(u, y)` on each record of the sweep's cell, as the sweep's rows."""
    cell = Cell(spec.n[0], spec.snr[0], spec.estimators[0])
    drawn = records(spec, cell, range(spec.realisations))
    return np.stack([vector(u, y) for u, y in zip(drawn["u"], drawn["y"], strict=True)])


def test_host_function_sweep_rows_equal_direct_calls(registry):
    example = _docs_example()
    jc.register_estimator("scipy_oe", example.scipy_output_error)
    spec = _spec("scipy_oe", max_nfev=50)
    table = run(spec, progress=False)
    direct = _direct(spec, lambda u, y: example.scipy_output_error(u, y, spec.orders, max_nfev=50))
    np.testing.assert_array_equal(table[list(spec.orders.names)].to_numpy(), direct)
    # the status is the package's word on each vector (`_basin.claim`), as on a direct call
    host = jc.estimator("scipy_oe", max_nfev=50)
    cell = Cell(spec.n[0], spec.snr[0], spec.estimators[0])
    drawn = records(spec, cell, range(spec.realisations))
    words = [
        status_names([int(host.solution(v, u, y, spec.orders).status)])[0]
        for v, u, y in zip(direct, drawn["u"], drawn["y"], strict=True)
    ]
    assert table["status"].tolist() == words and set(words) <= {"converged", "local_minimum"}
    assert (table["fit_seconds"] > 0).all() and table["fit_seconds"].nunique() == 3
    # the settings are recorded with the sweep like ours
    assert spec.to_dict()["estimator"] == {"scipy_oe": {"max_nfev": 50}}


def test_estimator_class_sweep_rows_equal_direct_calls(registry):
    jc.register_estimator("moments", Moments)
    spec = _spec("moments", scale=2.0)
    table = run(spec, progress=False)
    fit = jc.estimator("moments", scale=2.0)
    direct = _direct(spec, lambda u, y: np.asarray(fit(u, y, spec.orders).params.to_vector()))
    np.testing.assert_allclose(table[list(spec.orders.names)].to_numpy(), direct, rtol=1e-12)
    assert np.all(table["MR1"].to_numpy() != 0)


def test_host_function_failure_and_every_estimator_sees_the_same_records(registry):
    def failing(u, y, orders):
        """Fails on every record."""
        return np.full(len(orders.names), np.nan)

    jc.register_estimator("failing", failing)
    jc.register_estimator("mean_host", mean_host)
    spec = _spec("mean_host")
    spec = dataclasses.replace(spec, estimators=("mean_host", "failing"), settings={})
    table = run(spec, progress=False)
    failed = table[table["estimator"] == "failing"]
    assert (failed["status"] == "failed").all() and not failed["recovered"].any()
    host = table[table["estimator"] == "mean_host"]
    drawn = records(spec, Cell(300, 25.0, "mean_host"), range(3))
    np.testing.assert_array_equal(host["MR1"].to_numpy(), drawn["y"].mean(axis=1))
    np.testing.assert_array_equal(host["key"].to_numpy(), failed["key"].to_numpy())


def test_settings_are_validated(registry):
    jc.register_estimator("mean_host", mean_host)
    jc.register_estimator("moments", Moments)
    with pytest.raises(ValueError, match="Unknown setting 'offset'"):
        _spec("mean_host", offset=1.0)
    with pytest.raises(ValueError, match="must be a number"):
        _spec("mean_host", shift="a lot")
    with pytest.raises(ValueError, match="must be a number"):
        _spec("moments", scale="big")
    with pytest.raises(ValueError, match="one of jaxcascade's own"):
        jc.register_estimator("robust", mean_host)
    with pytest.raises(ValueError, match=r"take \(u, y, orders\)"):
        jc.register_estimator("bad", lambda u, y: None)
    with pytest.raises(ValueError, match="Unknown estimator 'nowhere'"):
        jc.estimator("nowhere")


def test_entry_point_is_read_on_first_look_up(registry, tmp_path, monkeypatch):
    package = tmp_path / "outside_estimators.py"
    package.write_text(
        "import numpy as np\n"
        "def zeros(u, y, orders):\n"
        '    """All zeros."""\n'
        "    return np.zeros(len(orders.names))\n"
    )
    info = tmp_path / "outside_estimators-1.0.dist-info"
    info.mkdir()
    metadata = "Metadata-Version: 2.1\nName: outside-estimators\nVersion: 1.0\n"
    (info / "METADATA").write_text(metadata)
    (info / "entry_points.txt").write_text(
        "[jaxcascade.estimators]\nzeros_outside = outside_estimators:zeros\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(_estimator, "_entry_points_read", False)
    assert "zeros_outside" not in _estimator.ESTIMATORS
    fit = jc.estimator("zeros_outside")
    assert _estimator.ESTIMATORS["zeros_outside"].summary == "All zeros."
    assert np.all(fit.vector(np.zeros(200), np.zeros(200), jc.Orders()) == 0)
    sys.modules.pop("outside_estimators", None)


def test_cli_sweep_and_fit_run_a_registered_host_function(registry, tmp_path, capsys):
    jc.register_estimator("mean_host", mean_host)
    out = tmp_path / "sweep.parquet"
    argv = ["sweep", "--example", "1", "--n", "300", "--realisations", "2", "--out", str(out)]
    assert main([*argv, "--estimator", "mean_host"]) == 0
    table = pd.read_parquet(out)
    assert set(table["estimator"]) == {"mean_host"}
    ex = jc.example(1)
    u = np.asarray(jc.uniform_input(jc_key(0), 300))
    y = np.asarray(jc.simulate(ex.params(), u))
    data = tmp_path / "record.csv"
    pd.DataFrame({"u": u, "y": y}).to_csv(data, index=False)
    capsys.readouterr()
    argv = ["fit", str(data), "--input", "u", "--output", "y", "--estimator", "mean_host"]
    code = main([*argv, "--scaling", "none"])  # its estimate as the function returns it
    # the paper's initial values with MR1 = mean(y) do not describe the record: the fit
    # prints its estimate and says why it is no estimate (exit code 3, `_cli._fit`)
    out = capsys.readouterr().out
    assert code == 3 and f"MR1 = {np.mean(y): .6f}" in out
    assert "mean_host estimator: local_minimum" in out


def test_reproduce_runs_a_registered_estimator_and_refuses_an_unknown_one(
    registry, tmp_path, capsys
):
    # `reproduce --estimator` takes what the registry knows, a user's estimator included
    jc.register_estimator("mean_host", mean_host)
    argv = ["reproduce", "--example", "1", "--snr", "inf", "--out", str(tmp_path), "--json"]
    assert main([*argv, "--estimator", "mean_host"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    # the paper's initial values with MR1 = mean(y): no estimate of the record, and said so
    assert summary["status"] == "local_minimum" and set(summary["estimates"]) >= {"MR1", "cR"}
    assert list(tmp_path.glob("*mean_host_estimates.csv"))
    assert main([*argv, "--estimator", "nowhere"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Unknown estimator 'nowhere'" in err


def jc_key(seed):
    import jax

    return jax.random.PRNGKey(seed)


def test_bench_times_a_registered_host_function(registry, capsys):
    jc.register_estimator("mean_host", mean_host)
    argv = ["bench", "--estimator", "mean_host", "--system", "example1", "--realisations", "3"]
    argv += ["--n", "300", "--baseline-realisations", "1", "--json"]
    assert main(argv) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["estimator"] == "mean_host" and figures["fits_per_s"] > 0
    assert figures["recovered"] == 0  # MR1 from the output's mean is no estimate
    assert main(["bench", "--estimator", "nowhere"]) == 2


def test_the_docs_show_the_complete_example():
    text = (ROOT / "docs" / "estimators.md").read_text()
    assert EXAMPLE.read_text() in text
