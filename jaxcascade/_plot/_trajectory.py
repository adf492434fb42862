"""Parameter trajectories of one fit, per block (the paper's Figs. 6-8 and 11-13)."""

from __future__ import annotations

import numpy as np


def plot_trajectories(solution, truth: dict, title: str, path=None):
    """The estimate of every parameter against the iteration, one panel per block of the
    cascade (NS, LD, ND), the true values dashed. Returns the figure; saves it to `path`
    when given."""
    orders = solution.params.orders
    history = np.asarray(solution.history)
    k = min(int(solution.iterations), history.shape[0] - 1)
    return plot_iterates(history[: k + 1], list(orders.names), orders.blocks, truth, title, path)


def plot_iterates(history, names, blocks, truth: dict, title: str, path=None, xlabel="iteration"):
    """`history` (one row per iterate, columns `names`) against the iterate, one panel
    per block (`blocks`: NS, LD, ND, each a list of names), the true values dashed."""
    from matplotlib.figure import Figure

    history = np.asarray(history)
    k = history.shape[0] - 1
    titles = {
        "NS": "static nonlinearity (NS)",
        "LD": "linear dynamics (LD)",
        "ND": "backlash (ND)",
    }
    figure = Figure(figsize=(14, 4.2), layout="constrained")
    axes = figure.subplots(1, len(blocks))
    for ax, (block, members) in zip(axes, blocks.items(), strict=True):
        for name in members:
            (line,) = ax.plot(range(k + 1), history[:, names.index(name)], marker=".", label=name)
            ax.axhline(truth[name], color=line.get_color(), ls="--", lw=0.8)
        ax.set_title(titles.get(block, block))
        ax.set_xlabel(xlabel)
        ax.set_ylabel("estimate")
        ax.legend(fontsize=8, ncol=2)
    figure.suptitle(title)
    if path is not None:
        figure.savefig(path, dpi=120)
    return figure
