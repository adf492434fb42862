"""Reading measured records: round trips, every user error, decimation, scaling, splits."""

import math
import os
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

from jaxcascade import Orders, example, simulate
from jaxcascade._data import Record, Scaling, read_record, record_from_arrays, split_record

ORDERS = Orders(2, 2, 2, 2)
BRFD = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "brfd"


def _frame(n=500, seed=0, period=0.01):
    rng = np.random.default_rng(seed)
    return pd.DataFrame(
        {
            "t": np.arange(n) * period,
            "u": rng.uniform(-2.0, 2.0, n),
            "y": rng.standard_normal(n) + 3.0,
            "other": np.zeros(n),
        }
    )


def _write(frame, path):
    if str(path).endswith(".csv"):
        frame.to_csv(path, index=False)
    else:
        frame.to_parquet(path, index=False)
    return path


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip(tmp_path, suffix):
    frame = _frame()
    path = _write(frame, tmp_path / f"record{suffix}")
    record = read_record(path, "u", "y", time_column="t", scaling="none", orders=ORDERS)
    assert isinstance(record, Record)
    assert record.u.dtype == np.float64 and record.y.dtype == np.float64
    # CSV stores shortest round-trip repr: values come back exactly.
    np.testing.assert_array_equal(record.u, frame["u"].to_numpy())
    np.testing.assert_array_equal(record.y, frame["y"].to_numpy())
    np.testing.assert_array_equal(record.time, frame["t"].to_numpy())
    assert record.sample_period == pytest.approx(0.01, rel=1e-12)
    assert record.source == os.fspath(path)
    assert (record.input_column, record.output_column, record.time_column) == ("u", "y", "t")
    assert record.to_dict()["samples"] == 500


def test_standard_scaling_is_recorded_and_inverts(tmp_path):
    frame = _frame()
    path = _write(frame, tmp_path / "record.csv")
    record = read_record(path, "u", "y", scaling="standard")
    assert abs(record.u.mean()) < 1e-12 and record.u.std() == pytest.approx(1.0)
    assert abs(record.y.mean()) < 1e-12 and record.y.std() == pytest.approx(1.0)
    assert record.scaling.y_offset == pytest.approx(frame["y"].mean())
    np.testing.assert_allclose(record.u_physical, frame["u"], rtol=0, atol=1e-13)
    np.testing.assert_allclose(record.y_physical, frame["y"], rtol=0, atol=1e-13)
    # A validation record reuses the estimation record's scaling.
    other = _write(_frame(seed=1), tmp_path / "other.csv")
    again = read_record(other, "u", "y", scaling=record.scaling)
    assert again.scaling == record.scaling


def test_scaling_round_trip_and_physical_parameters():
    scaling = Scaling(u_offset=0.3, u_scale=0.05, y_offset=-1.2, y_scale=4.0, method="given")
    rng = np.random.default_rng(2)
    u, y = rng.standard_normal(100), rng.standard_normal(100)
    back = scaling.to_physical(*scaling.to_model(u, y))
    np.testing.assert_allclose(back[0], u, atol=1e-14)
    np.testing.assert_allclose(back[1], y, atol=1e-14)
    # The model fitted in model units, with the mapped parameters, is the same system in
    # physical units: y - y_offset = cascade_phys(u - u_offset). Checked by simulation.
    params = example(1).params(jnp.float64)
    u_model = rng.uniform(-2.0, 2.0, 400)
    y_model = np.asarray(simulate(params, jnp.asarray(u_model)))
    physical = scaling.params_to_physical(params.to_dict())
    assert physical["mR"] == params.to_dict()["mR"] and physical["a2"] == params.to_dict()["a2"]
    params_phys = type(params).from_dict(physical, params.orders)
    u_phys = scaling.input_to_physical(u_model)
    y_phys = np.asarray(simulate(params_phys, jnp.asarray(u_phys - scaling.u_offset)))
    np.testing.assert_allclose(y_phys + scaling.y_offset, scaling.output_to_physical(y_model))
    with pytest.raises(ValueError, match="Unknown parameter name 'zz'"):
        scaling.params_to_physical({"zz": 1.0})
    with pytest.raises(ValueError, match="u_scale must be positive"):
        Scaling(u_scale=0.0)


