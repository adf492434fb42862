"""Hysteresis effects of the model-error loop (operators in `_hysteresis`).

Each is a path in parallel with the cascade (`Effect.parallel`: its force is added to
the cascade's output) except `InputBacklash`, which acts on the input. Their residual
signature is the `hysteresis` test of `_diagnose` (the residual depends on the direction
of motion or on a stop operator of the input), and the loop tries them only when that
test failed (`Effect.needs_signature`).

Fitting. `SlackFriction`, `PrandtlIshlinskii` and `DahlFriction` are linear in their
weights once a structure is fixed (a threshold, a grid of thresholds, a rate): each
structure of a small grid gives features of the input, the weights are a ridge
least-squares fit to the current model's residual (`_hysteresis.ridge`), and the
structure and the ridge parameter are chosen by leave-one-record-out cross-validation
over the estimation records (first half / second half when there is one record; each
record weighted by 1/length), never on the validation record (`fit_records`). The loop
then alternates a refit of the cascade on the output minus the path with a new ridge fit
(`_loop.fit_parallel`); no Levenberg-Marquardt refit of the extended model.
`InputBacklash` is nonlinear: the loop refits it with the cascade by output-error
Levenberg-Marquardt from the best gap of a grid.

- `SlackFriction` (issue 15 (a)): friction behind a slack zone. A stop operator with
  threshold `r` (the slack half-width plus the elastic travel) feeds the static map
  `slack_map`: zero for `|s| <= dead r`, linear ramps to the plateaus `upper` (at
  `s = r`, sliding forward) and `lower` (at `s = -r`, sliding back):
  `F = upper clip((s/r - dead)/(1 - dead), 0, 1) + lower clip((-s/r - dead)/(1 - dead), 0, 1)`.
  This is a rotor held by Coulomb friction and dragged through a slack of width
  `2 dead r` by a contact of stiffness `upper / ((1 - dead) r)`.
- `BacklashFriction` (issue 15 (a), physical form): Coulomb friction behind a slack with
  a contact stiffness (`_hysteresis.backlash_friction`): a stop operator with limits
  `-(gap + lower/stiffness)`, `gap + upper/stiffness` and
  `F = offset + stiffness (max(s - gap, 0) + min(s + gap, 0))`, averaged over
  initial positions of the rotor (`start_fractions`, unknown from the displacement:
  evenly on the slack); `BacklashFrictionContacts` (`backlash_friction_contacts`)
  averages over the two contacts instead (the rotor at rest against either side).
  Unlike `SlackFriction` its slack, stiffness and two levels are fitted jointly by
  output-error Levenberg-Marquardt on the residuals of the estimation records
  (each record weighted by 1/length) from a small grid of starts (`fit_records`); the
  loop alternates it with refits of the cascade like the linear paths.
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

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._compile import exported, pack, pad
from ..._status import Status
from ._base import (
    Effect,
    EffectState,
    ExtendedModel,
    Start,
    _batched,
    _repeat,
    recent,
    simulate_padded,
)
from ._operators import (
    backlash_friction,
    backlash_friction_from,
    backlash_friction_limits,
    dahl,
    dahl_from,
    normal_equations,
    pi_basis,
    pi_basis_from,
    ridge,
    ridge_solve,
    slack_map,
    stop_operator,
    stop_operators,
    stop_operators_from,
)

_SIGNATURE = ("hysteresis",)


def _operator_state(position, u) -> EffectState:
    """An operator's state before the record `u`: its positions, and the input before
    the first sample taken equal to it (no first increment), as the operators do."""
    return EffectState(jnp.asarray(position, u.dtype), u[:1])


def _operator_after(state, positions, u, at) -> EffectState:
    """The operator's state before sample `at`, from its trajectory `positions`."""
    joined = jnp.concatenate(
        [jnp.reshape(state.free, (1, -1)), jnp.reshape(positions, (len(u), -1))]
    )
    return EffectState(joined[at].reshape(state.free.shape), recent(state.known, u, at))


def _stops(u, thresholds) -> np.ndarray:
    """`stop_operators` of one record on the host, its length padded to a bucket (one
    compiled program per bucket and threshold count, `_compile.pad`)."""
    n = np.shape(u)[0]
    thresholds = jax.device_put(np.asarray(thresholds))
    return np.asarray(stop_operators(jax.device_put(pad(u)), thresholds))[:n]


