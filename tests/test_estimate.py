"""The literal Vörös iteration: fixed point, the paper's examples, first-step readings
against the oracle, stopping rules and statuses, jit, vmap."""

import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pandas as pd
import pytest

import jaxcascade
from jaxcascade import (
    CascadeParams,
    Orders,
    Status,
    example,
    initial_guess,
    measure,
    simulate,
)
from jaxcascade._compile import filter_jit
from jaxcascade._estimator import _literal
from jaxcascade._estimator._literal import voros_step

# compiled: called eagerly, every `lax.scan` inside compiles a program of its own at
# every call
_voros_step = filter_jit(voros_step)


def _example1_record(seed=0, n=None):
    ex = example(1)
    u = jaxcascade.uniform_input(jax.random.key(seed), n or ex.n_samples)
    return ex, u, simulate(ex.params(), u)


@pytest.mark.parametrize(
    "orders",
    [Orders(2, 2, 2, 2), Orders(1, 1, 1, 0), Orders(3, 2, 3, 1), Orders(2, 3, 1, 2)],
    ids=str,
)
def test_truth_is_a_fixed_point(orders):
    rng = np.random.default_rng(50 + orders.size)
    u = rng.uniform(-2, 2, 1000)
    for _ in range(2):
        vector, (_, _, y) = oracle.identifiable_system(rng, orders, u)
        params = CascadeParams.from_vector(jnp.asarray(vector), orders)
        new, singular, cost, _ = _voros_step(params, jnp.asarray(u), jnp.asarray(y))
        assert not bool(singular)
        # zero-residual least squares, scaled condition number < 1e4: error ~1e4 eps
        np.testing.assert_allclose(new, vector, rtol=0, atol=1e-10)
        assert float(cost) < 1e-24


NO_EARLY_STOP = {"tol": -1.0, "se_tol": -1.0, "cost_tol": -1.0}


def _paper_record(number, seed, snr):
    """The record of `jaxcascade reproduce --example NUMBER --seed SEED --snr SNR`."""
    ex = example(number)
    key_input, key_noise = jax.random.split(jax.random.PRNGKey(seed))
    u = jaxcascade.uniform_input(key_input, ex.n_samples, ex.amplitude)
    y, _ = measure(key_noise, ex.params(), u, snr)
    return ex, u, y


@pytest.mark.parametrize("number", [1, 2])
def test_paper_examples_noise_free_recovered(number):
    # The paper: both examples "meet the values of real parameters after about 6
    # iterations". With the "full" first step (the default) both are recovered exactly.
    ex, u, y = _paper_record(number, 0, np.inf)
    init = initial_guess(ex.orders, -2.0, 2.0)
    sol = jaxcascade.voros(u, y, ex.orders, init)
    assert sol.status == Status.converged
    # stopped at tol 1e-8 (relative) on a linearly contracting iteration
    np.testing.assert_allclose(sol.params.to_vector(), ex.params().to_vector(), atol=1e-7)
    np.testing.assert_array_equal(sol.history[0], init.to_vector())
    assert float(sol.cycle_amplitude) == 0.0


@pytest.mark.parametrize("reading", ["full", "fixed", "drop"])
@pytest.mark.parametrize(
    "number, seed, snr", [(1, 2, 25.0), (2, 3, np.inf), (1, 1, np.inf)], ids=str
)
def test_readings_match_oracle_history(reading, number, seed, snr):
    # Each first-step reading and the steps after it, against the plain-NumPy oracle,
    # for a fixed number of steps (the stopping rules are tested below).
    ex, u, y = _paper_record(number, seed, snr)
    u, y = u[:1500], y[:1500]
    init = initial_guess(ex.orders, -2.0, 2.0)
    steps = 12
    sol = jaxcascade.voros(
        u, y, ex.orders, init, first_step=reading, max_iterations=steps, **NO_EARLY_STOP
    )
    history = oracle.voros(
        np.asarray(u), np.asarray(y), ex.orders, np.asarray(init.to_vector()), steps, reading
    )
    assert history.shape[0] == steps + 1  # every step finite on these records
    assert int(sol.iterations) == steps
    # normal equations with Jacobi scaling vs lstsq on a well-conditioned problem
    # (~1e-13 per step), carried through 12 steps of a contracting iteration
    np.testing.assert_allclose(sol.history, history, rtol=0, atol=1e-8)


def test_readings_differ_in_the_first_step():
    # the three readings solve different regressions: their first iterates differ
    ex, u, y = _paper_record(2, 0, np.inf)
    init = initial_guess(ex.orders, -2.0, 2.0)
    firsts = [
        jaxcascade.voros(u, y, ex.orders, init, first_step=r, max_iterations=1).history[1]
        for r in ("full", "fixed", "drop")
    ]
    assert np.max(np.abs(firsts[0] - firsts[1])) > 1e-3
    assert np.max(np.abs(firsts[1] - firsts[2])) > 1e-3
    with pytest.raises(ValueError, match="first-step reading"):
        jaxcascade.voros(u, y, ex.orders, init, first_step="half")


