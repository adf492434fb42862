"""`loop_records` and `loop_benchmark`: the model-error loop on records, as `jaxcascade
loop` runs it, with the scores, the verdict and the report.

On the estimation records (an output that integrates its input modelled through its
difference, `_integrating.integration`), `model_error_loop` fits the declared cascade
and adds the effects the residual points to; the declared cascade, the final model and
the linear ARX peer (`_arx.arx_peer`) are then scored on every validation and test
record (`_scoring.score_record`: initialised on the samples before the scored ones, and
from rest), the input coverage of each record measured (`_coverage`), and a sentence
said where the final model is worse than the mean or the peer (`_scoring.verdict`).
`loop_benchmark` takes the records of a benchmark by its protocol
(`_benchmark_protocol`) and adds its test figures in its unit. `loop_command` runs the
command's `LoopSettings`: every setting checked before a file is read, then the records
read (the record specs, or the benchmark: in one scaling and of one sample period as
read) with their state-initialisation window, then the loop on them (`_loop`, which
`loop_records` calls once it has checked and prepared the records it is given). The
result, `LoopRun`, is what the command prints (`to_dict(brief=True)` is `--json`) and
writes (`report(folder)`, `_report`).
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .. import _defaults
from .._data import Record, check_sample_periods, in_scaling
from .._system._model import Orders


@dataclasses.dataclass
class LoopRun:
    """What `loop_records` and `loop_benchmark` return (`jaxcascade loop` prints and
    writes it).

    - `result`: the loop's `LoopResult` (the declared cascade, the final model, every
      candidate and the residual tests); `final`: the final model.
    - `estimation`, `validation`, `test`: the records as measured (`Record`s, model units
      in their scaling); `scaling`.
    - `scores`: `_scoring.RecordScore` of the declared cascade, the final model and the
      linear ARX peer on every validation and test record (RMSE in model units);
      `arx`: the peer, `arx_unstable_pole` its largest pole where no stable one fits.
    - `coverage`: each record's input coverage (`_coverage.Coverage`).
    - `integrating`: how the output was modelled through its difference, or None.
    - `init_samples`, `init_samples_rule` (the sentence where the default was cut).
    - `window`, `test_windows`: scoring windows in samples of the decimated records.
    - `benchmark`: a benchmark's records and protocol (`loop_benchmark`), or None.
    - `outliers`: per record with isolated outliers, their samples and sizes and the
      error with and without them (`_measured._outliers.on_records`); those of the
      estimation and validation records were left out of the loop's fits and decisions.
    - `warnings`: the sentences where the final model is worse than the mean or the ARX
      peer; `coverage_sentences`: where a record leaves the estimation range.

    `to_dict()` is `report.json`, `to_dict(brief=True)` the command's `--json`;
    `report(folder)` writes the report folder; `saved_model()` the final model with the
    records' preprocessing (`model.json`).
    """

    result: Any
    estimation: list[Record]
    validation: list[Record]
    test: list[Record]
    scores: list
    arx: Any
    arx_unstable_pole: float | None
    coverage: list
    integrating: dict | None
    init_samples: int
    init_samples_rule: str | None
    window: tuple[int, int] | None
    window_stored: tuple[int, int] | None
    test_windows: list
    settings: dict
    command: str
    benchmark: Any = None
    outliers: list = dataclasses.field(default_factory=list)

    @property
    def final(self):
        return self.result.final

    @property
    def scaling(self):
        return self.estimation[0].scaling

    def _by(self, model: str, role: str | None = None) -> list:
        return [s for s in self.scores if s.model == model and (role is None or s.role == role)]

    @property
    def warnings(self) -> list[str]:
        """The command's verdict: one sentence per scored record where the final model is
        worse than the mean (NRMSE 1) or the ARX peer, and where no stable ARX fits."""
        from .._measured import _coverage
        from .._measured._scoring import verdict

        out = verdict(
            self._by("final model"),
            self._by("linear ARX"),
            _coverage.uncovered(self.coverage),
            self.advice,
        )
        if self.arx_unstable_pole is not None:
            out.append(
                "No stable linear ARX model fits the estimation records (the best one's "
                f"largest pole is at |z| = {self.arx_unstable_pole:.4f}): the output "
                "integrates its input, which a stable model cannot follow in free run; leave "
                "--integrate at auto (the loop then models the output's difference) or model "
                "the loop closed around the output."
            )
        return out

    @property
    def advice(self) -> list:
        """What the records and the residual show (`_measured._advice.advise`): said after
        a poor score in `warnings`."""
        from .._measured import _coverage
        from .._measured._advice import advise
        from .._measured._integrating import leaky_integrator

        uncovered = sorted({record for record, _ in _coverage.uncovered(self.coverage)})
        leaky = None
        if self.integrating is None and self.arx_unstable_pole is None:
            # the peer's own records: the estimation records joined, as it was fitted
            u = np.concatenate([r.u for r in self.estimation])
            leaky = leaky_integrator(self.arx, u, np.concatenate([r.y for r in self.estimation]))
        return advise(
            [r.y_physical for r in self.estimation],
            integration=self.integrating,
            unstable_pole=self.arx_unstable_pole,
            leaky=leaky,
            uncovered=uncovered,
            failed=list(self.result.after.tests.failed),
        )

    @property
    def outlier_sentences(self) -> list[str]:
        from .._measured._outliers import sentences

        return sentences(self.outliers, self.settings.get("outliers") == "auto")

    @property
    def coverage_sentences(self) -> list[str]:
        from .._measured import _coverage

        return _coverage.sentences(self.coverage)

    def saved_model(self):
        """The final model with the estimation records' preprocessing (`model.json`)."""
        from .._measured._model_file import SavedModel

        return SavedModel.from_record(
            self.result.final,
            self.estimation[0],
            init_samples=self.init_samples,
            integrating=self.integrating is not None,
            provenance={"command": self.command, "declared": self.result.base.structure()},
            std_errors=self.result.standard_errors,
        )

    def to_dict(self, brief: bool = False) -> dict:
        """`report.json` (every figure, the models in the schema, the records); with
        `brief` the command's `--json` (the figures, decisions, tests and models)."""
        from .._measured import _coverage
        from .._measured._benchmark_protocol import benchmark_summary
        from .._measured._outliers import ALPHA, Z_MIN
        from .._measured._scoring import mean_score

        full = self.result.to_dict()
        full["robust"] = {"retries": self.settings["retries"], "seed": self.settings["seed"]}
        full["integrating"] = self.integrating
        models = ("declared cascade", "final model", "linear ARX")
        # the validation figures of each model: its record's, or the mean over several
        valid = {name: mean_score(self._by(name, "validation")) for name in models}
        full["validation_records"] = len(self.validation)
        full["init_samples"] = self.init_samples
        full["init_samples_rule"] = self.init_samples_rule
        for key, model in (("before", "declared cascade"), ("after", "final model")):
            s = valid[model]
            full[f"error_{key}"] = s.error
            full[f"window_error_{key}"] = s.window_error
            full[f"error_{key}_from_rest"] = s.error_from_rest
            full[f"window_error_{key}_from_rest"] = s.window_error_from_rest
        # RMSE in the records' own units (the scaling is affine: an error scales by y_scale)
        y_scale = self.scaling.y_scale
        full["scores"] = [{**s.to_dict(), "rmse": s.rmse * y_scale} for s in self.scores]
        if self.benchmark is not None:
            full["benchmark"] = benchmark_summary(
                self.benchmark, self.scores, self.scaling, self.init_samples
            )
        full["test"] = [
            {
                "record": s.record,
                "error": s.error,
                "window_error": s.window_error,
                "error_from_rest": s.error_from_rest,
                "window_error_from_rest": s.window_error_from_rest,
            }
            for s in self._by("final model", "test")
        ]
        full["verdict"] = self.warnings
        # what the records show, said in the verdict where the final model scores poorly
        full["advice"] = [a.to_dict() for a in self.advice] if full["verdict"] else []
        full["coverage"] = {
            "records": [r.to_dict() for r in self.coverage],
            "sentences": self.coverage_sentences,
            "outside_limit": _coverage.OUTSIDE,
            "span_limit": _coverage.SPAN,
        }
        full["outliers"] = {
            "option": self.settings.get("outliers"),
            "alpha": ALPHA,
            "z_min": Z_MIN,
            "records": self.outliers,
            "sentences": self.outlier_sentences,
        }
        a = valid["linear ARX"]
        full["arx"] = {
            "na": self.arx.orders[0],
            "nb": self.arx.orders[1],
            "largest_pole": self.arx.largest_pole,
            "stable": self.arx_unstable_pole is None,
            "error": a.error,
            "window_error": a.window_error,
            "error_from_rest": a.error_from_rest,
            "window_error_from_rest": a.window_error_from_rest,
        }
        full["window"] = (
            None
            if self.window is None
            else {
                "stored": f"{self.window_stored[0]}:{self.window_stored[1]}",
                "model_samples": list(self.window),
            }
        )
        full["records"] = {
            "estimation": [r.to_dict() for r in self.loop_estimation()],
            "validation": [v.to_dict() for v in self.validation],
            "test": [r.to_dict() for r in self.test],
        }
        if not brief:
            return full
        keys = ("error_before", "error_after", "error_before_from_rest", "error_after_from_rest")
        keys += ("prediction_error_before", "prediction_error_after", "init_samples")
        keys += ("effect_added", "actions", "structure_before", "structure_after")
        keys += ("significance", "candidates", "residual_tests", "model_before", "model_after")
        keys += ("test", "verdict", "coverage", "programs_compiled", "integrating", "outliers")
        if self.benchmark is not None:
            keys += ("benchmark",)
        if self.window is not None:
            keys += ("window_error_before", "window_error_after")
            keys += ("window_error_before_from_rest", "window_error_after_from_rest")
        return {key: full[key] for key in keys}

    def loop_estimation(self) -> list[Record]:
        """The estimation records as the loop fitted them: their output's difference
        where it integrates."""
        if self.integrating is None:
            return self.estimation
        from .._measured._integrating import differenced

        return [differenced(r) for r in self.estimation]

    def report(self, folder: str | os.PathLike, *, figures: bool = True) -> pathlib.Path:
        """Write the report folder `jaxcascade loop --report` writes (`report.json`,
        `report.md`, `scores.csv`, `candidates.csv`, `model.json`, and the figures unless
        `figures` is False); returns the folder."""
        from ._report import write_report

        return write_report(self, pathlib.Path(folder), figures=figures)

    def __repr__(self) -> str:
        r = self.result
        valid = [s for s in self._by("final model", "validation")]
        tests = "; ".join(
            f"test {s.record} NRMSE {s.headline:.4g}" for s in self._by("final model", "test")
        )
        warned = f"; {len(self.warnings)} warning(s)" if self.warnings else ""
        spikes = sum(len(row["samples"]) for row in self.outliers)
        warned += f"; {spikes} isolated outlier(s)" if spikes else ""
        return (
            f"LoopRun({r.final.structure()!r}; added {', '.join(r.added) or 'nothing'}; "
            f"validation NRMSE {r.before.error:.4g} -> {r.after.error:.4g}"
            + (f" ({len(valid)} records)" if len(valid) > 1 else "")
            + (f"; {tests}" if tests else "")
            + f"{warned})"
        )


