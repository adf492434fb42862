"""The model-error loop on data with an effect the declared model lacks (issue 5).

Each record is Example 1 (orders 2,2,2,2 declared) with one effect of the library
present but undeclared, at SNR 20 (noise floor 1/SNR = 0.05), 2000 estimation and 2000
validation samples. The loop must name the effect and bring the validation NRMSE
within 1.5 times the noise floor; on a record without an extra effect it must add
nothing. Effect sizes are chosen to be identifiable: e.g. an output offset smaller than
the backlash gaps is *exactly* a gap change (y + d is a backlash with cL + d and
cR - d / mR), so the offset used here exceeds what the gaps can absorb.
"""

import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

import jaxcascade as jc
from jaxcascade._measured._effects import (
    EFFECTS,
    ExtendedModel,
    InnerKink,
    OutputOffset,
    plain,
    simulate_extended,
)
from jaxcascade._measured._loop import model_error_loop, paired_improvement
from jaxcascade._measured._noise import ARNoise
from jaxcascade._measured._testing import UNDECLARED, undeclared_record

SNR = 20.0
N = 2000
TRUTH = jc.example(1).params


# Every effect record's loop over the whole library takes a minute or more on a 2-core
# machine: those run in the slow set (and `benchmarks/effects_loop.py` runs them all,
# `results/effects_loop.md`); in the default run each record is looped with its effect
# among rivals (`test_loop_names_the_undeclared_effect_among_rivals`), and the clean
# record over the whole library (nothing may be added).
LONG = tuple(e for e in UNDECLARED if e is not None)
# Rivals of every record: an output offset explains part of any residual with a mean,
# an extra pole part of any with dynamics, and the noise model any coloured one.
RIVALS = ("output_offset", "dynamics_order", "colored_noise")


def _undeclared(effect):
    model, ar = UNDECLARED[effect]()
    u, y = undeclared_record(model, jax.random.PRNGKey(1), N, SNR, ar)
    u_val, y_val = undeclared_record(model, jax.random.PRNGKey(2), N, SNR, ar)
    return u, y, u_val, y_val


@pytest.mark.parametrize(
    "effect",
    [pytest.param(e, marks=pytest.mark.slow) if e in LONG else e for e in UNDECLARED],
    ids=lambda e: str(e),
)
def test_loop_names_the_undeclared_effect(effect):
    u, y, u_val, y_val = _undeclared(effect)
    result = model_error_loop(u, y, u_val, y_val, jc.Orders(), init_samples=0)
    _check_named(effect, result)


@pytest.mark.parametrize("effect", LONG)
def test_loop_names_the_undeclared_effect_among_rivals(effect):
    # The same records and checks as above, the library cut to the effect and its
    # rivals (the full library: the slow set and results/effects_loop.md).
    u, y, u_val, y_val = _undeclared(effect)
    library = (effect, *(r for r in RIVALS if r != effect))
    result = model_error_loop(u, y, u_val, y_val, jc.Orders(), effects=library, init_samples=0)
    _check_named(effect, result)


def test_loop_names_the_friction_of_an_integrating_axis():
    # The force and position of an axis under proportional control with Coulomb
    # friction (`_testing.axis_record`): the loop models the position's difference and
    # names the friction among its rivals; the forces come back near the truth.
    from jaxcascade._measured._testing import INTEGRATING, axis_record

    friction = INTEGRATING["velocity_friction"]
    k_est, k_val = jax.random.split(jax.random.PRNGKey(1))
    u, y = axis_record(k_est, N, SNR, friction)
    u_val, y_val = axis_record(k_val, N, SNR, friction)
    library = ("velocity_friction", *RIVALS)
    result = model_error_loop(
        u[1:],
        np.diff(y),
        u_val[1:],
        np.diff(y_val),
        jc.Orders(),
        effects=library,
        integrating=True,
    )
    assert result.added == ["velocity_friction"]
    # the position's NRMSE, initialised on 50 samples: 0.22 -> 0.037 at this commit
    assert result.after.error < 0.25 * result.before.error
    forces = np.abs(np.asarray(result.final.effects[-1].forces))
    np.testing.assert_allclose(forces, friction, atol=0.1)


