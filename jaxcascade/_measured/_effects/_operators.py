"""Hysteresis operators: stop and play operators, the Prandtl-Ishlinskii basis, Dahl and
LuGre friction (traceable, `lax.scan`), and a ridge least-squares fit of weights that
enter linearly (host side).

- Stop operator (elastic-plastic element) with threshold `r >= 0`, from state `s(0) = 0`:
  `s(t) = clip(s(t-1) + u(t) - u(t-1), -r, r)`, with `u(-1) = u(0)`. On a triangle wave of
  amplitude `A > r` it follows the input's increments and saturates at `+-r`.
- Play operator (backlash) with half-width `r`: `p(t) = u(t) - s(t)`, the position of a
  body dragged through a slack of width `2r`.
- Prandtl-Ishlinskii / Maxwell-slip basis: stop operators on a grid of thresholds
  `r_1 < ... < r_K`, and hinge functions `max(+-s_k / r_k - c, 0)` of each; a weighted
  sum of the basis is linear in its weights.
- Dahl friction: `F(t) = F(t-1) + sigma du (1 - F(t-1)/Fc sgn(du))`, `du = u(t) - u(t-1)`,
  the rate-independent first-order friction model (Dahl 1968), clipped to `|F| <= Fc`.
- LuGre friction (Canudas de Wit et al. 1995) with direction-dependent levels:
  `dz/dt = v - sigma0 |v| z / g(v)`, `g(v) = Fc(v) + (Fs(v) - Fc(v)) exp(-(v/vs)^2)`,
  `F = sigma0 z + sigma1 dz/dt + sigma2 v`, levels `Fc, Fs` chosen by `sgn v`; the
  bristle state is integrated exactly over each step for constant `v` (stable for any
  step: `z -> z_ss + (z - z_ss) exp(-sigma0 |v| dt / g)`).
- Backlash friction (Coulomb friction behind a slack, with a contact stiffness): a rotor
  held by friction levels `F+` (sliding forward) and `F-` (sliding back) is driven through
  a slack of half-width `g` by a contact of stiffness `k`. With `s` the actuator's
  position relative to the rotor (a stop operator with limits `-(g + F-/k)`,
  `g + F+/k`): `s(t) = clip(s(t-1) + u(t) - u(t-1), -(g + F-/k), g + F+/k)`,
  `F = k (max(s - g, 0) + min(s + g, 0))`. The force is 0 in the slack `|s| <= g`,
  rises with slope `k` on contact and saturates at `F+` or `-F-` while the rotor
  slides. Where the rotor starts in the slack is unknown from the displacement:
  `backlash_friction` averages the force over several starts `s(0)` (the mean prediction
  over a prior on the initial position: evenly spaced on `[-g, g]`, or `+-g`, at rest
  against either side); every start gives the same force once the rotor has slid both
  ways.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


@jax.jit
def stop_operators(u, thresholds):
    """Stop operators of `u` for each threshold.

    **Arguments:** `u`: `Float[Array, " T"]`; `thresholds`: `Float[Array, " K"]` (>= 0).

    **Returns:** `Float[Array, "T K"]`.
    """
    thresholds = jnp.asarray(thresholds, u.dtype)
    du = jnp.diff(u, prepend=u[:1])

    def step(s, d):
        s = jnp.clip(s + d, -thresholds, thresholds)
        return s, s

    _, out = jax.lax.scan(step, jnp.zeros_like(thresholds), du)
    return out


def stop_operator(u, threshold):
    """One stop operator: `Float[Array, " T"]`."""
    return stop_operators(u, jnp.reshape(threshold, (1,)))[:, 0]


def play_operator(u, threshold):
    """Play operator (backlash of half-width `threshold` starting centred on `u(0)`)."""
    return u - stop_operator(u, threshold) - u[0]


@jax.jit
def pi_basis(u, thresholds, knots):
    """The Prandtl-Ishlinskii basis: for each threshold `r_k`, `s_k / r_k` and the hinges
    `max(s_k / r_k - c, 0)`, `max(-s_k / r_k - c, 0)` for `c` in `knots` (in `[0, 1)`).

    **Returns:** `Float[Array, "T K*(1 + 2 len(knots))"]`.
    """
    s = stop_operators(u, thresholds) / jnp.asarray(thresholds, u.dtype)
    knots = jnp.asarray(knots, u.dtype)
    up = jnp.maximum(s[:, :, None] - knots, 0.0)
    down = jnp.maximum(-s[:, :, None] - knots, 0.0)
    return jnp.concatenate([s, up.reshape(s.shape[0], -1), down.reshape(s.shape[0], -1)], 1)


def slack_map(s, r, dead, upper, lower, stiffness_ratio=None):
    """Static map of a stop operator's output `s` (in `[-r, r]`): zero in the dead zone
    `|s| <= dead r`, rising linearly to the plateau `upper` at `s = r` and to `lower` at
    `s = -r` (direction-dependent levels). `dead` in `[0, 1)`."""
    x = s / r
    ramp_up = jnp.clip((x - dead) / (1 - dead), 0.0, 1.0)
    ramp_down = jnp.clip((-x - dead) / (1 - dead), 0.0, 1.0)
    return upper * ramp_up + lower * ramp_down


def backlash_friction(u, gap, stiffness, upper, lower, starts=(0.0,)):
    """Backlash friction force (module docstring) for the displacement `u`: slack
    half-width `gap`, contact stiffness `stiffness`, levels `upper = F+` and
    `lower = F-` (all > 0), averaged over the initial positions `s(0) = gap * starts`
    (`starts`: fractions of the half-width; 0 the centre of the slack, +-1 at rest
    against either side, beyond +-1 a preloaded contact, clipped to the limits).
    Traceable and differentiable in every parameter almost everywhere.

    **Returns:** `Float[Array, " T"]`.
    """
    dtype = u.dtype
    gap, stiffness, upper, lower = (jnp.asarray(v, dtype) for v in (gap, stiffness, upper, lower))
    lo, hi = -(gap + lower / stiffness), gap + upper / stiffness
    s0 = jnp.clip(gap * jnp.atleast_1d(jnp.asarray(starts, dtype)), lo, hi)
    du = jnp.diff(u, prepend=u[:1])

    def step(s, d):
        s = jnp.clip(s + d, lo, hi)
        force = stiffness * (jnp.maximum(s - gap, 0.0) + jnp.minimum(s + gap, 0.0))
        return s, jnp.mean(force)

    _, out = jax.lax.scan(step, s0, du)
    return out


def backlash_friction_start(force, gap, stiffness, offset=0.0):
    """The start fraction (`backlash_friction`'s `starts`) of a rotor in contact with the
    initial force `force` (0: the centre of the slack): `sgn(f) (1 + |f| / (k gap))`,
    `f = force - offset`. For comparisons that use a measured initial force."""
    f = float(force) - float(offset)
    if f == 0.0:
        return 0.0
    return float(np.sign(f) * (1.0 + abs(f) / (float(stiffness) * float(gap))))


@jax.jit
def dahl(u, sigma, level):
    """Dahl friction force (module docstring); `level = Fc > 0`."""
    du = jnp.diff(u, prepend=u[:1])

    def step(f, d):
        f = f + sigma * d * (1 - f / level * jnp.sign(d))
        f = jnp.clip(f, -level, level)
        return f, f

    _, out = jax.lax.scan(step, jnp.zeros((), u.dtype), du)
    return out


@jax.jit
def lugre(u, dt, sigma0, sigma1, sigma2, fc_pos, fc_neg, fs_pos, fs_neg, vs):
    """LuGre friction force (module docstring) for the displacement `u`, sample period
    `dt`; velocity by the backward difference."""
    v = jnp.diff(u, prepend=u[:1]) / dt

    def step(z, vt):
        pos = vt >= 0
        fc = jnp.where(pos, fc_pos, fc_neg)
        fs = jnp.where(pos, fs_pos, fs_neg)
        g = jnp.maximum(fc + (fs - fc) * jnp.exp(-((vt / vs) ** 2)), 1e-9)
        z_ss = jnp.sign(vt) * g / sigma0
        z_new = z_ss + (z - z_ss) * jnp.exp(-sigma0 * jnp.abs(vt) * dt / g)
        dz = (z_new - z) / dt
        force = sigma0 * z_new + sigma1 * dz + sigma2 * vt
        return z_new, force

    _, out = jax.lax.scan(step, jnp.zeros((), u.dtype), v)
    return out


def normal_equations(X, y, w=1.0) -> tuple[np.ndarray, np.ndarray]:
    """One record's terms of `ridge`'s normal equations: `(X'wX, X'wy)`."""
    X = np.asarray(X)
    return X.T @ (X * np.reshape(w, (-1, 1))), X.T @ (np.asarray(y) * w)


def ridge_solve(terms, regularisation: float = 1e-6) -> np.ndarray:
    """`ridge` from the records' `normal_equations`, summed in their order (so that a
    cross-validation that forms each record's terms once gets `ridge`'s numbers bit
    for bit)."""
    gram = sum(term[0] for term in terms)
    rhs = sum(term[1] for term in terms)
    size = gram.shape[0]
    gram = gram + regularisation * np.trace(gram) / size * np.eye(size)
    # minimum-norm where features vanish on these records (a threshold beyond the
    # record's travel gives an all-zero column, and an all-zero Gram has no ridge)
    return np.linalg.lstsq(gram, rhs, rcond=None)[0]


def ridge(features, targets, weights=None, regularisation: float = 1e-6):
    """Weighted ridge least squares (host side): `argmin sum w (y - X theta)^2 + lambda
    |theta|^2` with `lambda = regularisation * trace(X'WX) / P` (scale-free).

    **Arguments:** lists of `X_i` (`T_i x P`), `y_i` (`T_i`) and optional per-record
    weights `w_i` (scalars or arrays); one list entry per record.
    """
    weights = weights or [1.0] * len(features)
    terms = [normal_equations(X, y, w) for X, y, w in zip(features, targets, weights, strict=True)]
    return ridge_solve(terms, regularisation)


_LUGRE = ("sigma0", "sigma1", "sigma2", "fc_pos", "fc_neg", "fs_pos", "fs_neg", "vs")


def fit_lugre(records, dt: float, max_steps: int = 200) -> dict[str, float]:
    """LuGre friction (`lugre`, plus an output offset) fitted by output-error
    Levenberg-Marquardt on several records `[(u, y), ...]` jointly, each simulated from
    rest; every parameter but the offset through its logarithm (positive). A peer model
    for measured friction, in the records' units. Returns `{name: value}`."""
    from ..._estimator._levenberg import least_squares

    us = tuple(jnp.asarray(u) for u, _ in records)
    ys = tuple(jnp.asarray(y, us[0].dtype) for _, y in records)
    span = float(max(np.max(np.abs(np.asarray(u))) for u, _ in records))
    level = float(np.mean([np.quantile(np.abs(np.asarray(y)), 0.9) for _, y in records]))
    speed = float(np.mean([np.std(np.diff(np.asarray(u))) / dt for u, _ in records]))
    start = [level / (0.05 * span), 1e-3, 0.1 * level / speed, level, level]
    start += [1.2 * level, 1.2 * level, speed]
    z0 = jnp.asarray(np.log(start).tolist() + [0.0], us[0].dtype)

    def model(z, u):
        p = jnp.exp(z[:-1])
        return lugre(u, dt, *p) + z[-1]

    def residual(z, args):
        return jnp.concatenate([model(z, u) - y for u, y in zip(us, ys, strict=True)])

    z, *_ = jax.jit(lambda z0: least_squares(residual, z0, None, max_steps=max_steps))(z0)
    z = np.asarray(z)
    return {**dict(zip(_LUGRE, np.exp(z[:-1]).tolist(), strict=True)), "offset": float(z[-1])}


