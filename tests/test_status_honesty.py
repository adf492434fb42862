"""What `converged` means for the on-line estimator (issue 35): settled over the last
window, relative to the recursion's standard errors, and at the noise level it
estimates; otherwise `tracking`. The word never describes an estimate far from the
truth on a noise-free record. Records are those `jaxcascade reproduce --example N --seed
S --snr SNR` draws (`_cli._reproduce.run_example`). `results/status_honesty.md` counts
every estimator's statuses against the truth over many records; here, the cases the
issue names.
"""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcascade._cli import main
from jaxcascade._estimator import estimator
from jaxcascade._estimator._recursive import NOISE_FREE, Recursive, recursive
from jaxcascade._examples import example
from jaxcascade._simulate import measure, uniform_input
from jaxcascade._status import Status, status_names

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
    assert [s.value for s in Status] == list(range(9))
    assert Status.tracking == 8 and Status.no_improvement == 7 and Status.converged == 0
    assert Status.tracking.failure and "noise level" in Status.tracking.message
    assert list(status_names([0, 8, 9])) == ["converged", "tracking", "unknown"]


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
    from jaxcascade._simulate import simulate

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