def _check_named(effect, result):
    expected = [] if effect is None else [effect]
    assert result.added == expected
    # 1.5 times the noise floor, the criterion; the floor is 1/SNR.
    assert result.after.error <= 1.5 / SNR
    if effect is not None and effect != "colored_noise":
        assert result.before.error > result.after.error
    assert result.after.tests.ok
    report = result.to_dict()
    assert report["effect_added"] == expected
    assert all(np.isfinite(c["error"]) for c in report["candidates"])
    # the final model's standard errors, on the estimation record: every cascade
    # parameter has one, finite and positive; without an undeclared effect the estimate
    # lies within 5 of them of the truth, parameter by parameter
    errors = report["model_after"]["std_errors_model_units"]
    names = result.final.orders.names
    assert all(np.isfinite(errors[name]) and errors[name] > 0 for name in names)
    assert errors == {n: result.standard_errors[n] for n in errors}
    if effect is None:
        estimate, truth = result.final.params.to_dict(), TRUTH().to_dict()
        assert all(abs(estimate[n] - truth[n]) <= 5 * errors[n] for n in names)


@pytest.mark.parametrize(
    "library",
    [
        pytest.param(None, marks=pytest.mark.slow, id="every-effect"),
        pytest.param(RIVALS, id="rivals"),
    ],
)
def test_loop_names_strongly_coloured_noise_on_the_prediction_error(library):
    # Issue 15, item 6: AR(1) output noise with pole 0.95 and nothing else undeclared.
    # The noise model leaves the simulation error at the noise floor (the cascade is
    # refitted on the prediction error it defines); it is judged, and named, on the
    # one-step-ahead prediction error (floor 0.05 sqrt(1 - 0.95^2) = 0.016). Over the
    # whole library in the slow set, among its rivals in the default run.
    model = plain(TRUTH())
    u, y = undeclared_record(model, jax.random.PRNGKey(1), N, SNR, 0.95)
    u_val, y_val = undeclared_record(model, jax.random.PRNGKey(2), N, SNR, 0.95)
    result = model_error_loop(u, y, u_val, y_val, jc.Orders(), effects=library, init_samples=0)
    assert result.added == ["colored_noise"]
    report = result.to_dict()
    assert report["effect_added"] == ["colored_noise"]
    assert report["error_after"] <= 1.5 / SNR
    assert report["prediction_error_after"] < 0.5 * report["prediction_error_before"]
    (noise,) = [c for c in report["candidates"] if c["name"] == "colored_noise"]
    assert noise["significant"] and noise["loss"] == "prediction" and noise["t"] > 3
    assert report["significance"]["test"] == "Diebold-Mariano"
    assert result.after.tests.whiteness_ok  # the tests after it see the whitened residual


def test_loop_builds_a_sandwich_whichever_block_comes_first():
    # Example 1, then the static map of output_polynomial's record, then the dynamics of
    # output_dynamics's (a Wiener-Hammerstein sandwich around the backlash): the loop may
    # add either block first; the map ends between the two linear blocks either way
    # (output_polynomial added before output_dynamics, or inner_polynomial after it)
    polynomial = UNDECLARED["output_polynomial"]()[0]
    dynamics = UNDECLARED["output_dynamics"]()[0].effects[0]
    model = polynomial.with_(effects=(*polynomial.effects, dynamics))
    u, y = undeclared_record(model, jax.random.PRNGKey(1), N, SNR)
    u_val, y_val = undeclared_record(model, jax.random.PRNGKey(2), N, SNR)
    # the three maps alone (the rivals of every record cost this default-run test 2 x
    # the time and did not change what was added, seeds 1, 2)
    library = ("output_polynomial", "output_dynamics", "inner_polynomial")
    result = model_error_loop(
        u, y, u_val, y_val, jc.Orders(), effects=library, init_samples=0, max_effects=2
    )
    assert sorted(result.added) in (
        ["output_dynamics", "output_polynomial"],
        ["inner_polynomial", "output_dynamics"],
    ), result.added
    assert result.final.structure().endswith("_polynomial -> output_dynamics -> y")
    assert result.after.error <= 1.5 / SNR


def test_loop_finds_a_diode_between_the_two_blocks():
    # Example 1, a two-slope map (slopes 1.5 and 0.5 about zero, a diode's) and the
    # dynamics of output_dynamics's record: the loop adds the second block, then the
    # kink between the blocks, not the smooth polynomial there
    dynamics = UNDECLARED["output_dynamics"]()[0].effects[0]
    kinked = UNDECLARED[None]()[0]
    model = kinked.with_(effects=(InnerKink(jnp.array([0.0, 0.5, 0.0])), dynamics))
    u, y = undeclared_record(model, jax.random.PRNGKey(1), N, SNR)
    u_val, y_val = undeclared_record(model, jax.random.PRNGKey(2), N, SNR)
    library = ("output_dynamics", "inner_polynomial", "inner_kink")
    result = model_error_loop(
        u, y, u_val, y_val, jc.Orders(), effects=library, init_samples=0, max_effects=2
    )
    assert result.added == ["output_dynamics", "inner_kink"], result.added
    assert result.final.structure().endswith("backlash -> inner_kink -> output_dynamics -> y")
    assert result.after.error <= 1.5 / SNR
    (kink,) = [c for c in result.candidates if c.name == "inner_kink"]
    (smooth,) = [c for c in result.candidates if c.name == "inner_polynomial"]
    assert kink.error < smooth.error


