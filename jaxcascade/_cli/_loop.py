"""`jaxcascade loop`: the model-error loop on measured records, with its report.

The report (`--report DIR`) holds `report.json` (what `--json` prints, plus the
models and the ARX peer), `report.md`, `candidates.csv`, the measured versus simulated
validation output before and after (`compare.png`), and the residual tests before and
after (`residual_before_*.png`, `residual_after_*.png`).
"""

from __future__ import annotations

import dataclasses
import pathlib
import sys

from .._names import EFFECTS, NOISE_MODEL
from ._common import (
    CLIError,
    add_record_arguments,
    examples,
    parse_orders,
    strict_json,
    writable_folder,
)


def _markdown(report: dict, command: str) -> str:
    from .._metrics import fit_percent

    lines = [
        "# Model-error loop report",
        "",
        f"Command: `{command}`",
        "",
        f"- validation NRMSE before: {report['error_before']:.4f} "
        f"(fit {fit_percent(report['error_before']):.1f} %)",
        f"- validation NRMSE after: {report['error_after']:.4f} "
        f"(fit {fit_percent(report['error_after']):.1f} %)",
        f"- effects added: {', '.join(report['effect_added']) or 'none'}",
        f"- one-step-ahead prediction NRMSE before: {report['prediction_error_before']:.4f}, "
        f"after: {report['prediction_error_after']:.4f}",
    ]
    if report.get("window"):
        lines.append(
            f"- window {report['window']['stored']} (stored samples): NRMSE before "
            f"{report['window_error_before']:.4f}, after {report['window_error_after']:.4f}"
        )
    lines += [
        "",
        "| model | NRMSE | prediction NRMSE | window NRMSE |",
        "|---|---|---|---|",
    ]
    for step in report["steps"]:
        w = step["window_error"]
        lines.append(
            f"| {step['model']} | {step['error']:.4f} | {step['prediction_error']:.4f} | "
            f"{'-' if w is None else f'{w:.4f}'} |"
        )
    if "arx" in report:
        arx = report["arx"]
        lines.append(
            f"- linear ARX peer (na={arx['na']}, nb={arx['nb']}): NRMSE {arx['error']:.4f} "
            f"(fit {fit_percent(arx['error']):.1f} %)"
        )
    test = report["significance"]
    lines += [
        "",
        "## Candidates",
        "",
        f"Significance: {test['test']} test of the squared errors against the current model "
        f"({test['statistic']}), {test['variance']}, truncation lag L by {test['bandwidth_rule']}; "
        f"significant when DM > {test['threshold']:g} and the NRMSE falls by more than "
        f"{100 * test['min_gain']:g} %. Loss: the simulation error for an effect, the "
        "one-step-ahead prediction error for the noise model.",
        "",
        "| round | effect | variant | NRMSE | prediction NRMSE | loss | DM | L | p | "
        "significant | signature matches |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in report["candidates"]:
        lines.append(
            f"| {c['round']} | {c['name']} | {c['variant']} | {c['error']:.4f} | "
            f"{c['prediction_error']:.4f} | {c['loss']} | {c['t']:.2f} | {c['bandwidth']} | "
            f"{c['p_value']:.2g} | {c['significant']} | {c['signature_match']} |"
        )
    lines += [
        "",
        "## Residual tests (p-values; pass at p >= 0.05)",
        "",
        "| test | before | after |",
        "|---|---|---|",
    ]
    before = report["residual_tests"]["before"]
    after = report["residual_tests"]["after"]
    for name, test in before.items():
        if isinstance(test, dict):
            lines.append(f"| {name} | {_p(test)} | {_p(after.get(name))} |")
    lines.append(f"| all tests pass | {before['ok']} | {after['ok']} |")
    return "\n".join(lines) + "\n"


def _p(test) -> str:
    if not test:
        return "-"
    p = test.get("p_value")
    mark = "pass" if test.get("passed") else "FAIL"
    return f"{p:.3g} {mark}" if p is not None else mark


def _window(text, decimate: int, length: int):
    """`--window START:STOP` (samples of the stored file) in samples of the decimated
    record, or None."""
    if text is None:
        return None
    try:
        start, stop = (int(part) for part in text.split(":"))
    except ValueError:
        raise CLIError(f"--window takes START:STOP in samples, got {text!r}.") from None
    first, last = start // decimate, -(-stop // decimate)
    if not 0 <= start < stop or last > length:
        raise CLIError(
            f"--window {text}: needs 0 <= START < STOP within the validation record "
            f"({length * decimate} samples as stored)."
        )
    if last - first < 2:
        raise CLIError(f"--window {text}: fewer than 2 samples after decimation by {decimate}.")
    return first, last


def run_loop(args) -> int:
    # imported here, not at the top: `--help` answers without importing JAX
    import numpy as np

    from .._arx import best_arx
    from .._data import Scaling, read_record
    from .._loop import model_error_loop
    from .._metrics import score
    from .._plot._loop import plot_compare
    from .._plot._residuals import save_residual_figures

    orders = parse_orders(args.orders)
    if args.max_effects < 0:
        raise CLIError(f"--max-effects must be >= 0, got {args.max_effects}.")
    if args.decimate < 1:
        raise CLIError(f"--decimate must be an integer >= 1, got {args.decimate}.")
    options = dict(time_column=args.time, decimate=args.decimate, orders=orders)
    raw = [
        read_record(path, args.input, args.output, scaling="none", **options) for path in args.train
    ]
    scaling = Scaling.from_data(
        np.concatenate([r.u for r in raw]), np.concatenate([r.y for r in raw]), args.scaling
    )
    training = [
        dataclasses.replace(
            r, u=scaling.input_to_model(r.u), y=scaling.output_to_model(r.y), scaling=scaling
        )
        for r in raw
    ]
    validation = read_record(args.validate, args.input, args.output, scaling=scaling, **options)
    window = _window(args.window, args.decimate, len(validation))
    if args.report:
        writable_folder(args.report, "--report")

    def say(message):
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)

    result = model_error_loop(
        [r.u for r in training],
        [r.y for r in training],
        validation.u,
        validation.y,
        orders,
        max_effects=args.max_effects,
        sample_period=validation.sample_period or 1.0,
        window=window,
        progress=say,
        effects=_effects(args.effects),
    )
    full = result.to_dict()
    # The ARX peer is fitted on the estimation records joined end to end.
    arx = best_arx(np.concatenate([r.u for r in training]), np.concatenate([r.y for r in training]))
    arx_val = arx.simulate(validation.u)
    full["arx"] = {
        "na": arx.orders[0],
        "nb": arx.orders[1],
        "error": score(validation.y, arx_val),
        "window_error": None
        if window is None
        else score(validation.y[slice(*window)], arx_val[slice(*window)]),
    }
    full["window"] = (
        None if window is None else {"stored": args.window, "model_samples": list(window)}
    )
    full["records"] = {
        "estimation": [r.to_dict() for r in training],
        "validation": validation.to_dict(),
    }
    keys = ("error_before", "error_after", "prediction_error_before", "prediction_error_after")
    keys += ("effect_added", "significance", "candidates", "residual_tests")
    keys += ("standard_errors_after",)
    if window is not None:
        keys += ("window_error_before", "window_error_after")
    if args.json:
        print(strict_json({key: full[key] for key in keys}))
    else:
        print(
            f"validation NRMSE before {full['error_before']:.4f}, after "
            f"{full['error_after']:.4f}; added: {', '.join(full['effect_added']) or 'none'}; "
            f"ARX peer {full['arx']['error']:.4f}"
        )
    if args.report:
        folder = pathlib.Path(args.report)
        command = "jaxcascade loop " + " ".join(sys.argv[2:])
        (folder / "report.json").write_text(strict_json(full, indent=1))
        (folder / "report.md").write_text(_markdown(full, command))
        import pandas as pd

        pd.DataFrame(full["candidates"]).to_csv(folder / "candidates.csv", index=False)
        period = validation.sample_period
        time = np.arange(len(validation)) * (period or 1.0)
        plot_compare(
            time,
            validation.y,
            result.before.simulated,
            result.after.simulated,
            folder / "compare.png",
            arx=arx_val,
            title="validation record (model units): measured vs free-run simulation",
        )
        save_residual_figures(result.before.tests, folder, prefix="residual_before_")
        save_residual_figures(result.after.tests, folder, prefix="residual_after_")
    return 0


