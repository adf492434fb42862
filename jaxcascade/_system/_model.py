"""Parameters of the three-block cascade NS -> LD -> ND (Vörös 2016, eqs. 1-11)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


@dataclasses.dataclass(frozen=True)
class Orders:
    """Model orders; they fix every array shape, so they are static.

    - `nR`, `nL`: number of right / left segments of the piecewise-linear block (>= 1).
    - `r`: numerator order of the linear block, `A(q) = q^-1 + a2 q^-2 + ... + ar q^-r` (>= 1).
    - `p`: denominator order, `B(q) = b1 q^-1 + ... + bp q^-p` (>= 0).
    - `degree`: the backlash branches' polynomial degree `q` (1 to `MAX_DEGREE`; 1, the
      default, is the 2016 paper's straight backlash). At `q > 1` the parameters go on
      with the branches' curvature terms `mL2..mLq`, `mR2..mRq` (the general output
      backlash, `_general_backlash`, `docs/general_backlash.md`); at `q = 1` nothing of
      the layout, the names or the text form changes.

    The largest supported orders are `MAX_SEGMENTS` (8) segments per side and `MAX_LAG`
    (16) for `r` and `p`: at most 64 parameters, so every allowed combination also fits
    the fused kernel (`_fused`, 64 block-1 columns, lags up to 16). A record needs at
    least `min_samples` samples, `SAMPLES_PER_PARAMETER` (10) per parameter.
    """

    MAX_SEGMENTS: ClassVar[int] = 8
    MAX_LAG: ClassVar[int] = 16
    MAX_DEGREE: ClassVar[int] = 4
    SAMPLES_PER_PARAMETER: ClassVar[int] = 10

    nR: int = 2
    nL: int = 2
    r: int = 2
    p: int = 2
    degree: int = 1

    def __post_init__(self):
        limits = (
            ("nR", 1, self.MAX_SEGMENTS),
            ("nL", 1, self.MAX_SEGMENTS),
            ("r", 1, self.MAX_LAG),
            ("p", 0, self.MAX_LAG),
            ("degree", 1, self.MAX_DEGREE),
        )
        for field, low, high in limits:
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise ValueError(f"Order {field} must be an integer >= {low}, got {value!r}.")
            if value > high:
                raise ValueError(
                    f"Order {field} = {value} is above the largest supported, {high} "
                    f"(nR, nL <= {self.MAX_SEGMENTS}; r, p <= {self.MAX_LAG}; "
                    f"degree <= {self.MAX_DEGREE})."
                )

    @classmethod
    def parse(cls, text: str) -> Orders:
        """Read orders from `"nR,nL,r,p"`, or `"nR,nL,r,p,q"` with the branch degree."""
        parts = [part.strip() for part in str(text).split(",")]
        if len(parts) not in (4, 5) or not all(part.lstrip("-").isdigit() for part in parts):
            raise ValueError(
                f"Orders must be four integers 'nR,nL,r,p' (or five, 'nR,nL,r,p,q' with the "
                f"backlash branches' degree q), got {text!r}."
            )
        return cls(*(int(part) for part in parts))

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in theta order (eq. 18), with `cR` in place of `C = cR mR`."""
        return (
            tuple(f"MR{i}" for i in range(1, self.nR + 1))
            + tuple(f"DR{i}" for i in range(1, self.nR))
            + tuple(f"ML{j}" for j in range(1, self.nL + 1))
            + tuple(f"DL{j}" for j in range(1, self.nL))
            + tuple(f"a{i}" for i in range(2, self.r + 1))
            + tuple(f"b{j}" for j in range(1, self.p + 1))
            + ("cL", "mR", "cR")
            + tuple(f"mL{i}" for i in range(2, self.degree + 1))
            + tuple(f"mR{i}" for i in range(2, self.degree + 1))
        )

    @property
    def size(self) -> int:
        """Number of free parameters (length of theta)."""
        return self.straight_size + 2 * (self.degree - 1)

    @property
    def straight_size(self) -> int:
        """Number of parameters up to `cR`: the cascade with the straight backlash."""
        return 2 * self.nR + 2 * self.nL - 2 + (self.r - 1) + self.p + 3

    @property
    def straight(self) -> Orders:
        """These orders with straight branches (degree 1)."""
        return dataclasses.replace(self, degree=1)

    # ---- the parameter-vector layout (the one place it is written) --------------------

    @property
    def slices(self) -> dict[str, slice]:
        """Where each field of `CascadeParams` sits in the vector (`names` order):
        `MR`, `DR`, `ML`, `DL`, `a`, `b`, `cL`, `mR`, `cR` (the three of length 1), `curveL`,
        `curveR` (`mL2..mLq`, `mR2..mRq`: empty at degree 1)."""
        out, start = {}, 0
        for field, length in zip(_ARRAY_FIELDS, self.lengths, strict=True):
            out[field] = slice(start, start + length)
            start += length
        return out

    @property
    def lengths(self) -> tuple[int, ...]:
        """Length of each field, in `_ARRAY_FIELDS` order."""
        q = self.degree - 1
        return (self.nR, self.nR - 1, self.nL, self.nL - 1, self.r - 1, self.p, 1, 1, 1, q, q)

    @property
    def static_dynamic(self) -> slice:
        """The NS and LD parameters (the paper's first step estimates only these)."""
        return slice(0, self.straight_size - 3)

    @property
    def backlash(self) -> slice:
        """The backlash parameters `cL`, `mR`, `cR` (`C = cR mR` in theta)."""
        return slice(self.straight_size - 3, self.straight_size)

    @property
    def curvature(self) -> slice:
        """The branches' curvature terms `mL2..mLq`, `mR2..mRq` (empty at degree 1)."""
        return slice(self.straight_size, self.size)

    @property
    def g1_columns(self) -> int:
        """Number of regressor columns that carry g1 (NS, LD and cL): the first block of
        the block-diagonal normal equations; the `mR` and `C` columns carry g2."""
        return self.straight_size - 2

    @property
    def breakpoints(self) -> tuple[int, ...]:
        """Indices of the breakpoints `DR`, `DL` in the vector."""
        s = self.slices
        return tuple(range(s["DR"].start, s["DR"].stop)) + tuple(range(s["DL"].start, s["DL"].stop))

    @property
    def blocks(self) -> dict[str, tuple[str, ...]]:
        """Parameter names per block of the cascade: NS, LD, ND."""
        names, s = self.names, self.slices
        return {
            "NS": names[s["MR"].start : s["DL"].stop],
            "LD": names[s["a"].start : s["b"].stop],
            "ND": names[s["cL"].start :],
        }

    @property
    def min_samples(self) -> int:
        """Fewest samples a record needs: `SAMPLES_PER_PARAMETER` per parameter. With
        fewer the estimates are mostly noise and the iterations rarely settle, so the
        work is refused up front; it also overdetermines the regression (which needs
        `2 P + max(r, p) + 1 <= 10 P`)."""
        return self.SAMPLES_PER_PARAMETER * self.size

    def __str__(self) -> str:
        text = f"{self.nR},{self.nL},{self.r},{self.p}"
        return text if self.degree == 1 else f"{text},{self.degree}"


