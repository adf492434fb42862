"""Every record under `../shared/data` read as `fit` and `loop` read it, by file and
signal names, with a range selected on the command line: no converter (issue 38).
Skipped where the shared data are absent (they are not part of the repository)."""

import pathlib

import numpy as np
import pandas as pd
import pytest
import scipy.io

from jaxcascade._cli import build_parser
from jaxcascade._cli._common import record_options
from jaxcascade._cli._loop import _settings
from jaxcascade._data import read_record
from jaxcascade._workflow._loop import _command_records

SHARED = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"
BENCH = SHARED / "nonlinear_benchmarks"

pytestmark = pytest.mark.skipif(not SHARED.is_dir(), reason=f"no shared data at {SHARED}")

# (file under SHARED, input, output, options): every record of every file
MAT = [
    ("nonlinear_benchmarks/CED/DATAUNIF.MAT", "u11", "z11", ["--ts", "0.02"]),
    ("nonlinear_benchmarks/CED/DATAUNIF.MAT", "u12", "z12", ["--ts", "0.02"]),
    *(
        ("nonlinear_benchmarks/CED/DATAPRBS.MAT", f"u{k}", f"z{k}", ["--ts", "0.02"])
        for k in (1, 2, 3)
    ),
    ("nonlinear_benchmarks/EMPS/DATA_EMPS.mat", "vir", "qm", ["--time", "t"]),
    ("nonlinear_benchmarks/EMPS/DATA_EMPS_PULSES.mat", "vir", "qm", ["--time", "t"]),
    *(
        (f"nonlinear_benchmarks/Silverbox/SilverboxFiles/{name}", "V1", "V2", ["--ts", "0.0016384"])
        for name in ("SNLS80mV.mat", "Schroeder80mV.mat")
    ),
]


def _tables():
    files = sorted((SHARED / "brfd").glob("*.csv"))
    files += sorted((SHARED / "brfd" / "characterization").glob("*.parquet"))
    return [str(p.relative_to(SHARED)) for p in files]


def _fit_reads(argv):
    """What `jaxcascade fit ARGV` reads (its record stage, nothing fitted)."""
    args = build_parser().parse_args(["fit", *argv])
    return read_record(args.data, **record_options(args), scaling=args.scaling)


@pytest.mark.parametrize(("name", "u", "y", "options"), MAT, ids=lambda v: str(v))
def test_every_shared_mat_record_is_read_by_spec(name, u, y, options):
    path = SHARED / name
    stored = scipy.io.loadmat(path)
    expected_u, expected_y = np.ravel(stored[u]), np.ravel(stored[y])
    stop = min(len(expected_u), 400)
    record = _fit_reads([f"{path}:{u},{y}:100:{stop}", *options, "--scaling", "none"])
    np.testing.assert_array_equal(record.u, expected_u[100:stop])
    np.testing.assert_array_equal(record.y, expected_y[100:stop])
    assert record.sample_period > 0


@pytest.mark.parametrize("name", _tables())
def test_every_shared_table_is_read_by_spec(name):
    path = SHARED / name
    frame = pd.read_csv(path) if path.suffix == ".csv" else pd.read_parquet(path)
    spec = f"{path}:displacement_in,force_kip:10:300"
    record = _fit_reads([spec, "--time", "time_s", "--scaling", "none"])
    np.testing.assert_array_equal(record.u, frame["displacement_in"].to_numpy()[10:300])
    np.testing.assert_array_equal(record.y, frame["force_kip"].to_numpy()[10:300])
    assert 1.0 / record.sample_period == pytest.approx(1024.0, rel=1e-3)


def test_the_loop_reads_records_of_several_files_and_formats_together():
    """Estimation records from a CSV and a Parquet file, a validation and a test record
    from CSV: one scaling, one period, by spec."""
    quake = SHARED / "brfd" / "earthquake_kocaeli_dbe.csv"
    harmonic = SHARED / "brfd" / "characterization" / "harmonic_1hz_30lb_1in.parquet"
    if not harmonic.exists():
        harmonic = sorted((SHARED / "brfd" / "characterization").glob("*.parquet"))[0]
    signals = "displacement_in,force_kip"
    argv = ["loop", f"{harmonic}:{signals}", f"{quake}:{signals}:0:4000"]
    argv += ["--validate", f"{quake}:{signals}:4000:6000", "--time", "time_s"]
    argv += ["--test", f"{quake}:{signals}:6000:8000"]
    settings = _settings(build_parser().parse_args(argv), None)
    training, validations, tests, _ = _command_records(settings)
    records = [*training, *validations, *tests]
    assert len({r.scaling for r in records}) == 1
    assert all(r.sample_period == pytest.approx(1 / 1024, rel=1e-3) for r in records)
    assert [len(r) for r in [*validations, *tests]] == [2000, 2000]
