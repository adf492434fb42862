"""Input designs (`_inputs`): scale, band, switching, file segments, the registry's
sentences, and the warning for a breakpoint the input never reaches."""

import jax
import numpy as np
import pandas as pd
import pytest

from jaxcascade._cli import main
from jaxcascade._experiment._inputs import DEFAULT_RMS, INPUTS, input_design
from jaxcascade._montecarlo._spec import InputRangeWarning, Spec
from jaxcascade._system._simulate import uniform_input

N = 512


def records(design, n=N, count=64, seed=0):
    keys = jax.random.split(jax.random.PRNGKey(seed), count)
    return np.asarray(jax.vmap(lambda k: design(k, n))(keys))


def test_uniform_is_the_papers_input_bit_for_bit():
    key = jax.random.PRNGKey(4)
    np.testing.assert_array_equal(input_design("uniform")(key, N), uniform_input(key, N, 2.0))
    assert input_design("uniform", rms=1.0).bound == pytest.approx(np.sqrt(3.0))


@pytest.mark.parametrize("name", ["uniform", "gaussian", "multisine", "multilevel"])
def test_every_kind_defaults_to_the_papers_input_power(name):
    u = records(input_design(name), count=200)
    # 200 x 512 samples: the power's relative SE is below 1 % for every kind
    assert np.sqrt(np.mean(u**2)) == pytest.approx(DEFAULT_RMS, rel=0.03)


def test_multisine_has_exactly_its_rms_and_only_lines_in_its_band():
    design = input_design("multisine", band=[0.2, 0.4], rms=1.5)
    u = records(design, count=4)
    np.testing.assert_allclose(np.sqrt(np.mean(u**2, axis=1)), 1.5, rtol=1e-12)
    spectrum = np.abs(np.fft.rfft(u, axis=1))
    lines = design.grid_lines(N)
    assert set(np.flatnonzero(spectrum[0] > 1e-9)) == set(lines)
    assert np.all((2 * lines / N >= 0.2) & (2 * lines / N <= 0.4))
    peaked = records(input_design("multisine", amplitude=2.0), count=4)
    np.testing.assert_allclose(np.max(np.abs(peaked), axis=1), 2.0, rtol=1e-12)
    assert len(input_design("multisine", lines=10).grid_lines(N)) == 10
    with pytest.raises(ValueError, match="no line"):
        input_design("multisine", band=[0.505, 0.51]).check(100)


def test_multilevel_switches_at_its_probability_and_binary_takes_two_levels():
    u = records(input_design("multilevel", levels=2, switch_probability=0.2), count=100)
    np.testing.assert_allclose(np.unique(u), [-DEFAULT_RMS, DEFAULT_RMS], rtol=1e-15)
    switches = np.mean(u[:, 1:] != u[:, :-1])
    assert switches == pytest.approx(0.2, abs=0.01)  # 51,000 Bernoulli draws: SE 0.002
    levels = records(input_design("multilevel", levels=5, amplitude=1.0), count=4)
    np.testing.assert_allclose(np.unique(levels), [-1.0, -0.5, 0.0, 0.5, 1.0], atol=1e-15)


@pytest.fixture
def csv_record(tmp_path):
    path = tmp_path / "record.csv"
    values = np.sin(np.arange(3000) / 37.0) + 0.3 * np.cos(np.arange(3000) / 5.0) + 4.0
    pd.DataFrame({"time": np.arange(3000), "x": values}).to_csv(path, index=False)
    return path, values


def test_file_input_takes_random_segments_of_the_scaled_record(csv_record):
    path, values = csv_record
    design = input_design("file", path=str(path), column="x", rms=2.0)
    centred = values - values.mean()
    scaled = 2.0 * centred / np.sqrt(np.mean(centred**2))
    np.testing.assert_allclose(design.record, scaled, rtol=1e-12)
    u = records(design, n=500, count=8)
    starts = set()
    for row in u:
        start = int(np.argmin(np.abs(scaled[: 3000 - 499] - row[0])))
        np.testing.assert_allclose(row, scaled[start : start + 500], rtol=1e-12)
        starts.add(start)
    assert len(starts) > 1
    whole = input_design("file", path=str(path), column="x", segment="whole")
    with pytest.raises(ValueError, match="N must be 3000"):
        whole.check(500)
    with pytest.raises(ValueError, match="longer than the record"):
        design.check(4000)
    each = records(input_design("file", path=str(path), column="x", normalise="segment"), 500, 4)
    np.testing.assert_allclose(np.sqrt(np.mean(each**2, axis=1)), DEFAULT_RMS, rtol=1e-12)
    with pytest.raises(ValueError, match="did you mean 'x'"):
        input_design("file", path=str(path), column="xx")


