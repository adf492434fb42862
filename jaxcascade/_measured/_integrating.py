"""Outputs that integrate their input: modelled through their difference (host side).

A position under feedback (EMPS: a motor's force in, the load's position out) integrates
its input: no stable model, the cascade or a linear ARX, follows it in free run, and every
equation-error ARX fit has a pole on the unit circle. Such a record is modelled through
its difference `dy(t) = y(t) - y(t-1)` (a velocity), which the cascade can describe, and
the model's output is integrated back for scoring, its position set from the measured
output as any other state:

- from rest: `y(0) = 0`, `y(t) = sum of dy(1..t)`;
- initialised on `[start - n, start)`: the difference model's state set on the measured
  differences of that window, and `y(t) = y_measured(start - 1) + sum of dy(start..t)`.

`integrates(u, y)` is the test: no stable ARX model up to order 4 fits the record, or the
best one has a pole within 1e-3 of the unit circle (`_arx.best_arx`) that a zero does not
cancel (its gain at zero frequency large against the output's spread over the input's: an
integrator's is unbounded; a friction force against a displacement has a slow pole that a
zero nearly cancels, and a bounded output); `integration`
applies it to the loop's estimation records under the option `auto`, `yes` or `no`
(`--integrate`) and says what it did in one sentence. Where the best stable fit's pole is
merely slow, with an integrator's gain (`leaky_integrator`: friction pulled the pole
inside), `auto` lets the validation record choose between the declared cascade fitted on
the output and on its difference (`leaky_choice`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._arx import best_arx

# A pole this close to 1 (or beyond) in the ARX peer is an integrator: at 1 kHz it is a
# time constant of 1 s held for ever in free run.
INTEGRATOR_POLE = 0.999
# ... and an integrator's gain at zero frequency, |B(1) / A(1)|, is at least this many times
# std(y) / std(u): an integrator's is unbounded (an axis under proportional control, whose
# fitted pole leaks a little: 15 to 85); a slow pole nearly cancelled by a zero is not one
# (the friction damper's force against its displacement at 1 kHz, pole 0.9991: 1.4).
INTEGRATOR_GAIN = 5.0
# A stable ARX fit whose largest pole is at least this close to 1, with an integrator's
# gain (`INTEGRATOR_GAIN`), may be an integrator whose pole the equation-error fit pulled
# inside the unit circle (Coulomb friction on an axis under proportional control: poles
# 0.97 to 0.998, gains 7 to 37 in `_testing.axis_record`'s seeds 2 to 7; CED, Silverbox,
# the stand-ins and every record of the friction damper: gains 0.07 to 1.5). It is not
# one for sure: a slow stable system under a broadband input has such a gain too
# (sqrt((1 + p) / (1 - p)) for a first-order pole p under white noise). So `--integrate
# auto` fits the declared cascade both ways there and the validation record chooses
# (`leaky_choice`, the loop's workflow); after a poor score the advice names it.
LEAKY_POLE = 0.95


def static_gain(arx, u, y) -> float:
    """The ARX model's gain at zero frequency, |B(1) / A(1)|, in units of
    std(y) / std(u) (infinite where A(1) = 0)."""
    a1 = 1.0 + float(np.sum(arx.a))
    b1 = float(np.sum(arx.b))
    scale = np.std(u) / max(float(np.std(y)), np.finfo(float).tiny)
    return abs(b1) * scale / abs(a1) if a1 != 0 else np.inf


def integrates(u, y) -> float | None:
    """The largest pole magnitude of the best ARX fit of `(u, y)` when no stable ARX
    model fits, or when it is at least `INTEGRATOR_POLE` and the fit's gain at zero
    frequency at least `INTEGRATOR_GAIN` (`static_gain`): the output integrates its
    input; else None."""
    try:
        arx = best_arx(u, y)
    except ValueError:
        return best_arx(u, y, stable=False).largest_pole
    pole = arx.largest_pole
    if pole < INTEGRATOR_POLE or static_gain(arx, u, y) < INTEGRATOR_GAIN:
        return None
    return pole


def leaky_integrator(arx, u, y) -> tuple[float, float] | None:
    """`(largest pole, gain at zero frequency)` of the stable ARX fit `arx` of `(u, y)`
    (`static_gain`'s units) where the pole is at least `LEAKY_POLE` and the gain at least
    `INTEGRATOR_GAIN`: an output that may integrate its input though `integrates` saw
    none; else None."""
    pole = float(arx.largest_pole)
    if not LEAKY_POLE <= pole < 1.0:
        return None
    gain = float(static_gain(arx, u, y))
    return (pole, gain) if gain >= INTEGRATOR_GAIN else None


def leaky_choice(leaky, level: float, difference: float) -> dict | None:
    """`integration`'s answer for a record with a `leaky_integrator` `(pole, gain)`, once
    the declared cascade was fitted on the output (validation NRMSE `level`) and on its
    difference (`difference`, of the output integrated back): the difference's where it
    scores lower, else None."""
    if not difference < level:
        return None
    pole, gain = leaky
    sentence = (
        f"The output integrates its input (the best stable ARX model's largest pole is at "
        f"|z| = {pole:.4f}, its gain at zero frequency {gain:.3g} times std(y) / std(u); the "
        f"declared cascade fitted on the output's difference scores validation NRMSE "
        f"{difference:.4g}, on the output itself {level:.4g}): the loop models its "
        "difference y(t) - y(t-1) and integrates the model's output back for scoring, its "
        "position set from the measured output like any other state (--integrate no turns "
        "this off)."
    )
    return {
        "largest_arx_pole": pole,
        "option": "auto",
        "sentence": sentence,
        "leaky": {"gain": gain, "level_error": level, "difference_error": difference},
    }


INTEGRATE_OPTIONS = ("auto", "yes", "no")


def integration(records, option: str = "auto") -> dict | None:
    """Whether the loop models the output of the estimation `records` (`_data.Record`s)
    through its difference: None where not (`option` "no", or "auto" and `integrates`
    finds a stable ARX fit), else `{"largest_arx_pole" (None where "yes" forced it),
    "option", "sentence"}`, the sentence the loop prints and reports."""
    if option not in INTEGRATE_OPTIONS:
        raise ValueError(
            f"integrate must be one of {', '.join(INTEGRATE_OPTIONS)}, got {option!r}."
        )
    if option == "no":
        return None
    pole = integrates(
        np.concatenate([r.u for r in records]), np.concatenate([r.y for r in records])
    )
    if option == "auto" and pole is None:
        return None
    sentence = (
        "The output integrates its input"
        + (
            f" (no stable linear ARX model fits it; the best one's largest pole is at "
            f"|z| = {pole:.4f})"
            if pole is not None
            else ""
        )
        + ": a stable model cannot follow it in free run, so the loop models its "
        "difference y(t) - y(t-1) and integrates the model's output back for scoring, "
        "its position set from the measured output like any other state (--integrate no "
        "turns this off)."
    )
    return {"largest_arx_pole": pole, "option": option, "sentence": sentence}


def differenced(record):
    """A `_data.Record` with its output replaced by the output's difference (one sample
    shorter: `u[1:]`, `y[1:] - y[:-1]`)."""
    time = None if record.time is None else record.time[1:]
    return dataclasses.replace(record, u=record.u[1:], y=np.diff(record.y), time=time)


def integrated(from_rest, initialised):
    """Position forms of a difference model's scoring functions (`_scoring`): `from_rest(u)`
    and `initialised(u, y, start, n)` of the *difference* model, on the *measured* record
    `(u, y)`. Returns the pair for the integrated output."""

    def rest(u):
        u = np.asarray(u, float)
        return np.concatenate([[0.0], np.cumsum(np.asarray(from_rest(u[1:]), float))])

    def init(u, y, start, n):
        u, y = np.asarray(u, float), np.asarray(y, float)
        start = max(int(start), 1)
        dy = np.diff(y)
        steps = np.asarray(initialised(u[1:], dy, start - 1, max(int(n) - 1, 0)), float)
        return y[start - 1] + np.cumsum(steps)

    return rest, init
