"""One schema for a fitted model, in the records' units: how `fit_record`'s and the
loop's results, `jaxcascade fit --json`, `jaxcascade loop --json`, `report.json` and
`model.json` write a model and its standard errors (`docs/models.md` documents it).

    {
      "structure": "u -> pwl(2,2) -> linear(2,2) -> general_backlash(3) -> y",
      "cascade": true,
      "orders": {"nR": 2, "nL": 2, "r": 2, "p": 2, "degree": 3},
      "estimates": {"MR1": ..., ..., "cR": ..., "mL2": ..., "mL3": ..., "mR2": ..., "mR3": ...},
      "std_errors": {same names},
      "estimates_model_units": {same names}, "std_errors_model_units": {same names},
      "effects": [{"name": "general_backlash",
                   "units": {"mL2": "output_power(2)", ...},
                   "parameters": {"mL2": ..., ...}, "std_errors": {"mL2": ..., ...},
                   "parameters_model_units": {"mL2": ..., ...},
                   "std_errors_model_units": {"mL2": ..., ...}}],
      "noise": {"name": "colored_noise", "ar": [...]},
      "scaling": {"u_offset": ..., "u_scale": ..., "y_offset": ..., "y_scale": ..., "method": ...}
    }

- `estimates`, `std_errors`: the cascade's parameters by `Orders.names`, in the records'
  units (`_data.Scaling.params_to_physical`: the model is `y - y_offset = cascade(u -
  u_offset)`). A curved output backlash (the loop's effect `general_backlash`) is the
  cascade's own ND block at degree `q`: its terms are the cascade's `mL2..mLq`,
  `mR2..mRq` and `orders.degree` is `q`, written so everywhere (the effect's fields
  `curveL`, `curveR` never leave the package). Empty where an effect replaced the
  cascade (`cascade` false).
- `*_model_units`: the same in the units the model was fitted in.
- `effects`: every added effect, in order: `units`, the kind of unit of each field
  (the effect's declaration, `Effect.units`; `_effects._units` defines the kinds), and
  `parameters`, `std_errors`, its fields in the records' units by that kind
  (`_units.record_units`: `record = factor * model + offset`, a standard error times
  `|factor|`), beside `parameters_model_units`, `std_errors_model_units`, the same in
  model units. The standard error of each fitted field is beside it (`null`: a field
  held fixed, or a parameter the records do not determine, whose standard error is
  infinite; JSON has no infinity). The records' units follow the cascade's: the
  output chain's signals are the record's output, a polynomial, a filter or a parallel
  path acts on the output less `y_offset`, a level (a clip, a fold) is a level of the
  record's output; the linear block's `x` (which feedback terms see) is in the output's
  units. By effect:
  - `output_offset.offset`, `output_drift.slope` (per 1000 samples), `output_dynamics.
    offset`, `velocity_friction.forces`: `output` (times `y_scale`).
  - `output_saturation.lower`, `upper`: `output_level` (`y_offset + y_scale` times).
  - `output_polynomial`, `inner_polynomial`: `c0, c2, c3` of `(y - y_offset)^k` times
    `y_scale ** (1 - k)`; `output_fold`: `c0` and `s` levels of the record's output,
    `c1` unitless, `c2` over `y_scale`; `inner_kink`: `c0` times `y_scale`, `s` a level
    of the record's output, `c1` unitless; `nonlinear_feedback`:
    `k2, k3` of `x^k` times `y_scale ** (1 - k)`; `general_backlash`: as the cascade's
    `mL_i`, `mR_i`.
  - `input_delay.delay` (samples), `output_feedthrough.gain`, `direct_term.gain`,
    `output_dynamics.zeros`, `poles`, `prandtl_ishlinskii.knots`, `slack_friction.dead`:
    unitless.
  - `input_backlash.gap`, `slack_friction.threshold`, `backlash_friction.gap`,
    `prandtl_ishlinskii.thresholds`: `input` (times `u_scale`).
  - `backlash_friction.stiffness` (and `backlash_friction_contacts`'),
    `dahl_friction.sigma`: `output_per_input` (`y_scale / u_scale`); the friction
    levels (`upper`, `lower`, `level`), a path's `offset` and
    `prandtl_ishlinskii.weights` (of a unitless basis): `output`.
  No field of the library's effects is left in model units (the kind `model`, for a
  field with no map, would leave it out of `parameters`); the small constants of the
  equations (`FLOOR`, `EPS`) are in model units.
- `noise`: the AR noise model's coefficients (`[]`: white noise).

`model_schema` writes it from an `ExtendedModel`, `model_from_schema` reads the model
back from the model units (the model file, `_model_file`; a file without the
records'-unit keys of effects, written before them, loads the same).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._data import Scaling
from .._system._model import CascadeParams, Orders
from ._effects import EFFECTS, ExtendedModel
from ._effects._curved import CurvedBacklash
from ._effects._units import record_units
from ._noise import ARNoise


def curve_names(degree: int) -> tuple[str, ...]:
    """The curved branches' terms at branch degree `degree`: `mL2..mLq, mR2..mRq`."""
    return tuple(f"{side}{i}" for side in ("mL", "mR") for i in range(2, degree + 1))


