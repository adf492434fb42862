"""Hysteresis effects of the model-error loop (operators in `_hysteresis`).

Each is a path in parallel with the cascade (`Effect.parallel`: its force is added to
the cascade's output) except `InputBacklash`, which acts on the input. Their residual
signature is the `hysteresis` test of `_diagnose` (the residual depends on the direction
of motion or on a stop operator of the input). Starting values are fitted by least
squares on the current model's residual (host side); the loop then refines them with
the cascade by output-error Levenberg-Marquardt.

- `SlackFriction` (issue 15 (a)): friction behind a slack zone. A stop operator with
  threshold `r` (the slack half-width plus the elastic travel) feeds the static map
  `slack_map`: zero for `|s| <= dead r`, linear ramps to the plateaus `upper` (at
  `s = r`, sliding forward) and `lower` (at `s = -r`, sliding back):
  `F = upper clip((s/r - dead)/(1 - dead), 0, 1) + lower clip((-s/r - dead)/(1 - dead), 0, 1)`.
  This is a rotor held by Coulomb friction and dragged through a slack of width
  `2 dead r` by a contact of stiffness `upper / ((1 - dead) r)`.
- `PrandtlIshlinskii` (b): `F = c + sum_k w_k . basis_k(u)`, the stop operators on a
  fixed grid of thresholds and hinges of each (`pi_basis`), linear in the weights `w`;
  the grid size and the ridge parameter are chosen by leave-one-record-out
  cross-validation over the estimation records (halves of the record when there is one).
- `DahlFriction` (c): `F = dahl(u; sigma, level)`.
- `InputBacklash` (d): the cascade with a backlash (play operator, half-width `gap`) in
  front of the static nonlinearity: `y = cascade(play(u))`.
"""

from __future__ import annotations

import itertools
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._effects import Effect, Start, _batched, _repeat
from ._hysteresis import dahl, pi_basis, ridge, slack_map, stop_operator

_SIGNATURE = ("hysteresis",)


def _span(u) -> float:
    u = np.asarray(u)
    return float(np.quantile(u, 0.995) - np.quantile(u, 0.005)) or 1.0


class SlackFriction(Effect):
    name: ClassVar[str] = "slack_friction"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "friction behind a slack zone: stop operator (threshold r) then a dead zone "
        "(|s| <= dead r) and plateaus upper, lower"
    )
    fractions: ClassVar[tuple[float, ...]] = (0.05, 0.1, 0.2, 0.35)
    refine_steps: ClassVar[int] = 30

    threshold: Float[Array, ""]
    dead: Float[Array, ""]
    upper: Float[Array, ""]
    lower: Float[Array, ""]

    def parallel(self, u):
        r = jnp.abs(self.threshold) + 1e-6
        s = stop_operator(u, r)
        dead = jnp.clip(self.dead, 0.0, 0.98)
        return slack_map(s, r, dead, self.upper, self.lower)

    @classmethod
    def starts_records(cls, model, records):
        span = _span(np.concatenate([r[0] for r in records]))
        rows = []
        for fraction, dead in itertools.product(cls.fractions, (0.3, 0.6)):
            r = fraction * span
            features, targets = [], []
            for u, _, residual in records:
                s = np.asarray(stop_operator(jnp.asarray(u), r))
                up = np.clip((s / r - dead) / (1 - dead), 0, 1)
                down = np.clip((-s / r - dead) / (1 - dead), 0, 1)
                features.append(np.stack([up, down], 1))
                targets.append(np.asarray(residual))
            upper, lower = ridge(features, targets)
            cost = sum(
                float(np.sum((t - X @ [upper, lower]) ** 2))
                for X, t in zip(features, targets, strict=True)
            )
            rows.append((cost, r, dead, upper, lower))
        # The two best structures by least squares on the residual start the refit.
        rows = sorted(rows)[:2]
        columns = np.array(rows).T[1:]
        effect = _batched(
            cls, threshold=columns[0], dead=columns[1], upper=columns[2], lower=columns[3]
        )
        return [Start(cls.name, model.orders, _repeat(model, len(rows)), effect)]

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])


