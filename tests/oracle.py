"""Plain-NumPy reference for the cascade and the literal Vörös estimator (the test oracle).

Written from METHOD.md (Vörös 2016, eqs. 1-28) one sample at a time, with explicit
Python loops, so that each line can be checked against the paper by eye. It does not
import jaxcascade: the JAX code is tested against it, not the other way round.

Parameters are plain vectors (or `{name: value}` dicts) in the order of `names(orders)`:
MR1..MRnR, DR1..DR(nR-1), ML1..MLnL, DL1..DL(nL-1), a2..ar, b1..bp, cL, mR, cR.
`orders` is anything with attributes `nR, nL, r, p`, or a tuple `(nR, nL, r, p)`.
"""

from __future__ import annotations

import numpy as np


def h(s: float) -> float:
    """The paper's switching function: 1 if s < 0 else 0."""
    return 1.0 if s < 0 else 0.0


def _orders(orders) -> tuple[int, int, int, int]:
    if hasattr(orders, "nR"):
        return orders.nR, orders.nL, orders.r, orders.p
    nR, nL, r, p = orders
    return nR, nL, r, p


def names(orders) -> list[str]:
    nR, nL, r, p = _orders(orders)
    return (
        [f"MR{i}" for i in range(1, nR + 1)]
        + [f"DR{i}" for i in range(1, nR)]
        + [f"ML{j}" for j in range(1, nL + 1)]
        + [f"DL{j}" for j in range(1, nL)]
        + [f"a{i}" for i in range(2, r + 1)]
        + [f"b{j}" for j in range(1, p + 1)]
        + ["cL", "mR", "cR"]
    )


def unpack(vector, orders) -> dict:
    """Vector (or dict) -> dict of lists/floats: MR, DR, ML, DL, a (a2..ar), b, cL, mR, cR."""
    nR, nL, r, p = _orders(orders)
    if isinstance(vector, dict):
        vector = [vector[name] for name in names(orders)]
    vector = [float(value) for value in vector]
    assert len(vector) == len(names(orders))
    out, k = {}, 0
    for key, size in (("MR", nR), ("DR", nR - 1), ("ML", nL), ("DL", nL - 1), ("a", r - 1)):
        out[key] = vector[k : k + size]
        k += size
    out["b"] = vector[k : k + p]
    k += p
    out["cL"], out["mR"], out["cR"] = vector[k], vector[k + 1], vector[k + 2]
    return out


def pack(P: dict) -> np.ndarray:
    """Inverse of `unpack`."""
    return np.array(
        [*P["MR"], *P["DR"], *P["ML"], *P["DL"], *P["a"], *P["b"], P["cL"], P["mR"], P["cR"]]
    )


def past(signal, k: int) -> float:
    """signal(k), zero before the record starts (u = y = 0 for t <= 0)."""
    return float(signal[k]) if k >= 0 else 0.0


# ---- the three blocks ------------------------------------------------------------------


def pwl_sample(P: dict, u: float) -> float:
    """NS, eq. 1: v = sum_i MR_i h(DR_{i-1} - u)(u - DR_{i-1}) + sum_j ML_j h(u - DL_{j-1})(...)."""
    DR = [0.0, *P["DR"]]
    DL = [0.0, *P["DL"]]
    v = 0.0
    for i in range(len(P["MR"])):
        v += P["MR"][i] * h(DR[i] - u) * (u - DR[i])
    for j in range(len(P["ML"])):
        v += P["ML"][j] * h(u - DL[j]) * (u - DL[j])
    return v


def pwl(P: dict, u) -> np.ndarray:
    return np.array([pwl_sample(P, float(u_t)) for u_t in u])


def linear(P: dict, v) -> np.ndarray:
    """LD: x(t) = v(t-1) + sum_{i>=2} a_i v(t-i) - sum_j b_j x(t-j)."""
    a = [1.0, *P["a"]]  # a1 = 1 (normalisation)
    b = P["b"]
    x = np.zeros(len(v))
    for t in range(len(v)):
        total = 0.0
        for i in range(1, len(a) + 1):
            total += a[i - 1] * past(v, t - i)
        for j in range(1, len(b) + 1):
            total -= b[j - 1] * past(x, t - j)
        x[t] = total
    return x


