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
    assert float(jax.grad(lambda x: f(x, power=2))(x)[3]) == 6.0
    assert float(jax.lax.scan(lambda c, v: (c + f(v, power=1), None), 0.0, x[:, None])[0]) == 6.0


def test_an_eager_vmap_compiles_its_own_program_with_the_options():
    # `_own_program`: arrays, or an eager vmap's tracers (JAX compiles the batched
    # program on its own, with the options); not inside jit, grad or scan
    from jaxcascade._compile import _own_program

    seen = []

    def probe(x):
        seen.append(_own_program(x))
        return x

    x = jnp.ones((3, 2))
    probe(x)
    jax.vmap(probe)(x)
    jax.vmap(jax.vmap(probe))(x)
    jax.jit(probe)(x)
    jax.jit(jax.vmap(probe))(x)
    jax.grad(lambda v: jnp.sum(probe(v)))(x)
    jax.lax.scan(lambda c, v: (c, probe(v)), 0.0, x)
    assert seen == [True, True, True, False, False, False, False]


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


def test_release_hands_the_freed_memory_back(monkeypatch):
    # glibc keeps what a thread freed in its arena: `release` trims it (`_compile.trim`),
    # else the programs it freed stay resident (the Wiener-Hammerstein stand-in's loop)
    from jaxcascade import _compile

    calls = []
    monkeypatch.setattr(_compile, "_malloc_trim", lambda: calls.append)
    _compile.release()
    assert calls == [0]


# Issue 33: traced programs kept across processes (`_compile.exported`). Run in a fresh
# interpreter: the persistent cache it needs stays off in the test process (conftest).
KEPT = r"""
import sys, pathlib
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_compilation_cache_dir", sys.argv[1])
from jaxcascade import _compile
from jaxcascade._measured._initial_state import _initialise
from jaxcascade._measured._testing import UNDECLARED, undeclared_record

model, _ = UNDECLARED["input_delay"]()
u, y = undeclared_record(model, jax.random.PRNGKey(3), 256, 20.0)
args = (model, u, y, jnp.asarray(100, jnp.int32))
options = dict(n=50, grid=(0.0, 0.5, 1.0), max_steps=20)
kept = _initialise(*args, **options)  # traced, exported, written, run
files = list((pathlib.Path(sys.argv[1]) / "exported").glob("*.bin"))
assert len(files) == 1, files
# a new process's view: nothing in memory, the program read back from its file
fresh = _compile.exported(_initialise.__wrapped__)
jax.clear_caches()
loaded_calls = []
load = _compile._load
_compile._load = lambda *a: loaded_calls.append(1) or load(*a)
read = fresh(*args, **options)
assert loaded_calls and load(files[0].parent, files[0].stem) is not None
plain = _initialise.jitted(*args, **options)
for a, b in zip(jax.tree.leaves((kept, read)), jax.tree.leaves((plain, plain))):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
assert type(read.state) is type(plain.state)

# a program jax.export cannot serialise (a host callback) runs its own jit instead
def host(x):
    return jax.pure_callback(np.sin, jax.ShapeDtypeStruct(x.shape, x.dtype), x) + 1.0
kept_host = _compile.exported(host)
np.testing.assert_array_equal(np.asarray(kept_host(jnp.ones(3))), np.sin(np.ones(3)) + 1.0)
assert len(list((pathlib.Path(sys.argv[1]) / "exported").glob("*.bin"))) == 1
print("ok")
"""


def test_exported_programs_are_read_back_and_give_the_same_results_bit_for_bit(tmp_path):
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-c", KEPT, str(tmp_path / "cache")],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-3000:]


def test_exported_keys_change_with_the_static_parts_and_shapes():
    from jaxcascade._compile import _key

    leaves = [np.zeros(3)]
    tree = jax.tree_util.tree_structure(leaves)
    base = _key("f", (None, {"n": 50}), tree, leaves)
    assert base == _key("f", (None, {"n": 50}), tree, leaves)
    assert base != _key("f", (None, {"n": 51}), tree, leaves)
    assert base != _key("g", (None, {"n": 50}), tree, leaves)
    assert base != _key("f", (None, {"n": 50}), tree, [np.zeros(4)])
    assert base != _key("f", (None, {"n": 50}), tree, [np.zeros(3, np.float32)])


def test_exported_is_the_functions_own_jit_without_a_persistent_cache():
    from jaxcascade._compile import exported, exported_folder

    assert exported_folder() is None  # conftest: the cache is off in the tests
    calls = []

    @exported
    def f(x):
        calls.append(1)
        return x * 2.0

    assert float(f(jnp.asarray(2.0))) == 4.0
    assert float(f(jnp.asarray(3.0))) == 6.0
    assert len(calls) == 1  # traced once, by its own jit