def _span(u) -> float:
    u = np.asarray(u)
    return float(np.quantile(u, 0.995) - np.quantile(u, 0.005)) or 1.0


REGULARISATIONS = (1e-8, 1e-6, 1e-4, 1e-2)


def _folds(records):
    """Cross-validation folds: the records, or the two halves of a single record."""
    if len(records) > 1:
        return [tuple(np.asarray(a) for a in r) for r in records]
    u, y, e = (np.asarray(a) for a in records[0])
    h = len(u) // 2
    return [(u[:h], y[:h], e[:h]), (u[h:], y[h:], e[h:])]


def cross_validate(structures, features, records, regularisations=REGULARISATIONS):
    """Choose a structure and a ridge parameter by leave-one-fold-out cross-validation
    of a ridge fit to the residuals (`_folds`; each fold weighted by 1/length, its error
    normalised by its residual variance), then fit the weights on every record.

    **Arguments:** `structures`: a list of hashable structures; `features(structure,
    u)`: the `T x P` features of the input `u`; `records`: `[(u, y, residual), ...]`.

    **Returns:** `(structure, weights, table)`, `table` rows `(structure, ridge, error)`.
    """
    folds = _folds(records)
    targets = [f[2] for f in folds]
    w = [1.0 / len(t) for t in targets]
    table = []
    for structure in structures:
        X = [features(structure, f[0]) for f in folds]
        # each fold's normal equations once (`ridge` sums the same terms in order)
        terms = [normal_equations(*fold) for fold in zip(X, targets, w, strict=True)]
        for lam in regularisations:
            errors = []
            for k in range(len(X)):
                theta = ridge_solve([t for i, t in enumerate(terms) if i != k], lam)
                errors.append(
                    np.mean((targets[k] - X[k] @ theta) ** 2) / (np.var(targets[k]) or 1.0)
                )
            table.append((structure, lam, float(np.mean(errors))))
    structure, lam, _ = min(table, key=lambda row: row[2])
    X = [features(structure, np.asarray(r[0])) for r in records]
    targets = [np.asarray(r[2]) for r in records]
    theta = ridge(X, targets, [1.0 / len(t) for t in targets], lam)
    return structure, theta, table


class _LinearPath(Effect):
    """A parallel path linear in its weights for a fixed structure (module docstring)."""

    linear: ClassVar[bool] = True
    needs_signature: ClassVar[bool] = True

    @classmethod
    def fit_records(cls, model, records) -> tuple[Effect, str]:
        """The effect (unbatched) fitted to the residuals of `records`
        `[(u, y, residual), ...]` (structure by cross-validation), and a label."""
        raise NotImplementedError

    @classmethod
    def starts_records(cls, model, records):
        effect, label = cls.fit_records(model, records)
        batched = _batched(cls, **{k: [v] for k, v in effect.parameters().items()})
        return [Start(label, model.orders, _repeat(model, 1), batched)]

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])


