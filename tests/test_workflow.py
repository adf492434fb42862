"""Every measured-data command as one Python call (issue 68): `fit_record`,
`loop_records`, `simulate_model`; the model schema in the record's units, the same in the
results, the command's JSON and the model file; a model file of format version 1 still
loads."""

import dataclasses
import json
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

import jaxcascade as jc
from jaxcascade._cli import main
from jaxcascade._json import strict_json

DATA = pathlib.Path(__file__).parent / "data"


def _physical_truth(u_scale: float, y_scale: float) -> jc.CascadeParams:
    """Example 1 written in a record's units where the input is `u_scale` times and the
    output `y_scale` times the paper's: NS slopes times y_scale / u_scale, breakpoints
    times u_scale, the backlash gaps times y_scale (x is in the output's units), the
    linear block and mR unchanged (written out here, not through `Scaling`)."""
    p = jc.example(1).params()
    return dataclasses.replace(
        p,
        MR=p.MR * y_scale / u_scale,
        ML=p.ML * y_scale / u_scale,
        DR=p.DR * u_scale,
        DL=p.DL * u_scale,
        cL=p.cL * y_scale,
        cR=p.cR * y_scale,
    )


@pytest.mark.parametrize(
    ("u_offset", "u_scale", "y_offset", "y_scale"),
    [(0.0, 250.0, 0.0, 0.004), (40.0, 250.0, -3.0, 0.004)],
    ids=["scale", "offset"],
)
def test_fit_record_returns_the_truth_in_the_record_s_units(u_offset, u_scale, y_offset, y_scale):
    """A noise-free record far from unit scale (input in the hundreds, output in the
    thousandths), with and without offsets: `fit_record` returns the system's parameters
    in the record's units, the schema the same in `to_dict`, and the model units beside."""
    truth = _physical_truth(u_scale, y_scale)
    u_model = np.asarray(jc.uniform_input(jax.random.PRNGKey(3), 1500))
    u = u_offset + u_scale * (u_model - u_model.mean())  # the input's mean is its offset
    y = y_offset + np.asarray(jc.simulate(truth, jnp.asarray(u - u_offset)))
    if u_offset:
        # an offset and an output whose level is not the mean: the scaling is given, as a
        # lab would give its operating point (`auto` would centre on the output's mean)
        scaling = jc.Scaling(u_offset, u_scale / 2, y_offset, 2 * y_scale, "given")
    else:
        scaling = "auto"  # the input crosses zero: scaled, not centred
    result = jc.fit_record(u, y, sample_period=0.01, scaling=scaling, input_unit="V")
    assert result.status.name == "converged" and not result.warnings and not result.failed
    assert result.nrmse < 1e-6
    expected = truth.to_dict()
    assert set(result.estimates) == set(expected)
    for name, value in expected.items():
        assert result.estimates[name] == pytest.approx(value, rel=1e-5, abs=1e-9 * abs(value)), name
    # the model units differ from the record's where the scale is far from 1
    assert result.estimates_model_units["DR1"] != pytest.approx(expected["DR1"], rel=0.1)
    out = result.to_dict()
    assert out["model"]["estimates"] == result.estimates
    assert out["model"]["std_errors"] == result.std_errors
    assert all(e >= 0 for e in result.std_errors.values())
    assert json.loads(strict_json(out))["model"]["orders"]["degree"] == 1
    text = repr(result)
    assert text.startswith("FitResult(robust: converged") and len(text) < 200


def test_fit_record_takes_records_and_says_what_it_cannot_determine():
    # Example 1's breakpoints outside the input's range (test_cli's record): the status
    # stays the estimator's, the warning names the parameters, `failed` is not set
    ex = jc.example(1)
    key_u, key_e = jax.random.split(jax.random.PRNGKey(0))
    u = jc.uniform_input(key_u, 1500, 0.8)
    y, _ = jc.measure(key_e, ex.params(), u, 50.0)
    record = jc.record_from_arrays(np.asarray(u), np.asarray(y), scaling="none")
    result = jc.fit_record(record)
    assert result.status.name == "on_edge" and not result.failed
    assert {"DR1", "DL1"} <= set(result.not_identifiable)
    (warning,) = result.warnings
    assert warning.startswith("not identifiable from this record: ")
    assert "not identifiable from this record" in result.message
    with pytest.raises(TypeError, match="give no y"):
        jc.fit_record(record, np.asarray(y))


