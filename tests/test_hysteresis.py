"""The hysteresis operators and the effects built on them (issue 15): closed forms on a
triangle wave, the NumPy oracle, linearity in the weights, the friction paths' levels,
slack and stiffness, recovery of their parameters, and a joint refit on two records."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

import jaxcascade as jc
from jaxcascade._compile import jit
from jaxcascade._measured._effects import EFFECTS, ExtendedModel, plain, simulate_extended
from jaxcascade._measured._noise import ARNoise

TRUTH = jc.example(1).params


def _triangle(amplitude=1.0, period=200, cycles=3):
    t = np.arange(period * cycles)
    phase = (t % period) / period
    return amplitude * np.where(
        phase < 0.25, 4 * phase, np.where(phase < 0.75, 2 - 4 * phase, 4 * phase - 4)
    )


def test_stop_operator_on_a_triangle_wave():
    from jaxcascade._measured._effects._operators import play_operator, stop_operator

    u = _triangle()
    r = 0.3
    s = np.asarray(stop_operator(jnp.asarray(u), r))
    du = np.diff(u, prepend=u[:1])
    # First rise from 0: s = min(u, r); then on every monotone branch s moves with u
    # until it saturates at +-r: a closed form from the distance travelled since the
    # last reversal.
    first = u <= r
    first[np.argmax(u >= 1.0) :] = False
    np.testing.assert_allclose(s[: np.argmax(u > r)], u[: np.argmax(u > r)], atol=1e-12)
    reversals = np.flatnonzero(np.sign(du[1:]) * np.sign(du[:-1]) < 0)
    for k in reversals[1:]:
        direction = -np.sign(du[k])
        travel = np.abs(u[k:] - u[k])
        branch = slice(k, k + 40)  # within the branch (50 samples per half-branch)
        expected = np.clip(np.sign(du[k]) * r + direction * travel[:40], -r, r)
        np.testing.assert_allclose(s[branch], expected, atol=1e-12)
    assert np.all(np.abs(s) <= r + 1e-12)
    # The play operator is the input minus the stop (a backlash of half-width r).
    np.testing.assert_allclose(play_operator(jnp.asarray(u), r), u - s - u[0], atol=1e-12)


def test_stop_operator_matches_the_numpy_oracle():
    from jaxcascade._measured._diagnose import stop_outputs
    from jaxcascade._measured._effects._operators import stop_operators

    u = np.cumsum(np.random.default_rng(0).normal(size=500)) * 0.1
    thresholds = np.array([0.05, 0.2, 1.0])
    np.testing.assert_allclose(
        stop_operators(jnp.asarray(u), thresholds), stop_outputs(u, thresholds), atol=1e-12
    )


def test_prandtl_ishlinskii_is_linear_in_its_weights():
    from jaxcascade._measured._effects import PrandtlIshlinskii

    u = jnp.asarray(_triangle())
    thresholds, knots = jnp.array([0.1, 0.4]), jnp.array([0.5])
    size = 2 * 3
    rng = np.random.default_rng(1)
    w1, w2 = jnp.asarray(rng.normal(size=size)), jnp.asarray(rng.normal(size=size))

    def pi(w, c=0.0):
        return PrandtlIshlinskii(thresholds, knots, w, jnp.asarray(c)).parallel(u)

    assert pi(w1).shape == u.shape
    np.testing.assert_allclose(pi(w1 + 2 * w2), pi(w1) + 2 * pi(w2), atol=1e-12)


def test_slack_friction_plateaus_and_dead_zone():
    from jaxcascade._measured._effects import SlackFriction

    u = jnp.asarray(_triangle())
    effect = SlackFriction(*(jnp.asarray(v) for v in (0.3, 0.5, 2.0, -1.5)))
    force = np.asarray(effect.parallel(u))
    from jaxcascade._measured._effects._operators import stop_operator

    s = np.asarray(stop_operator(u, 0.3))
    np.testing.assert_allclose(force[np.abs(s) <= 0.15], 0.0)  # the slack (dead zone)
    # The effect keeps its threshold positive by adding 1e-6: tolerance 1e-4.
    np.testing.assert_allclose(force[s >= 0.3 - 1e-12], 2.0, atol=1e-4)  # sliding forward
    np.testing.assert_allclose(force[s <= -0.3 + 1e-12], -1.5, atol=1e-4)  # sliding back


def test_backlash_friction_slack_stiffness_and_levels():
    # A triangle of amplitude 1 through a slack of half-width 0.1, stiffness 20, levels
    # 2 (forward) and 1.5 (back): after each reversal the force falls to 0 with slope k,
    # stays 0 for 2 gap of travel, then rises with slope k to the other level.
    from jaxcascade._measured._effects._operators import backlash_friction

    u = _triangle(period=2000)
    gap, k, upper, lower = 0.1, 20.0, 2.0, 1.5
    force = np.asarray(backlash_friction(jnp.asarray(u), gap, k, upper, lower))
    assert force.max() == pytest.approx(upper, abs=1e-12)
    assert force.min() == pytest.approx(-lower, abs=1e-12)
    # The second cycle, from the top (u = 1, sliding forward): the force is zero over a
    # travel of exactly 2 gap, after an elastic unloading of upper / k.
    top = 2000 + 500
    travel = u[top] - u[top : top + 1000]
    zero = np.abs(force[top : top + 1000]) < 1e-12
    assert travel[zero].min() == pytest.approx(upper / k, abs=2e-3)
    assert travel[zero].max() - travel[zero].min() == pytest.approx(2 * gap, abs=4e-3)
    contact = (travel > upper / k + 2 * gap + 0.01) & (travel < upper / k + 2 * gap + 0.05)
    slope = np.diff(force[top : top + 1000][contact]) / np.diff(-travel[contact])
    np.testing.assert_allclose(slope, k, rtol=1e-9)


def test_backlash_friction_starts_are_forgotten_after_sliding_both_ways():
    from jaxcascade._measured._effects._operators import backlash_friction, backlash_friction_start

    u = jnp.asarray(_triangle(period=400))
    one = np.asarray(backlash_friction(u, 0.1, 20.0, 2.0, 1.5, (0.0,)))
    mean = np.asarray(backlash_friction(u, 0.1, 20.0, 2.0, 1.5, np.linspace(-1, 1, 9)))
    # Before the first slides the starts disagree (the mean is not the centre's force);
    # after sliding forward and back (u from 1 to -1) every start gives the same force.
    assert np.abs(one[:100] - mean[:100]).max() > 0.1
    np.testing.assert_allclose(one[300:], mean[300:], atol=1e-12)
    # A start from a measured initial force reproduces it while the input is at rest.
    start = backlash_friction_start(0.7, 0.1, 20.0, offset=0.2)
    rest = jnp.zeros(10)
    np.testing.assert_allclose(backlash_friction(rest, 0.1, 20.0, 2.0, 1.5, (start,)), 0.5)
    assert backlash_friction_start(0.2, 0.1, 20.0, offset=0.2) == 0.0


def test_backlash_friction_is_traceable_and_differentiable():
    from jaxcascade._measured._effects._operators import backlash_friction

    u = jnp.asarray(_triangle(period=400))

    def cost(theta):
        return jnp.sum(backlash_friction(u, *theta, (-1.0, 1.0)) ** 2)

    grad = jit(jax.grad(cost))(jnp.array([0.1, 20.0, 2.0, 1.5]))
    assert np.all(np.isfinite(np.asarray(grad))) and np.all(np.asarray(grad) != 0)


@pytest.mark.parametrize("name", ["backlash_friction", "backlash_friction_contacts"])
def test_backlash_friction_effect_recovers_its_parameters(name):
    # Two synthetic records of different amplitudes (a rotor that slides in both), noise
    # 0.05: the output-error fit from the default grid of starts recovers the slack, the
    # stiffness, both levels and the offset.
    from jaxcascade._measured._effects import HYSTERESIS

    effect_class = EFFECTS[name]
    assert effect_class.needs_signature and name in HYSTERESIS
    truth = effect_class(*(jnp.asarray(v) for v in (0.08, 30.0, 2.3, 2.0, 0.1)))
    rng = np.random.default_rng(3)
    rows = []
    for amplitude in (0.5, 0.25):
        u = np.cumsum(rng.normal(size=1500))
        u = scipy.signal.lfilter([0.05], [1, -0.95], u - u.mean())
        u = amplitude * u / np.abs(u).max()
        y = np.asarray(truth.parallel(jnp.asarray(u))) + 0.05 * rng.normal(size=u.size)
        rows.append((u, y, y))
    fitted, label = effect_class.fit_records(None, rows)
    assert label.startswith(name + ":")
    got = [abs(float(v)) for v in (fitted.gap, fitted.stiffness, fitted.upper, fitted.lower)]
    np.testing.assert_allclose(got, [0.08, 30.0, 2.3, 2.0], rtol=0.05)
    assert float(fitted.offset) == pytest.approx(0.1, abs=0.02)


def test_backlash_friction_fit_keeps_the_best_of_its_starts_fitted_one_at_a_time():
    # The starts run side by side in one call (`vmap`); the result must be the one each
    # start fitted on its own gives, the lowest cost kept: the same parameters and cost.
    import itertools

    from jaxcascade._estimator._levenberg import least_squares
    from jaxcascade._measured._effects._hysteresis import BacklashFriction, backlash_friction

    truth = BacklashFriction(*(jnp.asarray(v) for v in (0.08, 30.0, 2.3, 2.0, 0.1)))
    rng = np.random.default_rng(5)
    u = scipy.signal.lfilter([0.05], [1, -0.95], np.cumsum(rng.normal(size=600)))
    u = 0.4 * (u - u.mean()) / np.abs(u - u.mean()).max()
    y = np.asarray(truth.parallel(jnp.asarray(u))) + 0.05 * rng.normal(size=u.size)
    theta, cost, status = BacklashFriction.fit([(u, y)])

    fractions = BacklashFriction.start_fractions
    span = float(np.quantile(u, 0.995) - np.quantile(u, 0.005))
    level = float(np.quantile(np.abs(y), 0.9))

    def residual(z, args):
        g, k, up, lo = jnp.exp(z[:4])
        return (z[4] + backlash_friction(jnp.asarray(u), g, k, up, lo, fractions) - y) / u.size**0.5

    # one compiled program for every start, run one start at a time
    single = jit(
        lambda z0: least_squares(
            residual, z0, None, max_steps=BacklashFriction.max_steps, ftol=BacklashFriction.ftol
        )
    )
    singles = []
    for gap, travel in itertools.product(
        BacklashFriction.gap_fractions, BacklashFriction.travel_fractions
    ):
        z0 = jnp.asarray(
            np.log([gap * span, level / (travel * span), level, level]).tolist() + [0.0]
        )
        z, c, code, _ = single(z0)
        theta_single = np.concatenate([np.exp(np.asarray(z[:4])), np.asarray(z[4:])])
        singles.append((float(c), theta_single, int(code)))
    best_cost, best_theta, best_status = min(singles, key=lambda triple: triple[0])
    assert status == best_status
    # `least_squares`'s cost is the mean of the squared residuals, (e / sqrt(T))^2 here;
    # `fit`'s the mean squared error
    assert cost == pytest.approx(best_cost * u.size, rel=1e-9)
    np.testing.assert_allclose(theta, best_theta, rtol=1e-7)


def test_backlash_friction_label_says_when_its_fit_ran_out_of_steps(monkeypatch):
    # a status is a claim: a kept start that stopped at the step budget says so in the
    # candidate's label; a converged one adds nothing
    from jaxcascade._measured._effects._hysteresis import BacklashFriction

    truth = BacklashFriction(*(jnp.asarray(v) for v in (0.08, 30.0, 2.3, 2.0, 0.1)))
    rng = np.random.default_rng(5)
    u = 0.4 * np.sin(np.linspace(0, 12 * np.pi, 400))
    y = np.asarray(truth.parallel(jnp.asarray(u))) + 0.05 * rng.normal(size=u.size)
    records = [(u, None, y)]
    _, label = BacklashFriction.fit_records(None, records)
    assert "max_iterations" not in label and BacklashFriction.fit([(u, y)])[2] == 0
    monkeypatch.setattr(BacklashFriction, "max_steps", 2)
    _, label = BacklashFriction.fit_records(None, records)
    assert label.endswith(",max_iterations (2 steps)")


def test_dahl_reaches_its_level():
    from jaxcascade._measured._effects._operators import dahl

    u = jnp.linspace(0.0, 1.0, 400)
    force = np.asarray(dahl(u, 50.0, 2.0))
    assert force[-1] == pytest.approx(2.0, rel=1e-6)
    assert np.all(np.diff(force) >= 0)


def test_hysteresis_effect_is_refitted_on_several_records():
    # A cascade plus a friction path: the loop machinery refits the path's parameters
    # jointly on two records, each from its own initial state.
    from jaxcascade._measured._effects import SlackFriction
    from jaxcascade._measured._loop import refit

    truth = SlackFriction(*(jnp.asarray(v) for v in (0.4, 0.4, 1.0, -0.8)))
    model = ExtendedModel(TRUTH(), (truth,), ARNoise.white())
    records = []
    for seed in (1, 2):
        u = jc.uniform_input(jax.random.PRNGKey(seed), 600)
        records.append((u, simulate_extended(model, u)))
    base = plain(TRUTH())
    rows = [
        (np.asarray(u), np.asarray(y), np.asarray(y - simulate_extended(base, u)))
        for u, y in records
    ]
    (start,) = SlackFriction.starts_records(base, rows)[:1]
    fitted, cost, _ = refit(base, start, [r[0] for r in records], [r[1] for r in records], 30)
    assert cost < 1e-3 * np.var(np.asarray(records[0][1]))


def test_ridge_with_vanishing_features_is_minimum_norm():
    from jaxcascade._measured._effects._operators import ridge

    X = np.zeros((50, 3))
    X[:, 0] = np.linspace(-1, 1, 50)
    theta = ridge([X], [2.0 * X[:, 0]])
    np.testing.assert_allclose(theta, [2.0, 0.0, 0.0], atol=1e-4)
    np.testing.assert_array_equal(ridge([np.zeros((10, 2))], [np.ones(10)]), [0.0, 0.0])