class SlackFriction(_LinearPath):
    name: ClassVar[str] = "slack_friction"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "friction behind a slack zone: stop operator (threshold r) then a dead zone "
        "(|s| <= dead r) and plateaus upper, lower"
    )
    # Structures: thresholds (fractions of the input span) x dead-zone fractions.
    fractions: ClassVar[tuple[float, ...]] = (0.02, 0.035, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3)
    deads: ClassVar[tuple[float, ...]] = (0.0, 0.2, 0.4, 0.6, 0.8)
    # The stop operator's threshold is r = |threshold| + FLOOR (its sign immaterial, kept
    # off zero, where the operator and its derivative are undefined); `dead` is clipped
    # to [0, 0.98].
    FLOOR: ClassVar[float] = 1e-6

    units: ClassVar[dict] = {
        "threshold": "input",
        "dead": "unitless",  # a fraction of the threshold
        "upper": "output",
        "lower": "output",
    }

    threshold: Float[Array, ""]
    dead: Float[Array, ""]
    upper: Float[Array, ""]
    lower: Float[Array, ""]

    def parallel(self, u):
        r = jnp.abs(self.threshold) + self.FLOOR
        s = stop_operator(u, r)
        dead = jnp.clip(self.dead, 0.0, 0.98)
        return slack_map(s, r, dead, self.upper, self.lower)

    def rest_state(self, u):
        return _operator_state(jnp.zeros((1,)), u)

    def parallel_with_state(self, u, state, at):
        r = jnp.abs(self.threshold) + self.FLOOR
        s = stop_operators_from(u, jnp.reshape(r, (1,)), state.free, state.known[0])
        dead = jnp.clip(self.dead, 0.0, 0.98)
        force = slack_map(s[:, 0], r, dead, self.upper, self.lower)
        return force, _operator_after(state, s, u, at)

    def state_range(self, state):
        r = jnp.abs(self.threshold) + self.FLOOR
        return -r * jnp.ones_like(state.free), r * jnp.ones_like(state.free)

    @classmethod
    def fit_records(cls, model, records):
        span = _span(np.concatenate([np.asarray(r[0]) for r in records]))
        radii = np.array(cls.fractions) * span
        cache = {}

        def features(structure, u):
            k, dead = structure
            key = (id(u), len(u))
            if key not in cache:
                cache[key] = (u, _stops(u, radii) / radii)
            x = cache[key][1][:, k]
            up = np.clip((x - dead) / (1 - dead), 0, 1)
            down = np.clip((-x - dead) / (1 - dead), 0, 1)
            return np.stack([up, down], 1)

        structures = list(itertools.product(range(len(radii)), cls.deads))
        (k, dead), (upper, lower), _ = cross_validate(structures, features, records)
        effect = cls(*(jnp.asarray(float(v)) for v in (radii[k], dead, upper, lower)))
        return effect, f"{cls.name}:r={cls.fractions[k]:g}span,dead={dead:g}"