def backlash(P: dict, x, y_prev: float = 0.0) -> np.ndarray:
    """ND, eq. 9 with mL = 1, from the output `y_prev` before the first sample (0: at
    rest); where both lines would switch, the left line wins."""
    cL, mR, cR = P["cL"], P["mR"], P["cR"]
    y = np.zeros(len(x))
    for t in range(len(x)):
        left = 1.0 * (x[t] + cL)
        right = mR * (x[t] - cR)
        if left < y_prev:
            y[t] = left
        elif y_prev < right:
            y[t] = right
        else:
            y[t] = y_prev
        y_prev = y[t]
    return y


def simulate(P: dict, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free (v, x, y)."""
    v = pwl(P, u)
    x = linear(P, v)
    return v, x, backlash(P, x)


# ---- the regression, eqs. 15-18 and 23-25 ----------------------------------------------


def switches(x_t: float, y_prev: float, cL: float, mR: float, cR: float) -> tuple[float, float]:
    """g1 = h(x + cL - y(t-1)), g2 = h((y(t-1) - mR x + mR cR) / mR), g2 cleared when g1."""
    g1 = h(x_t + cL - y_prev)
    g2 = 0.0 if g1 else h((y_prev - mR * x_t + mR * cR) / mR)
    return g1, g2


def regression_row(P: dict, t: int, u, y, v, x, unit_slopes: bool = False):
    """phi(t) (eq. 17) and yc(t) (eq. 25) for the estimates P."""
    nR, nL = len(P["MR"]), len(P["ML"])
    r, p = len(P["a"]) + 1, len(P["b"])
    DR = [0.0, *P["DR"]]
    DL = [0.0, *P["DL"]]
    MR = [1.0] * nR if unit_slopes else P["MR"]
    ML = [1.0] * nL if unit_slopes else P["ML"]
    u1 = past(u, t - 1)
    y_prev = past(y, t - 1)
    g1, g2 = switches(x[t], y_prev, P["cL"], P["mR"], P["cR"])
    yc = y[t] - y_prev * (1 - g1) * (1 - g2)

    row = []
    for i in range(1, nR + 1):  # h(DR_{i-1} - u1) u1 g1
        row.append(h(DR[i - 1] - u1) * u1 * g1)
    for i in range(2, nR + 1):  # -f1,i(t-1) g1, f1,i = MR_i h(DR_{i-1} - u)
        row.append(-MR[i - 1] * h(DR[i - 1] - u1) * g1)
    for j in range(1, nL + 1):  # h(u1 - DL_{j-1}) u1 g1
        row.append(h(u1 - DL[j - 1]) * u1 * g1)
    for j in range(2, nL + 1):  # -f2,j(t-1) g1, f2,j = ML_j h(u - DL_{j-1})
        row.append(-ML[j - 1] * h(u1 - DL[j - 1]) * g1)
    for i in range(2, r + 1):
        row.append(past(v, t - i) * g1)
    for j in range(1, p + 1):
        row.append(-past(x, t - j) * g1)
    row += [g1, x[t] * g2, -g2]
    return np.array(row), yc


def regression(P: dict, u, y, v, x, unit_slopes: bool = False):
    """(phi, yc) for the whole record, row by row."""
    rows, ycs = [], []
    for t in range(len(u)):
        row, yc = regression_row(P, t, u, y, v, x, unit_slopes)
        rows.append(row)
        ycs.append(yc)
    return np.array(rows), np.array(ycs)


def theta(P: dict) -> np.ndarray:
    """The paper's theta (eq. 18): the vector with C = cR mR in place of cR."""
    out = pack(P)
    out[-1] = P["cR"] * P["mR"]
    return out


# ---- the estimator, eqs. 19-28 ---------------------------------------------------------


def first_iteration(init: dict, u, y, reading: str = "full") -> dict:
    """v ~ u, x ~ y, unit slopes in f1, f2; only the NS and LD estimates are kept (the
    backlash keeps init); D coefficients / new M. The paper's text has three readings:

    - "full": least squares on every column of eq. 27;
    - "fixed": the backlash columns held at init, moved to the target;
    - "drop": the backlash columns left out.
    """
    phi, yc = regression(init, u, y, u, y, unit_slopes=True)
    held = theta(init)[-3:]  # cL, mR, C of the initial values
    if reading == "full":
        coef = np.linalg.lstsq(phi, yc, rcond=None)[0][:-3]
    elif reading == "fixed":
        coef = np.linalg.lstsq(phi[:, :-3], yc - phi[:, -3:] @ held, rcond=None)[0]
    elif reading == "drop":
        coef = np.linalg.lstsq(phi[:, :-3], yc, rcond=None)[0]
    else:
        raise ValueError(reading)
    new = unpack(np.concatenate([coef, pack(init)[-3:]]), _orders_of(init))
    # the breakpoint columns used unit slopes, so their coefficients are D_i * M_{i+1}
    new["DR"] = [new["DR"][i] / new["MR"][i + 1] for i in range(len(new["DR"]))]
    new["DL"] = [new["DL"][j] / new["ML"][j + 1] for j in range(len(new["DL"]))]
    return new


def full_iteration(P: dict, u, y) -> dict:
    """Steps a and b: v, x from the estimates, phi and yc, least squares for all of theta."""
    v = pwl(P, u)
    x = linear(P, v)
    phi, yc = regression(P, u, y, v, x)
    th = np.linalg.lstsq(phi, yc, rcond=None)[0]
    new = unpack(th, _orders_of(P))
    new["cR"] = th[-1] / th[-2]  # C = cR mR
    return new


def _orders_of(P: dict) -> tuple[int, int, int, int]:
    return len(P["MR"]), len(P["ML"]), len(P["a"]) + 1, len(P["b"])


def voros(u, y, orders, init, max_iterations: int = 50, reading: str = "full"):
    """The literal iteration for exactly `max_iterations` steps; returns the history.

    `history[k]` is iterate k as a vector (row 0 = init), or fewer rows if a step is
    non-finite (that step not kept). The stopping rules are tested on their own.
    """
    P = unpack(init, orders)
    history = [pack(P)]
    P = first_iteration(P, u, y, reading)
    if not np.all(np.isfinite(pack(P))):
        return np.array(history)
    history.append(pack(P))
    while len(history) - 1 < max_iterations:
        new = full_iteration(P, u, y)
        if not np.all(np.isfinite(pack(new))):
            break
        history.append(pack(new))
        P = new
    return np.array(history)


# ---- random systems for the tests ------------------------------------------------------


def random_system(rng: np.random.Generator, orders) -> np.ndarray:
    """A parameter vector drawn from the tests' prior (for an input uniform in (-2, 2)).

    Slope increments |M| in [0.2, 1.5] with random signs; DR1 in [0.3, 1.5] and
    DL1 in [-1.5, -0.3], further breakpoints 0.2-0.4 apart (so all inside (-2, 2) for
    up to 3 segments); a2..ar in [-0.4, 0.4]; poles of the linear block with radius
    below 0.7 (a complex pair or real); mR in [0.6, 1.5]; cL, cR in [0.05, 0.5].
    """
    nR, nL, r, p = _orders(orders)
    assert nR <= 3 and nL <= 3

    def slopes(n):
        return list(rng.uniform(0.2, 1.5, n) * rng.choice([-1.0, 1.0], n))

    def breakpoints(n):
        points = [rng.uniform(0.3, 1.5)] if n else []
        while len(points) < n:
            points.append(points[-1] + rng.uniform(0.2, 0.4))
        return points

    poles = []
    while len(poles) < p:
        if p - len(poles) >= 2 and rng.uniform() < 0.5:
            pole = rng.uniform(0.0, 0.7) * np.exp(1j * rng.uniform(0.0, np.pi))
            poles += [pole, np.conj(pole)]
        else:
            poles.append(rng.uniform(-0.7, 0.7))
    b = list(np.real(np.poly(poles))[1:]) if p else []
    P = {
        "MR": slopes(nR),
        "DR": breakpoints(nR - 1),
        "ML": slopes(nL),
        "DL": [-d for d in breakpoints(nL - 1)],
        "a": list(rng.uniform(-0.4, 0.4, r - 1)),
        "b": b,
        "cL": rng.uniform(0.05, 0.5),
        "mR": rng.uniform(0.6, 1.5),
        "cR": rng.uniform(0.05, 0.5),
    }
    return pack(P)


def identifiable_system(rng: np.random.Generator, orders, u, max_cond: float = 1e4):
    """`random_system` conditioned on the record identifying it.

    Some draws never excite a regime (e.g. the left backlash line only ever active
    on one input segment), which makes the regression rank-deficient at the truth.
    Redraw until the column-scaled regressor matrix at the true parameters has
    condition number below `max_cond`. Returns `(vector, (v, x, y))`.
    """
    for _ in range(100):
        vector = random_system(rng, orders)
        P = unpack(vector, orders)
        v, x, y = simulate(P, u)
        phi, _ = regression(P, u, y, v, x)
        norms = np.linalg.norm(phi, axis=0)
        if np.all(norms > 0) and np.linalg.cond(phi / norms) < max_cond:
            return vector, (v, x, y)
    raise RuntimeError("no identifiable system in 100 draws")
