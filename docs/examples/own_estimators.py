"""Two estimators from outside jaxcascade, one of each kind (docs/estimators.md).

- `scipy_output_error`, a plain host function: the paper's iteration for a start, then
  SciPy's `least_squares` on the simulation error, the parameters boxed into the
  model's domain. It returns the parameter vector in `orders.names` order.
- `LiteralRefined`, an `Estimator`: the paper's iteration, then jaxcascade's own
  output-error Levenberg-Marquardt (`refine`); traceable, so a sweep runs it batched.

    import jaxcascade as jc
    jc.register_estimator("scipy_oe", scipy_output_error)
    jc.register_estimator("literal_refined", LiteralRefined)
"""

from typing import ClassVar

import equinox as eqx
import numpy as np
from scipy.optimize import least_squares

import jaxcascade as jc


def scipy_output_error(u, y, orders, *, max_nfev: int = 100):
    """Output-error least squares by SciPy from the paper's iteration."""
    literal = jc.Literal()(u, y, orders)
    usable = not jc.Status(int(literal.status)).failure
    usable = usable and bool(jc.is_admissible(literal.params, u.min(), u.max()))
    start = literal.params if usable else jc.initial_guess(orders, u.min(), u.max())
    x0 = np.asarray(start.to_vector(), float)
    s, size = orders.slices, len(orders.names)
    low, high = np.full(size, -np.inf), np.full(size, np.inf)
    low[s["DR"]], high[s["DR"]] = 0.0, u.max()  # breakpoints inside the input range
    low[s["DL"]], high[s["DL"]] = u.min(), 0.0
    low[s["b"]], high[s["b"]] = -2.0, 2.0  # a box around the stable poles
    low[s["cL"]], low[s["mR"]], low[s["cR"]] = 0.0, 1e-3, 0.0  # gaps >= 0, mR > 0
    x0 = np.clip(x0, low + 1e-6, high - 1e-6)

    def residual(vector):
        params = jc.CascadeParams.from_vector(vector, orders, check=False)
        with np.errstate(all="ignore"):  # an unstable trial point overflows: keep it finite
            error = np.asarray(jc.simulate(params, u)) - y
        return np.clip(np.nan_to_num(error, nan=1e6), -1e6, 1e6)

    fit = least_squares(residual, x0, bounds=(low, high), max_nfev=max_nfev)
    return fit.x if fit.status >= 0 else np.full(size, np.nan)  # non-finite: failed


class LiteralRefined(jc.Estimator):
    """The paper's iteration, then output-error Levenberg-Marquardt."""

    name: ClassVar[str] = "literal_refined"
    summary: ClassVar[str] = "the paper's iteration, then output-error Levenberg-Marquardt"

    max_steps: int = eqx.field(static=True, default=30)  # a setting: static, with a default

    def __call__(self, u, y, orders, *, key=None, input_range=None):
        start = jc.Literal()(u, y, orders, input_range=input_range)
        fit = jc.refine(start.params, u, y, max_steps=self.max_steps)
        return eqx.tree_at(
            lambda s: (s.params, s.cost, s.status, s.iterations),
            start,
            (fit.params, fit.cost, fit.status, start.iterations + fit.steps),
        )
