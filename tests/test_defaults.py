"""One set of defaults for measured data (`_defaults`), the same at every door, and
the table in `docs/defaults.md` the same as the code's."""

import inspect
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from jaxcascade import _defaults
from jaxcascade._cli import build_parser
from jaxcascade._data import read_record, record_from_arrays
from jaxcascade._measured._loop import model_error_loop
from jaxcascade._system._model import Orders
from jaxcascade._workflow._fit import fit_record
from jaxcascade._workflow._loop import loop_benchmark, loop_records

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_the_docs_table_is_the_code_s():
    text = (ROOT / "docs" / "defaults.md").read_text()
    assert _defaults.table_markdown() in text


@pytest.mark.parametrize("command", ["fit", "loop"])
def test_every_measured_data_command_takes_the_same_defaults(command):
    argv = {"fit": ["fit", "data.csv"], "loop": ["loop", "a.csv", "--validate", "b.csv"]}
    args = build_parser().parse_args(argv[command])
    assert args.scaling == _defaults.SCALING
    assert args.detrend == _defaults.DETREND
    assert args.decimate == _defaults.DECIMATE
    assert args.orders == Orders.parse(_defaults.ORDERS)  # parsed as it is read
    if command == "fit":
        assert args.estimator == _defaults.ESTIMATOR


def test_the_api_takes_the_same_defaults():
    for function in (read_record, record_from_arrays):
        parameters = inspect.signature(function).parameters
        assert parameters["scaling"].default == _defaults.SCALING
        assert parameters["detrend"].default == _defaults.DETREND
        assert parameters["decimate"].default == _defaults.DECIMATE
    parameters = inspect.signature(fit_record).parameters
    assert parameters["estimator"].default == _defaults.ESTIMATOR
    assert parameters["orders"].default == _defaults.ORDERS
    assert parameters["scaling"].default == _defaults.SCALING


def test_the_loop_takes_the_command_s_defaults_in_python():
    """`jaxcascade loop`, `loop_records`, `loop_benchmark` and `model_error_loop`: one
    table (`_defaults`), the option's default equal to the argument's (issue 68)."""
    args = build_parser().parse_args(["loop", "a.csv", "--validate", "b.csv"])
    call = inspect.signature(loop_records).parameters
    engine = inspect.signature(model_error_loop.__wrapped__).parameters
    pairs = {
        "max_effects": "max_effects",
        "dm_threshold": "dm_threshold",
        "min_gain": "min_gain",
        "seed": "seed",
        "retries": "retries",
        "threads": "threads",
        "init_samples": "init_samples",
        "integrate": "integrate",
    }
    for option, argument in pairs.items():
        assert getattr(args, option) == call[argument].default, option
    assert call["orders"].default == _defaults.ORDERS
    assert args.orders == Orders.parse(_defaults.ORDERS)
    # the engine: the same rule for the window (None: the command's) and the threads
    assert engine["init_samples"].default is None and engine["threads"].default is None
    assert engine["max_effects"].default == args.max_effects
    assert engine["t_threshold"].default == args.dm_threshold
    assert engine["min_gain"].default == args.min_gain
    bench = inspect.signature(loop_benchmark).parameters
    args = build_parser().parse_args(["loop", "--benchmark", "CED", "--data", "."])
    assert args.max_samples == bench["max_samples"].default == _defaults.MAX_SAMPLES


def test_the_paper_commands_keep_the_paper_estimator():
    for argv in (["reproduce", "--example", "1"], ["bench"]):
        assert build_parser().parse_args(argv).estimator == _defaults.PAPER_ESTIMATOR


def test_a_one_sided_input_is_centred_by_default():
    """`auto`: an input that never crosses zero (a positive voltage) is centred, one on
    both sides of zero only scaled."""
    rng = np.random.default_rng(0)
    u = rng.uniform(1.0, 3.0, 500)
    record = record_from_arrays(u, 2.0 * u, sample_period=0.1)
    assert record.scaling.method == "standard"
    assert abs(float(np.mean(record.u))) < 1e-12
    record = record_from_arrays(u - 2.0, 2.0 * u, sample_period=0.1)
    assert record.scaling.method == "scale"


@pytest.mark.parametrize(
    ("lengths", "expected"),
    [((1024, 1024), 50), ((100, 100), 25), ((100, 400), 25), ((40,), 10), ((200,), 50)],
)
def test_the_initialisation_window_is_cut_to_a_quarter_of_the_shortest_record(lengths, expected):
    assert _defaults.init_samples(lengths) == expected


def test_a_float64_record_with_float64_off_is_one_warning_naming_the_switch():
    """Run in a fresh interpreter: the tests' own process has float64 on."""
    code = (
        "import warnings, numpy as np, jaxcascade as jc\n"
        "from jaxcascade._system._validate import record\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        "    u, y = record(np.linspace(0, 1, 50), np.linspace(0, 2, 50), where='fit')\n"
        "print(u.dtype)\n"
        "print(len(caught))\n"
        "print(caught[0].message)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    ).stdout.splitlines()
    assert out[0] == "float32"
    assert int(out[1]) == 1  # one for the record, naming both arrays and the switch
    assert "u and y are float64" in out[2] and "jax_enable_x64" in out[2]
