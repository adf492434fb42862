"""`jaxcascade loop`: the model-error loop on measured records, with its report.

The report (`--report DIR`) holds `report.json` (what `--json` prints, plus the
models and the ARX peer), `report.md`, `candidates.csv`, the measured versus simulated
validation output before and after (`compare.png`), every residual test before and
after in one figure each (`residual_before_overview.png`, `residual_after_overview.png`),
and the final model as a model file (`model.json`, `_model_file`: `jaxcascade simulate`
applies it to new records).
Each record's figure is `records/<k>-<role>.png`. `--no-figures` writes the same report
without the PNG files (on short records drawing them takes much of the loop's time).
While the loop runs, every finished fit and round is kept in `DIR/checkpoints/`
(`_loop_resume`: `--resume`, `--overwrite`, Ctrl-C).
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
import sys

from .._names import EFFECTS, NOISE_MODEL, NOISE_MODEL_DESCRIPTION
from ._common import (
    RECORD_SPEC,
    CLIError,
    add_record_arguments,
    examples,
    kind_help,
    parse_orders,
    strict_json,
    writable_folder,
)
from ._loop_resume import add_arguments as add_resume_arguments


def _f(value) -> str:
    return "-" if value is None else f"{value:.4f}"


def _markdown(report: dict, command: str) -> str:
    from .._metrics import fit_percent

    lines = ["# Model-error loop report", ""]
    if report.get("benchmark"):
        lines += _benchmark_table(report["benchmark"])
    # First: the final model against the trivial ones, on every scored record.
    if report.get("integrating"):
        lines += [report["integrating"]["sentence"], ""]
    lines += [*(f"**{sentence}**" for sentence in report["verdict"])]
    if not report["verdict"]:
        lines.append(
            "The final model is better than the mean of the output (NRMSE 1) and than the "
            "linear ARX peer on every scored record."
        )
    lines += [
        "",
        *([f"{report['init_samples_rule']}.", ""] if report.get("init_samples_rule") else []),
        f"State initialisation: {report['init_samples']} samples of the measured output "
        "before the scored ones set each model's state (never its parameters); the "
        "from-rest figures simulate the whole record from rest. NRMSE is normalised by "
        "the output's standard deviation: 1 is the mean.",
        "",
        "| record | role | model | window NRMSE | window, from rest | NRMSE | NRMSE, from rest |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in report["scores"]:
        lines.append(
            f"| {row['record']} | {row['role']} | {row['model']} | {_f(row['window_error'])} | "
            f"{_f(row['window_error_from_rest'])} | {_f(row['error'])} | "
            f"{_f(row['error_from_rest'])} |"
        )
    lines += [
        "",
        "The validation record chose among the candidates: only a test record's figure is "
        "out of sample.",
        "",
        *_coverage_lines(report.get("coverage")),
        f"Command: `{command}`",
        "",
        f"- structure before: `{report['structure_before']}`",
        f"- structure after: `{report['structure_after']}`",
        "- what the loop did: "
        + (
            ", ".join(
                f"{a['action']} {a['effect']} (round {a['round']})" for a in report["actions"]
            )
            or "nothing"
        ),
        *(
            [
                f"- {report['validation_records']} validation records: the loop pooled them; "
                "the validation figures below and in the first table's summary are the mean "
                "over them"
            ]
            if report.get("validation_records", 1) > 1
            else []
        ),
        f"- validation NRMSE from rest before: {report['error_before_from_rest']:.4f} "
        f"(fit {fit_percent(report['error_before_from_rest']):.1f} %), after: "
        f"{report['error_after_from_rest']:.4f} "
        f"(fit {fit_percent(report['error_after_from_rest']):.1f} %)",
        f"- one-step-ahead prediction NRMSE before: {report['prediction_error_before']:.4f}, "
        f"after: {report['prediction_error_after']:.4f}",
        f"- compiled programs: {report['programs_compiled']}",
    ]
    if report.get("window"):
        lines.append(f"- window {report['window']['stored']} (stored samples)")
    lines += [
        "",
        "Each step of the loop on the validation record, simulated from rest:",
        "",
        "| model | NRMSE | prediction NRMSE | window NRMSE |",
        "|---|---|---|---|",
    ]
    for step in report["steps"]:
        lines.append(
            f"| {step['model']} | {step['error']:.4f} | {step['prediction_error']:.4f} | "
            f"{_f(step['window_error'])} |"
        )
    if report.get("final_model"):
        lines += _final_model_lines(report["final_model"])
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
        "| round | effect | action | variant | NRMSE | prediction NRMSE | loss | DM | "
        "DM, validation alone | L | p | significant | signature matches |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for c in report["candidates"]:
        lines.append(
            f"| {c['round']} | {c['name']} | {c['action']} | {c['variant']} | {c['error']:.4f} | "
            f"{c['prediction_error']:.4f} | {c['loss']} | {c['t']:.2f} | {c['t_validation']:.2f} | "
            f"{c['bandwidth']} | "
            f"{c['p_value']:.2g} | {c['significant']} | {c['signature_match']} |"
        )
    lags = report["residual_tests"]["before"].get("max_lag")
    lines += [
        "",
        "## Residual tests (p-values; pass at p >= 0.05)",
        "",
        *(
            [
                f"The validation record is short: the correlation tests look at {lags} lags "
                "(20 from 80 scored samples on), the level and time tests at fewer groups.",
                "",
            ]
            if lags is not None and lags < 20
            else []
        ),
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


def _coverage_lines(cover: dict | None) -> list[str]:
    """The report's input coverage (`_measured._coverage`): its sentences, then one row
    per record."""
    if not cover:
        return []
    lines = [
        "Input coverage, in the records' units (`outside`: the share of a record's "
        "samples whose input lies outside the estimation records' range; `beyond`: how "
        "far the farthest of them lies outside it, as a share of its width; `span`: the "
        "share of that range its input covers). A sentence below flags a validation or "
        f"test record outside it on more than {100 * cover['outside_limit']:g} % of its "
        f"samples, and a validation record spanning less than "
        f"{100 * cover['span_limit']:g} % of it.",
        "",
    ]
    lines += [f"- {sentence}" for sentence in cover["sentences"]]
    lines += [""] if cover["sentences"] else []
    lines += [
        "| record | role | samples | input from | input to | output std | outside | beyond "
        "| span |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in cover["records"]:
        lines.append(
            f"| {r['record']} | {r['role']} | {r['samples']} | {r['u_min']:.4g} | "
            f"{r['u_max']:.4g} | {r['y_std']:.4g} | {100 * r['outside']:.1f} % | "
            f"{100 * r['beyond']:.0f} % | {100 * r['span']:.0f} % |"
        )
    return lines + [""]


def _final_model(model, errors: dict, scaling) -> dict:
    """The report's final model: its structure, its equations and every estimate with its
    standard error (model units), the cascade's also in the records' units."""
    from .._measured._effects import backlash_of
    from .._measured._loop import model_estimates

    values = model_estimates(model)
    physical = {}
    if model.cascade:
        physical = scaling.params_to_physical(model.params.to_dict())
        physical_errors = {
            k: abs(v)
            for k, v in scaling.params_to_physical(
                {k: errors[k] for k in model.orders.names}
            ).items()
        }
    rows = [
        {
            "name": name,
            "estimate": value,
            "std_error": errors.get(name),
            "physical": physical.get(name),
            "physical_std_error": physical_errors.get(name) if physical else None,
        }
        for name, value in values.items()
    ]
    return {
        "structure": model.structure(),
        "equations": _equations(model.params, backlash_of(model)) if model.cascade else [],
        "effects": [e.name for e in model.effects],
        "noise_order": int(model.noise.order),
        "scaling": scaling.to_dict(),
        "parameters": rows,
    }


def _equations(params, curved=None) -> list[str]:
    """The cascade's three blocks with the estimates written in (model units;
    docs/model.md gives the general form); `curved`: the general backlash an effect put
    in place of the straight one (`_effects.backlash_of`), or None."""
    p = params.to_dict()
    o = params.orders

    def slopes(side, count):
        total, parts = 0.0, []
        for i in range(1, count + 1):
            total += p[f"M{side}{i}"]
            lower = "0" if i == 1 else f"D{side}{i - 1} = {p[f'D{side}{i - 1}']:.4g}"
            parts.append(f"slope {total:.4g} beyond {lower}")
        return "; ".join(parts)

    def term(coefficient, signal):
        sign = "-" if coefficient < 0 else "+"
        return f" {sign} {abs(coefficient):.4g} {signal}"

    numerator = "v(t-1)" + "".join(term(p[f"a{j}"], f"v(t-{j})") for j in range(2, o.r + 1))
    denominator = "".join(term(-p[f"b{i}"], f"x(t-{i})") for i in range(1, o.p + 1))
    return [
        f"NS (static, piecewise linear): v = f(u), right of zero {slopes('R', o.nR)}; "
        f"left of zero {slopes('L', o.nL)}",
        f"LD (linear): x(t) = {numerator}{denominator}",
        _backlash_equation(p, curved),
    ]


def _backlash_equation(p: dict, curved) -> str:
    import numpy as np

    left, right = f"x(t) + {p['cL']:.4g}", f"{p['mR']:.4g} (x(t) - {p['cR']:.4g})"
    name = "backlash"
    if curved is not None:
        name = f"general backlash, degree {curved.degree}"
        for side, curve, s in (
            ("L", np.asarray(curved.curveL), f"(x(t) + {p['cL']:.4g})"),
            ("R", np.asarray(curved.curveR), f"(x(t) - {p['cR']:.4g})"),
        ):
            terms = "".join(
                f" {'-' if c < 0 else '+'} {abs(c):.4g} {s}^{i}"
                for i, c in enumerate(curve, start=2)
            )
            left, right = (left + terms, right) if side == "L" else (left, right + terms)
    return (
        f"ND ({name}): y(t) = {left} where that is below y(t-1); "
        f"y(t) = {right} where that is above y(t-1); else y(t) = y(t-1)"
    )


def _final_model_lines(final: dict) -> list[str]:
    sc = final["scaling"]
    lines = [
        "",
        "## The final model",
        "",
        f"`{final['structure']}`"
        + (f", effects {', '.join(final['effects'])}" if final["effects"] else "")
        + (f", AR({final['noise_order']}) noise model" if final["noise_order"] else ""),
        "",
        f"Fitted in model units (scaling `{sc['method']}`: input offset {sc['u_offset']:.4g}, "
        f"scale {sc['u_scale']:.4g}; output offset {sc['y_offset']:.4g}, scale "
        f"{sc['y_scale']:.4g}; the model in the records' units is y - y_offset = "
        "cascade(u - u_offset)). Standard errors from the output-error information on the "
        "estimation records (infinite: the records do not determine the parameter).",
        "",
        *(f"- {equation}" for equation in final["equations"]),
        "",
        "| parameter | estimate | standard error | in the records' units |",
        "|---|---|---|---|",
    ]
    for row in final["parameters"]:
        phys = (
            "-"
            if row["physical"] is None
            else f"{row['physical']:.6g} ± {row['physical_std_error']:.2g}"
        )
        error = "-" if row["std_error"] is None else f"{row['std_error']:.2g}"
        lines.append(f"| {row['name']} | {row['estimate']:.6g} | {error} | {phys} |")
    return lines


def _benchmark_table(bench: dict) -> list[str]:
    """The report's first table on a benchmark: test RMSE in its unit of the declared
    cascade, the final model, the ARX peer and the published baselines, per test set."""
    tests = bench["tests"]
    names = [t["record"] for t in tests]
    lines = [
        f"## {bench['name']}: test RMSE ({bench['unit']}), free-run simulation, state set on "
        f"the first {bench['n_init']} samples ({bench['loader']})",
        "",
        "| model | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for label, key in (
        ("declared cascade", "declared_test_rmse"),
        ("final model", "test_rmse"),
        ("linear ARX peer (this run)", "arx_test_rmse"),
    ):
        lines.append(f"| {label} | " + " | ".join(f"{t[key]:.4g}" for t in tests) + " |")
    published = sorted({k for t in tests for k in t["published"]})
    for key in published:
        values = [t["published"].get(key) for t in tests]
        lines.append(
            f"| {key.replace('_', ' ')} (published) | "
            + " | ".join("-" if v is None else f"{v:.4g}" for v in values)
            + " |"
        )
    lines += [
        "",
        "Final model: "
        + "; ".join(
            f"{t['record']}: NRMSE {t['test_nrmse']:.4f}, fit {t['test_fit_percent']:.1f} %"
            for t in tests
        )
        + f". Published figures: {bench['published_source']}. Estimation and validation "
        f"records from the training data: {bench['split_rule']} (MAX = {bench['max_samples']});"
        f" decimation {bench['decimation']} ({bench['decimation_rule']}).",
        "",
    ]
    return lines


def _p(test) -> str:
    if not test:
        return "-"
    p = test.get("p_value")
    mark = "pass" if test.get("passed") else "FAIL"
    return f"{p:.3g} {mark}" if p is not None else mark


def _window(text, decimate: int, length: int, option: str = "--window", offset: int = 0):
    """`--window START:STOP` (samples of the stored file) in samples of the decimated
    record, or None. `offset`: the file sample the record starts at (a ranged record
    spec, `Record.file_start`)."""
    if text is None:
        return None
    try:
        start, stop = (int(part) - offset for part in text.split(":"))
    except ValueError:
        raise CLIError(f"{option} takes START:STOP in samples, got {text!r}.") from None
    first, last = start // decimate, -(-stop // decimate)
    if not 0 <= start < stop or last > length:
        raise CLIError(
            f"{option} {text}: needs START < STOP within the scored record (file samples "
            f"{offset} to {offset + length * decimate} as stored)."
        )
    if last - first < 2:
        raise CLIError(f"{option} {text}: fewer than 2 samples after decimation by {decimate}.")
    return first, last


def _windows(texts, decimate: int, records) -> list:
    """`--test-window` values, one per test record (or none): decimated windows."""
    if not texts:
        return [None] * len(records)
    if len(texts) != len(records):
        raise CLIError(
            f"--test-window takes one START:STOP per --test record ({len(records)}), "
            f"got {len(texts)}."
        )
    return [
        _window(text, decimate, len(r), "--test-window", offset=r.file_start)
        for text, r in zip(texts, records, strict=True)
    ]


def run_loop(args) -> int:
    from ._loop_resume import run_kept

    return run_kept(args, _run_loop)


def _run_loop(args, checkpoints) -> int:
    from .._native import build_in_background

    # the declared cascade's robust fit needs the native kernel: on a machine's first
    # run it compiles on another core while this command imports and reads its records
    # (`_native`)
    build_in_background()
    # imported here, not at the top: `--help` answers without importing JAX
    import jax
    import numpy as np

    from .._estimator._robust import Robust
    from .._measured import _coverage
    from .._measured._arx import best_arx
    from .._measured._loop import (
        default_threads,
        initialised_output,
        model_error_loop,
        simulated_output,
    )
    from .._measured._scoring import score_record, verdict
    from .._plot._loop import plot_compare
    from .._plot._residuals import plot_residual_tests

    orders = parse_orders(args.orders, "loop")
    if args.max_effects < 0:
        raise CLIError(f"--max-effects must be >= 0, got {args.max_effects}.")
    if args.decimate < 1:
        raise CLIError(f"--decimate must be an integer >= 1, got {args.decimate}.")
    if not args.dm_threshold > 0:
        raise CLIError(f"--dm-threshold must be positive, got {args.dm_threshold}.")
    if not 0 <= args.min_gain < 1:
        raise CLIError(f"--min-gain must be in [0, 1), got {args.min_gain}.")
    if args.retries < 0:
        raise CLIError(f"--retries must be >= 0, got {args.retries}.")
    if args.threads is not None and args.threads < 1:
        raise CLIError(f"--threads must be an integer >= 1, got {args.threads}.")
    if args.init_samples is not None and args.init_samples < 0:
        raise CLIError(f"--init-samples must be >= 0, got {args.init_samples}.")
    if args.benchmark:
        training, validations, tests, bench = _benchmark_records(args, orders)
        window, test_windows = None, [None] * len(tests)
        if args.window or args.test_window:
            raise CLIError("--window and --test-window do not apply with --benchmark.")
    else:
        training, validations, tests = _file_records(args, orders)
        bench = None
        if args.window and len(validations) > 1:
            raise CLIError(
                f"--window scores one validation record; {len(validations)} were given to "
                "--validate: drop --window or give one."
            )
        first = validations[0]
        window = _window(args.window, args.decimate, len(first), offset=first.file_start)
        test_windows = _windows(args.test_window, args.decimate, tests)
    init_rule = None
    if args.init_samples is None:
        # the benchmark's own window (in samples after decimation), else the measured-data
        # default: at most a stated fraction of the shortest scored record (`_defaults`)
        from .. import _defaults

        if bench is not None:
            args.init_samples = -(-bench.n_init // args.decimate)
        else:
            args.init_samples = _defaults.init_samples(len(r) for r in [*validations, *tests])
            if args.init_samples < _defaults.INIT_SAMPLES:
                init_rule = (
                    f"--init-samples {args.init_samples}: the default "
                    f"{_defaults.INIT_SAMPLES} is at most {_defaults.INIT_FRACTION:g} of the "
                    "shortest scored record"
                )
    scaling = training[0].scaling
    if args.report:
        writable_folder(args.report, "--report")

    def say(message):
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)

    if init_rule is not None:
        say(init_rule)

    # An output that integrates its input (no stable ARX fits it) is modelled through its
    # difference and integrated back for scoring (`_integrating`).
    integrating = None
    if args.integrate != "no":
        from .._measured._integrating import integrates

        pole = integrates(
            np.concatenate([r.u for r in training]), np.concatenate([r.y for r in training])
        )
        if args.integrate == "yes" or pole is not None:
            integrating = {"largest_arx_pole": pole, "option": args.integrate}
    scored_records = (validations, tests)
    estimation = list(training)  # as measured (the loop may model their difference)
    if integrating is not None:
        from .._measured._integrating import differenced

        training = [differenced(r) for r in training]
        validations = [differenced(v) for v in validations]
        integrating["sentence"] = (
            "The output integrates its input"
            + (
                f" (no stable linear ARX model fits it; the best one's largest pole is at "
                f"|z| = {pole:.4f})"
                if pole is not None
                else ""
            )
            + ": a stable model cannot follow it in free run, so the loop models its "
            "difference y(t) - y(t-1) and integrates the model's output back for scoring, "
            "its position set from the measured output like any other state (--integrate no "
            "turns this off)."
        )
        say(integrating["sentence"])

    result = model_error_loop(
        [r.u for r in training],
        [r.y for r in training],
        [v.u for v in validations] if len(validations) > 1 else validations[0].u,
        [v.y for v in validations] if len(validations) > 1 else validations[0].y,
        orders,
        max_effects=args.max_effects,
        sample_period=validations[0].sample_period or 1.0,
        window=window,
        progress=say,
        effects=_effects(args.effects),
        robust=Robust(retries=args.retries),
        init_samples=max(args.init_samples - 1, 0) if integrating else args.init_samples,
        integrating=integrating is not None,
        t_threshold=args.dm_threshold,
        min_gain=args.min_gain,
        key=jax.random.PRNGKey(args.seed),
        checkpoints=checkpoints,
        threads=default_threads() if args.threads is None else args.threads,
    )
    full = result.to_dict()
    full["robust"] = {"retries": args.retries, "seed": args.seed}
    # The ARX peer is fitted on the estimation records joined end to end.
    u_all = np.concatenate([r.u for r in training])
    y_all = np.concatenate([r.y for r in training])
    unstable_arx = None
    try:
        arx = best_arx(u_all, y_all)
    except ValueError:
        # every equation-error fit has a pole on or outside the unit circle (an output
        # that integrates, with --integrate no): the best finite one is the peer
        arx = best_arx(u_all, y_all, stable=False)
        unstable_arx = arx.largest_pole
    say("scoring on the validation and test records (initialised and from rest)")
    models = {
        "declared cascade": (
            lambda u, m=result.base: simulated_output(m, u),
            lambda u, y, start, n, m=result.base: initialised_output(m, u, y, start, n),
        ),
        "final model": (
            lambda u: simulated_output(result.final, u),
            lambda u, y, start, n: initialised_output(result.final, u, y, start, n),
        ),
        "linear ARX": (
            arx.simulate,
            lambda u, y, start, n: arx.simulate(u, y, start)[start:],
        ),
    }
    if integrating is not None:
        from .._measured._integrating import integrated

        models = {name: integrated(*pair) for name, pair in models.items()}
        validations = scored_records[0]  # scored as measured, the output integrated back
    scored = [("validation", v, window) for v in validations]
    scored += [("test", r, w) for r, w in zip(tests, test_windows, strict=True)]
    scores = [
        score_record(name, _name(record), role, record.u, record.y, *pair, w, args.init_samples)
        for role, record, w in scored
        for name, pair in models.items()
    ]
    by_model = {name: [s for s in scores if s.model == name] for name in models}
    # where the scored records go that the estimation records did not (`_coverage`),
    # every record as measured, in its own units
    covered = _coverage.coverage(
        [(_name(r), r.u, r.y) for r in estimation],
        [
            (_name(r), role, r.u, r.y)
            for role, records in zip(("validation", "test"), scored_records, strict=True)
            for r in records
        ],
        u_map=scaling.input_to_physical,
        y_scale=scaling.y_scale,
    )
    warnings = verdict(
        by_model["final model"], by_model["linear ARX"], _coverage.uncovered(covered)
    )
    if unstable_arx is not None:
        warnings.append(
            "No stable linear ARX model fits the estimation records (the best one's largest "
            f"pole is at |z| = {unstable_arx:.4f}): the output integrates its input, which a "
            "stable model cannot follow in free run; leave --integrate at auto (the loop "
            "then models the output's difference) or model the loop closed around the output."
        )
    full["integrating"] = integrating
    full["final_model"] = _final_model(result.final, full["standard_errors_after"], scaling)
    # the validation figures of each model: its record's, or the mean over several
    valid = {
        name: _mean_score([s for s in scores if s.role == "validation" and s.model == name])
        for name in models
    }
    full["validation_records"] = len(validations)
    full["init_samples"] = args.init_samples
    full["init_samples_rule"] = init_rule
    for key, model in (("before", "declared cascade"), ("after", "final model")):
        s = valid[model]
        full[f"error_{key}"] = s.error
        full[f"window_error_{key}"] = s.window_error
        full[f"error_{key}_from_rest"] = s.error_from_rest
        full[f"window_error_{key}_from_rest"] = s.window_error_from_rest
    # RMSE in the records' own units (the scaling is affine: an error scales by y_scale)
    full["scores"] = [{**s.to_dict(), "rmse": s.rmse * scaling.y_scale} for s in scores]
    if bench is not None:
        full["benchmark"] = _benchmark_summary(bench, scores, scaling, args)
    full["test"] = [
        {
            "record": s.record,
            "error": s.error,
            "window_error": s.window_error,
            "error_from_rest": s.error_from_rest,
            "window_error_from_rest": s.window_error_from_rest,
        }
        for s in by_model["final model"]
        if s.role == "test"
    ]
    full["verdict"] = warnings
    full["coverage"] = {
        "records": [r.to_dict() for r in covered],
        "sentences": _coverage.sentences(covered),
        "outside_limit": _coverage.OUTSIDE,
        "span_limit": _coverage.SPAN,
    }
    a = valid["linear ARX"]
    full["arx"] = {
        "na": arx.orders[0],
        "nb": arx.orders[1],
        "largest_pole": arx.largest_pole,
        "stable": unstable_arx is None,
        "error": a.error,
        "window_error": a.window_error,
        "error_from_rest": a.error_from_rest,
        "window_error_from_rest": a.window_error_from_rest,
    }
    full["window"] = (
        None if window is None else {"stored": args.window, "model_samples": list(window)}
    )
    full["records"] = {
        "estimation": [r.to_dict() for r in training],
        "validation": [v.to_dict() for v in validations],
        "test": [r.to_dict() for r in tests],
    }
    keys = ("error_before", "error_after", "error_before_from_rest", "error_after_from_rest")
    keys += ("prediction_error_before", "prediction_error_after", "init_samples")
    keys += ("effect_added", "actions", "structure_before", "structure_after")
    keys += ("significance", "candidates", "residual_tests", "standard_errors_after")
    keys += ("test", "verdict", "coverage", "programs_compiled", "integrating")
    if bench is not None:
        keys += ("benchmark",)
    if window is not None:
        keys += ("window_error_before", "window_error_after")
        keys += ("window_error_before_from_rest", "window_error_after_from_rest")
    folder = pathlib.Path(args.report) if args.report else None
    if folder is not None:
        command = "jaxcascade loop " + " ".join(sys.argv[2:])
        (folder / "report.json").write_text(strict_json(full, indent=1))
        from .._measured._model_file import SavedModel  # the final model, for `jaxcascade simulate`

        saved = SavedModel.from_record(
            result.final,
            training[0],
            init_samples=args.init_samples,
            integrating=integrating is not None,
            provenance={"command": command, "declared": full["structure_before"]},
        )
        saved.save(folder / "model.json")
        roles = [("estimation", r) for r in estimation]
        roles += [("validation", r) for r in scored_records[0]]
        roles += [("test", r) for r in scored_records[1]]
        figures = _record_figures(saved, roles, folder, args.init_samples, args.figures)
        (folder / "report.md").write_text(_markdown(full, command) + figures)
        import pandas as pd

        pd.DataFrame(full["candidates"]).to_csv(folder / "candidates.csv", index=False)
        pd.DataFrame(full["scores"]).to_csv(folder / "scores.csv", index=False)
    if folder is not None and args.figures:
        # the loop's own (first) validation record: the output's difference when integrating
        shown = validations[0]
        units = _units(args.output or "y", scaling.method)
        if integrating is not None:
            from .._measured._integrating import differenced

            shown, units = differenced(shown), f"difference of {units}"
        period = shown.sample_period
        time = np.arange(len(shown)) * (period or 1.0)
        scored_from = window[0] if window is not None else min(args.init_samples, len(shown) - 2)
        init_from = max(scored_from - args.init_samples, 0)
        plot_compare(
            time,
            shown.y,
            result.before.simulated[: len(shown)],
            result.after.simulated[: len(shown)] if result.added else None,
            folder / "compare.png",
            arx=arx.simulate(shown.u),
            title=f"validation record {_name(shown)}: measured vs free-run simulation",
            units=units,
            init=(time[init_from], time[scored_from]) if scored_from > init_from else None,
            scored=(time[scored_from], time[(window[1] if window else len(time)) - 1]),
        )
        # every residual test in one figure per model (`plot_residual_tests`); a figure
        # per test as well (`save_residual_figures`) repeated its panels and more than
        # doubled the time spent drawing them
        models = [("before", result.before)] + ([("after", result.after)] if result.added else [])
        for when, evaluated in models:
            path = folder / f"residual_{when}_overview.png"
            plot_residual_tests(evaluated.tests).savefig(path, dpi=120)
    if args.json:
        print(strict_json({key: full[key] for key in keys}))
    else:
        print(_summary(full, folder))
    for sentence in [*warnings, *full["coverage"]["sentences"]]:
        print(sentence, file=sys.stderr if args.json else sys.stdout)
    return 0


def _record_figures(saved, roles, folder, init_samples, draw: bool = True) -> str:
    """One figure per record, `records/<k>-<role>.png`: measured against the final model
    (initialised on the `init_samples` samples before its scored part, and from rest) in
    the record's unit against time in seconds, with fit %, NRMSE and RMSE in the unit
    (`_model_file.SavedModel.compare`, `_plot._comparison`); returns the report's section
    that shows them. `draw` False: the section's figures without the PNG files."""
    from .._plot._comparison import plot_comparison

    lines = ["", "## Every record: measured against the final model", ""]
    if draw:
        (folder / "records").mkdir(exist_ok=True)
        lines += [
            "In the record's unit against time in seconds; the state set on the shaded "
            "samples, then simulated (`initialised`), and simulated from rest.",
            "",
        ]
    for k, (role, record) in enumerate(roles):
        c = saved.compare(record, init_samples)
        unit = record.output_unit or record.output_column
        name = f"records/{k:02d}-{role}.png"
        if draw:
            title = f"{role} record {_name(record)}: measured vs the final model"
            plot_comparison(c, folder / name, title=title, units=unit)
        s = c.score
        lines.append(
            f"- {role}, {_name(record)}: NRMSE {s.error:.4g} initialised ({s.error_from_rest:.4g} "
            f"from rest), RMSE {s.rmse:.4g} {unit}, period "
            + (f"{record.sample_period:g} s" if record.sample_period else "unknown (samples)")
            + (f"  \n  ![{role} {_name(record)}]({name})" if draw else "")
        )
    return "\n".join(lines) + "\n"


