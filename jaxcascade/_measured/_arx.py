"""Linear ARX model: the simplest peer the cascade is compared with on measured data.

`A(q) y(t) = B(q) u(t) + c + e(t)` with `A = 1 + a1 q^-1 + ... + a_na q^-na` and
`B = b1 q^-1 + ... + b_nb q^-nb`, fitted by least squares on the one-step equation error;
the orders are chosen by the free-run simulation error on the estimation record
(host side, numpy/scipy).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.signal


@dataclasses.dataclass(frozen=True)
class ARX:
    a: np.ndarray  # (na,)
    b: np.ndarray  # (nb,)
    c: float

    def simulate(self, u, y=None, start: int = 0) -> np.ndarray:
        """Free-run simulation from rest; with the measured output `y`, its samples before
        `start` set the model's state (its past outputs) and the simulation runs free
        from `start` on (the samples before it are `y`'s)."""
        u = np.asarray(u, float)
        if y is not None and start > 0:
            out = np.array(y, float, copy=True)
            na, nb = len(self.a), len(self.b)
            for t in range(start, len(u)):
                past_y = (
                    out[t - na : t][::-1] if t >= na else np.r_[out[:t][::-1], np.zeros(na - t)]
                )
                past_u = u[t - nb : t][::-1] if t >= nb else np.r_[u[:t][::-1], np.zeros(nb - t)]
                out[t] = -self.a @ past_y + self.b @ past_u + self.c
            return out
        den = np.concatenate([[1.0], self.a])
        num = np.concatenate([[0.0], self.b])
        return scipy.signal.lfilter(num, den, u) + scipy.signal.lfilter(
            [self.c], den, np.ones_like(u)
        )

    @property
    def orders(self) -> tuple[int, int]:
        return len(self.a), len(self.b)

    @property
    def largest_pole(self) -> float:
        """The largest pole magnitude of `1 / A(q)` (1 or more: not stable)."""
        return float(np.max(np.abs(np.roots(np.concatenate([[1.0], self.a])))))


def fit_arx(u, y, na: int, nb: int) -> ARX:
    """Least-squares ARX fit of orders `(na, nb)` with a constant term."""
    u, y = np.asarray(u, float), np.asarray(y, float)
    start = max(na, nb)
    rows = len(y) - start
    columns = [-y[start - i : start - i + rows] for i in range(1, na + 1)]
    columns += [u[start - j : start - j + rows] for j in range(1, nb + 1)]
    columns.append(np.ones(rows))
    theta, *_ = np.linalg.lstsq(np.stack(columns, axis=1), y[start:], rcond=None)
    return ARX(theta[:na], theta[na : na + nb], float(theta[-1]))


def best_arx(u, y, max_order: int = 4, stable: bool = True) -> ARX:
    """The ARX orders up to `max_order` with the lowest free-run error on `(u, y)`,
    among the stable fits (`stable`; a `ValueError` when none is), or among every fit
    whose free-run error is finite (`stable=False`: the peer of an output that integrates
    its input, whose equation-error fits all have a pole on the unit circle)."""
    best, best_error = None, np.inf
    for na in range(1, max_order + 1):
        for nb in range(1, max_order + 1):
            model = fit_arx(u, y, na, nb)
            if stable and model.largest_pole >= 1:
                continue
            with np.errstate(over="ignore", invalid="ignore"):
                error = np.mean((y - model.simulate(u)) ** 2)
            if np.isfinite(error) and error < best_error:
                best, best_error = model, error
    if best is None:
        kind = "stable " if stable else ""
        raise ValueError(f"No {kind}ARX model up to order {max_order} fits this record.")
    return best


def arx_peer(u, y) -> tuple[ARX, float | None]:
    """The loop's linear peer of the estimation records `(u, y)` joined end to end:
    `best_arx`, and None; where every equation-error fit has a pole on or outside the
    unit circle (an output that integrates, with `--integrate no`), the best finite one
    and its largest pole."""
    try:
        return best_arx(u, y), None
    except ValueError:
        arx = best_arx(u, y, stable=False)
        return arx, arx.largest_pole
