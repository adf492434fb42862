"""The defaults for measured data, in one place.

Every door through which a measured record enters the package takes its defaults from
here: the command line's `fit`, `loop` and `simulate`, and the Python API's `read_record`,
`record_from_arrays`, `fit_record`, `loop_records`, `loop_benchmark`, `model_error_loop`
and `simulate_model`. `reproduce`, `sweep` and
`bench` simulate the paper's systems instead: they keep the paper's estimator
(`literal`) and its units (no scaling), as `TABLE` says. `docs/defaults.md` shows `TABLE`
(`tests/test_defaults.py` holds the two equal).
"""

from __future__ import annotations

# Units the model is fitted in: "auto" divides input and output by their standard
# deviations, and also centres them when the input keeps to one side of zero
# (`_data.Scaling.from_data`), so that the static block's breakpoints lie in the
# record's operating range; estimates are mapped back to physical units.
SCALING = "auto"
DETREND = "none"
DECIMATE = 1
ORDERS = "2,2,2,2"
ESTIMATOR = "robust"

# The state-initialisation window of a scored record (the nonlinear benchmarks'
# convention): `INIT_SAMPLES` samples of the measured output before the scored ones, at
# most `INIT_FRACTION` of the shortest scored record (`init_samples`).
INIT_SAMPLES = 50
INIT_FRACTION = 0.25

# The model-error loop (`loop`, `loop_records`, `loop_benchmark`, `model_error_loop`): at
# most `MAX_EFFECTS` effects, one a round; a candidate counts when its Diebold-Mariano
# statistic exceeds `DM_THRESHOLD` and it lowers the validation NRMSE by `MIN_GAIN`; the
# declared cascade's robust fit draws its starts from `SEED` and repeats them `RETRIES`
# times; an output that integrates its input is modelled through its difference
# (`INTEGRATE`: "auto", "yes", "no"); a benchmark's estimation records hold at most
# `MAX_SAMPLES` samples after decimation. Threads: `_measured._loop.default_threads`.
# `MAX_EFFECTS` bounds the run time; the significance rule is what stops the loop: on
# every benchmark and stand-in of `results/nonlinear_benchmarks*` it stops before five
# (CED takes four, `results/nonlinear_benchmarks/CED/report.md`).
MAX_EFFECTS = 5
DM_THRESHOLD = 3.0
MIN_GAIN = 0.02
SEED = 0
RETRIES = 2
INTEGRATE = "auto"
MAX_SAMPLES = 5000
# isolated outliers of the output (`_measured._outliers`): "auto" leaves them out, "keep"
OUTLIERS = "auto"

# what the paper's reproduction uses instead
PAPER_ESTIMATOR = "literal"
PAPER_SCALING = "none"


def init_samples(lengths) -> int:
    """The default state-initialisation window for scored records of `lengths` samples
    (after decimation): `INIT_SAMPLES`, at most `INIT_FRACTION` of the shortest."""
    shortest = min(int(n) for n in lengths)
    return int(max(0, min(INIT_SAMPLES, int(INIT_FRACTION * shortest))))


# (setting, measured-data default, where it applies, the paper's reproduction)
TABLE = (
    (
        "scaling",
        f"`{SCALING}`",
        "`fit`, `loop`, `simulate` (the model file's own), `read_record`, `record_from_arrays`, "
        "`fit_record`, `loop_benchmark`",
        f"`{PAPER_SCALING}` (the paper's units)",
    ),
    ("detrend", f"`{DETREND}`", "`fit`, `loop`, `read_record`, `record_from_arrays`", "-"),
    ("decimate", f"`{DECIMATE}`", "`fit`, `loop`, `read_record`, `record_from_arrays`", "-"),
    (
        "orders nR,nL,r,p",
        f"`{ORDERS}`",
        "`fit`, `loop`, `fit_record`, `loop_records`, `model_error_loop`",
        "each example's own",
    ),
    (
        "estimator",
        f"`{ESTIMATOR}`",
        "`fit`, `fit_record`, the loop's declared cascade",
        f"`{PAPER_ESTIMATOR}` (eqs. 19-28)",
    ),
    (
        "init samples",
        f"{INIT_SAMPLES}, at most {INIT_FRACTION:g} of the shortest scored record",
        "`loop`, `loop_records`, `model_error_loop` (a benchmark: its own `n_init`), `simulate` "
        "(the model file's own)",
        "0 (from rest)",
    ),
    ("max effects", f"{MAX_EFFECTS}", "`loop`, `loop_records`, `model_error_loop`", "-"),
    (
        "significance",
        f"DM > {DM_THRESHOLD:g} and {100 * MIN_GAIN:g} % lower NRMSE",
        "`loop`, `loop_records`, `model_error_loop`",
        "-",
    ),
    (
        "seed, retries",
        f"{SEED}, {RETRIES}",
        "`loop`, `loop_records` (the declared cascade's robust fit)",
        "-",
    ),
    (
        "threads",
        "2 where the process may use two cores, else 1",
        "`loop`, `loop_records`, `model_error_loop`",
        "-",
    ),
    ("integrate", f"`{INTEGRATE}`", "`loop`, `loop_records`", "-"),
    ("outliers", f"`{OUTLIERS}`", "`loop`, `loop_records`", "-"),
    ("max samples", f"{MAX_SAMPLES}", "`loop --benchmark`, `loop_benchmark`", "-"),
)


def table_markdown() -> str:
    """`TABLE` as the Markdown table of `docs/defaults.md`."""
    lines = [
        "| setting | measured data | where | `reproduce`, `sweep`, `bench` |",
        "|---|---|---|---|",
    ]
    lines += [f"| {' | '.join(row)} |" for row in TABLE]
    return "\n".join(lines)
