"""Dask distributed backend: a real LocalCluster (2 worker processes on loopback).

A sweep sent to the cluster must give the in-process table exactly (timing columns
aside), also when a worker is killed in the middle of the run: the scheduler recomputes
its chunks elsewhere and no realisation is lost or duplicated.
"""

import dataclasses
import logging
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pandas as pd
import pytest

from jaxcascade._cli import main
from jaxcascade._montecarlo._run import _identity, run
from jaxcascade._montecarlo._spec import Spec
from jaxcascade._montecarlo._tables import without_timing

distributed = pytest.importorskip("distributed", reason="Dask distributed is not installed")

N = 300


def tiny_spec(**changes) -> Spec:
    # Same shapes as test_montecarlo's specs (N 300, chunk 3), so in one session the
    # in-process references reuse their compilations.
    fields = dict(example=1, n=N, snr=[25.0, 50.0], realisations=9, seed=0, chunk_size=3)
    return Spec(**{**fields, **changes})


@pytest.fixture(scope="module")
def cluster():
    cluster = distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=":0",
        silence_logs=logging.CRITICAL,
    )
    try:
        yield cluster
    finally:
        cluster.close(timeout=30)


def _in_thread(function):
    """Run `function()` in a thread; its result, or its exception re-raised."""
    box = {}

    def target():
        try:
            box["result"] = function()
        except BaseException as error:  # noqa: B036 - re-raised in the test's thread
            box["error"] = error

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    return thread, box


def test_cli_sweep_on_the_cluster_equals_the_in_process_run(cluster, tmp_path, capsys):
    expected = without_timing(run(tiny_spec(), progress=False))
    out = tmp_path / "dask.parquet"
    argv = [
        "sweep", "--example", "1", "--n", str(N), "--snr", "25,50", "--realisations", "9",
        "--chunk-size", "3", "--out", str(out),
    ]  # fmt: skip
    assert main([*argv, "--scheduler", cluster.scheduler_address]) == 0
    table = pd.read_parquet(out)
    pd.testing.assert_frame_equal(without_timing(table), expected, check_exact=True)
    assert (table["fit_seconds"] > 0).all()
    # The scheduler is how the run ran, not what it computed: a finished distributed
    # run is reused without it, and the identity leaves it out.
    capsys.readouterr()
    assert main([*argv, "--resume"]) == 0
    scheduler = tiny_spec(scheduler=cluster.scheduler_address)
    assert _identity(scheduler, np.float64) == _identity(tiny_spec(), np.float64)
    assert scheduler.to_dict()["scheduler"] == cluster.scheduler_address


def test_a_worker_running_other_code_is_refused(cluster, monkeypatch):
    import jaxcascade._montecarlo._distributed

    monkeypatch.setattr(jaxcascade._montecarlo._distributed, "FINGERPRINT", "0.0.0+edited")
    with pytest.raises(RuntimeError, match="other jaxcascade code"):
        run(tiny_spec(realisations=3, snr=[25.0], scheduler=cluster.scheduler_address))


def test_a_worker_killed_mid_run_loses_and_duplicates_nothing(cluster, tmp_path):
    # Restarted workers have compiled nothing, so each one's first chunk spends seconds
    # compiling: a worker caught processing then is surely killed in the middle of it.
    spec = tiny_spec(realisations=12)
    expected = without_timing(run(spec, progress=False))
    out = tmp_path / "killed.parquet"
    with distributed.Client(cluster.scheduler_address, set_as_default=False) as client:
        client.restart()
        pids = client.run(os.getpid)
        remote = dataclasses.replace(spec, scheduler=cluster.scheduler_address)
        thread, box = _in_thread(lambda: run(remote, out, progress=False))
        deadline = time.monotonic() + 60
        victim = None
        while victim is None:
            assert time.monotonic() < deadline, "no worker started a chunk within 60 s"
            busy = [w for w, keys in client.processing().items() if keys and w in pids]
            if busy:
                time.sleep(0.5)  # well inside its first chunk's compilation
                busy = [w for w, keys in client.processing().items() if keys and w in pids]
                victim = busy[0] if busy else None
            time.sleep(0.05)
        os.kill(pids[victim], signal.SIGKILL)
        thread.join(timeout=120)
        assert not thread.is_alive(), "the distributed run did not finish within 120 s"
        assert victim not in client.scheduler_info()["workers"]  # it really died
    if "error" in box:
        raise box["error"]
    table = pd.read_parquet(out)
    assert len(table) == 24 and not table.duplicated(["snr", "realisation"]).any()
    assert sorted(table["realisation"]) == sorted(list(range(12)) * 2)
    pd.testing.assert_frame_equal(without_timing(table), expected, check_exact=True)