def test_noisy_cycle_is_reported_with_its_amplitude():
    # Example 1, SNR 25, reproduce's seed 1: the switching pattern settles into a
    # period-4 cycle between estimates at the statistical precision (measured: spread
    # 0.013 in DR1). The old fixed tolerance called this max_iterations.
    ex, u, y = _paper_record(1, 1, 25.0)
    init = initial_guess(ex.orders, -2.0, 2.0)
    sol = jaxcascade.voros(u, y, ex.orders, init)
    assert sol.status == Status.cycled
    k = int(sol.iterations)
    assert k < 50
    history = np.asarray(sol.history)
    amplitude = float(sol.cycle_amplitude)
    assert 1e-3 < amplitude < 0.05
    # the last iterate revisits an earlier one: some period 2..8 closes the cycle
    theta = history.copy()
    theta[:, -1] *= theta[:, -2]
    closes = [np.max(np.abs(theta[k] - theta[k - j])) for j in range(2, 9)]
    steps = np.max(np.abs(theta[k] - theta[k - 1]))
    assert min(closes) < 1e-4 < steps
    # the amplitude is the largest spread of one parameter (theta) over the cycle
    period = 2 + int(np.argmin(closes))
    cycle = theta[k - period + 1 : k + 1]
    np.testing.assert_allclose(amplitude, np.max(cycle.max(0) - cycle.min(0)), rtol=1e-12)
    # still an estimate: every parameter within 0.05
    assert np.max(np.abs(sol.params.to_vector() - ex.params().to_vector())) < 0.05


def test_a_period_10_cycle_is_a_cycle_not_max_iterations():
    # Example 1, SNR 25, a record of the Monte-Carlo engine (sweep seed 2, realisation
    # 9): the switching pattern settles into a period-10 cycle at the statistical
    # precision (measured: amplitude 0.005, every parameter within 0.021 of the truth).
    # With the old window of 8 periods it was reported as max_iterations after 50 steps.
    from jaxcascade._montecarlo._engine import cell_key
    from jaxcascade._montecarlo._spec import Spec
    from jaxcascade._system._simulate import add_noise, simulate, uniform_input

    spec = Spec(example=1, n=4000, snr=(25.0,), realisations=40, seed=2, estimators=("literal",))
    key = jax.random.fold_in(cell_key(spec, spec.cells()[0]), 9)
    key_u, key_e, _, _ = jax.random.split(key, 4)
    truth = spec.truth()
    u = uniform_input(key_u, 4000, 2.0)
    y = add_noise(key_e, simulate(truth, u), 25.0)
    init = initial_guess(truth.orders, -2.0, 2.0)
    sol = jaxcascade.voros(u, y, truth.orders, init)
    assert sol.status == Status.cycled
    assert int(sol.iterations) < 50
    assert 1e-3 < float(sol.cycle_amplitude) < 0.05
    assert np.max(np.abs(sol.params.to_vector() - truth.to_vector())) < 0.05
    short = jaxcascade.voros(u, y, truth.orders, init, cycle_period=8)
    assert short.status == Status.max_iterations
    # 0 or 1: no cycle detection at all
    for off in (0, 1):
        none = jaxcascade.voros(u, y, truth.orders, init, cycle_period=off)
        assert none.status == Status.max_iterations and float(none.cycle_amplitude) == 0.0


def test_statistical_tolerance_stops_at_the_precision():
    # SNR 25: the last step is far below one standard error, and the iteration stops
    # long before a rounding-level parameter tolerance would.
    ex, u, y = _paper_record(1, 0, 25.0)
    init = initial_guess(ex.orders, -2.0, 2.0)
    sol = jaxcascade.voros(u, y, ex.orders, init)
    assert sol.status == Status.converged
    k = int(sol.iterations)
    _, _, _, se = _voros_step(
        CascadeParams.from_vector(sol.history[k - 1], ex.orders, check=False), u, y
    )
    assert np.all(np.asarray(se) > 1e-4)  # the statistical precision at SNR 25, N 4000
    theta = np.asarray(sol.history[k - 1 : k + 1]).copy()
    theta[:, -1] *= theta[:, -2]
    assert np.max(np.abs(theta[1] - theta[0]) / np.asarray(se)) <= 1e-2
    tight = jaxcascade.voros(u, y, ex.orders, init, se_tol=0.0, tol=1e-13, cost_tol=-1.0)
    assert int(tight.iterations) > k


