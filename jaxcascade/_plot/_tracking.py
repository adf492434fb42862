"""Figures of a sweep of a system that changes (`Spec.change`): per cell, the error
trajectory `estimate - truth(t)` of every parameter at the recorded samples, as the
median over realisations with its 25-75 % and 10-90 % quantile bands, the change marked
and the re-entry band (±0.05) drawn (matplotlib's `Figure` API, imported lazily)."""

from __future__ import annotations

import math
import pathlib

import numpy as np
import pandas as pd

from .._montecarlo._tables import CELL_COLUMNS, parameter_names, track_column


def plot_tracking(table: pd.DataFrame, samples, at: int, band: float, path, title: str = ""):
    """One cell's figure: a panel per parameter. `samples`: the recorded samples
    (`_tracking.tracking_samples`); `at`: the sample of the change. Saves to `path` and
    returns the figure."""
    from matplotlib.figure import Figure

    names = parameter_names(table)
    columns = min(4, len(names))
    rows = math.ceil(len(names) / columns)
    figure = Figure(figsize=(3.4 * columns, 2.5 * rows), layout="constrained")
    axes = figure.subplots(rows, columns, squeeze=False, sharex=True)
    for ax in axes.flat[len(names) :]:
        ax.set_visible(False)
    for ax, name in zip(axes.flat, names, strict=False):
        errors = np.stack(table[track_column(name)].to_list())  # (R, K)
        q = np.quantile(errors, [0.1, 0.25, 0.5, 0.75, 0.9], axis=0)
        ax.fill_between(samples, q[0], q[4], color="C0", alpha=0.2, lw=0, label="10-90 %")
        ax.fill_between(samples, q[1], q[3], color="C0", alpha=0.4, lw=0, label="25-75 %")
        ax.plot(samples, q[2], color="C0", lw=1, label="median")
        ax.axvline(at, color="k", lw=0.8, ls=":")
        for edge in (-band, band):
            ax.axhline(edge, color="C3", lw=0.7, ls="--")
        ax.set_ylim(-4 * band, 4 * band)
        ax.set_title(f"{name}: estimate - truth(t)", fontsize=9)
    axes.flat[0].legend(fontsize=7, loc="upper right")
    for ax in axes[-1]:
        ax.set_xlabel("sample")
    if title:
        figure.suptitle(title, fontsize=10)
    figure.savefig(pathlib.Path(path), dpi=100)
    return figure


def tracking_figures(spec, table: pd.DataFrame, folder, stem: str) -> list[pathlib.Path]:
    """`STEM_tracking_n{N}_snr{SNR}.png` per cell of `table` into `folder`."""
    from .._montecarlo._tracking import BAND, tracking_samples

    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    every = dict(spec.estimator_settings("recursive"))["every"]
    change = spec.change
    for (system, n, snr, estimator), group in table.groupby(CELL_COLUMNS, sort=False):
        path = folder / f"{stem}_tracking_n{n}_snr{snr:g}.png"
        title = (
            f"{system}, {estimator}, N {n}, SNR {snr:g}: {change.describe()}; "
            f"{len(group)} realisations"
        )
        plot_tracking(group, tracking_samples(int(n), every), change.at, BAND, path, title)
        paths.append(path)
    return paths
