"""Plain-NumPy reference for the effect library (the test oracle of `jc.EFFECTS`).

Written from the effects' documented definitions, one sample at a time, with explicit
Python loops, like `oracle.py` for the cascade (whose `simulate` it uses for the
cascade itself). It imports nothing from jaxcascade: it reads the effects' parameter
values from the model object (`model.params.to_dict()`, each effect's fields and its
documented constants, written out here: `ROTOR_STARTS`), never the package's code.

The definitions, and where they are documented:

- the extended model (`jaxcascade/_measured/_effects/_base.py`, module docstring and
  `ExtendedModel`): `y = output_effects(cascade(input_effects(u)), x)`, the effects in
  the order of `model.effects`; a parallel path (the hysteresis effects but
  `input_backlash`, `_effects/_hysteresis.py`) is a function of the model's input `u`,
  added to the output.
- `output_offset`: `y + d`; `output_drift`: `y + d t / 1000`, `t` the sample's index
  (the record's first sample is index 0: `OutputDrift.rest_state`, "the index of the
  record's first sample", is 0); `output_saturation`: `y` clipped to `[lower, upper]`;
  `output_feedthrough`: `y + d x`, `x` the linear block's output; `input_delay`:
  `u(t - d)`, zero before the record; `dynamics_order`, `pwl_segment`: no parameters
  of their own (they change the cascade's orders: `oracle.simulate`).
- the operators (`jaxcascade/_measured/_effects/_operators.py`, module docstring): the stop operator
  `s(t) = clip(s(t-1) + u(t) - u(t-1), -r, r)` from `s = 0` with `u(-1) = u(0)`; the
  play operator `p(t) = u(t) - s(t)`; Dahl friction
  `F(t) = F(t-1) + sigma du (1 - F(t-1)/Fc sgn(du))` clipped to `|F| <= Fc`, from
  `F = 0`; backlash friction: `s(t) = clip(s(t-1) + du, -(g + F-/k), g + F+/k)`,
  `F = k (max(s - g, 0) + min(s + g, 0))`, averaged over the starts `s(0) = g * f`
  (`f` in `start_fractions`, clipped to the limits); the Prandtl-Ishlinskii basis
  `s_k / r_k`, `max(s_k / r_k - c, 0)`, `max(-s_k / r_k - c, 0)` (`pi_basis`).
- `slack_friction` (`_effects/_hysteresis.py`): a stop operator of threshold `r`, then
  `F = upper clip((s/r - dead)/(1 - dead), 0, 1) + lower clip((-s/r - dead)/(1 - dead), 0, 1)`.
- `backlash_friction`, `backlash_friction_contacts`: `offset` plus backlash friction of
  `|gap|, |stiffness|, |upper|, |lower|` ("signs of the first four are immaterial").
- `prandtl_ishlinskii`: `F = c + sum_k w_k . basis_k(u)`. The docstrings name the basis
  functions but not the order of the weights; this reference lays them out as
  `pi_basis`'s docstring lists them, in blocks: the K stops `s_k / r_k`, then the hinges
  `max(s_k / r_k - c_j, 0)` (k major, j minor), then `max(-s_k / r_k - c_j, 0)`.
- `dahl_friction`: `F = dahl(u; sigma, level)`; a negative level is the force with the
  opposite sign (`DahlFriction.parallel`: "a force opposing the usual sign convention"),
  `sgn(level) dahl(u; |sigma|, |level|)`.
- `input_backlash`: `y = cascade(play(u))`, play operator of half-width `|gap|`.
- the terms inside the linear block's recursion (`_effects/_recursion.py`,
  `_effects/_feedback.py`): `x(t) = sum_i a_i v(t-i) - sum_j b_j x(t-j) + term(v(t),
  x(t-1), x(t) so far)`, the terms of every such effect added in order, `x` held within
  `+-LIMIT` (1e6):
  `nonlinear_feedback` `k2 x(t-1)^2 + k3 x(t-1)^3`; `direct_term` `d v(t)`;
  `velocity_friction` `-clip(x, -|f-|, |f+|)` of the value `x(t)` has so far (the
  linear recursion's plus the terms of the effects before it).
- the maps after the cascade (`_effects/_wiener.py`): `output_polynomial` `y + c0 + c2
  y^2 + c3 y^3`, and `inner_polynomial` the same map, acting just before the first
  `output_dynamics` when added after it; `output_fold` `c0 + c1 sqrt((y - s)^2 +
  EPS^2) + c2 (y - s)^2`, EPS = 1e-3 (`FOLD_EPS`); `inner_kink` `y + c0 + c1 sqrt((y -
  s)^2 + EPS^2)`, acting where `inner_polynomial` does; `output_dynamics` `w(t) = y(t) +
  sum_i beta_i y(t-i)`, `out(t) = w(t) - sum_j alpha_j out(t-j)`, from rest, plus
  `offset`.
- `general_backlash` (`_effects/_curved.py`, `docs/general_backlash.md`): the cascade's
  backlash with curved branches on its own `cL`, `mR`, `cR`:
  `fL = (x + cL) + sum_i curveL[i-2] (x + cL)^i`, `fR = mR (x - cR) + sum_i
  curveR[i-2] (x - cR)^i`; the output pushed down onto `fL` where it lies below the
  previous output, else up onto `fR` where it lies above it, else held; from `y = 0`.

`simulate(model, u, effective=...)` takes optional replacements of the values read from
the model (a test that states a documented-elsewhere deviation explicitly).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import oracle


def _value(x) -> float:
    return float(np.asarray(x))


def _array(x) -> np.ndarray:
    return np.asarray(x, dtype=float)


def sign(x: float) -> float:
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


def clip(x: float, low: float, high: float) -> float:
    return min(max(x, low), high)


# ---- operators ------------------------------------------------------------------------


def stop(u, r: float, s0: float = 0.0, u_prev: float | None = None) -> np.ndarray:
    """Stop operator of threshold `r`: `s(t) = clip(s(t-1) + u(t) - u(t-1), -r, r)`,
    from `s(-1) = s0` after the input `u_prev` (default `u(0)`: no first increment)."""
    u = _array(u)
    previous = float(u[0]) if u_prev is None else float(u_prev)
    s = float(s0)
    out = np.zeros(len(u))
    for t in range(len(u)):
        s = clip(s + (float(u[t]) - previous), -r, r)
        previous = float(u[t])
        out[t] = s
    return out


def play(u, r: float) -> np.ndarray:
    """Play operator (backlash) of half-width `r`: `p(t) = u(t) - s(t)`."""
    return _array(u) - stop(u, r)


def slack(u, r: float, dead: float, upper: float, lower: float) -> np.ndarray:
    """Slack friction: the stop operator of threshold `r`, then the slack map."""
    s = stop(u, r)
    out = np.zeros(len(s))
    for t in range(len(s)):
        x = s[t] / r
        up = clip((x - dead) / (1.0 - dead), 0.0, 1.0)
        down = clip((-x - dead) / (1.0 - dead), 0.0, 1.0)
        out[t] = upper * up + lower * down
    return out


def backlash_friction(u, gap, stiffness, upper, lower, fractions) -> np.ndarray:
    """Backlash friction force, the mean over the starts `s(0) = gap * f` (clipped)."""
    u = _array(u)
    low, high = -(gap + lower / stiffness), gap + upper / stiffness
    total = np.zeros(len(u))
    for f in fractions:
        s = clip(gap * float(f), low, high)
        previous = float(u[0])
        for t in range(len(u)):
            s = clip(s + (float(u[t]) - previous), low, high)
            previous = float(u[t])
            total[t] += stiffness * (max(s - gap, 0.0) + min(s + gap, 0.0))
    return total / len(fractions)


def dahl(u, sigma: float, level: float, f0: float = 0.0) -> np.ndarray:
    """Dahl friction `F(t) = F(t-1) + sigma du (1 - F(t-1)/level sgn du)`, clipped to
    `|F| <= level`, from `F = f0` with `u(-1) = u(0)`."""
    u = _array(u)
    previous, f = float(u[0]), float(f0)
    out = np.zeros(len(u))
    for t in range(len(u)):
        du = float(u[t]) - previous
        previous = float(u[t])
        f = f + sigma * du * (1.0 - f / level * sign(du))
        f = clip(f, -level, level)
        out[t] = f
    return out


def pi_basis(u, thresholds, knots) -> np.ndarray:
    """The Prandtl-Ishlinskii basis, `T x K (1 + 2 J)` (layout: module docstring)."""
    thresholds, knots = _array(thresholds), _array(knots)
    K, J = len(thresholds), len(knots)
    stops = [stop(u, float(r)) / float(r) for r in thresholds]
    out = np.zeros((len(_array(u)), K * (1 + 2 * J)))
    for t in range(out.shape[0]):
        for k in range(K):
            x = stops[k][t]
            out[t, k] = x
            for j in range(J):
                out[t, K + k * J + j] = max(x - knots[j], 0.0)
                out[t, K + K * J + k * J + j] = max(-x - knots[j], 0.0)
    return out


def delay(u, d: int) -> np.ndarray:
    """`u(t - d)`, zero before the record."""
    u = _array(u)
    return np.array([u[t - d] if t - d >= 0 else 0.0 for t in range(len(u))])


def general_backlash(x, cL: float, mR: float, cR: float, curveL, curveR) -> np.ndarray:
    """The general backlash's rule, sample by sample (module docstring)."""
    y, out = 0.0, np.empty(len(x))
    for t, xt in enumerate(np.asarray(x, float)):
        fL = (xt + cL) + sum(c * (xt + cL) ** i for i, c in enumerate(curveL, start=2))
        fR = mR * (xt - cR) + sum(c * (xt - cR) ** i for i, c in enumerate(curveR, start=2))
        if fL < y:
            y = fL
        elif fR > y:
            y = fR
        out[t] = y
    return out


