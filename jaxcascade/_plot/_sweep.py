"""Figures of Monte-Carlo sweeps (matplotlib's `Figure` API, imported lazily: no pyplot
state, the user's backend untouched).

The figures fit the sweep's shape (`figure_names`): a "versus SNR" figure only when the
sweep has two or more finite SNRs, a "versus N" one only with two or more sample sizes;
the distributions, the convergence rates and the efficiency are drawn for any shape
(at one cell: estimators side by side). Error bars are 95% Monte-Carlo intervals (1.96
standard errors). SNR axes drop `inf` (noise-free) cells; both SNR and N axes are
logarithmic. Estimators are drawn side by side, never on top of each other: on a log
axis each is shifted by a few per cent.
"""

from __future__ import annotations

import math
import pathlib

import numpy as np
import pandas as pd

from .._montecarlo._tables import parameter_names, true_column, used_mask

_Z = 1.96
_DODGE = 0.035  # log-axis shift between estimators (a few per cent of the value)
_MARKERS = "osD^v<>"
_BOUND = {"color": "k", "ls": "--", "lw": 0.9}


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


def _axis_values(summary: pd.DataFrame, axis: str) -> list:
    values = summary[axis].astype(float)
    return sorted(set(values[np.isfinite(values)].tolist()))


def _has_bound(summary: pd.DataFrame) -> bool:
    return "crlb_std" in summary and bool(np.isfinite(summary["crlb_std"].astype(float)).any())


def figure_names(summary: pd.DataFrame) -> list[str]:
    """The figures `plot_sweep` draws for this summary's shape, in drawing order.

    A statistic versus SNR (or N) only when the sweep has two or more finite SNRs (or
    sample sizes): a "versus" plot with one x value shows nothing a table would not.
    """
    names = []
    for against in ("snr", "n"):
        if len(_axis_values(summary, against)) > 1:
            names += [f"bias_vs_{against}", f"rmse_vs_{against}", f"std_vs_{against}"]
    names += ["convergence_rate", "distributions"]
    if "efficiency" in summary and np.isfinite(summary["efficiency"].astype(float)).any():
        names.append("efficiency")
    return names


def _dodge(values, k: int, count: int):
    # estimator k of count, shifted multiplicatively on a log axis
    return np.asarray(values, float) * np.exp(_DODGE * (k - (count - 1) / 2))


def _system(data: pd.DataFrame) -> str:
    return ", ".join(map(str, dict.fromkeys(data["system"])))


def plot_statistic(summary: pd.DataFrame, statistic: str, against: str, path) -> None:
    """`statistic` (`bias`, `rmse` or `std`) of every parameter versus `against` (`snr` or
    `n`), one line per estimator and value of the other grid axis, with 95% MC error
    bars; for `std` the Cramér-Rao bound of the same cells as dashed black lines (when the
    summary has one). Needs two or more values of `against`."""
    other = "n" if against == "snr" else "snr"
    data = summary[np.isfinite(summary[against].astype(float))]
    names = list(dict.fromkeys(data["parameter"]))
    estimators = list(dict.fromkeys(data["estimator"]))
    levels = sorted(set(data[other].astype(float)))
    fig, axes = _grid(len(names))
    bound = statistic == "std" and _has_bound(data)
    for ax, name in zip(axes, names, strict=False):
        rows = data[data["parameter"] == name]
        for (estimator, level), line in rows.groupby(["estimator", other], sort=True):
            line = line.sort_values(against)
            k = estimators.index(estimator)
            label = estimator
            if len(levels) > 1:
                label += f", {'N' if other == 'n' else 'SNR'} = {level:g}"
            ax.errorbar(
                _dodge(line[against], k, len(estimators)),
                line[statistic],
                yerr=_Z * line[f"{statistic}_se"],
                marker=_MARKERS[k % len(_MARKERS)],
                ms=3,
                capsize=2,
                lw=1,
                color=f"C{(k * len(levels) + levels.index(float(level))) % 10}",
                label=label,
            )
        if statistic == "bias":
            ax.axhline(0, color="k", lw=0.6)
        if bound:
            cells = rows.drop_duplicates([against, other]).sort_values(against)
            for _, line in cells.groupby(other, sort=True):
                ax.plot(line[against], line["crlb_std"], **_BOUND)
        _log_axis(ax, rows[against])
        if statistic in ("std", "rmse"):  # positive, spanning decades across a grid
            ax.set_yscale("log")
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("SNR" if against == "snr" else "N")
    if bound:
        axes[0].plot([], [], **_BOUND, label="Cramér-Rao bound")
    axes[0].legend(fontsize=7)
    what = "std and the Cramér-Rao bound" if bound else statistic
    fig.suptitle(
        f"{_system(data)}: {what} versus {'SNR' if against == 'snr' else 'N'} (95% MC bars)"
    )
    fig.savefig(path, dpi=110)


