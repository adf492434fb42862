"""A plain NumPy/SciPy implementation of the simulation and the literal Vörös iteration.

This is what a careful user would write without JAX: one realisation after another,
`scipy.signal.lfilter` for the linear block, vectorised NumPy for the piecewise-linear
block and the regressors, `numpy.linalg.lstsq` for each least-squares step. It is the
baseline of the benchmark (issue 6) and an oracle for `voros`: it follows the same
algorithm step by step (first iteration as in the paper, then full iterations, the same
stopping rules and status codes), on parameter vectors in `Orders.names` order.

The backlash is sequential. Without a compiler the honest fast version is a vectorised
parallel-prefix scan: while the two backlash lines do not cross over the record
(`mR (x - cR) <= x + cL`), one step is the clamp `y -> min(max(y, lo), hi)`, clamps compose
into clamps, and the composition of all steps up to t takes log2(T) vectorised passes.
Where the lines cross the plain Python loop is used.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np
from scipy.signal import lfilter

from .._status import Status
from .._system._model import Orders

_RUNNING = -1


class Parts(NamedTuple):
    MR: np.ndarray
    DR: np.ndarray
    ML: np.ndarray
    DL: np.ndarray
    a: np.ndarray
    b: np.ndarray
    cL: float
    mR: float
    cR: float


def unpack(vector, orders: Orders) -> Parts:
    """Split a vector in `Orders.names` order (ending in `cR`) into named parts."""
    vector = np.asarray(vector, dtype=float)
    slices = orders.slices
    arrays = [vector[slices[field]] for field in Parts._fields[:6]]
    return Parts(*arrays, *(float(vector[slices[field]][0]) for field in Parts._fields[6:]))


def shift(signal: np.ndarray, lag: int) -> np.ndarray:
    """`signal(t - lag)` with zeros before the record starts."""
    out = np.zeros_like(signal)
    out[lag:] = signal[: len(signal) - lag]
    return out


def pwl(vector, orders: Orders, u: np.ndarray) -> np.ndarray:
    """Piecewise-linear block NS (eq. 1)."""
    p = unpack(vector, orders)
    DR = np.concatenate([[0.0], p.DR])
    DL = np.concatenate([[0.0], p.DL])
    v = np.zeros_like(u)
    for M, D in zip(p.MR, DR, strict=True):
        v += M * np.where(u > D, u - D, 0.0)
    for M, D in zip(p.ML, DL, strict=True):
        v += M * np.where(u < D, u - D, 0.0)
    return v


def linear_block(vector, orders: Orders, v: np.ndarray) -> np.ndarray:
    """Linear block LD (eq. 6, a1 = 1) with zero initial conditions."""
    p = unpack(vector, orders)
    return lfilter(np.concatenate([[0.0, 1.0], p.a]), np.concatenate([[1.0], p.b]), v)


def backlash_loop(x: np.ndarray, cL: float, mR: float, cR: float) -> np.ndarray:
    """Backlash ND (eq. 9) as a plain Python loop, with the switching rule of the JAX code."""
    y = np.empty_like(x)
    prev, mRcR = 0.0, mR * cR
    for t, x_t in enumerate(x.tolist()):
        if x_t + cL - prev < 0:  # g1: left line
            prev = x_t + cL
        elif (prev - mR * x_t + mRcR) / mR < 0:  # g2: right line
            prev = mR * (x_t - cR)
        y[t] = prev
    return y


def backlash_scan(x: np.ndarray, cL: float, mR: float, cR: float) -> np.ndarray:
    """Backlash ND (eq. 9) by a vectorised prefix scan of clamps (see the module docstring)."""
    lo, hi = mR * (x - cR), x + cL
    if np.any(lo > hi):  # the lines cross: a step is no longer a clamp
        return backlash_loop(x, cL, mR, cR)
    lo, hi = lo.copy(), hi.copy()
    step = 1
    while step < len(x):  # Hillis-Steele: step t becomes (steps t-step+1..t) composed
        first_lo, first_hi = lo[:-step], hi[:-step]
        then_lo, then_hi = lo[step:], hi[step:]
        new_lo = np.minimum(np.maximum(first_lo, then_lo), then_hi)
        new_hi = np.minimum(np.maximum(first_hi, then_lo), then_hi)
        lo[step:], hi[step:] = new_lo, new_hi
        step *= 2
    return np.minimum(np.maximum(0.0, lo), hi)


def simulate(vector, orders: Orders, u: np.ndarray, *, backlash: str = "scan") -> np.ndarray:
    """Noise-free output y of the cascade; `backlash` is `"scan"` or `"loop"`."""
    p = unpack(vector, orders)
    x = linear_block(vector, orders, pwl(vector, orders, u))
    run = backlash_scan if backlash == "scan" else backlash_loop
    return run(x, p.cL, p.mR, p.cR)


def measure(rng: np.random.Generator, vector, orders: Orders, n: int, snr: float, amplitude=2.0):
    """A uniform input in (-amplitude, amplitude) and the output with noise at SNR (std ratio)."""
    u = rng.uniform(-amplitude, amplitude, n)
    y = simulate(vector, orders, u)
    return u, y + y.std() / snr * rng.standard_normal(n)


def regression(vector, orders: Orders, u, y, v, x, *, unit_slopes: bool = False):
    """Regressors `phi` (T x P, theta order) and corrected output `yc` (eqs. 15-18, 23-25)."""
    o, p = orders, unpack(vector, orders)
    y_prev = shift(y, 1)
    g1 = (x + p.cL - y_prev < 0).astype(float)
    g2 = ((y_prev - p.mR * x + p.mR * p.cR) / p.mR < 0) * (1 - g1)
    yc = y - y_prev * (1 - g1) * (1 - g2)
    u1 = shift(u, 1)[:, None]
    right = (u1 > np.concatenate([[0.0], p.DR])).astype(float)  # h(DR_{i-1} - u(t-1))
    left = (u1 < np.concatenate([[0.0], p.DL])).astype(float)  # h(u(t-1) - DL_{j-1})
    MR = np.ones(o.nR) if unit_slopes else p.MR
    ML = np.ones(o.nL) if unit_slopes else p.ML
    columns = [right * u1, -MR[1:] * right[:, 1:], left * u1, -ML[1:] * left[:, 1:]]
    columns += [shift(v, i)[:, None] for i in range(2, o.r + 1)]
    columns += [-shift(x, j)[:, None] for j in range(1, o.p + 1)]
    ns_ld = np.concatenate(columns, axis=1) * g1[:, None]
    phi = np.concatenate([ns_ld, np.stack([g1, x * g2, -g2], axis=1)], axis=1)
    return phi, yc


def solve(phi: np.ndarray, yc: np.ndarray):
    """`argmin |yc - phi theta|` by `lstsq` on unit-norm columns, with the singularity rule
    of the JAX code (a zero column, or cond(Gram) > 1/(1e4 eps), i.e. cond(phi) > 1/(100
    sqrt(eps))). Returns `(theta, singular, cost, inverse_diagonal)`. A singular problem
    gets the JAX code's solution (`_regression.solve_gram`): a ridge of `1e-8 max(d)^2`
    on the unscaled diagonal, close to the minimum-norm solution; `inverse_diagonal` is
    `diag((phi^T phi)^-1)` (of the regularised system when singular)."""
    if not (np.all(np.isfinite(phi)) and np.all(np.isfinite(yc))):  # an overflowed record
        nan = np.full(phi.shape[1], np.nan)
        return nan, True, float("inf"), nan
    eps = np.finfo(phi.dtype).eps
    d = np.linalg.norm(phi, axis=0)
    zero = d <= d.max() * eps
    d = np.where(zero, 1.0, d)
    scaled = phi / d
    theta, _, _, sv = np.linalg.lstsq(scaled, yc, rcond=None)
    singular = bool(zero.any() or sv[-1] <= sv[0] * 100 * np.sqrt(eps))
    if singular:  # the JAX code's ridge: 1e-8 max(d)^2 / d_i^2 on the scaled diagonal
        gram = scaled.T @ scaled
        gram[zero, :] = 0.0
        gram[:, zero] = 0.0
        gram[zero, zero] = 1.0
        ridged = gram + np.diag(1e-8 * (d.max() / d) ** 2)
        theta = np.linalg.solve(ridged, np.where(zero, 0.0, scaled.T @ yc)) / d
        inverse = np.diag(np.linalg.inv(ridged)) / d**2
    else:
        theta = theta / d
        inverse = np.diag(np.linalg.inv(scaled.T @ scaled)) / d**2
    return theta, singular, float(np.mean((yc - phi @ theta) ** 2)), inverse


def initial_guess(orders: Orders, u_min: float, u_max: float) -> np.ndarray:
    """The paper's initial values (as `jaxcascade.initial_guess`), as a vector."""
    o = orders
    return np.concatenate(
        [
            np.zeros(o.nR),
            np.arange(1, o.nR) * u_max / o.nR,
            np.zeros(o.nL),
            np.arange(1, o.nL) * u_min / o.nL,
            np.zeros(o.r - 1 + o.p),
            [0.001, 0.5, 0.001],
        ]
    )


