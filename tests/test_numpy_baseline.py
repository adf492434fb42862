"""The NumPy/SciPy benchmark baseline implements the same algorithm as `jaxcascade.voros`."""

import jax
import numpy as np
import pytest

from jaxcascade import Status, example, measure, simulate, uniform_input, voros
from jaxcascade._benchmark import _baseline

EX = example(1)
PARAMS = EX.params()
VECTOR = np.array([EX.values[name] for name in EX.orders.names])


def _record(seed, n=EX.n_samples, snr=EX.snr):
    key_u, key_e = jax.random.split(jax.random.PRNGKey(seed))
    u = uniform_input(key_u, n)
    y_measured, y = measure(key_e, PARAMS, u, snr)
    return u, y_measured, y


def test_simulation_matches_jax():
    u, _, y = _record(0)
    for backlash in ("loop", "scan"):
        got = _baseline.simulate(VECTOR, EX.orders, np.asarray(u), backlash=backlash)
        # lfilter and the JAX scan sum in different orders: rounding only
        np.testing.assert_allclose(got, np.asarray(y), rtol=0, atol=1e-12)


@pytest.mark.parametrize("mR", [0.5, 1.0, 1.2, 3.0])  # 3.0: the lines cross, scan falls back
def test_backlash_scan_equals_loop(mR):
    rng = np.random.default_rng(1)
    x = np.cumsum(rng.standard_normal(1000))
    loop = _baseline.backlash_loop(x, 0.2, mR, 0.3)
    # the scan only selects among 0, mR (x - cR) and x + cL: equal up to near-ties
    np.testing.assert_allclose(_baseline.backlash_scan(x, 0.2, mR, 0.3), loop, atol=1e-12)
    assert np.ptp(loop) > 1  # the record exercises both lines


@pytest.mark.parametrize("backend", ["xla", "auto"])
@pytest.mark.parametrize("noisy", [False, True], ids=["noise-free", "snr25"])
@pytest.mark.parametrize("fixed", [False, True], ids=["tol", "fixed20"])
def test_voros_matches_jax(noisy, fixed, backend):
    u, y_measured, y = _record(2)
    y = y_measured if noisy else y
    options = dict(max_iterations=20, tol=-1.0, se_tol=-1.0, cost_tol=-1.0) if fixed else {}
    want = voros(u, y, EX.orders, backend=backend, **options)
    got = _baseline.voros(np.asarray(u), np.asarray(y), EX.orders, **options)
    assert got.status == int(want.status)
    assert got.iterations == int(want.iterations)
    # lstsq (SVD) against the scaled normal equations, over up to 50 steps: ~1e-13 seen
    np.testing.assert_allclose(got.history, np.asarray(want.history), rtol=0, atol=1e-8)
    # noise-free the cost is rounding: ~1e-22 from residuals (xla); from the fused
    # kernel's normal equations, rounding of |yc|^2 / N (~1e-15): absolute tolerance there
    atol = 1e-18 if backend == "xla" else 1e-13
    np.testing.assert_allclose(got.cost, float(want.cost), rtol=1e-6, atol=atol)
    if not noisy and not fixed:  # converged (34 steps here): the truth is reached
        np.testing.assert_allclose(got.vector, VECTOR, atol=1e-8)


def test_statuses_match_jax_on_short_records():
    # N = 400 at SNR 25: records end converged, cycled, diverged or out of iterations;
    # the baseline must stop at the same step with the same status.
    seen = set()
    for seed in range(10):
        u, y, _ = _record(seed, n=400, snr=25.0)
        want = voros(u, y, EX.orders, max_iterations=25)
        got = _baseline.voros(np.asarray(u), np.asarray(y), EX.orders, max_iterations=25)
        assert (got.status, got.iterations) == (int(want.status), int(want.iterations))
        # a diverging iteration amplifies the rounding of its steps
        atol = 1e-5 if got.status in (Status.diverged, Status.singular) else 1e-8
        np.testing.assert_allclose(got.history, np.asarray(want.history), atol=atol)
        np.testing.assert_allclose(got.cycle_amplitude, float(want.cycle_amplitude), atol=1e-8)
        seen.add(got.status)
    assert len(seen) >= 4, seen


def test_simulation_matches_noise_free_record():
    # the baseline's own data path: noise at the requested SNR, output of the cascade
    rng = np.random.default_rng(3)
    u, y = _baseline.measure(rng, VECTOR, EX.orders, 4000, 25.0)
    clean = np.asarray(simulate(PARAMS, u))
    snr = np.std(clean) / np.std(y - clean)
    assert abs(snr - 25.0) < 2.0  # sample std of 4000 normals: ~1% spread