def plot_std_and_bound(summary: pd.DataFrame, against: str, path) -> None:
    """The Monte-Carlo std of every parameter versus `against`, log-log, with the
    Cramér-Rao bound (`plot_statistic(summary, "std", against, path)`)."""
    plot_statistic(summary, "std", against, path)


def _cells(summary: pd.DataFrame) -> pd.DataFrame:
    return summary.drop_duplicates(["system", "n", "snr", "estimator"])


def plot_convergence_rate(summary: pd.DataFrame, path) -> None:
    """Converged and recovered rates with 95% MC bars: versus SNR (one line per estimator
    and N) when the sweep has two or more finite SNRs, else versus N when it has two or
    more N, else bars per cell, estimators side by side."""
    cells = _cells(summary)
    snrs, ns = _axis_values(cells, "snr"), _axis_values(cells, "n")
    against = "snr" if len(snrs) > 1 else "n" if len(ns) > 1 else None
    estimators = list(dict.fromkeys(cells["estimator"]))
    fig = _figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2, sharey=True)
    rates = (
        ("converged_rate", "status converged"),
        ("recovered_rate", "every parameter within 0.05"),
    )
    for ax, (rate, title) in zip(axes, rates, strict=True):
        if against is None:
            _rate_bars(ax, cells, rate, estimators)
        else:
            other = "n" if against == "snr" else "snr"
            data = cells[np.isfinite(cells[against].astype(float))]
            levels = sorted(set(data[other].astype(float)))
            for (estimator, level), line in data.groupby(["estimator", other], sort=True):
                line = line.sort_values(against)
                k = estimators.index(estimator)
                label = estimator
                if len(levels) > 1:
                    label += f", {'N' if other == 'n' else 'SNR'} = {level:g}"
                j = k * len(levels) + levels.index(float(level))
                ax.errorbar(  # every line shifted: equal rates (often 1) stay visible
                    _dodge(line[against], j, len(estimators) * len(levels)),
                    line[rate],
                    yerr=_Z * line[f"{rate}_se"],
                    marker=_MARKERS[k % len(_MARKERS)],
                    ms=4,
                    capsize=2,
                    lw=1,
                    color=f"C{j % 10}",
                    label=label,
                )
            _log_axis(ax, data[against])
            ax.set_xlabel("SNR" if against == "snr" else "N")
        ax.set_ylim(-0.03, 1.08)
        ax.set_title(title, fontsize=10)
    axes[0].set_ylabel("rate")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right upper", fontsize=8)
    fig.suptitle(f"{_system(cells)}: convergence rates (95% MC bars)")
    fig.savefig(path, dpi=110)


def _cell_label(row) -> str:
    return f"N = {int(row['n'])}, SNR {float(row['snr']):g}"


