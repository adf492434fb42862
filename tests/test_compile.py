"""XLA options of the package's programs (`_compile`): passed per program, never
global, and the same estimates with or without them."""

import jax
import jax.numpy as jnp
import numpy as np

import jaxcascade as jc
from jaxcascade._compile import OPTIONS, compiler_options, jit


def test_options_on_the_cpu_and_the_way_back_to_xlas_defaults(monkeypatch):
    assert jax.default_backend() == "cpu"
    assert compiler_options() == OPTIONS
    monkeypatch.setenv("JAXCASCADE_COMPILE", "default")
    assert compiler_options() == {}


def test_jit_passes_them_at_the_top_and_not_when_nested():
    # JAX refuses compiler options on a jit inside another program: the wrapper gives
    # them to its own program only
    @jit(static_argnames=("power",))
    def f(x, power):
        return jnp.sum(x**power)

    x = jnp.arange(4.0)
    assert float(f(x, power=2)) == 14.0
    assert float(jax.jit(lambda x: f(x, power=2) + 1.0)(x)) == 15.0
    assert jax.vmap(lambda x: f(x, power=1))(jnp.ones((3, 2))).tolist() == [2.0, 2.0, 2.0]


def test_the_same_estimates_with_xlas_defaults():
    ex = jc.example(1)
    keys = jax.random.split(jax.random.PRNGKey(0), 8)

    def one(key):
        key_u, key_e = jax.random.split(key)
        u = jc.uniform_input(key_u, 1000)
        y, _ = jc.measure(key_e, ex.params(u.dtype), u, snr=25.0)
        return jc.voros(u, y, ex.orders).params.to_vector()

    tuned = jax.jit(jax.vmap(one), compiler_options=compiler_options())(keys)
    default = jax.jit(jax.vmap(one))(keys)
    np.testing.assert_allclose(tuned, default, rtol=1e-9, atol=1e-12)


def test_bound_releases_past_its_program_limit_and_keeps_programs_under_it():
    # Issue 21: the loop's stages share programs until more than `programs` were
    # compiled since the last release (or the process maps too much); then all go.
    from jaxcascade._compile import bound, compile_count, mappings, release

    release()
    square, x = jax.jit(lambda x: x * x), np.ones(3)
    square(x)
    assert compile_count() >= 1
    assert not bound(programs=10**6, mapped=10**9)  # under both limits: kept
    before = compile_count()
    square(x)
    assert compile_count() == before  # reused, not compiled again
    assert bound(programs=0, mapped=10**9)  # one program past a limit of none
    square(x)
    assert compile_count() > before  # released: compiled again
    if mappings() is not None:
        assert mappings() > 0
        assert bound(programs=10**6, mapped=0)
