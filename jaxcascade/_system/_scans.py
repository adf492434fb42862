"""The cascade's recursions in time as scans of associative maps: log-depth forms for
an accelerator, and the choice between them and the sequential `lax.scan`s.

Three recursions run along a record (eqs. 6 and 9, and their forward sensitivities,
`_estimator._sensitivity`). Each sample's update is a map of the state before it, and
the maps compose associatively, so every prefix composition follows in `log2 T` rounds
of element-wise work instead of `T` sequential steps (`prefix`). On a CPU the
sequential scans are faster (little parallel width to gain, the scan's per-step cost
small); on a GPU each sequential step is a kernel launch and a loop-condition read back
to the host, so the parallel forms are taken there (`parallel`, decided at trace time
from `jax.default_backend()`).

`prefix` is the doubling scan (Hillis and Steele): round `k` composes each element with
the one `2^k` before it, in a `lax.fori_loop`, so the operator is traced once.
`jax.lax.associative_scan` computes the same compositions with less work (odd-even
reduction) but traces the operator about `2 log2 T` times, each round a program part
of its own shape: on the backlash's maps of 64 records of N 4000 its program took 45 s
to compile on the CPU against 0.8 s for `prefix` (the same outputs), and the robust
estimator holds several such scans.

- **The pole recursion** `x(t) = w(t) - sum_j b_j x(t-j)` (LD, eq. 6) is an affine map of
  the state `s(t) = (x(t), ..., x(t-p+1))`: `s(t) = A s(t-1) + e_1 w(t)`, `A` the companion
  matrix of `b`. Affine maps `(M, c): s -> M s + c` compose as
  `(M2, c2) o (M1, c1) = (M2 M1, M2 c1 + c2)` (`compose_affine`); `poles` scans them. The
  sums are formed in another order than the sequential recursion's: equal up to
  rounding (relative 1e-15 on stable blocks, `tests/test_scans.py`). The same recursion
  with several right-hand sides (`w` of shape `T x K`) gives the sensitivities of `x`.
  `poles_blocked`, what the simulator and the sensitivities take, scans the maps of
  blocks of samples instead (their powers of `A` by a scan of matrix products), each
  block's response from rest a product with its Toeplitz matrix: fewer bytes moved
  than a scan over every sample.
- **The backlash** (ND, eq. 9 with `mR > 0`): with `L(t)` the left branch's value at
  `x(t)` (`x + cL`, curved: `fL(x)`) and `R(t)` the right branch's, the update is
  `y -> L(t) if y > L(t), else R(t) if y < R(t), else y`. Where `R(t) <= L(t)` that is a
  clamp of `y` into `[R(t), L(t)]`; where the branches cross (`mR != 1`, the left line
  wins, `_simulate.backlash_switches`) it is the threshold map
  `y -> R(t) if y <= L(t) else L(t)`. Clamps and threshold maps (`Hold`) compose among
  themselves into clamps and threshold maps (`compose_hold`), by comparisons and
  selections only: no arithmetic, so the scan's output is the sequential output's
  values exactly, except where the right switch's test (`(y - mR x + mR cR) / mR < 0`,
  rounded) and `y < R(t)` disagree within a few ulps of `R(t)`, where the outputs
  differ by those ulps. `hold` scans them; the general backlash's curved branches
  (issue 39) change only the values `L(t)` and `R(t)`. It needs `mR > 0` (the model's
  domain: eq. 11 divides by it); where a traced `mR` is not, the output is NaN rather
  than a different number than the sequential form's.
- **The backlash's sensitivities**: the switches are piecewise constant, so
  `dy(t) = on(t)` where a branch is active and `dy(t) = dy(t-1)` where it holds, from
  the switches of the output before: the value of the last active sample
  (`last_active`), a cumulative maximum of indices and a gather (exact).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float


def parallel() -> bool:
    """Whether the recursions in time take their associative-scan forms: on an
    accelerator (the default backend is not the CPU), at trace time."""
    return jax.default_backend() != "cpu"


# -- The scan -------------------------------------------------------------------------


def prefix(combine, elems, identity):
    """Every prefix composition of `elems` along their leading axis under the
    associative `combine(earlier, later)`, by doubling (module docstring): element `t`
    of the result is `elems[0] ... elems[t]` composed. `identity`: the operator's
    identity element (a pytree like one element of `elems`), which stands for the
    elements before the first."""
    leaves = jax.tree_util.tree_leaves(elems)
    T = leaves[0].shape[0]

    def level(k, elems):
        index = jnp.arange(T) - jnp.left_shift(1, k)
        valid = index >= 0

        def earlier(leaf, unit):
            taken = leaf[jnp.maximum(index, 0)]
            return jnp.where(valid.reshape((T,) + (1,) * (leaf.ndim - 1)), taken, unit)

        return combine(jax.tree_util.tree_map(earlier, elems, identity), elems)

    return jax.lax.fori_loop(0, max(T - 1, 0).bit_length(), level, elems)


# -- The pole recursion: affine maps of the state ---------------------------------------


def compose_affine(first, second):
    """`second o first` of affine maps `(M, c): s -> M s + c` (batched over leading axes;
    `c` is `... p` or `... p K`): `(M2 M1, M2 c1 + c2)`."""
    m1, c1 = first
    m2, c2 = second
    if c1.ndim == m1.ndim - 1:  # one right-hand side: `... p`
        return _product(m2, m1), jnp.sum(m2 * c1[..., None, :], axis=-1) + c2
    return _product(m2, m1), _product(m2, c1) + c2


def _product(a, b):
    # `a @ b` of small matrices; for the usual orders (p <= 4) as a sum of element-wise
    # products, which fuses with its neighbours where a batched product of 2 x 2
    # matrices would be a library call per scan level
    if a.shape[-1] > 4:
        return a @ b
    return jnp.sum(a[..., :, :, None] * b[..., None, :, :], axis=-2)


def companion(b: Float[Array, " p"]) -> Float[Array, "p p"]:
    """The companion matrix `A` of `x(t) = w(t) - sum_j b_j x(t-j)` on the state
    `(x(t), ..., x(t-p+1))`: first row `-b`, ones below the diagonal."""
    p = b.shape[0]
    shift = jnp.eye(p, k=-1, dtype=b.dtype)
    return shift.at[0].set(-b)


def poles(b: Float[Array, " p"], w: Float[Array, " T"] | Float[Array, "T K"]) -> Array:
    """`x(t) = w(t) - sum_j b_j x(t-j)` from rest (`x = 0` before the record), by an
    associative scan of the samples' affine maps (module docstring); `w` of shape `T` or
    `T x K` (`K` right-hand sides, each its own recursion). `p = 0`: `w` itself."""
    p = b.shape[0]
    if p == 0:
        return w
    dtype = w.dtype
    T = w.shape[0]
    A = companion(b.astype(dtype))
    M = jnp.broadcast_to(A, (T, p, p))
    # c(t) = e_1 w(t): the sample enters the state's first entry
    c = jnp.zeros((T, p, *w.shape[1:]), dtype).at[:, 0].set(w)
    _, states = prefix(compose_affine, (M, c), _affine_identity(p, c.shape[2:], dtype))
    return states[:, 0]


def _affine_identity(p, rest, dtype):
    return jnp.eye(p, dtype=dtype), jnp.zeros((p, *rest), dtype)


def poles_blocked(b: Float[Array, " p"], w, block: int = 64) -> Array:
    """`poles` in blocks of `block` samples: within a block the response from rest is a
    product with the impulse response's Toeplitz matrix `H`, and each block's map of
    the state before it to the state after it is affine, `s -> A^block s + z`, `z` the
    state its response from rest ends in; an associative scan of those maps gives every
    block's starting state `s`, whose response over the block is `G s` (`G`: row `t`
    the first row of `A^(t+1)`). The powers of `A` come from an associative scan of
    matrix products. A few large products and a scan over `T / block` maps instead of
    `T`: the same recursion, equal up to rounding."""
    p = b.shape[0]
    if p == 0:
        return w
    dtype = w.dtype
    T = w.shape[0]
    block = min(block, T)
    if block < max(p, 2):  # a block shorter than the state: the plain scan of maps
        return poles(b, w)
    A = companion(b.astype(dtype))
    # A^1 .. A^block
    powers = prefix(
        lambda x, y: _product(y, x), jnp.broadcast_to(A, (block, p, p)), jnp.eye(p, dtype=dtype)
    )
    G = powers[:, 0, :]  # x(t) from the state before the block: first row of A^(t+1)
    h = jnp.concatenate([jnp.ones((1,), dtype), powers[:-1, 0, 0]])  # h(t) = (A^t)[0, 0]
    lag = jnp.arange(block)[:, None] - jnp.arange(block)[None, :]
    H = jnp.where(lag >= 0, h[jnp.clip(lag, 0, None)], 0.0)
    count = -(-T // block)
    rest = w.shape[1:]
    padded = jnp.concatenate([w, jnp.zeros((count * block - T, *rest), dtype)])
    blocks = padded.reshape(count, block, *rest)
    free = jnp.einsum("ts,ks...->kt...", H, blocks)  # each block's response from rest
    # the state after each block's response from rest: its last p outputs, newest first
    ends = free[:, ::-1][:, :p]
    maps = (jnp.broadcast_to(powers[-1], (count, p, p)), ends)
    _, after = prefix(compose_affine, maps, _affine_identity(p, rest, dtype))
    before = jnp.concatenate([jnp.zeros_like(after[:1]), after[:-1]])
    x = free + jnp.einsum("tj,kj...->kt...", G, before)
    return x.reshape(count * block, *rest)[:T]


# -- The backlash: clamps and threshold maps ---------------------------------------------


class Hold(NamedTuple):
    """A map of the backlash's output before a sample to the output after it (or of a
    run of samples: their composition), one of two kinds, batched over leading axes:

    - a clamp (`step` False): `y -> min(max(y, low), high)`, `low <= high`;
    - a threshold map (`step` True): `y -> low if y <= at else high`.
    """

    step: Array
    low: Array
    high: Array
    at: Array


def apply_hold(f: Hold, y):
    """`f(y)` (element-wise over `f`'s leading axes and `y`'s)."""
    clamped = jnp.minimum(jnp.maximum(y, f.low), f.high)
    return jnp.where(f.step, jnp.where(y <= f.at, f.low, f.high), clamped)


def compose_hold(first: Hold, second: Hold) -> Hold:
    """`second o first` of two `Hold` maps, again a `Hold` (comparisons and selections
    only, so exact):

    - after a threshold map, any map: a threshold map at the same point, its two values
      mapped;
    - a clamp after a clamp: the clamp of the first's bounds, mapped;
    - a threshold map after a clamp `[a, b]`: the same threshold map where `a <= at < b`,
      else a constant (a threshold at `+inf` or `-inf`).
    """
    low = apply_hold(second, first.low)
    high = apply_hold(second, first.high)
    # a threshold map after a clamp: where the clamp's output can reach past its point
    inf = jnp.asarray(jnp.inf, second.at.dtype)
    at = jnp.where(second.at >= first.high, inf, jnp.where(second.at < first.low, -inf, second.at))
    mapped = first.step | ~second.step  # the first's point and mapped values
    return Hold(
        step=first.step | second.step,
        low=jnp.where(mapped, low, second.low),
        high=jnp.where(mapped, high, second.high),
        at=jnp.where(mapped, first.at, at),
    )


def backlash_maps(left: Float[Array, " T"], right: Float[Array, " T"]) -> Hold:
    """Each sample's update of the backlash as a `Hold`: `left` the left branch's value
    at the sample's input (taken where the output before lies above it), `right` the
    right branch's (taken below it; the left one wins where both hold)."""
    crossed = right > left
    return Hold(
        step=crossed,
        low=right,
        high=left,
        at=jnp.where(crossed, left, jnp.zeros_like(left)),
    )


