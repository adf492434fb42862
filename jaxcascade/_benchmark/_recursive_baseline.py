"""A plain NumPy loop of the recursive estimator (`jaxcascade.recursive`): the speed
baseline of `jaxcascade bench --estimator recursive` and an oracle for the JAX scan.

One sample after another, as a user without JAX would write it: the regressor row of
eqs. 17 and 23-25 built from the current estimate (the same window of past signals),
then the recursive least-squares update of each block where it is active, with the same
forgetting schedule, anti-windup variants, projection and on-line first iteration
(`_estimator._recursive`'s docstring says what each step is). Vectors are in
`Orders.names` order; theta (eq. 18) ends in `C = cR mR`, and the recursion holds the
breakpoint coefficients as `D M` (unit slopes in their columns).
"""

from __future__ import annotations

import time

import numpy as np

from .._system._model import Orders
from ._baseline import initial_guess, is_admissible, measure, unpack


def _vector(theta: np.ndarray) -> np.ndarray:
    out = theta.copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        out[-1] = theta[-1] / theta[-2]
    return out


def _params(theta: np.ndarray) -> np.ndarray:
    out = theta.copy()
    mR = theta[-2] if theta[-2] != 0 else np.finfo(float).eps
    out[-1] = theta[-1] / mR
    return out


def _model(theta, init_theta, o: Orders):
    """Breakpoint coefficients `D M` -> `D` (a zero slope keeps the initial breakpoint)."""
    out = theta.copy()
    s = o.slices
    for D, M in (("DR", "MR"), ("DL", "ML")):
        for i in range(s[D].stop - s[D].start):
            slope = theta[s[M].start + 1 + i]
            ratio = theta[s[D].start + i] / slope if slope != 0 else np.inf
            out[s[D].start + i] = ratio if np.isfinite(ratio) else init_theta[s[D].start + i]
    return out


def _pwl(p, u: float) -> float:
    v = 0.0
    for M, D in zip(p.MR, np.concatenate([[0.0], p.DR]), strict=True):
        v += M * (u - D) if u > D else 0.0
    for M, D in zip(p.ML, np.concatenate([[0.0], p.DL]), strict=True):
        v += M * (u - D) if u < D else 0.0
    return v


def _row(p, o: Orders, u1, y_t, y_prev, v_past, x_t, x_past, unit_slopes):
    """phi(t), yc(t), g1, g2 (eqs. 17, 23-25); v_past[i] = v(t-i), x_past[j] = x(t-j)."""
    g1 = 1.0 if x_t + p.cL - y_prev < 0 else 0.0
    g2 = 0.0 if g1 else (1.0 if (y_prev - p.mR * x_t + p.mR * p.cR) / p.mR < 0 else 0.0)
    yc = y_t - y_prev * (1 - g1) * (1 - g2)
    DR, DL = np.concatenate([[0.0], p.DR]), np.concatenate([[0.0], p.DL])
    MR = np.ones(o.nR) if unit_slopes else p.MR
    ML = np.ones(o.nL) if unit_slopes else p.ML
    row = [u1 * g1 if u1 > D else 0.0 for D in DR]
    row += [-MR[i] * g1 if u1 > DR[i] else 0.0 for i in range(1, o.nR)]
    row += [u1 * g1 if u1 < D else 0.0 for D in DL]
    row += [-ML[j] * g1 if u1 < DL[j] else 0.0 for j in range(1, o.nL)]
    row += [v_past[i] * g1 for i in range(2, o.r + 1)]
    row += [-x_past[j] * g1 for j in range(1, o.p + 1)]
    row += [g1, x_t * g2, -g2]
    return np.array(row), yc, g1, g2


def _update(theta, P, phi, error, lam, anti_windup, trace_max):
    Pphi = P @ phi
    r = phi @ Pphi
    if anti_windup == "directional":
        beta = 1.0 - (1.0 - lam) / r if r > 0 else 1.0
        gain = Pphi / (1.0 + beta * r)
        P = P - beta * np.outer(gain, Pphi)
    else:
        gain = Pphi / (lam + r)
        P = (P - np.outer(gain, Pphi)) / lam
        if anti_windup == "trace":
            P = P * min(1.0, trace_max / np.trace(P))
    return theta + gain * error, 0.5 * (P + P.T)


