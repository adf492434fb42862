"""`benchmark_data` reads exactly what the official loader `nonlinear-benchmarks` reads:
every array, the sampling time and the state-initialisation window, compared with the
package itself run offline on the shared MAT files (EMPS, CED, Silverbox) and on synthetic
files in the layout of the two benchmarks not shared here (Cascaded_Tanks, WH)."""

import pathlib

import numpy as np
import pytest
import scipy.io

from jaxcascade import BENCHMARKS, benchmark_data

SHARED = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data" / "nonlinear_benchmarks"
needs_shared = pytest.mark.skipif(
    not SHARED.is_dir(), reason=f"the shared benchmark files are not at {SHARED}"
)

# The file `cashed_download` looks for in ROOT/NAME/ to skip the download: the zip's name,
# the last part of the URL when the loader names no zip (CED), the MAT file itself for WH.
MARKERS = {
    "EMPS": "EMPS.zip",
    "CED": "FULLTEXT01.zip",
    "Silverbox": "SilverboxFiles.zip",
    "Cascaded_Tanks": "CascadedTanksFiles.zip",
    "WienerHammerBenchMark": None,
}
SHARED_FILES = {
    "EMPS": ["EMPS/DATA_EMPS.mat", "EMPS/DATA_EMPS_PULSES.mat"],
    "CED": ["CED/DATAUNIF.MAT"],
    "Silverbox": ["Silverbox/SilverboxFiles/SNLS80mV.mat"],
}


@pytest.fixture
def official(monkeypatch):
    """The `nonlinear_benchmarks` module, with every download path made to fail loudly."""
    nlb = pytest.importorskip("nonlinear_benchmarks", reason="pip install nonlinear-benchmarks")
    from nonlinear_benchmarks import utilities

    def no_download(*args, **kwargs):
        raise AssertionError(f"the loader tried to download: {args}")

    monkeypatch.setattr(utilities, "download_file_from_google_drive", no_download)
    monkeypatch.setattr(utilities.urllib.request, "urlretrieve", no_download)
    return nlb


def layout(root: pathlib.Path, name: str, files: dict[str, pathlib.Path]) -> None:
    """The loader's download folder under `root`: the files linked in, plus its marker."""
    for relative, target in files.items():
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).symlink_to(target)
    if MARKERS[name]:
        (root / name / MARKERS[name]).touch()


def official_split(nlb, name: str, root: pathlib.Path):
    train, test = getattr(nlb, name)(dir_placement=str(root), always_return_tuples_of_datasets=True)
    return tuple(train), tuple(test)


def assert_same_as_loader(ours, train, test):
    assert len(ours.train) == len(train) and len(ours.test) == len(test)
    for mine, theirs in zip((*ours.train, *ours.test), (*train, *test), strict=True):
        assert mine.u.dtype == mine.y.dtype == np.float64 and mine.u.ndim == 1
        np.testing.assert_array_equal(mine.u, theirs.u)
        np.testing.assert_array_equal(mine.y, theirs.y)
    assert ours.sampling_time == train[0].sampling_time
    assert all(t.state_initialization_window_length == ours.n_init for t in test)


@needs_shared
@pytest.mark.parametrize("name", sorted(SHARED_FILES))
def test_shared_files_read_as_the_loader_reads_them(name, official, tmp_path):
    layout(tmp_path, name, {f: SHARED / f for f in SHARED_FILES[name]})
    train, test = official_split(official, name, tmp_path)
    ours = benchmark_data(name, SHARED)
    assert_same_as_loader(ours, train, test)
    for t in test:
        # EMPS: the loader takes t[1] - t[0] of each file, 1.0000241 ms for the training
        # file and 1.0000080 ms for the test file (noise on the stored times)
        assert t.sampling_time == pytest.approx(ours.sampling_time, rel=1e-4)


def synthetic(name: str, root: pathlib.Path) -> None:
    """A small MAT file with the variable names and shapes (column vectors) of the original."""
    rng = np.random.default_rng(0)
    if name == "Cascaded_Tanks":
        path = root / "Cascaded_Tanks/CascadedTanksFiles/dataBenchmark.mat"
        n = 1024
        data = {k: rng.uniform(0, 10, (n, 1)) for k in ("uEst", "yEst", "uVal", "yVal")}
        data["Ts"] = np.array([[4.0]])
    else:
        path = root / "WienerHammerBenchMark/WienerHammerBenchMark.mat"
        n = 188000  # the original's length: the split takes [5200:184000]
        data = {k: rng.standard_normal((n, 1)) for k in ("uBenchMark", "yBenchMark")}
        data["fs"] = np.array([[51200.0]])
    path.parent.mkdir(parents=True)
    scipy.io.savemat(path, data)
    if MARKERS[name]:
        (root / name / MARKERS[name]).touch()


@pytest.mark.parametrize("name", ["Cascaded_Tanks", "WienerHammerBenchMark"])
def test_synthetic_files_read_as_the_loader_reads_them(name, official, tmp_path):
    synthetic(name, tmp_path)
    train, test = official_split(official, name, tmp_path)
    ours = benchmark_data(name, tmp_path)
    assert_same_as_loader(ours, train, test)
    # the two rows issue 67 quotes (linear state space, polynomial NARX), no whole table
    assert set(ours.published) == {"test"}
    assert set(ours.published["test"]) == {"linear_state_space", "polynomial_narx"}
    assert ours.best_linear("test") == ours.published["test"]["linear_state_space"]