def _as_list(records) -> list[Record]:
    if records is None:
        return []
    if isinstance(records, Record):
        return [records]
    records = list(records)
    if not all(isinstance(r, Record) for r in records):
        raise TypeError(
            "loop_records takes Records (read_record, record_from_arrays), one or a list."
        )
    return records


def loop_records(
    estimation: Record | Sequence[Record],
    validation: Record | Sequence[Record],
    test: Record | Sequence[Record] = (),
    *,
    orders=_defaults.ORDERS,
    max_effects: int = _defaults.MAX_EFFECTS,
    effects: Sequence[str] | None = None,
    window: tuple[int, int] | None = None,
    test_windows: Sequence[tuple[int, int] | None] | None = None,
    init_samples: int | None = None,
    dm_threshold: float = _defaults.DM_THRESHOLD,
    min_gain: float = _defaults.MIN_GAIN,
    seed: int = _defaults.SEED,
    retries: int = _defaults.RETRIES,
    threads: int | None = None,
    integrate: str = _defaults.INTEGRATE,
    outliers: str = _defaults.OUTLIERS,
    checkpoints=None,
    progress: Callable[[str], None] | None = None,
    command: str | None = None,
    _benchmark=None,
) -> LoopRun:
    """Run the model-error loop on records as `jaxcascade loop` does, with its defaults
    (`_defaults`, docs/defaults.md), and score the result (module docstring).

    - `estimation`, `validation`, `test`: `Record`s, one or a list each
      (`read_record`, `record_from_arrays`); the validation and test records are put in
      the estimation records' scaling; all must share a sample period.
    - `orders`: the declared cascade (`Orders` or `"nR,nL,r,p"`); `max_effects`,
      `effects` (names of `EFFECTS` and the noise model; default all), `dm_threshold`,
      `min_gain`: the loop's (`model_error_loop`); `seed`, `retries`: the declared
      cascade's robust fit; `threads`: candidates fitted at once (default 2 where the
      process may use two cores).
    - `window`: `(start, stop)` of the validation record also scored, in samples of its
      file as stored (before decimation, as `--window`); `test_windows`: one per test
      record, or None.
    - `init_samples`: samples that set each scored record's state (default 50, at most
      a quarter of the shortest scored record; 0 from rest).
    - `integrate`: `"auto"` models an output that integrates its input through its
      difference (`_integrating`), `"yes"` always, `"no"` never.
    - `outliers`: `"auto"` finds isolated outliers of the estimation and validation
      records in the final model's residual (`_measured._outliers`), leaves them out (the
      model's output in their place) and runs the loop again without them; every
      record's outliers are reported with the error with and without them (`outliers` of
      `to_dict()`). `"keep"`: none looked for.
    - `checkpoints`: a `_loop_checkpoint.Checkpoints` to keep and resume the loop's work;
      `progress`: a function that takes each progress line; `command`: what the report
      names as the run (default the call).

    Returns a `LoopRun`; a `ValueError` with one sentence for a bad setting or record.
    """
    # The settings, each refused in one sentence before any work.
    check_settings(
        max_effects, dm_threshold, min_gain, retries, threads, init_samples, outliers=outliers
    )
    if effects is not None:
        effects = _effect_names(effects)
    # The records, in the estimation records' scaling and of one sample period.
    estimation, validation, test = _as_list(estimation), _as_list(validation), _as_list(test)
    if not estimation or not validation:
        raise ValueError("loop_records needs estimation and validation records.")
    scaling = estimation[0].scaling
    if any(r.scaling != scaling for r in estimation):
        raise ValueError(
            "loop_records: the estimation records are in different scalings; read them "
            "with one (Scaling.from_data on them joined, as the command does)."
        )
    validation = [in_scaling(r, scaling) for r in validation]
    test = [in_scaling(r, scaling) for r in test]
    check_sample_periods([*estimation, *validation, *test])
    # The declared cascade and the state-initialisation window.
    orders = orders if isinstance(orders, Orders) else Orders.parse(str(orders))
    if orders.degree > 1:
        raise ValueError(
            f"orders {orders} have a branch degree; the loop declares the straight backlash "
            "(four orders) and adds curved branches itself where the residual asks for them "
            "(its effect general_backlash)."
        )
    return _loop(
        estimation,
        validation,
        test,
        orders,
        _init_window(init_samples, _benchmark, validation, test),
        init_default=init_samples is None and _benchmark is None,
        max_effects=max_effects,
        effects=effects,
        window=window,
        test_windows=test_windows,
        dm_threshold=dm_threshold,
        min_gain=min_gain,
        seed=seed,
        retries=retries,
        threads=threads,
        integrate=integrate,
        outliers=outliers,
        checkpoints=checkpoints,
        progress=progress,
        command=command,
        benchmark=_benchmark,
    )