def _benchmark_summary(bench, scores, scaling, args) -> dict:
    """`"benchmark"` of the JSON: per test record the test RMSE in the benchmark's unit
    (initialised simulation over `y[n_init:]`), NRMSE and fit % of the final model, the
    declared cascade's and the ARX peer's RMSE, and the published baselines."""
    from .._metrics import fit_percent

    factor = scaling.y_scale * bench.unit_factor
    tests = []
    for record in bench.test:
        row = {
            s.model: s
            for s in scores
            if s.role == "test" and s.record == f"{bench.name} {record.name}"
        }
        final, declared, arx = row["final model"], row["declared cascade"], row["linear ARX"]
        published = dict(bench.published.get(record.name, {}))
        best_linear = bench.best_linear(record.name)
        tests.append(
            {
                "record": record.name,
                "samples": len(record.u),
                "test_rmse": final.rmse * factor,
                "test_nrmse": final.error,
                "test_fit_percent": fit_percent(final.error),
                "declared_test_rmse": declared.rmse * factor,
                "arx_test_rmse": arx.rmse * factor,
                "arx_test_nrmse": arx.error,
                "beats_arx": bool(final.rmse < arx.rmse),
                "best_linear_published": best_linear,
                "beats_best_linear": None
                if best_linear is None
                else bool(final.rmse * factor < best_linear),
                "published": published,
            }
        )
    out = {
        "name": bench.name,
        "unit": bench.unit,
        "n_init": bench.n_init,
        "n_init_model_samples": args.init_samples,
        "loader": f"nonlinear-benchmarks {bench.loader}",
        "sampling_time": bench.sampling_time,
        "decimation": args.decimate,
        "max_samples": args.max_samples,
        "split_rule": BENCHMARK_RULE,
        "decimation_rule": args.decimation_rule,
        "published_source": "Champneys et al. (2024), arXiv 2405.10779, free-run test RMSE",
        "tests": tests,
    }
    if len(tests) == 1:
        out.update({k: tests[0][k] for k in ("test_rmse", "test_nrmse", "arx_test_rmse")})
        out["published"] = tests[0]["published"]
    return out