_ARRAY_FIELDS = ("MR", "DR", "ML", "DL", "a", "b", "cL", "mR", "cR", "curveL", "curveR")
_SCALARS = ("cL", "mR", "cR")


def _is_concrete(*values) -> bool:
    return not any(isinstance(value, jax.core.Tracer) for value in values)


class CascadeParams(eqx.Module):
    """Parameters of the cascade, normalised by `mL = 1` and `a1 = 1` (eq. 12).

    NS (eq. 1): `v = sum_i MR_i h(DR_{i-1} - u)(u - DR_{i-1})
    + sum_j ML_j h(u - DL_{j-1})(u - DL_{j-1})` with `DR_0 = DL_0 = 0`; slopes are
    increments, the slope of right segment k is `MR_1 + ... + MR_k`.
    LD (eq. 6): `x(t) = v(t-1) + sum_{i>=2} a_i v(t-i) - sum_j b_j x(t-j)`.
    ND (eq. 9): backlash with slopes `mL = 1`, `mR` and gaps `cL`, `cR`; at branch degree
    `q > 1` (`Orders.degree`) the general backlash, its branches
    `fL(x) = (x + cL) + sum_i mL_i (x + cL)^i`, `fR(x) = mR (x - cR) + sum_i mR_i (x - cR)^i`
    (`_general_backlash`).

    Fields (shapes follow `orders`, a static field):
    - `MR`: `Float[Array, " nR"]`, `DR`: `Float[Array, " nR-1"]` (increasing, > 0).
    - `ML`: `Float[Array, " nL"]`, `DL`: `Float[Array, " nL-1"]` (decreasing, < 0).
    - `a`: `Float[Array, " r-1"]` holding a2..ar; `b`: `Float[Array, " p"]`.
    - `cL`, `mR`, `cR`: scalars (`mR > 0`, gaps >= 0).
    - `curveL`, `curveR`: `Float[Array, "... q-1"]`, `mL2..mLq` and `mR2..mRq` (optional:
      empty, of the batch's shape, when not given; their length must be `degree - 1`).

    Leading batch dimensions are allowed on every array field (for `vmap`); the
    invariants are checked once at construction, and only on concrete values.
    """

    MR: Float[Array, "... nR"]
    DR: Float[Array, "... nRm1"]
    ML: Float[Array, "... nL"]
    DL: Float[Array, "... nLm1"]
    a: Float[Array, "... rm1"]
    b: Float[Array, "... p"]
    cL: Float[Array, ...]
    mR: Float[Array, ...]
    cR: Float[Array, ...]
    orders: Orders = eqx.field(static=True)
    curveL: Float[Array, "... qm1"] = None
    curveR: Float[Array, "... qm1"] = None

    def __post_init__(self):
        # straight branches (or degree 1) need no curvature: empty, of the batch's shape
        for name in ("curveL", "curveR"):
            if getattr(self, name) is None:
                mR = jnp.asarray(self.mR)
                dtype = mR.dtype if jnp.issubdtype(mR.dtype, jnp.floating) else float
                self.__setattr__(name, jnp.zeros(jnp.shape(mR) + (0,), dtype))

    def __check_init__(self):
        o = self.orders
        lengths = {
            "MR": (self.MR, o.nR, "nR"),
            "DR": (self.DR, o.nR - 1, "nR - 1"),
            "ML": (self.ML, o.nL, "nL"),
            "DL": (self.DL, o.nL - 1, "nL - 1"),
            "a": (self.a, o.r - 1, "r - 1 (a2..ar)"),
            "b": (self.b, o.p, "p"),
            "curveL": (self.curveL, o.degree - 1, "degree - 1 (mL2..mLq)"),
            "curveR": (self.curveR, o.degree - 1, "degree - 1 (mR2..mRq)"),
        }
        for name, (value, expected, what) in lengths.items():
            if jnp.shape(value)[-1:] != (expected,):
                raise ValueError(
                    f"{name} must have length {what} = {expected} for orders {o}, "
                    f"got shape {jnp.shape(value)}."
                )
        if not _is_concrete(self.DR, self.DL, self.cL, self.mR, self.cR):
            return
        DR, DL = np.asarray(self.DR), np.asarray(self.DL)
        if not np.all(
            np.isfinite(np.concatenate([np.ravel(np.asarray(f)) for f in self._arrays()]))
        ):
            raise ValueError("Parameters must be finite; got NaN or inf.")
        if DR.shape[-1] and (np.any(DR[..., 0] <= 0) or np.any(np.diff(DR, axis=-1) <= 0)):
            raise ValueError(f"Right breakpoints DR must be positive and increasing, got {DR}.")
        if DL.shape[-1] and (np.any(DL[..., 0] >= 0) or np.any(np.diff(DL, axis=-1) >= 0)):
            raise ValueError(f"Left breakpoints DL must be negative and decreasing, got {DL}.")
        if np.any(np.asarray(self.mR) <= 0):
            raise ValueError(f"Backlash slope mR must be positive, got {np.asarray(self.mR)}.")
        if np.any(np.asarray(self.cL) < 0) or np.any(np.asarray(self.cR) < 0):
            raise ValueError(
                f"Backlash gaps must be non-negative, got cL={np.asarray(self.cL)}, "
                f"cR={np.asarray(self.cR)}."
            )

    def _arrays(self):
        return tuple(getattr(self, field) for field in _ARRAY_FIELDS)

    @property
    def names(self) -> tuple[str, ...]:
        return self.orders.names

    # ---- conversions -------------------------------------------------------------------

    def to_vector(self) -> Float[Array, "... P"]:
        """Parameters in `names` order (with `cR`, not the paper's `C`)."""
        arrays = self._arrays()
        batch = jnp.shape(self.mR)
        return jnp.concatenate([jnp.reshape(a, batch + (-1,)) for a in arrays], axis=-1)

    def to_theta(self) -> Float[Array, "... P"]:
        """The paper's theta (eq. 18): like `to_vector` but ending in `C = cR mR`."""
        vector = self.to_vector()
        return vector.at[..., self.orders.straight_size - 1].set(self.cR * self.mR)

    @classmethod
    def from_vector(
        cls, vector: Float[Array, "... P"], orders: Orders, *, check: bool = True
    ) -> CascadeParams:
        """Inverse of `to_vector`.

        `check=False` skips the invariant checks: estimators use it to hold iterates that
        may be inadmissible, which they then report through a status, not an exception.
        """
        o = orders
        if jnp.shape(vector)[-1] != o.size:
            raise ValueError(
                f"Parameter vector must have {o.size} entries for orders {o}, "
                f"got {jnp.shape(vector)[-1]}."
            )
        slices = o.slices
        parts = {
            field: vector[..., slices[field].start]
            if field in _SCALARS
            else vector[..., slices[field]]
            for field in _ARRAY_FIELDS
        }
        if check:
            return cls(**parts, orders=o)
        self = object.__new__(cls)  # what equinox itself does when unflattening
        for field, value in parts.items():
            object.__setattr__(self, field, value)
        object.__setattr__(self, "orders", o)
        return self

    @classmethod
    def from_theta(
        cls, theta: Float[Array, "... P"], orders: Orders, *, check: bool = True
    ) -> CascadeParams:
        """Inverse of `to_theta`: recovers `cR = C / mR`."""
        k = orders.straight_size - 1
        vector = theta.at[..., k].set(theta[..., k] / theta[..., k - 1])
        return cls.from_vector(vector, orders, check=check)

    @classmethod
    def from_dict(cls, values: Mapping[str, float], orders: Orders | None = None) -> CascadeParams:
        """Build from `{name: value}`; orders are inferred from the names when not given."""
        if orders is None:
            orders = _infer_orders(values)
        missing = [name for name in orders.names if name not in values]
        extra = [name for name in values if name not in orders.names]
        if missing or extra:
            raise ValueError(
                f"Parameters for orders {orders} need exactly {list(orders.names)}; "
                f"missing {missing}, unexpected {extra}."
            )
        vector = np.array([float(values[name]) for name in orders.names])
        return cls.from_vector(jnp.asarray(vector), orders)

    def to_dict(self) -> dict[str, float]:
        """`{name: float}` for one (unbatched) parameter set."""
        vector = np.asarray(jax.device_get(self.to_vector()), dtype=float)
        if vector.ndim != 1:
            raise ValueError(
                f"to_dict and to_series need a single parameter set, not a batch of shape "
                f"{vector.shape[:-1]}; for a table with one row per record use "
                "jaxcascade.solution_table(solution) (or solution_table(params))."
            )
        return dict(zip(self.names, vector.tolist(), strict=True))

    def to_series(self):
        """A pandas Series indexed by parameter name."""
        import pandas as pd

        return pd.Series(self.to_dict(), name="value")

    def astype(self, dtype) -> CascadeParams:
        return CascadeParams.from_vector(self.to_vector().astype(dtype), self.orders, check=False)


