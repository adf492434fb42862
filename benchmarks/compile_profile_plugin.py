"""pytest plugin of `benchmarks/default_run_profile.py`: JAX's monitoring events (tracing,
lowering, XLA compile, each with its program's name) summed per test and per program
name in every pytest process (each xdist worker), written as JSON to the folder
`JAXCASCADE_PROFILE_DIR` at the session's end (nothing without it)."""

from __future__ import annotations

import collections
import json
import os
import pathlib
import time

import pytest

EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "compile",
}
_test = ["(collection)"]
_tests: dict = collections.defaultdict(collections.Counter)
_programs: dict = collections.defaultdict(collections.Counter)


def _listen(event, seconds, **kwargs):
    stage = EVENTS.get(event)
    if stage is None:
        return
    for table in (_tests[_test[0]], _programs[str(kwargs.get("fun_name", "?"))]):
        table[f"{stage}_s"] += seconds
        table[f"{stage}_n"] += 1


def pytest_configure(config):
    if os.environ.get("JAXCASCADE_PROFILE_DIR"):
        import jax

        jax.monitoring.register_event_duration_secs_listener(_listen)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _test[0] = item.nodeid
    began = time.perf_counter()
    yield
    _tests[item.nodeid]["wall_s"] += time.perf_counter() - began
    _test[0] = "(between tests)"


def pytest_sessionfinish(session):
    folder = os.environ.get("JAXCASCADE_PROFILE_DIR")
    if folder:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        path = pathlib.Path(folder) / f"{worker}.json"
        path.write_text(json.dumps({"tests": _tests, "programs": _programs}))
