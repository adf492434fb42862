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

from ._model import Orders
from ._status import Status

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
    o = orders
    vector = np.asarray(vector, dtype=float)
    bounds = np.cumsum([0, o.nR, o.nR - 1, o.nL, o.nL - 1, o.r - 1, o.p])
    parts = [vector[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:], strict=True)]
    return Parts(*parts, *vector[bounds[-1] : bounds[-1] + 3])


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
    sqrt(eps))). Returns `(theta, singular, cost)`; theta is zero when singular."""
    eps = np.finfo(phi.dtype).eps
    d = np.linalg.norm(phi, axis=0)
    zero = d <= d.max() * eps
    d = np.where(zero, 1.0, d)
    theta, _, _, sv = np.linalg.lstsq(phi / d, yc, rcond=None)
    singular = bool(zero.any() or sv[-1] <= sv[0] * 100 * np.sqrt(eps))
    theta = np.zeros_like(theta) if singular else theta / d
    return theta, singular, float(np.mean((yc - phi @ theta) ** 2))


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
    """The paper's first iteration (see `jaxcascade._estimate.first_step`)."""
    o = orders
    k = o.size - 3
    phi, yc = regression(init, o, u, y, u, y, unit_slopes=True)
    theta_init = init.copy()
    theta_init[-1] = init[-1] * init[-2]
    coef, singular, cost = solve(phi[:, :k], yc - phi[:, k:] @ theta_init[k:])
    vector = np.concatenate([coef, init[k:]])
    MR, DR = slice(0, o.nR), slice(o.nR, 2 * o.nR - 1)
    ML = slice(2 * o.nR - 1, 2 * o.nR - 1 + o.nL)
    DL = slice(ML.stop, ML.stop + o.nL - 1)
    vector[DR] = _safe_divide(vector[DR], vector[MR][1:])
    vector[DL] = _safe_divide(vector[DL], vector[ML][1:])
    return vector, singular, cost


def voros_step(vector: np.ndarray, orders: Orders, u, y):
    """One full iteration: v, x from the estimate, then the full regression."""
    v = pwl(vector, orders, u)
    x = linear_block(vector, orders, v)
    phi, yc = regression(vector, orders, u, y, v, x)
    theta, singular, cost = solve(phi, yc)
    with np.errstate(divide="ignore", invalid="ignore"):
        theta[-1] = theta[-1] / theta[-2]  # C = cR mR -> cR
    return theta, singular, cost


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


def voros(
    u,
    y,
    orders: Orders,
    init: np.ndarray | None = None,
    *,
    max_iterations: int = 50,
    tol: float = 1e-10,
    divergence_bound: float = 1e6,
) -> BaselineSolution:
    """The literal Vörös iteration in NumPy, with the stopping rules of `jaxcascade.voros`.

    `tol < 0` never reports convergence: exactly `max_iterations` steps unless one fails.
    """
    u, y = np.asarray(u, dtype=float), np.asarray(y, dtype=float)
    u_min, u_max = float(u.min()), float(u.max())
    start = initial_guess(orders, u_min, u_max) if init is None else np.asarray(init, float)

    def classify(new, singular):
        if singular:
            return Status.singular
        if not np.all(np.isfinite(new)) or np.max(np.abs(new)) > divergence_bound:
            return Status.diverged
        return _RUNNING if is_admissible(new, orders, u_min, u_max) else Status.left_domain

    new, singular, cost = first_step(start, orders, u, y)
    status = classify(new, singular)
    accepted = status == _RUNNING
    vector = new if accepted else start
    if accepted and max_iterations <= 1:
        status = Status.max_iterations
    k = int(accepted)
    history = np.tile(start, (max_iterations + 1, 1))
    history[1] = vector
    while status == _RUNNING:
        new, singular, new_cost = voros_step(vector, orders, u, y)
        status = classify(new, singular)
        if status != _RUNNING:
            break
        change = np.max(np.abs(new - vector))
        if change <= tol * (1 + np.max(np.abs(vector))):
            status = Status.converged
        elif k + 1 >= max_iterations:
            status = Status.max_iterations
        k, vector, cost = k + 1, new, new_cost
        history[k] = new
    history[k + 1 :] = vector
    return BaselineSolution(vector, history, k, cost, int(status))


def fit(rng: np.random.Generator, vector, orders: Orders, n: int, snr: float, iterations: int):
    """One realisation of the benchmark workload: simulate, add noise, `iterations` steps."""
    u, y = measure(rng, vector, orders, n, snr)
    return voros(u, y, orders, max_iterations=iterations, tol=-1.0)


def run(realisations: int, vector, orders: Orders, n: int, snr: float, iterations: int, seed=0):
    """Fit `realisations` records one after another; returns `(statuses, seconds)`."""
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    statuses = [fit(rng, vector, orders, n, snr, iterations).status for _ in range(realisations)]
    return np.array(statuses), time.perf_counter() - start
