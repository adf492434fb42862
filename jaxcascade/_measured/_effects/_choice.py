"""One program for a group of effects: a `Choice` stands for any member of its group.

The loop fits and scores many candidate models that differ only in one effect, and each
model structure is its own compiled program (`_compile`): a refit, an initial-state fit
and a simulation per candidate. Effects whose parameters are all scalars (their shapes
known from the class alone) are gathered in groups (`groups`); a `Choice` holds one
member of a group as arrays: which member (`index`, traced), its free parameters
padded to the group's largest count (`values`) and its held ones likewise (`held`). Its
stages (`input`, `output`, `parallel`, their `*_with_state` forms, `rest_state`,
`state_range`) are a `lax.switch` on `index` over the members' own, its state the
members' padded to the group's largest. So a program traced with a `Choice` serves
every member of its group: `choose(model, groups)` before a call, `unchoose` after.

Only the chosen branch runs (`index` is never batched: the refit's starts share it).
What differs from the member's own program is the arithmetic around the switch (XLA
fuses across it differently: outputs equal to rounding, a unit in the last place where
they differ, `tests/test_effect_choice.py`) and, for a member
with fewer parameters than the group's largest, padded parameters that change
nothing (zero columns of the Jacobian; the Levenberg-Marquardt step leaves them at
zero). The loop's programs, counted by name: `results/loop_speed.md`.

Groups are by whether a member's state has a range (`Effect.state_range`: an
initial-state fit then starts from a grid over it, so a mixed group would give every
member the grid's starts) and by the size of that state, in powers of two (a member with
a small state does not pay for the largest one's Jacobian columns): the output and input
effects in one group, the operator paths with a state of one or two in another, the
backlash friction (nine) alone. A group is used where a loop may try two or more of its
members (`grouping`), whole whichever they are; a member alone is left as it is. Only a
model's last effect is chosen (`choose`): the candidates differ in the effect they add,
and a `Choice` further up (the offset of a candidate that replaces the cascade, an effect
of an earlier round) would make every program of that structure larger without sharing
it. Both rules were measured on the damper run (`benchmarks/loop_compare.py --damper`
against the commit before): every effect of a model chosen, with every group used
whatever the loop tries, ran 1.14-1.19x slower and moved a candidate's validation NRMSE
by 0.178.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import functools
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._base import Effect, EffectState, ExtendedModel


def _scalar(annotation) -> bool:
    """Whether a field's annotation (a string: `from __future__ import annotations`) is
    a scalar parameter, `Float[Array, ""]`."""
    return "".join(c for c in str(annotation) if c not in "'\" ") == "Float[Array,]"


def _fields(kind) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """`(free, held)`: the names of `kind`'s refined and held (`Effect.fixed`) fields."""
    names = [f.name for f in dataclasses.fields(kind)]
    free = tuple(n for n in names if n not in kind.fixed)
    return free, tuple(n for n in names if n in kind.fixed)


def eligible(kind) -> bool:
    """Whether `kind` can be a member of a group: at least one field and every field a
    scalar parameter, and the cascade's straight backlash and its linear block's
    recursion left alone (a `Choice` switches the stages, not those)."""
    fields = dataclasses.fields(kind)
    return (
        bool(fields)
        and all(_scalar(f.type) for f in fields)
        and kind.backlash is Effect.backlash
        and kind.recursion is Effect.recursion
    )


@functools.cache
def _template(kind, dtype: str):
    """`(member of zeros, shape of its rest state or None)` of `kind` in `dtype`."""
    member = kind(**{f.name: jnp.zeros((), dtype) for f in dataclasses.fields(kind)})
    state = jax.eval_shape(member.rest_state, jax.ShapeDtypeStruct((8,), dtype))
    return member, state


def _state_size(kind) -> int:
    state = _template(kind, "float32")[1]  # sizes only: float32 exists with or without x64
    return 0 if state is None else int(np.prod(state.free.shape))


def groups(kinds) -> tuple[tuple[type[Effect], ...], ...]:
    """The groups of the eligible `kinds` (module docstring), each in `kinds`' order."""
    keyed: dict = {}
    for kind in kinds:
        if eligible(kind):
            ranged = kind.state_range is not Effect.state_range
            size = _state_size(kind)
            bucket = 1 << max(1, (size - 1).bit_length()) if size else 0
            keyed.setdefault((ranged, bucket), []).append(kind)
    return tuple(tuple(members) for members in keyed.values() if len(members) > 1)