# ---- the extended model ---------------------------------------------------------------


def parameters(effect) -> dict:
    """The effect's parameter values (its fields) and the documented class constants the
    definitions use, as floats or float arrays."""
    values = {}
    for field in dataclasses.fields(effect):
        value = _array(getattr(effect, field.name))
        values[field.name] = float(value) if value.ndim == 0 else value
    if effect.name in ROTOR_STARTS:
        values["start_fractions"] = ROTOR_STARTS[effect.name]
    return values


# The rotor's starts averaged over, fractions of the slack half-width, as documented and
# written out here (not read from the package's classes, so that a changed constant is
# caught): `backlash_friction` "evenly on the slack" (nine starts, its class comment),
# `backlash_friction_contacts` "at rest against either side of the slack (mean of the
# two)" (its description).
ROTOR_STARTS = {
    "backlash_friction": np.linspace(-1.0, 1.0, 9),
    "backlash_friction_contacts": np.array([-1.0, 1.0]),
}


def _input_effect(name, p, u):
    if name == "input_delay":
        return delay(u, int(p["delay"]))
    if name == "input_backlash":
        return play(u, abs(p["gap"]))
    return u


# The documented constant of the output fold, written out here (not read from the class,
# so that a changed constant is caught).
FOLD_EPS = 1e-3
LIMIT = 1e6