def _infer_orders(values: Mapping[str, float]) -> Orders:
    def count(prefix):
        return sum(
            1 for name in values if name.startswith(prefix) and name[len(prefix) :].isdigit()
        )

    nR, nL = count("MR"), count("ML")
    r = count("a") + 1
    p = count("b")
    degree = count("mL") + 1
    return Orders(nR=max(nR, 1), nL=max(nL, 1), r=r, p=p, degree=degree)


def reflection_coefficients(b: Float[Array, " p"]) -> Float[Array, " p"]:
    """Reflection coefficients `k_1..k_p` of `1 + b1 q^-1 + ... + bp q^-p` (Schur-Cohn
    step-down recursion); the polynomial is stable iff every `|k_i| < 1`. Traceable; a
    step with `|k| >= 1` is guarded so no NaN appears (the result then flags instability).
    """
    p = b.shape[-1]
    poly = jnp.concatenate([jnp.ones((1,), b.dtype), b])
    ks = []
    for m in range(p, 0, -1):
        k = poly[m]
        ks.append(k)
        denom = jnp.where(jnp.abs(k) < 1, 1 - k**2, 1.0)
        poly = (poly[:m] - k * poly[m:0:-1]) / denom
    return jnp.stack(ks[::-1]) if ks else jnp.zeros((0,), b.dtype)


def is_stable(b: Float[Array, " p"]) -> Array:
    """Whether `1 + b1 q^-1 + ... + bp q^-p` has all roots inside the unit circle."""
    k = reflection_coefficients(b)
    return jnp.all(jnp.abs(k) < 1) & jnp.all(jnp.isfinite(k))


def is_admissible(params: CascadeParams, u_min, u_max) -> Array:
    """Whether the estimates describe a usable model for an input in `[u_min, u_max]`.

    Breakpoints sorted and inside the input range (a segment never visited leaves its
    slope unidentifiable), `mR > 0` (eq. 11 divides by it), a stable linear block, and
    every value finite. Traceable; returns a boolean scalar.
    """
    checks = [jnp.all(jnp.isfinite(params.to_vector())), params.mR > 0, is_stable(params.b)]
    if params.orders.nR > 1:
        checks += [params.DR[0] > 0, jnp.all(jnp.diff(params.DR) > 0), params.DR[-1] < u_max]
    if params.orders.nL > 1:
        checks += [params.DL[0] < 0, jnp.all(jnp.diff(params.DL) < 0), params.DL[-1] > u_min]
    return jnp.all(jnp.stack([jnp.asarray(c) for c in checks]))