def test_the_schema_writes_curved_branches_one_way_in_the_record_s_units():
    """A final model with the curved backlash effect: orders of degree 3, the terms as
    the cascade's mL2.., mR2.. (never curveL), in the records' units such that the
    cascade at degree 3 with the schema's estimates, simulated in the records' units,
    is the saved model's simulation."""
    from jaxcascade._measured._effects import ExtendedModel
    from jaxcascade._measured._effects._curved import CurvedBacklash
    from jaxcascade._measured._model_file import SavedModel

    params = jc.example(1).params()
    curved = CurvedBacklash(jnp.asarray([-0.05, 0.02]), jnp.asarray([0.04, -0.01]))
    model = ExtendedModel(params, (curved,), jc.ARNoise(jnp.asarray([])))
    scaling = jc.Scaling(0.0, 3.0, 0.0, 0.2, "scale")
    saved = SavedModel(model, scaling=scaling)
    schema = saved.to_dict()["model"]
    assert schema["orders"]["degree"] == 3
    assert list(schema["estimates"])[-4:] == ["mL2", "mL3", "mR2", "mR3"]
    assert schema["effects"][0]["name"] == "general_backlash"
    assert set(schema["effects"][0]["parameters_model_units"]) == {"mL2", "mL3", "mR2", "mR3"}
    assert "curveL" not in json.dumps(schema)
    orders = jc.Orders(**schema["orders"])
    physical = jc.CascadeParams.from_dict(schema["estimates"], orders)
    u = 3.0 * np.asarray(jc.uniform_input(jax.random.PRNGKey(1), 300))
    np.testing.assert_allclose(
        np.asarray(jc.simulate(physical, jnp.asarray(u))), saved.simulate(u), rtol=1e-9, atol=1e-12
    )


def test_a_model_file_of_format_version_1_still_loads():
    """`tests/data/model_format_1_ced.json`: the model file `jaxcascade loop --benchmark
    CED` wrote before the schema (format version 1; its curved backlash under the
    effect's own field names, curveL and curveR). It loads, simulates as the model its
    numbers describe, and is written again in the schema (version 2)."""
    from jaxcascade._measured._effects import ExtendedModel
    from jaxcascade._measured._effects._curved import CurvedBacklash

    path = DATA / "model_format_1_ced.json"
    old = json.loads(path.read_text())
    assert old["format_version"] == 1
    saved = jc.load_model(path)
    assert saved.model.structure() == old["structure"]
    by_hand = ExtendedModel(
        jc.CascadeParams.from_dict(old["model"]["parameters"], jc.Orders()),
        (
            CurvedBacklash(
                *(jnp.asarray(v) for v in old["model"]["effects"][0]["parameters"].values())
            ),
        ),
        jc.ARNoise(jnp.asarray([])),
    )
    u = np.linspace(-2.0, 3.0, 200)
    direct = saved.scaling.output_to_physical(
        jc.simulate_extended(by_hand, jnp.asarray(saved.scaling.input_to_model(u)))
    )
    np.testing.assert_allclose(saved.simulate(u), direct, rtol=1e-12, atol=1e-12)
    new = saved.to_dict()
    assert new["format_version"] == 2
    curve = old["model"]["effects"][0]["parameters"]
    values = new["model"]["estimates_model_units"]
    assert [values[n] for n in ("mL2", "mL3")] == curve["curveL"]
    assert [values[n] for n in ("mR2", "mR3")] == curve["curveR"]
    assert new["model"]["orders"]["degree"] == 3


def test_model_error_loop_takes_records_with_the_command_s_defaults(tmp_path):
    """Records in place of arrays (issue 68: an `IndexError` before): their scaling goes
    into the result's schema; the default window is the command's (50, at most a quarter
    of the validation record); a short `repr`."""
    ex = jc.example(1)
    records = []
    for seed in (1, 2):
        u = np.asarray(jc.uniform_input(jax.random.PRNGKey(seed), 400))
        y = np.asarray(jc.simulate(ex.params(), jnp.asarray(u)))
        y = 0.01 * y + 1e-4 * np.random.default_rng(seed).normal(size=u.shape)
        records.append((100.0 * u, y))
    train = jc.record_from_arrays(*records[0], sample_period=0.1)
    valid = jc.record_from_arrays(*records[1], sample_period=0.1, scaling=train.scaling)
    # the declared cascade given, in model units (its robust fit is fit_record's, tested
    # above): the truth in the records' units mapped by the scaling's factors
    truth = _physical_truth(100.0, 0.01).to_dict()
    factor = train.scaling.params_to_physical({name: 1.0 for name in truth})
    base = jc.CascadeParams.from_dict({k: v / factor[k] for k, v in truth.items()}, jc.Orders())
    result = jc.model_error_loop(train, valid, max_effects=0, base=base)
    report = result.to_dict()
    assert report["model_after"]["scaling"] == train.scaling.to_dict()
    estimates = report["model_after"]["estimates"]
    assert all(estimates[k] == pytest.approx(v, rel=1e-12) for k, v in truth.items())
    assert result.after.error < 0.1 and result.warnings == []
    text = repr(result)
    assert text.startswith("LoopResult('u -> pwl(2,2)") and len(text) < 300
    # the worse-than-the-mean warning the command prints, on the result itself
    worse = dataclasses.replace(result, after=dataclasses.replace(result.after, error=1.165))
    (warning,) = worse.warnings
    assert "worse than the mean of the output" in warning and "1.165" in warning