def _loop(
    estimation: list[Record],
    validation: list[Record],
    test: list[Record],
    orders: Orders,
    init_samples: int,
    *,
    init_default: bool,
    max_effects: int,
    effects: tuple[str, ...] | None,
    window: tuple[int, int] | None,
    test_windows: Sequence[tuple[int, int] | None] | None,
    dm_threshold: float,
    min_gain: float,
    seed: int,
    retries: int,
    threads: int | None,
    integrate: str,
    outliers: str,
    checkpoints,
    progress: Callable[[str], None] | None,
    command: str | None,
    benchmark,
) -> LoopRun:
    """The loop on records as `loop_records` and `loop_command` have prepared them (each
    setting checked; the records in the estimation records' scaling and of one sample
    period; the declared `orders`; the state-initialisation window `init_samples`,
    `init_default` where it is the measured-data default): the scoring windows in
    samples of the decimated records, then the loop, the ARX peer, the scores and the
    coverage (module docstring)."""
    import jax

    from .._estimator._robust import Robust
    from .._measured import _coverage
    from .._measured._arx import arx_peer
    from .._measured._integrating import (
        differenced,
        integrated,
        integration,
        leaky_choice,
        leaky_integrator,
    )
    from .._measured._loop import (
        default_threads,
        initialised_output,
        model_error_loop,
        simulated_output,
    )
    from .._measured._outliers import find_outliers, impute, on_records
    from .._measured._report import record_name
    from .._measured._scoring import score_record, stored_window

    # The scoring windows, in samples of the decimated records.
    if window is not None and len(validation) > 1:
        raise ValueError(
            f"the window (--window) scores one validation record; {len(validation)} were "
            "given: drop the window or give one validation record."
        )
    if test_windows and len(test_windows) != len(test):
        raise ValueError(
            f"test_windows (--test-window) takes one (start, stop) per test record "
            f"({len(test)}), got {len(test_windows)}."
        )
    window_stored = None if window is None else (int(window[0]), int(window[1]))
    window = stored_window(window, validation[0], "window (--window)")
    test_windows = [
        stored_window(w, r, "test window (--test-window)")
        for w, r in zip(test_windows or [None] * len(test), test, strict=True)
    ]
    scaling = estimation[0].scaling
    say = progress or (lambda message: None)
    init_rule = None
    if init_default and init_samples < _defaults.INIT_SAMPLES:
        # the default is at most a stated fraction of the shortest scored record
        init_rule = (
            f"--init-samples {init_samples}: the default {_defaults.INIT_SAMPLES} is "
            f"at most {_defaults.INIT_FRACTION:g} of the shortest scored record"
        )
        say(init_rule)
    # An output that integrates its input (no stable ARX fits it) is modelled through its
    # difference and integrated back for scoring (`_integrating`).
    integrating = integration(estimation, integrate)

    def fit(estimation, validation, store, rounds=max_effects, tell=say, difference=None):
        # `difference`: model the output's difference (default: as `integrating` says)
        difference = integrating is not None if difference is None else difference
        training, validations = estimation, validation
        if difference:
            training = [differenced(r) for r in estimation]
            validations = [differenced(v) for v in validation]
        result = model_error_loop(
            [r.u for r in training],
            [r.y for r in training],
            [v.u for v in validations] if len(validations) > 1 else validations[0].u,
            [v.y for v in validations] if len(validations) > 1 else validations[0].y,
            orders,
            max_effects=rounds,
            sample_period=validations[0].sample_period or 1.0,
            window=window,
            progress=tell,
            effects=effects,
            robust=Robust(retries=retries),
            init_samples=max(init_samples - 1, 0) if difference else init_samples,
            integrating=difference,
            t_threshold=dm_threshold,
            min_gain=min_gain,
            key=jax.random.PRNGKey(seed),
            checkpoints=store,
            threads=default_threads() if threads is None else threads,
            scaling=scaling,
        )
        return training, result

    def scorers(model):
        pair = (
            lambda u: simulated_output(model, u),
            lambda u, y, start, n: initialised_output(model, u, y, start, n),
        )
        return integrated(*pair) if integrating is not None else pair

    if integrating is None and integrate == "auto":
        # A stable ARX peer with a slow pole and an integrator's gain (`leaky_integrator`):
        # the declared cascade fitted both ways, the validation record chooses.
        u_joined = np.concatenate([r.u for r in estimation])
        y_joined = np.concatenate([r.y for r in estimation])
        leaky = leaky_integrator(arx_peer(u_joined, y_joined)[0], u_joined, y_joined)
        if leaky is not None:
            say(
                f"the best stable ARX model's largest pole is at |z| = {leaky[0]:.4f} with an "
                "integrator's gain: the declared cascade is fitted on the output and on its "
                "difference, and the validation record chooses"
            )
            errors = []
            for as_difference in (False, True):
                _, trial = fit(estimation, validation, None, 0, lambda m: None, as_difference)
                errors.append(trial.before.error)
            integrating = leaky_choice(leaky, *errors)
    if integrating is not None:
        say(integrating["sentence"])

    training, result = fit(estimation, validation, checkpoints)
    # Isolated outliers of the estimation and validation records (`_outliers`): left out
    # (the model's output in their place) and the loop run again on the records without
    # them, so that neither a fit nor a decision follows a spike.
    fitted = [*estimation, *validation]
    left_out = [None] * len(fitted)  # per record, the outliers the loop left out
    if outliers == "auto":
        rest = scorers(result.final)[0]
        left_out = [find_outliers(r.y - rest(r.u), r.y) for r in fitted]
        if any(len(o) for o in left_out):
            count = sum(len(o) for o in left_out)
            names = [record_name(r) for r, o in zip(fitted, left_out, strict=True) if len(o)]
            say(
                f"{count} isolated outlier(s) in {', '.join(names)}: left out, the loop runs "
                "again without them"
            )
            cleaned = [
                dataclasses.replace(r, y=impute(r.y, rest(r.u), o)) if len(o) else r
                for r, o in zip(fitted, left_out, strict=True)
            ]
            training, result = fit(cleaned[: len(estimation)], cleaned[len(estimation) :], None)
    # The ARX peer is fitted on the estimation records joined end to end.
    arx, unstable = arx_peer(
        np.concatenate([r.u for r in training]), np.concatenate([r.y for r in training])
    )
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
    if result.floor is not None:  # the linear output-error peer (`_oe`, the loop's floor)
        models["linear output-error"] = (
            lambda u, m=result.floor.model: simulated_output(m, u),
            lambda u, y, start, n, m=result.floor.model: initialised_output(m, u, y, start, n),
        )
    if integrating is not None:
        # scored as measured, the output integrated back
        models = {name: integrated(*pair) for name, pair in models.items()}
    outlier_rows = []
    if outliers == "auto":
        roles = [("estimation", r) for r in estimation] + [("validation", v) for v in validation]
        roles += [("test", r) for r in test]
        outlier_rows = on_records(
            [(record_name(r), role, r) for role, r in roles],
            *models["final model"],
            init_samples=init_samples,
            found=[*left_out, *([None] * len(test))],
        )
    scored = [("validation", v, window) for v in validation]
    scored += [("test", r, w) for r, w in zip(test, test_windows, strict=True)]
    scores = [
        score_record(name, record_name(record), role, record.u, record.y, *pair, w, init_samples)
        for role, record, w in scored
        for name, pair in models.items()
    ]
    # where the scored records go that the estimation records did not (`_coverage`),
    # every record as measured, in its own units
    covered = _coverage.coverage(
        [(record_name(r), r.u, r.y) for r in estimation],
        [(record_name(r), role, r.u, r.y) for role, r, _ in scored],
        u_map=scaling.input_to_physical,
        y_scale=scaling.y_scale,
    )
    return LoopRun(
        result=result,
        estimation=estimation,
        validation=validation,
        test=test,
        scores=scores,
        arx=arx,
        arx_unstable_pole=unstable,
        coverage=covered,
        integrating=integrating,
        init_samples=init_samples,
        init_samples_rule=init_rule,
        window=window,
        window_stored=window_stored,
        test_windows=test_windows,
        settings={"retries": retries, "seed": seed, "outliers": outliers},
        outliers=outlier_rows,
        command=command or "loop_records(...)",
        benchmark=benchmark,
    )


