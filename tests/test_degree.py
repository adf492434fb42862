"""The branch degree in the orders (`Orders.degree`, issue 39): degree 1 changes nothing
(the committed sweeps' keys, the examples' outputs, the layout), and degree > 1 is the
general backlash through simulation, the estimators and the Monte-Carlo engine."""

import json
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from degree_one_reference import reference

from jaxcascade._compile import jit
from jaxcascade._estimator import estimator
from jaxcascade._system._examples import example
from jaxcascade._system._general_backlash import general_example, simulate_general
from jaxcascade._system._model import CascadeParams, Orders
from jaxcascade._system._simulate import simulate, uniform_input

REFERENCE = pathlib.Path(__file__).parent / "data" / "degree_one_reference.json"


def curved(name="general1", degree=3):
    """The note's example as parameters of orders with the branch degree."""
    ex = general_example(name)
    nd = ex.backlash()
    orders = Orders(ex.orders.nR, ex.orders.nL, ex.orders.r, ex.orders.p, degree)
    pad = degree - 1 - nd.curveL.shape[0]
    curves = [jnp.concatenate([c, jnp.zeros((pad,), c.dtype)]) for c in (nd.curveL, nd.curveR)]
    vector = jnp.concatenate([ex.params().to_vector(), *curves])
    return CascadeParams.from_vector(vector, orders), ex


def test_degree_one_keeps_the_committed_sweeps_keys_and_the_examples_outputs():
    expected = json.loads(REFERENCE.read_text())
    assert reference() == expected


def test_degree_one_is_the_default_and_keeps_the_layout():
    orders = Orders(2, 2, 2, 2, 1)
    assert orders == Orders() and str(orders) == "2,2,2,2"
    assert Orders.parse("2,2,2,2") == orders
    params = example(1).params()
    assert params.curveL.shape == (0,) and params.to_vector().shape == (orders.size,)
    assert orders.names[-3:] == ("cL", "mR", "cR")


def test_curved_orders_name_and_place_the_curvature_terms():
    orders = Orders.parse("2,2,2,2,3")
    assert str(orders) == "2,2,2,2,3" and orders.size == 16
    assert orders.names[12:] == ("mL2", "mL3", "mR2", "mR3")
    assert orders.curvature == slice(12, 16) and orders.backlash == slice(9, 12)
    params, _ = curved()
    assert CascadeParams.from_dict(params.to_dict()).orders == orders
    theta = params.to_theta()
    assert float(theta[11]) == pytest.approx(0.3 * 1.2)  # C = cR mR, before the curvature
    assert np.array_equal(CascadeParams.from_theta(theta, orders).to_vector(), params.to_vector())


def test_bad_degree_and_curvature_are_one_sentence():
    with pytest.raises(ValueError, match="degree"):
        Orders(2, 2, 2, 2, 5)
    fields = example(1).params()
    parts = {name: getattr(fields, name) for name in ("MR", "DR", "ML", "DL", "a", "b")}
    parts |= {name: getattr(fields, name) for name in ("cL", "mR", "cR")}
    with pytest.raises(ValueError, match="curveL must have length degree - 1"):
        CascadeParams(**parts, orders=Orders(2, 2, 2, 2, 2))  # no curvature given
    with pytest.raises(ValueError, match="curveR must have length degree - 1"):
        CascadeParams(**parts, orders=Orders(2, 2, 2, 2, 2), curveL=jnp.zeros(1))


@pytest.mark.parametrize("name", ["general1", "general2"])
def test_simulate_at_a_degree_is_the_general_backlash_bit_for_bit(name):
    params, ex = curved(name, 3)
    u = uniform_input(jax.random.PRNGKey(3), 1500)
    general = simulate_general(ex.params(), ex.backlash(), u)
    assert np.array_equal(np.asarray(simulate(params, u)), np.asarray(general))


def test_the_functional_forms_refuse_curved_orders_in_one_sentence():
    from jaxcascade._estimator._literal import voros
    from jaxcascade._estimator._pem import pem
    from jaxcascade._estimator._robust import robust

    params, _ = curved()
    u = uniform_input(jax.random.PRNGKey(0), 2000)
    y = simulate(params, u)
    for function in (voros, robust, pem):
        with pytest.raises(ValueError, match="curved backlash branches .* registered estimators"):
            function(u, y, params.orders)


def test_literal_and_robust_fit_curved_branches_batched():
    """Noise-free records of general1 with cubic branches: the key-term iteration (where
    it says converged) and robust reach the truth, under `vmap`."""
    params, _ = curved("general1", 3)
    keys = jax.random.split(jax.random.PRNGKey(5), 2)
    u = jax.vmap(lambda k: uniform_input(k, 2000))(keys)
    y = jax.vmap(lambda one: simulate(params, one))(u)
    truth = np.asarray(params.to_vector())
    for name in ("literal", "robust"):
        one = estimator(name)
        fit = jit(jax.vmap(lambda a, b, k, one=one: one(a, b, params.orders, key=k)))
        solution = fit(u, y, keys)
        errors = np.max(np.abs(np.asarray(solution.params.to_vector()) - truth), axis=1)
        converged = np.asarray(solution.status) == 0
        assert solution.params.to_vector().shape == (2, params.orders.size)
        assert np.all(errors[converged] < 1e-6), (name, errors, solution.status)
        if name == "robust":
            assert converged.all(), solution.status


def test_pem_fits_curved_branches_batched():
    params, _ = curved("general2", 3)
    keys = jax.random.split(jax.random.PRNGKey(8), 2)
    u = jax.vmap(lambda k: uniform_input(k, 1500))(keys)
    y = jax.vmap(lambda one: simulate(params, one))(u)
    pem = estimator("pem")
    solution = jit(jax.vmap(lambda a, b, k: pem(a, b, params.orders, key=k)))(u, y, keys)
    estimate, truth = (np.asarray(p.to_vector()) for p in (solution.params, params))
    errors = np.max(np.abs(estimate - truth), axis=1)
    assert np.all(np.asarray(solution.status) == 0) and np.all(errors < 1e-6), errors


