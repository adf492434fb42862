"""`jaxcascade reproduce`: the paper's examples, figures 6-8 and 11-13, and a table
(`_workflow._reproduce.reproduce_example`), printed or as JSON (`Reproduction.to_dict`).

One record of an example is simulated (input uniform in (-2, 2), output noise at the
given SNR), fitted (default: the literal iteration from the paper's initial values), and
the parameter trajectories are drawn per block as in the paper's figures. With `--snr
inf` an estimator that declares settings for a noise-free record (`noise_free`: the
recursive estimator's constant memory and Gauss-Newton gain, `_recursive.NOISE_FREE`)
runs with them; the output names the settings used.
"""

from __future__ import annotations

from ._common import CLIError, estimator_help, examples, strict_json, writable_folder


def _print(args, result) -> int:
    """The command's answer: the result as JSON (`Reproduction.to_dict`), or the title,
    the status, the table and the files written."""
    if args.json:
        print(strict_json(result.to_dict()))
    else:
        print(result.title)
        print(f"{result.status.name}: {result.message}")
        print(result.table.to_string(index=False, float_format=lambda v: f"{v: .6f}"))
        print(f"written: {result.stem}_{{{','.join(result.written)}}}")
    return 0


def reproduce(args) -> int:
    # imported here, not at the top: `--help` answers without importing JAX
    from .._workflow._reproduce import reproduce_example

    writable_folder(args.out)
    result = reproduce_example(
        args.example,
        seed=args.seed,
        snr=args.snr,
        estimator=args.estimator,
        max_iterations=args.max_iterations,
        out=args.out,
    )
    return _print(args, result)


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
