"""`simulate_model`: apply a saved model to records, as `jaxcascade simulate` does.

Each record is read (or mapped) as the model's estimation records were
(`SavedModel.read_record`: the saved decimation, detrending and scaling) and scored as
the loop scores a test record (`SavedModel.compare`): initialised on its first
`init_samples` samples (default the saved number) and from rest; NRMSE, RMSE in the
record's unit and fit %.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
from collections.abc import Sequence
from typing import Any

from .._data import Record, in_scaling
from .._json import strict_json


@dataclasses.dataclass(frozen=True)
class Simulation:
    """What `simulate_model` returns (`jaxcascade simulate` prints it): the `model`
    (`SavedModel`) and where it came from (`source`), the `records` simulated and one
    `Comparison` per record (`comparisons`: the score, the measured and simulated
    outputs in the record's unit). `to_dict()` is `--json`, `markdown()` the table the
    command prints, `report(folder)` writes `simulate.json`, `simulate.md` and one
    figure per record."""

    model: Any
    source: str
    records: list[Record]
    comparisons: list

    @property
    def unit(self) -> str | None:
        return self.records[0].output_unit

    def to_dict(self) -> dict:
        return {
            "model": self.source,
            "structure": self.model.model.structure(),
            "sample_period": self.model.sample_period,
            "decimation": self.model.decimation,
            "unit": self.unit,
            "records": [c.to_dict() for c in self.comparisons],
        }

    def markdown(self) -> str:
        from .._measured._report import simulate_markdown

        return simulate_markdown(self.to_dict(), self.unit or "output unit")

    def report(self, folder: str | os.PathLike) -> pathlib.Path:
        """Write `simulate.json`, `simulate.md` and `simulate_<k>.png` into `folder`."""
        from .._plot._comparison import plot_comparison

        folder = pathlib.Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        result = self.to_dict()
        (folder / "simulate.json").write_text(strict_json(result, indent=1))
        (folder / "simulate.md").write_text(self.markdown())
        for k, c in enumerate(self.comparisons, 1):
            plot_comparison(
                c,
                folder / f"simulate_{k}.png",
                title=f"{c.score.record}: measured vs {result['structure']}",
                units=self.unit or "output unit",
            )
        return folder

    def __repr__(self) -> str:
        rows = "; ".join(
            f"{c.score.record} NRMSE {c.score.error:.4g} (from rest {c.score.error_from_rest:.4g})"
            for c in self.comparisons
        )
        return f"Simulation({self.model.model.structure()!r}; {rows})"


def simulate_model(
    model,
    records: Record | str | os.PathLike | Sequence[Record | str | os.PathLike],
    *,
    init_samples: int | None = None,
    input_column=None,
    output_column=None,
    time_column=None,
    sample_period: float | None = None,
    input_unit: str | None = None,
    output_unit: str | None = None,
) -> Simulation:
    """Apply a saved model to records (module docstring).

    - `model`: a `SavedModel` or the path of a model file (`load_model`).
    - `records`: `Record`s (put in the model's scaling through their physical units) or
      record specs / files, read with the model's options (`SavedModel.read_record`,
      which the signal, time, period and unit arguments override).
    - `init_samples`: samples that set each record's state (default the model's; 0 from
      rest).
    """
    from .._measured._model_file import SavedModel, load_model
    from .._measured._report import record_name

    if init_samples is not None and init_samples < 0:
        raise ValueError(f"init_samples (--init-samples) must be >= 0, got {init_samples}.")
    source = "the model" if isinstance(model, SavedModel) else str(model)
    saved = model if isinstance(model, SavedModel) else load_model(model)
    if isinstance(records, Record | str | os.PathLike):
        records = [records]
    options = dict(
        input_column=input_column,
        output_column=output_column,
        time_column=time_column,
        sample_period=sample_period,
        input_unit=input_unit,
        output_unit=output_unit,
    )
    read = [
        in_scaling(r, saved.scaling) if isinstance(r, Record) else saved.read_record(r, **options)
        for r in records
    ]
    for record in read:  # all refused before any work
        saved.check_period(record)
    comparisons = [saved.compare(r, init_samples, name=record_name(r)) for r in read]
    return Simulation(saved, source, read, comparisons)