def _effects(text: str | None) -> tuple[str, ...] | None:
    """`--effects a,b`: names of the library (and the noise model) the loop considers."""
    if text is None:
        return None
    from .._effects import EFFECTS
    from .._noise import ARNoise

    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in {*EFFECTS, ARNoise.name}]
    if unknown or not names:
        known = ", ".join([*EFFECTS, ARNoise.name])
        raise CLIError(f"--effects: unknown effect(s) {unknown or text!r}; known: {known}.")
    return names


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "loop",
        help="fit, test the residual, add the missing effect, report before/after",
        description=(
            "The model-error loop: fit the declared cascade on TRAIN, test its residual "
            "on the validation record, add the effect the residual points to, repeat."
        ),
        epilog=examples(
            "jaxcascade loop train.csv --validate valid.csv --input u --output y "
            "--time t --decimate 4 --report results/loop",
            "jaxcascade loop a.csv b.parquet --validate c.csv --input u --output y "
            "--decimate 8 --window 3072:7680 --json",
        ),
    )
    parser.add_argument(
        "train", nargs="+", help="estimation record(s) (CSV or Parquet), estimated jointly"
    )
    parser.add_argument("--validate", required=True, help="validation record")
    add_record_arguments(parser, scaling="scale")
    parser.add_argument(
        "--max-effects",
        type=int,
        default=3,
        help="at most this many effects are added, one per round (default 3; 0: fit and "
        "test only)",
    )
    parser.add_argument(
        "--window",
        default=None,
        help="START:STOP: also score the validation record on these samples of the file "
        "as stored (before decimation)",
    )
    parser.add_argument(
        "--effects",
        default=None,
        help="NAME,NAME: the effects of the library the loop considers (default: all): "
        f"{', '.join([*EFFECTS, NOISE_MODEL])}",
    )
    parser.add_argument("--report", default=None, help="folder for the report and figures")
    parser.add_argument("--json", action="store_true", help="print the JSON summary")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    parser.set_defaults(func=run_loop)