# The groups in force (`grouping`): none outside a loop, so that every other caller runs
# the member's own program, as before groups existed.
_ACTIVE: contextvars.ContextVar = contextvars.ContextVar("jaxcascade_groups", default=())


@contextlib.contextmanager
def grouping(kinds, library=None):
    """Within the block, `choose` and `choice` use the groups of `library` (`groups`;
    default `kinds`) that hold two or more of `kinds` (the effects a loop may try: a
    member alone is left as it is). A group keeps all its members whichever of them are
    tried, so that loops that try different effects share its programs. A thread pool's
    tasks see it where they run in a copy of the context (`contextvars.copy_context`)."""
    kinds = list(kinds)
    found = groups(kinds if library is None else library)
    token = _ACTIVE.set(tuple(g for g in found if sum(k in kinds for k in g) > 1))
    try:
        yield
    finally:
        _ACTIVE.reset(token)


class Choice(Effect):
    """One member of the group `kinds` (module docstring): `index` the member,
    `values` its free parameters (padded with zeros), `held` its held ones."""

    name: ClassVar[str] = "choice"
    fixed: ClassVar[tuple[str, ...]] = ("index", "held")

    kinds: tuple[type[Effect], ...] = eqx.field(static=True)
    index: Int[Array, ""]
    values: Float[Array, " P"]
    held: Float[Array, " H"]

    # -- members ---------------------------------------------------------------------

    def _member(self, j: int) -> Effect:
        free, held = _fields(self.kinds[j])
        values = {name: self.values[..., i] for i, name in enumerate(free)}
        values.update({name: self.held[..., i] for i, name in enumerate(held)})
        return self.kinds[j](**values)

    def _switch(self, branch, *operands):
        """`branch(j, member j, *operands)` of the chosen member `j`."""
        if len(self.kinds) == 1:
            return branch(0, self._member(0), *operands)
        branches = [
            functools.partial(lambda j, *a: branch(j, self._member(j), *a), j)
            for j in range(len(self.kinds))
        ]
        return jax.lax.switch(self.index, branches, *operands)

    def _overrides(self, method: str) -> bool:
        return any(getattr(kind, method) is not getattr(Effect, method) for kind in self.kinds)

    # -- states: each member's padded to the group's largest -------------------------

    def _shapes(self, dtype):
        return [_template(kind, jnp.dtype(dtype).name)[1] for kind in self.kinds]

    def _padded_sizes(self, dtype):
        shapes = [s for s in self._shapes(dtype) if s is not None]
        if not shapes:
            return None
        return (
            max(int(np.prod(s.free.shape)) for s in shapes),
            max(int(np.prod(s.known.shape)) for s in shapes),
        )

    def _pad(self, state, sizes, dtype):
        if state is None:
            return EffectState(jnp.zeros((sizes[0],), dtype), jnp.zeros((sizes[1],), dtype))
        free, known = jnp.ravel(state.free), jnp.ravel(state.known).astype(dtype)
        return EffectState(
            jnp.pad(free, (0, sizes[0] - free.size)), jnp.pad(known, (0, sizes[1] - known.size))
        )

    def _unpad(self, j, state, dtype):
        shape = self._shapes(dtype)[j]
        if shape is None:
            return None
        f, k = int(np.prod(shape.free.shape)), int(np.prod(shape.known.shape))
        return EffectState(
            state.free[:f].reshape(shape.free.shape), state.known[:k].reshape(shape.known.shape)
        )

    def _with_state(self, method, state, at, first, *rest):
        """The chosen member's `method(first, *rest, its state, at)` with the state
        unpadded for it and padded back."""
        dtype = first.dtype
        sizes = self._padded_sizes(dtype)

        def branch(j, member, state, first, *rest):
            own = None if sizes is None else self._unpad(j, state, dtype)
            out, own = getattr(member, method)(first, *rest, own, at)
            if out is None:
                out = jnp.zeros_like(first)
            return out, (state if sizes is None or own is None else self._pad(own, sizes, dtype))

        return self._switch(branch, state, first, *rest)

    # -- the stages --------------------------------------------------------------------

    def input(self, u):
        if not self._overrides("input"):
            return u
        return self._switch(lambda j, m, u: m.input(u), u)

    def output(self, y, x):
        if not self._overrides("output"):
            return y
        return self._switch(lambda j, m, y, x: m.output(y, x), y, x)

    def parallel(self, u):
        if not self._overrides("parallel"):
            return None

        def path(j, member, u):
            out = member.parallel(u)
            return jnp.zeros_like(u) if out is None else out

        return self._switch(path, u)

    def rest_state(self, u):
        sizes = self._padded_sizes(u.dtype)
        if sizes is None:
            return None
        return self._switch(lambda j, m, u: self._pad(m.rest_state(u), sizes, u.dtype), u)

    def input_with_state(self, u, state, at):
        if not self._overrides("input_with_state") and not self._overrides("input"):
            return u, state
        return self._with_state("input_with_state", state, at, u)

    def output_with_state(self, y, x, state, at):
        if not self._overrides("output_with_state") and not self._overrides("output"):
            return y, state
        return self._with_state("output_with_state", state, at, y, x)

    def parallel_with_state(self, u, state, at):
        if not self._overrides("parallel_with_state") and not self._overrides("parallel"):
            return None, state
        return self._with_state("parallel_with_state", state, at, u)

    def state_range(self, state):
        if not self._overrides("state_range"):
            return None
        dtype = state.free.dtype

        def bounds(j, member, state):
            own = self._unpad(j, state, dtype)
            found = None if own is None else member.state_range(own)
            if found is None:  # no range: every grid start is the warm one
                return state.free, state.free
            pad = (0, state.free.size - own.free.size)
            return jnp.pad(jnp.ravel(found[0]), pad), jnp.pad(jnp.ravel(found[1]), pad)

        return self._switch(bounds, state)


