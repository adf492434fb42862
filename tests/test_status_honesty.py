"""What `converged` means for the on-line estimator (issue 35): settled over the last
window, relative to the recursion's standard errors, and at the noise level it
estimates; otherwise `tracking`. The word never describes an estimate far from the
truth on a noise-free record. Records are those `jaxcascade reproduce --example N --seed
S --snr SNR` draws (`_workflow._reproduce.run_example`). `results/status_honesty.md`
counts every estimator's statuses against the truth over many records; here, the cases
the issue names.
"""

import functools
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcascade._cli import main
from jaxcascade._compile import jit
from jaxcascade._estimator import estimator
from jaxcascade._estimator._recursive import NOISE_FREE, Recursive, recursive
from jaxcascade._status import Status, status_names
from jaxcascade._system._examples import example
from jaxcascade._system._simulate import measure, uniform_input

BOUNDS = (-2.0, 2.0)


def records(number, snr, seeds):
    ex = example(number)

    def draw(seed):
        key_input, key_noise = jax.random.split(jax.random.PRNGKey(seed))
        u = uniform_input(key_input, ex.n_samples, ex.amplitude)
        return u, measure(key_noise, ex.params(), u, snr)[0]

    U, Y = jax.vmap(draw)(jnp.asarray(seeds))
    return ex, U, Y


def largest_error(solution, ex):
    return np.max(np.abs(np.asarray(solution.params.to_vector() - ex.params().to_vector())), -1)


def test_the_new_status_keeps_every_code():
    # codes are stored in result tables as numbers: a new status only appends
    assert [s.value for s in Status] == list(range(11))
    assert Status.tracking == 8 and Status.no_improvement == 7 and Status.converged == 0
    assert Status.local_minimum == 9 and Status.on_edge == 10
    assert Status.tracking.failure and "noise level" in Status.tracking.message
    assert Status.local_minimum.failure and Status.on_edge.failure
    assert list(status_names([0, 8, 10, 11])) == ["converged", "tracking", "on_edge", "unknown"]


