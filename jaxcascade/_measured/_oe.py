"""Linear output-error model: the linear floor of the model-error loop (host side).

`y(t) = B(q) / F(q) u(t) + c + e(t)` with `B = b_1 q^-1 + .. + b_nb q^-nb` and
`F = 1 + f_1 q^-1 + .. + f_nf q^-nf`: what MATLAB's `oe` fits, with an output offset. It
is fitted by Levenberg-Marquardt on the free-run simulation error of every estimation
record (each simulated from rest), its Jacobian by filtering (`dy/db_j = q^-j u / F`,
`dy/df_i = -q^-i (B / F u) / F`), from the least-squares ARX fit of the same orders; a
pole that leaves the unit circle is reflected inside it (`_stabilised`). The orders are
chosen on the validation records (`linear_floor`): the pair `(nb, nf)` up to `MAX_ORDER`
whose free-run validation error is lowest.

The loop always considers this model: the cascade with one input segment a side of
equal slopes, the same linear block and no backlash gap is exactly it (`as_cascade`), so
it starts the declared fit where its orders fit inside the declared ones, competes as a
candidate in place of the cascade, and the final model is never worse on the validation
records than it (`_loop.model_error_loop`). Its test figures are the report's linear
peer, beside the ARX peer (`_arx`), as a practitioner builds both.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.signal

from ._arx import fit_arx

MAX_ORDER = 4
# a relative cost decrease below this ends the fit
_TOLERANCE = 1e-10
_MAX_STEPS = 100


@dataclasses.dataclass(frozen=True)
class OE:
    """A fitted output-error model: `b` (nb,), `f` (nf,), the output offset `c`."""

    b: np.ndarray
    f: np.ndarray
    c: float

    @property
    def orders(self) -> tuple[int, int]:
        return len(self.b), len(self.f)

    @property
    def largest_pole(self) -> float:
        return float(np.max(np.abs(np.roots(np.concatenate([[1.0], self.f])))))

    def simulate(self, u) -> np.ndarray:
        """Free-run output from rest."""
        u = np.asarray(u, float)
        return scipy.signal.lfilter(np.concatenate([[0.0], self.b]), self._den(), u) + self.c

    def _den(self) -> np.ndarray:
        return np.concatenate([[1.0], self.f])


# The largest reflection coefficient of `F` (Schur-Cohn): the cascade's refits hold the
# linear block's poles by reflection coefficients within 0.999 (`_estimator._refine`), so
# a floor inside this bound is a start they take as it is.
REFLECTION_BOUND = 0.9989


def _reflection(f: np.ndarray) -> np.ndarray:
    """Reflection coefficients `k_1..k_n` of `1 + f_1 q^-1 + ..` (step-down recursion;
    `_system._model.reflection_coefficients` on the host)."""
    poly = np.concatenate([[1.0], f])
    ks = []
    for m in range(len(f), 0, -1):
        k = poly[m]
        ks.append(k)
        poly = (poly[:m] - k * poly[m:0:-1]) / (1 - k**2 if abs(k) < 1 else 1.0)
    return np.array(ks[::-1])


def _step_up(k: np.ndarray) -> np.ndarray:
    """Inverse of `_reflection`."""
    poly = np.ones(1)
    for value in k:
        padded = np.concatenate([poly, [0.0]])
        poly = padded + value * padded[::-1]
    return poly[1:]


def _stabilised(f: np.ndarray) -> np.ndarray:
    """`F` with every root outside the unit circle reflected inside (`1 / conj(root)`),
    and its reflection coefficients within `REFLECTION_BOUND`."""
    if f.size == 0:
        return f
    roots = np.roots(np.concatenate([[1.0], f]))
    outside = np.abs(roots) >= 1
    if outside.any():
        roots = np.where(outside, 1 / np.conj(roots) * 0.999, roots)
        f = np.real(np.poly(roots))[1:]
    k = _reflection(f)
    if np.all(np.abs(k) <= REFLECTION_BOUND):
        return f
    return _step_up(np.clip(k, -REFLECTION_BOUND, REFLECTION_BOUND))


def _residuals_and_jacobian(theta, nb, nf, records, integrated=False):
    b, f, c = theta[:nb], theta[nb : nb + nf], theta[-1]
    den = np.concatenate([[1.0], f])
    num = np.concatenate([[0.0], b])
    rows, jac = [], []
    for u, y in records:
        x = scipy.signal.lfilter(num, den, u)
        uf = scipy.signal.lfilter([1.0], den, u)
        xf = scipy.signal.lfilter([1.0], den, x)
        columns = [np.concatenate([np.zeros(j), uf[:-j]]) for j in range(1, nb + 1)]
        columns += [-np.concatenate([np.zeros(i), xf[:-i]]) for i in range(1, nf + 1)]
        columns.append(np.ones_like(u))
        residual, columns = x + c - y, np.stack(columns, axis=1)
        if integrated:  # the errors of the output integrated back, from the record's start
            residual, columns = np.cumsum(residual), np.cumsum(columns, axis=0)
        rows.append(residual)
        jac.append(columns)
    return np.concatenate(rows), np.concatenate(jac)


def fit_oe(us, ys, nb: int, nf: int, integrated: bool = False) -> OE:
    """The output-error model of orders `(nb, nf)` on the records `us`, `ys` (sequences of
    1-D arrays, each simulated from rest), from the ARX fit on them joined. `integrated`:
    the outputs are differences of a measured output (`_integrating`), and the fit of the
    difference is then polished on the error of the output integrated back, as the
    loop's refits are."""
    records = [(np.asarray(u, float), np.asarray(y, float)) for u, y in zip(us, ys, strict=True)]
    arx = fit_arx(
        np.concatenate([r[0] for r in records]), np.concatenate([r[1] for r in records]), nf, nb
    )
    theta = np.concatenate([arx.b, _stabilised(arx.a), [0.0]])
    # the offset of the ARX fit, as an output offset: c / A(1)
    theta[-1] = arx.c / max(1e-6, abs(1 + np.sum(arx.a))) * np.sign(1 + np.sum(arx.a))
    theta = _levenberg_marquardt(theta, nb, nf, records, False)
    if integrated:  # polished on the output integrated back, from the difference's fit
        theta = _levenberg_marquardt(theta, nb, nf, records, True)
    return OE(theta[:nb], theta[nb : nb + nf], float(theta[-1]))