@dataclasses.dataclass(frozen=True)
class LoopSettings:
    """What `jaxcascade loop` asks for, as one value: the command line builds it
    (`_cli._loop`), `loop_command` checks and runs it.

    The records: the record specs `train`, `validate`, `test`, read with `read`
    (`read_record`'s settings) in the estimation records' joint `scaling`; or the
    benchmark `benchmark` under the folder `data` (`loop_benchmark`: at most
    `max_samples` estimation samples, decimated by `decimate`, None its rule).
    `decimate`: the factor given, None where it was not. `window`, `test_windows` and the
    rest: `loop_records`'.
    """

    orders: Orders
    train: tuple[str, ...] = ()
    validate: tuple[str, ...] = ()
    test: tuple[str, ...] = ()
    read: dict | None = None
    scaling: str = _defaults.SCALING
    benchmark: str | None = None
    data: str | None = None
    max_samples: int = _defaults.MAX_SAMPLES
    decimate: int | None = None
    window: tuple[int, int] | None = None
    test_windows: tuple[tuple[int, int], ...] | None = None
    max_effects: int = _defaults.MAX_EFFECTS
    effects: tuple[str, ...] | None = None
    init_samples: int | None = None
    dm_threshold: float = _defaults.DM_THRESHOLD
    min_gain: float = _defaults.MIN_GAIN
    seed: int = _defaults.SEED
    retries: int = _defaults.RETRIES
    threads: int | None = None
    integrate: str = _defaults.INTEGRATE
    outliers: str = _defaults.OUTLIERS
    checkpoints: Any = None
    progress: Callable[[str], None] | None = None
    command: str | None = None