class BacklashFriction(_LinearPath):
    """Coulomb friction behind a slack (module docstring). Not linear in its
    parameters: it reuses the linear paths' route through the loop (`fit_records` on the
    residuals, alternating with refits of the cascade), with an output-error
    Levenberg-Marquardt fit (`fit`) in place of the ridge fit.

    Parameters: `gap` (slack half-width, input units), `stiffness` (contact stiffness,
    output per input unit), `upper`, `lower` (friction levels sliding forward and back,
    > 0), `offset` (output offset). Signs of the first four are immaterial."""

    name: ClassVar[str] = "backlash_friction"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "Coulomb friction (levels upper, lower) behind a slack (half-width gap) through a "
        "contact of stiffness k, averaged over the rotor's unknown start in the slack"
    )
    # Initial positions of the rotor averaged over, fractions of the slack half-width
    # (the prior on where it starts, unknown from the displacement): evenly on the slack.
    start_fractions: ClassVar[tuple[float, ...]] = tuple(np.linspace(-1.0, 1.0, 9).tolist())
    # Starts of the fit: slack half-width and elastic travel (level / stiffness) as
    # fractions of the input span.
    gap_fractions: ClassVar[tuple[float, ...]] = (0.01, 0.03, 0.1)
    travel_fractions: ClassVar[tuple[float, ...]] = (0.01, 0.04)
    max_steps: ClassVar[int] = 200
    # A start's fit also ends (converged) after an accepted step that lowers its cost by
    # less than this fraction of it (`least_squares`' `ftol`): the operator's kinks keep
    # the step-size test from passing while the cost has stopped falling, and the starts
    # run side by side until the last one ends.
    ftol: ClassVar[float] = 1e-10
    # The stiffness enters as |stiffness| + FLOOR (kept off zero, where the slack's
    # travel gap / stiffness is undefined).
    FLOOR: ClassVar[float] = 1e-9

    units: ClassVar[dict] = {
        "gap": "input",
        "stiffness": "output_per_input",
        "upper": "output",
        "lower": "output",
        "offset": "output",
    }

    gap: Float[Array, ""]
    stiffness: Float[Array, ""]
    upper: Float[Array, ""]
    lower: Float[Array, ""]
    offset: Float[Array, ""]

    def parallel(self, u):
        # Magnitudes: the sign of every parameter but the offset is immaterial.
        tiny = self.FLOOR
        return self.offset + backlash_friction(
            u,
            jnp.abs(self.gap),
            jnp.abs(self.stiffness) + tiny,
            jnp.abs(self.upper),
            jnp.abs(self.lower),
            self.start_fractions,
        )

    def _magnitudes(self):
        tiny = self.FLOOR
        return (
            jnp.abs(self.gap),
            jnp.abs(self.stiffness) + tiny,
            jnp.abs(self.upper),
            jnp.abs(self.lower),
        )

    def rest_state(self, u):
        # the rotor's relative position for each averaged start (`backlash_friction`)
        gap, stiffness, upper, lower = (jnp.asarray(v, u.dtype) for v in self._magnitudes())
        low, high = backlash_friction_limits(gap, stiffness, upper, lower)
        fractions = jnp.asarray(self.start_fractions, u.dtype)
        return _operator_state(jnp.clip(gap * fractions, low, high), u)

    def parallel_with_state(self, u, state, at):
        force, positions = backlash_friction_from(
            u, *self._magnitudes(), state.free, state.known[0]
        )
        return self.offset + force, _operator_after(state, positions, u, at)

    def state_range(self, state):
        low, high = backlash_friction_limits(*self._magnitudes())
        ones = jnp.ones_like(state.free)
        return low * ones, high * ones

    @classmethod
    def fit(cls, records) -> tuple[np.ndarray, float, int]:
        """Output-error fit to the targets of `records` `[(u, target), ...]` jointly
        (each record's squared error weighted by 1/length): parameters
        `(gap, stiffness, upper, lower, offset)`, the weighted mean squared error and the
        kept start's `Status` code (`converged` or `max_iterations`)."""
        us = [np.asarray(r[0], float) for r in records]
        ys = [np.asarray(r[1], float) for r in records]
        groups = pack(us, ys)
        # each record's squared error weighted by 1/length
        weights = tuple(
            jnp.asarray(M, M.dtype) / jnp.sum(M, axis=1, keepdims=True) ** 0.5 for _, _, M in groups
        )
        span = _span(np.concatenate(us))
        level = float(np.mean([np.quantile(np.abs(y), 0.9) for y in ys])) or 1.0
        # every start in one call: its steps run side by side (`vmap`), one program
        starts = [
            np.log([gap * span, level / (travel * span), level, level]).tolist() + [0.0]
            for gap, travel in itertools.product(cls.gap_fractions, cls.travel_fractions)
        ]
        zs, costs, statuses = _fit_backlash_friction(
            jax.device_put(np.asarray(starts)),
            groups,
            weights,
            tuple(cls.start_fractions),
            cls.max_steps,
            cls.ftol,
        )
        # on the host: indexing the device arrays would compile programs of its own
        zs, costs = np.asarray(zs), np.asarray(costs)
        costs = np.where(np.isfinite(costs), costs, np.inf)
        if not np.isfinite(costs).any():
            raise ValueError("backlash_friction: no start gave a finite fit")
        # the lowest cost; of equal ones the first start
        best = int(np.argmin(costs))
        z, cost, status = zs[best], float(costs[best]), int(np.asarray(statuses)[best])
        # `least_squares`'s cost is the mean over the padded samples
        padded = sum(int(M.size) for _, _, M in groups)
        return np.concatenate([np.exp(z[:4]), z[4:]]), cost * padded / len(ys), status

    @classmethod
    def fit_records(cls, model, records):
        theta, _, status = cls.fit([(r[0], r[2]) for r in records])
        effect = cls(*(jnp.asarray(float(v)) for v in theta))
        g, k, up, lo, _ = theta
        label = f"{cls.name}:gap={g:.3g},k={k:.3g},levels={up:.3g}/{lo:.3g}"
        if status != Status.converged:  # the label says where the fit stopped short
            label += f",{Status(status).name} ({cls.max_steps} steps)"
        return effect, label


@exported
def _fit_backlash_friction(z0, groups, weights, starts, max_steps, ftol):
    """Levenberg-Marquardt of `BacklashFriction.fit` from each row of `z0` on packed
    records (`_compile.pack`), the starts side by side (`vmap`): one compiled program
    per record buckets and number of starts, not per call, kept across processes
    (`_compile.exported`; `starts`, `max_steps` and `ftol` are static). Returns each start's
    parameters, cost and `Status` code."""
    from ..._estimator._levenberg import least_squares

    def residual(z, args):
        g, k, up, lo = jnp.exp(z[:4])

        def one(u, y):
            return z[4] + backlash_friction(u, g, k, up, lo, starts) - y

        return jnp.concatenate(
            [
                (jax.vmap(one)(U, Y) * c).reshape(-1)
                for (U, Y, _), c in zip(groups, weights, strict=True)
            ]
        )

    def one_start(z):
        z, cost, status, _ = least_squares(residual, z, None, max_steps=max_steps, ftol=ftol)
        return z, cost, status

    return jax.vmap(one_start)(z0)


