"""The loop's report folder (`LoopRun.report`, `jaxcascade loop --report DIR`):

- `report.json` (`LoopRun.to_dict()`), `report.md` (`_measured._report.markdown` and the
  section on every record), `scores.csv`, `candidates.csv`;
- `model.json`, the final model as a model file (`_measured._model_file`: `jaxcascade
  simulate` applies it to new records);
- figures, unless `figures` is False (on short records drawing them takes much of the
  loop's time): the measured versus simulated validation output before and after
  (`compare.png`), every residual test before and after in one figure each
  (`residual_before_overview.png`, `residual_after_overview.png`), and each record
  against the final model (`records/<k>-<role>.png`).
"""

from __future__ import annotations

import pathlib

import numpy as np

from .._json import strict_json


def write_report(run, folder: pathlib.Path, *, figures: bool = True) -> pathlib.Path:
    """Write `run`'s report into `folder` (module docstring); returns the folder."""
    import pandas as pd

    from .._measured._report import markdown

    folder.mkdir(parents=True, exist_ok=True)
    full = run.to_dict()
    (folder / "report.json").write_text(strict_json(full, indent=1))
    saved = run.saved_model()
    saved.save(folder / "model.json")
    roles = [("estimation", r) for r in run.estimation]
    roles += [("validation", r) for r in run.validation]
    roles += [("test", r) for r in run.test]
    section = _record_figures(saved, roles, folder, run.init_samples, figures)
    (folder / "report.md").write_text(markdown(full, run.command) + section)
    pd.DataFrame(full["candidates"]).to_csv(folder / "candidates.csv", index=False)
    pd.DataFrame(full["scores"]).to_csv(folder / "scores.csv", index=False)
    if figures:
        _loop_figures(run, folder)
    return folder


def _units(column: str, scaling: str) -> str:
    if scaling == "none":
        return column
    return f"{column} ({'scaled' if scaling == 'scale' else 'standardised'})"


def _loop_figures(run, folder: pathlib.Path) -> None:
    """`compare.png` and the residual tests' overviews before and after."""
    from .._measured._report import record_name
    from .._plot._loop import plot_compare
    from .._plot._residuals import plot_residual_tests

    result, window, n = run.result, run.window, run.init_samples
    # the loop's own (first) validation record: the output's difference when integrating
    shown = run.validation[0]
    units = _units(shown.output_column or "y", run.scaling.method)
    if run.integrating is not None:
        from .._measured._integrating import differenced

        shown, units = differenced(shown), f"difference of {units}"
    period = shown.sample_period
    time = np.arange(len(shown)) * (period or 1.0)
    scored_from = window[0] if window is not None else min(n, len(shown) - 2)
    init_from = max(scored_from - n, 0)
    plot_compare(
        time,
        shown.y,
        result.before.simulated[: len(shown)],
        result.after.simulated[: len(shown)] if result.added else None,
        folder / "compare.png",
        arx=run.arx.simulate(shown.u),
        title=f"validation record {record_name(shown)}: measured vs free-run simulation",
        units=units,
        init=(time[init_from], time[scored_from]) if scored_from > init_from else None,
        scored=(time[scored_from], time[(window[1] if window else len(time)) - 1]),
    )
    # every residual test in one figure per model (`plot_residual_tests`); a figure per
    # test as well (`save_residual_figures`) repeated its panels and more than doubled
    # the time spent drawing them
    models = [("before", result.before)] + ([("after", result.after)] if result.added else [])
    for when, evaluated in models:
        path = folder / f"residual_{when}_overview.png"
        plot_residual_tests(evaluated.tests).savefig(path, dpi=120)


def _record_figures(saved, roles, folder, init_samples, draw: bool = True) -> str:
    """One figure per record, `records/<k>-<role>.png`: measured against the final model
    (initialised on the `init_samples` samples before its scored part, and from rest) in
    the record's unit against time in seconds, with fit %, NRMSE and RMSE in the unit
    (`_model_file.SavedModel.compare`, `_plot._comparison`); returns the report's section
    that shows them (`_measured._report.records_section`). `draw` False: the section
    without the PNG files."""
    from .._measured._report import record_name, records_section
    from .._plot._comparison import plot_comparison

    if draw:
        (folder / "records").mkdir(exist_ok=True)
    rows = []
    for k, (role, record) in enumerate(roles):
        c = saved.compare(record, init_samples)
        unit = record.output_unit or record.output_column
        name = f"records/{k:02d}-{role}.png"
        if draw:
            title = f"{role} record {record_name(record)}: measured vs the final model"
            plot_comparison(c, folder / name, title=title, units=unit)
        rows.append(
            {
                "role": role,
                "name": record_name(record),
                "unit": unit,
                "period": record.sample_period,
                "figure": name,
                "score": c.score,
            }
        )
    return records_section(rows, draw)
