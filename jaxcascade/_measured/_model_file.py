"""A fitted model saved to reuse: one JSON file that holds everything needed to apply it
to a new record (MATLAB's `compare` and `sim`, SysIdentPy's `predict`).

The file (`docs/models.md` documents every key) holds the model in the package's one
schema (`_schema`: its structure and orders, every estimate with its standard error in
the records' units and in model units, the effects in order, the AR noise model), and
what the records went through before the model saw them: the sample period after
decimation (the model's dynamics are per sample), the decimation and its anti-alias
filter, the detrending, the affine scaling to model units (`_data.Scaling`), the
signals' names and units, whether the output was modelled through its difference
(`_integrating`), and the state-initialisation window of initialised scoring
(`_scoring`). `format` and `format_version` name the layout, `jaxcascade_version` the
package that wrote it. Version 2 writes the model in the schema; a file of version 1
(before it: the cascade's parameters in model units under `model.parameters`, the
effects' fields under their own names, the scaling under `data`) still loads.

`SavedModel` applies the model the way the loop scores its records: a record read with
the saved options (`record_options`) and scaling is scored by `_scoring.score_record`
with the loop's own simulations (`_loop.simulated_output`, `_loop.initialised_output`,
wrapped by `_integrating.integrated` for an integrating output), so `jaxcascade
simulate` on a loop's test record gives the loop's test figures.

Numbers are written as Python's shortest round-trip decimal: a loaded model is the
saved one to the last bit.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pathlib
from typing import Any

import numpy as np

from .._data import Record, Scaling, record_from_arrays
from .._json import finite_or_null
from .._metrics import fit_percent
from .._system._model import CascadeParams, Orders
from .._version import __version__
from ._effects import EFFECTS, ExtendedModel
from ._noise import ARNoise
from ._schema import model_from_schema, model_schema, schema_errors
from ._scoring import RecordScore, score_record

FORMAT = "jaxcascade-model"
FORMAT_VERSION = 2
# A record's sample period may differ from the model's by this fraction
# (`_data.check_sample_periods`' tolerance: CSV times are rounded).
PERIOD_RTOL = 1e-2


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A saved model applied to one record: `score` (`_scoring.RecordScore`, its `rmse` in
    the record's physical unit), `rmse_from_rest` (physical, over the whole record),
    `time` (seconds, or samples where the period is unknown: `seconds` False), the
    measured output `y`,
    the simulation `from_rest` and the `initialised` one (NaN on the `init_samples`
    samples that set its state), all in physical units."""

    score: RecordScore
    rmse_from_rest: float
    time: np.ndarray
    y: np.ndarray
    from_rest: np.ndarray
    initialised: np.ndarray
    seconds: bool = True

    def to_dict(self) -> dict[str, Any]:
        s = self.score
        return {
            "record": s.record,
            "samples": int(self.y.shape[0]),
            "init_samples": s.init_samples,
            "error": s.error,
            "window_error": s.window_error,
            "error_from_rest": s.error_from_rest,
            "window_error_from_rest": s.window_error_from_rest,
            "rmse": s.rmse,
            "rmse_from_rest": self.rmse_from_rest,
            "fit_percent": fit_percent(s.error),
            "fit_percent_from_rest": fit_percent(s.error_from_rest),
        }