def _curve_values(effect: CurvedBacklash) -> dict[str, float]:
    left = np.ravel(np.asarray(effect.curveL, float))
    right = np.ravel(np.asarray(effect.curveR, float))
    values = dict(zip(curve_names(effect.degree), [*left, *right], strict=True))
    return {name: float(value) for name, value in values.items()}


def _curved(model: ExtendedModel) -> CurvedBacklash | None:
    return next((e for e in model.effects if isinstance(e, CurvedBacklash)), None)


def schema_orders(model: ExtendedModel) -> Orders:
    """The model's orders as the schema writes them: the cascade's, at the degree of a
    curved backlash effect where one was added."""
    curved = _curved(model)
    if curved is None or model.orders.degree > 1:
        return model.orders
    return dataclasses.replace(model.orders, degree=curved.degree)


def cascade_estimates(model: ExtendedModel) -> dict[str, float]:
    """The cascade's parameters in model units by the schema's names (`schema_orders`);
    empty where an effect replaced the cascade."""
    if not model.cascade:
        return {}
    values = {k: float(v) for k, v in model.params.to_dict().items()}
    curved = _curved(model)
    if curved is not None:
        values.update(_curve_values(curved))
    return values


def _flat_name(effect, field: str, index: int | None) -> str:
    """The name `_loop.model_standard_errors` gives an effect's parameter."""
    return f"{effect.name}.{field}" + ("" if index is None else f"[{index}]")


def _effect_errors(effect, errors: dict) -> dict:
    """`{field: value or nested list}` of the standard errors of `effect`'s fields, in
    the shapes of `Effect.parameters` (None for a fixed field), from the flat names of
    `_loop.model_standard_errors` (`EFFECT.field`, or `EFFECT.field[i]` for an array of
    more than one entry)."""
    out = {}
    for field in dataclasses.fields(effect):
        value = np.asarray(getattr(effect, field.name), float)
        if field.name in effect.fixed:
            flat = [None] * value.size
        elif value.size == 1:
            flat = [errors.get(_flat_name(effect, field.name, None))]
        else:
            flat = [errors.get(_flat_name(effect, field.name, i)) for i in range(value.size)]
        flat = [_number(v) for v in flat]
        out[field.name] = (
            flat[0]
            if value.ndim == 0
            else np.reshape(np.asarray(flat, dtype=object), value.shape).tolist()
        )
    return out


def model_schema(
    model: ExtendedModel, scaling: Scaling | None = None, std_errors: dict | None = None
) -> dict:
    """`model` in the schema (module docstring). `scaling`: the records' units (default:
    the model's own); `std_errors`: the standard errors by the names of
    `_loop.model_standard_errors` (the cascade's `Orders.names`, an effect's
    `EFFECT.field[i]`), or None where none were computed (every error then None)."""
    scaling = Scaling() if scaling is None else scaling
    errors = {} if std_errors is None else dict(std_errors)
    curved = _curved(model)
    if curved is not None:  # the effect's terms under the cascade's names
        left = np.ravel(np.asarray(curved.curveL))
        for k, name in enumerate(curve_names(curved.degree)):
            side, i = ("curveL", k) if k < left.size else ("curveR", k - left.size)
            errors.setdefault(name, errors.get(_flat_name(curved, side, i)))
    values = cascade_estimates(model)
    value_errors = {name: _number(errors.get(name)) for name in values}
    physical = scaling.params_to_physical(values) if values else {}
    # the map multiplies each parameter by a factor: a standard error maps with its size
    known = {k: v for k, v in value_errors.items() if v is not None}
    physical_errors = {k: abs(v) for k, v in scaling.params_to_physical(known).items()}
    effects = []
    for effect in model.effects:
        if isinstance(effect, CurvedBacklash):
            terms = _curve_values(effect)
            entry_errors = {name: value_errors.get(name) for name in terms}
            # the cascade's terms: in `estimates`, by `params_to_physical`
            units = {name: f"output_power({name[2:]})" for name in terms}
            parameters = {name: physical[name] for name in terms}
            record_errors = {name: physical_errors.get(name) for name in terms}
        else:
            terms = effect.parameters()
            entry_errors = _effect_errors(effect, errors)
            parameters, record_errors, units = record_units(effect, scaling, entry_errors)
        effects.append(
            {
                "name": effect.name,
                "units": units,
                "parameters": parameters,
                "std_errors": record_errors,
                "parameters_model_units": terms,
                "std_errors_model_units": entry_errors,
            }
        )
    return {
        "structure": model.structure(),
        "cascade": bool(model.cascade),
        "orders": dataclasses.asdict(schema_orders(model)),
        "estimates": physical,
        "std_errors": {name: physical_errors.get(name) for name in values},
        "estimates_model_units": values,
        "std_errors_model_units": value_errors,
        "effects": effects,
        "noise": {"name": ARNoise.name, "ar": np.asarray(model.noise.coefficients, float).tolist()},
        "scaling": scaling.to_dict(),
    }