def _term(name, p, v_t, x_prev, x_new):
    """One effect's term inside the linear block's recursion, or 0."""
    if name == "nonlinear_feedback":
        k2, k3 = p["coefficients"]
        return k2 * x_prev**2 + k3 * x_prev**3
    if name == "direct_term":
        return float(np.ravel(p["gain"])[0]) * v_t
    if name == "velocity_friction":
        f_up, f_down = (abs(f) for f in p["forces"])
        return -clip(x_new, -f_down, f_up)
    return 0.0


RECURSION = ("nonlinear_feedback", "direct_term", "velocity_friction")


def linear_with_terms(P: dict, v, effects) -> np.ndarray:
    """The linear block with the effects' terms inside its recursion, one sample at a
    time, from rest."""
    a = [1.0, *P["a"]]
    b = list(P["b"])
    x = np.zeros(len(v))
    for t in range(len(v)):
        value = sum(a[i - 1] * oracle.past(v, t - i) for i in range(1, len(a) + 1))
        value -= sum(b[j - 1] * oracle.past(x, t - j) for j in range(1, len(b) + 1))
        for name, p in effects:
            value += _term(name, p, v[t], oracle.past(x, t - 1), value)
        x[t] = clip(value, -LIMIT, LIMIT)
    return x


def _output_effect(name, p, y, x):
    if name in ("output_polynomial", "inner_polynomial"):
        c0, c2, c3 = p["coefficients"]
        return y + c0 + c2 * y**2 + c3 * y**3
    if name == "output_fold":
        c0, c1, c2, s = p["coefficients"]
        return c0 + c1 * np.sqrt((y - s) ** 2 + FOLD_EPS**2) + c2 * (y - s) ** 2
    if name == "inner_kink":
        c0, c1, s = p["coefficients"]
        return y + c0 + c1 * np.sqrt((y - s) ** 2 + FOLD_EPS**2)
    if name == "output_dynamics":
        beta, alpha = np.atleast_1d(p["zeros"]), np.atleast_1d(p["poles"])
        out = np.zeros(len(y))
        for t in range(len(y)):
            w = y[t] + sum(beta[i - 1] * oracle.past(y, t - i) for i in range(1, len(beta) + 1))
            out[t] = w - sum(
                alpha[j - 1] * oracle.past(out, t - j) for j in range(1, len(alpha) + 1)
            )
        return out + p["offset"]
    if name == "output_offset":
        return y + p["offset"]
    if name == "output_drift":
        return np.array([y[t] + p["slope"] * t / 1000.0 for t in range(len(y))])
    if name == "output_saturation":
        return np.array([clip(y[t], p["lower"], p["upper"]) for t in range(len(y))])
    if name == "output_feedthrough":
        return y + p["gain"] * x
    return y