def test_a_kink_refines_a_static_map_already_before_the_second_block():
    # The loop may add a cubic before the second block exists (output_polynomial, then
    # output_dynamics after it): the kink is still tried between the blocks, after the
    # cubic, so that a diode is not left to a cubic fitted without the second block;
    # once a kink is there, no second one is
    from jaxcascade._measured._effects import OutputPolynomial

    dynamics = UNDECLARED["output_dynamics"]()[0].effects[0]
    base = UNDECLARED[None]()[0]
    truth = base.with_(effects=(InnerKink(jnp.array([0.0, 0.5, 0.0])), dynamics))
    u, y = undeclared_record(truth, jax.random.PRNGKey(1), N, SNR)
    cubic = OutputPolynomial(jnp.array([0.0, 0.0, -0.05]))
    model = base.with_(effects=(cubic, dynamics))
    residual = np.asarray(y) - np.asarray(simulate_extended(model, u)[0])
    starts = InnerKink.starts_records(model, [(u, y, residual)])
    assert [s.label for s in starts] == ["inner_kink"]
    kinked = model.with_(effects=(*model.effects, InnerKink(jnp.array([0.0, 0.5, 0.0]))))
    assert kinked.structure().endswith("output_polynomial -> inner_kink -> output_dynamics -> y")
    assert InnerKink.starts_records(kinked, [(u, y, residual)]) == []


def test_the_backward_step_takes_out_an_effect_a_later_one_made_unnecessary():
    # A record with an output offset alone, and the model of a loop that added a drift
    # first (a drift explains part of a mean too) and the offset after it: the backward
    # step takes the drift out. On a record with both, both stay.
    from jaxcascade._measured._effects import OutputDrift
    from jaxcascade._measured._loop import _no_effect, _prune, evaluate, refit

    offset_only = UNDECLARED["output_offset"]()[0]
    both = offset_only.with_(effects=(OutputDrift(jnp.asarray(0.2)), *offset_only.effects))
    for truth, expected in ((offset_only, ["output_drift"]), (both, [])):
        u, y = undeclared_record(truth, jax.random.PRNGKey(1), N, SNR)
        u_val, y_val = undeclared_record(truth, jax.random.PRNGKey(2), N, SNR)
        # the loop's model: the truth's cascade, a drift, then the offset, fitted
        start = both.with_(effects=(OutputDrift(jnp.asarray(0.02)), *offset_only.effects))
        fitted = refit(start, _no_effect(start.params), [u], [y])[0]
        model = fitted.with_(effects=fitted.effects[:-1])

        def assess(m, u_val=u_val, y_val=y_val):
            return evaluate(m, u_val, y_val)

        gone = list(_prune(model, assess(model), [u], [y], assess, 0.02))
        assert [name for name, *_ in gone] == expected
        if gone:
            _, reduced, evaluation = gone[-1]
            assert reduced.names == ("output_offset",)
            assert evaluation.error <= 1.1 / SNR


def test_every_effect_declares_a_signature():
    tests = {
        "autocorrelation",
        "cross_correlation",
        "e_eu",
        "u2_e",
        "u2_e2",
        "spectrum",
        "mean",
        "regime",
        "branch",
        "level",
        "time",
        "hysteresis",
    }
    for effect in EFFECTS.values():
        assert effect.signature and set(effect.signature) <= tests, effect.name


def test_offset_within_the_gaps_is_a_gap_change():
    # The identifiability fact the offset test relies on: exact equality of outputs.
    p = TRUTH()
    d = 0.1
    u = jc.uniform_input(jax.random.PRNGKey(0), 500)
    v = p.to_dict()
    v.update(cL=v["cL"] + d, cR=v["cR"] - d / v["mR"])
    shifted = jc.simulate(jc.CascadeParams.from_dict(v), u)
    # Both backlash states start at y = 0, so compare after the first move has
    # settled the state on a line.
    offset = ExtendedModel(p, (OutputOffset(jnp.asarray(d)),), ARNoise.white())
    with_offset = simulate_extended(offset, u)
    start = int(np.argmax(np.abs(np.diff(np.asarray(shifted))) > 0)) + 5
    np.testing.assert_allclose(shifted[start:], with_offset[start:], atol=1e-12)