class BacklashFrictionContacts(BacklashFriction):
    name: ClassVar[str] = "backlash_friction_contacts"
    description: ClassVar[str] = (
        "backlash_friction with the rotor starting at rest against either side of the "
        "slack (mean of the two)"
    )
    start_fractions: ClassVar[tuple[float, ...]] = (-1.0, 1.0)


class PrandtlIshlinskii(_LinearPath):
    name: ClassVar[str] = "prandtl_ishlinskii"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "Prandtl-Ishlinskii sum of stop operators (thresholds on a grid, fixed) and hinges "
        "of each, linear in the weights"
    )
    fixed: ClassVar[tuple[str, ...]] = ("thresholds", "knots")
    sizes: ClassVar[tuple[int, ...]] = (4, 8, 16, 24)
    knot_values: ClassVar[tuple[float, ...]] = (0.5, 0.9)

    # the basis is the stop operators over their thresholds and hinges of those
    # (`pi_basis`): unitless, so a weight is in the output's units
    units: ClassVar[dict] = {
        "thresholds": "input",
        "knots": "unitless",
        "weights": "output",
        "offset": "output",
    }

    thresholds: Float[Array, " K"]
    knots: Float[Array, " J"]
    weights: Float[Array, " P"]
    offset: Float[Array, ""]

    def parallel(self, u):
        return pi_basis(u, self.thresholds, self.knots) @ self.weights + self.offset

    def rest_state(self, u):
        return _operator_state(jnp.zeros(self.thresholds.shape), u)

    def parallel_with_state(self, u, state, at):
        basis, positions = pi_basis_from(u, self.thresholds, self.knots, state.free, state.known[0])
        return basis @ self.weights + self.offset, _operator_after(state, positions, u, at)

    def state_range(self, state):
        r = jnp.asarray(self.thresholds, state.free.dtype)
        return -r, r

    @classmethod
    def grid(cls, span: float, size: int) -> np.ndarray:
        """Thresholds from 1% to 50% of the input span, geometrically spaced."""
        return np.geomspace(0.01 * span, 0.5 * span, size)

    @classmethod
    def _features(cls, u, thresholds):
        knots = jnp.asarray(cls.knot_values)
        X = np.asarray(pi_basis(jnp.asarray(u), jnp.asarray(thresholds), knots))
        return np.concatenate([X, np.ones((len(X), 1))], 1)

    @classmethod
    def select(cls, records):
        """Grid size and ridge parameter by cross-validation (`cross_validate`).
        Returns `(thresholds, weights, offset, cv_table)`."""
        span = _span(np.concatenate([np.asarray(r[0]) for r in records]))
        grids = {size: cls.grid(span, size) for size in cls.sizes}
        every = np.concatenate(list(grids.values()))
        columns, at = {}, 0
        for size in cls.sizes:
            columns[size] = slice(at, at + size)
            at += size
        knots = np.asarray(cls.knot_values)
        cache = {}

        def features(size, u):
            # The stop operators of every grid at once, one scan per record (`pi_basis`
            # in NumPy from them).
            key = (id(u), len(u))
            if key not in cache:
                cache[key] = (u, _stops(u, every) / every)
            x = cache[key][1][:, columns[size]]
            up = np.maximum(x[:, :, None] - knots, 0.0).reshape(len(x), -1)
            down = np.maximum(-x[:, :, None] - knots, 0.0).reshape(len(x), -1)
            return np.concatenate([x, up, down, np.ones((len(x), 1))], 1)

        size, theta, table = cross_validate(list(cls.sizes), features, records)
        return grids[size], theta[:-1], theta[-1], table

    @classmethod
    def fit_records(cls, model, records):
        thresholds, weights, offset, _ = cls.select(records)
        effect = cls(
            jnp.asarray(thresholds),
            jnp.asarray(cls.knot_values),
            jnp.asarray(weights),
            jnp.asarray(float(offset)),
        )
        return effect, f"{cls.name}:K={len(thresholds)}"


