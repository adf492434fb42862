"""`reproduce_example`: one record of a paper example, fitted, with its table and figure,
as `jaxcascade reproduce` does.

One record of an example is simulated (input uniform in (-2, 2), output noise at the
given SNR), fitted (default: the literal iteration from the paper's initial values), and
the parameter trajectories are drawn per block as in the paper's figures 6-8 and 11-13.
With `snr=inf` an estimator that declares settings for a noise-free record
(`noise_free`: the recursive estimator's constant memory and Gauss-Newton gain,
`_recursive.NOISE_FREE`) runs with them; the title names the settings used. The general
output backlash's examples (`general1`, `general2`, docs/general_backlash.md) are fitted
by the note's key-term iteration (`literal`) or the robust fit refined with curved
branches (`robust`).

The result, `Reproduction`, holds the title, the status, the table of estimates and the
files written (`<tag>_estimates.csv`, `<tag>_estimates.md`, `<tag>_convergence.png`);
`to_dict()` is the command's `--json`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import pathlib
from typing import Any

from .._status import Status

GENERAL_ESTIMATORS = ("literal", "robust")


@dataclasses.dataclass(frozen=True)
class Reproduction:
    """What `reproduce_example` returns (`jaxcascade reproduce` prints it).

    - `title`: the example, the record and the estimator, with the status and the
      iterations (the figure's and the Markdown table's title).
    - `status` (`Status`), `message` (the status's sentence).
    - `table`: a pandas DataFrame, one row per parameter: `parameter`, `true`,
      `estimate`, `error`.
    - `summary`: the example, the iterations, the status (its name), the estimates and
      the true values by name (a paper example's also the noise-free `settings` used and
      the `cycle_amplitude`).
    - `stem`: the folder and the tag the files' names start with
      (`example1_snr25_seed0`, `general1_snrinf_seed0_robust`); `written`: the ends of
      their names (`estimates.csv`, `estimates.md`, `convergence.png`); `files`: their
      paths.

    `to_dict()` is `jaxcascade reproduce --json`: `summary` with the message after the
    status.
    """

    title: str
    status: Status
    message: str
    table: Any
    summary: dict
    stem: pathlib.Path
    written: tuple[str, ...]

    @property
    def files(self) -> list[pathlib.Path]:
        """The paths of the files written."""
        return [self.stem.with_name(f"{self.stem.name}_{end}") for end in self.written]

    def to_dict(self) -> dict[str, Any]:
        """`jaxcascade reproduce --json`: `summary`, the message right after the status."""
        keys = list(self.summary)
        keys.insert(keys.index("status") + 1, "message")
        return {k: self.message if k == "message" else self.summary[k] for k in keys}

    def __repr__(self) -> str:
        return f"Reproduction({self.title!r}; {len(self.written)} files at {str(self.stem)!r})"


def reproduce_example(
    example: int | str,
    *,
    seed: int = 0,
    snr: float = 25.0,
    estimator: str = "literal",
    max_iterations: int | None = None,
    out: str | os.PathLike = "results",
) -> Reproduction:
    """Simulate one record of `example`, fit it and write its table and figure into
    `out` (module docstring), as `jaxcascade reproduce` does.

    - `example`: 1 or 2 (the paper's), `"general1"` or `"general2"` (the general output
      backlash: `estimator` `literal` or `robust`).
    - `seed`: the record's PRNG seed; `snr`: sqrt(var y / var e), positive, `inf` for a
      noise-free record (with the estimator's noise-free settings where it has them).
    - `estimator`: a registered estimator's name (a user's too).
    - `max_iterations`: the budget of estimators that have one (default 50; 200 for the
      key-term iteration of `general1`, `general2`).
    - `out`: the folder (created if needed); as given, it is also the `--out` of the
      command the Markdown table names.

    Raises `ValueError` (before any work) for a non-positive `snr`, a `max_iterations`
    below 1, an unknown estimator or one the general-backlash examples do not take.
    """
    if not snr > 0:
        raise ValueError(
            f"--snr must be positive (an amplitude ratio; inf = noise-free), got {snr}."
        )
    general = isinstance(example, str)
    if max_iterations is None:
        max_iterations = 200 if general else 50
    if max_iterations < 1:
        raise ValueError(f"--max-iterations must be at least 1, got {max_iterations}.")
    folder = pathlib.Path(out)
    if general:
        return _reproduce_general(example, seed, snr, estimator, max_iterations, out, folder)
    return _reproduce_paper(example, seed, snr, estimator, max_iterations, out, folder)


def run_example(
    ex,
    seed: int = 0,
    snr: float | None = None,
    dtype=None,
    name: str = "literal",
    **settings,
) -> tuple:
    """Simulate one record of `ex` and fit it with the registered estimator `name`
    (default: the paper's iteration from the paper's initial values).

    The input key and the noise key are the two halves of `PRNGKey(seed)`. `snr=inf`
    gives a noise-free record. The estimator is told the input distribution's range
    (`input_range`), so the literal iteration starts from the paper's DR1 = 1, DL1 = -1.
    Returns the solution (`Solution`) and the true values by name.
    """
    import jax

    from .._estimator import estimator
    from .._system._simulate import measure, uniform_input

    dtype = dtype or jax.numpy.result_type(float)
    snr = ex.snr if snr is None else snr
    key_input, key_noise = jax.random.split(jax.random.PRNGKey(seed))
    truth = ex.params(dtype)
    u = uniform_input(key_input, ex.n_samples, ex.amplitude, dtype)
    y, _ = measure(key_noise, truth, u, snr)
    fit = estimator(name, **settings)
    solution = fit(u, y, ex.orders, input_range=(-ex.amplitude, ex.amplitude))
    return jax.device_get(solution), truth.to_dict()


def estimates_table(solution, truth: dict):
    """pandas DataFrame: parameter, true value, estimate, error."""
    return _table(solution.params.to_dict(), truth)


def _table(estimate: dict, truth: dict):
    import pandas as pd

    return pd.DataFrame(
        {
            "parameter": list(truth),
            "true": list(truth.values()),
            "estimate": [estimate[name] for name in truth],
            "error": [estimate[name] - truth[name] for name in truth],
        }
    )


def _markdown(table, header: str) -> str:
    lines = [header, "", "| parameter | true | estimate | error |", "|---|---|---|---|"]
    for row in table.itertuples():
        lines.append(
            f"| {row.parameter} | {row.true:.4f} | {row.estimate:.6f} | {row.error:+.2e} |"
        )
    return "\n".join(lines) + "\n"


def curvature_names(degree: int) -> list[str]:
    """The general backlash's curvature terms by name: `mL_2..mL_q`, `mR_2..mR_q`."""
    powers = range(2, degree + 1)
    return [f"mL_{i}" for i in powers] + [f"mR_{i}" for i in powers]


def run_general_example(
    ex, seed: int = 0, snr: float | None = None, name: str = "literal", **settings
):
    """One record of the general-backlash example `ex` (`_general_backlash`), fitted.

    The record is drawn as `run_example` draws the 2016 examples' (input uniform in
    `(-amplitude, amplitude)`, the two halves of `PRNGKey(seed)`, white noise at the
    amplitude SNR), the output simulated with the curved branches. `name`: `literal`,
    the note's key-term iteration from the paper's initial values (curvature 0;
    `key_term_general`, with `settings`), or `robust`, the robust straight fit refined
    with curved branches (`robust_general`). Returns `(status, iterations, estimates,
    truth, history)`: estimates and truth by name (the cascade's, then `curvature_names`),
    `history` one row per iterate in that order (`None` for `robust`)."""
    import jax
    import numpy as np

    from .._estimator._general_keyterm import key_term_general
    from .._estimator._general_refine import robust_general
    from .._system._general_backlash import simulate_general
    from .._system._model import CascadeParams
    from .._system._simulate import add_noise, uniform_input

    dtype = jax.numpy.result_type(float)
    snr = ex.snr if snr is None else snr
    key_input, key_noise = jax.random.split(jax.random.PRNGKey(seed))
    params, nd = ex.params(dtype), ex.backlash(dtype)
    u = uniform_input(key_input, ex.n_samples, ex.amplitude, dtype)
    y = add_noise(key_noise, simulate_general(params, nd, u), snr)
    names = [*ex.orders.names, *curvature_names(nd.degree)]

    def by_name(p, curved) -> dict:
        values = [
            *np.asarray(p.to_vector()),
            *np.asarray(curved.curveL),
            *np.asarray(curved.curveR),
        ]
        return {n: float(v) for n, v in zip(names, values, strict=True)}

    truth = by_name(params, nd)
    if name == "literal":
        fit = jax.device_get(key_term_general(u, y, ex.orders, nd.degree, **settings))
        k = int(fit.iterations)
        size = ex.orders.size
        theta = np.asarray(fit.history)[: k + 1]
        cascade = np.asarray(
            CascadeParams.from_theta(
                jax.numpy.asarray(theta[:, :size]), ex.orders, check=False
            ).to_vector()
        )
        history = np.concatenate([cascade, theta[:, size:]], axis=1)
        return int(fit.status), k, by_name(fit.params, fit.backlash), truth, history
    fit = jax.device_get(robust_general(u, y, ex.orders, nd.degree, key=key_noise, **settings))
    return int(fit.status), int(fit.steps), by_name(fit.params, fit.backlash), truth, None


def _reproduce_general(
    name: str, seed: int, snr: float, estimator: str, max_iterations: int, out, folder
) -> Reproduction:
    from .._plot._trajectory import plot_iterates
    from .._system._general_backlash import general_example

    if estimator not in GENERAL_ESTIMATORS:
        raise ValueError(
            f"--estimator {estimator}: the general-backlash examples take literal (the "
            "note's key-term iteration) or robust (the robust fit refined with curved branches)."
        )
    ex = general_example(name)
    folder.mkdir(parents=True, exist_ok=True)
    settings = {"max_iterations": max_iterations} if estimator == "literal" else {}
    code, iterations, estimates, truth, history = run_general_example(
        ex, seed, snr, estimator, **settings
    )
    status = Status(code)
    table = _table(estimates, truth)
    tag = f"{ex.name}_snr{snr:g}_seed{seed}"
    if estimator != "literal":
        tag += f"_{estimator}"
    degree = len(ex.curveL) + 1
    what = "key-term iteration" if estimator == "literal" else "robust estimator, refined"
    title = (
        f"Example {ex.name} (general backlash, degree {degree}), N = {ex.n_samples}, "
        f"SNR = {snr:g}, seed {seed}, {what}: {status.name} after {iterations} "
        f"{'iterations' if estimator == 'literal' else 'steps'}"
    )
    table.to_csv(folder / f"{tag}_estimates.csv", index=False)
    header = (
        f"## {title}\n\nCommand: `jaxcascade reproduce --example {ex.name} --seed {seed} "
        f"--snr {snr:g} --estimator {estimator} --out {out}`"
    )
    (folder / f"{tag}_estimates.md").write_text(_markdown(table, header))
    written = ["estimates.csv", "estimates.md"]
    if history is not None:
        blocks = {block: list(names) for block, names in ex.orders.blocks.items()}
        blocks["ND"] = [*blocks["ND"], *curvature_names(degree)]
        names = list(truth)
        plot_iterates(history, names, blocks, truth, title, folder / f"{tag}_convergence.png")
        written.append("convergence.png")
    summary = {"example": ex.name, "iterations": iterations, "status": status.name}
    summary |= {"estimates": estimates, "true": truth}
    return Reproduction(title, status, status.message, table, summary, folder / tag, tuple(written))


def _reproduce_paper(
    number: int, seed: int, snr: float, estimator: str, max_iterations: int, out, folder
) -> Reproduction:
    from .._estimator import lookup
    from .._plot._trajectory import plot_trajectories
    from .._system._examples import example

    ex = example(number)
    try:  # ours, or a user's (registered, or by its package's entry point)
        registered = lookup(estimator)
    except ValueError as error:
        raise ValueError(f"--estimator: {error}") from None
    folder.mkdir(parents=True, exist_ok=True)
    takes = "max_iterations" in registered.settings()
    settings = {"max_iterations": max_iterations} if takes else {}
    if math.isinf(snr):  # noise-free: the estimator's own noise-free settings
        settings |= dict(getattr(registered, "noise_free", {}))
    solution, truth = run_example(ex, seed, snr, name=estimator, **settings)
    status = Status(int(solution.status))
    iterations = int(solution.iterations)
    table = estimates_table(solution, truth)
    tag = f"example{ex.number}_snr{snr:g}_seed{seed}"
    if estimator != "literal":
        tag += f"_{estimator}"
    used = {k: v for k, v in settings.items() if k != "max_iterations"}
    named = ", ".join(f"{k}={v}" for k, v in used.items())
    title = (
        f"Example {ex.number}, N = {ex.n_samples}, SNR = {snr:g}, seed {seed}, "
        f"{estimator} estimator{f' ({named})' if named else ''}: {status.name} after "
        f"{iterations} iterations"
    )
    table.to_csv(folder / f"{tag}_estimates.csv", index=False)
    header = (
        f"## {title}\n\nEstimator `{estimator}`: {registered.summary}. "
        f"Command: `jaxcascade reproduce --example {ex.number} --seed {seed} "
        f"--snr {snr:g} --estimator {estimator} --out {out}`"
    )
    (folder / f"{tag}_estimates.md").write_text(_markdown(table, header))
    plot_trajectories(solution, truth, title, folder / f"{tag}_convergence.png")

    summary = {
        "example": ex.number,
        "iterations": iterations,
        "status": status.name,
        "settings": used,
        "cycle_amplitude": float(solution.cycle_amplitude),
        "estimates": solution.params.to_dict(),
        "true": truth,
    }
    written = ("estimates.csv", "estimates.md", "convergence.png")
    return Reproduction(title, status, status.message, table, summary, folder / tag, written)