def _number(value) -> float | None:
    """A standard error as a float; None for a missing one. Infinite stays infinite (the
    JSON writers write it as null)."""
    if value is None:
        return None
    value = float(value)
    return value if not math.isnan(value) else None


def model_from_schema(data: dict) -> ExtendedModel:
    """The model that `model_schema` wrote (model units); a `ValueError` naming what
    does not fit (unknown effect, parameters not those of the orders, a value that is not
    finite)."""
    import jax.numpy as jnp

    def array(value, name):
        values = np.asarray(value, float)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"parameter {name} is not a finite number")
        return jnp.asarray(values)

    written = Orders(**data["orders"])
    values = data["estimates_model_units"]
    entries = data["effects"]
    curved = [e for e in entries if e["name"] == CurvedBacklash.name]
    # a curved backlash effect holds the terms above degree 1: the cascade is straight
    orders = written.straight if curved else written
    if not data["cascade"] and not values:
        # a replaced cascade: its parameters are never used; the straight cascade's zeros
        # would be inadmissible but are unchecked like the loop's own
        values = {name: 0.0 for name in orders.names}
    missing = [name for name in orders.names if name not in values]
    extra = sorted(set(values) - set(orders.names) - set(curve_names(written.degree)))
    if missing or extra:
        raise ValueError(
            f"the estimates {list(values)} are not those of orders {written}, {list(written.names)}"
        )
    vector = array([values[name] for name in orders.names], "of the cascade")
    params = CascadeParams.from_vector(vector, orders, check=False)
    effects = []
    for entry in entries:
        kind = EFFECTS.get(entry["name"])
        if kind is None:
            raise ValueError(f"unknown effect {entry['name']!r} (known: {', '.join(EFFECTS)})")
        given = entry["parameters_model_units"]
        if kind is CurvedBacklash:
            names = curve_names(written.degree)
            if sorted(given) != sorted(names):
                raise ValueError(f"effect {kind.name} takes the terms {list(names)}, got {given}")
            q = written.degree - 1
            terms = [given[name] for name in names]
            effects.append(kind(curveL=array(terms[:q], "mL"), curveR=array(terms[q:], "mR")))
            continue
        fields = [f.name for f in dataclasses.fields(kind)]
        if sorted(given) != sorted(fields):
            raise ValueError(f"effect {kind.name} takes the parameters {fields}, got {given}")
        effects.append(kind(**{f: array(given[f], f"{kind.name}.{f}") for f in fields}))
    noise = ARNoise(array(data["noise"]["ar"], "ar").reshape(-1))
    return ExtendedModel(params, tuple(effects), noise, cascade=bool(data["cascade"]))


def schema_errors(data: dict) -> dict[str, float]:
    """The standard errors of a schema (model units) by the flat names `model_schema`
    takes (`_loop.model_standard_errors`'s; the curved terms by the cascade's names). A
    null (a parameter the records do not determine, or none computed) is left out: the
    schema written again has null there."""
    out = {
        name: float(value)
        for name, value in data["std_errors_model_units"].items()
        if value is not None
    }
    for entry in data["effects"]:
        kind = EFFECTS.get(entry["name"])
        if kind is None or kind is CurvedBacklash:
            continue
        for field, value in entry["std_errors_model_units"].items():
            if field in kind.fixed:
                continue
            flat = np.ravel(np.asarray(value, dtype=object))
            for i, error in enumerate(flat):
                if error is not None:
                    name = f"{kind.name}.{field}" + ("" if flat.size == 1 else f"[{i}]")
                    out[name] = float(error)
    return out
