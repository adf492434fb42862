"""Sweep figures fit the sweep's shape: which figures a one-cell sweep, a line of cells
and a grid draw (names, not pixels), and that the bound's legend entry appears only
where a bound is drawn."""

import numpy as np
import pandas as pd
import pytest

from jaxcascade._montecarlo._run import run
from jaxcascade._montecarlo._spec import Spec
from jaxcascade._montecarlo._tables import summarise
from jaxcascade._plot._sweep import figure_names, plot_statistic, plot_sweep, sweep_figures

VERSUS = {f"{s}_vs_{a}" for s in ("bias", "rmse", "std") for a in ("snr", "n")}
ALWAYS = {"convergence_rate", "distributions", "efficiency"}


@pytest.fixture(scope="module")
def one_cell() -> pd.DataFrame:
    # Two estimators in one cell (N = 300, SNR 25), the shape of the README's quickstart:
    # the literal cell computed (the program test_montecarlo.py compiles too) and copied
    # under a second estimator's name, the figures' choice depending only on the labels.
    spec = Spec(example=1, n=300, snr=[25.0], realisations=6, seed=0, chunk_size=3)
    table = run(spec, progress=False)
    return pd.concat([table, table.assign(estimator="robust")], ignore_index=True)


def relabelled(table: pd.DataFrame, ns=(300,), snrs=(25.0,)) -> pd.DataFrame:
    # A grid from one computed cell: the figures' choice depends on the cells' labels,
    # not on the numbers in them, and no further program is compiled.
    frames = [table.assign(n=n, snr=snr) for n in ns for snr in snrs]
    return pd.concat(frames, ignore_index=True)


def drawn(table, tmp_path, stem):
    paths = plot_sweep(summarise(table), table, tmp_path, stem)
    assert all(p.stat().st_size > 10_000 for p in paths)  # a figure, not an empty canvas
    return {p.name.removeprefix(f"{stem}_").removesuffix(".png") for p in paths}


def test_one_cell_draws_no_versus_plot(one_cell, tmp_path):
    assert drawn(one_cell, tmp_path, "cell") == ALWAYS


def names(table) -> set[str]:
    # what plot_sweep draws (drawing itself: the one-cell test above, and
    # test_montecarlo.py's test_plots_are_written for a line of SNRs)
    found = figure_names(summarise(table))
    assert len(found) == len(set(found))  # no figure twice
    return set(found)


def test_a_line_of_snrs_draws_versus_snr_only(one_cell):
    table = relabelled(one_cell, snrs=(10.0, 25.0, np.inf))
    assert names(table) == ALWAYS | {"bias_vs_snr", "rmse_vs_snr", "std_vs_snr"}


def test_a_line_of_sample_sizes_draws_versus_n_only(one_cell):
    table = relabelled(one_cell, ns=(300, 600))
    assert names(table) == ALWAYS | {"bias_vs_n", "rmse_vs_n", "std_vs_n"}


def test_a_grid_draws_every_figure_once(one_cell, tmp_path):
    table = relabelled(one_cell, ns=(300, 600, 1200), snrs=(10.0, 25.0, 50.0))
    assert names(table) == ALWAYS | VERSUS
    # a rerun with --overwrite finds every earlier figure of the stem, and only those
    for name in [*VERSUS, *ALWAYS, "other_distributions"]:
        (tmp_path / f"grid_{name}.png").touch()
    found = {
        p.name.removeprefix("grid_").removesuffix(".png") for p in sweep_figures(tmp_path, "grid")
    }
    assert found == ALWAYS | VERSUS


def test_noise_free_cells_do_not_make_a_versus_snr_plot(one_cell):
    # SNR axes drop inf: 25 and inf are one finite SNR, so no "versus SNR" figure.
    table = relabelled(one_cell, snrs=(25.0, np.inf))
    assert not set(figure_names(summarise(table))) & VERSUS


def test_bound_is_in_the_legend_only_where_drawn(one_cell, tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    legends = []
    monkeypatch.setattr(
        Figure,
        "savefig",
        lambda fig, *a, **k: legends.append(
            [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().texts]
        ),
    )
    summary = summarise(relabelled(one_cell, snrs=(10.0, 25.0)))
    plot_statistic(summary, "std", "snr", tmp_path / "a.png")
    plot_statistic(summary.assign(crlb_std=np.nan), "std", "snr", tmp_path / "b.png")
    plot_statistic(summary, "bias", "snr", tmp_path / "c.png")
    with_bound, without, bias = legends
    assert "Cramér-Rao bound" in with_bound
    assert "Cramér-Rao bound" not in without and "Cramér-Rao bound" not in bias
    assert {"literal", "robust"} <= set(bias)  # one cell of N: labels name the estimator
