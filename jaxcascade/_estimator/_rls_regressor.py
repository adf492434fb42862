"""The key-term regressor of one sample (eqs. 17 and 23-25) for the current estimate.

A recursion needs `phi(t)` and `yc(t)` one sample at a time. They depend on the record
only through a short window: `u(t-1)`, `v(t-2..t-r)`, `x(t)`, `x(t-1..t-p)`, `y(t)`,
`y(t-1)`. So the row is the last row of `_regression.regression` run on a window of
`window(orders)` samples (the zeros it shifts in at the window's start reach only the
rows before the last): one construction of the regressors in the package, not two.
"""

from __future__ import annotations

from jaxtyping import Array, Float

from .._system._model import CascadeParams, Orders
from ._regression import regression


def window(orders: Orders) -> int:
    """Samples in the window of `sample_regression`: the current one and the `max(r, p,
    1)` before it."""
    return max(orders.r, orders.p, 1) + 1


def sample_regression(
    params: CascadeParams,
    u: Float[Array, " W"],
    y: Float[Array, " W"],
    v: Float[Array, " W"],
    x: Float[Array, " W"],
    *,
    unit_slopes: bool = False,
) -> tuple[Float[Array, " P"], Float[Array, ""], Float[Array, ""], Float[Array, ""]]:
    """`(phi(t), yc(t), g1(t), g2(t))` from windows ending at sample t (last entry),
    with the switching functions f1, f2 and g1, g2 of `params` (eqs. 19-20, 23-24).
    `unit_slopes` as in `_regression.regression` (the paper's first iteration)."""
    reg = regression(params, u, y, v, x, unit_slopes=unit_slopes)
    return reg.phi[-1], reg.yc[-1], reg.g1[-1], reg.g2[-1]
