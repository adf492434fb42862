"""General output backlash: the backlash ND with polynomial branches (issue 39, step 1).

The straight backlash of the 2016 paper (`_simulate.backlash`) has two lines, the left
one `x + cL` (slope `mL = 1`, the normalisation) and the right one `mR (x - cR)`. Its
general form (Vörös 2012, 2014; stated in `docs/general_backlash.md`) replaces them by
curves. We write them as polynomials of degree `q` in the shifted input, expanded around
the point where each crosses zero, as the straight lines are:

    fL(x) = (x + cL) + sum_{i=2..q} mL_i (x + cL)^i
    fR(x) = mR (x - cR) + sum_{i=2..q} mR_i (x - cR)^i

switched by the package's rule (`_simulate.backlash_switches`): the left branch where it
lies below the previous output (pushed down), else the right branch where it lies above
it (pushed up), else the output holds. Where both hold (the branches cross) the left one
wins. The curvature terms are added to the straight lines' own expressions, so that at
`q = 1` (no curvature terms) every operation is today's: the same output bit for bit.

This module holds the block (`GeneralBacklash`), its simulation inside the cascade
(`general_signals`), the check of its parameters and of its branches on a record's range
(`check_branches`, `branch_report`), and the two examples of the note (`general_example`).
The estimators in this parameterisation are later steps of issue 39.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._examples import Example
from ._model import CascadeParams, Orders
from ._simulate import (  # the branches' simulation, shared with `signals` at degree > 1
    Signals,
    _curvature,
    _plus,
    general_backlash,
    general_switches,  # noqa: F401 (re-exported: the block and its rule in one module)
    linear_block,
    pwl,
)
from ._validate import record

# Largest branch degree (`Orders.MAX_DEGREE`): cubic branches are what the sources use;
# quartic leaves room.
MAX_DEGREE = Orders.MAX_DEGREE


class GeneralBacklash(eqx.Module):
    """The ND block with branches of degree `1 + len(curveL)` (module docstring).

    - `cL`, `cR`: the gaps (>= 0): `-cL` and `cR` are where the left and right branches
      cross zero.
    - `mR`: the right branch's slope at `cR` (> 0); the left branch's slope at `-cL` is 1
      (the normalisation `mL_1 = 1`).
    - `curveL`: `Float[Array, " q-1"]`, the left branch's `mL_2..mL_q`; `curveR`: the
      right branch's `mR_2..mR_q` (the same length: one degree for both branches).

    Invariants are checked at construction on concrete values (not under `jit` or
    `vmap`): one sentence naming the parameter and the rule.
    """

    cL: Float[Array, ""]
    mR: Float[Array, ""]
    cR: Float[Array, ""]
    curveL: Float[Array, " qm1"]
    curveR: Float[Array, " qm1"]

    def __check_init__(self):
        left, right = jnp.shape(self.curveL), jnp.shape(self.curveR)
        if len(left) != 1 or left != right:
            raise ValueError(
                f"GeneralBacklash: curveL and curveR must be 1-D arrays of one length "
                f"(degree - 1), got shapes {left} and {right}."
            )
        if not 0 <= left[0] <= MAX_DEGREE - 1:
            raise ValueError(
                f"GeneralBacklash: the branch degree must be 1 to {MAX_DEGREE}, got {left[0] + 1}."
            )
        fields = (self.cL, self.mR, self.cR, self.curveL, self.curveR)
        if any(isinstance(field, jax.core.Tracer) for field in fields):
            return  # traced: checked where the values were concrete
        values = {n: np.asarray(getattr(self, n), float) for n in ("cL", "mR", "cR")}
        curves = [np.asarray(c, float) for c in (self.curveL, self.curveR)]
        for name, value in {**values, "curveL": curves[0], "curveR": curves[1]}.items():
            if not np.all(np.isfinite(value)):
                raise ValueError(f"GeneralBacklash: {name} must be finite, got {value}.")
        for name in ("cL", "cR"):
            if np.any(values[name] < 0):
                raise ValueError(
                    f"GeneralBacklash: the gap {name} must be >= 0, got {values[name]}."
                )
        if np.any(values["mR"] <= 0):
            raise ValueError(
                f"GeneralBacklash: the right branch's slope mR at cR must be > 0, "
                f"got {values['mR']}."
            )
        if values["mR"].ndim == 0:  # one block, not a batch: the expansion points
            for side, slope, curve, point in (
                ("left", 1.0, curves[0], "-cL"),
                ("right", float(values["mR"]), curves[1], "cR"),
            ):
                other = _other_rising_zero(slope, curve)
                if other is not None:
                    raise ValueError(
                        f"GeneralBacklash: the {side} branch also rises through zero "
                        f"{other:+.6g} from {point}; expand it around one zero only "
                        f"(the same curve has other coefficients there)."
                    )

    @property
    def degree(self) -> int:
        """The branches' polynomial degree `q` (1: the straight backlash)."""
        return int(jnp.shape(self.curveL)[-1]) + 1

    @classmethod
    def straight(cls, params: CascadeParams, degree: int = 1) -> GeneralBacklash:
        """The straight backlash of `params` (`cL`, `mR`, `cR`) as a general backlash of
        `degree` with zero curvature."""
        if not 1 <= int(degree) <= MAX_DEGREE:
            raise ValueError(
                f"GeneralBacklash: the branch degree must be 1 to {MAX_DEGREE}, got {degree}."
            )
        dtype = jnp.asarray(params.mR).dtype
        zero = jnp.zeros((degree - 1,), dtype)
        return cls(
            jnp.asarray(params.cL), jnp.asarray(params.mR), jnp.asarray(params.cR), zero, zero
        )

    @classmethod
    def unchecked(cls, cL, mR, cR, curveL, curveR) -> GeneralBacklash:
        """The block without the construction checks: for values an optimiser is trying
        (the loop's `general_backlash` effect), judged afterwards on a record's range
        (`branch_report`)."""
        shape = jnp.zeros((jnp.shape(curveL)[-1],))
        template = cls(jnp.zeros(()), jnp.ones(()), jnp.zeros(()), shape, shape)
        return eqx.tree_at(
            lambda nd: (nd.cL, nd.mR, nd.cR, nd.curveL, nd.curveR),
            template,
            (cL, mR, cR, curveL, curveR),
        )

    def branches(self, x) -> tuple[Array, Array]:
        """`(fL(x), fR(x))` of the module docstring."""
        x = jnp.asarray(x)
        cL, mR, cR = (jnp.asarray(c, x.dtype) for c in (self.cL, self.mR, self.cR))
        left = _plus(x + cL, _curvature(self.curveL, x + cL))
        return left, _plus(mR * (x - cR), _curvature(self.curveR, x - cR))


