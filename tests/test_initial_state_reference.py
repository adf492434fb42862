"""The initial-state fit against an independent truth: a known cascade simulated by the
plain-NumPy oracle (`oracle_state.py`, `oracle_effects.stop`) from a known state other
than rest, noise-free; the package's initialised output (`_loop.initialised_output`:
the state before `start - n` fitted to the measured output on `[start - n, start)`)
must reproduce the oracle's output after `start`.

Tolerance, derived from the fit's stopping rule: Levenberg-Marquardt
(`_estimator._levenberg.least_squares`) stops once a step moves every state component by
less than `atol + rtol |z_k|` (1e-10, 1e-8), so the fitted state is within about that of
a state that reproduces the window. The output after the window moves, for such a
change of each component, by what the oracle says (every block is continuous and
piecewise affine in the state, so a finite difference of that size is the local
gain); the tolerance is 10 times the sum over components (all off by their bound at
once). It comes out 1e-8 to 1e-7 of the output's scale; observed errors are ~1e-14.
"""

import jax.numpy as jnp
import numpy as np
import oracle
import oracle_effects
import oracle_state
import pytest

from jaxcascade._measured._effects import InputBacklash, plain
from jaxcascade._measured._loop import initialised_output
from jaxcascade._system._model import CascadeParams, Orders

ORDERS = Orders(2, 2, 2, 2)
# Example 1's static block and backlash with slower real poles (0.85, 0.7; no overshoot)
# and a zero at 0.8 (steady gain 4.4): the linear block's state is felt for tens of
# samples.
P = {
    "MR": [1.2, -1.4],
    "DR": [1.0],
    "ML": [0.7, -0.8],
    "DL": [-0.9],
    "a": [-0.8],
    "b": [-1.55, 0.595],
    "cL": 0.2,
    "mR": 1.2,
    "cR": 0.3,
}
# the state before sample 0 (not rest): v(-1), v(-2); x(-1), x(-2); y(-1)
STATE = {"v_past": [0.8, -0.5], "x_past": [2.5, 1.0], "y_prev": 1.1}
GAP, POSITION = 0.4, -0.3  # input backlash: half-width, stop operator's position
ATOL, RTOL = 1e-10, 1e-8  # `least_squares`'s defaults, used by the initial-state fit
T, N_INIT = 300, 30


def _params():
    return CascadeParams.from_vector(jnp.asarray(oracle.pack(P)), ORDERS)


HOLD = 100


def _input():
    """100 samples of small motion about 0.233, then uniform in (-2, 2). While it lasts
    the linear block's output settles near 1.05 from its state (from above: the
    backlash's left line, y = x + cL) or from rest (from below: the right line), and
    stays in the dead band between; the input backlash's operator stays inside its
    slack. The state is remembered until sample 100, and the window shows it."""
    t = np.arange(HOLD)
    rng = np.random.default_rng(11)
    return np.concatenate([0.233 + 0.02 * np.sin(t / 4), rng.uniform(-2.0, 2.0, T - HOLD)])


def _truth(u, state, position=None):
    """Oracle output from `state` (and, with `position`, through an input backlash whose
    stop operator is at `position` before sample 0, no first increment)."""
    z = [*state["v_past"], *state["x_past"], state["y_prev"]]
    if position is not None:
        z.append(position)

    def output(z):
        w = u if position is None else u - oracle_effects.stop(u, GAP, z[5], u[0])
        return oracle_state.simulate_from(P, w, z[0:2], z[2:4], z[4])[2]

    return z, output


def _tolerance(z, output, start):
    base = output(z)[start:]
    total = 0.0
    for k in range(len(z)):
        moved = list(z)
        moved[k] += ATOL + RTOL * abs(z[k])
        total += np.max(np.abs(output(moved)[start:] - base))
    return 10 * total


def test_state_oracle_from_rest_is_the_oracle():
    u = _input()
    got = oracle_state.simulate_from(P, u, [0.0, 0.0], [0.0, 0.0], 0.0)
    for a, b in zip(got, oracle.simulate(P, u), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("backlash", [False, True], ids=["cascade", "input-backlash"])
def test_initialised_output_reproduces_the_oracle_after_the_window(backlash):
    start = N_INIT  # the state is fitted before sample 0, where the oracle's is known
    u = _input()
    z, output = _truth(u, STATE, POSITION if backlash else None)
    y = output(z)
    model = plain(_params())
    if backlash:
        model = model.with_(effects=(InputBacklash(jnp.asarray(GAP)),))
    # from rest the output after the window is wrong by a margin (else nothing is tested)
    rest = output([0.0] * len(z))
    assert np.max(np.abs(rest[start:HOLD] - y[start:HOLD])) > 0.1 * np.std(y)

    got = initialised_output(model, u, y, start, N_INIT)
    assert got.shape == (T - start,)
    tolerance = _tolerance(z, output, start)
    assert tolerance < 1e-6 * np.std(y)  # the derivation gives a tight bound
    np.testing.assert_allclose(got, y[start:], rtol=0, atol=tolerance)
