"""The curved output backlash as an effect of the loop (issue 39, point 5).

`CurvedBacklash` replaces the cascade's straight backlash by the general backlash of
`_general_backlash` (its branches `fL = (x + cL) + sum mL_i (x + cL)^i`,
`fR = mR (x - cR) + sum mR_i (x - cR)^i`, `i = 2..q`): the effect holds the curvature
terms `mL_2..q`, `mR_2..q`; the gaps and the right slope stay the cascade's own `cL`,
`mR`, `cR`, refined with them. With the curvature zero the model is the straight
cascade. The simulator (`simulate_with_switches`), the initial-state fit
(`_initial_state.simulate_from`) and the loop's regime signals ask a model for its
backlash with `backlash_of`.

Its residual signature: a straight line through a curved branch leaves an error whose
mean changes with the output level along the branch (`_diagnose.branch_test`, the
`branch` test), and so with the input level (`level`); held stretches at levels the
straight line misplaces look like hysteresis (`hysteresis`). It is tried only when one
of those fails (`needs_signature`).

Starts: on the current model's active samples of each branch (its regime signals), the
residual is regressed on the curvature columns `s^2..s^q` (`s = x + cL` on the left,
`x - cR` on the right), for `q = 2` and `3`; each degree is one candidate structure,
refined jointly with the cascade, the lower degree kept unless the higher lowers the
cost by more than its two parameters are worth (`_loop._fit_candidate`, BIC). A fit
whose branches stop increasing on the records' range of `x` (`admissible`) is not a
backlash any more and is dropped.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from jaxtyping import Array, Float

from ..._system._general_backlash import GeneralBacklash, branch_report
from ..._system._model import CascadeParams
from ..._system._simulate import backlash_switches
from ._base import Effect, ExtendedModel, Start, _batched, _repeat, simulate_padded


def _signals(model: ExtendedModel, u):
    """`(y, x, y_cascade)` of `model` on one record (host side, padded to its bucket)."""
    return simulate_padded(model, np.asarray(u, float))


class CurvedBacklash(Effect):
    name: ClassVar[str] = "general_backlash"
    signature: ClassVar[tuple[str, ...]] = ("branch", "level", "hysteresis")
    description: ClassVar[str] = (
        "curved branches of the output backlash (general backlash, polynomial degree 2-3)"
    )
    degrees: ClassVar[tuple[int, ...]] = (2, 3)
    needs_signature: ClassVar[bool] = True

    # mL_i, mR_i (i = 2..q) of the powers of x in the output's units
    # (`_data.Scaling.params_to_physical`; the schema writes them under those names)
    units: ClassVar[dict] = {"curveL": "output_powers(2)", "curveR": "output_powers(2)"}

    curveL: Float[Array, " qm1"]
    curveR: Float[Array, " qm1"]

    def backlash(self, params: CascadeParams) -> GeneralBacklash:
        return GeneralBacklash.unchecked(params.cL, params.mR, params.cR, self.curveL, self.curveR)

    @property
    def degree(self) -> int:
        return int(np.shape(self.curveL)[-1]) + 1

    def admissible(self, model: ExtendedModel, us) -> str | None:
        """None where both branches increase on the records' range of `x`, else why not."""
        x = np.concatenate([_signals(model, u)[1] for u in us])
        report = branch_report(self.backlash(model.params), x)
        for side in ("left", "right"):
            if not report[f"min_slope_{side}"] > 0:
                return (
                    f"its {side} branch turns inside the records' range of x (smallest "
                    f"slope {report[f'min_slope_{side}']:.3g})"
                )
        return None

    @classmethod
    def starts_records(cls, model, records):
        if not model.cascade or any(isinstance(e, cls) for e in model.effects):
            return []
        p = model.params
        cL, cR = float(p.cL), float(p.cR)
        sides = {"left": ([], []), "right": ([], [])}
        for u, _, residual in records:
            _, x, y_cascade = _signals(model, u)
            previous = np.concatenate([[0.0], y_cascade[:-1]])
            # the straight backlash's switches, on the host (`general_switches` of
            # `GeneralBacklash.straight(p)` is `backlash_switches`, the same operations)
            g1, g2 = backlash_switches(x, previous, cL, float(p.mR), cR)
            for side, active, s in (("left", g1 > 0, x + cL), ("right", g2 > 0, x - cR)):
                sides[side][0].append(s[active])
                sides[side][1].append(np.asarray(residual)[active])
        starts = []
        for q in cls.degrees:
            curves = {}
            for side, (s, r) in sides.items():
                s, r = np.concatenate(s), np.concatenate(r)
                if s.size < 10 * q:  # a branch the records hardly reach: nothing to fit
                    curves[side] = np.zeros(q - 1)
                    continue
                columns = np.stack([s**i for i in range(2, q + 1)], axis=1)
                curves[side] = np.linalg.lstsq(columns, r, rcond=None)[0]
            # the residual's fit, half of it, and the straight backlash: the
            # joint refit moves the cascade too
            scales = np.array([1.0, 0.5, 0.0])[:, None]
            effect = _batched(cls, curveL=scales * curves["left"], curveR=scales * curves["right"])
            starts.append(Start(f"{cls.name}:{q}", model.orders, _repeat(model, 3), effect))
        return starts

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])