def test_domain_stop_is_the_safeguarded_variant():
    # Example 2 noise-free, seed 0 of reproduce: with the "fixed" reading an iterate
    # leaves the domain; without the domain stop the iteration goes on.
    ex, u, y = _paper_record(2, 0, np.inf)
    init = initial_guess(ex.orders, -2.0, 2.0)
    outcomes = {}
    for stop in (False, True):
        sol = jaxcascade.voros(u, y, ex.orders, init, first_step="fixed", domain_stop=stop)
        outcomes[stop] = sol
        assert np.all(np.isfinite(sol.params.to_vector()))
    safeguarded = outcomes[True]
    assert int(safeguarded.status) == Status.left_domain
    # the stop happened before the inadmissible iterate, which is not returned
    assert bool(jaxcascade.is_admissible(safeguarded.params, u.min(), u.max()))
    assert int(outcomes[False].iterations) > int(safeguarded.iterations)


def test_max_iterations_status():
    ex, u, y = _example1_record(seed=1, n=2000)
    init = initial_guess(ex.orders, -2.0, 2.0)
    sol = jaxcascade.voros(u, y, ex.orders, init, max_iterations=3)
    assert sol.status == Status.max_iterations
    assert int(sol.iterations) == 3 and sol.history.shape == (4, ex.orders.size)
    history = oracle.voros(np.asarray(u), np.asarray(y), ex.orders, np.asarray(init.to_vector()), 3)
    # three steps of a well-conditioned least squares: rounding only
    np.testing.assert_allclose(sol.history, history, rtol=0, atol=1e-10)


@pytest.mark.parametrize(
    "low, high",
    [(0.05, 2.0), (-2.0, 0.8)],
    ids=["positive-input", "segment-DR1-never-reached"],
)
def test_unvisited_regime_reports_status(low, high):
    # u > 0 never visits the left segments; u < 0.8 never passes DR1 = 1 (the init's
    # breakpoint): their slope columns vanish, so the regression cannot be solved. The
    # plain iteration goes on from a regularised step and fails one way or another; the
    # safeguarded one stops at once.
    ex = example(1)
    u = jax.random.uniform(jax.random.key(3), (2000,), minval=low, maxval=high)
    y, _ = measure(jax.random.key(4), ex.params(), u, 25.0)
    failures = (Status.singular, Status.left_domain, Status.diverged)
    for init, domain_stop in itertools.product(
        (initial_guess(ex.orders, -2.0, 2.0), None), (False, True)
    ):
        sol = jaxcascade.voros(u, y, ex.orders, init, domain_stop=domain_stop)
        assert int(sol.status) in (failures[:2] if domain_stop else failures)
        assert np.all(np.isfinite(sol.params.to_vector()))
        assert np.all(np.isfinite(sol.history))
        assert np.isfinite(float(sol.cost))


def test_no_retrace_for_same_shapes(monkeypatch):
    # `first_iteration` is called once per trace of `voros`; a length used nowhere else
    # makes sure the first call here traces.
    counted = eqx.debug.assert_max_traces(_literal.first_iteration, max_traces=1)
    monkeypatch.setattr(_literal, "first_iteration", counted)
    ex = example(1)
    n = 701
    for seed in range(3):
        u = jaxcascade.uniform_input(jax.random.key(seed), n)
        y, _ = measure(jax.random.key(seed + 10), ex.params(), u, 25.0)
        init = initial_guess(ex.orders, -2.0 + 0.1 * seed, 2.0)
        # new data, initial values and tolerances; the same keywords each call (jit keys
        # its cache on which keywords are passed)
        jaxcascade.voros(u, y, ex.orders, init, tol=10.0**-seed, divergence_bound=1e3 + seed)
    assert eqx.debug.get_num_traces(counted) == 1


def test_vmap_over_realisations_equals_loop():
    ex = example(1)
    u = jaxcascade.uniform_input(jax.random.key(5), 2000)
    keys = jax.random.split(jax.random.key(6), 3)
    ys, _ = jax.vmap(measure, in_axes=(0, None, None, None))(keys, ex.params(), u, 25.0)
    init = initial_guess(ex.orders, -2.0, 2.0)
    batched = jax.vmap(lambda y: jaxcascade.voros(u, y, ex.orders, init))(ys)
    assert batched.params.MR.shape == (3, 2)
    for i in range(3):
        one = jaxcascade.voros(u, ys[i], ex.orders, init)
        assert int(batched.status[i]) == int(one.status)
        assert int(batched.iterations[i]) == int(one.iterations)
        # batched linear algebra may round differently; the iteration contracts
        np.testing.assert_allclose(batched.history[i], one.history, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            batched.params.to_vector()[i], one.params.to_vector(), rtol=0, atol=1e-9
        )
    # the batch as a table: one row per record, the same as each record's own row
    table = jaxcascade.solution_table(batched)
    assert list(table.index) == [0, 1, 2] and table.index.name == "record"
    for i in range(3):
        one = jaxcascade.solution_table(jax.tree.map(lambda leaf, i=i: leaf[i], batched))
        pd.testing.assert_series_equal(table.iloc[i], one.iloc[0], check_names=False)