def loop_command(settings: LoopSettings) -> LoopRun:
    """`jaxcascade loop` as `settings` says, in three stages: the settings checked (a
    `ValueError` in one sentence before any file is read), the records read (the record
    specs in one scaling and of one sample period, `read_jointly`, or the benchmark by
    its protocol, built so) with their state-initialisation window, and the loop on them
    (`_loop`, as `loop_records` runs it)."""
    s = settings
    check_settings(
        s.max_effects,
        s.dm_threshold,
        s.min_gain,
        s.retries,
        s.threads,
        s.init_samples,
        s.decimate,
        s.outliers,
    )
    effects = None if s.effects is None else _effect_names(s.effects)
    estimation, validation, test, benchmark = _command_records(s)
    return _loop(
        estimation,
        validation,
        test,
        s.orders,
        _init_window(s.init_samples, benchmark, validation, test),
        init_default=s.init_samples is None and benchmark is None,
        max_effects=s.max_effects,
        effects=effects,
        window=s.window,
        test_windows=s.test_windows,
        dm_threshold=s.dm_threshold,
        min_gain=s.min_gain,
        seed=s.seed,
        retries=s.retries,
        threads=s.threads,
        integrate=s.integrate,
        outliers=s.outliers,
        checkpoints=s.checkpoints,
        progress=s.progress,
        command=s.command,
        benchmark=benchmark,
    )


