"""Figures of Monte-Carlo sweeps (matplotlib's `Figure` API, imported lazily: no pyplot
state, the user's backend untouched).

Error bars are 95% Monte-Carlo intervals (1.96 standard errors). SNR axes drop
`inf` (noise-free) cells; both SNR and N axes are logarithmic.
"""

from __future__ import annotations

import math
import pathlib

import numpy as np
import pandas as pd

from .._montecarlo._tables import parameter_names, true_column, used_mask

_Z = 1.96


def _figure(**kwargs):
    from matplotlib.figure import Figure

    return Figure(layout="constrained", **kwargs)


def _grid(count: int, width: float = 3.4, height: float = 2.6):
    columns = min(4, count)
    rows = math.ceil(count / columns)
    fig = _figure(figsize=(width * columns, height * rows))
    axes = fig.subplots(rows, columns, squeeze=False)
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    return fig, axes.flat


def _log_axis(ax, values) -> None:
    # Log scale with the grid values as tick labels (the default minor labels collide).
    from matplotlib.ticker import NullFormatter

    values = sorted(set(float(v) for v in values))
    ax.set_xscale("log")
    # explicit limits: a panel whose statistic is NaN everywhere (no admissible estimate
    # in any cell) has no data limits of its own, and a log axis needs them
    ax.set_xlim(values[0] / 1.25, values[-1] * 1.25)
    ax.set_xticks(values)
    ax.set_xticklabels([f"{v:g}" for v in values], fontsize=8)
    ax.xaxis.set_minor_formatter(NullFormatter())


def plot_statistic(summary: pd.DataFrame, statistic: str, against: str, path) -> None:
    """`statistic` (`bias` or `rmse`) of every parameter versus `against` (`snr` or `n`).

    One line per estimator and value of the other grid axis, with 95% MC error bars.
    """
    other = "n" if against == "snr" else "snr"
    data = summary[np.isfinite(summary[against].astype(float))]
    names = list(dict.fromkeys(data["parameter"]))
    fig, axes = _grid(len(names))
    for ax, name in zip(axes, names, strict=False):
        rows = data[data["parameter"] == name]
        for (estimator, level), line in rows.groupby(["estimator", other], sort=True):
            line = line.sort_values(against)
            label = f"{estimator}, {'N' if other == 'n' else 'SNR'} = {level:g}"
            ax.errorbar(
                line[against],
                line[statistic],
                yerr=_Z * line[f"{statistic}_se"],
                marker="o",
                ms=3,
                capsize=2,
                lw=1,
                label=label,
            )
        if statistic == "bias":
            ax.axhline(0, color="k", lw=0.6)
        _log_axis(ax, rows[against])
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("SNR" if against == "snr" else "N")
    axes[0].legend(fontsize=7)
    system = ", ".join(map(str, dict.fromkeys(data["system"])))
    fig.suptitle(f"{system}: {statistic} versus {'SNR' if against == 'snr' else 'N'} (95% MC bars)")
    fig.savefig(path, dpi=110)


def plot_convergence_rate(summary: pd.DataFrame, path) -> None:
    """Converged and recovered rates versus SNR, one line per estimator and N."""
    cells = summary.drop_duplicates(["system", "n", "snr", "estimator"])
    cells = cells[np.isfinite(cells["snr"].astype(float))]
    fig = _figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2)
    for ax, rate, title in (
        (axes[0], "converged_rate", "status converged"),
        (axes[1], "recovered_rate", "every parameter within 0.05"),
    ):
        for (estimator, n), line in cells.groupby(["estimator", "n"], sort=True):
            line = line.sort_values("snr")
            ax.errorbar(
                line["snr"],
                line[rate],
                yerr=_Z * line[f"{rate}_se"],
                marker="o",
                ms=3,
                capsize=2,
                lw=1,
                label=f"{estimator}, N = {n}",
            )
        _log_axis(ax, cells["snr"])
        ax.set_ylim(-0.03, 1.03)
        ax.set_xlabel("SNR")
        ax.set_ylabel("rate")
        ax.set_title(title, fontsize=10)
    axes[0].legend(fontsize=8)
    fig.savefig(path, dpi=110)


def plot_distributions(table: pd.DataFrame, path, n: int | None = None) -> None:
    """Box plots of every parameter's estimates versus SNR at one N (default the largest).

    Only the estimates the summary uses are drawn (`used_mask`); the dashed line is the truth.
    For a family of systems (the truth varies by row) the errors `estimate - truth` are
    drawn instead, around a dashed zero.
    """

    n = int(table["n"].max()) if n is None else n
    data = table[(table["n"].to_numpy() == n) & used_mask(table)]
    names = parameter_names(table)
    groups = list(data.groupby(["estimator", "snr"], sort=True))
    fig, axes = _grid(len(names), width=3.6)
    for ax, name in zip(axes, names, strict=False):
        truth = table[true_column(name)].to_numpy()
        varying = not np.all(truth == truth[0])
        ax.boxplot(
            [
                group[name].to_numpy() - (group[true_column(name)].to_numpy() if varying else 0)
                for _, group in groups
            ],
            showfliers=True,
            flierprops={"ms": 2, "alpha": 0.4},
        )
        ax.set_xticks(range(1, len(groups) + 1))
        ax.set_xticklabels(
            [
                f"{e}\n{s:g}" if len(set(data["estimator"])) > 1 else f"{s:g}"
                for (e, s), _ in groups
            ],
            fontsize=7,
        )
        ax.axhline(0.0 if varying else float(truth[0]), color="k", ls="--", lw=0.8)
        ax.set_title(f"{name} - truth" if varying else name, fontsize=10)
        ax.set_xlabel("SNR")
    fig.suptitle(
        f"Distributions of the estimates, N = {n} (estimates used in the summary; dashed: truth)"
    )
    fig.savefig(path, dpi=110)