def _safe_divide(num, den):
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den != 0, num / np.where(den != 0, den, 1.0), np.inf)


def first_step(init: np.ndarray, orders: Orders, u, y):
    """The paper's first iteration, the `"full"` reading (`jaxcascade.voros`): the whole
    regression with v ~ u, x ~ y; only the NS and LD estimates are kept."""
    o = orders
    k = o.static_dynamic.stop
    phi, yc = regression(init, o, u, y, u, y, unit_slopes=True)
    g1 = o.g1_columns  # block 1: the NS, LD and cL columns (they carry g1)
    theta1, singular, _, _ = solve(phi[:, :g1], yc)
    theta2, _, _, _ = solve(phi[:, g1:], yc)
    theta = np.concatenate([theta1, theta2])
    cost = float(np.mean((yc - phi @ theta) ** 2))
    vector = np.concatenate([theta1[:k], init[k:]])
    s = o.slices
    MR, DR, ML, DL = s["MR"], s["DR"], s["ML"], s["DL"]
    vector[DR] = _safe_divide(vector[DR], vector[MR][1:])
    vector[DL] = _safe_divide(vector[DL], vector[ML][1:])
    return vector, singular, cost


def voros_step(vector: np.ndarray, orders: Orders, u, y):
    """One full iteration: v, x from the estimate, then the full regression (its two
    blocks, which have disjoint supports, solved apart). Returns `(vector, singular,
    cost, standard_errors)`, the standard errors of theta (eq. 18 order). An estimate
    with an unstable linear block overflows: the result is then non-finite (diverged),
    as in the JAX code, without warnings."""
    with np.errstate(all="ignore"):
        return _voros_step(vector, orders, u, y)


