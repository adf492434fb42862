"""Plain-NumPy cascade continued from a given state (the oracle of the initial-state fit).

`oracle.py` simulates from rest (`u = y = 0` for `t <= 0`); here the same three blocks,
one sample at a time, start from the state before the record's first sample:

- `v_past = (v(-1), ..., v(-r))` and `x_past = (x(-1), ..., x(-p))`, newest first: the
  linear block `x(t) = v(t-1) + sum_{i>=2} a_i v(t-i) - sum_j b_j x(t-j)` reads them for
  `t - i < 0`, `t - j < 0`;
- `y_prev = y(-1)`: the backlash (eq. 9, mL = 1; where both lines would switch, the left
  line wins) starts from it;
- the static block has no state.

It imports nothing from jaxcascade.
"""

from __future__ import annotations

import numpy as np
import oracle


def linear_from(P: dict, v, v_past, x_past) -> np.ndarray:
    a = [1.0, *P["a"]]  # a1 = 1
    b = P["b"]
    assert len(v_past) == len(a) and len(x_past) == len(b)
    x = np.zeros(len(v))

    def v_at(k):
        return float(v[k]) if k >= 0 else float(v_past[-k - 1])

    def x_at(k):
        return float(x[k]) if k >= 0 else float(x_past[-k - 1])

    for t in range(len(v)):
        total = 0.0
        for i in range(1, len(a) + 1):
            total += a[i - 1] * v_at(t - i)
        for j in range(1, len(b) + 1):
            total -= b[j - 1] * x_at(t - j)
        x[t] = total
    return x


def backlash_from(P: dict, x, y_prev: float) -> np.ndarray:
    """The backlash from the output `y_prev` before the first sample (`oracle.backlash`)."""
    return oracle.backlash(P, x, y_prev)


def simulate_from(P: dict, u, v_past, x_past, y_prev: float):
    """Noise-free `(v, x, y)` from the state `(v_past, x_past, y_prev)`."""
    v = oracle.pwl(P, u)
    x = linear_from(P, v, v_past, x_past)
    return v, x, backlash_from(P, x, y_prev)