def test_innovations_invert_an_ar_filter():
    e = np.asarray(jax.random.normal(jax.random.PRNGKey(3), (1000,)))
    coloured = scipy.signal.lfilter([1.0], [1.0, -0.7, 0.2], e)
    noise = ARNoise(jnp.array([0.7, -0.2]))
    np.testing.assert_allclose(noise.innovations(jnp.asarray(coloured)), e, atol=1e-12)


def test_noise_fitted_on_several_records():
    # One set of AR coefficients from two records, each record's lags from its own samples.
    rng = np.random.default_rng(5)
    records = [scipy.signal.lfilter([1.0], [1.0, -0.8], rng.normal(size=3000)) for _ in range(2)]
    noise, p_value = ARNoise.fit_records(records)
    assert noise.order >= 1 and p_value < 1e-6
    assert noise.coefficients[0] == pytest.approx(0.8, abs=0.03)
    white, p_white = ARNoise.fit_records([rng.normal(size=3000), rng.normal(size=3000)])
    assert white.order == 0 and p_white == 1.0


def test_paired_improvement_sign():
    rng = np.random.default_rng(0)
    noise = rng.normal(size=2000)
    # d = noise + 0.25, white: the statistic is about 0.25 sqrt(2000) = 11.
    assert paired_improvement(noise + 0.5, noise) > 8
    assert paired_improvement(noise, noise + 0.5) < -8
    assert abs(paired_improvement(noise, rng.normal(size=2000))) < 4


def test_every_effect_of_the_library_has_an_undeclared_record():
    # The hysteresis paths and the curved backlash are tried only when a test of their
    # signature fails, which the hysteresis test does on none of these records
    # (test_diagnose); they have tests of their own (below, test_hysteresis.py,
    # test_curved_backlash_effect.py). Every other effect has a synthetic record: Example
    # 1 with it (`UNDECLARED`), or the axis under control whose output integrates
    # (`INTEGRATING`).
    from jaxcascade._measured._effects import HYSTERESIS
    from jaxcascade._measured._testing import INTEGRATING

    records = {name for name in (*UNDECLARED, *INTEGRATING) if name is not None}
    own_tests = {
        "slack_friction",
        "backlash_friction",
        "backlash_friction_contacts",
        "prandtl_ishlinskii",
        "dahl_friction",
        "input_backlash",
        "general_backlash",
        # the static part of a sandwich whose second block came first: its record has
        # two effects (test_loop_builds_a_sandwich_whichever_block_comes_first,
        # test_loop_finds_a_diode_between_the_two_blocks)
        "inner_polynomial",
        "inner_kink",
    }
    assert records | own_tests == {*EFFECTS, ARNoise.name}
    assert not records & own_tests
    assert own_tests <= set(HYSTERESIS)
    assert all(EFFECTS[name].needs_signature for name in HYSTERESIS)


def test_loop_compiles_a_bounded_set_of_programs():
    # Issue 21: a loop over many estimation records compiles one program per model
    # structure and record-length bucket, never one per record. From nothing compiled,
    # the loop on 2 records of two buckets compiles under a fixed bound; the loop on 10
    # records of lengths in the same two buckets then compiles no more than that (only
    # the programs whose batch of records has another size: one per record would be
    # about five times as many).
    from jaxcascade._compile import compile_count, compiler_options, release

    # the XLA options' one-off probe (a tiny program, once per process) would otherwise
    # count in the first loop when this test runs first in its process
    compiler_options()
    model = ExtendedModel(TRUTH(), (OutputOffset(jnp.asarray(0.8)),), ARNoise.white())

    # the records: windows of one long record (a record of a new length simulated
    # eagerly compiles its own operations: a second apiece)
    u_all, y_all = (np.asarray(a) for a in jaxcascade_record(model, 0, 3200))
    u_val, y_val = u_all[-400:], y_all[-400:]

    def record(seed, n):
        return u_all[200 * seed : 200 * seed + n], y_all[200 * seed : 200 * seed + n]

    counts = []
    release()
    for lengths in ([150, 310], [150, 151, 152, 153, 154, 155, 300, 301, 305, 310]):
        records = [record(seed, n) for seed, n in enumerate(lengths)]
        base = TRUTH()
        before = compile_count()
        result = model_error_loop(
            [u for u, _ in records],
            [y for _, y in records],
            u_val,
            y_val,
            jc.Orders(),
            base=base,
            effects=("output_offset",),
            max_effects=1,
            init_samples=0,
        )
        assert result.added == ["output_offset"]
        counts.append(compile_count() - before)
        assert result.programs_compiled == counts[-1]
    assert 0 < counts[1] <= counts[0] <= 60, counts


