"""The ARX peer (`_arx.py`) against plain NumPy: a least-squares fit with the regressor
matrix built row by row, the free-run recursion written out, and `best_arx`'s choice
redone from them.

Convention (docs/model.md, MATLAB's): `A(q) y(t) = B(q) u(t) + c + e(t)`,
`A = 1 + a1 q^-1 + ... + a_na q^-na` (`ARX.a`, the denominator, MATLAB's sign),
`B = b1 q^-1 + ... + b_nb q^-nb` (`ARX.b`, the numerator, one sample of delay), signals
zero before the record. So `y(t) = -sum_i a_i y(t-i) + sum_j b_j u(t-j) + c + e(t)`.
"""

import numpy as np
import pytest

from jaxcascade._measured._arx import ARX, best_arx, fit_arx

EPS = np.finfo(float).eps
N = 500
# A = 1 - 1.5 q^-1 + 0.7 q^-2: a complex pair of poles of modulus sqrt(0.7)
A_TRUE, B_TRUE, C_TRUE = np.array([-1.5, 0.7]), np.array([1.0, 0.5]), 0.3


def recursion(a, b, c, u, e=None, y=None, start=0):
    """`y(t) = -sum a_i y(t-i) + sum b_j u(t-j) + c + e(t)`, zero before the record;
    with `y`, its samples before `start` are kept and the recursion runs from `start`."""
    out = np.zeros(len(u)) if y is None else np.array(y, float)
    for t in range(start, len(u)):
        total = c + (0.0 if e is None else e[t])
        for i in range(1, len(a) + 1):
            total -= a[i - 1] * (out[t - i] if t - i >= 0 else 0.0)
        for j in range(1, len(b) + 1):
            total += b[j - 1] * (u[t - j] if t - j >= 0 else 0.0)
        out[t] = total
    return out


def least_squares(u, y, na, nb):
    """Equation-error least squares on every sample whose regressors lie in the record
    (t >= max(na, nb)): rows `[-y(t-1) .. -y(t-na), u(t-1) .. u(t-nb), 1]`."""
    rows, targets = [], []
    for t in range(max(na, nb), len(y)):
        rows.append(
            [-y[t - i] for i in range(1, na + 1)] + [u[t - j] for j in range(1, nb + 1)] + [1.0]
        )
        targets.append(y[t])
    phi = np.array(rows)
    theta = np.linalg.lstsq(phi, np.array(targets), rcond=None)[0]
    return theta[:na], theta[na : na + nb], float(theta[-1]), np.linalg.cond(phi)


def _record(noise):
    rng = np.random.default_rng(40)
    u = rng.uniform(-1.0, 1.0, N)
    e = noise * rng.normal(size=N)
    return u, recursion(A_TRUE, B_TRUE, C_TRUE, u, e)


def _theta(a, b, c):
    return np.concatenate([a, b, [c]])


@pytest.mark.parametrize("na, nb", [(2, 2), (3, 1), (1, 3), (4, 4)])
def test_fit_arx_is_the_least_squares_fit(na, nb):
    # Both solve the same least-squares problem; solutions of one problem agree to
    # about cond(phi) eps |theta| (here below 1e-12), so 1e-10 is a tight bound.
    u, y = _record(noise=0.1)
    a, b, c, cond = least_squares(u, y, na, nb)
    want = _theta(a, b, c)
    assert cond * EPS * np.max(np.abs(want)) < 1e-12
    fit = fit_arx(u, y, na, nb)
    assert fit.orders == (na, nb)
    np.testing.assert_allclose(_theta(fit.a, fit.b, fit.c), want, rtol=0, atol=1e-10)


def test_noise_free_fit_recovers_the_matlab_polynomials():
    # Noise-free, the equation holds exactly: the fit is the truth, with A's signs
    # (a = [-1.5, 0.7], not [1.5, -0.7]) and b the numerator after one delay.
    u, y = _record(noise=0.0)
    fit = fit_arx(u, y, 2, 2)
    _, _, _, cond = least_squares(u, y, 2, 2)
    np.testing.assert_allclose(fit.a, A_TRUE, rtol=0, atol=100 * cond * EPS)
    np.testing.assert_allclose(fit.b, B_TRUE, rtol=0, atol=100 * cond * EPS)
    assert fit.c == pytest.approx(C_TRUE, abs=100 * cond * EPS)
    # z^2 - 1.5 z + 0.7 has complex roots of modulus sqrt(0.7)
    assert ARX(A_TRUE, B_TRUE, C_TRUE).largest_pole == pytest.approx(np.sqrt(0.7), rel=1e-12)


def test_simulate_is_the_recursion():
    # Free run from rest and from the measured output before `start`: a stable
    # recursion (poles of modulus 0.84) of N steps, so the two orders of the same sums
    # differ by at most about N eps of the output's scale; 10 N eps scale is the bound.
    u, y = _record(noise=0.1)
    model = ARX(A_TRUE, B_TRUE, C_TRUE)
    want = recursion(A_TRUE, B_TRUE, C_TRUE, u)
    scale = np.max(np.abs(want))
    np.testing.assert_allclose(model.simulate(u), want, rtol=0, atol=10 * N * EPS * scale)
    start = 50
    want = recursion(A_TRUE, B_TRUE, C_TRUE, u, y=y, start=start)
    got = model.simulate(u, y, start)
    np.testing.assert_array_equal(got[:start], y[:start])
    np.testing.assert_allclose(got, want, rtol=0, atol=10 * N * EPS * scale)
    # the free run from `start` differs from the from-rest run (the state matters)
    assert np.max(np.abs(got[start:] - model.simulate(u)[start:])) > 0.01 * scale


def test_best_arx_picks_the_lowest_free_run_error_and_the_true_orders():
    # `best_arx`'s criterion (the code): every (na, nb) in 1..max_order (4) fitted by
    # least squares, fits with a pole of modulus >= 1 dropped (`stable=True`), the lowest
    # mean squared free-run error from rest over the whole record chosen. On a record
    # of a known ARX(2, 2) with small noise, every fit missing a true lag has an error
    # far above the noise's, so the choice includes the truth: na >= 2 and nb >= 2.
    u, y = _record(noise=0.01)
    errors = {}
    for na in range(1, 5):
        for nb in range(1, 5):
            a, b, c, _ = least_squares(u, y, na, nb)
            if np.max(np.abs(np.roots(np.r_[1.0, a]))) >= 1:
                continue
            errors[na, nb] = np.mean((y - recursion(a, b, c, u)) ** 2)
    ranked = sorted(errors, key=errors.get)
    # the choice is well posed: the best two errors are not tied to rounding
    assert errors[ranked[1]] - errors[ranked[0]] > 1e-9 * errors[ranked[0]]
    best = best_arx(u, y)
    assert best.orders == ranked[0]
    assert best.orders[0] >= 2 and best.orders[1] >= 2
    a, b, c, _ = least_squares(u, y, *ranked[0])
    np.testing.assert_allclose(_theta(best.a, best.b, best.c), _theta(a, b, c), rtol=0, atol=1e-10)
    # the fits that miss a lag are far worse than the truth's noise floor
    floor = np.mean((y - recursion(A_TRUE, B_TRUE, C_TRUE, u)) ** 2)
    missing = [errors[o] for o in errors if o[0] < 2 or o[1] < 2]
    assert min(missing) > 10 * floor
    assert errors[ranked[0]] < 2 * floor