def _rate_bars(ax, cells: pd.DataFrame, rate: str, estimators: list) -> None:
    # one group of bars per cell (N, SNR), one bar per estimator, side by side
    groups = list(cells.groupby(["n", "snr"], sort=True))
    width = 0.8 / max(len(estimators), 1)
    for k, estimator in enumerate(estimators):
        xs, heights, errors = [], [], []
        for g, (_, group) in enumerate(groups):
            row = group[group["estimator"] == estimator]
            if row.empty:
                continue
            xs.append(g + (k - (len(estimators) - 1) / 2) * width)
            heights.append(float(row[rate].iloc[0]))
            errors.append(_Z * float(row[f"{rate}_se"].iloc[0]))
        bars = ax.bar(xs, heights, width, yerr=errors, capsize=3, color=f"C{k}", label=estimator)
        ax.bar_label(bars, labels=[f"{h:.2f}" for h in heights], fontsize=7, padding=2)
    ax.set_xticks(range(len(groups)))
    ax.set_xticklabels([f"N = {n:g}\nSNR {snr:g}" for (n, snr), _ in groups], fontsize=8)


def plot_distributions(
    table: pd.DataFrame, path, n: int | None = None, summary: pd.DataFrame | None = None
) -> None:
    """Every parameter's estimates at one N (default the largest): a box per SNR and
    estimator, estimators side by side; the dashed line is the truth, the black error bar
    beside each box the truth +- the Cramér-Rao std of that cell (when known), the white
    diamond with its bar the mean with its 95% Monte-Carlo interval.

    Only the estimates the summary uses are drawn (`used_mask`). For a family of systems
    (the truth varies by row) the errors `estimate - truth` are drawn instead, around a
    dashed zero.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    n = int(table["n"].max()) if n is None else n
    data = table[(table["n"].to_numpy() == n) & used_mask(table)]
    names = parameter_names(table)
    estimators = list(dict.fromkeys(table["estimator"]))
    snrs = sorted(set(data["snr"].astype(float)))
    width = 0.8 / max(len(estimators), 1)
    fig, axes = _grid(len(names), width=3.6, height=2.8)
    bound_drawn = False
    for ax, name in zip(axes, names, strict=False):
        truth = table[true_column(name)].to_numpy()
        varying = not np.all(truth == truth[0])
        centre = 0.0 if varying else float(truth[0])
        for g, snr in enumerate(snrs):
            for k, estimator in enumerate(estimators):
                group = data[(data["snr"] == snr) & (data["estimator"] == estimator)]
                if group.empty:
                    continue
                x = g + (k - (len(estimators) - 1) / 2) * width
                values = group[name].to_numpy() - (
                    group[true_column(name)].to_numpy() if varying else 0.0
                )
                box = ax.boxplot(
                    [values],
                    positions=[x],
                    widths=0.6 * width,
                    patch_artist=True,
                    showfliers=True,
                    flierprops={"ms": 2, "alpha": 0.4, "markeredgecolor": f"C{k}"},
                    medianprops={"color": "k", "lw": 0.8},
                )
                box["boxes"][0].set_facecolor(f"C{k}")
                box["boxes"][0].set_alpha(0.55)
                se = values.std(ddof=1) / math.sqrt(len(values)) if len(values) > 1 else np.nan
                ax.errorbar(
                    [x], [values.mean()], yerr=[_Z * se], fmt="D", ms=3.5, mfc="w",
                    mec="k", ecolor="k", capsize=2, lw=0.8, zorder=4,
                )  # fmt: skip
                bound = _bound(summary, group, name)
                if np.isfinite(bound):
                    ax.errorbar(
                        [x + 0.38 * width], [centre], yerr=[bound], fmt="none",
                        ecolor="k", capsize=3, lw=1.2,
                    )  # fmt: skip
                    bound_drawn = True
        ax.axhline(centre, color="k", ls="--", lw=0.8)
        ax.set_xticks(range(len(snrs)))
        if len(snrs) > 1:
            ax.set_xticklabels([f"{s:g}" for s in snrs], fontsize=8)
            ax.set_xlabel("SNR")
        else:
            ax.set_xticklabels([])
        ax.set_xlim(-0.6, len(snrs) - 0.4)
        ax.set_title(f"{name} - truth" if varying else name, fontsize=10)
    handles = [Patch(color=f"C{k}", alpha=0.55, label=e) for k, e in enumerate(estimators)]
    handles.append(Line2D([], [], color="k", ls="--", lw=0.8, label="truth"))
    handles.append(
        Line2D([], [], marker="D", ms=3.5, mfc="w", mec="k", color="k", lw=0.8,
               label="mean, 95% MC interval")
    )  # fmt: skip
    if bound_drawn:
        handles.append(Line2D([], [], color="k", lw=1.2, marker="_", ms=6,
                              label="truth ± Cramér-Rao std"))  # fmt: skip
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8)
    where = f"N = {n}" + (f", SNR {snrs[0]:g}" if len(snrs) == 1 else "")
    fig.suptitle(f"{_system(table)}: distributions of the estimates, {where} (estimates used)")
    fig.savefig(path, dpi=110)


def _bound(summary: pd.DataFrame | None, group: pd.DataFrame, name: str) -> float:
    """The Cramér-Rao std of `name` in `group`'s cell: from the summary when given, else
    the median of the table's per-realisation bound column."""
    if summary is not None and "crlb_std" in summary:
        row = summary[
            (summary["n"] == group["n"].iloc[0])
            & (summary["snr"] == group["snr"].iloc[0])
            & (summary["estimator"] == group["estimator"].iloc[0])
            & (summary["parameter"] == name)
        ]
        if not row.empty:
            return float(row["crlb_std"].iloc[0])
    column = f"crlb_{name}"
    if column in group:
        values = group[column].to_numpy(float)
        values = values[np.isfinite(values)]
        return float(np.median(values)) if values.size else np.nan
    return np.nan


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
    fig = _figure(figsize=(min(12.0, max(6.0, 0.5 * len(names) * len(estimators))), 3.6))
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
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="the bound (efficiency 1)")
    ax.set_xticks(x)
    ax.set_xticklabels(names, fontsize=8)
    ax.set_ylabel("efficiency (bound variance / MC variance)")
    ax.legend(fontsize=8)
    system = ", ".join(map(str, dict.fromkeys(cell["system"])))
    ax.set_title(f"{system}, N = {n}, SNR {snr:g} (95% MC bars)", fontsize=10)
    fig.savefig(path, dpi=110)