@pytest.mark.parametrize("number", [1, 2])
def test_reproduce_noise_free_reaches_the_truth_and_says_converged(number, capsys, tmp_path):
    # the commands: `--snr inf` runs the recursive estimator's noise-free settings
    # (constant memory, Gauss-Newton gain) and names them; to 1e-6, `converged`
    argv = ["reproduce", "--example", str(number), "--snr", "inf", "--estimator", "recursive"]
    assert main([*argv, "--json", "--out", str(tmp_path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "converged" and out["settings"] == NOISE_FREE
    assert max(abs(out["estimates"][k] - v) for k, v in out["true"].items()) < 1e-6
    assert "noise level" in out["message"]


def test_the_defaults_noise_free_are_not_called_converged():
    # The issue's case: Example 2's reproduce record, noise-free, default settings: the
    # estimate ends 2.8 from the truth and used to be `converged`. It moves by several
    # standard errors over the last window and its errors are far above its noise level
    # (0: the output rests exactly). Example 1's ends 2e-4 off, still moving: `tracking`.
    for number, far in ((2, 1.0), (1, 1e-4)):
        ex, U, Y = records(number, jnp.inf, [0])
        out = recursive(U[0], Y[0], ex.orders, input_range=BOUNDS)
        assert largest_error(out.solution, ex) > far
        assert int(out.solution.status) == Status.tracking
        assert float(out.noise_level) == 0.0 and float(out.noise_ratio) > 1e3


def test_noise_free_settings_converge_with_a_zero_noise_level():
    ex, U, Y = records(2, jnp.inf, [0, 1, 2])
    fit = Recursive(**NOISE_FREE)
    solution = jax.vmap(lambda u, y: fit(u, y, ex.orders, input_range=BOUNDS))(U, Y)
    assert np.all(np.asarray(solution.status) == Status.converged)
    assert np.max(largest_error(solution, ex)) < 1e-6


def test_under_noise_the_defaults_converge_at_the_noise_level_they_estimate():
    # Example 1 at SNR 25: every estimate settles; the noise level the recursion
    # estimates (from the steps of the output where it puts the backlash at rest) is
    # the noise added, std(y) / 25, within the lower quartile's sampling error on about
    # 70 samples (measured 0.8 to 1.2 times it)
    ex, U, Y = records(1, 25.0, [0, 1, 2, 3])
    out = jax.vmap(lambda u, y: recursive(u, y, ex.orders, input_range=BOUNDS))(U, Y)
    assert np.all(np.asarray(out.solution.status) == Status.converged)
    assert np.max(largest_error(out.solution, ex)) < 0.05
    from jaxcascade._system._simulate import simulate

    sigma = np.asarray([np.std(simulate(ex.params(), u)) / 25.0 for u in U])
    np.testing.assert_allclose(np.asarray(out.noise_level) / sigma, 1.0, atol=0.35)
    assert np.all(np.asarray(out.settling) <= 3.0) and np.all(np.asarray(out.noise_ratio) <= 3)


def test_the_thresholds_are_settings_and_decide():
    ex, U, Y = records(1, 25.0, [0])
    out = recursive(U[0], Y[0], ex.orders, input_range=BOUNDS)
    assert int(out.solution.status) == Status.converged
    # the same record, asked to settle to a tenth of its own statistic: tracking
    strict = recursive(
        U[0], Y[0], ex.orders, input_range=BOUNDS, settle_tolerance=0.1 * float(out.settling)
    )
    assert int(strict.solution.status) == Status.tracking
    # passes over the record: the budget of passes ran out
    again = recursive(U[0], Y[0], ex.orders, input_range=BOUNDS, passes=2, noise_tolerance=1e-3)
    assert int(again.solution.status) == Status.max_iterations
    for bad in ({"settle_window": 1}, {"settle_tolerance": 0.0}, {"noise_tolerance": -1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            estimator("recursive", **bad)


# ---- output-error fits: the data's word (`_basin.claim`) -------------------------------


def _numpy_validity(xi, u, lags=10):
    """Billings and Voon's five tests in plain NumPy (an independent reference)."""
    n = len(xi)

    def rho(a, b, first):
        a, b = a - a.mean(), b - b.mean()
        scale = np.sqrt((a @ a) * (b @ b))
        return np.array([a[k:] @ b[: n - k] for k in range(first, first + lags)]) / scale

    xi = xi - xi.mean()
    u2 = u**2 - np.mean(u**2)
    pairs = [(xi, xi, 1), (xi, u, 0), (xi, xi * u, 1), (xi, u2, 0), (xi**2 - np.mean(xi**2), u2, 0)]
    return max((n * np.sum(rho(a, b, f) ** 2) - lags) / np.sqrt(2 * lags) for a, b, f in pairs)


def _ar(pole):
    from jaxcascade._experiment._disturbance import disturbance

    return disturbance("ar", poles=(pole,))


def _ar_noise(key, n, pole):
    return _ar(pole)(key, n, jnp.float64)


def test_validity_statistic_matches_numpy_and_ignores_the_noise_colour():
    from jaxcascade._estimator._basin import validity_statistic, whitened

    key_u, key_e = jax.random.split(jax.random.PRNGKey(11))
    u = uniform_input(key_u, 2000, 2.0)
    e = jax.random.normal(key_e, (2000,))
    np.testing.assert_allclose(
        float(validity_statistic(e, u)), _numpy_validity(np.asarray(e), np.asarray(u)), rtol=1e-9
    )
    statistic = jit(validity_statistic)  # one program, not one per eager call
    # noise independent of a white input passes, white or AR(1) with pole 0.9 once
    # whitened (each test about standard normal: bound 5 is P ~ 4e-4 per test)
    for k in jax.random.split(key_e, 6):
        assert float(statistic(jax.random.normal(k, (2000,)), u)) < 5.0
        assert float(statistic(whitened(_ar_noise(k, 2000, 0.9)), u)) < 5.0
    # coloured and not whitened, it fails: the tests are not blind
    assert float(statistic(_ar_noise(key_e, 2000, 0.9), u)) > 5.0


@pytest.mark.parametrize("noise", ["none", "white", "ar0.9"])
def test_claim_refuses_what_the_model_cannot_describe_and_keeps_the_truth(noise):
    # Example 1's record under three noises, judged as robust judges its estimate (the
    # residual whitened and projected off the whitened Jacobian): the truth keeps
    # `converged`; the truth on the same record clipped at its 5 % and 95 % quantiles
    # (a model error no parameter of the cascade can absorb) becomes `local_minimum`;
    # the truth with a breakpoint moved onto the end of the input's range, `on_edge`; a
    # failed status stays what it was. Without the projection, a backlash gap 0.1 too
    # wide is refused too (its error is the Jacobian's: robust's own estimation error
    # under coloured noise is of that kind, and the projection lets it pass).
    from jaxcascade._estimator._basin import claim
    from jaxcascade._estimator._sensitivity import output_jacobian
    from jaxcascade._system._model import CascadeParams
    from jaxcascade._system._simulate import add_noise, simulate

    ex = example(1)
    key_u, key_e = jax.random.split(jax.random.PRNGKey(5))
    u = uniform_input(key_u, ex.n_samples, ex.amplitude)
    y0 = simulate(ex.params(), u)
    snr = jnp.inf if noise == "none" else 25.0
    shape = _ar(0.9) if noise == "ar0.9" else None
    y = add_noise(key_e, y0, snr, shape)
    low, high = jnp.quantile(y0, jnp.array([0.05, 0.95]))
    clipped = add_noise(key_e, jnp.clip(y0, low, high), snr, shape)
    truth = ex.params().to_vector()
    names = list(ex.orders.names)

    # one compiled program per `project` (eagerly, each call compiles every scan anew)
    @functools.partial(jit, static_argnames="project")
    def judged(vector, start, record, project):
        params = CascadeParams.from_vector(vector, ex.orders, check=False)
        simulated, jacobian = output_jacobian(params, u)
        jacobian = jacobian if project else None
        return claim(start, params, simulated - record, u, record, 5.0, jacobian=jacobian)

    def status(vector, start=Status.converged, record=y, project=True):
        return Status(int(judged(vector, jnp.asarray(int(start)), record, project)))

    assert status(truth) is Status.converged
    assert status(truth, record=clipped) is Status.local_minimum
    assert status(truth.at[names.index("DR1")].set(0.999 * float(u.max()))) is Status.on_edge
    assert status(truth, Status.max_iterations) is Status.max_iterations
    wide = truth.at[names.index("cR")].add(0.1)
    assert status(wide, project=False) is Status.local_minimum


def _returning(vector):
    def fixed(u, y, orders):
        return vector

    return fixed


def test_a_host_functions_vector_gets_the_packages_word():
    # a host function's finite vector is not "converged" by being finite: the truth is,
    # a wrong backlash gap is a local minimum, a vector outside the domain left it
    from jaxcascade._estimator._host import HostEstimator

    ex, U, Y = records(1, 25.0, [0])
    truth = np.asarray(ex.params().to_vector())
    names = list(ex.orders.names)
    wrong = truth.copy()
    wrong[names.index("cR")] += 0.1
    outside = truth.copy()
    outside[names.index("mR")] = -1.0
    for vector, expected in (
        (truth, Status.converged),
        (wrong, Status.local_minimum),
        (outside, Status.left_domain),
        (np.full_like(truth, np.nan), Status.failed),
    ):
        fit = HostEstimator("fixed", _returning(vector))()
        assert Status(int(fit(U[0], Y[0], ex.orders).status)) is expected