def curved_spec(**changes):
    from jaxcascade._montecarlo._spec import Spec

    params, _ = curved("general1", 3)
    fields = dict(
        params=params.to_dict(),
        orders=str(params.orders),
        n=(800,),
        snr=(25.0,),
        realisations=6,
        seed=0,
        estimators=("literal",),
        chunk_size=3,
    )
    return Spec(**{**fields, **changes})


def test_a_sweep_of_curved_branches_chunks_and_resumes_to_the_same_table(tmp_path, monkeypatch):
    """The degree travels through the Monte-Carlo engine: the spec's orders and
    parameters, the batched estimator, the curved model's bound, chunks of any size, a
    run stopped by a failed chunk and resumed."""
    import pandas as pd

    from jaxcascade._montecarlo import _run
    from jaxcascade._montecarlo._engine import run_chunk
    from jaxcascade._montecarlo._run import run
    from jaxcascade._montecarlo._tables import without_timing

    spec = curved_spec()
    assert spec.orders.degree == 3 and "2,2,2,2,3" in spec.cell_identity(spec.cells()[0])
    table = without_timing(run(spec, progress=False))
    assert {"mL3", "true_mR3", "crlb_mR3"} <= set(table.columns)
    assert np.all(np.isfinite(table["crlb_mR3"])) and np.all(table["true_mR3"] == 0.05)
    converged = table[table["status"] == "converged"]
    assert len(converged) >= 1 and np.all(np.abs(converged["mR3"] - 0.05) < 0.05)
    bound = [c for c in table.columns if c.startswith("crlb_")]
    other = without_timing(run(curved_spec(chunk_size=6), progress=False))
    pd.testing.assert_frame_equal(other.drop(columns=bound), table.drop(columns=bound))
    pd.testing.assert_frame_equal(other[bound], table[bound], check_exact=False, rtol=1e-12)

    def failing(spec, cell, indices):
        if 3 in indices:
            raise RuntimeError("a chunk failed")
        return run_chunk(spec, cell, indices)

    out = tmp_path / "curved.parquet"
    monkeypatch.setattr(_run, "run_chunk", failing)
    with pytest.raises(RuntimeError, match="a chunk failed"):
        run(spec, out, progress=False)
    assert len(list((tmp_path / "curved.parquet.partial").glob("chunk-*.parquet"))) == 1
    monkeypatch.undo()
    resumed = without_timing(run(spec, out, progress=False))
    pd.testing.assert_frame_equal(resumed, table, check_exact=True)

    # a chunk as a Dask worker runs it: the spec pickled, the task in the caller's dtype
    import pickle

    from jaxcascade._montecarlo._distributed import chunk_task

    dtype, _, rows = chunk_task(
        pickle.loads(pickle.dumps(spec)), spec.cells()[0], [3, 4, 5], "float64"
    )
    rows = without_timing(rows).reset_index(drop=True)
    expected = table[table["realisation"] >= 3].reset_index(drop=True)
    assert dtype == "float64"
    pd.testing.assert_frame_equal(rows, expected, check_exact=True)


def test_a_spec_names_the_general_backlash_examples():
    from jaxcascade._cli import build_parser
    from jaxcascade._montecarlo._spec import Spec

    spec = Spec(example="general1", n=(800,))
    params, ex = curved("general1", 3)
    assert spec.orders == params.orders and spec.snr == (ex.snr,)
    assert spec.true_values() == params.to_dict()
    assert Spec.from_dict(spec.to_dict()) == spec
    assert spec.cell_identity(spec.cells()[0]) != Spec(example=1, n=(800,)).cell_identity(
        Spec(example=1, n=(800,)).cells()[0]
    )
    with pytest.raises(ValueError, match="general1 and general2"):
        Spec(example="general3", n=(800,))
    with pytest.raises(ValueError, match="family draws straight backlash branches"):
        Spec(family="random", orders="2,2,2,2,3", n=(800,))
    args = build_parser().parse_args(["sweep", "--example", "general2", "--n", "800"])
    assert args.example == "general2"
    assert build_parser().parse_args(["sweep", "--example", "1"]).example == 1


def test_the_loop_refuses_declared_curved_branches_in_one_sentence():
    from jaxcascade._measured._loop import model_error_loop

    params, _ = curved()
    u = uniform_input(jax.random.PRNGKey(0), 1000)
    y = simulate(params, u)
    with pytest.raises(ValueError, match="declares the straight backlash .* general_backlash"):
        model_error_loop(u, y, u, y, params.orders)


def test_recursive_fits_curved_branches_on_line():
    """The recursive estimator's regressor gains the curvature columns, each in its
    regime's block: noise-free general1 with cubic branches, with the noise-free
    settings, converges to the truth on every record, batched."""
    from jaxcascade._estimator._recursive import NOISE_FREE

    params, _ = curved("general1", 3)
    keys = jax.random.split(jax.random.PRNGKey(3), 2)
    u = jax.vmap(lambda k: uniform_input(k, 4000))(keys)
    y = jax.vmap(lambda one: simulate(params, one))(u)
    recursive = estimator("recursive", **NOISE_FREE)
    solution = jit(jax.vmap(lambda a, b: recursive(a, b, params.orders)))(u, y)
    estimate, truth = (np.asarray(p.to_vector()) for p in (solution.params, params))
    errors = np.max(np.abs(estimate - truth), axis=1)
    assert np.all(np.asarray(solution.status) == 0) and np.all(errors < 1e-6), errors