def plot_sweep(summary: pd.DataFrame, table: pd.DataFrame, folder, stem: str) -> list[pathlib.Path]:
    """The figures of a sweep that fit its shape (`figure_names`) into `folder`, named
    `STEM_NAME.png`; returns the paths."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in figure_names(summary):
        path = folder / f"{stem}_{name}.png"
        if name.startswith(("bias_vs_", "rmse_vs_", "std_vs_")):
            statistic, against = name.split("_vs_")
            plot_statistic(summary, statistic, against, path)
        elif name == "convergence_rate":
            plot_convergence_rate(summary, path)
        elif name == "distributions":
            plot_distributions(table, path, summary=summary)
        else:
            plot_efficiency(summary, path)
        paths.append(path)
    return paths


def sweep_figures(folder, stem: str) -> list[pathlib.Path]:
    """The sweep figures of any shape already in `folder` under `stem` (so that a rerun
    that replaces a sweep can remove figures the new shape does not draw)."""
    kinds = [f"{s}_vs_{a}" for s in ("bias", "rmse", "std") for a in ("snr", "n")]
    kinds += ["convergence_rate", "distributions", "efficiency"]
    folder = pathlib.Path(folder)
    return [folder / f"{stem}_{k}.png" for k in kinds if (folder / f"{stem}_{k}.png").exists()]
