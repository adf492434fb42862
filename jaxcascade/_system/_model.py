"""Parameters of the three-block cascade NS -> LD -> ND (Vörös 2016, eqs. 1-11)."""

from __future__ import annotations

from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._orders import _ARRAY_FIELDS
from ._orders import Orders as Orders  # the orders, in a module of their own

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