def test_loop_records_is_the_command(tmp_path, capsys):
    """`loop_records` on records gives the command's JSON and its report folder."""
    ex = jc.example(1)
    paths = []
    for seed in (1, 2, 3):
        u = jc.uniform_input(jax.random.PRNGKey(seed), 500)
        y = jc.simulate(ex.params(), u) + 0.02 * jax.random.normal(
            jax.random.PRNGKey(9 + seed), (500,)
        )
        path = tmp_path / f"r{seed}.csv"
        pd.DataFrame({"u": np.asarray(u), "y": np.asarray(y)}).to_csv(path, index=False)
        paths.append(str(path))
    argv = ["loop", paths[0], "--validate", paths[1], "--test", paths[2], "--input", "u"]
    argv += ["--output", "y", "--max-effects", "0", "--json", "--quiet", "--threads", "1"]
    assert main(argv) == 0
    command = json.loads(capsys.readouterr().out)
    train, valid, test = (jc.read_record(p, "u", "y") for p in paths)
    valid = jc.read_record(paths[1], "u", "y", scaling=train.scaling)
    test = jc.read_record(paths[2], "u", "y", scaling=train.scaling)
    run = jc.loop_records(train, valid, test, max_effects=0, threads=1)
    brief = json.loads(strict_json(run.to_dict(brief=True)))
    command.pop("programs_compiled"), brief.pop("programs_compiled")
    assert brief == command
    assert run.warnings == command["verdict"] == []
    text = repr(run)
    assert text.startswith("LoopRun(") and "test r3.csv NRMSE" in text and len(text) < 300
    folder = run.report(tmp_path / "report", figures=False)
    names = {p.name for p in folder.iterdir()}
    assert {"report.json", "report.md", "scores.csv", "candidates.csv", "model.json"} <= names
    saved = json.loads((folder / "model.json").read_text())
    assert saved["model"]["estimates"] == pytest.approx(command["model_after"]["estimates"])
    # the saved model applied to the test record gives the run's test figures
    simulation = jc.simulate_model(folder / "model.json", paths[2])
    (row,) = simulation.to_dict()["records"]
    assert row["error"] == pytest.approx(command["test"][0]["error"], rel=1e-9)
    assert repr(simulation).startswith("Simulation(")


def _effect_examples():
    """One instance of every effect in `EFFECTS` with fields (model units), values that
    keep Example 1's cascade with the effect stable on a uniform input."""
    from jaxcascade._measured import _effects as E

    a = jnp.asarray
    return {
        "output_offset": E.OutputOffset(a(0.3)),
        "input_delay": E.InputDelay(a(2.0)),
        "output_saturation": E.OutputSaturation(a(-0.4), a(0.5)),
        "output_drift": E.OutputDrift(a(0.4)),
        "output_feedthrough": E.OutputFeedthrough(a(-0.5)),
        "slack_friction": E.SlackFriction(a(0.2), a(0.3), a(0.5), a(-0.4)),
        "backlash_friction": E.BacklashFriction(a(0.1), a(2.0), a(0.3), a(0.2), a(0.1)),
        "backlash_friction_contacts": E.BacklashFrictionContacts(
            a(0.1), a(2.0), a(0.3), a(0.2), a(0.1)
        ),
        "prandtl_ishlinskii": E.PrandtlIshlinskii(
            a([0.1, 0.3]), a([0.5, 0.9]), a(np.linspace(-0.3, 0.4, 10)), a(0.1)
        ),
        "dahl_friction": E.DahlFriction(a(3.0), a(0.4)),
        "input_backlash": E.InputBacklash(a(0.1)),
        "general_backlash": E.CurvedBacklash(a([-0.05, 0.02]), a([0.04, -0.01])),
        "nonlinear_feedback": E.NonlinearFeedback(a([0.05, -0.02])),
        "direct_term": E.DirectTerm(a([0.3])),
        "velocity_friction": E.VelocityFriction(a([0.05, 0.08])),
        "output_polynomial": E.OutputPolynomial(a([0.1, 0.2, -0.05])),
        # the fold below the output's range: the smoothing EPS (model units) is then
        # immaterial in either units
        "output_fold": E.OutputFold(a([0.1, 1.0, 0.1, -20.0])),
        "output_dynamics": E.OutputDynamics(a([0.2, 0.1]), a([-0.5, 0.0625]), a(0.1)),
        "inner_polynomial": E.InnerPolynomial(a([0.1, 0.2, -0.05])),
        "inner_kink": E.InnerKink(a([0.1, 0.5, 20.0])),
    }


