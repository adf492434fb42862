"""Records as labs ship them (issue 38): MAT files (v4/v5, v7.3) holding several records,
CSV/TSV with any delimiter and a decimal comma, signals by name or 0-based index, the record
spec `FILE[:INPUT,OUTPUT[:START:STOP]]`, --ts, --units, --detrend and the check that the
records of one command share a sample period. Read through `read_record` and the CLI's
record stage (the shared benchmark files where present); one `fit` end to end."""

import json
import pathlib

import numpy as np
import pandas as pd
import pytest
import scipy.io
import scipy.signal

from jaxcascade._cli import build_parser, main
from jaxcascade._cli._common import record_options
from jaxcascade._data import check_sample_periods, parse_record_spec, read_record

SHARED = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"
BENCHMARKS = SHARED / "nonlinear_benchmarks"
CED = BENCHMARKS / "CED" / "DATAUNIF.MAT"
SILVERBOX = BENCHMARKS / "Silverbox" / "SilverboxFiles" / "SNLS80mV.mat"
needs_ced = pytest.mark.skipif(not CED.is_file(), reason=f"shared CED data not at {CED}")
needs_silverbox = pytest.mark.skipif(
    not SILVERBOX.is_file(), reason=f"shared Silverbox data not at {SILVERBOX}"
)


