"""`_effects._choice`: a `Choice` behaves as the member it stands for, and one program
serves every member of its group.

A `Choice` runs its member's own operations behind a `lax.switch`, and padded state and
parameters enter no arithmetic; but XLA fuses (and contracts into fused multiply-adds)
across the switch differently, so outputs agree to rounding, not always bit for bit
(1 ulp observed on the slack friction's path). Tolerance: `test_effect_references`'
`10 N eps` of the output's scale, the same operations rounded differently."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_effect_references import MODELS, TOLERANCE, _input

from jaxcascade._compile import compile_count, pad
from jaxcascade._measured import _initial_state
from jaxcascade._measured._effects import (
    EFFECTS,
    choose,
    grouping,
    groups,
    simulate_with_switches,
    unchoose,
    unchoose_states,
)
from jaxcascade._measured._effects._choice import Choice, choice, eligible, unchoice

LIBRARY = groups(EFFECTS.values())
GROUPED = [name for name in EFFECTS if any(EFFECTS[name] in g for g in LIBRARY)]


def test_groups_of_the_library():
    # the effects with scalar parameters and the cascade's own backlash, by whether their
    # state has a range and its size; the structural effects (no parameters), those with
    # array parameters and a member alone (the backlash friction, a state of nine) are
    # left as they are (`_choice`'s docstring)
    assert [[kind.name for kind in group] for group in LIBRARY] == [
        [
            "output_offset",
            "input_delay",
            "output_saturation",
            "output_drift",
            "output_feedthrough",
        ],
        ["slack_friction", "backlash_friction_contacts", "dahl_friction", "input_backlash"],
    ]
    assert all(eligible(kind) for group in LIBRARY for kind in group)
    assert eligible(EFFECTS["backlash_friction"])
    assert not eligible(EFFECTS["prandtl_ishlinskii"])  # array parameters
    assert not eligible(EFFECTS["general_backlash"])  # and a backlash of its own
    # groups among the effects a loop tries: a member alone is no group
    assert groups([EFFECTS["output_offset"], EFFECTS["slack_friction"]]) == ()
    # in a loop, a library group used whole where two of its members are tried
    model = MODELS["output_offset"]()
    tried = [EFFECTS["output_offset"], EFFECTS["output_drift"], EFFECTS["slack_friction"]]
    with grouping(tried, EFFECTS.values()):
        assert choose(model).effects[-1].kinds == LIBRARY[0]
    with grouping(tried[::2], EFFECTS.values()):
        assert not isinstance(choose(model).effects[-1], Choice)


@pytest.mark.parametrize("name", GROUPED)
def test_choice_round_trip_batched_and_not(name):
    effect = MODELS[name]().effects[-1]
    back = unchoice(choice(effect, LIBRARY))
    assert type(back) is type(effect)
    for field in dataclasses.fields(effect):
        np.testing.assert_array_equal(getattr(back, field.name), getattr(effect, field.name))
    batched = jax.tree_util.tree_map(lambda leaf: jnp.stack([leaf, leaf + 1.0]), effect)
    chosen = choice(batched, LIBRARY)
    assert isinstance(chosen, Choice) and chosen.index.shape == ()  # shared by the starts
    back = unchoice(chosen)
    for field in dataclasses.fields(effect):
        np.testing.assert_array_equal(getattr(back, field.name), getattr(batched, field.name))


def _close(got, want):
    got, want = np.asarray(got), np.asarray(want)
    scale = max(float(np.nanmax(np.abs(want), initial=0.0)), 1.0)
    np.testing.assert_allclose(got, want, rtol=0, atol=TOLERANCE * scale)


_simulate = eqx.filter_jit(simulate_with_switches)
_from = eqx.filter_jit(_initial_state.simulate_from)


@pytest.mark.parametrize("name", GROUPED)
def test_choice_simulates_as_its_member(name):
    model = MODELS[name]()
    chosen = choose(model, LIBRARY)
    assert isinstance(chosen.effects[-1], Choice)
    u = jnp.asarray(_input())
    for got, want in zip(_simulate(chosen, u), _simulate(model, u), strict=True):
        _close(got, want)
    # from a state, and the state after: the member's, unpadded
    rest = _initial_state.rest_state(model, u)
    rest_chosen = _initial_state.rest_state(chosen, u)
    half = u.shape[0] // 2
    want = _from(model, u, rest, half)
    got = _from(chosen, u, rest_chosen, half)
    _close(got[0], want[0])
    states = jax.tree_util.tree_leaves(unchoose_states(model, chosen, got[3].effects))
    wanted = jax.tree_util.tree_leaves(want[3].effects)
    assert [np.shape(a) for a in states] == [np.shape(b) for b in wanted]
    for a, b in zip(states, wanted, strict=True):
        _close(a, b)
    assert unchoose(chosen).effects[-1].name == name


def test_one_initial_state_program_for_a_group_and_the_members_own_result():
    u = _input()
    fits = {}
    for name in ("output_offset", "output_drift", "input_delay", "slack_friction", "dahl_friction"):
        model = MODELS[name]()
        y = np.asarray(_simulate(model, jnp.asarray(u))[0])
        before = compile_count()
        with grouping(EFFECTS.values()):
            fits[name] = (_initial_state.initialise(model, u, y, 150, 40), compile_count() - before)
        if name not in ("output_offset", "dahl_friction"):  # one member's own program each
            continue
        own = _initial_state._initialise.jitted(
            model,
            jnp.asarray(pad(u)),
            jnp.asarray(pad(y)),
            jnp.asarray(110, jnp.int32),
            n=40,
            grid=_initial_state.GRID,
            max_steps=_initial_state.MAX_STEPS,
        )
        _close(fits[name][0].y, np.asarray(own.y)[: u.shape[0]])
        assert fits[name][0].cost == pytest.approx(float(own.cost), rel=1e-9, abs=1e-15)
        assert [np.shape(s.known) for s in fits[name][0].state.effects if s is not None] == [
            np.shape(s.known) for s in own.state.effects if s is not None
        ]
    # a group's first member compiles its program; the others compile nothing
    assert fits["output_offset"][1] > 0 and fits["slack_friction"][1] > 0
    assert fits["output_drift"][1] == 0
    assert fits["input_delay"][1] == 0
    assert fits["dahl_friction"][1] == 0


def test_only_the_last_effect_and_only_inside_a_loop():
    model = MODELS["output_offset"]()
    both = model.with_(effects=(*model.effects, *MODELS["output_drift"]().effects))
    with grouping(EFFECTS.values()):
        kinds = [type(e) for e in choose(both).effects]
    assert kinds == [type(both.effects[0]), Choice]
    assert choose(model) is not None and not isinstance(choose(model).effects[-1], Choice)
    with grouping(EFFECTS.values()):
        assert isinstance(choose(model).effects[-1], Choice)
    assert not isinstance(choose(model).effects[-1], Choice)


@pytest.mark.parametrize("name", ["slack_friction", "output_drift", "prandtl_ishlinskii"])
def test_records_of_one_loop_share_one_simulation_program(name):
    # `padded_to`: the records of a loop (here of three length buckets) simulated by one
    # program, each padded to the longest's bucket; the simulation is causal and every
    # sample's arithmetic the same as in its own bucket's program, so bit for bit the
    # output of each record simulated alone (an effect's state, a drift's sample index,
    # the blocked pole recursion: each sample depends on the samples before it only)
    from jaxcascade._measured._effects import padded_to, simulate_padded

    model = MODELS[name]()
    u = _input()
    records = [u[:90], u[:170], u[:400]]  # buckets 96, 176 and 400
    alone = [simulate_padded(model, r) for r in records]
    with padded_to([len(r) for r in records]):
        before = compile_count()
        shared = [simulate_padded(model, r) for r in records]
        assert compile_count() - before <= 1  # the longest bucket's, if not compiled yet
    for a, b in zip(alone, shared, strict=True):
        for x, z in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, z)


def test_a_record_far_shorter_than_the_longest_keeps_its_own_bucket():
    # simulating 100 samples at a bucket of 2,000 would cost more than its own program
    from jaxcascade._compile import bucket_length
    from jaxcascade._measured._effects import padded_to
    from jaxcascade._measured._effects._base import SHARED_WITHIN, padded

    u = np.arange(2000.0)
    common = bucket_length(2000)
    with padded_to([100, 400, 2000]):
        assert padded(u[:400]).shape == (common,)  # within SHARED_WITHIN of the longest
        assert common > SHARED_WITHIN * bucket_length(100)
        assert padded(u[:100]).shape == (bucket_length(100),)  # its own bucket
        assert padded(u).shape == (common,)
    assert padded(u[:400]).shape == (bucket_length(400),)  # outside a loop: its own
