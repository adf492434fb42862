"""The figure of a model applied to a record (`jaxcascade simulate`, the loop report's
`records/`): measured versus simulated output against time, a zoomed window, and the
residual with its autocorrelation's confidence band (MATLAB's `compare` and `resid`)."""

from __future__ import annotations

import numpy as np

from .._metrics import fit_percent

# The zoomed panel: the first `ZOOM_FRACTION` of the scored samples, at least
# `ZOOM_MIN` samples (the whole scored part of a shorter record).
ZOOM_FRACTION = 0.1
ZOOM_MIN = 100
# The residual autocorrelation: lags 1 to `MAX_LAG` (a quarter of a shorter record), and
# the band a white residual stays inside at the 99 % level, +-2.58 / sqrt(N).
MAX_LAG = 25
BAND_Z = 2.576


def zoom_window(first: int, length: int) -> tuple[int, int]:
    """The zoomed panel's samples `[start, stop)` of a record of `length` samples whose
    scored part starts at `first`."""
    scored = length - first
    count = min(scored, max(ZOOM_MIN, int(ZOOM_FRACTION * scored)))
    return first, first + count


def plot_comparison(comparison, path, *, title: str = "", units: str = "output"):
    """Measured output, the initialised simulation (its state set on the shaded samples)
    and the simulation from rest of one `_model_file.Comparison`, against time in
    seconds (in samples where the record's period is unknown: `seconds` False), with fit
    %, NRMSE and RMSE in `units` in the legend; below, a zoomed window (`zoom_window`),
    the initialised residual in `units` and its autocorrelation with the 99 % band of a
    white residual. Returns the `Figure`; its first axes are the whole record's."""
    from matplotlib.figure import Figure

    c, s = comparison, comparison.score
    figure = Figure(figsize=(12, 7.5), layout="constrained")
    grid = figure.add_gridspec(2, 3, height_ratios=(1.2, 1.0))
    ax = figure.add_subplot(grid[0, :])
    zoom = figure.add_subplot(grid[1, 0])
    res = figure.add_subplot(grid[1, 1])
    acf = figure.add_subplot(grid[1, 2])
    xlabel = "time (s)" if c.seconds else "sample"
    first = int(np.argmax(np.isfinite(c.initialised)))
    labels = {
        "measured": "measured",
        "initialised": f"initialised ({fit_percent(s.error):.1f} % fit, NRMSE "
        f"{s.error:.4f}, RMSE {s.rmse:.4g} {units})",
        "from rest": f"from rest ({fit_percent(s.error_from_rest):.1f} % fit, NRMSE "
        f"{s.error_from_rest:.4f}, RMSE {c.rmse_from_rest:.4g} {units})",
    }
    start, stop = zoom_window(first, len(c.y))
    for axis, part in ((ax, slice(None)), (zoom, slice(start, stop))):
        t = c.time[part]
        axis.plot(t, c.y[part], color="0.3", lw=0.8, label=labels["measured"])
        axis.plot(t, c.initialised[part], lw=0.8, label=labels["initialised"])
        axis.plot(t, c.from_rest[part], lw=0.7, ls="--", label=labels["from rest"])
        axis.set_ylabel(units)
        axis.set_xlabel(xlabel)
    if first > 0:
        ax.axvspan(c.time[0], c.time[first], color="tab:orange", alpha=0.25, label="state set")
    if stop - start < 0.9 * (len(c.y) - first):
        ax.axvspan(c.time[start], c.time[stop - 1], color="0.85", alpha=0.5, label="zoomed below")
    ax.legend(loc="upper right", fontsize=8)
    unit_of_time = "s" if c.seconds else "samples"
    zoom.set_title(
        f"zoom: samples {start} to {stop - 1} ({c.time[start]:.4g} to {c.time[stop - 1]:.4g} "
        f"{unit_of_time})",
        fontsize=9,
    )
    residual = (c.y - c.initialised)[first:]
    res.plot(c.time[first:], residual, color="tab:red", lw=0.7)
    res.axhline(0.0, color="0.5", lw=0.6)
    res.set_ylabel(f"residual ({units})")
    res.set_xlabel(xlabel)
    res.set_title("measured - initialised simulation", fontsize=9)
    lags, r = _autocorrelation(residual)
    band = BAND_Z / np.sqrt(max(len(residual), 1))
    acf.vlines(lags, 0.0, r, color="tab:red", lw=1.2)
    acf.axhspan(-band, band, color="tab:blue", alpha=0.15, label="99 % band of white noise")
    acf.axhline(0.0, color="0.5", lw=0.6)
    acf.set_xlabel("lag (samples)")
    acf.set_ylabel("autocorrelation")
    acf.set_title("residual autocorrelation", fontsize=9)
    acf.legend(loc="upper right", fontsize=8)
    figure.suptitle(title)
    figure.savefig(path, dpi=100)
    return figure


def _autocorrelation(residual) -> tuple[np.ndarray, np.ndarray]:
    """Lags 1 to `MAX_LAG` (at most a quarter of the record) and the residual's
    normalised autocorrelation there (zeros for a constant or too short residual)."""
    e = np.asarray(residual, float)
    e = e[np.isfinite(e)]
    count = int(max(1, min(MAX_LAG, len(e) // 4)))
    lags = np.arange(1, count + 1)
    e = e - e.mean() if len(e) else e
    denominator = float(np.sum(e**2))
    if len(e) <= count or denominator == 0.0:
        return lags, np.zeros(count)
    return lags, np.array([np.sum(e[k:] * e[:-k]) / denominator for k in lags])
