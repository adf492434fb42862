"""Bad input at the Python API, the native kernel and the command line (issue 14).

Every row of the issue's table and each of its five points has a test here, asserting
the outcome exactly: a `ValueError` / `TypeError` whose sentence names the problem, or
the command line's one line on stderr with its exit code. Nothing here may crash the
interpreter, return NaN or report `converged`.

Fits are kept few and short (N = 300) and share their compiled shapes: the literal
estimator at its defaults (the API tests and `fit --estimator literal`), once under
`vmap`, and the robust estimator at `SMALL` settings (one compilation, reused by the
float32 row and by its jitted core fed non-finite data).
"""

import json
import math
import pydoc
import re

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import jaxcascade as jc
from jaxcascade import Orders, Status
from jaxcascade._cli import main
from jaxcascade._cli._common import strict_json
from jaxcascade._cli._fit import FAILED
from jaxcascade._estimator import _fused
from jaxcascade._estimator._normal_equations import normal_equations
from jaxcascade._estimator._robust import _robust, judge

ORDERS = Orders(2, 2, 2, 2)
N = 300
# The robust estimator, small: one compilation serves every robust test here.
SMALL = dict(n_starts=2, n_refine=1, max_steps=(8, 8), literal_start=False)
# What `robust(..., **SMALL)` passes its jitted core (so the core's cache is shared).
CORE = dict(SMALL, subset=1000, rtol=1e-6, atol=1e-9)


@pytest.fixture(scope="module")
def record():
    """One noisy record of the paper's Example 1 (float64 JAX arrays)."""
    ex = jc.example(1)
    u = jc.uniform_input(jax.random.key(0), N)
    y, _ = jc.measure(jax.random.key(1), ex.params(), u, 25.0)
    return u, y


def _one_line_error(capsys, argv, code=2):
    assert main(argv) == code
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith("jaxcascade: error: ") and "Traceback" not in err
    assert captured.out == ""  # nothing printed, in particular no JSON
    return err


def _csv(path, **columns):
    pd.DataFrame(columns).to_csv(path, index=False)
    return str(path)


def _strict(text):
    def refuse(constant):
        raise AssertionError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def _all_finite(solution):
    leaves = jax.tree_util.tree_leaves(solution)
    return all(bool(jnp.all(jnp.isfinite(leaf))) for leaf in leaves if leaf.dtype.kind == "f")


# ---- table rows: shapes, lengths and dtypes at the Python API ----------------------------


@pytest.mark.parametrize(
    "fit",
    [
        lambda u, y: jc.voros(u, y, ORDERS),
        lambda u, y: jc.robust(u, y, ORDERS),
        lambda u, y: jc.Literal()(u, y, ORDERS),
        lambda u, y: jc.Robust()(u, y, ORDERS),
    ],
    ids=["voros", "robust", "Literal", "Robust"],
)
def test_two_dimensional_batch_is_refused_before_the_kernel(record, fit):
    # Row 1: (2, N) arrays reached the fused kernel, which read past its buffers.
    u, y = record
    with pytest.raises(ValueError, match=r"got shape \(2, 300\).*jax\.vmap"):
        fit(jnp.stack([u, u]), jnp.stack([y, y]))


def test_column_vector_is_refused(record):
    # Row 2: a (N, 1) column was a segmentation fault.
    u, y = record
    with pytest.raises(ValueError, match=r"voros: u must be one record.*\(300, 1\).*ravel"):
        jc.voros(u[:, None], y[:, None], ORDERS)


def test_mismatched_lengths_are_refused(record):
    # Row 3: 300 samples of u against 250 of y gave a `singular` fit with a random cost.
    u, y = record
    with pytest.raises(ValueError, match="u and y must have the same length, got 300 and 250"):
        jc.voros(u, y[:250], ORDERS)
    with pytest.raises(ValueError, match="same length, got 300 and 250"):
        jc.Robust()(u, y[:250], ORDERS)