def _file_records(args, orders):
    """Estimation, validation and test records read from the record specs on the command
    line (`RECORD_SPEC`), all in the estimation records' scaling, of one sample period."""
    import numpy as np

    from .._data import Scaling, check_sample_periods, parse_record_spec, read_record
    from ._common import record_options

    specs = [*args.train, *(args.validate or []), *(args.test or [])]
    named = bool(specs) and all(parse_record_spec(spec).input is not None for spec in specs)
    missing = [
        option
        for option, value in (
            ("TRAIN", args.train),
            ("--validate", args.validate),
            ("--input", args.input or named),
            ("--output", args.output or named),
        )
        if not value
    ]
    if missing:
        raise CLIError(
            f"loop needs {', '.join(missing)} (or --benchmark NAME --data ROOT); see "
            "jaxcascade loop --help."
        )
    # Lengths are checked by the loop: the estimation records together, a scored record
    # against its initialisation window.
    options = record_options(args)
    raw = [read_record(spec, **options, scaling="none") for spec in args.train]
    scaling = Scaling.from_data(
        np.concatenate([r.u for r in raw]), np.concatenate([r.y for r in raw]), args.scaling
    )
    training = [
        dataclasses.replace(
            r, u=scaling.input_to_model(r.u), y=scaling.output_to_model(r.y), scaling=scaling
        )
        for r in raw
    ]
    validations = [read_record(spec, **options, scaling=scaling) for spec in args.validate]
    tests = [read_record(spec, **options, scaling=scaling) for spec in args.test or []]
    check_sample_periods([*training, *validations, *tests])
    return training, validations, tests