def simulate_lugre(params: dict[str, float], u, dt: float):
    """Force of a fitted LuGre model (`fit_lugre`) for the displacement `u`."""
    u = jnp.asarray(u)
    return lugre(u, dt, *(params[name] for name in _LUGRE)) + params["offset"]


# State-carrying forms (`_initial_state`): the same recursions continued from a given
# state instead of from rest. `position` is the operator's state after the sample before
# `u(0)`, and `u_prev` that sample's input: the first increment is `u(0) - u_prev`
# (from rest: position 0 or the start fractions, `u_prev = u(0)`, as above). Each
# returns the trajectory of its state, from which a caller reads the state at any sample.


def stop_operators_from(u, thresholds, position, u_prev):
    """`stop_operators` from the positions `position` (`Float[Array, " K"]`) after the
    input `u_prev`. **Returns:** the positions, `Float[Array, "T K"]`."""
    thresholds = jnp.asarray(thresholds, u.dtype)
    du = jnp.diff(u, prepend=jnp.reshape(jnp.asarray(u_prev, u.dtype), (1,)))

    def step(s, d):
        s = jnp.clip(s + d, -thresholds, thresholds)
        return s, s

    _, out = jax.lax.scan(step, jnp.asarray(position, u.dtype), du)
    return out


def pi_basis_from(u, thresholds, knots, position, u_prev):
    """`pi_basis` from the stop operators' positions `position` after `u_prev`.
    **Returns:** `(basis, positions)`."""
    thresholds = jnp.asarray(thresholds, u.dtype)
    positions = stop_operators_from(u, thresholds, position, u_prev)
    s = positions / thresholds
    knots = jnp.asarray(knots, u.dtype)
    up = jnp.maximum(s[:, :, None] - knots, 0.0)
    down = jnp.maximum(-s[:, :, None] - knots, 0.0)
    basis = jnp.concatenate([s, up.reshape(s.shape[0], -1), down.reshape(s.shape[0], -1)], 1)
    return basis, positions


