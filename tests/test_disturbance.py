"""Output noise kinds (`_disturbance`): unit variance from the first sample, the ARMA
recursion against a plain NumPy loop, tails and outliers, and the SNR as added."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcascade._experiment._disturbance import NOISES, disturbance
from jaxcascade._experiment._disturbance._arma import autocovariance
from jaxcascade._system._simulate import add_noise

N, RECORDS = 400, 2000


def draws(noise, n=N, records=RECORDS, seed=0):
    keys = jax.random.split(jax.random.PRNGKey(seed), records)
    return np.asarray(jax.vmap(lambda k: noise(k, n))(keys))


@pytest.mark.parametrize(
    ("name", "settings"),
    [
        ("white", {}),
        ("ar", {"poles": [0.9]}),
        ("ar", {"poles": [0.97, -0.5]}),
        ("arma", {"poles": [0.9], "zeros": [0.5]}),
        ("arma", {"poles": [], "zeros": [0.5, -0.3]}),
        ("ar", {"poles": [[0.95, 0.6]]}),
        ("arma", {"poles": [0.5, [0.9, 1.2]], "zeros": [[0.8, 2.0]]}),
        ("student_t", {"dof": 5}),
        ("outliers", {"fraction": 0.02, "size": 10}),
    ],
)
def test_every_kind_has_unit_variance_from_its_first_sample(name, settings):
    e = draws(disturbance(name, **settings))
    # 2000 records: the variance at one sample has a relative SE of sqrt(2 / 2000) ~ 3 %
    # (Gaussian; heavier tails more: 6 sigma-ish bounds below)
    tolerance = {"student_t": 0.25, "outliers": 0.3}.get(name, 0.12)
    assert abs(np.var(e[:, 0]) - 1) < tolerance  # stationary at once: no burn-in
    assert abs(np.var(e[:, -1]) - 1) < tolerance
    assert abs(np.var(e) - 1) < 0.05
    assert abs(np.mean(e)) < 0.02


def test_ar1_autocorrelation_is_the_pole_to_the_lag():
    e = draws(disturbance("ar", poles=[0.9]), records=500)
    for lag in (1, 2, 5):
        r = np.mean(e[:, lag:] * e[:, :-lag])
        assert abs(r - 0.9**lag) < 0.03, lag


def test_arma_is_the_recursion_of_a_numpy_loop():
    noise = disturbance("arma", poles=[0.8, -0.3], zeros=[0.5])
    key = jax.random.PRNGKey(3)
    e = np.asarray(noise(key, 50))
    a, c = noise.coefficients()
    _, factor, std = noise.stationary()
    key_w, key_past = jax.random.split(key)
    w = np.asarray(jax.random.normal(key_w, (50,)))
    past = factor @ np.asarray(jax.random.normal(key_past, (factor.shape[0],)))
    s = list(past[::-1])  # s(-m) .. s(-1)
    m = len(s)
    for t in range(50):
        s.append(w[t] - sum(a[j] * s[m + t - 1 - j] for j in range(len(a))))
    expected = [
        (s[m + t] + sum(c[k] * s[m + t - 1 - k] for k in range(len(c)))) / std for t in range(50)
    ]
    np.testing.assert_allclose(e, expected, rtol=1e-12, atol=1e-12)  # float64, same sums


def test_a_pole_pair_is_a_resonance():
    # [radius, angle]: the conjugate poles r exp(+-i w), A(q) = 1 - 2 r cos(w) q^-1 + r^2 q^-2
    radius, angle = 0.9, 0.8
    noise = disturbance("ar", poles=[[radius, angle]])
    a, c = noise.coefficients()
    np.testing.assert_allclose(a, [-2 * radius * np.cos(angle), radius**2], rtol=1e-14)
    assert c.size == 0
    # an AR(2)'s lag-1 autocorrelation is -a1 / (1 + a2)
    e = draws(noise, records=500)
    rho = np.mean(e[:, 1:] * e[:, :-1])
    assert abs(rho - 2 * radius * np.cos(angle) / (1 + radius**2)) < 0.03
    # its spectrum peaks near the angle: |1 / A(e^{iw})| is largest there
    grid = np.linspace(0.01, np.pi - 0.01, 2000)
    response = 1 / np.abs(1 + a[0] * np.exp(-1j * grid) + a[1] * np.exp(-2j * grid))
    assert abs(grid[np.argmax(response)] - angle) < 0.05
    # as settings: nested lists, and back to the same noise
    assert noise.settings() == {"poles": [[radius, angle]]}
    assert disturbance("ar", **noise.settings()) == noise
    # a real pole and a pair together: the product of their polynomials
    both = disturbance("arma", poles=[0.5, [radius, angle]], zeros=[-0.3]).coefficients()[0]
    np.testing.assert_allclose(np.r_[1, both], np.convolve([1, -0.5], np.r_[1, a]), rtol=1e-14)


def test_autocovariance_of_an_ar1():
    gamma = autocovariance(np.array([-0.9]), 4)
    np.testing.assert_allclose(gamma, 0.9 ** np.arange(4) / (1 - 0.81), rtol=1e-12)


def test_student_t_has_heavy_tails_and_outliers_their_fraction():
    t = draws(disturbance("student_t", dof=5)).ravel()
    kurtosis = np.mean(t**4) / np.mean(t**2) ** 2
    assert kurtosis > 5  # Gaussian 3, t(5) 9
    noise = disturbance("outliers", fraction=0.05, size=10)
    e = draws(noise).ravel() * np.sqrt(1 + 0.05 * 100)
    assert abs(np.mean(np.abs(e) > 5) - 0.05) < 0.005


def test_add_noise_keeps_the_snr_of_the_noise_as_added_and_white_is_the_default():
    y = jnp.sin(jnp.arange(4000) / 10.0) * 3.0
    key = jax.random.PRNGKey(1)
    np.testing.assert_array_equal(
        add_noise(key, y, 25.0), add_noise(key, y, 25.0, disturbance("white"))
    )
    keys = jax.random.split(key, 200)
    noise = disturbance("ar", poles=[0.97])
    added = jax.vmap(lambda k: add_noise(k, y, 25.0, noise) - y)(keys)
    ratio = np.std(y) / np.sqrt(np.mean(np.asarray(added) ** 2))
    assert abs(ratio - 25.0) < 1.0  # 200 records of an AR(0.97): a few % spread


@pytest.mark.parametrize(
    ("name", "settings", "message"),
    [
        ("pink", {}, "Unknown noise kind 'pink'"),
        ("ar", {"pole": 0.9}, "Unknown setting 'pole'"),
        ("ar", {"zeros": [0.1]}, "Unknown setting 'zeros'"),
        ("ar", {"poles": [1.2]}, "every pole must lie in (-1, 1)"),
        ("ar", {"poles": [[1.0, 0.6]]}, "a pole pair's radius must lie in [0, 1)"),
        ("ar", {"poles": [[0.9, 0.0]]}, "0 < angle < pi"),
        ("arma", {"zeros": [[0.9, 3.2]]}, "0 < angle < pi"),
        ("ar", {"poles": [[0.9]]}, "a real number or a pair [radius, angle]"),
        ("ar", {"poles": [[0.9, 0.5]] * 5}, "at most 8 are supported (a pair counts two)"),
        ("student_t", {"dof": 2}, "dof must lie in (2, "),
        ("outliers", {"fraction": 1.5}, "fraction must lie in [0, 1]"),
    ],
)
def test_bad_settings_are_one_sentence(name, settings, message):
    with pytest.raises(ValueError, match=None) as error:
        disturbance(name, **settings)
    assert message in str(error.value)


def test_registry_settings_round_trip():
    for name, cls in NOISES.items():
        noise = cls()
        assert disturbance(name, **noise.settings()) == noise
