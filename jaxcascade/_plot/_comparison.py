"""The figure of a saved model applied to a record (`jaxcascade simulate`): measured
versus simulated output against time."""

from __future__ import annotations

import numpy as np

from .._metrics import fit_percent


def plot_comparison(comparison, path, *, title: str = "", units: str = "output"):
    """Measured output, the initialised simulation (its state set on the shaded samples)
    and the simulation from rest of one `_model_file.Comparison`, against time in
    seconds (in samples where the record's period is unknown: `seconds` False). Returns
    the `Figure`."""
    from matplotlib.figure import Figure

    c, s = comparison, comparison.score
    figure = Figure(figsize=(12, 4.2), layout="constrained")
    ax = figure.subplots()
    ax.plot(c.time, c.y, color="0.3", lw=0.8, label="measured")
    ax.plot(
        c.time,
        c.initialised,
        lw=0.8,
        label=f"initialised ({fit_percent(s.error):.1f} % fit, NRMSE {s.error:.4f})",
    )
    ax.plot(
        c.time,
        c.from_rest,
        lw=0.7,
        ls="--",
        label=f"from rest ({fit_percent(s.error_from_rest):.1f} % fit, "
        f"NRMSE {s.error_from_rest:.4f})",
    )
    first = int(np.argmax(np.isfinite(c.initialised)))
    if first > 0:
        ax.axvspan(c.time[0], c.time[first], color="tab:orange", alpha=0.25, label="state set")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_ylabel(units)
    ax.set_xlabel("time (s)" if c.seconds else "sample")
    figure.suptitle(title)
    figure.savefig(path, dpi=110)
    return figure