def _benchmark_records(args, orders):
    """Estimation, validation and test records of a benchmark (`BENCHMARK_RULE`)."""
    import numpy as np

    from .._data import Scaling, record_from_arrays
    from .._measured._benchmark_data import benchmark_data

    if args.train or args.validate or args.test:
        raise CLIError(
            "--benchmark takes its records from the benchmark's files: drop TRAIN, "
            "--validate and --test."
        )
    if not args.data:
        raise CLIError("--benchmark needs --data ROOT, the folder that holds NAME/ as distributed.")
    if args.max_samples < 100:
        raise CLIError(f"--max-samples must be >= 100, got {args.max_samples}.")
    bench = benchmark_data(args.benchmark, args.data)
    records = [(r.name, np.asarray(r.u, float), np.asarray(r.y, float)) for r in bench.train]
    if type(args.decimate) is DefaultDecimation:  # not given: the benchmarks' rule
        args.decimate = benchmark_decimation(records, args.max_samples)
        args.decimation_rule = f"by the rule without --decimate: {BENCHMARK_DECIMATION}"
    else:
        args.decimation_rule = "--decimate as given"
    # MAX samples after decimation
    parts = benchmark_split(records, args.max_samples * args.decimate)
    u_all = np.concatenate([u for _, u, _ in parts["estimation"]])
    y_all = np.concatenate([y for _, _, y in parts["estimation"]])
    scaling = Scaling.from_data(u_all, y_all, args.scaling)

    def build(name, u, y):
        return record_from_arrays(
            u,
            y,
            sample_period=bench.sampling_time,
            decimate=args.decimate,
            scaling=scaling,
            source=f"{bench.name} {name}",
            input_column=args.input or "u",
            output_column=args.output or "y",
            output_unit=bench.file_unit,
        )

    training = [build(*part) for part in parts["estimation"]]
    validation = build(*parts["validation"])
    tests = [build(r.name, np.asarray(r.u, float), np.asarray(r.y, float)) for r in bench.test]
    return training, [validation], tests, bench


