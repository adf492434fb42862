"""`jaxcascade reproduce`: the paper's examples, figures 6-8 and 11-13, and a table.

One record of an example is simulated (input uniform in (-2, 2), output noise at the
given SNR), fitted (default: the literal iteration from the paper's initial values), and
the parameter trajectories are drawn per block as in the paper's figures. With `--snr
inf` an estimator that declares settings for a noise-free record (`noise_free`: the
recursive estimator's constant memory and Gauss-Newton gain, `_recursive.NOISE_FREE`)
runs with them; the output names the settings used.
"""

from __future__ import annotations

import math
import pathlib

from ._common import CLIError, estimator_help, examples, strict_json, writable_folder


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


def _markdown(table, header: str) -> str:
    lines = [header, "", "| parameter | true | estimate | error |", "|---|---|---|---|"]
    for row in table.itertuples():
        lines.append(
            f"| {row.parameter} | {row.true:.4f} | {row.estimate:.6f} | {row.error:+.2e} |"
        )
    return "\n".join(lines) + "\n"


GENERAL_ESTIMATORS = ("literal", "robust")


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


def _reproduce_general(args, out: pathlib.Path) -> int:
    import pandas as pd

    from .._plot._trajectory import plot_iterates
    from .._status import Status
    from .._system._general_backlash import general_example

    if args.estimator not in GENERAL_ESTIMATORS:
        raise CLIError(
            f"--estimator {args.estimator}: the general-backlash examples take literal (the "
            "note's key-term iteration) or robust (the robust fit refined with curved branches)."
        )
    ex = general_example(args.example)
    settings = {"max_iterations": args.max_iterations} if args.estimator == "literal" else {}
    code, iterations, estimates, truth, history = run_general_example(
        ex, args.seed, args.snr, args.estimator, **settings
    )
    status = Status(code).name
    table = pd.DataFrame(
        {
            "parameter": list(truth),
            "true": list(truth.values()),
            "estimate": [estimates[n] for n in truth],
            "error": [estimates[n] - truth[n] for n in truth],
        }
    )
    tag = f"{ex.name}_snr{args.snr:g}_seed{args.seed}"
    if args.estimator != "literal":
        tag += f"_{args.estimator}"
    degree = len(ex.curveL) + 1
    what = "key-term iteration" if args.estimator == "literal" else "robust estimator, refined"
    title = (
        f"Example {ex.name} (general backlash, degree {degree}), N = {ex.n_samples}, "
        f"SNR = {args.snr:g}, seed {args.seed}, {what}: {status} after {iterations} "
        f"{'iterations' if args.estimator == 'literal' else 'steps'}"
    )
    table.to_csv(out / f"{tag}_estimates.csv", index=False)
    header = (
        f"## {title}\n\nCommand: `jaxcascade reproduce --example {ex.name} --seed {args.seed} "
        f"--snr {args.snr:g} --estimator {args.estimator} --out {args.out}`"
    )
    (out / f"{tag}_estimates.md").write_text(_markdown(table, header))
    written = ["estimates.csv", "estimates.md"]
    if history is not None:
        blocks = {block: list(names) for block, names in ex.orders.blocks.items()}
        blocks["ND"] = [*blocks["ND"], *curvature_names(degree)]
        names = list(truth)
        plot_iterates(history, names, blocks, truth, title, out / f"{tag}_convergence.png")
        written.append("convergence.png")
    summary = {"example": ex.name, "iterations": iterations, "status": status}
    return _print(
        args, summary | {"estimates": estimates, "true": truth}, title, table, out / tag, written
    )


def _print(args, summary: dict, title: str, table, stem, written) -> int:
    """The command's answer: `summary` as JSON (with the status's message), or the
    title, the status, the table and the files written."""
    from .._status import Status

    message = Status[summary["status"]].message
    if args.json:  # the message right after the status, as before
        keys = list(summary)
        keys.insert(keys.index("status") + 1, "message")
        print(strict_json({k: message if k == "message" else summary[k] for k in keys}))
    else:
        print(title)
        print(f"{summary['status']}: {message}")
        print(table.to_string(index=False, float_format=lambda v: f"{v: .6f}"))
        print(f"written: {stem}_{{{','.join(written)}}}")
    return 0