def test_threads_give_the_loop_of_one_thread_bit_for_bit(monkeypatch):
    from jaxcascade._measured import _loop

    # A round's candidates fitted at once in threads (`_loop._Workers`, the CLI's
    # default of 2): each runs the same programs on the same arrays as one at a time,
    # so the decisions, every candidate's figures and the final model are the same bit
    # for bit, whatever the number of threads (here more than the round's candidates).
    model = ExtendedModel(TRUTH(), (OutputOffset(jnp.asarray(0.8)),), ARNoise.white())
    (u, y), (u_val, y_val) = jaxcascade_record(model, 1, 500), jaxcascade_record(model, 2, 500)
    library = ("output_offset", "output_drift", "dynamics_order")
    reports, where = [], []
    fit = _loop._fit_candidate

    def fit_in(*args, **kwargs):  # which thread fits each candidate
        where.append(threading.current_thread().name)
        return fit(*args, **kwargs)

    for threads in (1, 4):
        monkeypatch.setattr(_loop, "_fit_candidate", fit_in)
        result = model_error_loop(
            u,
            y,
            u_val,
            y_val,
            jc.Orders(),
            base=TRUTH(),
            effects=library,
            threads=threads,
            init_samples=0,
        )
        report = result.to_dict()
        report.pop("programs_compiled")
        reports.append(report)
    main = threading.main_thread().name
    assert where[:3] == [main] * 3
    assert all(name.startswith("jaxcascade-candidate") for name in where[3:])
    assert reports[0]["effect_added"] == ["output_offset"]
    # one round: the library's candidates, and the linear floor where it may be better
    names = [c["name"] for c in reports[0]["candidates"]]
    assert names[:3] == list(library) and set(names[3:]) <= {"linear_floor"}
    assert reports[1] == reports[0]
    with pytest.raises(ValueError, match="threads"):
        model_error_loop(u, y, u_val, y_val, jc.Orders(), base=TRUTH(), threads=0)


def jaxcascade_record(model, seed, n):
    from jaxcascade._measured._testing import undeclared_record

    return undeclared_record(model, jax.random.PRNGKey(seed), n, SNR, None)


def test_loop_replaces_the_cascade_by_a_hysteresis_path():
    # Issue 21, item 2: a friction force behind a slack with no cascade in it. The loop
    # tries the hysteresis path added to the declared cascade and in its place; the
    # replacement wins, with the true parameters, and the structure line says so.
    from jaxcascade._measured._effects import BacklashFriction

    truth = BacklashFriction(*(jnp.asarray(v) for v in (0.08, 30.0, 2.3, 2.0, 0.1)))
    rng = np.random.default_rng(3)

    def record(n, amplitude):
        u = np.cumsum(rng.normal(size=n))
        u = scipy.signal.lfilter([0.05], [1, -0.95], u - u.mean())
        u = amplitude * u / np.abs(u).max()
        return u, np.asarray(truth.parallel(jnp.asarray(u))) + 0.05 * rng.normal(size=n)

    (u1, y1), (u2, y2), (u_val, y_val) = record(1500, 0.5), record(1500, 0.3), record(1500, 0.4)
    result = model_error_loop(
        [u1, u2],
        [y1, y2],
        u_val,
        y_val,
        jc.Orders(),
        effects=("backlash_friction",),
        init_samples=0,
    )
    assert result.actions[0] == {"effect": "backlash_friction", "action": "replace", "round": 1}
    assert not result.final.cascade
    assert result.final.structure().startswith("u -> backlash_friction")
    (path,) = [e for e in result.final.effects if e.name == "backlash_friction"]
    got = [abs(float(v)) for v in (path.gap, path.stiffness, path.upper, path.lower)]
    np.testing.assert_allclose(got, [0.08, 30.0, 2.3, 2.0], rtol=0.05)
    # noise 0.05 on a force of about 2: the floor is a few hundredths
    assert result.after.error < 0.1 < result.before.error
    assert "u -> backlash_friction" in result.to_dict()["structure_after"]