# The rule that cuts estimation and validation records from a benchmark's training data,
# the same for every benchmark (`benchmark_split`).
BENCHMARK_RULE = (
    "validation: the last quarter of the last training record, at most MAX/4 samples; "
    "estimation: every other training record and the samples of the last one before the "
    "validation part, the latest MAX samples of them in all (MAX = --max-samples, in "
    "samples after decimation)"
)


# The decimation of a benchmark's records without --decimate, the same for every
# benchmark (`benchmark_decimation`): a long record at a high rate is decimated as far as
# its signals' band allows, so that the estimation samples span all of it.
BENCHMARK_DECIMATION = (
    "the largest factor d, up to the one that brings the training data within MAX "
    "samples, at which 99.9 % of the power of the input and of the output's difference "
    "(their means removed) lies below 0.4/d cycles per sample (80 % of the decimated "
    "Nyquist frequency); 1 where none does"
)


class DefaultDecimation(int):
    """`--decimate`'s default in `loop`: the measured-data default's value, told apart
    from the same factor given, which `--benchmark` takes as given."""


def band_edge(x, fraction: float = 0.999) -> float:
    """The frequency (cycles per sample) below which `fraction` of the power of `x`, its
    mean removed, lies (periodogram); 0 for a constant signal."""
    import numpy as np

    x = np.asarray(x, float)
    power = np.abs(np.fft.rfft(x - x.mean())) ** 2
    total = power.sum()
    if not total > 0:
        return 0.0
    cumulative = np.cumsum(power) / total
    return float(np.fft.rfftfreq(x.size)[np.searchsorted(cumulative, fraction)])


