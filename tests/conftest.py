"""Tests compute in float64: the oracle comparisons need it (the package never sets it).

The CLI turns on JAX's persistent compilation cache (`~/.cache/jaxcascade/xla`) when it
runs; the tests call the CLI in-process, so the cache would stay on for every later test
and read back executables compiled by earlier ones. Deserialising those (executables
with the fused kernel's FFI call among them) crashed the interpreter in
`compilation_cache.get_executable_and_time` late in a full run, once on CI and once here,
not in any subset we could isolate. The tests therefore run with the cache off, and
leave the user's cache alone.
"""

import os

os.environ["JAXCASCADE_CACHE"] = "off"

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)


import pytest  # noqa: E402


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Free every compiled executable after each test module. A full run compiles
    thousands of programs; XLA's CPU code for each is mapped into the process, and two
    full runs crashed late (a segfault reading a cache entry, an abort inside an XLA
    compile) with that code still held. Each module starts from empty caches instead."""
    yield
    from jaxcascade import _compile
    from jaxcascade._montecarlo import _engine

    _engine._EXECUTABLES.clear()
    _engine._compiled.cache_clear()
    _engine._parts.cache_clear()
    # `release`, not a bare `jax.clear_caches()`: it also restarts the count of programs
    # compiled since the last release, which `_compile.bound` compares with its limit.
    # Counted across modules, a loop in a later module found the limit passed at its
    # first stage and released what it had just compiled (the robust fit, compiled twice).
    _compile.release()