def test_a_changed_file_changes_the_cell_identity(csv_record):
    from jaxcascade._montecarlo._engine import cell_identity, run_chunk

    path, values = csv_record
    spec = Spec(example=1, n=300, input="file", input_settings={"path": str(path), "column": "x"})
    before = cell_identity(spec, spec.cells()[0])
    pd.DataFrame({"time": np.arange(3000), "x": values[::-1]}).to_csv(path, index=False)
    again = Spec(example=1, n=300, input="file", input_settings={"path": str(path), "column": "x"})
    assert cell_identity(again, again.cells()[0]) != before
    # the spec made before holds the old file's identity: it refuses to draw from the new
    with pytest.raises(ValueError, match="changed since the spec was made"):
        run_chunk(spec, spec.cells()[0], [0])


@pytest.mark.parametrize(
    ("name", "settings", "message"),
    [
        ("chirp", {}, "Unknown input kind 'chirp'"),
        ("gaussian", {"amplitude": 2.0}, "Unknown setting 'amplitude' for input 'gaussian'"),
        ("uniform", {"amplitude": 2.0, "rms": 1.0}, "not both"),
        ("multisine", {"band": [0.5, 0.2]}, "0 <= low < high <= 1"),
        ("multilevel", {"levels": 1}, "levels must be 0"),
        ("multilevel", {"switch_probability": 0.0}, "switch_probability must lie in (0, 1]"),
        ("file", {"column": "x"}, "needs path"),
    ],
)
def test_bad_settings_are_one_sentence(name, settings, message):
    with pytest.raises(ValueError) as error:
        input_design(name, **settings)
    assert message in str(error.value)


def test_every_kind_lists_its_settings_round_trip():
    for name in INPUTS:
        if name == "file":
            continue
        design = input_design(name)
        assert input_design(name, **design.settings()).settings() == design.settings()


def test_a_breakpoint_outside_the_input_warns(tmp_path, capsys):
    with pytest.warns(InputRangeWarning, match="DR1 = 1 lie outside"):
        Spec(example=1, n=300, amplitude=0.95)
    # The Gaussian input reaches about 3 std at N = 300; example 1's breakpoints are
    # inside at the paper's power
    Spec(example=1, n=300, input="gaussian")
    out = tmp_path / "w.parquet"
    argv = ["sweep", "--example", "1", "--n", "300", "--realisations", "2", "--chunk-size", "2"]
    assert main([*argv, "--amplitude", "0.95", "--out", str(out)]) == 0
    lines = capsys.readouterr().err.strip().splitlines()
    assert [line for line in lines if "warning" in line] == [
        line for line in lines if line.startswith("jaxcascade: warning: The true breakpoint(s)")
    ]


def test_distribution_is_the_old_name_of_kind_and_old_run_identities_still_match():
    import numpy as np

    from jaxcascade._montecarlo._run import _check_same, _identity

    old = {"example": 1, "n": [300], "input": {"distribution": "uniform", "amplitude": 2.0}}
    assert Spec.from_dict(old) == Spec(example=1, n=300)
    with pytest.raises(ValueError, match="kind and distribution"):
        Spec.from_dict({**old, "input": {"distribution": "uniform", "kind": "gaussian"}})
    # a partial run written before input designs and noise kinds: its stamp still matches
    spec = Spec(example=1, n=300)
    stored = {"spec": {**spec.to_dict(chunk_size=False), "input": old["input"]}}
    stored["spec"].pop("noise")
    stored["dtype"] = "float64"
    _check_same(stored, _identity(spec, np.float64), "stamp")
    with pytest.raises(ValueError, match="different spec"):
        _check_same(stored, _identity(Spec(example=1, n=300, noise="student_t"), np.float64), "x")