def _levenberg_marquardt(theta, nb, nf, records, integrated):
    """`theta` refined by Levenberg-Marquardt on the simulation error (Jacobi-scaled
    normal equations, the poles kept stable by reflection)."""
    residual, J = _residuals_and_jacobian(theta, nb, nf, records, integrated)
    cost, damping = float(residual @ residual), 1e-3
    for _ in range(_MAX_STEPS):
        g, H = J.T @ residual, J.T @ J
        scale = np.sqrt(np.diag(H)) + 1e-300
        Hs = H / scale[:, None] / scale[None, :]
        improved = False
        while damping < 1e10:
            step = -np.linalg.solve(Hs + damping * np.eye(len(theta)), g / scale) / scale
            trial = theta + step
            trial[nb : nb + nf] = _stabilised(trial[nb : nb + nf])
            r_trial, J_trial = _residuals_and_jacobian(trial, nb, nf, records, integrated)
            c_trial = float(r_trial @ r_trial)
            if np.isfinite(c_trial) and c_trial < cost:
                decrease = (cost - c_trial) / max(cost, 1e-300)
                theta, residual, J, cost = trial, r_trial, J_trial, c_trial
                damping = max(damping / 10, 1e-12)
                improved = True
                break
            damping *= 10
        if not improved or decrease < _TOLERANCE:
            break
    return theta


def validation_error(model: OE, u_vals, y_vals, skip: int = 0, integrating: bool = False):
    """The free-run NRMSE of `model` over the validation records joined (from rest, the
    first `skip` samples of each left out; of the output integrated back where
    `integrating`)."""
    sims, meas = [], []
    for u, y in zip(u_vals, y_vals, strict=True):
        y = np.asarray(y, float)
        s = model.simulate(u)
        if integrating:
            s, y = np.cumsum(s), np.cumsum(y)
        sims.append(s[skip:])
        meas.append(y[skip:])
    s, y = np.concatenate(sims), np.concatenate(meas)
    return float(np.sqrt(np.mean((s - y) ** 2)) / (np.std(y) + 1e-300))


def linear_floor(
    us, ys, u_vals, y_vals, *, skip: int = 0, integrating: bool = False, max_order: int = MAX_ORDER
):
    """The output-error model whose orders `(nb, nf)`, up to `max_order` each, give the
    lowest free-run validation error (`validation_error`), with that error: `(OE,
    error)`. Among orders within 0.1 % of the lowest error the fewest parameters win."""
    fits = []
    for nf in range(1, max_order + 1):
        for nb in range(1, max_order + 1):
            model = fit_oe(us, ys, nb, nf, integrating)
            if not model.largest_pole < 1:
                continue
            error = validation_error(model, u_vals, y_vals, skip, integrating)
            if np.isfinite(error):
                fits.append((error, nb + nf, model))
    if not fits:
        raise ValueError("No stable output-error model fits these records.")
    lowest = min(e for e, _, _ in fits)
    close = [f for f in fits if f[0] <= lowest * 1.001]
    best = min(close, key=lambda f: (f[1], f[0]))
    return best[2], best[0]


# The backlash gaps of the cascade form of a linear model: zero is on the edge of the
# refit's parameterisation (a softplus), so a gap this small stands for it.
GAP = 1e-8


def cascade_vector(model: OE, orders, breakpoints=None) -> np.ndarray | None:
    """The linear model as a parameter vector of the cascade of `orders` (`orders.names`):
    every input segment of slope `b_1`, the linear block `a_i = b_i / b_1` and `b = f`
    (zeros beyond), no backlash gap; None where the model does not fit inside `orders`
    or has no gain at lag 1 (the cascade's normalisation `a_1 = 1`). `breakpoints`:
    `{name: value}` of the cascade's breakpoints (default: spread over +-1)."""
    nb, nf = model.orders
    b = np.asarray(model.b, float)
    if nb > orders.r or nf > orders.p or not abs(b[0]) > 1e-6 * np.max(np.abs(b)):
        return None
    values = {"MR1": b[0], "ML1": b[0], "cL": GAP, "mR": 1.0, "cR": GAP}
    values.update({f"a{i}": b[i - 1] / b[0] for i in range(2, nb + 1)})
    values.update({f"b{j}": model.f[j - 1] for j in range(1, nf + 1)})
    for i in range(1, orders.nR):
        values[f"DR{i}"] = (breakpoints or {}).get(f"DR{i}", float(i))
    for i in range(1, orders.nL):
        values[f"DL{i}"] = (breakpoints or {}).get(f"DL{i}", -float(i))
    return np.array([float(values.get(name, 0.0)) for name in orders.names])
