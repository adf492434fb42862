"""The linear block with terms inside its recursion: a feedback of its own output.

The cascade's linear block (`_system._simulate.linear_block`, METHOD.md eq. 6) is

    x(t) = sum_{i=1..r} a_i v(t-i) - sum_{j=1..p} b_j x(t-j)        (a_1 = 1)

and an effect with a `recursion` term (`Effect.recursion`, `_feedback`) adds to it, at
every sample, a function of the block's input `v(t)`, its output `x(t-1)` and the value
`x(t)` has so far (the linear recursion's plus the terms before it, in the effects'
order):

    x(t) = w(t) + term_1(v(t), x(t-1), w(t)) + term_2(v(t), x(t-1), w(t) + term_1) + ...

a static nonlinearity in feedback around the dynamics (a Duffing spring, a Lur'e loop,
friction on a velocity) or an input acting within the sample. The recursion is then
nonlinear and runs sample by sample (`lax.scan`), not blocked as the linear one is; its
output is held within `LIMIT` so that a diverging candidate (a cubic feedback driven
beyond its basin) ends with a large, finite cost instead of infinities.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..._system._model import CascadeParams

# |x| is held below this (model units: the records' standard deviation is about one)
LIMIT = 1e6


def linear_with_terms(params: CascadeParams, v, terms, v_past=None, x_past=None):
    """The linear block's output `x` for the input `v` (1-D) with the `terms`
    (callables `term(v_t, x_prev, x_new)`, `Effect.recursion`) inside its recursion,
    continued from the past `v_past` (`v(-1) .. v(-r)`) and `x_past` (`x(-1) .. x(-p)`),
    newest first (default zero: rest). Needs `p >= 1`."""
    o, T, dtype = params.orders, v.shape[0], v.dtype
    v_past = jnp.zeros((o.r,), dtype) if v_past is None else v_past.astype(dtype)
    x_past = jnp.zeros((o.p,), dtype) if x_past is None else x_past.astype(dtype)
    a = jnp.concatenate([jnp.ones((1,), dtype), params.a.astype(dtype)])
    joined = jnp.concatenate([v_past[::-1], v])
    w = sum(a[i - 1] * joined[o.r - i : o.r - i + T] for i in range(1, o.r + 1))
    b = params.b.astype(dtype)

    def step(past, inputs):
        w_t, v_t = inputs
        x_t = w_t - jnp.dot(b, past)
        for term in terms:
            x_t = x_t + term(v_t, past[0], x_t)
        x_t = jnp.clip(x_t, -LIMIT, LIMIT)
        return jnp.concatenate([x_t[None], past[:-1]]), x_t

    _, x = jax.lax.scan(step, x_past, (w, v))
    return x
