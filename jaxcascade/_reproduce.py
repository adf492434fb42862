"""`jaxcascade reproduce`: the paper's examples, figures 6-8 and 11-13, and a table.

One record of an example is simulated (input uniform in (-2, 2), output noise at the
given SNR), the literal iteration is run from the paper's initial values, and the
parameter trajectories are drawn per block as in the paper's figures.
"""

from __future__ import annotations

import json
import pathlib

import jax
import numpy as np

from ._estimate import Solution, initial_guess, voros
from ._examples import Example, example
from ._simulate import measure, uniform_input
from ._status import Status

_BLOCKS = {
    "static nonlinearity (NS)": ("MR", "DR", "ML", "DL"),
    "linear dynamics (LD)": ("a", "b"),
    "backlash (ND)": ("cL", "mR", "cR"),
}


def run_example(
    ex: Example,
    seed: int = 0,
    snr: float | None = None,
    max_iterations: int = 50,
    dtype=None,
    estimator: str = "literal",
) -> tuple[Solution, dict]:
    """Simulate one record of `ex` and fit it (default: the paper's iteration from the
    paper's initial values; `estimator="robust"`: the multi-start output-error fit).

    The input key and the noise key are the two halves of `PRNGKey(seed)`. `snr=inf`
    gives a noise-free record. Returns the solution and the true values by name.
    """
    dtype = dtype or jax.numpy.result_type(float)
    snr = ex.snr if snr is None else snr
    key_input, key_noise = jax.random.split(jax.random.PRNGKey(seed))
    truth = ex.params(dtype)
    u = uniform_input(key_input, ex.n_samples, ex.amplitude, dtype)
    y, _ = measure(key_noise, truth, u, snr)
    if estimator == "robust":
        from ._estimator._robust import robust

        solution = robust(u, y, ex.orders)
    else:
        init = initial_guess(ex.orders, -ex.amplitude, ex.amplitude, dtype)
        solution = voros(u, y, ex.orders, init, max_iterations=max_iterations)
    return jax.device_get(solution), truth.to_dict()


def estimates_table(solution: Solution, truth: dict):
    """pandas DataFrame: parameter, true value, estimate, error."""
    import pandas as pd

    estimate = solution.params.to_dict()
    return pd.DataFrame(
        {
            "parameter": list(truth),
            "true": list(truth.values()),
            "estimate": [estimate[name] for name in truth],
            "error": [estimate[name] - truth[name] for name in truth],
        }
    )


def plot_convergence(solution: Solution, truth: dict, title: str, path) -> None:
    """Parameter trajectories per block (the paper's Figs. 6-8 / 11-13) in one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(truth)
    history = np.asarray(solution.history)
    k = min(int(solution.iterations), history.shape[0] - 1)
    history = history[: k + 1]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), constrained_layout=True)
    for ax, (block, prefixes) in zip(axes, _BLOCKS.items(), strict=True):
        for index, name in enumerate(names):
            if name.rstrip("0123456789") not in prefixes:
                continue
            (line,) = ax.plot(range(k + 1), history[:, index], marker=".", label=name)
            ax.axhline(truth[name], color=line.get_color(), ls="--", lw=0.8)
        ax.set_title(block)
        ax.set_xlabel("iteration")
        ax.set_ylabel("estimate")
        ax.legend(fontsize=8, ncol=2)
    fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _markdown(table, header: str) -> str:
    lines = [header, "", "| parameter | true | estimate | error |", "|---|---|---|---|"]
    for row in table.itertuples():
        lines.append(
            f"| {row.parameter} | {row.true:.4f} | {row.estimate:.6f} | {row.error:+.2e} |"
        )
    return "\n".join(lines) + "\n"


def reproduce(args) -> int:
    from ._cli import CLIError, writable_folder

    ex = example(args.example)
    if not args.snr > 0:
        raise CLIError(
            f"--snr must be positive (an amplitude ratio; inf = noise-free), got {args.snr}."
        )
    if args.max_iterations < 1:
        raise CLIError(f"--max-iterations must be at least 1, got {args.max_iterations}.")
    out = pathlib.Path(args.out)
    writable_folder(out)

    solution, truth = run_example(
        ex, args.seed, args.snr, args.max_iterations, estimator=args.estimator
    )
    status = Status(int(solution.status)).name
    iterations = int(solution.iterations)
    table = estimates_table(solution, truth)
    tag = f"example{ex.number}_snr{args.snr:g}_seed{args.seed}"
    if args.estimator != "literal":
        tag += f"_{args.estimator}"
    title = (
        f"Example {ex.number}, N = {ex.n_samples}, SNR = {args.snr:g}, seed {args.seed}, "
        f"{args.estimator} estimator: {status} after {iterations} iterations"
    )
    table.to_csv(out / f"{tag}_estimates.csv", index=False)
    header = (
        f"## {title}\n\n{_DESCRIPTION[args.estimator]} "
        f"Command: `jaxcascade reproduce --example {ex.number} --seed {args.seed} "
        f"--snr {args.snr:g} --estimator {args.estimator} --out {args.out}`"
    )
    (out / f"{tag}_estimates.md").write_text(_markdown(table, header))
    plot_convergence(solution, truth, title, out / f"{tag}_convergence.png")

    if args.json:
        print(
            json.dumps(
                {
                    "example": ex.number,
                    "iterations": iterations,
                    "status": status,
                    "estimates": solution.params.to_dict(),
                    "true": truth,
                }
            )
        )
    else:
        print(title)
        print(table.to_string(index=False, float_format=lambda v: f"{v: .6f}"))
        print(f"written: {out / tag}_{{estimates.csv,estimates.md,convergence.png}}")
    return 0


_DESCRIPTION = {
    "literal": "Literal iteration (paper eqs. 19-28) from the paper's initial values.",
    "robust": "Robust estimator (multi-start output-error Levenberg-Marquardt); its "
    "history rows are the chosen start, the subset stage and the final estimate.",
}


def _example_number(text: str) -> int:
    from ._cli import CLIError

    if text not in ("1", "2"):
        raise CLIError(f"unknown example {text!r}; the paper has examples 1 and 2.")
    return int(text)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "reproduce", help="rerun a paper example and draw its convergence figures"
    )
    parser.add_argument("--example", type=_example_number, required=True, help="1 or 2")
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed of the record (default 0)")
    parser.add_argument(
        "--snr", type=float, default=25.0, help="sqrt(var y / var e); inf = noise-free (default 25)"
    )
    parser.add_argument("--max-iterations", type=int, default=50)
    parser.add_argument(
        "--estimator",
        choices=("literal", "robust"),
        default="literal",
        help="literal: the paper's iteration (default); robust: multi-start output error",
    )
    parser.add_argument("--out", default="results", help="output folder (default results/)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary")
    parser.set_defaults(func=reproduce)