def test_shapes_are_checked_under_jit_too(record):
    # Traced arrays have static shapes: the same sentence, at trace time, before XLA.
    u, y = record
    fit = jax.jit(lambda u, y: jc.voros(u, y, ORDERS))
    with pytest.raises(ValueError, match=r"got shape \(2, 300\)"):
        fit(jnp.stack([u, u]), jnp.stack([y, y]))
    with pytest.raises(ValueError, match="same length, got 300 and 299"):
        jax.jit(lambda u, y: jc.Literal()(u, y, ORDERS))(u, y[:-1])


@pytest.mark.parametrize("where", ["u", "y"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_values_are_refused_by_both_estimators(record, where, bad):
    # Row 4: NaN in u gave NaN estimates of DR1 and DL1 from both estimators.
    u, y = (np.array(a) for a in record)
    (u if where == "u" else y)[17] = bad
    pattern = f"{where} has 1 NaN or infinite values, the first at index 17"
    for fit in (jc.voros, jc.robust):
        with pytest.raises(ValueError, match=pattern):
            fit(u, y, ORDERS)
    with pytest.raises(ValueError, match=pattern):
        jc.Literal()(u, y, ORDERS)


@pytest.mark.parametrize("where", ["u", "y"])
def test_huge_values_are_refused(record, where):
    # Rows 5 and 6 at the API: 1e300 squared overflows; robust "converged" on it.
    u, y = (np.array(a) for a in record)
    (u if where == "u" else y)[3] = 1e300
    with pytest.raises(ValueError, match=f"robust: {where} reaches 1e\\+300.*rescale the record"):
        jc.robust(u, y, ORDERS)


def test_float32_records_with_x64_fit_like_float64(record):
    # Row 7: float32 arrays with x64 enabled failed inside optimistix.
    u, y = (np.asarray(a, np.float32) for a in record)
    got = jc.robust(u, y, ORDERS, **SMALL)
    want = jc.robust(u.astype(np.float64), y.astype(np.float64), ORDERS, **SMALL)
    assert got.params.mR.dtype == jnp.float64
    np.testing.assert_array_equal(got.params.to_vector(), want.params.to_vector())
    assert Status(int(got.status)) == Status.converged


def test_python_lists_are_accepted(record):
    # Row 8: a list as u was an AttributeError.
    u, y = record
    as_lists = jc.Literal()(np.asarray(u).tolist(), np.asarray(y).tolist(), ORDERS)
    as_arrays = jc.Literal()(u, y, ORDERS)
    np.testing.assert_array_equal(as_lists.params.to_vector(), as_arrays.params.to_vector())
    assert int(as_lists.status) == int(as_arrays.status)
    np.testing.assert_array_equal(jc.simulate(jc.example(1).params(), [0.5, -1.0, 2.0]).shape, (3,))


@pytest.mark.parametrize(
    "u, n_y, error, words",
    [
        (["a"] * N, N, TypeError, "voros: u must hold real numbers"),
        (np.ones(N, complex), N, TypeError, "got dtype complex128"),
        (np.ones(N, bool), N, TypeError, "got dtype bool"),
        ([[1.0, 2.0], [3.0]], N, TypeError, "u must be a 1-D array of numbers"),
        (np.zeros(0), 0, ValueError, "u is empty"),
        (np.linspace(-1, 1, 100), 100, ValueError, "fewer than the 120 that orders 2,2,2,2 need"),
    ],
    ids=["strings", "complex", "bool", "ragged", "empty", "short"],
)
def test_other_bad_records_are_one_sentence(u, n_y, error, words):
    with pytest.raises(error, match=words):
        jc.voros(u, np.ones(n_y), ORDERS)


def test_orders_and_init_of_the_wrong_kind():
    u = np.linspace(-1, 1, N)
    with pytest.raises(TypeError, match=r"orders must be an Orders.*got tuple"):
        jc.voros(u, u, (2, 2, 2, 2))
    init = jc.initial_guess(Orders(1, 1, 1, 0), -1.0, 1.0)
    with pytest.raises(ValueError, match="init has orders 1,1,1,0, the fit 2,2,2,2"):
        jc.voros(u, u, ORDERS, init)


def test_simulator_and_loop_check_their_records(record):
    u, y = record
    params = jc.example(1).params()
    with pytest.raises(ValueError, match=r"simulate: u must be one record.*\(300, 1\)"):
        jc.simulate(params, u[:, None])
    with pytest.raises(ValueError, match="measure: u has 1 NaN"):
        jc.measure(jax.random.key(0), params, np.where(np.arange(N) == 5, np.nan, 0.0), 25.0)
    with pytest.raises(TypeError, match="params must be CascadeParams"):
        jc.simulate(params.to_vector(), u)
    # The output follows a float input's dtype; integers become the default float.
    assert jc.simulate(params, np.arange(5, dtype=np.float32)).dtype == jnp.float32
    assert jc.simulate(params, np.arange(5)).dtype == jnp.float64
    with pytest.raises(ValueError, match=r"model_error_loop \(validation\): u and y"):
        jc.model_error_loop(u, y, u, y[:200], ORDERS)


# ---- point 1: the kernel checks its own buffers ----------------------------------------


fused = pytest.mark.skipif(not _fused.available(), reason=f"no fused kernel: {_fused.reason()}")


def _kernel(u, y, params, orders=ORDERS):
    k = orders.g1_columns
    shapes = [(k, k), (k,), (2, 2), (2,), ()]
    call = jax.ffi.ffi_call(_fused.TARGET, [jax.ShapeDtypeStruct(s, jnp.float64) for s in shapes])
    attributes = {name: np.int64(getattr(orders, name)) for name in ("nR", "nL", "r", "p")}
    return jax.block_until_ready(call(u, y, params, first=np.int64(0), **attributes))


@fused
@pytest.mark.parametrize(
    "shapes, words",
    [
        (((300,), (250,), (12,)), r"u and y must have the same shape, got \(300,\) and \(250,\)"),
        (((300, 1), (300, 1), (12,)), r"params must have shape \(batch\.\.\., 12\)"),
        (((2, 300), (2, 300), (12,)), r"for u of shape \(2, 300\), got \(12,\)"),
        (((300,), (300,), (11,)), r"params must have shape .* got \(11,\)"),
        (((2, 300), (2, 300), (2, 12)), "the results do not hold a batch of 2 records"),
    ],
    ids=["short-y", "column", "batch-unbatched-params", "params-size", "results"],
)
def test_kernel_refuses_mismatched_buffers(shapes, words):
    u, y, params = (jnp.ones(shape) for shape in shapes)
    with pytest.raises(jax.errors.JaxRuntimeError, match=words):
        _kernel(u, y, params)


@fused
def test_kernel_error_reaches_the_caller_of_normal_equations(record):
    # The original crash: 2-D records straight into the fused normal equations.
    u, y = record
    params = jc.initial_guess(ORDERS, -2.0, 2.0)
    with pytest.raises(jax.errors.JaxRuntimeError, match="normal_equations: params"):
        jax.block_until_ready(
            normal_equations(params, jnp.stack([u, u]), jnp.stack([y, y]), backend="fused")
        )
    # the same buffers, well formed, still work
    ne = normal_equations(params, u, y, backend="fused")
    assert all(bool(jnp.all(jnp.isfinite(a))) for a in ne)


# ---- point 2: no NaN and no garbage status leave an estimator --------------------------


def _poisoned(record):
    u, y = record
    us = jnp.stack([u, u.at[5].set(jnp.nan), u])
    ys = jnp.stack([y, y, y.at[9].set(jnp.inf)])
    return us, ys


def test_literal_under_vmap_with_non_finite_data_returns_finite_failures(record):
    us, ys = _poisoned(record)
    solutions = jax.vmap(lambda u, y: jc.Literal()(u, y, ORDERS, input_range=(-2.0, 2.0)))(us, ys)
    assert _all_finite(solutions.params) and _all_finite(solutions.history)
    assert not bool(jnp.any(jnp.isnan(solutions.cost)))
    statuses = [Status(int(code)) for code in solutions.status]
    assert statuses[1].failure and statuses[2].failure, statuses


def test_robust_core_with_non_finite_data_returns_finite_failures(record):
    # Inside vmap or jit the eager checks see tracers, not values: NaN, inf and 1e300
    # reach the jitted core. It is called here directly, with the compiled shapes of
    # the float32 test above (the same traced code as under vmap, without a batch axis).
    u, y = record
    for bad_u, bad_y in (
        (u.at[5].set(jnp.nan), y),
        (u, y.at[9].set(jnp.inf)),
        (u.at[5].set(1e300), y),
    ):
        solution = _robust(bad_u, bad_y, ORDERS, None, **CORE)
        assert _all_finite(solution.params) and _all_finite(solution.history)
        assert not bool(jnp.isnan(solution.cost))
        assert Status(int(solution.status)).failure


def test_robust_judge_says_no_improvement():
    y = jnp.asarray(np.random.default_rng(0).standard_normal(N))
    start = jnp.linspace(0.1, 1.2, ORDERS.size)
    moved = start + 0.1
    variance = float(jnp.var(y))

    def judged(status, cost, estimate, trusted=False):
        return Status(int(judge(status, jnp.asarray(cost), y, start, estimate, trusted, 1e-6)))

    # a fit that explains the output and moved: its own status
    assert judged(Status.converged, 0.1 * variance, moved) == Status.converged
    # NRMSE >= 1 (or a non-finite cost): nothing explained
    assert judged(Status.converged, variance, moved) == Status.no_improvement
    assert judged(Status.cycled, jnp.nan, moved) == Status.no_improvement
    # never moved from a random start: the restart's "settled" must not say converged
    assert judged(Status.converged, 0.1 * variance, start) == Status.no_improvement
    # ... unless the start was itself an estimate (the literal fit, not failed)
    assert judged(Status.converged, 0.1 * variance, start, trusted=True) == Status.converged
    # a failure keeps its own, more specific, status
    assert judged(Status.max_iterations, variance, start) == Status.max_iterations
    assert Status.no_improvement.failure and "NRMSE >= 1" in Status.no_improvement.message
    assert list(jc.status_names([7])) == ["no_improvement"]


# ---- point 3: machine-readable output ----------------------------------------------------


def test_strict_json_writes_null_for_non_finite_numbers():
    value = {"nrmse": math.inf, "cost": np.float64("nan"), "list": [1.0, -math.inf, np.int64(3)]}
    assert _strict(strict_json(value)) == {"nrmse": None, "cost": None, "list": [1.0, None, 3]}


def test_fit_exits_3_on_a_failed_fit_with_strict_json(capsys, tmp_path):
    # Pure noise as output: the literal iteration cannot fit it (status `singular`).
    rng = np.random.default_rng(1)
    path = _csv(tmp_path / "noise.csv", u=rng.uniform(-2, 2, N), y=rng.standard_normal(N))
    argv = ["fit", path, "--input", "u", "--output", "y", "--estimator", "literal", "--json"]
    assert main(argv) == FAILED == 3
    captured = capsys.readouterr()
    assert captured.err == ""  # no raw warning
    result = _strict(captured.out)
    status = Status[result["status"]]
    assert status.failure and result["message"] == status.message
    assert all(math.isfinite(value) for value in result["model"]["estimates"].values())


@pytest.mark.parametrize("column", ["u", "y"])
def test_fit_refuses_1e300_before_fitting(capsys, tmp_path, column):
    # Rows 5 and 6: robust "converged" with DR1 = 5e299; "nrmse": Infinity, a raw
    # RuntimeWarning and exit 0.
    rng = np.random.default_rng(2)
    columns = {"u": rng.uniform(-2, 2, N), "y": rng.standard_normal(N)}
    columns[column][40] = 1e300
    path = _csv(tmp_path / "huge.csv", **columns)
    err = _one_line_error(capsys, ["fit", path, "--input", "u", "--output", "y", "--json"])
    assert f"'{column}'" in err and "1e+300" in err and "row 40" in err and "rescale" in err


def test_fit_help_documents_the_exit_codes(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"{FAILED} when it is a failure" in text and "2 for a bad request" in text


# ---- point 4: orders limits and work that cannot finish ----------------------------------


def test_largest_orders_are_stated_and_fit_the_kernel():
    largest = Orders(Orders.MAX_SEGMENTS, Orders.MAX_SEGMENTS, Orders.MAX_LAG, Orders.MAX_LAG)
    assert largest.g1_columns <= _fused.MAX_COLUMNS and Orders.MAX_LAG <= _fused.MAX_LAG
    with pytest.raises(ValueError, match=r"Order p = 65 is above the largest supported, 16"):
        Orders(2, 2, 2, 65)
    with pytest.raises(ValueError, match=r"Order nR = 50 is above the largest supported, 8"):
        Orders.parse("50,50,2,2")
    with pytest.raises(ValueError, match="above the largest supported"):
        jc.Spec.from_dict({"system": {"family": "random", "orders": "2,2,2,65"}})
    # ten samples per parameter, up front
    assert largest.min_samples == 640 and ORDERS.min_samples == 120


@pytest.mark.parametrize("command", ["fit", "loop", "sweep"])
@pytest.mark.parametrize("orders", ["2,2,2,65", "50,50,2,2"])
def test_orders_beyond_the_limits_fail_at_parse_time(capsys, tmp_path, command, orders):
    # Row 9 (a 41-line traceback; sweep left a .partial folder) and row 10 (no output
    # for 300 s): one line, before any file is read or written.
    out = tmp_path / "sweep.parquet"
    argv = {
        "fit": ["fit", "data.csv", "--input", "u", "--output", "y"],
        "loop": ["loop", "data.csv", "--validate", "v.csv", "--input", "u", "--output", "y"],
        "sweep": ["sweep", "--system", "random", "--n", "2000", "--out", str(out)],
    }[command]
    err = _one_line_error(capsys, [*argv, f"--orders={orders}"])
    assert "--orders" in err and "above the largest supported" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["fit", "loop"])
def test_a_branch_degree_in_a_straight_command_is_one_line(capsys, tmp_path, command):
    # fit and loop declare the straight backlash: a fifth number (the branch degree,
    # which sweeps take) is refused before any file is read
    argv = {
        "fit": ["fit", "data.csv", "--input", "u", "--output", "y"],
        "loop": ["loop", "data.csv", "--validate", "v.csv", "--input", "u", "--output", "y"],
    }[command]
    err = _one_line_error(capsys, [*argv, "--orders=2,2,2,2,3"])
    assert f"jaxcascade {command} declares the straight backlash" in err and "sweep" in err
    assert list(tmp_path.iterdir()) == []


def test_too_few_samples_per_parameter_is_refused_up_front(capsys, tmp_path):
    rng = np.random.default_rng(3)
    path = _csv(tmp_path / "short.csv", u=rng.uniform(-2, 2, N), y=rng.standard_normal(N))
    err = _one_line_error(
        capsys, ["fit", path, "--input", "u", "--output", "y", "--orders", "8,8,16,16"]
    )
    assert "has 300 samples, fewer than the 640 that orders 8,8,16,16 need" in err


# ---- point 5: the smaller ones -----------------------------------------------------------


def test_duplicate_csv_columns_are_refused(capsys, tmp_path):
    # Row 11: pandas renamed the second 'y' to 'y.1' and the first was used silently.
    path = tmp_path / "dup.csv"
    path.write_text("u,y,y\n" + "".join(f"{i % 7 - 3},{i % 5},{i % 3}\n" for i in range(N)))
    with pytest.raises(ValueError, match=r"repeated column names: 'y' \(columns 'u', 'y', 'y'\)"):
        jc.read_record(path, "u", "y")
    err = _one_line_error(capsys, ["fit", str(path), "--input", "u", "--output", "y"])
    assert "repeated column names: 'y'" in err


def test_duplicate_parquet_columns_are_refused(tmp_path):
    path = tmp_path / "dup.parquet"
    column = pa.array(np.linspace(-1, 1, N))
    pq.write_table(pa.table([column, column, column], names=["u", "u", "y"]), path)
    with pytest.raises(ValueError, match=r"repeated column names: 'u' \(columns 'u', 'u', 'y'\)"):
        jc.read_record(path, "u", "y")


def _summary(path, system="example2", n=999):
    rows = [
        {"system": system, "n": n, "snr": 25.0, "estimator": "literal", "parameter": name}
        | {"bias": 0.0, "bias_se": 0.1, "std": 1.0, "std_se": 0.1}
        for name in ORDERS.names
    ]
    pd.DataFrame(rows).to_csv(path, index=False)
    return str(path)


def test_compare_baseline_without_a_shared_cell_is_refused_before_the_sweep(capsys, tmp_path):
    # Row 12: reported only after the whole sweep had run.
    baseline = _summary(tmp_path / "baseline.csv")
    out = tmp_path / "run.parquet"
    argv = ["sweep", "--example", "1", "--n", "300", "--snr", "25", "--realisations", "2"]
    err = _one_line_error(capsys, [*argv, "--out", str(out), "--compare", baseline])
    assert "--compare" in err and "shares no grid cell" in err
    assert "example2 N=999 SNR=25 literal" in err and "example1 N=300 SNR=25 literal" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["baseline.csv"]  # nothing ran


def test_unwritable_folders_name_their_option(capsys, tmp_path):
    # Row 13: the message said to change --out.
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    rng = np.random.default_rng(4)
    data = _csv(tmp_path / "data.csv", u=rng.uniform(-2, 2, N), y=rng.standard_normal(N))
    out = str(tmp_path / "run.parquet")
    sweep = ["sweep", "--example", "1", "--n", "300", "--snr", "25", "--realisations", "2"]
    err = _one_line_error(capsys, [*sweep, "--out", out, "--plots", str(blocker / "plots")])
    assert "choose another with --plots" in err
    loop = ["loop", data, "--validate", data, "--input", "u", "--output", "y"]
    err = _one_line_error(capsys, [*loop, "--report", str(blocker / "report")])
    assert "choose another with --report" in err
    err = _one_line_error(capsys, ["fit", data, "--input", "u", "--output", "y", "--decimate", "0"])
    assert err.endswith("--decimate must be an integer >= 1, got 0.")


def test_loop_threads_below_one_is_refused_before_reading(capsys, tmp_path):
    missing = str(tmp_path / "missing.csv")  # never read: the option is refused first
    loop = ["loop", missing, "--validate", missing, "--input", "u", "--output", "y"]
    err = _one_line_error(capsys, [*loop, "--threads", "0"])
    assert err.endswith("threads (--threads) must be >= 1, got 0.")


@pytest.mark.parametrize("command", ["reproduce", "sweep", "fit", "loop", "bench"])
def test_every_help_ends_with_examples(capsys, command):
    with pytest.raises(SystemExit) as exit_:
        main([command, "--help"])
    assert exit_.value.code == 0
    lines = capsys.readouterr().out.rstrip().splitlines()
    examples = lines[lines.index("examples:") + 1 :]
    # a few examples, each a whole command line: enough to start from, short to read
    assert 1 <= len(examples) <= 4
    assert all(re.match(rf"  jaxcascade {command}( |$)", line) for line in examples), examples


def test_help_lists_every_public_function_and_class():
    text = pydoc.render_doc(jc, renderer=pydoc.plaintext)
    public = [
        n for n in dir(jc) if not n.startswith("_") and not isinstance(getattr(jc, n), type(jc))
    ]
    missing = [n for n in public if f"`{n}`" not in jc.__doc__ and f"`{n}(" not in jc.__doc__]
    assert not missing, missing
    assert jc.__doc__.strip().splitlines()[0] in text


def test_float64_data_with_float64_off_is_one_warning():
    """A float64 record computed in float32 without a word loses digits silently: the
    checks warn once, naming the switch (the package never flips it itself)."""
    import subprocess
    import sys

    code = (
        "import warnings, numpy as np, jaxcascade as jc\n"
        "u = np.linspace(-1, 1, 200)\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        "    jc.simulate(jc.example(1).params(), u)\n"
        "print([str(w.message) for w in caught])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "jax_enable_x64" in out.stdout and "float32" in out.stdout