def _voros_step(vector: np.ndarray, orders: Orders, u, y):
    v = pwl(vector, orders, u)
    x = linear_block(vector, orders, v)
    phi, yc = regression(vector, orders, u, y, v, x)
    k = orders.g1_columns
    theta1, singular1, _, inverse1 = solve(phi[:, :k], yc)
    theta2, singular2, _, inverse2 = solve(phi[:, k:], yc)
    theta = np.concatenate([theta1, theta2])
    cost = float(np.mean((yc - phi @ theta) ** 2))
    n = len(u)
    se = np.sqrt(
        np.maximum(cost * n / max(n - orders.size, 1) * np.concatenate([inverse1, inverse2]), 0)
    )
    new = theta.copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        new[-1] = theta[-1] / theta[-2]  # C = cR mR -> cR
    return new, singular1 or singular2, cost, se


def _theta(vector: np.ndarray) -> np.ndarray:
    out = np.array(vector, dtype=float)
    out[..., -1] = out[..., -1] * out[..., -2]
    return out


def is_stable(b: np.ndarray) -> bool:
    """Schur-Cohn test of `1 + b1 q^-1 + ... + bp q^-p` (as `jaxcascade.is_stable`)."""
    poly = np.concatenate([[1.0], b])
    for m in range(len(b), 0, -1):
        k = poly[m]
        if not abs(k) < 1:
            return False
        poly = (poly[:m] - k * poly[m:0:-1]) / (1 - k**2)
    return True