def test_missing_dask_is_one_clear_error(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails
    argv = ["sweep", "--example", "1", "--n", str(N), "--realisations", "2"]
    out = tmp_path / "r.parquet"
    assert main([*argv, "--scheduler", "tcp://127.0.0.1:1", "--out", str(out)]) == 2
    error = capsys.readouterr().err.strip()
    assert "install jaxcascade[distributed]" in error and len(error.splitlines()) == 1


def test_unreachable_scheduler_is_one_clear_error(tmp_path, capsys):
    argv = ["sweep", "--example", "1", "--n", str(N), "--realisations", "2"]
    out = tmp_path / "r.parquet"
    spec = tiny_spec(scheduler="tcp://127.0.0.1:9")  # discard port: nothing listens
    from jaxcascade._montecarlo._distributed import distributed_chunks

    with pytest.raises(OSError, match="cannot reach the Dask scheduler"):
        next(distributed_chunks(spec, [(spec.cells()[0], [0])], np.float64, connect_timeout=2))
    assert main([*argv, "--scheduler", "nonsense", "--out", str(out)]) == 2
    assert "tcp://HOST:8786" in capsys.readouterr().err


def test_the_default_path_does_not_import_dask():
    code = (
        "import sys, jaxcascade, jaxcascade._montecarlo, jaxcascade._cli;"
        "jaxcascade._cli.build_parser();"
        "assert not {'dask', 'distributed'} & set(sys.modules), 'dask imported'"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_throughput_runner_on_a_tiny_workload(tmp_path):
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "distributed_throughput.py"
    spec = importlib.util.spec_from_file_location("distributed_throughput", path)
    runner = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(runner)
    out = tmp_path / "throughput.csv"
    argv = ["--realisations", "6", "--n", str(N), "--chunk-size", "3", "--workers", "1"]
    assert runner.main([*argv, "--out", str(out)]) == 0
    table = pd.read_csv(out)
    assert list(table["mode"]) == ["in-process", "in-process threads", "dask"]
    assert list(table["workers"]) == [0, 2, 1]  # two chunks at once in-process; a worker
    assert (table["realisations_per_s"] > 0).all() and table["speedup"].iloc[0] == 1.0


def test_multisine_input_and_ar_noise_on_the_cluster_equal_the_in_process_run(cluster):
    spec = tiny_spec(
        realisations=6,
        snr=[25.0],
        input="multisine",
        input_settings={"band": [0.0, 0.8]},
        noise="ar",
        noise_settings={"poles": [0.9]},
    )
    expected = without_timing(run(spec, progress=False))
    remote = dataclasses.replace(spec, scheduler=cluster.scheduler_address)
    table = without_timing(run(remote, progress=False))
    assert set(table["noise"]) == {"ar"} and set(table["input"]) == {"multisine"}
    pd.testing.assert_frame_equal(table, expected, check_exact=True)


SCRIPT = '''
import dataclasses, logging, sys
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import distributed
import pandas as pd

jax.config.update("jax_enable_x64", True)
import jaxcascade as jc
from jaxcascade._montecarlo._run import run
from jaxcascade._montecarlo._tables import without_timing


def mean_host(u, y, orders, *, shift: float = 0.0):
    """Defined in this script only: the workers get it by value."""
    vector = np.array(jc.initial_guess(orders, -2.0, 2.0).to_vector())
    vector[0] = float(np.mean(np.abs(y))) + shift
    return vector


class Moments(jc.Estimator):
    name: ClassVar[str] = "moments_here"
    summary: ClassVar[str] = "defined in this script only"
    scale: float = eqx.field(static=True, default=1.0)

    def __call__(self, u, y, orders, *, key=None, input_range=None):
        init = jc.initial_guess(orders, jnp.min(u), jnp.max(u), u.dtype)
        vector = init.to_vector().at[0].set(self.scale * jnp.std(y))
        params = jc.CascadeParams.from_vector(vector, orders, check=False)
        return jc.Solution(
            params=params, history=vector[None], iterations=jnp.ones((), jnp.int32),
            cost=jnp.mean((jc.simulate(params, u) - y) ** 2), status=jnp.zeros((), jnp.int32),
            cycle_amplitude=jnp.zeros((), u.dtype), path=jnp.zeros((), jnp.int32),
        )


if __name__ == "__main__":
    jc.register_estimator("mean_here", mean_host)
    jc.register_estimator("moments_here", Moments)
    spec = jc.Spec(example=1, n=(300,), snr=(25.0,), realisations=4, seed=0, chunk_size=2,
                   estimators=("mean_here",), settings={"mean_here": {"shift": 0.5}})
    expected = without_timing(run(spec, progress=False))
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=":0",
                                  silence_logs=logging.CRITICAL) as cluster:
        remote = dataclasses.replace(spec, scheduler=cluster.scheduler_address)
        table = without_timing(run(remote, progress=False))
        pd.testing.assert_frame_equal(table, expected, check_exact=True)
        assert set(table["estimator"]) == {"mean_here"}
        print("identical", len(table))
        classed = dataclasses.replace(remote, estimators=("moments_here",), settings={})
        try:
            run(classed, progress=False)
        except ValueError as error:
            print("refused:", error)
'''


def test_estimators_registered_in_a_script_run_on_the_cluster(tmp_path):
    # a host function that exists only in the caller's script (`__main__`): the workers
    # get it with each chunk, and the table equals the in-process one; an Estimator class
    # of the script is refused in one sentence (equinox classes do not survive pickling
    # by value)
    script = tmp_path / "mine.py"
    script.write_text(SCRIPT)
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "identical 4" in done.stdout
    assert "refused: Estimator 'moments_here' is an Estimator class defined" in done.stdout
