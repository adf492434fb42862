"""The general output backlash's Cramér-Rao bound and prediction-error estimator (issue
39, point 2): degree 1 is today's bound; a curved block's bound is the one of a
finite-difference Jacobian of the simulator; `pem_general` finds the AR noise model of
coloured noise, is output error where the noise is white, and never raises."""

import jax
import numpy as np
import pytest

import jaxcascade as jc
from jaxcascade._compile import filter_jit
from jaxcascade._estimator._efficiency import crlb, fisher_information
from jaxcascade._estimator._general_pem import pem_general
from jaxcascade._estimator._general_refine import refine_general
from jaxcascade._experiment._disturbance import disturbance
from jaxcascade._system._general_backlash import (
    GeneralBacklash,
    general_example,
    simulate_general,
)
from jaxcascade._system._simulate import add_noise

# compiled: called eagerly, every `lax.scan` inside compiles a program of its own at
# every call
_crlb = filter_jit(crlb)
_fisher_information = filter_jit(fisher_information)


def _input(n, seed=0, amplitude=2.0):
    return jc.uniform_input(jax.random.PRNGKey(seed), n, amplitude)


@pytest.mark.parametrize("number", [1, 2])
def test_degree_one_bound_is_todays(number):
    params = jc.example(number).params()
    u = _input(600)
    straight = GeneralBacklash.straight(params, 1)
    for options in ({"snr": 25.0}, {"sigma": 0.1, "poles": (0.8,)}):
        # the same simulation bit for bit; its derivatives through the general block's
        # (empty) curvature sums agree to rounding (1.4e-15 relative observed)
        np.testing.assert_allclose(
            np.asarray(_crlb(params, u, backlash=straight, **options)),
            np.asarray(_crlb(params, u, **options)),
            rtol=1e-12,
        )


def test_curved_bound_is_the_finite_difference_jacobians():
    # an independent Jacobian: central differences of the simulator with curved branches,
    # theta = the cascade's parameters, then curveL, then curveR
    example = general_example("general1")
    params, nd = example.params(), example.backlash()
    orders, q1 = params.orders, nd.degree - 1
    u = _input(800)
    truth = np.concatenate([params.to_vector(), nd.curveL, nd.curveR])

    def simulate_theta(theta):
        p = jc.CascadeParams.from_vector(theta[: orders.size], orders, check=False)
        curved = GeneralBacklash.unchecked(
            p.cL, p.mR, p.cR, theta[orders.size : orders.size + q1], theta[orders.size + q1 :]
        )
        return np.asarray(simulate_general(p, curved, u))

    step = 1e-6
    J = np.stack(
        [
            (simulate_theta(truth + step * e) - simulate_theta(truth - step * e)) / (2 * step)
            for e in np.eye(len(truth))
        ],
        axis=1,
    )
    sigma = 0.05
    expected = sigma * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    bound = np.asarray(_crlb(params, u, sigma=sigma, backlash=nd))
    assert bound.shape == (orders.size + 2 * q1,)
    np.testing.assert_allclose(bound, expected, rtol=1e-5)
    information = np.asarray(_fisher_information(params, u, sigma=sigma, backlash=nd))
    np.testing.assert_allclose(information, J.T @ J / sigma**2, rtol=1e-5, atol=1e-6)


def _record(noise, n=1500, snr=25.0):
    example = general_example("general1")
    params, nd = example.params(), example.backlash()
    u = _input(n)
    y = add_noise(jax.random.PRNGKey(3), simulate_general(params, nd, u), snr, noise)
    start = refine_general(params, GeneralBacklash.straight(params, nd.degree), u, y)
    return params, nd, u, y, start


def test_pem_general_finds_the_ar_noise_and_beats_output_error():
    params, nd, u, y, start = _record(disturbance("ar", poles=(0.8,)))
    fit = pem_general(u, y, params.orders, nd.degree, start=start)
    assert int(fit.status) == jc.Status.converged and fit.increasing
    assert fit.c.shape == (1,) and abs(float(fit.c[0]) - 0.8) < 0.05
    truth = np.concatenate([params.to_vector(), nd.curveL, nd.curveR])
    bound = np.asarray(_crlb(params, u, snr=25.0, poles=(0.8,), backlash=nd))

    def error(f):  # the estimate's distance from the truth in units of the bound
        vector = np.concatenate([f.params.to_vector(), f.backlash.curveL, f.backlash.curveR])
        return np.sqrt(np.mean(((vector - truth) / bound) ** 2))

    # output error is consistent but not efficient under coloured noise: on this record
    # it is 1.78 bounds (root mean square over the parameters) from the truth, prediction
    # error 0.95
    assert error(fit) < 1.5 and error(fit) < 0.75 * error(start)


def test_pem_general_is_output_error_under_white_noise():
    params, nd, u, y, start = _record(None)
    fit = pem_general(u, y, params.orders, nd.degree, start=start)
    assert fit.c.shape == (0,) and int(fit.status) == jc.Status.converged
    np.testing.assert_allclose(fit.params.to_vector(), start.params.to_vector(), atol=1e-8)
    np.testing.assert_allclose(fit.backlash.curveR, start.backlash.curveR, atol=1e-8)
    np.testing.assert_allclose(float(fit.cost), float(start.cost), rtol=1e-10)


def test_pem_general_refuses_in_one_sentence():
    params, nd, u, y, start = _record(None, n=300)
    with pytest.raises(ValueError, match="degree 3, not 2"):
        pem_general(u, y, params.orders, 2, start=start)
    with pytest.raises(ValueError, match="unknown order criterion 'aicc'"):
        pem_general(u, y, params.orders, 3, start=start, criterion="aicc")