@pytest.mark.parametrize("anti_alias", ["fir", "iir"])
def test_decimation_shortens_and_filters(anti_alias):
    n, q = 4000, 4
    t = np.arange(n)
    slow = np.sin(2 * np.pi * 0.005 * t)
    fast = np.sin(2 * np.pi * 0.23 * t)  # above the new Nyquist frequency 0.125
    rng = np.random.default_rng(3)
    record = record_from_arrays(
        slow + fast,
        rng.standard_normal(n),
        time=t * 0.001,
        decimate=q,
        anti_alias=anti_alias,
        scaling="none",
    )
    assert len(record) == math.ceil(n / q) and record.y.shape == record.u.shape
    assert record.sample_period == pytest.approx(0.004)
    np.testing.assert_array_equal(record.time, t[::q] * 0.001)
    assert (record.decimation, record.anti_alias) == (q, anti_alias)
    # The fast component would alias to 0.08 cycles/sample under plain subsampling, with
    # amplitude 1; the filter removes it (stopband attenuation of both filters < 2%)
    # while the slow component passes. The last few samples keep some of the fast
    # component, as at any edge of a zero-phase filter; the start (where the fast
    # component is zero) shows that odd-symmetric padding keeps the level.
    aliased = (slow + fast)[::q] - slow[::q]
    assert np.max(np.abs(aliased)) > 0.9
    np.testing.assert_allclose(record.u[:-10], slow[::q][:-10], atol=0.03)


def test_split_sizes_and_scaling():
    rng = np.random.default_rng(4)
    record = record_from_arrays(rng.uniform(-1, 1, 1000), rng.standard_normal(1000))
    estimation, validation = split_record(record, 0.7)
    assert (len(estimation), len(validation)) == (700, 300)
    assert validation.start == 700 and estimation.scaling == validation.scaling
    np.testing.assert_array_equal(np.concatenate([estimation.u, validation.u]), record.u)
    first, second = record.split(250)
    assert (len(first), len(second)) == (250, 750)
    with pytest.raises(ValueError, match="strictly between 0 and 1"):
        split_record(record, 1.0)
    with pytest.raises(ValueError, match="between 1 and 999"):
        split_record(record, 1000)
    with pytest.raises(ValueError, match="fewer than the 120 that orders 2,2,2,2 need"):
        split_record(record, 20, orders=ORDERS)


# ---- every user error: one ValueError sentence, nothing written -----------------------------


def _csv(tmp_path, frame, name="bad.csv"):
    return _write(frame, tmp_path / name)


def _with(frame, column, rows, value):
    frame = frame.copy()
    frame[column] = frame[column].astype(object if isinstance(value, str) else float)
    frame.loc[rows, column] = value
    return frame


