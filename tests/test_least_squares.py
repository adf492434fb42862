"""`_levenberg.least_squares` (the model-error loop's Levenberg-Marquardt) is
optimistix's method computed on the normal equations: against `optx.least_squares`
with `optx.LevenbergMarquardt` itself, the same iterates (the same number of steps,
give or take the last, and the same estimate to rounding) on smooth problems, on one
that needs rejected steps, and on a simulated backlash record, where the error is
piecewise smooth."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import jaxcascade as jc
from jaxcascade._compile import jit
from jaxcascade._estimator._levenberg import least_squares

RTOL, ATOL = 1e-8, 1e-10  # the loop's tolerances (`least_squares`'s defaults)


def _rosenbrock(z, args):
    return jnp.stack([10.0 * (z[1] - z[0] ** 2), 1.0 - z[0]])


def _exponentials(z, args):
    t = jnp.linspace(0.0, 4.0, 60)
    measured = 2.0 * jnp.exp(-1.3 * t) + 0.5 * jnp.exp(-0.2 * t) + 0.01 * jnp.sin(7 * t)
    return z[0] * jnp.exp(-z[1] * t) + z[2] * jnp.exp(-z[3] * t) - measured


def _backlash(z, args):
    # Example 1's cascade with its backlash gaps and slope from z, on a record of itself
    truth = jc.example(1).params()
    u = jax.random.uniform(jax.random.PRNGKey(2), (300,), minval=-2.0, maxval=2.0)
    y = jc.simulate(truth, u)
    params = jc.CascadeParams.from_vector(
        truth.to_vector().at[-3:].set(jnp.exp(z)), truth.orders, check=False
    )
    return jc.simulate(params, u) - y


def _optimistix(residual, z0, max_steps):
    solver = optx.LevenbergMarquardt(rtol=RTOL, atol=ATOL)
    solution = optx.least_squares(residual, solver, z0, max_steps=max_steps, throw=False)
    return solution.value, int(solution.stats["num_steps"]), solution.result


@pytest.mark.parametrize(
    "residual, z0",
    [
        (_rosenbrock, [-1.2, 1.0]),
        (_exponentials, [1.0, 2.0, 1.0, 0.1]),
        (_backlash, np.log([0.1, 0.8, 0.05])),
    ],
    ids=["rosenbrock", "exponentials", "backlash"],
)
def test_the_iterates_are_optimistix_levenberg_marquardt(residual, z0):
    z0 = jnp.asarray(z0, jnp.float64)
    expected, steps, result = _optimistix(residual, z0, 200)
    assert result == optx.RESULTS.successful  # the reference converged
    z, cost, status, taken = jit(lambda z: least_squares(residual, z, None, max_steps=200))(z0)
    assert int(status) == int(jc.Status.converged)
    # the same iterates; the last step may differ by one: at the minimum accepting the
    # step is a matter of rounding (`least_squares`'s docstring)
    assert abs(int(taken) - steps) <= 1
    np.testing.assert_allclose(z, expected, rtol=1e-8, atol=1e-10)
    assert float(cost) == pytest.approx(float(jnp.mean(residual(expected, None) ** 2)), rel=1e-6)


def test_rejected_steps_and_the_budget():
    # Rosenbrock from far: optimistix rejects steps on the way (it takes more steps than
    # it accepts); a budget below what it needs is `max_iterations` at the same iterate
    z0 = jnp.asarray([-3.0, 8.0])
    for max_steps in (5, 9):
        expected, steps, result = _optimistix(_rosenbrock, z0, max_steps)
        assert result == optx.RESULTS.nonlinear_max_steps_reached
        z, _, status, taken = least_squares(_rosenbrock, z0, None, max_steps=max_steps)
        assert int(status) == int(jc.Status.max_iterations)
        assert int(taken) == steps == max_steps
        np.testing.assert_allclose(z, expected, rtol=1e-10, atol=1e-12)


def test_the_cost_test_ends_the_fit_at_a_step_that_hardly_lowers_the_loss():
    # `ftol`: the iterates are the plain fit's; the fit ends, `converged`, at the first
    # accepted step that lowers the loss by at most ftol times it, before the Cauchy test
    z0 = jnp.asarray([-1.2, 1.0])
    run = jit(
        lambda z, budget, ftol: least_squares(_rosenbrock, z, None, max_steps=budget, ftol=ftol),
        static_argnums=(1, 2),
    )
    plain = run(z0, 200, None)
    assert int(plain[2]) == int(jc.Status.converged)
    ftol = 0.2  # Rosenbrock from the usual start: the first such step is the 13th
    z, cost, status, steps = run(z0, 200, ftol)
    assert int(status) == int(jc.Status.converged) and int(steps) < int(plain[3])
    # the plain fit's iterate after as many steps
    np.testing.assert_array_equal(z, run(z0, int(steps), None)[0])
    # the losses of the plain fit step by step: the last change, the stopping step's, is
    # a fall of at most ftol of the loss, and no earlier accepted step's is
    losses = [float(run(z0, k, None)[1]) for k in range(1, int(steps) + 1)]
    changes = [(a, b) for a, b in zip(losses, losses[1:], strict=False) if a != b]
    assert changes[-1][0] - changes[-1][1] <= ftol * changes[-1][0]
    assert all(a - b > ftol * a for a, b in changes[:-1])
    # off by default: the same iterates as without the argument
    np.testing.assert_array_equal(plain[0], least_squares(_rosenbrock, z0, None, max_steps=200)[0])


def test_no_step_allowed_is_the_starts_cost():
    z, cost, status, steps = least_squares(_rosenbrock, jnp.asarray([-1.2, 1.0]), None, max_steps=0)
    assert float(cost) == pytest.approx(12.1, rel=1e-14)
    assert (int(status), int(steps)) == (int(jc.Status.max_iterations), 0)
    np.testing.assert_array_equal(z, [-1.2, 1.0])


def test_a_start_that_is_not_finite_is_diverged_and_returned():
    def residual(z, args):
        return jnp.log(z) - 1.0

    z0 = jnp.asarray([-1.0, 2.0])
    z, cost, status, _ = least_squares(residual, z0, None)
    assert int(status) == int(jc.Status.diverged)
    assert float(cost) == np.inf
    np.testing.assert_array_equal(z, z0)


def test_nothing_to_fit_is_the_starts_cost():
    def residual(z, args):
        return jnp.asarray([1.0, -3.0])

    z, cost, status, steps = least_squares(residual, jnp.zeros((0,)), None)
    assert (z.shape, float(cost), int(status), int(steps)) == ((0,), 5.0, 0, 0)
