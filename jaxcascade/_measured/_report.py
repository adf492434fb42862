"""The text of the loop's report and of `simulate`'s: `report.md`, the lines stdout ends
with, each record's line beside its figure, the final model's equations, and the report
a loop that was interrupted leaves. Every function takes the JSON the run writes
(`report.json`, `simulate.json`), so that the text is a function of the figures.
"""

from __future__ import annotations

import pathlib

import numpy as np

from .._metrics import fit_percent


def _f(value) -> str:
    return "-" if value is None else f"{value:.4f}"


def record_name(record) -> str:
    """A record's name in reports: its file's name with the spec's signals and range
    (`DATAUNIF.MAT:u11,z11:0:300`), a benchmark's record name, or "arrays"."""
    return pathlib.Path(record.source).name if record.source else "arrays"


def markdown(report: dict, command: str) -> str:
    """`report.md` of the loop from its `report.json` (`LoopRun.to_dict`) and the
    command that ran it, up to the section on every record (`records_section`)."""
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
        *_outlier_lines(report.get("outliers")),
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
    if report.get("model_after"):
        lines += _final_model_lines(report["model_after"])
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
        ("linear output-error peer (this run)", "oe_test_rmse"),
        ("linear ARX peer (this run)", "arx_test_rmse"),
    ):
        if all(t.get(key) is None for t in tests):
            continue
        lines.append(
            f"| {label} | "
            + " | ".join("-" if t.get(key) is None else f"{t[key]:.4g}" for t in tests)
            + " |"
        )
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
    missing = [t["missing_mechanism"] for t in tests if t.get("missing_mechanism")]
    if missing:
        lines += ["Where the final model stays above the polynomial NARX baseline:", ""]
        lines += [f"- {sentence}" for sentence in missing] + [""]
    return lines


def _p(test) -> str:
    if not test:
        return "-"
    p = test.get("p_value")
    mark = "pass" if test.get("passed") else "FAIL"
    return f"{p:.3g} {mark}" if p is not None else mark


def equations(model: dict) -> list[str]:
    """The cascade's three blocks with the estimates written in, in the records' units
    (`model`: the schema, `_schema.model_schema`; docs/model.md gives the general form).
    Empty where an effect replaced the cascade."""
    if not model["cascade"]:
        return []
    p, o = model["estimates"], model["orders"]

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

    numerator = "v(t-1)" + "".join(term(p[f"a{j}"], f"v(t-{j})") for j in range(2, o["r"] + 1))
    denominator = "".join(term(-p[f"b{i}"], f"x(t-{i})") for i in range(1, o["p"] + 1))
    return [
        f"NS (static, piecewise linear): v = f(u), right of zero {slopes('R', o['nR'])}; "
        f"left of zero {slopes('L', o['nL'])}",
        f"LD (linear): x(t) = {numerator}{denominator}",
        _backlash_equation(p, o["degree"]),
    ]


def _backlash_equation(p: dict, degree: int) -> str:
    left, right = f"x(t) + {p['cL']:.4g}", f"{p['mR']:.4g} (x(t) - {p['cR']:.4g})"
    name = "backlash"
    if degree > 1:
        name = f"general backlash, degree {degree}"
        for side, s in (("L", f"(x(t) + {p['cL']:.4g})"), ("R", f"(x(t) - {p['cR']:.4g})")):
            terms = "".join(
                f" {'-' if p[f'm{side}{i}'] < 0 else '+'} {abs(p[f'm{side}{i}']):.4g} {s}^{i}"
                for i in range(2, degree + 1)
            )
            left, right = (left + terms, right) if side == "L" else (left, right + terms)
    return (
        f"ND ({name}): y(t) = {left} where that is below y(t-1); "
        f"y(t) = {right} where that is above y(t-1); else y(t) = y(t-1)"
    )


def _error(value) -> str:
    return "-" if value is None else f"{value:.2g}"


def _outlier_lines(outliers: dict | None) -> list[str]:
    """The report's isolated outliers (`_outliers`): one sentence per record that has any."""
    if not outliers or not outliers.get("records"):
        return []
    lines = [
        "Isolated outliers of the output (a sample farther from the mean of its two "
        "neighbours than the robust scale of that difference times the normal quantile of "
        f"{outliers['alpha']:g} / N, at least {outliers['z_min']:g} scales):",
        "",
    ]
    return lines + [f"- {sentence}" for sentence in outliers["sentences"]] + [""]


