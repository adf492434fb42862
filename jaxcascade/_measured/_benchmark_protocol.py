"""A benchmark's protocol in the loop: one rule that cuts the estimation and validation
records from its training data, one that decimates a long record at a high rate, the
same for every benchmark, and the test figures in the benchmark's unit beside the
published baselines (`_benchmark_data` reads the records as the official loader splits
them).

- `BENCHMARK_RULE` (`benchmark_split`): the validation record is the last quarter of the
  last training record (at most MAX/4 samples); the estimation records are the other
  training records and the samples before it, the latest MAX of them in all.
- `BENCHMARK_DECIMATION` (`benchmark_decimation`): the largest factor, up to the one that
  brings the training data within MAX samples, at which the input's and the output
  difference's band lies below 80 % of the decimated Nyquist frequency.

`benchmark_records` applies both and returns `Record`s in the estimation records'
scaling, with the test records and the state-initialisation window in samples after
decimation; `benchmark_summary` gives the `"benchmark"` block of the loop's JSON (per
test record the RMSE in the benchmark's unit of the final model, the declared cascade
and the ARX peer, and the published figures).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .. import _defaults
from .._data import Record, Scaling, record_from_arrays
from ._benchmark_data import MECHANISMS, Benchmark

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


def band_edge(x, fraction: float = 0.999) -> float:
    """The frequency (cycles per sample) below which `fraction` of the power of `x`, its
    mean removed, lies (periodogram); 0 for a constant signal."""
    x = np.asarray(x, float)
    power = np.abs(np.fft.rfft(x - x.mean())) ** 2
    total = power.sum()
    if not total > 0:
        return 0.0
    cumulative = np.cumsum(power) / total
    return float(np.fft.rfftfreq(x.size)[np.searchsorted(cumulative, fraction)])


def benchmark_decimation(records, max_samples: int) -> int:
    """`BENCHMARK_DECIMATION`'s factor for the training records `[(name, u, y), ...]`."""
    wanted = max(1, -(-sum(len(u) for _, u, _ in records) // max_samples))
    edge = max(max(band_edge(u), band_edge(np.diff(y))) for _, u, y in records)
    allowed = int(0.4 // edge) if edge > 0 else wanted
    return max(1, min(wanted, allowed))


def benchmark_split(records, max_samples: int) -> dict:
    """`records`: `[(name, u, y), ...]`, the benchmark's training records in order.
    Returns `{"estimation": [(name, u, y), ...], "validation": (name, u, y)}` by
    `BENCHMARK_RULE`; names carry the sample ranges."""
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


def check_max_samples(max_samples) -> None:
    """At least 100 estimation samples (a `ValueError` in one sentence)."""
    if isinstance(max_samples, bool) or not isinstance(max_samples, int) or max_samples < 100:
        raise ValueError(
            f"max_samples (--max-samples) must be an integer >= 100, got {max_samples!r}."
        )


@dataclasses.dataclass(frozen=True)
class BenchmarkRecords:
    """A benchmark's records for the loop (`benchmark_records`): `estimation` and
    `validation` (`[Record]`) cut by `BENCHMARK_RULE`, the official `test` records, all
    in the estimation records' scaling; `decimation` and the sentence that says how it
    was chosen (`decimation_rule`); `init_samples`, the benchmark's `n_init` in samples
    after decimation; `max_samples`; the `benchmark` itself."""

    benchmark: Benchmark
    estimation: list[Record]
    validation: list[Record]
    test: list[Record]
    decimation: int
    decimation_rule: str
    init_samples: int
    max_samples: int


def benchmark_records(
    benchmark: Benchmark,
    *,
    max_samples: int = _defaults.MAX_SAMPLES,
    decimate: int | None = None,
    scaling: str = _defaults.SCALING,
    input_column: str = "u",
    output_column: str = "y",
) -> BenchmarkRecords:
    """The loop's records of `benchmark` (module docstring). `decimate`: None applies
    `BENCHMARK_DECIMATION`, a factor is taken as given; `max_samples` (at least 100)
    counts the estimation samples after decimation."""
    check_max_samples(max_samples)
    if decimate is not None and (
        isinstance(decimate, bool) or not isinstance(decimate, int) or decimate < 1
    ):
        raise ValueError(f"decimate must be an integer >= 1, got {decimate!r}.")
    records = [(r.name, np.asarray(r.u, float), np.asarray(r.y, float)) for r in benchmark.train]
    if decimate is None:  # the benchmarks' rule
        decimate = benchmark_decimation(records, max_samples)
        rule = f"by the rule without --decimate: {BENCHMARK_DECIMATION}"
    else:
        rule = "--decimate as given"
    # MAX samples after decimation
    parts = benchmark_split(records, max_samples * decimate)
    u_all = np.concatenate([u for _, u, _ in parts["estimation"]])
    y_all = np.concatenate([y for _, _, y in parts["estimation"]])
    scale = Scaling.from_data(u_all, y_all, scaling)

    def build(name, u, y):
        return record_from_arrays(
            u,
            y,
            sample_period=benchmark.sampling_time,
            decimate=decimate,
            scaling=scale,
            source=f"{benchmark.name} {name}",
            input_column=input_column,
            output_column=output_column,
            output_unit=benchmark.file_unit,
        )

    return BenchmarkRecords(
        benchmark=benchmark,
        estimation=[build(*part) for part in parts["estimation"]],
        validation=[build(*parts["validation"])],
        test=[
            build(r.name, np.asarray(r.u, float), np.asarray(r.y, float)) for r in benchmark.test
        ],
        decimation=decimate,
        decimation_rule=rule,
        init_samples=-(-benchmark.n_init // decimate),
        max_samples=max_samples,
    )


# where the published figures come from
PUBLISHED_SOURCE = "Champneys et al. (2024), arXiv 2405.10779, free-run test RMSE"


def benchmark_summary(records: BenchmarkRecords, scores, scaling: Scaling, init_samples: int):
    """The `"benchmark"` block of the loop's JSON: per official test record the test RMSE
    in the benchmark's unit (initialised simulation over `y[n_init:]`), NRMSE and fit %
    of the final model, the declared cascade's and the ARX peer's RMSE, and the
    published baselines, the linear output-error peer's where it was scored, and where the
    final model stays above the published polynomial NARX, a sentence naming the
    mechanism the system has (`_benchmark_data.MECHANISMS`). `scores`: the loop's
    `_scoring.RecordScore`s (models "final model", "declared cascade", "linear ARX",
    "linear output-error"), their RMSE in model units."""
    from .._metrics import fit_percent

    bench = records.benchmark
    factor = scaling.y_scale * bench.unit_factor
    tests = []
    for record in bench.test:
        row = {
            s.model: s
            for s in scores
            if s.role == "test" and s.record == f"{bench.name} {record.name}"
        }
        final, declared, arx = row["final model"], row["declared cascade"], row["linear ARX"]
        oe = row.get("linear output-error")
        published = dict(bench.published.get(record.name, {}))
        best_linear = bench.best_linear(record.name)
        narx = published.get("polynomial_narx")
        above_narx = narx is not None and final.rmse * factor > narx
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
                "oe_test_rmse": None if oe is None else oe.rmse * factor,
                "beats_oe": None if oe is None else bool(final.rmse <= oe.rmse),
                "polynomial_narx_published": narx,
                # where the final model stays above the polynomial NARX: what is missing
                "missing_mechanism": (
                    f"{record.name}: {final.rmse * factor:.4g} {bench.unit} against the "
                    f"polynomial NARX's {narx:.4g}: the system has "
                    f"{MECHANISMS[bench.name]}."
                    if above_narx and bench.name in MECHANISMS
                    else None
                ),
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
        "n_init_model_samples": init_samples,
        "loader": f"nonlinear-benchmarks {bench.loader}",
        "sampling_time": bench.sampling_time,
        "decimation": records.decimation,
        "max_samples": records.max_samples,
        "split_rule": BENCHMARK_RULE,
        "decimation_rule": records.decimation_rule,
        "published_source": PUBLISHED_SOURCE,
        "tests": tests,
    }
    if len(tests) == 1:
        out.update({k: tests[0][k] for k in ("test_rmse", "test_nrmse", "arx_test_rmse")})
        out["published"] = tests[0]["published"]
    return out