def hold(
    left: Float[Array, " T"],
    right: Float[Array, " T"],
    y_prev: Float[Array, ""],
) -> Float[Array, " T"]:
    """The backlash's output `y(t)` from `y_prev` (the output before the first sample),
    each sample's update given by its branches' values (`backlash_maps`), by an
    associative scan of the maps (module docstring)."""
    inf = jnp.asarray(jnp.inf, left.dtype)
    identity = Hold(jnp.zeros((), bool), -inf, inf, jnp.zeros((), left.dtype))  # no clamp
    maps = prefix(compose_hold, backlash_maps(left, right), identity)
    return apply_hold(maps, y_prev)


def backlash(
    x: Float[Array, " T"],
    left: Float[Array, " T"],
    right: Float[Array, " T"],
    mR: Float[Array, ""],
    y_prev=None,
) -> Float[Array, " T"]:
    """The backlash's output from its input `x` and its branches' values there (`hold`),
    NaN from the first non-finite input on (as the sequential recursion's output) and
    wholly where `mR` is not positive (the parallel form's domain: module docstring)."""
    y0 = jnp.zeros((), x.dtype) if y_prev is None else jnp.asarray(y_prev, x.dtype)
    y = hold(left, right, y0)
    broken = jax.lax.cummax((~jnp.isfinite(x)).astype(jnp.int32)) > 0
    return jnp.where(broken | ~(mR > 0), jnp.nan, y)


# -- The backlash's sensitivities: the value of the last active sample ---------------------


def last_active(active: Bool[Array, " T"], values: Float[Array, "T ..."]) -> Array:
    """`z(t) = values(t)` where `active(t)`, else `z(t-1)` (`z = 0` before the record):
    the value at the last active sample up to `t`, by a cumulative maximum of the active
    samples' indices and a gather (exact)."""
    T = active.shape[0]
    index = jax.lax.cummax(jnp.where(active, jnp.arange(T), -1))
    taken = values[jnp.maximum(index, 0)]
    seen = (index >= 0).reshape((T,) + (1,) * (values.ndim - 1))
    return jnp.where(seen, taken, jnp.zeros_like(taken))
