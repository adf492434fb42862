"""Advice from the evidence: when the final model scores worse than the mean or the
linear peer, what the records and the residual show, and the option that addresses it.

Each kind of evidence is a rule on the estimation records' output (in their own units)
or on what the loop found, stated here with its threshold (rules of thumb, not fitted to
any record):

- `integrating`: the output integrates its input (`_integrating`): the loop modelled its
  difference and still scores poorly (friction on the velocity of a positioning system,
  or a loop closed around the output), or `--integrate no` left it to a stable model, or
  the ARX peer is stable with a slow pole and an integrator's gain at zero frequency
  (`_integrating.leaky_integrator`: friction or a controller pulled the integrator's
  pole inside) and the loop modelled the output itself (`--integrate no`, or `auto`
  where the validation record preferred the declared cascade on the output);
- `sign_blind`: the output never goes below a floor it touches in sharp V-shaped
  minima (`SIGN_BLIND_TOUCHES` or more, no flat stretch): a sign-blind sensor, |x|, or a
  rectifier;
- `clipped`: the output sits exactly at its largest or smallest value on at least
  `CLIP_SHARE` of its samples, and on at least `CLIP_RATIO` times as many as at any
  value between (a continuous signal repeats no value; a quantised one repeats each of
  its levels, its extremes least): a sensor's or an actuator's limit;
- `quantised`: the output takes at most `QUANTISED_LEVELS` levels on a grid of one
  step: quantisation alone leaves an NRMSE near `step / sqrt(12) / std(y)`;
- `range`: a validation or test record leaves the estimation records' input range
  (`_coverage`);
- `missing_effect`: residual tests still fail after the loop and none of the above
  explains them: a mechanism the effect library lacks.

`advise` returns the `Advice` that apply, each with its sentence; the loop's verdict
(`_scoring.verdict`) puts them after a poor score in place of the generic list of
options.
"""

from __future__ import annotations

import dataclasses

import numpy as np

# a clipped output sits at its extreme on at least this share of its samples
CLIP_SHARE = 0.01
# and on this many times as many samples as at any value between its extremes
CLIP_RATIO = 2.0
# a quantised output takes at most this many distinct levels, on one grid
QUANTISED_LEVELS = 64
# a sign-blind output touches its floor in at least this many sharp minima
SIGN_BLIND_TOUCHES = 5
# "at the floor": within this share of the output's range above its minimum
FLOOR_BAND = 0.02


@dataclasses.dataclass(frozen=True)
class Advice:
    """One kind of evidence (`kind`, module docstring), what the records show
    (`evidence`) and the option that addresses it (`option`)."""

    kind: str
    evidence: str
    option: str

    @property
    def sentence(self) -> str:
        return f"{self.evidence}: {self.option}"

    def to_dict(self) -> dict:
        return {**dataclasses.asdict(self), "sentence": self.sentence}


def _held(y: np.ndarray, level: float) -> float:
    """The share of `y`'s samples exactly at `level` (one of its extremes) where that is a
    limit it is held at (`clipped`, module docstring), else 0."""
    values, counts = np.unique(y, return_counts=True)
    at = int(counts[values == level][0])
    between = counts[(values > y.min()) & (values < y.max())]
    most = int(between.max()) if between.size else 1
    share = at / y.size
    return share if share >= CLIP_SHARE and at >= CLIP_RATIO * most else 0.0


def clipped(y) -> Advice | None:
    """`clipped` (module docstring) on one output, in its units."""
    y = np.asarray(y, float)
    if not np.ptp(y) > 0:
        return None
    for side, level in (("largest", y.max()), ("smallest", y.min())):
        share = _held(y, level)
        if share:
            return Advice(
                "clipped",
                f"The output sits at its {side} value, {level:.4g}, on {100 * share:.1f} % of "
                "the estimation samples: it is clipped (a sensor's or an actuator's limit)",
                "the effect output_saturation models a clipped output (--effects "
                "output_saturation), or cut the records to where the output is in range "
                "(a record spec's START:STOP)",
            )
    return None


def quantised(y) -> Advice | None:
    """`quantised` (module docstring) on one output, in its units."""
    y = np.asarray(y, float)
    levels = np.unique(y)
    if not 3 <= levels.size <= QUANTISED_LEVELS or levels.size > y.size // 10:
        return None
    gaps = np.diff(levels)
    step = float(gaps.min())
    if not step > 0 or not np.allclose(gaps / step, np.round(gaps / step), atol=1e-3):
        return None
    floor = step / np.sqrt(12.0) / float(np.std(y))
    return Advice(
        "quantised",
        f"The output takes {levels.size} levels in steps of {step:.4g}: quantisation alone "
        f"leaves an NRMSE near {floor:.3g}",
        "a score near that is the record's resolution, not the model's; a finer sensor "
        "resolution, or averaging over samples (--decimate), lowers it",
    )