def test_every_effect_declares_the_unit_of_every_field():
    """`Effect.units` names a known kind for each field of every effect in `EFFECTS`
    (a new effect cannot forget), and nothing else; `_effect_examples` covers them."""
    from jaxcascade._measured._effects import EFFECTS
    from jaxcascade._measured._effects._units import element_kinds, valid_kind

    examples = _effect_examples()
    for name, kind in EFFECTS.items():
        fields = {f.name for f in dataclasses.fields(kind)}
        assert set(kind.units) == fields, name
        for field, unit in kind.units.items():
            units = unit if isinstance(unit, tuple) else (unit,)
            assert all(valid_kind(u) for u in units), (name, field, unit)
        if fields:
            effect = examples[name]
            for field in fields:
                size = int(np.size(getattr(effect, field)))
                assert len(element_kinds(kind.units[field], size)) == size, (name, field)


def test_every_effect_s_fields_in_the_record_s_units_give_the_record_s_output():
    """With only scales (no offsets), far from 1: Example 1 with one effect, its cascade
    and the effect's fields written in the records' units by the schema (`estimates`,
    the effect's `parameters`), simulated on the record's input, is the model's output
    in model units times y_scale; for every effect of `EFFECTS` with fields."""
    from jaxcascade._measured._effects import EFFECTS, ExtendedModel, simulate_padded
    from jaxcascade._measured._schema import model_schema

    # signals larger than in model units: the constants of the equations in model units
    # (`FLOOR`, `EPS`) then weigh less in the record's form than in the model's
    scaling = jc.Scaling(0.0, 250.0, 0.0, 50.0, "given")
    params = jc.example(1).params()
    u = np.asarray(jc.uniform_input(jax.random.PRNGKey(5), 200))
    noise = jc.ARNoise(jnp.asarray([]))
    for name, effect in _effect_examples().items():
        model = ExtendedModel(params, (effect,), noise)
        schema = model_schema(model, scaling)
        (entry,) = schema["effects"]
        orders = jc.Orders(**schema["orders"])
        if name == "general_backlash":  # the cascade's own terms (the test above)
            assert entry["parameters"] == {k: schema["estimates"][k] for k in entry["parameters"]}
            assert entry["units"]["mL3"] == "output_power(3)"
            continue
        assert entry["parameters_model_units"] == effect.parameters()
        assert set(entry["units"]) == set(entry["parameters"]) == set(entry["std_errors"])
        physical = jc.CascadeParams.from_dict(schema["estimates"], orders)
        kind = EFFECTS[name]
        mapped = kind(**{f: jnp.asarray(v, float) for f, v in entry["parameters"].items()})
        in_record = ExtendedModel(physical, (mapped,), noise)
        y_model = simulate_padded(model, u)[0]
        y_record = simulate_padded(in_record, scaling.input_to_physical(u))[0]
        assert np.all(np.isfinite(y_model)) and np.std(y_model) > 0.1, name
        # to 1e-4 of the output's scale: the floors of an equation (`FLOOR`: 1e-6 added
        # to a threshold, a Dahl level) stay in model units (`_units`), 1e-5 of the
        # output's scale here; a wrong factor is off by y_scale, u_scale or their ratio
        np.testing.assert_allclose(
            y_record,
            scaling.output_to_physical(y_model),
            rtol=1e-6,
            atol=1e-4 * 50.0,
            err_msg=name,
        )