@dataclasses.dataclass(frozen=True)
class SavedModel:
    """A model with what a record needs to go through before it (module docstring).

    - `model`: the `ExtendedModel` (cascade, effects, noise model), in model units.
    - `scaling`: physical to model units of input and output.
    - `sample_period`: the time between the model's samples (after decimation), or None.
    - `decimation`, `anti_alias`, `detrend`: as `_data.read_record` applies them.
    - `input_column`, `output_column`, `time_column`, `input_unit`, `output_unit`: the
      estimation records' signals, the defaults for a record that names none.
    - `init_samples`: samples of measured output that set the state of an initialised
      simulation (`_scoring`).
    - `integrating`: the model's output is the difference of the measured one
      (`_integrating`), integrated back when applied.
    - `provenance`: what wrote it (a command, the declared structure, the loop's
      actions), free-form; `version`: the package version that wrote it.
    - `std_errors`: the estimates' standard errors in model units (the names of
      `_loop.model_standard_errors`), or None where none were saved (a file of version 1).
    """

    model: ExtendedModel
    scaling: Scaling = Scaling()
    sample_period: float | None = None
    decimation: int = 1
    anti_alias: str = "fir"
    detrend: str = "none"
    input_column: str | None = None
    output_column: str | None = None
    time_column: str | None = None
    input_unit: str | None = None
    output_unit: str | None = None
    init_samples: int = 50
    integrating: bool = False
    provenance: dict = dataclasses.field(default_factory=dict)
    version: str = __version__
    std_errors: dict | None = None

    @classmethod
    def from_record(cls, model: ExtendedModel, record: Record, **settings) -> SavedModel:
        """`model` with the preprocessing of `record` (an estimation record: its scaling,
        period, decimation, detrending, signals and units); `settings` set the rest."""
        return cls(
            model,
            scaling=record.scaling,
            sample_period=record.sample_period,
            decimation=record.decimation,
            anti_alias=record.anti_alias or "fir",
            detrend=record.detrend,
            input_column=record.input_column,
            output_column=record.output_column,
            time_column=record.time_column,
            input_unit=record.input_unit,
            output_unit=record.output_unit,
            **settings,
        )

    # ---- applying the model ------------------------------------------------------------

    def scorers(self):
        """`(from_rest, initialised)` in model units, as `_scoring.score_record` takes
        them: the loop's own simulations of the model, integrated for an integrating
        output."""
        from ._loop import initialised_output, simulated_output

        model = self.model
        pair = (
            lambda u: simulated_output(model, u),
            lambda u, y, start, n: initialised_output(model, u, y, start, n),
        )
        if self.integrating:
            from ._integrating import integrated

            pair = integrated(*pair)
        return pair

    def simulate(self, u) -> np.ndarray:
        """The output simulated from rest (zero input and output in model units before
        the record) for the input `u`, both in physical units at the model's sample
        period."""
        from_rest, _ = self.scorers()
        u_model = self.scaling.input_to_model(np.asarray(u, float).ravel())
        return self.scaling.output_to_physical(from_rest(u_model))

    def record(self, u, y, *, source: str | None = None) -> Record:
        """A `Record` from physical arrays at the model's sample period, in its scaling."""
        return record_from_arrays(
            u,
            y,
            sample_period=self.sample_period,
            scaling=self.scaling,
            source=source,
            input_unit=self.input_unit,
            output_unit=self.output_unit,
        )

    def read_record(
        self,
        spec,
        *,
        input_column=None,
        output_column=None,
        time_column=None,
        sample_period: float | None = None,
        input_unit: str | None = None,
        output_unit: str | None = None,
    ) -> Record:
        """A record read as the model's estimation records were (`_data.read_record`:
        the saved decimation, anti-alias filter, detrending and scaling): its signals
        from the spec, the arguments or the saved names; its period from
        `time_column`, the saved time column unless `sample_period` is given, or
        `sample_period`, else the model's; its units the given or the saved ones. A
        record sampled otherwise than the model is refused (`check_period`)."""
        from .._data import read_record

        if time_column is None and sample_period is None:
            time_column = self.time_column
        if sample_period is None and time_column is None and self.sample_period:
            # a record without time column or period: taken at the model's period
            sample_period = self.sample_period / self.decimation
        record = read_record(
            spec,
            input_column if input_column is not None else self.input_column,
            output_column if output_column is not None else self.output_column,
            time_column=time_column,
            sample_period=sample_period,
            input_unit=input_unit or self.input_unit,
            output_unit=output_unit or self.output_unit,
            detrend=self.detrend,
            decimate=self.decimation,
            anti_alias=self.anti_alias,
            scaling=self.scaling,
        )
        self.check_period(record)
        return record

    def check_period(self, record: Record) -> None:
        """Refuse a record sampled otherwise than the model (one sentence)."""
        a, b = self.sample_period, record.sample_period
        if a is None or b is None or abs(a - b) <= PERIOD_RTOL * min(a, b):
            return
        raise ValueError(
            f"The record {record.source or 'arrays'!r} has sample period {b:g} s after "
            f"decimation by {record.decimation} but the model's is {a:g} s; its dynamics are "
            "per sample, so resample the record (or correct its time column or --ts)."
        )

    def compare(
        self, record: Record, init_samples: int | None = None, name: str | None = None
    ) -> Comparison:
        """Apply the model to `record` (in this model's scaling, `record(...)` or read with
        the saved options) as the loop scores a test record: initialised on the first
        `init_samples` samples (default the saved ones) and from rest."""
        self.check_period(record)
        if record.scaling != self.scaling:
            raise ValueError(
                "The record is not in the model's scaling; read it with scaling=model.scaling "
                "or build it with SavedModel.record."
            )
        n = self.init_samples if init_samples is None else int(init_samples)
        if n < 0:
            raise ValueError(f"init_samples must be >= 0, got {n}.")
        from_rest, initialised = self.scorers()
        kept = {}

        def rest(u):
            kept["rest"] = np.asarray(from_rest(u), float)
            return kept["rest"]

        def init(u, y, start, count):
            kept["init"] = np.asarray(initialised(u, y, start, count), float)
            return kept["init"]

        if name is None:
            name = pathlib.Path(record.source).name if record.source else "arrays"
        s = score_record(name, name, "test", record.u, record.y, rest, init, None, n)
        factor = self.scaling.y_scale
        T = len(record)
        period = record.sample_period or self.sample_period
        with np.errstate(over="ignore", invalid="ignore"):
            rmse_rest = float(np.sqrt(np.mean((record.y - kept["rest"]) ** 2))) * factor
        initialised_y = np.full(T, np.nan)
        initialised_y[T - kept["init"].shape[0] :] = kept["init"]
        return Comparison(
            score=dataclasses.replace(s, model="saved model", rmse=s.rmse * factor),
            rmse_from_rest=rmse_rest if math.isfinite(rmse_rest) else math.inf,
            time=np.arange(T) * (period or 1.0),
            y=record.y_physical,
            from_rest=self.scaling.output_to_physical(kept["rest"]),
            initialised=self.scaling.output_to_physical(initialised_y),
            seconds=period is not None,
        )

    def score(self, u, y, init_samples: int | None = None) -> RecordScore:
        """`compare` on physical arrays `(u, y)` at the model's sample period: NRMSE
        initialised and from rest, RMSE in the output's physical unit."""
        return self.compare(self.record(u, y), init_samples).score

    # ---- the file ----------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The file's contents: the model in the schema (`_schema.model_schema`, in the
        records' units and in model units) and the records' preprocessing."""
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "jaxcascade_version": self.version,
            "model": model_schema(self.model, self.scaling, self.std_errors),
            "data": {
                "sample_period": self.sample_period,
                "decimation": self.decimation,
                "anti_alias": self.anti_alias,
                "detrend": self.detrend,
                "input": {"column": self.input_column, "unit": self.input_unit},
                "output": {"column": self.output_column, "unit": self.output_unit},
                "time_column": self.time_column,
            },
            "scoring": {"init_samples": self.init_samples, "integrating": self.integrating},
            "provenance": self.provenance,
        }

    def save(self, path: str | os.PathLike) -> pathlib.Path:
        """Write the model file (`to_dict` as JSON); non-finite parameters are refused
        (an infinite standard error, of a parameter the records do not determine, is
        written as null)."""
        data = self.to_dict()
        model = data["model"]
        for key in ("std_errors", "std_errors_model_units"):
            model[key] = finite_or_null(model[key])
        for entry in model["effects"]:
            for key in ("std_errors", "std_errors_model_units"):
                if key in entry:
                    entry[key] = finite_or_null(entry[key])
        try:
            text = json.dumps(data, indent=1, allow_nan=False)
        except ValueError:
            raise ValueError(
                "The model has a parameter that is not a finite number; it cannot be saved."
            ) from None
        path = pathlib.Path(path)
        path.write_text(text + "\n")
        return path

    @classmethod
    def from_dict(cls, data: dict, where: str = "the model") -> SavedModel:
        """Inverse of `to_dict`; a `ValueError` with one sentence naming `where` for
        anything that is not a model of this format."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f"{where} is not a jaxcascade model file (no format {FORMAT!r}).")
        version = data.get("format_version")
        if not isinstance(version, int) or version > FORMAT_VERSION or version < 1:
            raise ValueError(
                f"{where} has format version {version!r}; this jaxcascade ({__version__}) "
                f"reads versions 1 to {FORMAT_VERSION}: upgrade jaxcascade."
            )
        try:
            return cls._from_dict(data)
        except (KeyError, TypeError, ValueError, AttributeError) as error:
            what = f"key {error}" if isinstance(error, KeyError) else str(error).splitlines()[0]
            raise ValueError(f"{where} is not a valid jaxcascade model file: {what}") from None

    @classmethod
    def _from_dict(cls, data: dict) -> SavedModel:
        if data["format_version"] == 1:
            model, scaling, errors = _version_1_model(data), data["data"]["scaling"], None
        else:
            model, scaling = model_from_schema(data["model"]), data["model"]["scaling"]
            errors = schema_errors(data["model"]) or None
        d, s = data["data"], data["scoring"]
        period = d["sample_period"]
        if period is not None and not (float(period) > 0 and math.isfinite(float(period))):
            raise ValueError(f"sample_period must be a positive number, got {period}")
        return cls(
            model,
            scaling=Scaling(**scaling),
            sample_period=None if period is None else float(period),
            decimation=int(d["decimation"]),
            anti_alias=d["anti_alias"],
            detrend=d["detrend"],
            input_column=d["input"]["column"],
            output_column=d["output"]["column"],
            time_column=d["time_column"],
            input_unit=d["input"]["unit"],
            output_unit=d["output"]["unit"],
            init_samples=int(s["init_samples"]),
            integrating=bool(s["integrating"]),
            provenance=dict(data.get("provenance") or {}),
            version=str(data.get("jaxcascade_version")),
            std_errors=errors,
        )


