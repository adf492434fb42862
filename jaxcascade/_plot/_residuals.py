"""Figures of the residual tests in `_diagnose.py` (matplotlib, imported lazily).

Figures are built with `matplotlib.figure.Figure`, not `pyplot`: no global state, no
backend needed to draw or save, and nothing to close. Each function draws into `ax` when
given and returns the figure.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

_PASS_COLOUR = {True: "tab:green", False: "tab:red"}


def _new_axes(ax, figsize=(6.0, 3.6)):
    if ax is not None:
        return ax.figure, ax
    from matplotlib.figure import Figure

    figure = Figure(figsize=figsize, layout="constrained")
    return figure, figure.add_subplot()


def _verdict(test) -> str:
    return f"{'passed' if test.passed else 'FAILED'} (p = {test.p_value:.3g})"


def plot_correlation(test, ax=None):
    """Correlation against lag, the pointwise 95% band and the simultaneous bound."""
    figure, ax = _new_axes(ax)
    lags, values = np.asarray(test.lags), np.asarray(test.values)
    colour = _PASS_COLOUR[bool(test.passed)]
    ax.vlines(lags, 0.0, values, color=colour, lw=1.5)
    ax.plot(lags, values, "o", color=colour, ms=3)
    ax.axhspan(-test.bound, test.bound, color="tab:blue", alpha=0.15, label="95% pointwise")
    for sign in (-1, 1):
        ax.axhline(
            sign * test.simultaneous_bound,
            color="k",
            ls="--",
            lw=0.8,
            label="simultaneous bound" if sign > 0 else None,
        )
    ax.axhline(0.0, color="k", lw=0.5)
    if test.name == "autocorrelation":
        ax.set_ylim(min(-2.5 * test.bound, float(np.min(values[1:])) * 1.1), 1.05)
    ax.set_xlabel("lag k (samples)")
    ax.set_ylabel(test.label)
    ax.set_title(f"{test.label}: {_verdict(test)}", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    return figure


def plot_groups(test, ax=None, xlabel: str | None = None):
    """Mean residual per group with 95% intervals (regime, input level or time block)."""
    figure, ax = _new_axes(ax)
    valid = np.asarray(test.counts) >= 2
    means = np.asarray(test.means)
    half = 1.96 * np.asarray(test.standard_errors)
    if test.name == "regime":
        x = np.arange(len(test.labels))
        ax.set_xticks(x, test.labels, fontsize=8)
    else:
        x = np.asarray(test.positions)
    colour = _PASS_COLOUR[bool(test.passed)]
    ax.errorbar(x[valid], means[valid], yerr=half[valid], fmt="o", color=colour, capsize=3)
    ax.axhline(0.0, color="k", lw=0.5)
    default = {
        "regime": "backlash regime",
        "branch": "model's backlash output on the left / right branch (bin mean)",
        "level": "input u (bin mean)",
        "time": "sample",
    }
    ax.set_xlabel(xlabel or default.get(test.name, test.name))
    ax.set_ylabel("mean residual ± 1.96 se")
    ax.set_title(
        f"residual by {test.name}: {_verdict(test)}; "
        f"p(zero) = {test.p_zero:.3g}, p(equal) = {test.p_equal:.3g}",
        fontsize=9,
    )
    return figure


def plot_drift(test, ax=None):
    """Block means over time and the fitted straight line."""
    figure, ax = _new_axes(ax)
    blocks = test.blocks
    plot_groups(blocks, ax=ax, xlabel="sample")
    starts = np.asarray(blocks.positions)
    n = float(np.sum(blocks.counts))
    t = np.array([0.0, n - 1.0])
    ax.plot(t, test.intercept + test.slope * t / n, color="k", lw=1, label="linear fit")
    ax.legend(fontsize=7)
    ax.set_xlim(-0.02 * n, 1.02 * n if starts.size else 1.0)
    ax.set_title(
        f"residual over time: {_verdict(test)}; slope {test.slope:.3g} ± "
        f"{1.96 * test.slope_se:.2g} per record",
        fontsize=9,
    )
    return figure


def plot_spectrum(test, axes=None):
    """Welch PSD of the residual (left) and the cumulative periodogram with its KS band."""
    if axes is None:
        from matplotlib.figure import Figure

        figure = Figure(figsize=(9.0, 3.6), layout="constrained")
        axes = figure.subplots(1, 2)
    left, right = axes
    figure = left.figure
    colour = _PASS_COLOUR[bool(test.passed)]
    f, psd = np.asarray(test.frequency), np.asarray(test.psd)
    left.semilogy(f[1:], psd[1:], color=colour)
    left.axhline(test.psd_level, color="k", ls="--", lw=0.8, label="flat level")
    left.set_xlabel("frequency")
    left.set_ylabel("PSD of residual (Welch)")
    left.set_title(f"spectrum, flatness {test.flatness:.3f}", fontsize=9)
    left.legend(fontsize=7)
    fc, cum = np.asarray(test.cumulative_frequency), np.asarray(test.cumulative)
    line = np.arange(1, cum.size + 1) / cum.size
    right.plot(fc, cum, color=colour, lw=1)
    right.plot(fc, line, color="k", lw=0.8)
    right.fill_between(fc, line - test.ks_bound, line + test.ks_bound, color="tab:blue", alpha=0.15)
    right.set_xlabel("frequency")
    right.set_ylabel("cumulative periodogram")
    right.set_title(f"flatness test: {_verdict(test)}", fontsize=9)
    return figure


def plot_hysteresis(test, ax=None):
    """Partial correlation of the residual with stop operators of the input against the
    threshold, with the simultaneous bounds; the direction means in the title."""
    figure, ax = _new_axes(ax)
    r, values, bounds = (np.asarray(a) for a in (test.thresholds, test.values, test.bounds))
    ax.plot(r, values, "o-", ms=3, label="corr(e, stop_r(u) | cubic in u)")
    ax.fill_between(r, -bounds, bounds, color="0.85", label="simultaneous bound")
    ax.set_xscale("log")
    ax.set_xlabel("stop-operator threshold r (model units)")
    means = ", ".join(
        f"{label} {m:.3g}"
        for label, m in zip(test.direction.labels, test.direction.means, strict=True)
    )
    ax.set_title(f"hysteresis: {_verdict(test)} (means {means})", fontsize=9)
    ax.legend(fontsize=7)
    return figure


def plot_test(test):
    """A new figure for one test of a `ResidualTests`."""
    from .._measured._diagnose import (
        CorrelationTest,
        DriftTest,
        GroupTest,
        HysteresisTest,
        SpectrumTest,
    )

    if isinstance(test, HysteresisTest):
        return plot_hysteresis(test)

    if isinstance(test, CorrelationTest):
        return plot_correlation(test)
    if isinstance(test, DriftTest):
        return plot_drift(test)
    if isinstance(test, GroupTest):
        return plot_groups(test)
    if isinstance(test, SpectrumTest):
        return plot_spectrum(test)
    raise ValueError(f"No figure for a {type(test).__name__}.")


def residual_figures(tests) -> dict:
    """One figure per test, by test name (the mean test is shown in none: it is one number)."""
    return {name: plot_test(test) for name, test in tests.tests().items() if name != "mean"}


def plot_residual_tests(tests):
    """All tests of a `ResidualTests` in one overview figure."""
    from matplotlib.figure import Figure

    items = [(n, t) for n, t in tests.tests().items() if n not in ("mean", "spectrum")]
    rows = (len(items) + 1) // 2 + 1
    figure = Figure(figsize=(11.0, 3.0 * rows), layout="constrained")
    grid = figure.add_gridspec(rows, 2)
    for i, (name, test) in enumerate(items):
        ax = figure.add_subplot(grid[i // 2, i % 2])
        if name == "time":
            plot_drift(test, ax=ax)
        elif name in ("regime", "branch", "level"):
            plot_groups(test, ax=ax)
        elif name == "hysteresis":
            plot_hysteresis(test, ax=ax)
        else:
            plot_correlation(test, ax=ax)
    plot_spectrum(tests.spectrum, axes=[figure.add_subplot(grid[rows - 1, j]) for j in (0, 1)])
    flags = (
        f"whiteness {'ok' if tests.whiteness_ok else 'FAILED'}, "
        f"independence {'ok' if tests.independence_ok else 'FAILED'}, "
        f"conditional means {'ok' if tests.conditional_ok else 'FAILED'} "
        f"(N = {tests.n}, alpha = {tests.alpha}; mean {tests.mean.mean:.3g}, "
        f"{_verdict(tests.mean)})"
    )
    figure.suptitle(flags, fontsize=10)
    return figure


def save_residual_figures(
    tests, folder: str | os.PathLike, *, prefix: str = "residual_", format: str = "png", dpi=120
) -> list[Path]:
    """Write one figure per test and the overview into `folder`; returns the paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    figures = {"overview": plot_residual_tests(tests), **residual_figures(tests)}
    paths = []
    for name, figure in figures.items():
        path = folder / f"{prefix}{name}.{format}"
        figure.savefig(path, dpi=dpi)
        paths.append(path)
    return paths