def test_wiener_hammerstein_split_and_sources(tmp_path):
    synthetic("WienerHammerBenchMark", tmp_path)
    wh = benchmark_data("WienerHammerBenchMark", tmp_path)
    assert [r.source for r in (*wh.train, *wh.test)] == [
        "WienerHammerBenchMark/WienerHammerBenchMark.mat:uBenchMark,yBenchMark[5200:105200]",
        "WienerHammerBenchMark/WienerHammerBenchMark.mat:uBenchMark,yBenchMark[105200:184000]",
    ]
    assert (wh.unit, wh.unit_factor, wh.sampling_time) == ("mV", 1000.0, 1 / 51200)


@needs_shared
def test_names_sources_units_and_published_baselines():
    ced = benchmark_data("CED", SHARED)
    assert [r.name for r in ced.train] == ["train 1", "train 2"]
    assert [r.name for r in ced.test] == ["test 1", "test 2"]
    assert [r.source for r in ced.test] == [
        "CED/DATAUNIF.MAT:u11,z11[400:500]",
        "CED/DATAUNIF.MAT:u12,z12[400:500]",
    ]
    assert ced.best_linear("test 1") == 0.224 and ced.best_linear("test 2") == 0.331
    sb = benchmark_data("Silverbox", SHARED)
    assert [r.name for r in sb.test] == ["multisine", "arrow full", "arrow no extrapolation"]
    assert [r.source.split(":", 1)[1] for r in (*sb.train, *sb.test)] == [
        "V1,V2[40650:105712]",
        "V1,V2[105712:127400]",
        "V1,V2[100:40575]",
        "V1,V2[100:32100]",
    ]
    emps = benchmark_data("EMPS", SHARED)
    assert emps.published["test"]["lstm"] == 74.1 and emps.best_linear("test") == 5.53
    assert set(emps.published["test"]) == set(ced.published["test 2"])
    # unit_factor puts y in the published unit: the test outputs' standard deviations of the
    # data's README (EMPS 82.6 mm; CED 0.422, 0.662; Silverbox 54.3, 53.4 mV), to its digits
    for bench, stds in ((emps, [82.6]), (ced, [0.422, 0.662]), (sb, [54.3, 53.4])):
        got = [np.std(r.y) * bench.unit_factor for r in bench.test[: len(stds)]]
        np.testing.assert_allclose(got, stds, rtol=2e-3)
    assert {emps.unit, ced.unit, sb.unit} == {"mm", "ticks/s", "mV"}


@needs_shared
def test_loader_versions_differ_in_the_windows_only():
    for name, old in (("CED", 4), ("EMPS", 20), ("Silverbox", 50)):
        new_split, old_split = (
            benchmark_data(name, SHARED),
            benchmark_data(name, SHARED, loader="1.0.0"),
        )
        assert old_split.n_init == old and old_split.loader == "1.0.0"
        for a, b in zip(new_split.test, old_split.test, strict=True):
            np.testing.assert_array_equal(a.y, b.y)
    assert benchmark_data("CED", SHARED).n_init == 10
    with pytest.raises(ValueError, match="loader version '2.0'.*1.0.1, 1.0.0"):
        benchmark_data("CED", SHARED, loader="2.0")


def test_errors_are_one_sentence_naming_what_to_do(tmp_path):
    with pytest.raises(ValueError) as error:
        benchmark_data("Silverbx", tmp_path)
    message = str(error.value)
    assert all(name in message for name in BENCHMARKS) and message.count(". ") == 0
    with pytest.raises(ValueError) as error:
        benchmark_data("CED", tmp_path)
    message = str(error.value)
    assert str(tmp_path / "CED" / "DATAUNIF.MAT") in message
    assert "nonlinearbenchmark.org" in message and "nonlinear-benchmarks" in message
    assert message.endswith(".") and message.count(". ") == 0


def test_mat_v73_and_wrong_variables_are_named(tmp_path):
    path = tmp_path / "CED" / "DATAUNIF.MAT"
    path.parent.mkdir()
    # the 128-byte header of an HDF5-based MAT v7.3 file: version 0x0200, little-endian
    path.write_bytes(b"MATLAB 7.3 MAT-file".ljust(116) + bytes(8) + b"\x00\x02IM" + bytes(64))
    with pytest.raises(ValueError, match="MAT v7.3"):
        benchmark_data("CED", tmp_path)
    scipy.io.savemat(path, {"u11": np.zeros((500, 1))})
    with pytest.raises(ValueError, match="no variable 'z11'.*holds u11"):
        benchmark_data("CED", tmp_path)


def test_records_are_read_only_copies(tmp_path):
    synthetic("Cascaded_Tanks", tmp_path)
    tanks = benchmark_data("Cascaded_Tanks", tmp_path)
    assert (tanks.n_init, tanks.unit, tanks.sampling_time) == (50, "V", 4.0)
    assert (
        tanks.test[0].source
        == "Cascaded_Tanks/CascadedTanksFiles/dataBenchmark.mat:uVal,yVal[0:1024]"
    )
    with pytest.raises(ValueError, match="read-only"):
        tanks.train[0].y[0] = 1.0
    assert benchmark_data("Cascaded_Tanks", tmp_path, loader="1.0.0").n_init == 5
