"""An effect's fields in the records' units: each effect declares the unit of every field
(`Effect.units`, a class-level table), and one function maps them (`record_units`).

The records' units follow the cascade's (`_data.Scaling.params_to_physical`): a model
unit signal `s` is the record's `offset + scale * s`, and the model is
`y - y_offset = cascade(u - u_offset)`. The cascade's inner signals (the static block's
output `v`, the linear block's `x`) are in the output's units, relative to zero (`x`
times `y_scale`, as the backlash gaps). So the output chain's signals are the record's
output, a polynomial, a filter or a path acts on the output less `y_offset` (as the
cascade does), and a level that the output is compared with (a clip, a fold) is a level
of the record's output itself.

Kinds (`record = factor * model + offset`):

- `"unitless"`: factor 1 (a delay in samples, a pole, a zero, a gain from `x` or `v` to
  the output, a fraction).
- `"input"`: `u_scale`, a change of the input (a threshold, a gap on the input).
- `"input_level"`: `u_scale`, plus `u_offset` (a level of the record's input).
- `"output"`: `y_scale`, a change of the output or of `x` (an offset added to the output,
  a force of a parallel path, a drift, a friction force on `x`).
- `"output_level"`: `y_scale`, plus `y_offset` (a level of the record's output: a clip,
  a fold, the output at a fold).
- `"output_per_input"`: `y_scale / u_scale` (a stiffness, a Dahl rate).
- `"output_power(k)"`: `y_scale ** (1 - k)`, the coefficient of the `k`-th power of a
  signal in the output's units (relative to `y_offset`) in a term in the output's units
  (`output_power(0)` is `output`, `output_power(1)` unitless).
- `"output_powers(k)"`: an array of such coefficients of the powers `k, k + 1, ...`.
- `"model"`: kept in model units: a field with no map to the records' units (none of
  the library's effects has one now; the schema then leaves it out of `parameters`).

A field's kind is one kind for every entry, or a tuple of kinds, one per entry (a
polynomial's coefficients `c0, c2, c3`). A standard error maps with `|factor|` alone
(an offset does not change a spread). The small constants of an effect's equations
(`FLOOR`, `EPS`) are in model units: the records' form of an equation has them times the
field's scale.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

KINDS = (
    "unitless",
    "input",
    "input_level",
    "output",
    "output_level",
    "output_per_input",
    "model",
)
_POWER = re.compile(r"output_power\((-?\d+)\)")
_POWERS = re.compile(r"output_powers\((-?\d+)\)")


def valid_kind(kind: str) -> bool:
    return kind in KINDS or bool(_POWER.fullmatch(kind) or _POWERS.fullmatch(kind))


def element_kinds(kind: str | tuple[str, ...], size: int) -> list[str]:
    """The kind of each of a field's `size` entries (flattened)."""
    if isinstance(kind, tuple):
        if len(kind) != size:
            raise ValueError(f"{len(kind)} kinds {kind} for a field of {size} entries")
        return list(kind)
    powers = _POWERS.fullmatch(kind)
    if powers is not None:
        return [f"output_power({int(powers.group(1)) + i})" for i in range(size)]
    return [kind] * size


def unit_map(kind: str, scaling) -> tuple[float, float] | None:
    """`(factor, offset)` of one entry's kind, `record = factor * model + offset`; None
    for `"model"` (kept in model units)."""
    power = _POWER.fullmatch(kind)
    if power is not None:
        return scaling.y_scale ** (1 - int(power.group(1))), 0.0
    maps = {
        "unitless": (1.0, 0.0),
        "input": (scaling.u_scale, 0.0),
        "input_level": (scaling.u_scale, scaling.u_offset),
        "output": (scaling.y_scale, 0.0),
        "output_level": (scaling.y_scale, scaling.y_offset),
        "output_per_input": (scaling.y_scale / scaling.u_scale, 0.0),
        "model": None,
    }
    if kind not in maps:
        raise ValueError(f"unknown unit kind {kind!r}")
    return maps[kind]


def field_kinds(effect) -> dict[str, list[str]]:
    """`{field: [kind of each entry]}` of one (unbatched) effect, from its class's
    `units`; a `ValueError` for a field it does not declare."""
    out = {}
    for field in dataclasses.fields(effect):
        if field.name not in type(effect).units:
            raise ValueError(f"effect {effect.name} declares no unit for its field {field.name}")
        size = int(np.size(getattr(effect, field.name)))
        out[field.name] = element_kinds(type(effect).units[field.name], size)
    return out


def _shaped(values: list, like):
    like = np.asarray(like)
    if like.ndim == 0:
        return values[0]
    return np.reshape(np.asarray(values, object), like.shape).tolist()


def record_units(effect, scaling, errors: dict | None = None) -> tuple[dict, dict, dict]:
    """One (unbatched) effect in the records' units: `(parameters, std_errors, units)`,
    each by field in the shapes of `Effect.parameters` (`units`: the declared kind, a
    string, or a list of one per entry as declared). `errors`: the standard errors
    in model units in the same shapes (None entries stay None); fields of kind
    `"model"` are left out of `parameters` and `std_errors`."""
    errors = {} if errors is None else errors
    parameters, std_errors, units = {}, {}, {}
    for name, kinds in field_kinds(effect).items():
        value = np.asarray(getattr(effect, name), float)
        declared = type(effect).units[name]
        units[name] = list(declared) if isinstance(declared, tuple) else declared
        maps = [unit_map(k, scaling) for k in kinds]
        if any(m is None for m in maps):
            continue
        flat = value.ravel()
        parameters[name] = _shaped(
            [float(f * v + o) for (f, o), v in zip(maps, flat, strict=True)], value
        )
        error = errors.get(name)
        if error is None:
            flat_errors = [None] * flat.size
        else:
            flat_errors = list(np.ravel(np.asarray(error, dtype=object)))
        std_errors[name] = _shaped(
            [
                None if e is None else abs(f) * float(e)
                for (f, _), e in zip(maps, flat_errors, strict=True)
            ],
            value,
        )
    return parameters, std_errors, units
