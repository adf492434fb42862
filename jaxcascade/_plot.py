"""Plots of Monte-Carlo sweeps (matplotlib, imported lazily, Agg backend).

Error bars are 95% Monte-Carlo intervals (1.96 standard errors). SNR axes drop
`inf` (noise-free) cells; both SNR and N axes are logarithmic.
"""

from __future__ import annotations

import math
import pathlib

import numpy as np
import pandas as pd

_Z = 1.96


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _grid(plt, count: int, width: float = 3.4, height: float = 2.6):
    columns = min(4, count)
    rows = math.ceil(count / columns)
    fig, axes = plt.subplots(
        rows,
        columns,
        figsize=(width * columns, height * rows),
        squeeze=False,
        constrained_layout=True,
    )
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    return fig, axes.flat


def _log_axis(ax, values) -> None:
    # Log scale with the grid values as tick labels (the default minor labels collide).
    from matplotlib.ticker import NullFormatter

    values = sorted(set(float(v) for v in values))
    ax.set_xscale("log")
    ax.set_xticks(values)
    ax.set_xticklabels([f"{v:g}" for v in values], fontsize=8)
    ax.xaxis.set_minor_formatter(NullFormatter())


def plot_statistic(summary: pd.DataFrame, statistic: str, against: str, path) -> None:
    """`statistic` (`bias` or `rmse`) of every parameter versus `against` (`snr` or `n`).

    One line per estimator and value of the other grid axis, with 95% MC error bars.
    """
    plt = _pyplot()
    other = "n" if against == "snr" else "snr"
    data = summary[np.isfinite(summary[against].astype(float))]
    names = list(dict.fromkeys(data["parameter"]))
    fig, axes = _grid(plt, len(names))
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
    plt.close(fig)


def plot_convergence_rate(summary: pd.DataFrame, path) -> None:
    """Converged and recovered rates versus SNR, one line per estimator and N."""
    plt = _pyplot()
    cells = summary.drop_duplicates(["system", "n", "snr", "estimator"])
    cells = cells[np.isfinite(cells["snr"].astype(float))]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    for ax, rate, title in (
        (axes[0], "converged_rate", "status converged"),
        (axes[1], "recovered_rate", "converged and every parameter within 0.05"),
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
    plt.close(fig)


def plot_distributions(table: pd.DataFrame, path, n: int | None = None) -> None:
    """Box plots of every parameter's estimates versus SNR at one N (default the largest).

    Only the estimates the summary uses are drawn (`used_mask`); the dashed line is the truth.
    For a family of systems (the truth varies by row) the errors `estimate - truth` are
    drawn instead, around a dashed zero.
    """
    plt = _pyplot()
    from ._tables import parameter_names, true_column, used_mask

    n = int(table["n"].max()) if n is None else n
    data = table[(table["n"].to_numpy() == n) & used_mask(table)]
    names = parameter_names(table)
    groups = list(data.groupby(["estimator", "snr"], sort=True))
    fig, axes = _grid(plt, len(names), width=3.6)
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
    plt.close(fig)


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
    return paths