def _final_model_lines(model: dict) -> list[str]:
    """The report's section on the final model (`model`: the schema): its structure,
    equations and every estimate with its standard error, in the records' units and in
    model units; each effect's fields in model units."""
    sc = model["scaling"]
    effects = [e["name"] for e in model["effects"]]
    noise = len(model["noise"]["ar"])
    lines = [
        "",
        "## The final model",
        "",
        f"`{model['structure']}`"
        + (f", effects {', '.join(effects)}" if effects else "")
        + (f", AR({noise}) noise model" if noise else ""),
        "",
        f"In the records' units: y - y_offset = cascade(u - u_offset), fitted in model units "
        f"(scaling `{sc['method']}`: input offset {sc['u_offset']:.4g}, scale "
        f"{sc['u_scale']:.4g}; output offset {sc['y_offset']:.4g}, scale {sc['y_scale']:.4g}). "
        "Standard errors from the output-error information on the estimation records "
        "(infinite: the records do not determine the parameter); an effect's fields in "
        "the records' units by the unit each declares (its `units` in report.json).",
        "",
        *(f"- {equation}" for equation in equations(model)),
        "",
        "| parameter | estimate | standard error | in model units |",
        "|---|---|---|---|",
    ]
    for name, value in model["estimates"].items():
        error = model["std_errors"][name]
        inner = model["estimates_model_units"][name]
        inner_error = model["std_errors_model_units"][name]
        lines.append(
            f"| {name} | {value:.6g} | {_error(error)} | {inner:.6g} ± {_error(inner_error)} |"
        )
    for effect in model["effects"]:
        if effect["name"] == "general_backlash":
            continue  # its terms are the cascade's mL2.., mR2.. above
        # a report of before the records' units (its effects in model units alone)
        outer = effect.get("parameters", {})
        outer_errors = effect.get("std_errors", {})
        for field, value in effect["parameters_model_units"].items():
            values = np.ravel(np.asarray(value, float))
            errors = np.ravel(np.asarray(effect["std_errors_model_units"][field], dtype=object))
            size = values.size
            if field in outer:
                records = np.ravel(np.asarray(outer[field], float))
                record_errors = np.ravel(np.asarray(outer_errors[field], dtype=object))
            else:  # a field kept in model units
                records, record_errors = [None] * size, [None] * size
            rows = zip(values, errors, records, record_errors, strict=True)
            for i, (v, e, rv, re_) in enumerate(rows):
                name = f"{effect['name']}.{field}" + ("" if size == 1 else f"[{i}]")
                shown = f"{v:.6g}" + ("" if e is None else f" ± {_error(e)}")
                estimate = "-" if rv is None else f"{rv:.6g}"
                error = "-" if rv is None or re_ is None else _error(re_)
                lines.append(f"| {name} | {estimate} | {error} | {shown} |")
    return lines


def summary(report: dict, folder) -> str:
    """The lines stdout ends with: structure, window figures, the report's path."""
    lines = [
        f"structure: {report['structure_after']}",
        "effects: "
        + (", ".join(f"{a['action']} {a['effect']}" for a in report["actions"]) or "none"),
    ]
    for row in [r for r in report["scores"] if r["model"] != "declared cascade"]:
        w, wr = row["window_error"], row["window_error_from_rest"]
        figure = (
            f"window NRMSE {w:.4f} (from rest {wr:.4f})"
            if w is not None
            else f"NRMSE {row['error']:.4f} (from rest {row['error_from_rest']:.4f})"
        )
        lines.append(f"{row['role']} {row['record']}: {row['model']} {figure}")
    if folder is not None:
        lines.append(f"report: {pathlib.Path(folder) / 'report.md'}")
    return "\n".join(lines)


def records_section(rows: list[dict], draw: bool) -> str:
    """The report's section on every record: one line each (`rows`: `{"role", "name",
    "unit", "period", "figure", "score"}`, `score` a `_scoring.RecordScore` in the
    record's unit), its figure beside it where `draw`."""
    lines = ["", "## Every record: measured against the final model", ""]
    if draw:
        lines += [
            "In the record's unit against time in seconds; the state set on the shaded "
            "samples, then simulated (`initialised`), and simulated from rest.",
            "",
        ]
    for row in rows:
        s, role, name, unit = row["score"], row["role"], row["name"], row["unit"]
        period = row["period"]
        lines.append(
            f"- {role}, {name}: NRMSE {s.error:.4g} initialised ({s.error_from_rest:.4g} "
            f"from rest), RMSE {s.rmse:.4g} {unit}, period "
            + (f"{period:g} s" if period else "unknown (samples)")
            + (f"  \n  ![{role} {name}]({row['figure']})" if draw else "")
        )
    return "\n".join(lines) + "\n"


def simulate_markdown(result: dict, unit: str) -> str:
    """`simulate.md` (and `jaxcascade simulate`'s stdout) from `simulate.json`."""
    rows = result["records"]
    lines = [
        f"model: `{result['structure']}` ({result['model']})",
        "",
        "| record | samples | init samples | NRMSE | fit % | RMSE "
        f"({unit}) | NRMSE, from rest | fit %, from rest | RMSE, from rest |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['record']} | {r['samples']} | {r['init_samples']} | {_f(r['error'])} | "
            f"{_f1(r['fit_percent'])} | {r['rmse']:.4g} | {_f(r['error_from_rest'])} | "
            f"{_f1(r['fit_percent_from_rest'])} | {r['rmse_from_rest']:.4g} |"
        )
    lines += [
        "",
        "Initialised: the state set from the measured output on the first init samples, "
        "scored after them; from rest: the whole record simulated from rest. NRMSE is "
        "normalised by the output's standard deviation (1 is the mean).",
    ]
    return "\n".join(lines) + "\n"


def _f1(value) -> str:
    return "-" if value is None else f"{value:.1f}"


def interrupted_markdown(sentence: str, finished: list[dict], command: str) -> str:
    """`report.md` of a loop interrupted by Ctrl-C (`_cli._loop_resume`): where it
    stopped, how to continue it, and what it had finished."""
    lines = ["# Model-error loop report: interrupted", "", sentence, ""]
    lines += ["Continue it (finished fits are loaded, not refitted) with:", ""]
    lines += [f"    {command}", ""]
    if finished:
        lines += [
            "| finished | round | model | NRMSE | DM | significant |",
            "|---|---|---|---|---|---|",
        ]
        for item in finished:
            lines.append(
                f"| {item['item']} | {item.get('round', '-')} | {item.get('label', '-')} | "
                f"{_number(item.get('error'))} | {_number(item.get('t'), '.2f')} | "
                f"{item.get('significant', '-')} |"
            )
        lines.append("")
    return "\n".join(lines)


def _number(value, spec: str = ".4f") -> str:
    return "-" if value is None else format(value, spec)
