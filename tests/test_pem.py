"""Coloured output noise (issue 24): the noise filters, the Cramér-Rao bound of coloured
noise against a SciPy oracle, and the prediction-error estimator `pem` on AR noise drawn
here with `scipy.signal.lfilter`."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.signal
import scipy.stats

import jaxcascade as jc
from jaxcascade._compile import jit
from jaxcascade._estimator._efficiency import crlb, fisher_information, information_factor, jacobian
from jaxcascade._experiment._noise_filter import (
    ar_from_unconstrained,
    ar_to_unconstrained,
    coefficients,
    fit_ar,
    roots,
    variance_ratio,
    whiten,
)

EX = jc.example(1)


def ar_noise(seed, n, poles=(), zeros=()):
    """`C(q)/A(q) w` by SciPy, after a burn-in of 2000 samples (stationary)."""
    rng = np.random.default_rng(seed)
    A = np.poly(poles) if poles else [1.0]
    C = np.poly(zeros) if zeros else [1.0]
    return scipy.signal.lfilter(C, A, rng.standard_normal(n + 2000))[2000:]


def record(seed, n, pole, snr=25.0, number=1):
    ex = jc.example(number)
    u = np.asarray(jc.uniform_input(jax.random.PRNGKey(seed), n))
    y0 = np.asarray(jc.simulate(ex.params(), u))
    e = ar_noise(seed, n, (pole,))
    return u, y0 + e / e.std() * y0.std() / snr


def test_whiten_and_variance_ratio_agree_with_scipy():
    poles, zeros = (0.9, -0.3), (0.5,)
    c, d = coefficients(poles, zeros)
    e = ar_noise(0, 500, poles, zeros)
    oracle = scipy.signal.lfilter(np.poly(poles), np.poly(zeros), e)  # A/C e, from rest
    np.testing.assert_allclose(np.asarray(whiten(jnp.asarray(e), c, d)), oracle, atol=1e-12)
    impulse = scipy.signal.lfilter(np.poly(zeros), np.poly(poles), np.eye(1, 4096)[0])
    np.testing.assert_allclose(float(variance_ratio(c, d)), np.sum(impulse**2), rtol=1e-12)
    with pytest.raises(ValueError, match="inside the unit circle"):
        coefficients((1.0,))
    # a zero outside the unit circle: its reciprocal, the same spectrum's predictor
    np.testing.assert_allclose(coefficients((), (2.0,))[1], coefficients((), (0.5,))[1])
    # a [radius, angle] pair: the conjugate roots; outside, the reciprocal radius
    pair = np.array([0.9 * np.exp(0.7j), 0.9 * np.exp(-0.7j)])
    c, d = coefficients(((0.9, 0.7),), ((2.0, 1.1),))
    np.testing.assert_allclose(c, -np.poly(pair).real[1:], rtol=1e-14)
    np.testing.assert_allclose(d, coefficients((), ((0.5, 1.1),))[1], rtol=1e-14)
    with pytest.raises(ValueError, match="inside the unit circle"):
        coefficients(((1.0, 0.7),))


def test_reflection_parameterisation_round_trips():
    c = jnp.asarray(coefficients((0.9, -0.5, 0.2))[0])
    round_trip = jax.jit(lambda c: ar_from_unconstrained(ar_to_unconstrained(c)))
    np.testing.assert_allclose(round_trip(c), c, atol=1e-12)


@pytest.mark.parametrize("pole", [0.0, 0.9])
def test_fit_ar_chooses_the_order_by_bic(pole):
    e = ar_noise(1, 4000, (pole,) if pole else ())
    c, order = jax.jit(fit_ar, static_argnums=(1, 2))(jnp.asarray(e), 4, "bic")
    assert int(order) == (1 if pole else 0)
    # the least-squares AR(1) estimate's standard error is sqrt((1 - a^2) / n)
    assert abs(float(c[0]) - pole) < 4 * np.sqrt((1 - pole**2) / 4000) + 1e-12
    assert np.all(np.asarray(c[1:]) == 0)


def test_coloured_bound_is_the_whitened_jacobians():
    u = jc.uniform_input(jax.random.PRNGKey(3), 1500)
    params = EX.params()
    J = np.asarray(jacobian(params, u))
    sigma = 0.01
    for poles, zeros in (((0.9,), ()), ((0.5, -0.3), (0.4,)), (((0.95, 0.6),), ((0.5, 2.0),))):
        A, C = np.poly(roots(poles)).real, np.poly(roots(zeros)).real if zeros else [1.0]
        Jw = scipy.signal.lfilter(A, C, J, axis=0)
        impulse = scipy.signal.lfilter(C, A, np.eye(1, 4096)[0])
        sigma_w = sigma / np.sqrt(np.sum(impulse**2))
        oracle = sigma_w * np.sqrt(np.diag(np.linalg.inv(Jw.T @ Jw)))
        bound = np.asarray(crlb(params, u, sigma=sigma, poles=poles, zeros=zeros))
        np.testing.assert_allclose(bound, oracle, rtol=1e-6)
        information = fisher_information(params, u, sigma=sigma, poles=poles, zeros=zeros)
        np.testing.assert_allclose(np.asarray(information), Jw.T @ Jw / sigma_w**2, rtol=1e-8)
    # no poles and no zeros: the white-noise bound, sigma times the plain Jacobian's
    white = np.asarray(crlb(params, u, sigma=sigma))
    np.testing.assert_allclose(white, sigma * np.sqrt(np.diag(np.linalg.inv(J.T @ J))), rtol=1e-6)


def test_noise_bound_options_read_poles_and_zeros():
    import types

    from jaxcascade._estimator._efficiency import noise_bound_options

    arma = types.SimpleNamespace(poles=(0.9,), zeros=[0.3])
    assert noise_bound_options(arma) == {"poles": (0.9,), "zeros": (0.3,)}
    resonant = types.SimpleNamespace(poles=(0.5, (0.95, 0.6)), zeros=[[2, 1]])
    assert noise_bound_options(resonant) == {"poles": (0.5, (0.95, 0.6)), "zeros": ((2.0, 1.0),)}
    heavy = types.SimpleNamespace(dof=3.0)  # no filter: the Gaussian bound of its variance
    assert noise_bound_options(heavy) == {"poles": (), "zeros": ()}
    assert noise_bound_options() == {}


def test_information_factor_of_student_t_by_integration():
    nu = 3.0

    def score_squared(x):  # (d log p / dx)^2 p of the unit-scale Student-t
        return ((nu + 1) * x / (nu + x**2)) ** 2 * scipy.stats.t.pdf(x, nu)

    information = scipy.integrate.quad(score_squared, -np.inf, np.inf)[0]
    variance = nu / (nu - 2)
    assert information_factor("student_t", dof=nu) == pytest.approx(information * variance)
    assert information_factor() == 1.0
    # outliers far from the Gaussian part: every sample, hit or not, locates the noise's
    # centre as well as a Gaussian sample of unit variance, whose variance is 1 + f k^2
    assert information_factor("outliers", fraction=0.02, size=10.0) == pytest.approx(3.0, 1e-4)
    assert information_factor("outliers", fraction=0.0, size=10.0) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="dof > 2"):
        information_factor("student_t", dof=2)


def _check_fit(fit, u, y):
    """A fit of Example 1 under AR(1) noise, pole 0.9, SNR 25: converged, the pole
    recovered, the cascade within 4 coloured-noise bounds of the truth, and its cost the
    mean squared prediction error of its own noise model."""
    solution = jax.device_get(fit.solution)
    assert jc.Status(int(solution.status)) == jc.Status.converged
    assert int(fit.noise_order) >= 1
    assert abs(float(fit.c[0]) - 0.9) < 0.05
    truth = np.asarray(EX.params().to_vector())
    bound = np.asarray(crlb(EX.params(), jnp.asarray(u), snr=25.0, poles=(0.9,)))
    error = np.asarray(solution.params.to_vector()) - truth
    assert np.all(np.abs(error) < 4 * bound)
    # the estimator's cost is the mean squared prediction error of its own noise model
    residual = y - np.asarray(jc.simulate(solution.params, u))
    innovations = np.asarray(whiten(jnp.asarray(residual), fit.c))
    assert float(solution.cost) == pytest.approx(np.mean(innovations**2), rel=1e-6)


@pytest.mark.parametrize("bias", [0.0, 0.03], ids=["from-the-truth", "biased"])
def test_prediction_error_refinement_fits_the_cascade_and_the_noise_model(bias):
    # step 3 alone (Levenberg-Marquardt on the prediction error), from the truth and from
    # a start 0.03 off in every parameter (about 30 coloured-noise bounds: only the
    # iteration brings it within 4), the start's AR model fitted to its residual: what
    # `pem` does after its robust start (the whole estimator: slow tests)
    from jaxcascade._estimator._solution import Solution

    u, y = record(5, 2000, 0.9)
    vector = EX.params().to_vector() + bias
    params = jc.CascadeParams.from_vector(vector, EX.orders)
    start = Solution(
        params=params,
        history=vector[None],
        iterations=jnp.ones((), jnp.int32),
        cost=jnp.zeros(()),
        status=jnp.zeros((), jnp.int32),
        cycle_amplitude=jnp.zeros(()),
        path=jnp.ones((), jnp.int32),
    )
    fit = _pem_step(start, jnp.asarray(u), jnp.asarray(y))
    _check_fit(fit, u, y)
    moved = np.max(np.abs(np.asarray(fit.solution.params.to_vector()) - np.asarray(vector)))
    assert moved > 0.02 or bias == 0.0


@jit
def _pem_step(start, u, y):
    # pem's step 3 at its defaults (one compiled program for both starts above)
    from jaxcascade._estimator._pem import DEFAULTS, _refine

    settings = [DEFAULTS[k] for k in ("order", "criterion", "max_steps", "rtol", "atol")]
    return _refine(start, u, y, EX.orders, *settings, DEFAULTS["threshold"])


@pytest.mark.slow
def test_pem_fits_the_cascade_and_the_noise_model():
    u, y = record(5, 2000, 0.9)
    _check_fit(jc.pem_fit(u, y, EX.orders), u, y)


def test_pem_is_registered_and_validates_its_settings():
    assert jc.ESTIMATORS["pem"] is jc.Pem
    with pytest.raises(ValueError, match="criterion"):
        jc.estimator("pem", criterion="hqc")
    with pytest.raises(ValueError, match="order must be an integer >= 0"):
        jc.estimator("pem", order=-1)
    with pytest.raises(ValueError, match="must be an integer"):
        jc.estimator("pem", max_steps=2.5)


@pytest.mark.slow
def test_pem_under_vmap_equals_one_record():
    u, y = record(7, 400, 0.5)
    fit = jc.estimator("pem", order=2, n_starts=2, retries=0)
    batch = jax.vmap(lambda u, y: fit(u, y, EX.orders))(jnp.stack([u, u]), jnp.stack([y, y]))
    one = fit(u, y, EX.orders)
    np.testing.assert_allclose(
        np.asarray(batch.params.to_vector())[1], np.asarray(one.params.to_vector()), atol=1e-9
    )
    assert np.all(np.isfinite(np.asarray(batch.params.to_vector())))