# -- host side: effects to choices and back ------------------------------------------


def _group(kind, of) -> tuple[type[Effect], ...] | None:
    for members in of:
        if kind in members:
            return members
    return None


def choice(effect: Effect, of=None) -> Effect:
    """`effect` (batched or not: a leading axis on every parameter) as a `Choice` of its
    group among `of` (`groups`; default those in force, `grouping`), or `effect` itself
    where it has none. The index is a scalar even for a batched effect: the starts share
    it. Built on the host (NumPy): eager `jnp` calls would each compile a program."""
    kinds = _group(type(effect), _ACTIVE.get() if of is None else of)
    if kinds is None:
        return effect
    width = max(len(_fields(kind)[0]) for kind in kinds)
    depth = max(len(_fields(kind)[1]) for kind in kinds)
    free, held = _fields(type(effect))
    first = np.asarray(getattr(effect, (free + held)[0]))
    dtype, batch = first.dtype, first.shape

    def stack(names, width):
        out = np.zeros((*batch, width), dtype)
        for i, name in enumerate(names):
            out[..., i] = np.asarray(getattr(effect, name))
        return jax.device_put(out)

    index = jax.device_put(np.asarray(kinds.index(type(effect)), np.int32))
    return Choice(kinds, index, stack(free, width), stack(held, depth))


def unchoice(effect: Effect) -> Effect:
    """The member a `Choice` stands for (batched where its parameters are), or
    `effect` itself; on the host, as `choice`."""
    if not isinstance(effect, Choice):
        return effect
    host = jax.tree_util.tree_map(np.asarray, effect)
    member = host._member(int(np.ravel(host.index)[0]))
    return jax.tree_util.tree_map(lambda a: jax.device_put(np.ascontiguousarray(a)), member)


def choose(model: ExtendedModel, of=None) -> ExtendedModel:
    """`model` with its last effect as its `Choice` where it has a group among `of`
    (default: those in force, `grouping`). Only the last: the loop's candidates differ in
    the effect they add, and an effect before it (one added in an earlier round, the
    offset of a candidate that replaces the cascade) would make its structure's program
    larger without sharing it."""
    if not model.effects:
        return model
    return model.with_(effects=(*model.effects[:-1], choice(model.effects[-1], of)))


def unchoose(model: ExtendedModel) -> ExtendedModel:
    """`model` with every `Choice` as the member it stands for."""
    return model.with_(effects=tuple(unchoice(e) for e in model.effects))


def unchoose_states(model: ExtendedModel, chosen: ExtendedModel, states):
    """The effects' states of `chosen` (`choose(model)`), each as its member's."""
    out = []
    for effect, picked, state in zip(model.effects, chosen.effects, states, strict=True):
        if isinstance(picked, Choice) and state is not None:
            j = picked.kinds.index(type(effect))
            state = jax.tree_util.tree_map(np.asarray, state)
            state = picked._unpad(j, state, state.free.dtype)
            state = jax.tree_util.tree_map(jax.device_put, state)
        out.append(state)
    return tuple(out)