def reproduce(args) -> int:
    # imported here, not at the top: `--help` answers without importing JAX
    from .._estimator import lookup
    from .._plot._trajectory import plot_trajectories
    from .._status import Status
    from .._system._examples import example

    if not args.snr > 0:
        raise CLIError(
            f"--snr must be positive (an amplitude ratio; inf = noise-free), got {args.snr}."
        )
    if args.max_iterations is None:
        args.max_iterations = 200 if isinstance(args.example, str) else 50
    if args.max_iterations < 1:
        raise CLIError(f"--max-iterations must be at least 1, got {args.max_iterations}.")
    out = pathlib.Path(args.out)
    writable_folder(out)
    if isinstance(args.example, str):
        return _reproduce_general(args, out)
    ex = example(args.example)

    try:  # ours, or a user's (registered, or by its package's entry point)
        registered = lookup(args.estimator)
    except ValueError as error:
        raise CLIError(f"--estimator: {error}") from None
    takes = "max_iterations" in registered.settings()
    settings = {"max_iterations": args.max_iterations} if takes else {}
    if math.isinf(args.snr):  # noise-free: the estimator's own noise-free settings
        settings |= dict(getattr(registered, "noise_free", {}))
    solution, truth = run_example(ex, args.seed, args.snr, name=args.estimator, **settings)
    status = Status(int(solution.status)).name
    iterations = int(solution.iterations)
    table = estimates_table(solution, truth)
    tag = f"example{ex.number}_snr{args.snr:g}_seed{args.seed}"
    if args.estimator != "literal":
        tag += f"_{args.estimator}"
    used = {k: v for k, v in settings.items() if k != "max_iterations"}
    named = ", ".join(f"{k}={v}" for k, v in used.items())
    title = (
        f"Example {ex.number}, N = {ex.n_samples}, SNR = {args.snr:g}, seed {args.seed}, "
        f"{args.estimator} estimator{f' ({named})' if named else ''}: {status} after "
        f"{iterations} iterations"
    )
    table.to_csv(out / f"{tag}_estimates.csv", index=False)
    header = (
        f"## {title}\n\nEstimator `{args.estimator}`: {registered.summary}. "
        f"Command: `jaxcascade reproduce --example {ex.number} --seed {args.seed} "
        f"--snr {args.snr:g} --estimator {args.estimator} --out {args.out}`"
    )
    (out / f"{tag}_estimates.md").write_text(_markdown(table, header))
    plot_trajectories(solution, truth, title, out / f"{tag}_convergence.png")

    summary = {
        "example": ex.number,
        "iterations": iterations,
        "status": status,
        "settings": used,
        "cycle_amplitude": float(solution.cycle_amplitude),
        "estimates": solution.params.to_dict(),
        "true": truth,
    }
    written = ["estimates.csv", "estimates.md", "convergence.png"]
    return _print(args, summary, title, table, out / tag, written)


def _example_number(text: str) -> int | str:
    if text in ("general1", "general2"):
        return text
    if text not in ("1", "2"):
        raise CLIError(
            f"unknown example {text!r}; the paper has examples 1 and 2, the general backlash "
            "general1 and general2."
        )
    return int(text)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "reproduce",
        help="rerun a paper example and draw its convergence figures",
        description=(
            "Simulate one record of a paper example, fit it and draw the parameter "
            "trajectories per block (the paper's figures 6-8 and 11-13) with a table."
        ),
        epilog=examples(
            "jaxcascade reproduce --example 1",
            "jaxcascade reproduce --example 2 --snr inf --estimator robust --out results/ex2",
            "jaxcascade reproduce --example general1 --snr inf",
        ),
    )
    parser.add_argument(
        "--example",
        type=_example_number,
        required=True,
        help=(
            "1 or 2 (the paper's), general1 or general2 (the general output backlash, "
            "docs/general_backlash.md; --estimator literal: the key-term iteration, robust)"
        ),
    )
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed of the record (default 0)")
    parser.add_argument(
        "--snr",
        type=float,
        default=25.0,
        help=(
            "sqrt(var y / var e); inf = noise-free, with the estimator's noise-free settings "
            "where it has them (recursive: gradient=True, lam=0.95) (default 25)"
        ),
    )
    parser.add_argument(
        "--max-iterations",
        type=int,
        default=None,
        help=(
            "iteration budget of estimators that have one (default 50; 200 for the "
            "key-term iteration of general1, general2, key_term_general's own)"
        ),
    )
    parser.add_argument(
        "--estimator",
        default="literal",
        metavar="NAME",
        help=f"default literal; {estimator_help()}",
    )
    parser.add_argument("--out", default="results", help="output folder (default results/)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary")
    parser.set_defaults(func=reproduce)