def is_admissible(vector, orders: Orders, u_min: float, u_max: float) -> bool:
    p = unpack(vector, orders)
    ok = bool(np.all(np.isfinite(vector))) and p.mR > 0 and is_stable(p.b)
    if orders.nR > 1:
        ok = ok and p.DR[0] > 0 and np.all(np.diff(p.DR) > 0) and p.DR[-1] < u_max
    if orders.nL > 1:
        ok = ok and p.DL[0] < 0 and np.all(np.diff(p.DL) < 0) and p.DL[-1] > u_min
    return bool(ok)


class BaselineSolution(NamedTuple):
    """As `jaxcascade.Solution`, with the estimate as a vector in `Orders.names` order."""

    vector: np.ndarray
    history: np.ndarray
    iterations: int
    cost: float
    status: int
    cycle_amplitude: float


def voros(
    u,
    y,
    orders: Orders,
    init: np.ndarray | None = None,
    *,
    max_iterations: int = 50,
    tol: float = 1e-8,
    se_tol: float = 1e-3,
    cost_tol: float = 1e-12,
    cycle_period: int = 16,
    divergence_bound: float = 1e6,
) -> BaselineSolution:
    """The literal Vörös iteration in NumPy, with the stopping rules of `jaxcascade.voros`
    (default first step, no domain stop): converged, cycled, max_iterations, diverged;
    singular or left_domain judged on the final estimate.

    Negative tolerances never stop early: exactly `max_iterations` steps unless one
    diverges.
    """
    u, y = np.asarray(u, dtype=float), np.asarray(y, dtype=float)
    u_min, u_max = float(u.min()), float(u.max())
    start = initial_guess(orders, u_min, u_max) if init is None else np.asarray(init, float)

    def diverged(new, singular):
        if not np.all(np.isfinite(new)) or np.max(np.abs(new)) > divergence_bound:
            return Status.singular if singular else Status.diverged
        return None

    new, singular, cost = first_step(start, orders, u, y)
    status, amplitude = _RUNNING, 0.0
    if diverged(new, singular) is not None:
        status, vector, k = diverged(new, singular), start, 0
    else:
        vector, k = new, 1
        if max_iterations <= 1:
            status = Status.max_iterations
    history = np.tile(start, (max_iterations + 1, 1))
    history[1] = vector
    while status == _RUNNING:
        new, new_singular, new_cost, se = voros_step(vector, orders, u, y)
        if diverged(new, new_singular) is not None:
            status = diverged(new, new_singular)
            break
        theta_new = _theta(new)
        tolerance = se_tol * se + tol * (1 + np.abs(theta_new))
        converged = bool(np.all(np.abs(theta_new - _theta(vector)) <= tolerance))
        converged = converged or (
            cost_tol >= 0 and cost > 0 and abs(new_cost - cost) <= cost_tol * cost
        )
        period = 0
        if not converged:
            for j in range(2, cycle_period + 1):
                if k + 1 - j >= 1 and np.all(
                    np.abs(theta_new - _theta(history[k + 1 - j])) <= tolerance
                ):
                    period = j
                    break
        k, vector, cost, singular = k + 1, new, new_cost, new_singular
        history[k] = new
        if converged:
            status = Status.converged
        elif period:
            status = Status.cycled
            cycle = history[k + 1 - period : k + 1]
            amplitude = float(np.max(cycle.max(axis=0) - cycle.min(axis=0)))
        elif k >= max_iterations:
            status = Status.max_iterations
    if status in (Status.converged, Status.cycled, Status.max_iterations):
        if singular:
            status = Status.singular
        if not is_admissible(vector, orders, u_min, u_max):
            status = Status.left_domain
    history[k + 1 :] = vector
    return BaselineSolution(vector, history, k, cost, int(status), amplitude)


def fit(rng: np.random.Generator, vector, orders: Orders, n: int, snr: float, iterations: int):
    """One realisation of the benchmark workload: simulate, add noise, `iterations` steps."""
    u, y = measure(rng, vector, orders, n, snr)
    return voros(u, y, orders, max_iterations=iterations, tol=-1.0, se_tol=-1.0, cost_tol=-1.0)


def run(realisations: int, vector, orders: Orders, n: int, snr: float, iterations: int, seed=0):
    """Fit `realisations` records one after another; returns `(statuses, seconds)`."""
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    statuses = [fit(rng, vector, orders, n, snr, iterations).status for _ in range(realisations)]
    return np.array(statuses), time.perf_counter() - start
