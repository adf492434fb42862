"""The loop's `general_backlash` effect (issue 39, point 5): a model with it simulates as
the general backlash of the note (against the plain NumPy rule of
`test_general_backlash`), from rest and from a state; zero curvature is the straight
cascade; its starts read the curvature off a residual; a fit whose branch turns is not
admissible; it survives the checkpoint and the model file."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_general_backlash import _numpy_general_backlash

import jaxcascade as jc
from jaxcascade._measured._effects import EFFECTS, CurvedBacklash, ExtendedModel, backlash_of, plain
from jaxcascade._measured._effects import simulate_with_switches as simulate
from jaxcascade._measured._initial_state import rest_state, simulate_from
from jaxcascade._measured._loop_checkpoint import model_from_dict, model_to_dict
from jaxcascade._measured._noise import ARNoise
from jaxcascade._system._general_backlash import general_example


def _curved(name="general1"):
    ex = general_example(name)
    effect = CurvedBacklash(jnp.asarray(ex.curveL, float), jnp.asarray(ex.curveR, float))
    return ex, ExtendedModel(ex.params(), (effect,), ARNoise.white())


def _record(n=1500, seed=3):
    return jc.uniform_input(jax.random.PRNGKey(seed), n)


@pytest.mark.parametrize("name", ["general1", "general2"])
def test_a_model_with_the_effect_is_the_notes_general_backlash(name):
    ex, model = _curved(name)
    u = _record()
    y, x, y_cascade = simulate(model, u)
    p = ex.params()
    expected = _numpy_general_backlash(
        np.asarray(x), float(p.cL), float(p.mR), float(p.cR), ex.curveL, ex.curveR
    )
    np.testing.assert_allclose(np.asarray(y), expected, atol=1e-12)
    np.testing.assert_allclose(np.asarray(y_cascade), expected, atol=1e-12)
    # from rest through the initial-state path: the same output
    from_rest = simulate_from(model, u, rest_state(model, u))[0]
    np.testing.assert_allclose(np.asarray(from_rest), expected, atol=1e-12)
    assert model.structure().endswith("general_backlash(3) -> y")
    assert backlash_of(model).degree == 3 and backlash_of(plain(p)) is None


def test_from_a_state_it_continues_the_record():
    # simulated in two parts, the second from the state the first ends in: the whole
    _, model = _curved("general2")
    u = _record(800)
    whole = simulate_from(model, u, rest_state(model, u))[0]
    first, _, _, state = simulate_from(model, u[:300], rest_state(model, u[:300]))
    second = simulate_from(model, u[300:], state)[0]
    np.testing.assert_allclose(np.concatenate([first, second]), whole, atol=1e-12)


def test_zero_curvature_is_the_straight_cascade():
    ex = general_example("general1")
    zero = jnp.zeros(2)
    model = ExtendedModel(ex.params(), (CurvedBacklash(zero, zero),), ARNoise.white())
    u = _record()
    np.testing.assert_allclose(
        np.asarray(simulate(model, u)[0]), np.asarray(jc.simulate(ex.params(), u)), atol=1e-14
    )


def test_starts_read_the_curvature_off_the_straight_models_residual():
    # the straight cascade of the truth, its residual on a noise-free curved record: the
    # degree-3 start's least squares recovers the curvature the record holds
    ex, truth = _curved("general1")
    u = _record(4000)
    y = np.asarray(simulate(truth, u)[0])
    straight = plain(ex.params())
    residual = y - np.asarray(simulate(straight, u)[0])
    starts = CurvedBacklash.starts(straight, np.asarray(u), y, residual)
    assert [s.label for s in starts] == ["general_backlash:2", "general_backlash:3"]
    cubic = starts[1].effect
    assert cubic.curveL.shape == (3, 2) and starts[1].vectors.shape[0] == 3
    np.testing.assert_allclose(np.asarray(cubic.curveL[0]), ex.curveL, atol=0.01)
    np.testing.assert_allclose(np.asarray(cubic.curveR[0]), ex.curveR, atol=0.01)
    np.testing.assert_array_equal(np.asarray(cubic.curveR[2]), 0.0)  # the straight start
    # a model that already has curved branches gets no second set
    assert CurvedBacklash.starts(truth, np.asarray(u), y, residual) == []


def test_a_branch_that_turns_on_the_record_is_not_admissible():
    ex, model = _curved("general1")
    u = [np.asarray(_record())]
    assert model.effects[0].admissible(model, u) is None
    turning = CurvedBacklash(jnp.asarray([0.0, -0.5]), jnp.asarray([0.0, 0.05]))
    bad = model.with_(effects=(turning,))
    reason = turning.admissible(bad, u)
    assert reason is not None and reason.startswith("its left branch turns")


def test_the_effect_is_in_the_library_and_survives_checkpoint_and_model_file(tmp_path):
    assert EFFECTS["general_backlash"] is CurvedBacklash and CurvedBacklash.needs_signature
    _, model = _curved("general2")
    again = model_from_dict(model_to_dict(model))
    for a, b in zip(
        jax.tree_util.tree_leaves(model), jax.tree_util.tree_leaves(again), strict=True
    ):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    from jaxcascade._measured._model_file import SavedModel, load_model

    path = tmp_path / "model.json"
    SavedModel(model).save(path)
    loaded = load_model(path).model
    u = _record(300)
    np.testing.assert_array_equal(
        np.asarray(simulate(loaded, u)[0]), np.asarray(simulate(model, u)[0])
    )


def test_the_loop_adds_curved_branches_where_the_record_has_them():
    # general2 at SNR 25 (its curvature moves y by 2.4 noise stds), only this effect in
    # the library: the straight cascade's residual fails a test of the signature, the
    # curved model is significant and ends at the noise floor. (The full library on
    # both examples and on straight records: benchmarks/general_backlash_loop.py.)
    from jaxcascade._measured._testing import CURVED, undeclared_record

    model, orders = CURVED["general2"]()
    k_est, k_val = jax.random.split(jax.random.PRNGKey(1))
    u, y = undeclared_record(model, k_est, 1024, 25.0)
    u_val, y_val = undeclared_record(model, k_val, 1024, 25.0)
    result = jc.model_error_loop(
        u, y, u_val, y_val, orders, effects=("general_backlash",), init_samples=0
    )
    assert result.added == ["general_backlash"]
    assert set(result.before.tests.failed) & set(CurvedBacklash.signature)
    assert result.after.error < 1.15 / 25 < result.before.error
    curved = backlash_of(result.final)
    assert curved is not None and curved.degree in (2, 3)
    assert result.final.structure().endswith(f"general_backlash({curved.degree}) -> y")


def test_an_inadmissible_best_start_gives_way_to_the_next_admissible_one(monkeypatch):
    # `_fit_candidate` takes, per candidate structure, the start of lowest cost whose fit
    # is a backlash on the records; before, an inadmissible best start dropped the whole
    # structure. The refit is stubbed: start 0 costs least and its left branch turns,
    # start 1 is admissible, start 2 costs most.
    from jaxcascade._measured import _loop
    from jaxcascade._measured._effects import Start

    ex, model = _curved("general1")
    u = np.asarray(_record(600))
    y = np.asarray(simulate(model, u)[0])
    good, turning = (
        model.effects[0],
        CurvedBacklash(jnp.asarray([0.0, -0.5]), jnp.asarray([0.0, 0.05])),
    )
    fits = [model.with_(effects=(e,)) for e in (turning, good, turning)]
    batch = jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *fits)
    costs = np.array([1.0, 2.0, 3.0])
    start = Start("general_backlash:3", ex.orders, np.zeros((3, ex.orders.size)), good)
    monkeypatch.setattr(CurvedBacklash, "starts_records", classmethod(lambda cls, m, r: [start]))
    monkeypatch.setattr(
        _loop, "refit_all", lambda *a, **k: (batch, costs, np.zeros(3, int), np.argsort(costs))
    )
    base = model.with_(effects=())
    fitted, label = _loop._fit_candidate("general_backlash", base, [u], [y], [(u, y, y)])
    assert label == "general_backlash:3"
    np.testing.assert_array_equal(np.asarray(fitted.effects[0].curveL), np.asarray(good.curveL))
    # every start inadmissible: no fit of this kind
    batch = jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *[fits[0]] * 3)
    assert _loop._fit_candidate("general_backlash", base, [u], [y], [(u, y, y)]) is None