def recursive(
    u,
    y,
    orders: Orders,
    *,
    lam=1.0,
    memory0=10.0,
    growth=0.1,
    acceleration=3e-4,
    first_samples=400,
    anti_windup="none",
    delta=1e3,
    project=True,
    input_range=None,
    init=None,
) -> np.ndarray:
    """The final estimate (`Orders.names` order) of one pass over the record; `init` a
    vector of initial values (default the paper's, `_baseline.initial_guess`)."""
    o = orders
    u, y = np.asarray(u, float), np.asarray(y, float)
    u_min, u_max = (u.min(), u.max()) if input_range is None else input_range
    init = initial_guess(o, u_min, u_max) if init is None else np.asarray(init, float)
    init_theta = init.copy()
    init_theta[-1] = init[-1] * init[-2]
    first_parts = unpack(np.where(_is_slope(o), 1.0, init), o)
    b1 = o.g1_columns
    theta = init_theta.copy()  # the breakpoint coefficients are D M throughout
    for D, M in (("DR", "MR"), ("DL", "ML")):
        theta[o.slices[D]] = init_theta[o.slices[D]] * init_theta[o.slices[M]][1:]
    P1, P2 = delta * np.eye(b1), delta * np.eye(2)
    lags = max(o.r, o.p, 1)
    x = np.zeros(len(u))
    for t in range(len(u)):
        first = t < first_samples
        if t == first_samples and first_samples > 0:
            P2 = delta * np.eye(2)
            theta = np.concatenate([theta[o.static_dynamic], init_theta[o.backlash]])
            theta = _hold(theta, theta, init_theta, o, u_min, u_max, init_theta)
            x[max(t - lags, 0) : t] = y[max(t - lags, 0) : t]  # x ~ y before the switch
        p = unpack(_params(_model(theta, init_theta, o)), o)

        def past(signal, lag, t=t):
            return signal[t - lag] if t - lag >= 0 else 0.0

        if first:
            v_past = [past(u, i) for i in range(o.r + 1)]
            x_t, x_past = y[t], [past(y, j) for j in range(o.p + 1)]
            parts = first_parts
        else:
            v_past = [_pwl(p, past(u, i)) if t - i >= 0 else 0.0 for i in range(o.r + 1)]
            x_t = sum((1.0 if i == 1 else p.a[i - 2]) * v_past[i] for i in range(1, o.r + 1)) - sum(
                p.b[j - 1] * past(x, j) for j in range(1, o.p + 1)
            )
            x_past = [past(x, j) for j in range(o.p + 1)]
            parts = p
        x[t] = x_t
        phi, yc, g1, g2 = _row(
            parts, o, past(u, 1), y[t], past(y, 1), v_past, x_t, x_past, unit_slopes=True
        )
        error = yc - phi @ theta
        k = t - first_samples
        memory = memory0 + growth * k + acceleration * k * k
        lam_t = 1.0 if first else min(lam, 1.0 - 1.0 / memory)
        new, new_P1, new_P2 = theta.copy(), P1, P2
        trace_max = delta * o.size
        if g1 > 0:
            new[:b1], new_P1 = _update(
                theta[:b1], P1, phi[:b1], error, lam_t, anti_windup, trace_max
            )
        if g2 > 0:
            new[b1:], new_P2 = _update(
                theta[b1:], P2, phi[b1:], error, lam_t, anti_windup, trace_max
            )
        if project and not first:
            new = _hold(new, theta, init_theta, o, u_min, u_max)
        model = _params(_model(new, init_theta, o))
        if first or not project or is_admissible(model, o, u_min, u_max):
            theta, P1, P2 = new, new_P1, new_P2
    return _vector(_model(theta, init_theta, o))


def _hold(new, theta, init_theta, o: Orders, u_min, u_max, fallback=None):
    """`new` with each breakpoint that is not inside the input range on its side of 0, in
    order (and every one after it), put back where it is in `theta` (or at `fallback`,
    the initial values), its `D M` with the new slope."""
    D_new, D_old = _model(new, init_theta, o), _model(theta, init_theta, o)
    if fallback is not None:
        D_old = fallback
    out = new.copy()
    for name, M, outward, edge in (("DR", "MR", 1.0, u_max), ("DL", "ML", -1.0, u_min)):
        s, slope = o.slices[name], new[o.slices[M]][1:]
        previous, ok = 0.0, True
        for i, d in enumerate(D_new[s]):
            ok = ok and outward * (d - previous) > 0 and outward * (edge - d) > 0
            out[s.start + i] = (d if ok else D_old[s.start + i]) * slope[i]
            previous = d
    return out


def _is_slope(o: Orders) -> np.ndarray:
    mask = np.zeros(o.size, bool)
    mask[o.slices["MR"]] = True
    mask[o.slices["ML"]] = True
    return mask


def run(realisations: int, vector, orders: Orders, n: int, snr: float, seed=0, **settings):
    """Simulate and fit `realisations` records one after another; returns `(seconds,
    estimates)` for the fits alone (the simulation is not timed)."""
    rng = np.random.default_rng(seed)
    records = [measure(rng, vector, orders, n, snr) for _ in range(realisations)]
    start = time.perf_counter()
    estimates = [recursive(u, y, orders, **settings) for u, y in records]
    return time.perf_counter() - start, np.array(estimates)