def _one_line_error(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def _signals(n=400, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-2.0, 2.0, n), rng.standard_normal(n) + 1.0


# ---- MAT files ---------------------------------------------------------------------------


@needs_ced
def test_ced_records_by_spec_with_ranges_match_loadmat():
    stored = scipy.io.loadmat(CED)
    for spec, (u, y), (first, last) in [
        (f"{CED}:u11,z11:0:400", ("u11", "z11"), (0, 400)),
        (f"{CED}:u12,z12:300:400", ("u12", "z12"), (300, 400)),
        (f"{CED}:u11,z11::300", ("u11", "z11"), (0, 300)),
        (f"{CED}:u12,z12:400:", ("u12", "z12"), (400, 500)),
        (f"{CED}:u12,z12:-100:", ("u12", "z12"), (400, 500)),
    ]:
        record = read_record(spec, scaling="none")
        np.testing.assert_array_equal(record.u, stored[u][first:last, 0])
        np.testing.assert_array_equal(record.y, stored[y][first:last, 0])
        assert (record.input_column, record.output_column) == (u, y)
        # the source names the samples used, the range resolved
        assert record.source == f"{CED}:{u},{y}:{first}:{last}"
        assert record.file_start == first and record.sample_period is None
    # the spec's signals override the options; without a range the whole record
    record = read_record(f"{CED}:u12,z12", "u11", "z11", scaling="none")
    np.testing.assert_array_equal(record.u, stored["u12"][:, 0])
    assert record.source == f"{CED}:u12,z12"
    # a plain file with the signals as options: the source is the file, as before
    assert read_record(CED, "u11", "z11", scaling="none").source == str(CED)


@needs_silverbox
def test_silverbox_row_vectors():
    stored = scipy.io.loadmat(SILVERBOX)
    assert stored["V1"].shape == (1, 131072)
    record = read_record(f"{SILVERBOX}:V1,V2:40000:42000", sample_period=1 / 610.35)
    np.testing.assert_allclose(record.u_physical, stored["V1"][0, 40000:42000], rtol=1e-12)
    np.testing.assert_allclose(record.y_physical, stored["V2"][0, 40000:42000], rtol=1e-12)
    assert len(record) == 2000 and record.sample_period == pytest.approx(1 / 610.35)


def test_matrix_and_non_numeric_variables_are_one_sentence(tmp_path):
    u, y = _signals()
    path = tmp_path / "lab.mat"
    scipy.io.savemat(path, {"u": u, "y": y, "both": np.stack([u, y], 1), "note": "run 3"})
    with pytest.raises(ValueError, match=r"'both' .* is a 400 x 2 matrix, not one signal"):
        read_record(f"{path}:both,y")
    with pytest.raises(ValueError, match=r"'note' .* is a MATLAB char, not numbers"):
        read_record(f"{path}:u,note")
    with pytest.raises(ValueError, match=r"available variables are 'u', 'y', 'both', 'note'\.$"):
        read_record(f"{path}:0,1")  # a MAT file names its signals by variable


def _write_v73(path, variables):
    """A MATLAB v7.3 file as MATLAB writes one: a 128-byte text header in a 512-byte
    user block, then HDF5 with each array transposed (column-major) and its class."""
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w", userblock_size=512) as file:
        for name, value in variables.items():
            data = file.create_dataset(name, data=np.atleast_2d(value))  # N -> 1 x N: a column
            data.attrs["MATLAB_class"] = np.bytes_("double")
        file.create_group("#refs#")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: jaxcascade tests HDF5 schema"
    with open(path, "r+b") as file:
        file.write(header.ljust(124) + b"\x00\x02IM")


def test_v73_mat_file_through_h5py(tmp_path, monkeypatch):
    import sys

    u, y = _signals()
    path = tmp_path / "v73.mat"
    _write_v73(path, {"u1": u, "y1": y, "grid": np.ones((3, 4))})
    record = read_record(f"{path}:u1,y1:100:300", scaling="none")
    np.testing.assert_array_equal(record.u, u[100:300])
    np.testing.assert_array_equal(record.y, y[100:300])
    with pytest.raises(ValueError, match=r"'u2' not found .*variables are 'grid', 'u1', 'y1'"):
        read_record(f"{path}:u2,y1")
    with pytest.raises(ValueError, match=r"'grid' .* is a 4 x 3 matrix"):
        read_record(f"{path}:grid,y1")
    monkeypatch.setitem(sys.modules, "h5py", None)  # as if h5py were not installed
    with pytest.raises(ValueError, match=r"is a MATLAB v7\.3 \(HDF5\) file, which needs the h5py"):
        read_record(f"{path}:u1,y1")


# ---- text and Parquet ----------------------------------------------------------------------


def test_tsv_and_semicolon_files_with_a_decimal_comma(tmp_path):
    u, y = np.round(_signals(), 6)
    lines = [f"{a:.6f}\t{b:.6f}".replace(".", ",") for a, b in zip(u, y, strict=True)]
    tsv = tmp_path / "lab.tsv"
    tsv.write_text("input\toutput\n" + "\n".join(lines) + "\n")
    record = read_record(tsv, "input", "output", scaling="none")
    np.testing.assert_allclose(record.u, u, rtol=0, atol=1e-12)
    np.testing.assert_allclose(record.y, y, rtol=0, atol=1e-12)
    semicolons = tmp_path / "lab.csv"
    semicolons.write_text("u;y\n" + "\n".join(line.replace("\t", ";") for line in lines))
    record = read_record(f"{semicolons}:u,y:10:20", scaling="none")
    np.testing.assert_allclose(record.y, y[10:20], rtol=0, atol=1e-12)


def test_csv_by_column_index_and_headerless_text(tmp_path):
    u, y = _signals()
    path = tmp_path / "r.csv"
    pd.DataFrame({"t": np.arange(400) * 0.01, "u": u, "y": y}).to_csv(path, index=False)
    record = read_record(f"{path}:1,2", time_column=0, scaling="none")
    np.testing.assert_array_equal(record.u, u)
    assert (record.input_column, record.output_column, record.time_column) == ("u", "y", "t")
    assert record.sample_period == pytest.approx(0.01)
    with pytest.raises(ValueError, match=r"'5' not found .*or their 0-based indices 0 to 2\.$"):
        read_record(f"{path}:1,5")
    # whitespace-separated numbers without a header: columns by index only
    text = tmp_path / "plain.txt"
    text.write_text("".join(f"  {a:.17g}   {b:.17g}\n" for a, b in zip(u, y, strict=True)))
    record = read_record(f"{text}:0,1:0:50", scaling="none")
    np.testing.assert_array_equal(record.y, y[:50])


def test_parquet_by_name_and_index(tmp_path):
    u, y = _signals()
    path = tmp_path / "r.parquet"
    pd.DataFrame({"u": u, "y": y}).to_parquet(path, index=False)
    record = read_record(f"{path}:0,y:-50:", scaling="none")
    np.testing.assert_array_equal(record.u, u[-50:])
    assert record.source == f"{path}:u,y:350:400"


# ---- the record spec -----------------------------------------------------------------------


def test_spec_parsing_and_a_path_that_holds_a_colon(tmp_path):
    u, y = _signals()

    def parts(text):
        spec = parse_record_spec(text)
        return spec.path, spec.input, spec.output, spec.start, spec.stop, spec.ranged

    assert parts("a.mat:u,y:0:300") == ("a.mat", "u", "y", 0, 300, True)
    assert parts("a.mat:u,y::300") == ("a.mat", "u", "y", None, 300, True)
    assert parts("a.mat:u,y") == ("a.mat", "u", "y", None, None, False)
    assert parts("a.mat") == ("a.mat", None, None, None, None, False)
    # a path that exists as given is a file, even with ':' in its name
    odd = tmp_path / "run:3,4:0:10.csv"
    pd.DataFrame({"u": u, "y": y}).to_csv(odd, index=False)
    assert parse_record_spec(str(odd)).path == str(odd)
    record = read_record(str(odd), "u", "y", scaling="none")
    assert len(record) == 400
    record = read_record(f"{odd}:u,y:0:100", scaling="none")
    assert len(record) == 100 and record.source == f"{odd}:u,y:0:100"
    # FILE::START:STOP takes the signals from the options
    assert len(read_record(f"{odd}::100:", "u", "y")) == 300


@pytest.mark.parametrize(
    "suffix, message",
    [
        (":u,y:0:500", r"range 0:500 of .* lies outside the record, .* hold 400 samples"),
        (":u,y:-500:", r"range -500: of .* lies outside the record"),
        (":u,y:300:200", r"range 300:200 of .* holds no samples; STOP must exceed START\."),
        (":u,y:5:5", r"holds no samples"),
        (":u,y:a:5", r"has the range 'a:5'; give START:STOP"),
        (":u,y:0:5:9", r"has the range '0:5:9'; give START:STOP"),
        (":u,y:0", r"has the range '0'; give START:STOP"),
        (":u", r"names its signals as 'u'; give two, INPUT,OUTPUT"),
        (":u,y,t", r"names its signals as 'u,y,t'"),
        ("", r"No input and output signals named for .*; name them in the record spec"),
    ],
)
def test_spec_errors_are_one_sentence(tmp_path, suffix, message):
    u, y = _signals()
    path = tmp_path / "r.csv"
    pd.DataFrame({"u": u, "y": y}).to_csv(path, index=False)
    with pytest.raises(ValueError, match=message) as info:
        read_record(f"{path}{suffix}")
    assert "\n" not in str(info.value) and str(info.value).endswith(".")


# ---- options: --ts, --units, --detrend --------------------------------------------------------


def _record_stage(argv):
    """What `fit` reads for `argv`: its record options through `read_record`."""
    args = build_parser().parse_args(["fit", *argv])
    return read_record(args.data, **record_options(args), scaling=args.scaling)


@needs_ced
def test_ts_units_and_detrend_options():
    stored = scipy.io.loadmat(CED)
    spec = f"{CED}:u11,z11:100:400"
    record = _record_stage([spec, "--ts", "0.02", "--units", "V,V"])
    assert record.sample_period == 0.02 and (record.input_unit, record.output_unit) == ("V", "V")
    assert record.to_dict()["output_unit"] == "V" and record.detrend == "none"
    assert _record_stage([spec]).input_unit is None
    assert _record_stage([spec, "--ts", "0.02", "--decimate", "2"]).sample_period == 0.04
    u, y = stored["u11"][100:400, 0], stored["z11"][100:400, 0]
    for option, kind in (("mean", "constant"), ("linear", "linear")):
        # in the file's units (the measured-data default `--scaling auto` would scale them)
        record = _record_stage([spec, "--detrend", option, "--scaling", "none"])
        # scipy's detrend is MATLAB's; the two agree to rounding
        np.testing.assert_allclose(record.u, scipy.signal.detrend(u, type=kind), atol=1e-12)
        np.testing.assert_allclose(record.y, scipy.signal.detrend(y, type=kind), atol=1e-12)
        assert record.detrend == option
    assert abs(_record_stage([spec, "--detrend", "mean"]).y.mean()) < 1e-12


def test_ts_against_a_time_column_and_bad_options(capsys, tmp_path):
    u, y = _signals()
    path = tmp_path / "r.csv"
    pd.DataFrame({"t": np.arange(400) * 0.01, "u": u, "y": y}).to_csv(path, index=False)
    base = ["fit", str(path), "--input", "u", "--output", "y", "--time", "t"]
    assert _record_stage(base[1:] + ["--ts", "0.01005"]).sample_period == pytest.approx(0.01)
    err = _one_line_error(capsys, [*base, "--ts", "0.02"])
    assert "Sample period 0.02 disagrees with the time column's step 0.01" in err
    err = _one_line_error(capsys, [*base, "--units", "V"])
    assert "--units takes INPUT_UNIT,OUTPUT_UNIT, got 'V'." in err
    err = _one_line_error(capsys, [*base, "--ts", "-1"])
    assert "--ts must be a positive number of seconds" in err


# ---- the command line -----------------------------------------------------------------------


def test_mismatched_sample_periods_are_refused(capsys, tmp_path):
    u, y = _signals()
    paths = []
    for period in (0.01, 0.01, 0.02):
        path = tmp_path / f"r{len(paths)}.csv"
        pd.DataFrame({"t": np.arange(400) * period, "u": u, "y": y}).to_csv(path, index=False)
        paths.append(str(path))
    argv = ["loop", paths[0], "--validate", paths[1], "--test", paths[2], "--time", "t"]
    err = _one_line_error(capsys, [*argv, "--input", "u", "--output", "y"])
    assert f"'{paths[0]}' (sample period 0.01) and '{paths[2]}' (sample period 0.02)" in err
    assert "must share a sample period" in err
    # records without a period are not compared; 1 % apart is the same period
    a = read_record(paths[0], "u", "y")
    check_sample_periods([a, read_record(paths[0], "u", "y", time_column="t")])
    check_sample_periods([a, read_record(paths[0], "u", "y", sample_period=0.01)])


@needs_ced
def test_loop_reads_ced_by_specs_without_input_and_output(capsys):
    from jaxcascade._cli._loop import _settings
    from jaxcascade._workflow._loop import _command_records

    def spec(signals, span):
        return f"{CED}:{signals}:{span}"

    argv = ["loop", spec("u11,z11", "0:400"), spec("u12,z12", "0:300")]
    argv += ["--validate", spec("u12,z12", "300:400")]
    argv += ["--test", spec("u11,z11", "400:500"), spec("u12,z12", "400:500"), "--ts", "0.02"]
    argv += ["--validate", spec("u11,z11", "400:500")]  # a second validation record
    settings = _settings(build_parser().parse_args(argv), None)
    training, validations, tests, _ = _command_records(settings)
    assert [len(r) for r in training] == [400, 300] and [len(v) for v in validations] == [
        100,
        100,
    ]
    validation = validations[0]
    assert [r.source for r in tests] == [spec("u11,z11", "400:500"), spec("u12,z12", "400:500")]
    assert all(r.sample_period == 0.02 for r in [*training, validation, *tests])
    # one scaling, the estimation records' together
    stored = scipy.io.loadmat(CED)
    estimation = np.concatenate([stored["u11"][:400, 0], stored["u12"][:300, 0]])
    assert training[1].scaling == validation.scaling == tests[0].scaling
    np.testing.assert_allclose(training[0].scaling.u_scale, np.std(estimation))
    # a record spec without signals still needs --input and --output
    err = _one_line_error(capsys, ["loop", str(CED), "--validate", spec("u12,z12", "300:")])
    assert "loop needs --input, --output" in err


@needs_ced
def test_unknown_variable_is_one_line_listing_the_variables(capsys):
    err = _one_line_error(capsys, ["fit", f"{CED}:u13,z11:0:300"])
    assert "'u13' not found" in err and "available variables are 'u11', 'u12', 'z11', 'z12'" in err
    err = _one_line_error(capsys, ["fit", str(CED), "--input", "u11", "--output", "z13"])
    assert "(did you mean 'z12' for 'z13'?)" in err


def test_fit_on_a_range_of_a_mat_file(capsys, tmp_path):
    # the one whole fit here (literal, ~15 s): Example 1 stored as a MATLAB row and column
    # behind 500 samples of another experiment, read by spec; the estimates match the
    # truth only if the range picked exactly the recorded samples
    import jax

    import jaxcascade as jc

    ex = jc.example(1)
    key_u, key_e = jax.random.split(jax.random.PRNGKey(0))
    u = jc.uniform_input(key_u, 1500)
    y = np.asarray(jc.measure(key_e, ex.params(), u, 50.0)[0])
    other_u, other_y = _signals(500, seed=7)
    path = tmp_path / "lab.mat"
    uu = np.concatenate([other_u, np.asarray(u)])[None, :]  # a 1 x 2000 row
    yy = np.concatenate([other_y, y])[:, None]  # a 2000 x 1 column
    scipy.io.savemat(path, {"uu": uu, "yy": yy})
    argv = ["fit", f"{path}:uu,yy:500:", "--ts", "0.001", "--estimator", "literal", "--json"]
    argv += ["--scaling", "none"]  # the paper's units, where the paper's iteration starts
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["status"] in ("converged", "cycled") and result["nrmse"] < 1.3 / 50
    truth = ex.params().to_dict()
    assert max(abs(result["model"]["estimates"][k] - v) for k, v in truth.items()) < 0.05