def test_output_levels_and_polynomials_in_the_record_s_units_with_offsets():
    """A record with offsets and scales far from 0 and 1: the record's output computed
    by hand from the schema's record-unit fields (the cascade's output `c` in the
    record's units, relative to y_offset: `y_offset + cascade(u - u_offset)`) equals the
    model's output mapped back: a clip at levels of the record's output, a polynomial of
    the output less y_offset, a fold at a level of the record's output, an offset."""
    from jaxcascade._measured._effects import ExtendedModel, simulate_padded
    from jaxcascade._measured._schema import model_schema

    scaling = jc.Scaling(40.0, 250.0, -3.0, 0.004, "given")
    params = jc.example(1).params()
    u_model = np.asarray(jc.uniform_input(jax.random.PRNGKey(6), 200))
    u = scaling.input_to_physical(u_model)
    noise = jc.ARNoise(jnp.asarray([]))
    examples = _effect_examples()
    cascade = ExtendedModel(params, (), noise)
    schema = model_schema(cascade, scaling)
    physical = jc.CascadeParams.from_dict(schema["estimates"], jc.Orders(**schema["orders"]))
    # the cascade in the record's units (`y - y_offset = cascade(u - u_offset)`)
    c = scaling.y_offset + np.asarray(jc.simulate(physical, jnp.asarray(u - scaling.u_offset)))
    np.testing.assert_allclose(
        c, scaling.output_to_physical(simulate_padded(cascade, u_model)[0]), rtol=1e-9
    )
    y0 = scaling.y_offset

    def offset(p):
        return c + p["offset"]

    def saturation(p):
        return np.clip(c, p["lower"], p["upper"])

    def polynomial(p):
        c0, c2, c3 = p["coefficients"]
        return c + c0 + c2 * (c - y0) ** 2 + c3 * (c - y0) ** 3

    def fold(p):
        c0, c1, c2, s = p["coefficients"]
        return c0 + c1 * np.abs(c - s) + c2 * (c - s) ** 2

    # levels inside the output's range, so that the clip acts
    low, high = np.quantile(simulate_padded(cascade, u_model)[0], [0.2, 0.8])
    clip = type(examples["output_saturation"])(jnp.asarray(low), jnp.asarray(high))
    cases = [
        (examples["output_offset"], offset),
        (clip, saturation),
        (examples["output_polynomial"], polynomial),
        (examples["output_fold"], fold),
    ]
    for effect, by_hand in cases:
        model = ExtendedModel(params, (effect,), noise)
        (entry,) = model_schema(model, scaling)["effects"]
        expected = scaling.output_to_physical(simulate_padded(model, u_model)[0])
        np.testing.assert_allclose(
            by_hand(entry["parameters"]), expected, rtol=1e-9, atol=1e-9, err_msg=effect.name
        )
        assert entry["parameters"] != entry["parameters_model_units"]
    clipped = saturation(
        model_schema(ExtendedModel(params, (clip,), noise), scaling)["effects"][0]["parameters"]
    )
    assert np.mean(clipped != c) > 0.2  # the clip acted


def test_an_effect_s_standard_errors_map_with_the_size_of_the_factor():
    """A standard error in the records' units is the model's times |factor| (a level's
    offset does not move it); a fixed field's (the delay) stays null."""
    from jaxcascade._measured._effects import ExtendedModel
    from jaxcascade._measured._schema import model_schema

    scaling = jc.Scaling(40.0, 250.0, -3.0, 0.004, "given")
    effects = _effect_examples()
    model = ExtendedModel(
        jc.example(1).params(),
        (effects["input_delay"], effects["output_saturation"], effects["output_fold"]),
        jc.ARNoise(jnp.asarray([])),
    )
    errors = {
        "output_saturation.lower": 0.1,
        "output_fold.coefficients[0]": 0.2,
        "output_fold.coefficients[2]": 0.3,
    }
    delay, saturation, fold = model_schema(model, scaling, errors)["effects"]
    assert delay["std_errors"] == {"delay": None} and delay["parameters"] == {"delay": 2.0}
    assert saturation["std_errors"]["lower"] == pytest.approx(0.1 * 0.004)
    assert saturation["std_errors"]["upper"] is None
    assert saturation["parameters"]["lower"] == pytest.approx(-3.0 - 0.4 * 0.004)
    expected = [0.2 * 0.004, None, 0.3 / 0.004, None]
    assert fold["std_errors"]["coefficients"] == pytest.approx(expected)
    kinds = ["output_level", "unitless", "output_power(2)", "output_level"]
    assert fold["units"]["coefficients"] == kinds
