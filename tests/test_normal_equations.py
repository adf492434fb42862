"""The normal equations of a step: the fused native kernel against the XLA reference."""

import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pytest

import jaxcascade
from jaxcascade import CascadeParams, Orders, Status, _native, example, initial_guess, measure
from jaxcascade._compile import filter_jit
from jaxcascade._estimator import _fused
from jaxcascade._estimator._literal import voros_step
from jaxcascade._estimator._normal_equations import normal_equations, resolve

# compiled: called eagerly, every `lax.scan` inside compiles a program of its own at
# every call
_normal_equations = filter_jit(normal_equations)
_voros_step = filter_jit(voros_step)

fused = pytest.mark.skipif(not _fused.available(), reason=f"no fused kernel: {_fused.reason()}")

ORDERS = [Orders(2, 2, 2, 2), Orders(1, 1, 1, 0), Orders(3, 2, 3, 1), Orders(2, 3, 1, 3)]


def _record(orders, seed, n=700):
    rng = np.random.default_rng(seed)
    u = rng.uniform(-2, 2, n)
    vector, (_, _, y) = oracle.identifiable_system(rng, orders, u)
    y = y + 0.02 * rng.standard_normal(n)
    # estimates a little off the truth, so that every switch and column is exercised
    off = vector * (1 + 0.03 * rng.standard_normal(vector.size))
    params = CascadeParams.from_vector(jnp.asarray(off), orders, check=False)
    return params, jnp.asarray(u), jnp.asarray(y)


def _relative(a, b):
    return float(jnp.max(jnp.abs(a - b)) / jnp.maximum(jnp.max(jnp.abs(a)), 1e-300))


@fused
@pytest.mark.parametrize("orders", ORDERS, ids=str)
@pytest.mark.parametrize("first", [False, True], ids=["full-step", "first-step"])
def test_fused_equals_xla(orders, first):
    params, u, y = _record(orders, seed=orders.size)
    want = _normal_equations(params, u, y, first=first, backend="xla")
    got = _normal_equations(params, u, y, first=first, backend="fused")
    for a, b in zip(want, got, strict=True):
        assert a.shape == b.shape
        assert _relative(a, b) < 1e-12  # sums in another order: rounding only


@fused
@pytest.mark.parametrize("batch", [1, 5, 8])
def test_fused_under_vmap_equals_loop(batch):
    # Records are packed four to a SIMD group; a batch that is not a multiple of four
    # leaves lanes unused, and they must not leak into the real records.
    orders = Orders()
    records = [_record(orders, seed=100 + i) for i in range(batch)]
    params = jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *[r[0] for r in records])
    us = jnp.stack([r[1] for r in records])
    ys = jnp.stack([r[2] for r in records])
    batched = jax.vmap(lambda p, u, y: _normal_equations(p, u, y, backend="fused"))(params, us, ys)
    for i, (p, u, y) in enumerate(records):
        one = _normal_equations(p, u, y, backend="xla")
        for a, b in zip(one, batched, strict=True):
            assert _relative(a, b[i]) < 1e-12


@fused
@pytest.mark.parametrize("orders", ORDERS, ids=str)
def test_truth_is_a_fixed_point_of_the_fused_step(orders):
    rng = np.random.default_rng(70 + orders.size)
    u = rng.uniform(-2, 2, 1000)
    vector, (_, _, y) = oracle.identifiable_system(rng, orders, u)
    params = CascadeParams.from_vector(jnp.asarray(vector), orders)
    new, singular, cost, _ = _voros_step(params, jnp.asarray(u), jnp.asarray(y), backend="fused")
    assert not bool(singular)
    np.testing.assert_allclose(new, vector, rtol=0, atol=1e-10)
    # the cost comes from the normal equations: rounding of |yc|^2 / N, not of J
    assert float(cost) < 1e-13