def _other_rising_zero(slope: float, curve: np.ndarray) -> float | None:
    """A real zero `s != 0` of `slope s + sum curve[i-2] s^i` at which it rises, or None.
    (The branch in powers of `s`, its shifted input: `s = 0` is its expansion point.)"""
    if curve.size == 0 or not np.any(curve != 0):
        return None
    # s (slope + curve[0] s + curve[1] s^2 + ...): the other zeros are the roots of the
    # bracket (np.roots: highest power first)
    roots = np.roots(np.concatenate([curve[::-1], [slope]]))
    coefficients = np.concatenate([[0.0, slope], curve])  # lowest power first
    derivative = np.polynomial.polynomial.polyder(coefficients)
    for root in roots:
        if abs(root.imag) <= 1e-12 * max(1.0, abs(root.real)) and abs(root.real) > 1e-12:
            if np.polynomial.polynomial.polyval(root.real, derivative) > 0:
                return float(root.real)
    return None


def general_signals(params: CascadeParams, nd: GeneralBacklash, u: Float[Array, " T"]) -> Signals:
    """v, x and y of the cascade NS -> LD -> ND with the general backlash `nd` in place
    of `params`' straight one (whose `cL`, `mR`, `cR` are not used)."""
    u = record(u, where="general_signals", cast=False)[0]
    v = pwl(params, u)
    x = linear_block(params, v)
    return Signals(v, x, general_backlash(nd, x))


@jax.jit
def _simulate_general(params, nd, u):
    return general_signals(params, nd, u).y


def simulate_general(params: CascadeParams, nd: GeneralBacklash, u) -> Float[Array, " T"]:
    """Noise-free output of the cascade with the general backlash `nd` (`u` checked
    first, as in `simulate`)."""
    return _simulate_general(params, nd, record(u, where="simulate_general", cast=False)[0])


# -- Branches on a record's range --------------------------------------------------------


def branch_report(nd: GeneralBacklash, x, points: int = 2001) -> dict:
    """How the branches behave on the range of `x` (a record's LD output, or its
    `(low, high)`): the range, each branch's smallest slope there, and the smallest
    dead band `fL - fR` (negative where the branches cross). Evaluated on `points`
    evenly spaced values and at the extrema of the slopes and of the band inside the
    range (zeros of their derivatives), so a dip between grid points is not missed."""
    x = np.asarray(x, float)
    low, high = float(np.min(x)), float(np.max(x))
    grid = np.linspace(low, high, points)
    left = np.concatenate([[0.0, 1.0], np.asarray(nd.curveL, float)])  # powers of x + cL
    right = np.concatenate([[0.0, float(nd.mR)], np.asarray(nd.curveR, float)])
    P = np.polynomial.Polynomial
    fL = P(left)(P([float(nd.cL), 1.0]))  # as polynomials of x
    fR = P(right)(P([-float(nd.cR), 1.0]))
    band = fL - fR

    def smallest(poly):
        candidates = [grid]
        for root in poly.deriv().roots():
            if abs(root.imag) < 1e-12 and low <= root.real <= high:
                candidates.append(np.array([root.real]))
        return float(np.min(poly(np.concatenate(candidates))))

    return {
        "x_low": low,
        "x_high": high,
        "min_slope_left": smallest(fL.deriv()),
        "min_slope_right": smallest(fR.deriv()),
        "min_dead_band": smallest(band),
    }