class PrandtlIshlinskii(Effect):
    name: ClassVar[str] = "prandtl_ishlinskii"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "Prandtl-Ishlinskii sum of stop operators (thresholds on a grid, fixed) and hinges "
        "of each, linear in the weights"
    )
    fixed: ClassVar[tuple[str, ...]] = ("thresholds", "knots")
    sizes: ClassVar[tuple[int, ...]] = (4, 8, 16)
    regularisations: ClassVar[tuple[float, ...]] = (1e-6, 1e-4, 1e-2)
    knot_values: ClassVar[tuple[float, ...]] = (0.5, 0.9)
    refine_steps: ClassVar[int] = 20

    thresholds: Float[Array, " K"]
    knots: Float[Array, " J"]
    weights: Float[Array, " P"]
    offset: Float[Array, ""]

    def parallel(self, u):
        return pi_basis(u, self.thresholds, self.knots) @ self.weights + self.offset

    @classmethod
    def grid(cls, span: float, size: int) -> np.ndarray:
        """Thresholds from 1% to 50% of the input span, geometrically spaced."""
        return np.geomspace(0.01 * span, 0.5 * span, size)

    @classmethod
    def _basis(cls, records, thresholds):
        knots = jnp.asarray(cls.knot_values)
        out = []
        for u, _, _ in records:
            X = np.asarray(pi_basis(jnp.asarray(u), jnp.asarray(thresholds), knots))
            out.append(np.concatenate([X, np.ones((len(X), 1))], 1))
        return out

    @classmethod
    def select(cls, records):
        """Grid size and ridge parameter by cross-validation: leave one record out (each
        record weighted by 1/length), or first half / second half for one record.
        Returns `(thresholds, weights, offset, cv_table)`."""
        if len(records) == 1:
            u, y, e = (np.asarray(a) for a in records[0])
            h = len(u) // 2
            folds_of = [(u[:h], y[:h], e[:h]), (u[h:], y[h:], e[h:])]
        else:
            folds_of = list(records)
        span = _span(np.concatenate([np.asarray(r[0]) for r in records]))
        table = []
        for size in cls.sizes:
            thresholds = cls.grid(span, size)
            X = cls._basis(folds_of, thresholds)
            targets = [np.asarray(r[2]) for r in folds_of]
            w = [1.0 / len(t) for t in targets]
            for lam in cls.regularisations:
                errors = []
                for k in range(len(X)):
                    keep = [i for i in range(len(X)) if i != k]
                    theta = ridge(
                        [X[i] for i in keep], [targets[i] for i in keep], [w[i] for i in keep], lam
                    )
                    errors.append(np.mean((targets[k] - X[k] @ theta) ** 2) / np.var(targets[k]))
                table.append((size, lam, float(np.mean(errors))))
        size, lam, _ = min(table, key=lambda row: row[2])
        thresholds = cls.grid(span, size)
        X = cls._basis(records, thresholds)
        targets = [np.asarray(r[2]) for r in records]
        theta = ridge(X, targets, [1.0 / len(t) for t in targets], lam)
        return thresholds, theta[:-1], theta[-1], table

    @classmethod
    def starts_records(cls, model, records):
        thresholds, weights, offset, _ = cls.select(records)
        effect = _batched(
            cls,
            thresholds=[thresholds],
            knots=[list(cls.knot_values)],
            weights=[weights],
            offset=[offset],
        )
        return [Start(cls.name, model.orders, _repeat(model, 1), effect)]

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])


class DahlFriction(Effect):
    name: ClassVar[str] = "dahl_friction"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "Dahl friction: dF = sigma du (1 - F/level sgn du), in parallel with the cascade"
    )
    fractions: ClassVar[tuple[float, ...]] = (0.02, 0.1, 0.3)
    refine_steps: ClassVar[int] = 30

    sigma: Float[Array, ""]
    level: Float[Array, ""]

    def parallel(self, u):
        # A negative level is a force opposing the usual sign convention of the record.
        level = jnp.abs(self.level) + 1e-6
        return jnp.sign(self.level) * dahl(u, jnp.abs(self.sigma), level)

    @classmethod
    def starts_records(cls, model, records):
        span = _span(np.concatenate([r[0] for r in records]))
        rows = []
        for fraction in cls.fractions:
            # A unit-level Dahl force reaches 63% of its level after a travel 1/sigma;
            # the level then enters linearly.
            sigma = 1.0 / (fraction * span)
            X = [np.asarray(dahl(jnp.asarray(u), sigma, 1.0))[:, None] for u, _, _ in records]
            targets = [np.asarray(r[2]) for r in records]
            (level,) = ridge(X, targets)
            cost = sum(
                float(np.sum((t - level * x[:, 0]) ** 2)) for x, t in zip(X, targets, strict=True)
            )
            rows.append((cost, sigma, level))
        rows = sorted(rows)[:1]
        effect = _batched(cls, sigma=[r[1] for r in rows], level=[r[2] for r in rows])
        return [Start(cls.name, model.orders, _repeat(model, len(rows)), effect)]

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])


class InputBacklash(Effect):
    name: ClassVar[str] = "input_backlash"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "backlash (play operator, half-width gap) in front of the static nonlinearity"
    )
    fractions: ClassVar[tuple[float, ...]] = (0.02, 0.05, 0.1, 0.2)
    refine_steps: ClassVar[int] = 30

    gap: Float[Array, ""]

    def input(self, u):
        return u - stop_operator(u, jnp.abs(self.gap))

    @classmethod
    def starts(cls, model, u, y, residual):
        span = _span(u)
        gaps = [fraction * span for fraction in cls.fractions]
        effect = _batched(cls, gap=gaps)
        return [Start(cls.name, model.orders, _repeat(model, len(gaps)), effect)]
