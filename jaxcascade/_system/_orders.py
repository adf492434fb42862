"""The model orders (`Orders`): the cascade's segments, lags and branch degree, which fix
every array shape. Plain Python and NumPy, so that a command line can read `--orders`
without importing JAX (`_cli._common.orders_option`); `_model` builds the parameters on
them."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

# The parameter vector's parts in order (`Orders.slices`, `CascadeParams`' fields).
_ARRAY_FIELDS = ("MR", "DR", "ML", "DL", "a", "b", "cL", "mR", "cR", "curveL", "curveR")


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