def _version_1_model(data: dict) -> ExtendedModel:
    """The model of a file of format version 1: the cascade's parameters in model units
    under `model.parameters` by `Orders.names`, each effect's fields under their own
    names (`Effect.parameters`)."""
    import jax.numpy as jnp

    def array(value, name):
        values = np.asarray(value, float)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"parameter {name} is not a finite number")
        return jnp.asarray(values)

    m = data["model"]
    orders = Orders(**m["orders"])
    values = m["parameters"]
    if list(values) != list(orders.names):
        raise ValueError(
            f"the parameters {list(values)} are not those of orders {orders}, {list(orders.names)}"
        )
    vector = array([values[name] for name in orders.names], "of the cascade")
    # unchecked like the loop's own models: a replaced cascade's are never used
    params = CascadeParams.from_vector(vector, orders, check=False)
    effects = []
    for entry in m["effects"]:
        kind = EFFECTS.get(entry["name"])
        if kind is None:
            raise ValueError(f"unknown effect {entry['name']!r} (known: {', '.join(EFFECTS)})")
        fields = [f.name for f in dataclasses.fields(kind)]
        given = entry["parameters"]
        if sorted(given) != sorted(fields):
            raise ValueError(f"effect {kind.name} takes the parameters {fields}, got {given}")
        effects.append(kind(**{f: array(given[f], f"{kind.name}.{f}") for f in fields}))
    noise = ARNoise(array(m["noise"]["ar"], "ar").reshape(-1))
    return ExtendedModel(params, tuple(effects), noise, cascade=bool(m["cascade"]))


def load_model(path: str | os.PathLike) -> SavedModel:
    """Read a model file written by `jaxcascade loop --report` (`model.json`), `jaxcascade
    fit --save-model` or `SavedModel.save`. A `ValueError` with one sentence for a
    missing file or one that is not such a model."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"Model file '{path}' does not exist; check the path.")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"Model file '{path}' is not JSON ({error}).") from None
    return SavedModel.from_dict(data, where=f"Model file '{path}'")