def sign_blind(y) -> Advice | None:
    """`sign_blind` (module docstring) on one output, in its units."""
    y = np.asarray(y, float)
    span = float(np.ptp(y))
    if not span > 0 or y.size < 10:
        return None
    floor = float(y.min())
    band = floor + FLOOR_BAND * span
    # local minima at the floor, entered and left steeply (a V, not a flat)
    inner = y[1:-1]
    before, after = inner - y[:-2], y[2:] - inner
    step = float(np.median(np.abs(np.diff(y)))) or span / y.size
    touches = (inner <= band) & (before < -step / 2) & (after > step / 2)
    count = int(np.sum(touches))
    if count < SIGN_BLIND_TOUCHES or _held(y, floor):  # held at the floor: clipped
        return None
    return Advice(
        "sign_blind",
        f"The output never goes below {floor:.4g} and touches it in {count} sharp V-shaped "
        "minima: it is sign-blind (a sensor that reads |x|, a rectifier)",
        "the effect output_fold models an output folded at a level (--effects output_fold)",
    )


def integrating(
    integration: dict | None,
    unstable_pole: float | None,
    leaky: tuple[float, float] | None = None,
) -> Advice | None:
    """`integrating` (module docstring): `integration` the loop's (`_integrating.
    integration`), `unstable_pole` the ARX peer's largest pole where no stable one fits,
    `leaky` the stable peer's `(pole, gain)` where `_integrating.leaky_integrator` finds
    them."""
    if integration is not None:
        pole = integration.get("largest_arx_pole")
        shown = f" (the best ARX model's largest pole at |z| = {pole:.4f})" if pole else ""
        return Advice(
            "integrating",
            f"The output integrates its input{shown}; the loop modelled its difference and "
            f"integrated it back (--integrate {integration.get('option', 'auto')})",
            "friction on a positioning system's velocity is the effect velocity_friction "
            "(--effects velocity_friction); an output held by a controller (a position "
            "under feedback) is a closed loop no cascade describes: model the plant from "
            "its own input, or the closed loop from its reference",
        )
    if unstable_pole is not None:
        return Advice(
            "integrating",
            "No stable linear ARX model fits the estimation records (the best one's largest "
            f"pole is at |z| = {unstable_pole:.4f}): the output integrates its input",
            "leave --integrate at auto (the loop then models the output's difference), or "
            "--integrate yes",
        )
    if leaky is not None:
        pole, gain = leaky
        return Advice(
            "integrating",
            f"The best linear ARX model is stable but its largest pole is at |z| = {pole:.4f} "
            f"and its gain at zero frequency is {gain:.3g} times std(y) / std(u): an output "
            "that integrates its input looks so when friction or a controller pulls the "
            "fitted pole inside the unit circle, and the loop modelled the output itself",
            "--integrate yes models the output's difference and integrates it back (with "
            "velocity_friction for friction on a positioning system's velocity)",
        )
    return None


def out_of_range(uncovered: list[str]) -> Advice | None:
    """`range` (module docstring): `uncovered` the names of the scored records that leave
    the estimation range (`_coverage.uncovered`)."""
    if not uncovered:
        return None
    return Advice(
        "range",
        f"{', '.join(uncovered)} {'leaves' if len(uncovered) == 1 else 'leave'} the "
        "estimation records' input range (the report's input coverage)",
        "estimation records whose input covers the scored records' (more varied "
        "estimation records) measure the structure rather than its extrapolation",
    )


def missing_effect(failed: list[str]) -> Advice | None:
    """`missing_effect` (module docstring): `failed` the residual tests the final model
    still fails."""
    if not failed:
        return None
    return Advice(
        "missing_effect",
        f"After the loop the residual still fails the {', '.join(sorted(failed))} "
        f"test{'s' if len(failed) > 1 else ''}",
        "no effect of the library removed it: a mechanism it lacks (the effects are listed "
        "by jaxcascade loop --help, --effects; docs/architecture.md says how to add one), or "
        "other --orders",
    )


def advise(
    outputs,
    *,
    integration: dict | None = None,
    unstable_pole: float | None = None,
    leaky: tuple[float, float] | None = None,
    uncovered: list[str] = (),
    failed: list[str] = (),
) -> list[Advice]:
    """The advice that applies (module docstring), in order of the kinds there.
    `outputs`: the estimation records' outputs in their own units (each checked alone,
    the first finding of a kind kept); the rest what the loop found."""
    found = []
    advice = integrating(integration, unstable_pole, leaky)
    if advice is not None:
        found.append(advice)
    for rule in (sign_blind, clipped, quantised):
        hits = [rule(y) for y in outputs]
        hit = next((a for a in hits if a is not None), None)
        if hit is not None:
            found.append(hit)
    advice = out_of_range(list(uncovered))
    if advice is not None:
        found.append(advice)
    if not found:
        advice = missing_effect(list(failed))
        if advice is not None:
            found.append(advice)
    return found