def _init_window(init_samples, benchmark, validation, test) -> int:
    """The state-initialisation window: `init_samples` where given, else the benchmark's
    own (in samples after decimation), else the measured-data default of the scored
    records' lengths (`_defaults.init_samples`)."""
    if init_samples is not None:
        return init_samples
    if benchmark is not None:
        return benchmark.init_samples
    return _defaults.init_samples(len(r) for r in [*validation, *test])


def _command_records(s: LoopSettings) -> tuple[list, list, list, Any]:
    """The estimation, validation and test records `s` names, and the benchmark's
    records and protocol (or None): the benchmark read by its protocol, else the record
    specs, once the command line names them and their signals."""
    if s.benchmark:
        records = _benchmark_records(s.benchmark, s.data, s.max_samples, s.decimate, s.scaling)
        return records.estimation, records.validation, records.test, records
    from .._data import parse_record_spec, read_jointly

    specs = [*s.train, *s.validate, *s.test]
    named = bool(specs) and all(parse_record_spec(spec).input is not None for spec in specs)
    needed = (
        ("TRAIN", s.train),
        ("--validate", s.validate),
        ("--input", s.read["input_column"] or named),
        ("--output", s.read["output_column"] or named),
    )
    missing = [option for option, value in needed if not value]
    if missing:
        raise ValueError(
            f"loop needs {', '.join(missing)} (or --benchmark NAME --data ROOT); see "
            "jaxcascade loop --help."
        )
    # Lengths are checked by the loop: the estimation records together, a scored record
    # against its initialisation window.
    return (*read_jointly(s.train, s.validate, s.test, **s.read, scaling=s.scaling), None)