@fused
@pytest.mark.parametrize("seed, snr", [(1, np.inf), (2, 25.0), (1, 25.0)])
def test_voros_fused_equals_xla(seed, snr):
    ex = example(1)
    u = jaxcascade.uniform_input(jax.random.key(seed), 2000)
    y, _ = measure(jax.random.key(100 + seed), ex.params(), u, snr)
    init = initial_guess(ex.orders, -2.0, 2.0)
    a = jaxcascade.voros(u, y, ex.orders, init, backend="xla")
    b = jaxcascade.voros(u, y, ex.orders, init, backend="fused")
    assert int(a.status) == int(b.status) and int(a.iterations) == int(b.iterations)
    np.testing.assert_allclose(a.history, b.history, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.cost, b.cost, rtol=1e-8, atol=1e-13)


@fused
def test_unvisited_regime_is_singular_with_the_fused_kernel():
    ex = example(1)
    u = jax.random.uniform(jax.random.key(3), (2000,), minval=0.05, maxval=2.0)
    y, _ = measure(jax.random.key(4), ex.params(), u, 25.0)
    sol = jaxcascade.voros(u, y, ex.orders, initial_guess(ex.orders, -2.0, 2.0), backend="fused")
    assert int(sol.status) == Status.singular
    assert np.all(np.isfinite(sol.history))


def test_backend_resolution():
    orders = Orders()
    assert resolve("xla", orders, jnp.float64) == "xla"
    # float32 and other devices always have the XLA path
    assert resolve("auto", orders, jnp.float32) == "xla"
    with pytest.raises(ValueError, match="fused kernel cannot run"):
        resolve("fused", orders, jnp.float32)
    with pytest.raises(ValueError, match="Unknown backend"):
        resolve("gpu", orders, jnp.float64)
    if _fused.available():
        assert resolve("auto", orders, jnp.float64) == "fused"


def test_disabled_kernel_is_reported(monkeypatch, tmp_path):
    monkeypatch.setenv("JAXCASCADE_FUSED", "off")
    _native.build.cache_clear()
    try:
        path, why = _native.build()
        assert path is None and "JAXCASCADE_FUSED" in why
    finally:
        monkeypatch.delenv("JAXCASCADE_FUSED")
        _native.build.cache_clear()


def test_missing_compiler_is_reported(monkeypatch, tmp_path):
    # A fresh build folder and no compiler: no kernel, a reason, and no exception.
    monkeypatch.setenv("JAXCASCADE_BUILD_DIR", str(tmp_path))
    monkeypatch.setenv("CXX", "no-such-compiler")
    monkeypatch.setattr(_native.shutil, "which", lambda name: None)
    _native.build.cache_clear()
    try:
        path, why = _native.build()
        assert path is None and "compiler" in why
    finally:
        _native.build.cache_clear()


def test_a_build_in_the_background_is_the_build_a_later_call_waits_for(monkeypatch, tmp_path):
    # A stand-in compiler that takes a while and counts its runs: the command's
    # background build and the estimator's own call while it runs compile once and
    # agree on the file.
    import sys
    import threading

    runs = tmp_path / "runs"
    compiler = tmp_path / "slow-c++"
    compiler.write_text(
        f"#!{sys.executable}\n"
        "import pathlib, sys, time\n"
        "time.sleep(0.5)\n"
        f"with open({str(runs)!r}, 'a') as f: f.write('x')\n"
        "pathlib.Path(sys.argv[sys.argv.index('-o') + 1]).write_bytes(b'')\n"
    )
    compiler.chmod(0o755)
    monkeypatch.setenv("JAXCASCADE_BUILD_DIR", str(tmp_path / "build"))
    monkeypatch.setenv("CXX", str(compiler))
    _native.build.cache_clear()
    try:
        _native.build_in_background()
        path, why = _native.build()
        for thread in threading.enumerate():
            if thread.name == "jaxcascade-kernel-build":
                thread.join(timeout=30)
        assert why == "" and path.exists() and path.parent == tmp_path / "build"
        assert runs.read_text() == "x"
        assert not [p for p in (tmp_path / "build").iterdir() if p.is_dir()]  # no scratch left
    finally:
        _native.build.cache_clear()
