"""The robust estimator's adaptive path, its multi-start fallback and their batching."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcascade as jc
from jaxcascade._compile import jit
from jaxcascade._estimator._basin import residual_statistic
from jaxcascade._estimator._robust import _adaptive, _robust
from jaxcascade._estimator._solution import PATH_ADAPTIVE, PATH_MULTISTART
from jaxcascade._system._prior import random_systems

ORDERS = jc.Orders()
N = 400
# small multi-start settings: these tests check paths and batching, not recovery
SMALL = dict(n_starts=2, n_refine=1, max_steps=(8, 8), literal_start=False, fallback_batch=1)
STAGE = dict(rtol=1e-6, atol=1e-9, steps=50, bound=5.0)


@pytest.fixture(scope="module")
def records():
    """(easy, wrong basin): a noise-free random system the literal estimate plus
    Levenberg-Marquardt fits exactly, and noise-free Example 2 at N = 400, where the fit
    of the adaptive path ends in a wrong basin (cost ~0.005, the residual far from
    white). (Noise-free Example 1 at N = 400 was such a record, and random system 1 an
    easy one, until the adaptive path started from the literal iteration's second
    iterate where the iteration ends unusable.)"""
    easy_truth = jc.random_system(jax.random.PRNGKey(2), ORDERS)
    u_easy = jc.uniform_input(jax.random.key(2), N)
    u_hard = jc.uniform_input(jax.random.key(3), N)
    return (
        (u_easy, jc.simulate(easy_truth, u_easy), easy_truth),
        (u_hard, jc.simulate(jc.example(2).params(), u_hard), jc.example(2).params()),
    )


@pytest.fixture(scope="module")
def stages(records):
    u = jnp.stack([r[0] for r in records])
    y = jnp.stack([r[1] for r in records])
    return jit(jax.vmap(lambda u, y: _adaptive(u, y, ORDERS, **STAGE)))(u, y)


def test_adaptive_path_accepts_an_easy_record(records, stages):
    truth = records[0][2].to_vector()
    assert bool(stages.accepted[0])
    assert int(stages.solution.status[0]) == jc.Status.converged
    np.testing.assert_allclose(stages.solution.params.to_vector()[0], truth, atol=1e-6)


def test_adaptive_path_refuses_a_wrong_basin(records, stages):
    assert not bool(stages.accepted[1])
    u, y, _ = records[1]
    residual = y - jc.simulate(
        jc.CascadeParams.from_vector(stages.solution.params.to_vector()[1], ORDERS, check=False),
        u,
    )
    assert float(residual_statistic(residual, u)) > 5.0


def test_residual_statistic_of_white_noise_is_small():
    # about standard normal for a white residual independent of u (threshold 5)
    key_u, key_e = jax.random.split(jax.random.key(3))
    stats = [
        float(residual_statistic(jax.random.normal(k, (2000,)), jc.uniform_input(key_u, 2000)))
        for k in jax.random.split(key_e, 8)
    ]
    assert max(stats) < 5.0 and min(stats) > -3.0


def test_batched_fit_takes_each_records_path(records):
    # Under vmap only the failures of step 1 run the multi-start (gathered by the
    # custom_vmap rule, one per round here); each row equals the unbatched fit.
    u = jnp.stack([records[0][0], records[1][0], records[0][0]])
    y = jnp.stack([records[0][1], records[1][1], records[0][1]])
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    batched = jit(jax.vmap(lambda u, y, k: _robust(u, y, ORDERS, k, **SMALL)))(u, y, keys)
    assert batched.path.tolist() == [PATH_ADAPTIVE, PATH_MULTISTART, PATH_ADAPTIVE]
    one = _robust(u[1], y[1], ORDERS, keys[1], **SMALL)
    assert int(one.path) == PATH_MULTISTART
    np.testing.assert_allclose(
        batched.params.to_vector()[1], one.params.to_vector(), rtol=1e-9, atol=1e-12
    )
    assert int(batched.status[1]) == int(one.status)
    np.testing.assert_allclose(batched.params.to_vector()[0], batched.params.to_vector()[2])


def test_random_systems_draw_the_prior_in_one_batch():
    # the multi-start's starts: the same prior as `random_system`, every draw admissible
    orders = jc.Orders()
    batch = random_systems(jax.random.PRNGKey(0), 2000, orders)
    vectors = np.asarray(batch.to_vector())
    reference = np.asarray(
        jax.vmap(lambda k: jc.random_system(k, orders).to_vector())(
            jax.random.split(jax.random.PRNGKey(1), 2000)
        )
    )
    assert vectors.shape == (2000, orders.size)
    assert bool(jnp.all(jax.vmap(lambda p: jc.is_admissible(p, -2.0, 2.0))(batch)))
    np.testing.assert_allclose(vectors.min(0), reference.min(0), atol=0.05)
    np.testing.assert_allclose(vectors.max(0), reference.max(0), atol=0.05)
    # 2000 draws: the means agree to a few standard errors (< 0.1 for every range here)
    np.testing.assert_allclose(vectors.mean(0), reference.mean(0), atol=0.1)


def test_retries_keep_the_cheaper_estimate_or_one_that_passes(records):
    # The wrong-basin record with a multi-start too small to find the basin (SMALL): the
    # first attempt uses the record's key as a single multi-start does, and every retry
    # can only replace it by an estimate that passes the basin test or costs less.
    u, y, _ = records[1]
    key = jax.random.PRNGKey(0)
    once = _robust(u, y, ORDERS, key, **SMALL, retries=0)
    again = _robust(u, y, ORDERS, key, **SMALL, retries=2)
    assert int(once.path) == int(again.path) == PATH_MULTISTART
    passed = float(residual_statistic(y - jc.simulate(again.params, u), u)) <= 5.0
    assert float(again.cost) <= float(once.cost) or passed
    with pytest.raises(ValueError, match="retries"):
        jc.robust(u, y, ORDERS, retries=-1)


@pytest.mark.slow
def test_an_estimate_on_the_domain_edge_is_not_accepted():
    # Random family, seed 1, realisation 17 (results/robust_vs_literal_seed1): the literal
    # estimate puts DL1 on the wrong side of 0; refined, it stayed on the edge (DL1 = -0)
    # with a white residual and was reported `converged`, inadmissible, NRMSE inf on the
    # validation record. Now the adaptive path refuses it and the multi-start recovers it.
    spec = jc.Spec(
        family="random", n=3000, snr=(30.0,), realisations=100, estimators=("robust",),
        chunk_size=8, seed=1,
    )  # fmt: skip
    row = jc.run_chunk(spec, spec.cells()[0], [17]).iloc[0]
    assert row["admissible"] and row["robust_path"] == "multistart"
    assert row["status"] == "converged" and row["recovered"]


def test_multistart_recovers_a_record_the_literal_path_cannot(records):
    # End to end at the defaults: the noise-free Example 2 record whose literal-then-
    # refined fit ends in a wrong basin (`test_adaptive_path_refuses_a_wrong_basin`). The
    # multi-start finds the true basin: the truth to rounding, `converged`. (Without the
    # multi-start, the cheapest estimate is the wrong basin's: `local_minimum`.)
    u, y, truth = records[1]
    solution = jc.robust(u, y, ORDERS, jax.random.PRNGKey(0))
    assert int(solution.path) == PATH_MULTISTART
    assert jc.Status(int(solution.status)) is jc.Status.converged
    np.testing.assert_allclose(solution.params.to_vector(), truth.to_vector(), atol=1e-6)