def backlash_friction_limits(gap, stiffness, upper, lower):
    """The stop operator's limits `(-(gap + lower/stiffness), gap + upper/stiffness)` of
    `backlash_friction`: the admissible relative positions."""
    return -(gap + lower / stiffness), gap + upper / stiffness


def backlash_friction_from(u, gap, stiffness, upper, lower, position, u_prev):
    """`backlash_friction` from the relative positions `position` (one per averaged
    start, `Float[Array, " K"]`) after the input `u_prev`.

    **Returns:** `(force, positions)`, `Float[Array, " T"]` and `Float[Array, "T K"]`.
    """
    dtype = u.dtype
    gap, stiffness, upper, lower = (jnp.asarray(v, dtype) for v in (gap, stiffness, upper, lower))
    lo, hi = backlash_friction_limits(gap, stiffness, upper, lower)
    du = jnp.diff(u, prepend=jnp.reshape(jnp.asarray(u_prev, dtype), (1,)))

    def step(s, d):
        s = jnp.clip(s + d, lo, hi)
        force = stiffness * (jnp.maximum(s - gap, 0.0) + jnp.minimum(s + gap, 0.0))
        return s, (jnp.mean(force), s)

    _, (force, positions) = jax.lax.scan(step, jnp.asarray(position, dtype), du)
    return force, positions


def dahl_from(u, sigma, level, force, u_prev):
    """`dahl` from the force `force` (a scalar) after the input `u_prev`.
    **Returns:** the force, `Float[Array, " T"]` (the operator's state)."""
    du = jnp.diff(u, prepend=jnp.reshape(jnp.asarray(u_prev, u.dtype), (1,)))

    def step(f, d):
        f = f + sigma * d * (1 - f / level * jnp.sign(d))
        f = jnp.clip(f, -level, level)
        return f, f

    _, out = jax.lax.scan(step, jnp.asarray(force, u.dtype), du)
    return out