def _parallel(name, p, u):
    if name == "slack_friction":
        return slack(u, p["threshold"], p["dead"], p["upper"], p["lower"])
    if name in ("backlash_friction", "backlash_friction_contacts"):
        magnitudes = (abs(p[k]) for k in ("gap", "stiffness", "upper", "lower"))
        return p["offset"] + backlash_friction(u, *magnitudes, p["start_fractions"])
    if name == "prandtl_ishlinskii":
        return pi_basis(u, p["thresholds"], p["knots"]) @ p["weights"] + p["offset"]
    if name == "dahl_friction":
        return sign(p["level"]) * dahl(u, abs(p["sigma"]), abs(p["level"]))
    return None


STRUCTURAL = ("dynamics_order", "pwl_segment")
INNER = ("inner_polynomial", "inner_kink")
KNOWN = (
    "output_offset",
    "output_drift",
    "output_saturation",
    "output_feedthrough",
    "input_delay",
    "input_backlash",
    "slack_friction",
    "backlash_friction",
    "backlash_friction_contacts",
    "prandtl_ishlinskii",
    "dahl_friction",
    "general_backlash",
    *RECURSION,
    "output_polynomial",
    "output_fold",
    "output_dynamics",
    "inner_polynomial",
    "inner_kink",
    *STRUCTURAL,
)


def simulate(model, u, effective: dict | None = None) -> np.ndarray:
    """Noise-free output of an `ExtendedModel` (with its cascade) for the input `u`.

    `effective`: `{effect name: {parameter: value}}` replacing values read from the
    model (default none)."""
    assert model.cascade, "the reference covers models with their cascade"
    effective = effective or {}
    u_model = _array(u)
    effects = []
    for effect in model.effects:
        if effect.name not in KNOWN:
            raise NotImplementedError(f"no reference for effect {effect.name!r}")
        effects.append((effect.name, {**parameters(effect), **effective.get(effect.name, {})}))
    u_in = u_model
    for name, p in effects:
        u_in = _input_effect(name, p, u_in)
    P = oracle.unpack({k: float(v) for k, v in model.params.to_dict().items()}, model.params.orders)
    terms = [(name, p) for name, p in effects if name in RECURSION]
    if terms:
        x = linear_with_terms(P, oracle.pwl(P, u_in), terms)
        y = oracle.backlash(P, x)
    else:
        _, x, y = oracle.simulate(P, u_in)
    for name, p in effects:
        if name == "general_backlash":  # in place of the cascade's straight backlash
            curves = (np.atleast_1d(p["curveL"]), np.atleast_1d(p["curveR"]))
            y = general_backlash(x, P["cL"], P["mR"], P["cR"], *curves)
    # in the order added, but an inner map (inner_polynomial, inner_kink) acts just before
    # the first output_dynamics (the static part of the sandwich)
    block = next((i for i, (name, _) in enumerate(effects) if name == "output_dynamics"), None)
    if block is not None:
        moved = [i > block and e[0] in INNER for i, e in enumerate(effects)]
        inner = [e for e, m in zip(effects, moved, strict=True) if m]
        rest = [e for e, m in zip(effects, moved, strict=True) if not m]
        at = next(i for i, (name, _) in enumerate(rest) if name == "output_dynamics")
        effects = rest[:at] + inner + rest[at:]
    for name, p in effects:
        y = _output_effect(name, p, y, x)
        path = _parallel(name, p, u_model)
        if path is not None:
            y = y + path
    return y