ERRORS = {
    "missing file": (
        lambda p: p / "nope.csv",
        {},
        r"does not exist",
    ),
    "unknown format": (
        lambda p: _write(_frame(), p / "record.csv").rename(p / "record.xlsx") or p / "record.xlsx",
        {},
        r"Unknown data format '\.xlsx'.*use a \.csv, \.tsv, \.txt, \.parquet or \.mat file",
    ),
    "missing columns": (
        lambda p: _csv(p, _frame()),
        {"input_column": "U", "output_column": "force"},
        r"Column\(s\) 'U', 'force' not found.*available columns are 't', 'u', 'y', 'other'"
        r" \(did you mean 'u' for 'U'\?\)",
    ),
    "missing time column": (
        lambda p: _csv(p, _frame()),
        {"time_column": "time_s"},
        r"'time_s' not found",
    ),
    "NaN": (
        lambda p: _csv(p, _with(_frame(), "y", [17, 30, 31], np.nan)),
        {},
        r"'y' in .* has 3 NaN or infinite values, the first at row 17",
    ),
    "inf": (
        lambda p: _csv(p, _with(_frame(), "u", [5], np.inf)),
        {},
        r"'u' in .* has 1 NaN or infinite values, the first at row 5",
    ),
    "non-numeric": (
        lambda p: _csv(p, _with(_frame(), "u", [9], "abc")),
        {},
        r"Column 'u' .* has 1 non-numeric values, the first at data row 9 \('abc'\)",
    ),
    "mismatched lengths": (
        lambda p: _csv(p, _with(_frame(), "y", list(range(490, 500)), np.nan)),
        {},
        r"different lengths \('u' has 500, 'y' has 490, 't' has 500 values\)",
    ),
    "too few samples": (
        lambda p: _csv(p, _frame(n=20)),
        {"orders": ORDERS},
        r"has 20 samples, fewer than the 120 that orders 2,2,2,2 need",
    ),
    "too few after decimation": (
        lambda p: _csv(p, _frame(n=500)),
        {"orders": ORDERS, "decimate": 20},
        r"has 25 samples after decimation by 20, fewer than the 120",
    ),
    "constant input": (
        lambda p: _csv(p, _with(_frame(), "u", slice(None), 1.5)),
        {},
        r"The input 'u' .* is constant \(1\.5 throughout\)",
    ),
    "constant output": (
        lambda p: _csv(p, _with(_frame(), "y", slice(None), 0.0)),
        {},
        r"The output 'y' .* is constant",
    ),
    "uneven time": (
        lambda p: _csv(p, _with(_frame(), "t", [100], 1.005)),
        {},
        r"not evenly sampled",
    ),
    "decreasing time": (
        lambda p: _csv(p, _with(_frame(), "t", [100], 0.0)),
        {},
        r"must increase strictly, but row 100 does not",
    ),
    "same column twice": (
        lambda p: _csv(p, _frame()),
        {"output_column": "u"},
        r"must be different",
    ),
    "bad decimation": (
        lambda p: _csv(p, _frame()),
        {"decimate": 0},
        r"Decimation factor must be an integer >= 1",
    ),
    "unreadable parquet": (
        lambda p: (p / "broken.parquet").write_text("not parquet") and p / "broken.parquet",
        {},
        r"Could not read .* as PARQUET",
    ),
}


@pytest.mark.parametrize("case", list(ERRORS))
def test_errors_are_one_clear_sentence_and_write_nothing(tmp_path, case):
    make, kwargs, message = ERRORS[case]
    path = make(tmp_path)
    kwargs = {"input_column": "u", "output_column": "y", "time_column": "t"} | kwargs
    if case == "missing time column":
        kwargs["time_column"] = "time_s"
    before = sorted(os.listdir(tmp_path))
    with pytest.raises(ValueError, match=message) as info:
        read_record(path, **kwargs)
    text = str(info.value)
    assert "\n" not in text and text.endswith(".")
    assert sorted(os.listdir(tmp_path)) == before


def test_array_errors():
    rng = np.random.default_rng(5)
    u, y = rng.standard_normal(100), rng.standard_normal(100)
    with pytest.raises(ValueError, match=r"lengths differ .*'u' has 100, 'y' has 99"):
        record_from_arrays(u, y[:99])
    with pytest.raises(ValueError, match=r"'y' in 'the arrays' has 1 NaN .* row 3"):
        record_from_arrays(u, np.where(np.arange(100) == 3, np.nan, y))
    with pytest.raises(ValueError, match=r"input 'u' in 'the arrays' is constant"):
        record_from_arrays(np.ones(100), y)
    with pytest.raises(ValueError, match="disagrees with the time column"):
        record_from_arrays(u, y, time=np.arange(100) * 0.1, sample_period=0.2)


@pytest.mark.skipif(
    not BRFD.is_dir(),
    reason=f"shared BRFD records not found at {BRFD} (they are not part of the repository)",
)
def test_reads_shared_brfd_records():
    files = sorted(BRFD.glob("*.csv"))
    assert files, f"no CSV files in {BRFD}"
    for path in files:
        record = read_record(
            path,
            "displacement_in",
            "force_kip",
            time_column="time_s",
            orders=ORDERS,
        )
        frame = pd.read_csv(path)
        assert len(record) == len(frame) > 5000
        assert 1.0 / record.sample_period == pytest.approx(1024.0, rel=1e-4)
        np.testing.assert_allclose(record.u_physical, frame["displacement_in"], atol=1e-12)
        decimated = read_record(
            path, "displacement_in", "force_kip", time_column="time_s", decimate=8
        )
        assert len(decimated) == math.ceil(len(frame) / 8)
        assert 1.0 / decimated.sample_period == pytest.approx(128.0, rel=1e-4)