def _benchmark_records(name, root, max_samples, decimate, scaling):
    """A benchmark's records by its protocol (`_benchmark_protocol.benchmark_records`),
    `max_samples` checked before its files are read."""
    from .._measured._benchmark_data import benchmark_data
    from .._measured._benchmark_protocol import benchmark_records, check_max_samples

    check_max_samples(max_samples)  # before the files are read
    data = benchmark_data(name, root)
    return benchmark_records(data, max_samples=max_samples, decimate=decimate, scaling=scaling)


def loop_benchmark(
    name: str,
    root: str | os.PathLike,
    *,
    max_samples: int = _defaults.MAX_SAMPLES,
    decimate: int | None = None,
    scaling: str = _defaults.SCALING,
    command: str | None = None,
    **options,
) -> LoopRun:
    """Run the loop on a nonlinear benchmark read from `root` (`ROOT/NAME/` as the
    `nonlinear-benchmarks` package lays it out: `benchmark_data`), as `jaxcascade loop
    --benchmark NAME --data ROOT` does: its estimation and validation records cut from
    its training data by one rule, at most `max_samples` estimation samples after
    decimation, decimated by the benchmarks' rule unless `decimate` is given
    (`_benchmark_protocol`), its official test records scored with its `n_init` (unless
    `init_samples` is given). `options`: those of `loop_records`. The `LoopRun`'s
    `to_dict()["benchmark"]` holds the test RMSE in the benchmark's unit beside the
    published baselines."""
    records = _benchmark_records(name, root, max_samples, decimate, scaling)
    return loop_records(
        records.estimation,
        records.validation,
        records.test,
        command=command or f"loop_benchmark({name!r}, {os.fspath(root)!r})",
        _benchmark=records,
        **options,
    )