def benchmark_decimation(records, max_samples: int) -> int:
    """`BENCHMARK_DECIMATION`'s factor for the training records `[(name, u, y), ...]`."""
    import numpy as np

    wanted = max(1, -(-sum(len(u) for _, u, _ in records) // max_samples))
    edge = max(max(band_edge(u), band_edge(np.diff(y))) for _, u, y in records)
    allowed = int(0.4 // edge) if edge > 0 else wanted
    return max(1, min(wanted, allowed))


def benchmark_split(records, max_samples: int) -> dict:
    """`records`: `[(name, u, y), ...]`, the benchmark's training records in order.
    Returns `{"estimation": [(name, u, y), ...], "validation": (name, u, y), "cut": ...}`
    by `BENCHMARK_RULE`; names carry the sample ranges."""
    *others, (name, u, y) = records
    T = len(u)
    quarter = min(T // 4, max_samples // 4)
    cut = T - quarter
    validation = (f"{name} [{cut}:{T}]", u[cut:], y[cut:])
    estimation = [(name_, u_, y_) for name_, u_, y_ in others] + [
        (f"{name} [0:{cut}]", u[:cut], y[:cut])
    ]
    # the latest max_samples estimation samples: whole records from the last backwards,
    # the earliest one cut at its end part
    kept, budget = [], max_samples
    for name_, u_, y_ in reversed(estimation):
        if budget <= 0:
            break
        if len(u_) > budget:
            first = len(u_) - budget
            base, _, span = name_.partition(" [")
            start = int(span.split(":")[0]) if span else 0
            stop = start + len(u_)
            name_ = f"{base} [{start + first}:{stop}]"
            u_, y_ = u_[first:], y_[first:]
        kept.append((name_, u_, y_))
        budget -= len(u_)
    return {"estimation": kept[::-1], "validation": validation}


def _mean_score(scores):
    """One model's validation figures: its one record's score, or the mean over several
    (a window applies to one record only)."""
    import numpy as np

    from .._measured._scoring import RecordScore

    if len(scores) == 1:
        return scores[0]
    first = scores[0]
    return RecordScore(
        first.model,
        "mean over the validation records",
        "validation",
        float(np.mean([s.error for s in scores])),
        None,
        float(np.mean([s.error_from_rest for s in scores])),
        None,
        first.init_samples,
        float(np.sqrt(np.mean([s.rmse**2 for s in scores]))),
    )


def _name(record) -> str:
    """A record's name in reports: its file's name with the spec's signals and range
    (`DATAUNIF.MAT:u11,z11:0:300`), a benchmark's record name, or "arrays"."""
    return pathlib.Path(record.source).name if record.source else "arrays"


def _units(column: str, scaling: str) -> str:
    if scaling == "none":
        return column
    return f"{column} ({'scaled' if scaling == 'scale' else 'standardised'})"


def _summary(full: dict, folder) -> str:
    """The lines stdout ends with: structure, window figures, the report's path."""
    lines = [
        f"structure: {full['structure_after']}",
        "effects: "
        + (", ".join(f"{a['action']} {a['effect']}" for a in full["actions"]) or "none"),
    ]
    for row in [r for r in full["scores"] if r["model"] != "declared cascade"]:
        w, wr = row["window_error"], row["window_error_from_rest"]
        figure = (
            f"window NRMSE {w:.4f} (from rest {wr:.4f})"
            if w is not None
            else f"NRMSE {row['error']:.4f} (from rest {row['error_from_rest']:.4f})"
        )
        lines.append(f"{row['role']} {row['record']}: {row['model']} {figure}")
    if folder is not None:
        lines.append(f"report: {folder / 'report.md'}")
    return "\n".join(lines)


def _effects(text: str | None) -> tuple[str, ...] | None:
    """`--effects a,b`: names of the library (and the noise model) the loop considers."""
    if text is None:
        return None
    from .._measured._effects import EFFECTS
    from .._measured._noise import ARNoise

    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in {*EFFECTS, ARNoise.name}]
    if unknown or not names:
        known = ", ".join([*EFFECTS, ARNoise.name])
        raise CLIError(f"--effects: unknown effect(s) {unknown or text!r}; known: {known}.")
    return names


def add_parser(subparsers) -> None:
    from .. import _defaults

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
            "jaxcascade loop a.csv b.parquet --validate c.csv --window 3072:7680 --test d.csv "
            "--test-window 6144:14336 --input u --output y --decimate 8 --json",
            "jaxcascade loop --benchmark CED --data ../shared/data/nonlinear_benchmarks "
            "--report results/ced --json",
            "jaxcascade loop train.csv --validate valid.csv --input u --output y "
            "--report results/loop --resume",
        ),
    )
    parser.add_argument(
        "train",
        nargs="*",
        metavar="TRAIN",
        help=f"estimation record(s), estimated jointly; each a record spec, {RECORD_SPEC}",
    )
    parser.add_argument(
        "--validate",
        nargs="+",
        action="extend",
        default=None,
        metavar="SPEC",
        help="validation record spec(s), as TRAIN (required with TRAIN): simulated, "
        "never fitted, to choose among the candidates; several are scored each from its "
        "own initial state and pooled (the loop's NRMSE, residual tests and significance "
        "test on their scored samples joined; the report's validation figures the mean "
        "over them)",
    )
    parser.add_argument(
        "--benchmark",
        default=None,
        metavar="NAME",
        help="a nonlinear system-identification benchmark read from --data: EMPS, CED, "
        "Silverbox, Cascaded_Tanks, WienerHammerBenchMark (its official split; estimation "
        "and validation records cut from its training data by one rule; its test records "
        "scored with its n_init, RMSE in its unit)",
    )
    parser.add_argument(
        "--data",
        default=None,
        metavar="ROOT",
        help="with --benchmark: the folder holding NAME/ as the benchmark is distributed",
    )
    parser.add_argument(
        "--max-samples",
        type=int,
        default=5000,
        help="with --benchmark: at most this many estimation samples (the latest of the "
        "training data) and a quarter of it for validation (default 5000)",
    )
    add_record_arguments(parser, required=False)
    # the measured-data default (1), or with --benchmark the benchmarks' rule
    parser.set_defaults(decimate=DefaultDecimation(_defaults.DECIMATE))
    parser._option_string_actions["--decimate"].help = (
        "anti-aliased decimation factor (default 1; with --benchmark, the largest factor "
        "that brings the training data within --max-samples and that the signals' band "
        "allows: see the report)"
    )
    parser.add_argument(
        "--max-effects",
        type=int,
        default=3,
        help="at most this many effects are added, one per round (default 3; 0: fit and test only)",
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
        + kind_help({**EFFECTS, NOISE_MODEL: NOISE_MODEL_DESCRIPTION}),
    )
    parser.add_argument(
        "--test",
        nargs="+",
        default=None,
        metavar="SPEC",
        help="test record spec(s), as TRAIN: scored with the final model only, used neither "
        "for fitting nor for choosing candidates (the only out-of-sample figures when the "
        "validation record chose the model)",
    )
    parser.add_argument(
        "--test-window",
        nargs="+",
        default=None,
        metavar="START:STOP",
        help="one scoring window per --test record, in samples of the file as stored",
    )
    parser.add_argument(
        "--init-samples",
        type=int,
        default=None,
        help="N: on every scored record the model's state (never its parameters) is set "
        "from the measured output on the N samples (after decimation) before the scored "
        "ones, the nonlinear benchmarks' convention; from-rest figures are reported beside "
        f"(default {_defaults.INIT_SAMPLES}, at most {_defaults.INIT_FRACTION:g} of the "
        "shortest validation or test record after decimation, said when it is cut; with "
        "--benchmark the benchmark's n_init; 0 scores from rest only)",
    )
    parser.add_argument(
        "--dm-threshold",
        type=float,
        default=3.0,
        help="a candidate counts when its Diebold-Mariano statistic against the current "
        "model exceeds this (default 3: with about ten candidates a round, a one-sided "
        "level near 0.001 each)",
    )
    parser.add_argument(
        "--min-gain",
        type=float,
        default=0.02,
        help="... and it lowers the validation NRMSE by at least this fraction (default 0.02)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="PRNG seed of the declared cascade's robust fit (its multi-start draws; default 0)",
    )
    parser.add_argument(
        "--retries",
        type=int,
        default=2,
        help="repeats of the robust fit's multi-start from fresh draws while its estimate "
        "fails the residual test (default 2)",
    )
    parser.add_argument(
        "--threads",
        type=int,
        default=None,
        help="candidates of a round fitted at once, in threads: the same results for any "
        "number (default: 2 where the process may use two or more cores, else 1)",
    )
    parser.add_argument(
        "--integrate",
        default="auto",
        choices=("auto", "yes", "no"),
        help="model the output through its difference y(t) - y(t-1), integrated back for "
        "scoring: auto (default) when no stable linear ARX model fits the estimation "
        "records (an output that integrates its input, a position under feedback)",
    )
    parser.add_argument(
        "--report",
        default=None,
        metavar="DIR",
        help="folder for the report and figures; the loop keeps its finished fits in "
        "DIR/checkpoints/ while it runs (see --resume)",
    )
    parser.add_argument(
        "--figures",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="draw the report's figures (default); --no-figures writes the report's "
        "tables and text without the PNG files, faster",
    )
    add_resume_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the JSON summary")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    parser.set_defaults(func=run_loop)