class DahlFriction(_LinearPath):
    name: ClassVar[str] = "dahl_friction"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "Dahl friction: dF = sigma du (1 - F/level sgn du), in parallel with the cascade"
    )
    # A Dahl force is its level times a unit-level Dahl force of rate sigma / level: for
    # a fixed rate it is linear in the level. Rates: 1 / (fraction of the input span).
    fractions: ClassVar[tuple[float, ...]] = (0.01, 0.02, 0.05, 0.1, 0.2, 0.3)
    # The level enters as sgn(level) (|level| + FLOOR): kept off zero, where the Dahl
    # rate sigma / level is undefined.
    FLOOR: ClassVar[float] = 1e-6

    # dF = sigma du (..): a force per input
    units: ClassVar[dict] = {"sigma": "output_per_input", "level": "output"}

    sigma: Float[Array, ""]
    level: Float[Array, ""]

    def parallel(self, u):
        # A negative level is a force opposing the usual sign convention of the record.
        level = jnp.abs(self.level) + self.FLOOR
        return jnp.sign(self.level) * dahl(u, jnp.abs(self.sigma), level)

    def rest_state(self, u):
        # the unit-sign force of `dahl`, before the sign of the level
        return _operator_state(jnp.zeros((1,)), u)

    def parallel_with_state(self, u, state, at):
        level = jnp.abs(self.level) + self.FLOOR
        force = dahl_from(u, jnp.abs(self.sigma), level, state.free[0], state.known[0])
        return jnp.sign(self.level) * force, _operator_after(state, force, u, at)

    def state_range(self, state):
        level = jnp.abs(self.level) + self.FLOOR
        return -level * jnp.ones_like(state.free), level * jnp.ones_like(state.free)

    @classmethod
    def fit_records(cls, model, records):
        span = _span(np.concatenate([np.asarray(r[0]) for r in records]))

        def features(fraction, u):
            n = np.shape(u)[0]
            force = dahl(jax.device_put(pad(u)), 1.0 / (fraction * span), 1.0)
            return np.asarray(force)[:n, None]

        fraction, (level,), _ = cross_validate(list(cls.fractions), features, records)
        rate = 1.0 / (fraction * span)
        effect = cls(jnp.asarray(rate * abs(float(level))), jnp.asarray(float(level)))
        return effect, f"{cls.name}:travel={fraction:g}span"


def _simulate_padded(model, u) -> np.ndarray:
    """`simulate_extended` of one record on the host, padded like `_stops`."""
    return simulate_padded(model, u)[0]


class InputBacklash(Effect):
    name: ClassVar[str] = "input_backlash"
    signature: ClassVar[tuple[str, ...]] = _SIGNATURE
    description: ClassVar[str] = (
        "backlash (play operator, half-width gap) in front of the static nonlinearity"
    )
    fractions: ClassVar[tuple[float, ...]] = (0.02, 0.05, 0.1, 0.2)
    refine_steps: ClassVar[int] = 30
    needs_signature: ClassVar[bool] = True

    # a half-width on the input (the play operator commutes with the input's offset)
    units: ClassVar[dict] = {"gap": "input"}

    gap: Float[Array, ""]

    def input(self, u):
        return u - stop_operator(u, jnp.abs(self.gap))

    def rest_state(self, u):
        return _operator_state(jnp.zeros((1,)), u)

    def input_with_state(self, u, state, at):
        gap = jnp.reshape(jnp.abs(self.gap), (1,))
        s = stop_operators_from(u, gap, state.free, state.known[0])
        return u - s[:, 0], _operator_after(state, s, u, at)

    def state_range(self, state):
        gap = jnp.abs(self.gap)
        return -gap * jnp.ones_like(state.free), gap * jnp.ones_like(state.free)

    @classmethod
    def starts_records(cls, model, records):
        """One start: the gap of the grid whose model (the current cascade, not refitted)
        has the smallest squared error on the records."""
        span = _span(np.concatenate([np.asarray(r[0]) for r in records]))
        costs = []
        for fraction in cls.fractions:
            effect = cls(jnp.asarray(fraction * span))
            extended = ExtendedModel(model.params, (*model.effects, effect), model.noise)
            costs.append(
                sum(
                    float(np.sum((np.asarray(y) - _simulate_padded(extended, u)) ** 2))
                    for u, y, _ in records
                )
            )
        gap = cls.fractions[int(np.nanargmin(costs))] * span
        return [Start(cls.name, model.orders, _repeat(model, 1), _batched(cls, gap=[gap]))]

    @classmethod
    def starts(cls, model, u, y, residual):
        return cls.starts_records(model, [(u, y, residual)])