def check_settings(
    max_effects=0,
    dm_threshold=1.0,
    min_gain=0.0,
    retries=0,
    threads=None,
    init_samples=None,
    decimate=1,
    outliers="auto",
) -> None:
    """The loop's settings, a `ValueError` in one sentence naming the argument and the
    command's option (`loop_records` checks them; `loop_command` before it reads a
    record)."""
    checks = (
        (max_effects >= 0, "max_effects (--max-effects) must be >= 0", max_effects),
        (dm_threshold > 0, "dm_threshold (--dm-threshold) must be positive", dm_threshold),
        (0 <= min_gain < 1, "min_gain (--min-gain) must be in [0, 1)", min_gain),
        (retries >= 0, "retries (--retries) must be >= 0", retries),
        (threads is None or threads >= 1, "threads (--threads) must be >= 1", threads),
        (
            init_samples is None or init_samples >= 0,
            "init_samples (--init-samples) must be >= 0",
            init_samples,
        ),
        (decimate is None or decimate >= 1, "decimate (--decimate) must be >= 1", decimate),
        (
            outliers in ("auto", "keep"),
            "outliers (--outliers) must be auto or keep",
            repr(outliers),
        ),
    )
    for ok, message, value in checks:
        if not ok:
            raise ValueError(f"{message}, got {value}.")


def _effect_names(names) -> tuple[str, ...]:
    """The effects of the library (and the noise model) the loop considers."""
    from .._measured._effects import EFFECTS
    from .._measured._noise import ARNoise

    names = tuple(name.strip() for name in names if name.strip())
    unknown = [name for name in names if name not in {*EFFECTS, ARNoise.name}]
    if unknown or not names:
        known = ", ".join([*EFFECTS, ARNoise.name])
        raise ValueError(
            f"effects (--effects): unknown effect(s) {unknown or list(names)!r}; known: {known}."
        )
    return names
