"""Figures of the model-error loop's report."""

from __future__ import annotations

from .._metrics import fit_percent, score


def plot_compare(
    time, y, before, after, path, *, arx=None, title="", units="output", init=None, scored=None
) -> None:
    """Measured versus simulated validation output: the declared cascade, and the final
    model when the loop changed it (`after`, None otherwise: one panel), the ARX peer,
    the initialisation span (`init`, shaded) and the scored span (`scored`, marked)."""
    from matplotlib.figure import Figure

    panels = [("declared cascade", before)] + (
        [("final model", after)] if after is not None else []
    )
    figure = Figure(figsize=(12, 3.4 * len(panels) + 0.4), layout="constrained")
    axes = figure.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (label, simulated) in zip(axes, panels, strict=True):
        ax.plot(time, y, color="0.3", lw=0.8, label="measured")
        ax.plot(
            time,
            simulated,
            lw=0.8,
            label=f"{label}, from rest ({fit_percent(score(y, simulated)):.1f} % fit)",
        )
        if arx is not None:
            ax.plot(
                time, arx, lw=0.6, ls="--", label=f"ARX ({fit_percent(score(y, arx)):.1f} % fit)"
            )
        if init is not None:
            ax.axvspan(*init, color="tab:orange", alpha=0.25, label="state initialisation")
        if scored is not None:
            ax.axvspan(*scored, color="tab:green", alpha=0.08, label="scored samples")
        ax.legend(loc="upper right", fontsize=8)
        ax.set_ylabel(units)
    axes[-1].set_xlabel("time" if time is not None else "sample")
    figure.suptitle(title)
    figure.savefig(path, dpi=110)