def check_branches(nd: GeneralBacklash, x, where: str = "the general backlash") -> dict:
    """`branch_report`, raising `ValueError` (one sentence) where a branch is not
    strictly increasing on the range of `x`: the switching rule then no longer describes
    a backlash there. Crossing branches are allowed (the rule defines the output; the
    report says where `min_dead_band < 0`)."""
    report = branch_report(nd, x)
    for side in ("left", "right"):
        if report[f"min_slope_{side}"] <= 0:
            raise ValueError(
                f"{where}: the {side} branch is not increasing on the record's range of x "
                f"[{report['x_low']:.4g}, {report['x_high']:.4g}] (its smallest slope there "
                f"is {report[f'min_slope_{side}']:.4g}); choose smaller curvature terms."
            )
    return report


# -- The note's examples ---------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class GeneralExample:
    """An example of `../shared/GENERAL_BACKLASH.md`: the cascade (whose straight
    backlash holds `cL`, `mR`, `cR`), the branches' curvature and the experiment (input
    uniform in `(-amplitude, amplitude)`, `n_samples`, output noise at `snr`)."""

    name: str
    values: dict
    orders: Orders
    curveL: tuple
    curveR: tuple
    n_samples: int = 4000
    snr: float = 25.0
    amplitude: float = 2.0

    def params(self, dtype=None) -> CascadeParams:
        return CascadeParams.from_dict(self.values, self.orders).astype(
            dtype or jnp.result_type(float)
        )

    def backlash(self, dtype=None) -> GeneralBacklash:
        p = self.params(dtype)
        curves = (jnp.asarray(c, p.mR.dtype) for c in (self.curveL, self.curveR))
        return GeneralBacklash(p.cL, p.mR, p.cR, *curves)

    @property
    def degree(self) -> int:
        return len(self.curveL) + 1

    def example(self) -> Example:
        """The example as a paper example is held (`_examples.Example`, what a sweep's
        `example = "general1"` runs): orders with the branch degree (`Orders.degree`),
        the values with the curvature terms."""
        o = self.orders
        values = dict(self.values)
        values.update({f"mL{i + 2}": float(c) for i, c in enumerate(self.curveL)})
        values.update({f"mR{i + 2}": float(c) for i, c in enumerate(self.curveR)})
        orders = Orders(o.nR, o.nL, o.r, o.p, self.degree)
        return Example(self.name, values, self.n_samples, self.snr, self.amplitude, orders)


def _example1_values() -> dict:
    from ._examples import example

    return dict(example(1).values)


GENERAL_EXAMPLES = {
    # The 2016 Example 1 with cubic branches (the note's `general1`).
    "general1": GeneralExample(
        "general1", _example1_values(), Orders(2, 2, 2, 2), (0.0, 0.04), (0.0, 0.05)
    ),
    # The 2014 paper's linear block x(t) = 0.7 u(t-1) + 0.5 u(t-2) + 0.2 x(t-1)
    # - 0.35 x(t-2), normalised (a_1 = 1): NS one line of slope 0.7 on each side, LD
    # a2 = 5/7, b = (-0.2, 0.35); asymmetric quadratic-and-cubic branches of our choice
    # (the note's `general2`; `results/general_backlash/examples.md` checks them).
    "general2": GeneralExample(
        "general2",
        {"MR1": 0.7, "ML1": 0.7, "a2": 5 / 7, "b1": -0.2, "b2": 0.35}
        | {"cL": 0.5, "mR": 0.9, "cR": 0.4},
        Orders(1, 1, 2, 2),
        (-0.03, 0.02),
        (0.04, 0.02),
    ),
}


def general_example(name: str) -> GeneralExample:
    """The note's example `general1` or `general2`."""
    if name not in GENERAL_EXAMPLES:
        raise ValueError(
            f"Unknown general-backlash example {name!r}; the examples are "
            f"{', '.join(GENERAL_EXAMPLES)}."
        )
    return GENERAL_EXAMPLES[name]