def plot_std_and_bound(summary: pd.DataFrame, against: str, path) -> None:
    """The Monte-Carlo std of every parameter versus `against` (`n` or `snr`), log-log,
    one line per estimator and level of the other axis (95% MC bars), with the
    Cramér-Rao bound of the same cells as a dashed black line (`_efficiency`)."""
    other = "n" if against == "snr" else "snr"
    data = summary[np.isfinite(summary[against].astype(float))]
    names = list(dict.fromkeys(data["parameter"]))
    fig, axes = _grid(len(names))
    for ax, name in zip(axes, names, strict=False):
        rows = data[data["parameter"] == name]
        for (estimator, level), line in rows.groupby(["estimator", other], sort=True):
            line = line.sort_values(against)
            label = f"{estimator}, {'N' if other == 'n' else 'SNR'} = {level:g}"
            ax.errorbar(
                line[against],
                line["std"],
                yerr=_Z * line["std_se"],
                marker="o",
                ms=3,
                capsize=2,
                lw=1,
                label=label,
            )
        bound = rows.drop_duplicates([against, other]).sort_values(against)
        for _, line in bound.groupby(other, sort=True):
            ax.plot(line[against], line["crlb_std"], "k--", lw=0.9)
        _log_axis(ax, rows[against])
        ax.set_yscale("log")
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("SNR" if against == "snr" else "N")
    axes[0].plot([], [], "k--", lw=0.9, label="Cramér-Rao bound")
    axes[0].legend(fontsize=7)
    system = ", ".join(map(str, dict.fromkeys(data["system"])))
    fig.suptitle(f"{system}: std versus {'SNR' if against == 'snr' else 'N'} and the bound")
    fig.savefig(path, dpi=110)


def plot_efficiency(summary: pd.DataFrame, path, n=None, snr=None) -> None:
    """Efficiency (`crlb_std^2 / std^2`) per parameter as bars, one bar per estimator,
    with 95% Monte-Carlo error bars, for one cell (default: the largest N and the SNR
    closest to 25)."""
    data = summary[np.isfinite(summary["efficiency"].astype(float))]
    if n is None:
        n = int(data["n"].max())
    if snr is None:
        snrs = data["snr"].unique()
        snr = float(snrs[np.argmin(np.abs(np.log(snrs / 25.0)))])
    cell = data[(data["n"] == n) & (data["snr"] == snr)]
    names = list(dict.fromkeys(cell["parameter"]))
    estimators = list(dict.fromkeys(cell["estimator"]))
    fig = _figure(figsize=(max(6.0, 0.7 * len(names) * len(estimators)), 3.6))
    ax = fig.add_subplot()
    width = 0.8 / max(len(estimators), 1)
    x = np.arange(len(names))
    for k, estimator in enumerate(estimators):
        rows = cell[cell["estimator"] == estimator].set_index("parameter").reindex(names)
        ax.bar(
            x + (k - (len(estimators) - 1) / 2) * width,
            rows["efficiency"],
            width,
            yerr=_Z * rows["efficiency_se"],
            capsize=2,
            label=estimator,
        )
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xticks(x)
    ax.set_xticklabels(names, fontsize=8)
    ax.set_ylabel("efficiency (bound variance / MC variance)")
    ax.legend(fontsize=8)
    system = ", ".join(map(str, dict.fromkeys(cell["system"])))
    ax.set_title(f"{system}, N = {n}, SNR {snr:g} (95% MC bars)", fontsize=10)
    fig.savefig(path, dpi=110)


def plot_sweep(summary: pd.DataFrame, table: pd.DataFrame, folder, stem: str) -> list[pathlib.Path]:
    """Every plot of a sweep into `folder`, named `STEM_*.png`; returns the paths."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for statistic in ("bias", "rmse"):
        for against in ("snr", "n"):
            path = folder / f"{stem}_{statistic}_vs_{against}.png"
            plot_statistic(summary, statistic, against, path)
            paths.append(path)
    path = folder / f"{stem}_convergence_rate.png"
    plot_convergence_rate(summary, path)
    paths.append(path)
    path = folder / f"{stem}_distributions.png"
    plot_distributions(table, path)
    paths.append(path)
    if "efficiency" in summary and np.isfinite(summary["efficiency"].astype(float)).any():
        for against in ("n", "snr"):
            path = folder / f"{stem}_std_vs_{against}.png"
            plot_std_and_bound(summary, against, path)
            paths.append(path)
        path = folder / f"{stem}_efficiency.png"
        plot_efficiency(summary, path)
        paths.append(path)
    return paths
