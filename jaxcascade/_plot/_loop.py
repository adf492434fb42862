"""Figures of the model-error loop's report."""

from __future__ import annotations

from .._metrics import fit_percent, nrmse


def plot_compare(time, y, before, after, path, *, arx=None, title="") -> None:
    """Measured versus simulated validation output, before and after the loop."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(12, 6.5), layout="constrained")
    axes = figure.subplots(2, 1, sharex=True)
    for ax, (label, simulated) in zip(axes, (("before", before), ("after", after)), strict=True):
        ax.plot(time, y, color="0.3", lw=0.8, label="measured")
        ax.plot(
            time,
            simulated,
            lw=0.8,
            label=f"cascade {label} ({fit_percent(nrmse(y, simulated)):.1f} % fit)",
        )
        if arx is not None:
            ax.plot(
                time, arx, lw=0.6, ls="--", label=f"ARX ({fit_percent(nrmse(y, arx)):.1f} % fit)"
            )
        ax.legend(loc="upper right", fontsize=8)
        ax.set_ylabel("output")
    axes[-1].set_xlabel("time" if time is not None else "sample")
    figure.suptitle(title)
    figure.savefig(path, dpi=110)
