"""The paper's estimator in recursive least-squares form (Vörös 2016, conclusion): the
key-term regression (eqs. 16-18) solved sample by sample, with forgetting.

The paper's closing remark: the model "can be applied for on-line identification ...
using the known recursive least-squares algorithm". Here each sample t

1. rebuilds the internal variables from the current estimate, as eqs. 19-25 do for the
   whole record: `v(t-i)` from the piecewise-linear block (eq. 21) at the window's
   inputs, `x(t)` from the linear block's recursion (eq. 22) on the past `x` the
   recursion itself produced, then g1, g2 (eqs. 23-24), `yc(t)` (eq. 25) and `phi(t)`
   (eq. 17; `_rls_regressor.sample_regression`);
2. updates theta by recursive least squares (`_rls.update`) on the a-priori error
   `yc(t) - phi(t) theta`, each of the regression's two blocks (the g1 and the g2
   columns, disjoint in time) where it is active.

**Curved branches** (`Orders.degree > 1`, the general output backlash): the regressor
gains the curvature's columns (`_regression.regression`), the left branch's in the g1
block, the right's in the g2 block (`_blocks`); everything else is the same.

**Breakpoints as `D M`.** Eq. 17's breakpoint columns are `-M_i h(D_{i-1} - u(t-1))`
with coefficient `D_{i-1}`. In a recursion that column vanishes whenever the running
estimate of a slope increment passes near 0, and the breakpoint then drifts with
nothing to hold it (noise-free Example 1 with `lam = 0.99`: 27 of 100 records ended
more than 0.05 from the truth, `results/recursive_noise_free.md` at commit 3d178d6).
So the recursion keeps the paper's first-iteration form throughout: unit slopes in
those columns (`_regression.regression(..., unit_slopes=True)`) and the
coefficient `D M`, divided by the slope estimate wherever `D` itself is needed (the
switching functions, the piecewise-linear block, the estimate returned; a slope of 0
keeps the initial breakpoint). The same model, the same fixed point; only the
coordinates of the recursion change (with them all 100 reach 1e-6 at `lam = 0.98`).

**The start is the paper's first iteration, on-line.** The first `first_samples` samples
are the first iteration's regression (v ~ u, x ~ y, the backlash at its initial values:
`_literal.first_iteration`) accumulated with no forgetting, from the same initial values
as `voros` (`_literal.initial_guess`). At sample `first_samples` its NS and LD estimates
and their information are kept, the backlash restarts at its initial values (its block's
`P` at `delta I`), the past `x` are taken as the past `y` (the first iteration's
approximation), and the full recursion starts. Only samples up to t ever enter the
estimate at t: the whole procedure is on-line.

**Forgetting** (`_rls.forgetting`): the memory `1 / (1 - lam_k)` starts at
`memory0` samples and grows by `growth k + acceleration k^2` after k samples, up to
`1 / (1 - lam)`. `lam = 1`: a factor that tends to 1, for a system that does not change;
`lam < 1`: a constant memory, for tracking (and, noise-free, exact convergence: the
start is forgotten exponentially). Default: `lam = 1`, `memory0 = 10`, `growth = 0.1`,
`acceleration = 3e-4`: `lam_k = 1 - 1 / (10 + 0.1 k + 3e-4 k^2)`, which tends to 1.
Why: early regressors are built from poor estimates and must fade, but a memory that
grows only linearly (`growth g`) weighs sample s at time k by `(s / k)^(1 / g)`, so it
keeps paying for the transient with variance (`g = 0.25`: the last quarter of the
record carries most of the weight; the RMSE of the final estimate 1.4-1.7 times the
batch iteration's). A memory that grows like `k^2` forgets sample s by `exp(-(1/s -
1/k) / acceleration)`: the start (s below about `1 / acceleration` = 3300 samples) fades,
the rest of the record tends to equal weights. The linear term keeps the memory short
while the estimate converges. Chosen among about twenty schedules on 64 Example 1
records at SNR 25 (records 0..63: the largest RMSE ratio to the batch iteration's over
the parameters, 1.68 for `g = 0.25` alone, 1.41 for this one), then measured on 200
others (`results/recursive_vs_batch.md`).

**The gain's regressor** (`gradient`). The recursion above is a pseudo-linear
regression: `phi(t)` is built from the current estimate and then treated as data, so the
dependence of `v`, `x` and so of `phi(t) theta` on theta is ignored. Near the truth the
error then contracts only by the paper's fixed-point map, and on short memories slowly:
noise-free Example 2 from up to 1 % off the truth (`lam = 0.99`), none of 200 records
reached 1e-6 by N = 2000 (76 % 1e-3). On one record tried at `lam = 0.95`, putting in
the true `x` took the final error from 1e-8 to 1e-12 and the true `v` changed nothing:
the slow mode is `x`'s dependence on theta through the linear block's recursion. With
`gradient=True` the gain uses instead `psi(t)`, the total derivative of the key-term
prediction `phi(t) theta` with respect to theta (with `x(t)`'s sensitivity carried
through eq. 22's recursion, the switching functions held: they are piecewise
constant), and one full `P`: the recursive prediction-error (Gauss-Newton) form of the
same regression (Ljung and Söderström 1983): near the truth its steps are Gauss-Newton
steps on the prediction error, not steps of the fixed-point map. The error it corrects
is the same `yc(t) - phi(t) theta`, so the truth stays an exact fixed point. From the
same starts 189 of the 200 reached 1e-6 (all 1e-3).

**What "converged" means.** An on-line estimate never stops by itself: the status is
read at the end of the record from its last window (`settle_window = 400` samples, fewer
when less is left after the first iteration). It is `converged` only when both hold:

1. *settled*: every coefficient of the regression (eq. 18, breakpoints as `D M`) moved
   over the window by at most `settle_tolerance = 3` standard errors, `s sqrt(P_ii)`
   with `P` the recursion's covariance at the end (the full `P` with `gradient=True`)
   and `s` the RMS a-priori error of the window's updating samples, plus rounding
   (`sqrt(eps) (1 + |theta_i|)`: 1.5e-8 in float64);
2. *at the noise level*: the window's RMS prediction error (a dead-zone sample's error,
   the output's step `e(t) - e(t-1)`, counted half) is at most `noise_tolerance = 3`
   times the noise level the recursion estimates, plus rounding (`sqrt(eps)` times the
   output's RMS), and at most a fifth of the output's spread. The noise level comes
   from the samples the estimate puts in the backlash's dead zone (g1 = g2 = 0), where
   the noiseless output does not move and the error is `e(t) - e(t-1)`: their lower
   quartile (robust to samples put there wrongly), capped by the window's 2 % smallest
   output steps whatever the estimate (exactly 0 wherever the output rests exactly, as
   it does noise-free); 0 when the estimate puts fewer than 10 samples there. This
   scale does not depend on the static and linear blocks' estimates, so a wrong
   estimate cannot make its own errors look like noise: noise-free, where the output
   rests, the noise level is 0 and `converged` needs the errors at rounding level.

Otherwise `tracking` (still moving, or its errors above the noise level; one pass:
the record ended first), `max_iterations` with `passes > 1`, `singular` when fewer
samples of the window than parameters updated the estimate (the output never left the
estimate's dead zone), `left_domain`, `diverged`. Thresholds: on correct estimates at
SNR 25 (Examples 1 and 2, random systems) the settling statistic, the largest of 12
roughly standard normal ratios, is rarely above 3 and the noise ratio mostly 0.6 to 2;
noise-free with the defaults, Example 2's seed-0 record, 2.8 off, moved 4.3 standard
errors over the window and its errors are 10^7 times its noise level's rounding floor.
The fifth of the spread: a stuck estimate on a random system whose output almost never
rests makes errors that pass for noise at SNR 3-4 (2 of 200 records, noise-free), which
no record can tell from real noise; a converged estimate therefore also claims an SNR of
at least 5. Measured for every estimator in `results/status_honesty.md`.

**Noise-free settings** (`NOISE_FREE`, what `jaxcascade reproduce --snr inf` runs):
`gradient=True, lam=0.95`. Without noise, the only error left is that of the early
regressors, built from poor estimates; a constant memory (20 samples) forgets them
exponentially and the Gauss-Newton gain contracts fast, so the estimate reaches the
truth to rounding (200 of 200 records of each example, below). Under noise that short
memory averages over 20 samples only: at SNR 25 the final estimate's error is several
times the default's (Example 1: 108 of 200 records more than 0.05 off, against 1 with
the default schedule); the default memory, which grows without bound, averages the
noise over the whole record but keeps a remnant of the start (noise-free, median
largest error 5e-4 on Example 1, and `tracking` says so).

**What is measured** (`benchmarks/recursive_noise_free.py`, `recursive_vs_batch.py`).
The true parameters are an exact fixed point (zero a-priori error at every sample,
noise-free). Noise-free, one on-line pass from the paper's initial values: with
`gradient=True, lam = 0.95` (memory 20 samples) every one of 200 records of each example
reaches 1e-6 within the paper's N (4000, 2000; 199 of Example 2's at `lam = 0.93`); with
the key-term regressor, 198 of Example 1's at `lam = 0.98` but at most 14 % of Example
2's (`lam = 0.93`), whose g1 regime (the only one that informs the static and linear
blocks) holds 28 % of its samples against 43 % in Example 1 (true switches, 20 records),
over half the length (`results/recursive_noise_free.md`). Noise-free the
factor is constant, below 1: with no noise to average, the only error left is that of
the early regressors, which a constant memory forgets exponentially; the default
schedule, which tends to 1, keeps a remnant of them (median largest error 5e-4 on
Example 1). At SNR 25 the final estimate's RMSE per parameter is 0.85 to 1.30 times
the batch iteration's on 200 Example 1 records with the defaults, 0.30 to 1.12 times
with `gradient=True` (`results/recursive_vs_batch.md`). `passes > 1` (off-line)
recovers most records exactly. `project` keeps the estimate admissible (Ljung's
projection); a breakpoint that would leave the input range is held instead (a slope
estimated at exactly 0, a segment the first iteration never saw, leaves `D M / M`
undefined: rejecting every update that moved it froze 5 of 60 Example 2 records at the
first iteration's estimate), and the first iteration's breakpoints outside the range go
back to their initial values.
"""

from __future__ import annotations

import statistics
from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int, PRNGKeyArray

from .._compile import jit
from .._status import Status
from .._system._model import CascadeParams, Orders, is_admissible
from .._system._simulate import pwl
from .._system._validate import is_traced, record
from ._base import Estimator, keyword_defaults, setting
from ._literal import initial_guess
from ._rls import ANTI_WINDUP, forgetting, update
from ._rls_regressor import sample_regression, window
from ._solution import PATH_ONLY, Solution, finite


class Recursion(NamedTuple):
    """What `recursive` returns.

    - `solution`: the final estimate as a `Solution`; its `history` holds the start (row
      0) and, with `every = k > 0`, the estimate after samples k, 2k, ... (the last row
      the final estimate; during the first `first_samples` samples, the first
      iteration's estimate so far), else the final estimate alone (row 1).
      `iterations` is the number of sample updates, `cost` the mean squared a-priori
      error over the samples after the start.
    - `errors`: `Float[Array, " T"]`, the a-priori prediction error of the corrected
      output, `yc(t) - phi(t) theta_{t-1}` (zero-length unless `errors=True`).
    - `settling`: the largest change of a regression coefficient over the status's
      window, in standard errors (`converged` needs at most `settle_tolerance`).
    - `noise_ratio`: the window's prediction error over the noise level it estimates
      (`converged` needs at most `noise_tolerance`).
    - `noise_level`: that noise level (the output noise's standard deviation; 0 where
      the output rests exactly, as noise-free, or where the estimate puts fewer than 10
      samples of the window in the backlash's dead zone).
    """

    solution: Solution
    errors: Float[Array, " T"]
    settling: Float[Array, ""]
    noise_ratio: Float[Array, ""]
    noise_level: Float[Array, ""]


def recursive(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    init: CascadeParams | None = None,
    *,
    lam: float = 1.0,
    memory0: float = 10.0,
    growth: float = 0.1,
    acceleration: float = 3e-4,
    first_samples: int = 400,
    anti_windup: str = "none",
    delta: float = 1e3,
    divergence_bound: float = 1e6,
    every: int = 0,
    errors: bool = False,
    project: bool = True,
    passes: int = 1,
    input_range: tuple[float, float] | None = None,
    gradient: bool = False,
    settle_window: int = 400,
    settle_tolerance: float = 3.0,
    noise_tolerance: float = 3.0,
) -> Recursion:
    """The recursive least-squares form of the paper's estimator on one record.

    **Arguments:**

    - `u`, `y`: input and measured output (checked by `_validate.record`).
    - `orders`: static model orders.
    - `init`: initial values; default `initial_guess(orders, min(u), max(u))`.
    - `lam`, `memory0`, `growth`, `acceleration`: the forgetting schedule `lam_k =
      min(lam, 1 - 1 / (memory0 + growth k + acceleration k^2))` (`_rls.forgetting`),
      k the samples since the first iteration.
    - `first_samples`: samples of the on-line first iteration (module docstring).
    - `anti_windup`: `"none"` (default: exponential forgetting, each block forgotten
      only where it is active, which already keeps the dead zone from winding `P` up),
      `"trace"` or `"directional"` (`_rls`).
    - `delta`: `P` starts (and restarts after the first iteration) at `delta I`.
    - `divergence_bound`: an estimate larger than this is `diverged`.
    - `every`: keep the estimate every `every` samples (0: only the final one).
    - `errors`: also return the a-priori prediction errors (of the last pass).
    - `project`: Ljung's projection (default on): an update that would leave the
      model's domain is not taken, except that a breakpoint that would leave the input
      range is held where it is and the rest of the update taken.
    - `gradient`: the gain's regressor (module docstring). False (default): `phi(t)`,
      the key-term regressor (the paper's least squares, a pseudo-linear regression);
      True: the gradient of the key-term prediction `phi(t) theta` with respect to
      theta, the internal variables' dependence on theta included (the recursive
      prediction-error form); about 1.5 times slower per sample.
    - `passes`: 1 (default): one pass over the record, on-line. More passes run the
      recursion over the record again, carrying the estimate and `P` (each pass starts
      the signals from rest): an off-line use of the recursion, NOT on-line
      identification (the estimate at sample t then depends on later samples).
    - `input_range`: `(u_min, u_max)` for the initial breakpoints and the domain check;
      default the record's range (which an on-line user does not know in advance: pass
      the input's nominal range).

    - `settle_window`, `settle_tolerance`, `noise_tolerance`: what `converged` means
      (below).

    **Status** (the module docstring's **What "converged" means**): `converged` when,
    over the last `settle_window` samples (fewer when the record after the first
    iteration is shorter), the estimate has settled (every coefficient moved by at most
    `settle_tolerance` standard errors, from the recursion's `P` and the window's
    prediction error, plus rounding) and its prediction error is at the noise level it
    estimates (at most `noise_tolerance` times it, plus rounding, and at most a fifth
    of the output's spread); `tracking` when either fails (`max_iterations` with
    `passes > 1`); `singular` when fewer samples of the window than parameters updated
    the estimate; `left_domain` when the final estimate is not admissible
    (`is_admissible` on the input's range); `diverged` when it became non-finite or
    exceeded `divergence_bound` (`_solution.finite`), or when a sample's error was not
    finite (NaN or inf in the record: the projection skips such a sample, and the
    status says it happened). `Recursion` carries the figures the status was read
    from.
    """
    u, y = record(u, y, orders=orders, where="recursive", curved=True)
    if init is not None and not isinstance(init, CascadeParams):
        raise TypeError(f"recursive: init must be CascadeParams, got {type(init).__name__}.")
    check_settings(
        lam,
        memory0,
        growth,
        first_samples,
        anti_windup,
        delta,
        every,
        passes,
        acceleration,
        settle_window,
        settle_tolerance,
        noise_tolerance,
    )
    if first_samples >= u.shape[0]:
        raise ValueError(
            f"recursive: first_samples = {first_samples} leaves nothing of a record of "
            f"{u.shape[0]} samples; use fewer."
        )
    return _recursive(
        u,
        y,
        orders,
        init,
        input_range,
        lam=lam,
        memory0=memory0,
        growth=growth,
        acceleration=acceleration,
        first_samples=first_samples,
        anti_windup=anti_windup,
        delta=delta,
        divergence_bound=divergence_bound,
        every=every,
        errors=errors,
        project=project,
        passes=passes,
        gradient=gradient,
        settle_window=settle_window,
        settle_tolerance=settle_tolerance,
        noise_tolerance=noise_tolerance,
    )


def check_settings(
    lam,
    memory0,
    growth,
    first_samples,
    anti_windup,
    delta,
    every,
    passes=1,
    acceleration=0.0,
    settle_window=400,
    settle_tolerance=3.0,
    noise_tolerance=3.0,
):
    """A `ValueError` naming the first bad setting (checked once, before tracing)."""
    if not 0 < lam <= 1:
        raise ValueError(f"recursive: lam must lie in (0, 1], got {lam}.")
    if not memory0 >= 1:
        raise ValueError(f"recursive: memory0 must be at least 1 sample, got {memory0}.")
    if not growth >= 0:
        raise ValueError(f"recursive: growth must be non-negative, got {growth}.")
    if not acceleration >= 0:
        raise ValueError(f"recursive: acceleration must be non-negative, got {acceleration}.")
    if isinstance(first_samples, bool) or not isinstance(first_samples, int | np.integer):
        raise TypeError(f"recursive: first_samples must be an integer, got {first_samples!r}.")
    if first_samples < 0:
        raise ValueError(f"recursive: first_samples must be non-negative, got {first_samples}.")
    if anti_windup not in ANTI_WINDUP:
        raise ValueError(
            f"recursive: unknown anti_windup {anti_windup!r}; known: {', '.join(ANTI_WINDUP)}."
        )
    if not delta > 0:
        raise ValueError(f"recursive: delta must be positive, got {delta}.")
    if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 0:
        raise ValueError(f"recursive: every must be a non-negative integer, got {every!r}.")
    if isinstance(passes, bool) or not isinstance(passes, int | np.integer) or passes < 1:
        raise ValueError(f"recursive: passes must be a positive integer, got {passes!r}.")
    if (
        isinstance(settle_window, bool)
        or not isinstance(settle_window, int | np.integer)
        or settle_window < 2
    ):
        raise ValueError(
            f"recursive: settle_window must be an integer of at least 2 samples, got "
            f"{settle_window!r}."
        )
    for name, value in (
        ("settle_tolerance", settle_tolerance),
        ("noise_tolerance", noise_tolerance),
    ):
        if not value > 0:
            raise ValueError(f"recursive: {name} must be positive, got {value}.")


def _vector(theta, orders):
    """theta (eq. 18, ending in `C = cR mR`) -> `Orders.names` order, without dividing by
    zero (a zero `mR` gives a non-finite `cR`, which `finite` turns into a status)."""
    k = orders.straight_size - 1  # C (the last entry at degree 1)
    mR = theta[k - 1]
    return theta.at[k].set(theta[k] / mR)


def _params(theta, orders):
    k = orders.straight_size - 1  # C (the last entry at degree 1)
    mR = theta[k - 1]
    safe = jnp.where(mR != 0, mR, jnp.finfo(theta.dtype).eps)
    return CascadeParams.from_vector(theta.at[k].set(theta[k] / safe), orders, check=False)


def _after_first(theta, init_theta, orders):
    """The first iteration's estimate: NS and LD coefficients with `D M / M` (a zero
    slope keeps the initial breakpoint), the backlash at its initial values."""
    o = orders
    s = o.slices
    out = jnp.concatenate([theta[o.static_dynamic], init_theta[o.static_dynamic.stop :]])
    for D, M in (("DR", "MR"), ("DL", "ML")):
        DM, slope = out[s[D]], out[s[M]][1:]
        ok = (slope != 0) & jnp.isfinite(DM / jnp.where(slope != 0, slope, 1.0))
        out = out.at[s[D]].set(jnp.where(ok, DM / jnp.where(ok, slope, 1.0), init_theta[s[D]]))
    return out


def _divide_breakpoints(theta, init_theta, orders):
    """theta with breakpoint coefficients `D M` (unit-slope columns) -> `D` (a zero or
    non-finite quotient keeps the initial breakpoint)."""
    s = orders.slices
    out = theta
    for D, M in (("DR", "MR"), ("DL", "ML")):
        DM, slope = theta[s[D]], theta[s[M]][1:]
        ok = (slope != 0) & jnp.isfinite(DM / jnp.where(slope != 0, slope, 1.0))
        out = out.at[s[D]].set(jnp.where(ok, DM / jnp.where(ok, slope, 1.0), init_theta[s[D]]))
    return out


def _hold_breakpoints(proposal, proposed_D, held_at, init_theta, orders, u_min, u_max):
    """`proposal` (breakpoints as `D M`; `proposed_D` the same with `D`, `model`'s
    output) with each breakpoint that is not inside the input range on its side of 0,
    in order (and every one after it), held at its value in `held_at` (`D`
    coordinates): its `D M` becomes that `D` times the proposed slope. Slopes and
    everything else unchanged. Returns the held proposal and its `D` form (a held
    breakpoint whose proposed slope is 0 at its initial value, as `model` gives it)."""
    s = orders.slices
    out, out_D = proposal, proposed_D
    for name, M, outward, edge in (("DR", "MR", 1.0, u_max), ("DL", "ML", -1.0, u_min)):
        d, slope = proposed_D[s[name]], proposal[s[M]][1:]
        previous = jnp.concatenate([jnp.zeros((1,), d.dtype), d[:-1]])
        ok = (outward * (d - previous) > 0) & (outward * (edge - d) > 0)
        ok = jnp.cumprod(ok) > 0
        held = held_at[s[name]]
        out = out.at[s[name]].set(jnp.where(ok, d, held) * slope)
        out_D = out_D.at[s[name]].set(
            jnp.where(ok, d, jnp.where(slope != 0, held, init_theta[s[name]]))
        )
    return out, out_D


def _blocks(orders):
    """`(block1, block2, join, covariance)`: the regression's two blocks, the columns
    that carry g1 (NS, LD, `cL` and the left branch's curvature `mL2..mLq`) and those
    that carry g2 (`mR`, `C` and `mR2..mRq`), taken from a vector in theta order, put
    back together, and their covariances as one matrix in theta order. At degree 1 they
    are the vector's first `g1_columns` entries and the last two."""
    b1, q1, size = orders.g1_columns, orders.degree - 1, orders.size
    if q1 == 0:
        return (
            lambda v: v[:b1],
            lambda v: v[b1:],
            lambda a, b: jnp.concatenate([a, b]),
            jax.scipy.linalg.block_diag,
        )
    straight = orders.straight_size
    first = jnp.asarray(list(range(b1)) + list(range(straight, straight + q1)))
    second = jnp.asarray([b1, b1 + 1] + list(range(straight + q1, size)))

    def join(a, b):
        return jnp.zeros((size,), a.dtype).at[first].set(a).at[second].set(b)

    def covariance(P1, P2):
        P = jnp.zeros((size, size), P1.dtype)
        return (
            P.at[first[:, None], first[None, :]]
            .set(P1)
            .at[second[:, None], second[None, :]]
            .set(P2)
        )

    return (lambda v: v[first], lambda v: v[second], join, covariance)


def _multiply_breakpoints(theta, orders):
    s = orders.slices
    out = theta
    for D, M in (("DR", "MR"), ("DL", "ML")):
        out = out.at[s[D]].set(theta[s[D]] * theta[s[M]][1:])
    return out


@jit(
    static_argnames=(
        "orders",
        "first_samples",
        "anti_windup",
        "every",
        "errors",
        "project",
        "passes",
        "gradient",
        "settle_window",
    )
)
def _recursive(
    u,
    y,
    orders: Orders,
    init: CascadeParams | None,
    input_range,
    *,
    lam,
    memory0,
    growth,
    acceleration,
    first_samples: int,
    anti_windup: str,
    delta,
    divergence_bound,
    every: int,
    errors: bool,
    project: bool,
    passes: int,
    gradient: bool = False,
    settle_window: int = 400,
    settle_tolerance=3.0,
    noise_tolerance=3.0,
) -> Recursion:
    o = orders
    dtype = u.dtype
    y = y.astype(dtype)
    T = u.shape[0]
    if input_range is None:
        u_min, u_max = jnp.min(u), jnp.max(u)
    else:
        u_min, u_max = (jnp.asarray(b, dtype) for b in input_range)
    if init is None:
        init = initial_guess(o, u_min, u_max, dtype)
    init = init.astype(dtype)
    start = init.to_vector()
    init_theta = init.to_theta()
    # the first iteration's switching functions: unit slopes, the initial breakpoints
    # and backlash (`_regression.regression(..., unit_slopes=True)`)
    first_params = _unit_slopes(init)
    W = window(o)
    block1, block2, join, covariance = _blocks(o)
    n1, n2 = o.g1_columns + o.degree - 1, 2 + o.degree - 1
    total = passes * T
    # the status's window: the last `settle_window` samples (fewer when the record after
    # the first iteration is shorter)
    last = max(min(settle_window, total - first_samples), 1)
    window_start = total - last
    trace_max = jnp.asarray(delta, dtype) * o.size

    def model(theta):
        return _divide_breakpoints(theta, init_theta, o)

    def at_switch(theta):
        # the end of the first iteration: its NS and LD estimates and their information
        # stay (breakpoints outside the range back at their initial values), the
        # backlash restarts at its initial values
        kept = jnp.concatenate([theta[o.static_dynamic], init_theta[o.static_dynamic.stop :]])
        return _hold_breakpoints(kept, model(kept), init_theta, init_theta, o, u_min, u_max)[0]

    def step(carry, inputs):
        theta, P1, P2, u_past, y_past, x_past, extra, sq, mark = carry
        k, u_t, y_t, valid = inputs  # k: samples since the start, over all passes
        t = k % T
        first = k < first_samples
        switch = (k == first_samples) & (first_samples > 0)
        # (`switch` does not depend on the record: a real branch under `vmap`)
        theta = jax.lax.cond(switch, at_switch, lambda theta: theta, theta)
        mark = jnp.where(k == window_start, theta, mark)  # the estimate the window starts at
        P2 = jnp.where(switch, delta * jnp.eye(n2, dtype=dtype), P2)
        x_past = jnp.where(switch, y_past, x_past)
        # a new pass starts from rest, as the record does
        restart = (t == 0) & (k > 0)
        u_past, y_past, x_past = (jnp.where(restart, 0.0, z) for z in (u_past, y_past, x_past))
        if gradient:
            Pf, S = extra
            Pf = jnp.where(switch, covariance(P1, P2), Pf)
            S = jnp.where(switch | restart, 0.0, S)

        current_D = model(theta)
        params = _params(current_D, o)
        u_w = jnp.concatenate([u_past, u_t[None]])
        y_w = jnp.concatenate([y_past, y_t[None]])
        v_w = pwl(params, u_w)  # eq. 21 at the window's inputs
        # eq. 22, a1 = 1: x(t) = v(t-1) + a2 v(t-2) + ... - b1 x(t-1) - ...
        a = jnp.concatenate([jnp.ones((1,), dtype), params.a])
        x_t = a @ v_w[W - 2 :: -1][: o.r] - params.b @ x_past[::-1][: o.p]
        x_w = jnp.concatenate([x_past, x_t[None]])
        current = jax.tree.map(lambda f, p: jnp.where(first, f, p), first_params, params)
        phi, yc, g1, g2 = sample_regression(
            current,
            u_w,
            y_w,
            jnp.where(first, u_w, v_w),
            jnp.where(first, y_w, x_w),
            unit_slopes=True,
        )
        error = yc - phi @ theta
        lam_k = forgetting(k - first_samples, lam, memory0, growth, acceleration)
        lam_k = jnp.where(first, 1.0, lam_k)
        new1, new_P1 = update(
            block1(theta),
            P1,
            block1(phi),
            error,
            lam_k,
            valid & (g1 > 0),
            anti_windup=anti_windup,
            trace_max=trace_max,
        )
        new2, new_P2 = update(
            block2(theta),
            P2,
            block2(phi),
            error,
            lam_k,
            valid & (g2 > 0),
            anti_windup=anti_windup,
            trace_max=trace_max,
        )
        proposal = join(new1, new2)
        if gradient:

            def predict(theta_, x_past_):
                p_ = _params(model(theta_), o)
                v_ = pwl(p_, u_w)
                a_ = jnp.concatenate([jnp.ones((1,), dtype), p_.a])
                x_ = a_ @ v_[W - 2 :: -1][: o.r] - p_.b @ x_past_[::-1][: o.p]
                phi_ = sample_regression(
                    p_, u_w, y_w, v_, jnp.concatenate([x_past_, x_[None]]), unit_slopes=True
                )[0]
                return jnp.stack([phi_ @ theta_, x_])

            J_theta, J_x = jax.jacfwd(predict, argnums=(0, 1))(theta, x_past)
            total = J_theta + J_x @ S
            psi, dx_t = total[0], total[1]
            newf, new_Pf = update(
                theta,
                Pf,
                psi,
                error,
                lam_k,
                valid & ~first & (g1 + g2 > 0),
                anti_windup=anti_windup,
                trace_max=trace_max,
            )
            proposal = jnp.where(first, proposal, newf)
        if project:
            # Ljung's projection: an update that takes the estimate out of the model's
            # domain (a breakpoint outside the input range, mR <= 0, an unstable linear
            # block) is not taken. The first iteration's coefficients are no model yet.
            # A breakpoint that would leave the range is held where it is and the rest
            # of the update taken: a slope estimated at exactly 0 (a segment the first
            # iteration never saw) leaves its `D M / M` undefined, and rejecting every
            # update that moves it froze the whole estimate (Example 2, 5 of 60 records).
            proposed_D = model(proposal)
            held, held_D = _hold_breakpoints(
                proposal, proposed_D, current_D, init_theta, o, u_min, u_max
            )
            proposal = jnp.where(first, proposal, held)
            keep = first | is_admissible(_params(held_D, o), u_min, u_max)
        else:
            keep = jnp.asarray(True)
        theta = jnp.where(keep, proposal, theta)
        P1 = jnp.where(keep, new_P1, P1)
        P2 = jnp.where(keep, new_P2, P2)
        if gradient:
            Pf = jnp.where(keep, new_Pf, Pf)
            S = jnp.where(valid, jnp.concatenate([S[1:], dx_t[None]]), S)
            extra = (Pf, S)
        u_past = jnp.where(valid, u_w[1:], u_past)
        y_past = jnp.where(valid, y_w[1:], y_past)
        x_past = jnp.where(valid, x_w[1:], x_past)
        # [sum of squared errors, their count, non-finite samples]: a NaN in the record
        # is never taken by the projection, so it is counted here to reach the status
        finite_error = jnp.isfinite(error)
        counted = jnp.stack(
            [jnp.where(finite_error, error**2, 0.0), jnp.ones((), dtype), (~finite_error) * 1.0]
        )
        sq = sq + jnp.where(valid & (~first | ~finite_error), counted, 0.0)
        estimate = jnp.where(first, _after_first(theta, init_theta, o), model(theta))
        # the samples that update the estimate (a regime active) and those the estimate
        # places in the backlash's dead zone (g1 = g2 = 0: phi = 0, the error is y(t) -
        # y(t-1)), for the status's window
        regime = jnp.where(
            valid & ~first & jnp.isfinite(error), jnp.where(g1 + g2 > 0, _ACTIVE, _DEAD), 0
        ).astype(jnp.int8)
        carry = (theta, P1, P2, u_past, y_past, x_past, extra, sq, mark)
        return carry, (estimate, error, regime)

    zeros = jnp.zeros((W - 1,), dtype)
    carry = (
        _multiply_breakpoints(init_theta, o),
        delta * jnp.eye(n1, dtype=dtype),
        delta * jnp.eye(n2, dtype=dtype),
        zeros,
        zeros,
        zeros,
        (delta * jnp.eye(o.size, dtype=dtype), jnp.zeros((W - 1, o.size), dtype))
        if gradient
        else (),
        jnp.zeros((3,), dtype),
        _multiply_breakpoints(init_theta, o),
    )
    k = jnp.arange(total)
    u_all, y_all = jnp.tile(u, passes), jnp.tile(y, passes)
    valid = jnp.ones((total,), bool)
    if every == 0:

        def plain(carry, inputs):
            carry, (_, error, regime) = step(carry, inputs)
            return carry, (error, regime)

        carry, (error_all, regime_all) = jax.lax.scan(plain, carry, (k, u_all, y_all, valid))
        rows = jnp.zeros((0, o.size), dtype)
    else:
        count = -(-total // every)
        pad = count * every - total

        def blocks(x, fill):
            return jnp.concatenate([x, jnp.full((pad,), fill, x.dtype)]).reshape(count, every)

        inputs = (blocks(k, total), blocks(u_all, 0.0), blocks(y_all, 0.0), blocks(valid, False))

        def block(carry, inputs):
            carry, (estimates, error, regime) = jax.lax.scan(step, carry, inputs)
            return carry, (estimates[-1], error, regime)

        carry, (rows, error_all, regime_all) = jax.lax.scan(block, carry, inputs)
        rows = jax.vmap(lambda row: _vector(row, o))(rows)
        error_all, regime_all = error_all.reshape(-1)[:total], regime_all.reshape(-1)[:total]
    error_out = error_all[-T:] if errors else jnp.zeros((0,), dtype)

    theta, P1, P2, sq, mark = carry[0], carry[1], carry[2], carry[7], carry[8]
    P = carry[6][0] if gradient else covariance(P1, P2)
    check = _settling(
        theta,
        mark,
        P,
        error_all[window_start:],
        regime_all[window_start:],
        # the window's outputs and the one before it (0 at a record's start: from rest)
        jnp.concatenate([jnp.zeros((1,), dtype), y_all])[window_start:],
    )
    vector = _vector(model(theta), o)
    history = jnp.concatenate([start[None, :], rows if every else vector[None, :]], axis=0)
    params = CascadeParams.from_vector(vector, o, check=False)
    admissible = is_admissible(params, u_min, u_max)
    settled = (check.settling <= settle_tolerance) & (check.noise_ratio <= noise_tolerance)
    settled = settled & (check.prediction_error <= check.spread / _MIN_SNR)
    status = jnp.where(
        settled, Status.converged, Status.max_iterations if passes > 1 else Status.tracking
    )
    status = jnp.where(check.updates >= o.size, status, Status.singular)
    status = jnp.where(admissible, status, Status.left_domain)
    bounded = jnp.all(jnp.abs(vector) <= divergence_bound) & (sq[2] == 0)
    status = jnp.where(bounded, status, Status.diverged)
    solution = Solution(
        params=params,
        history=history,
        iterations=jnp.asarray(total, jnp.int32),
        cost=sq[0] / jnp.maximum(sq[1], 1.0),
        status=status.astype(jnp.int32),
        cycle_amplitude=jnp.zeros((), dtype),
        path=jnp.asarray(PATH_ONLY, jnp.int32),
    )
    return Recursion(
        finite(solution, start),
        error_out,
        check.settling,
        check.noise_ratio,
        check.noise_level,
    )


# `regime` codes of a sample in the status's window
_ACTIVE = 1  # g1 or g2 active: the sample updates the estimate
_DEAD = 2  # g1 = g2 = 0: phi = 0 and the error is the output's own step y(t) - y(t-1)
# fewer samples than this in the estimate's dead zone estimate no noise level
_MIN_DEAD = 10
# the fraction of the window's smallest output steps taken as the output at rest
_RESTING = 0.02
# the largest prediction error a converged estimate may have, as a fraction of the
# output's spread (an estimated SNR of 5): a stuck estimate on a system whose output
# never rests makes errors that look like noise at SNR 3-4 (2 of 200 random systems,
# noise-free), and no record can tell those from noise
_MIN_SNR = 5.0


class _Check(NamedTuple):
    settling: Float[Array, ""]
    noise_ratio: Float[Array, ""]
    noise_level: Float[Array, ""]
    prediction_error: Float[Array, ""]
    spread: Float[Array, ""]
    updates: Int[Array, ""]


def _step_quantile(q: float) -> float:
    """The q-quantile of |e(t) - e(t-1)|, e white Gaussian noise of unit variance."""
    return statistics.NormalDist().inv_cdf((1.0 + q) / 2.0) * 2**0.5


def _settling(theta, mark, P, errors, regime, y) -> _Check:
    """What the status says of the last window (module docstring, **Status**): `theta`
    and `mark` the regression's coefficients at its end and start, `P` the recursion's
    covariance at its end, `errors` and `regime` the a-priori errors and regimes of its
    samples, `y` its outputs with the one before it."""
    dtype = theta.dtype
    # rounding: noise-free, the errors and the steps end at this relative size
    tol = jnp.sqrt(jnp.finfo(dtype).eps)
    active, dead = regime == _ACTIVE, regime == _DEAD
    n_active, n_dead = jnp.sum(active), jnp.sum(dead)
    # settled: the change over the window against the standard errors at its end
    s2 = jnp.sum(jnp.where(active, errors**2, 0.0)) / jnp.maximum(n_active, 1)
    se = jnp.sqrt(s2 * jnp.abs(jnp.diag(P)))
    change = jnp.abs(theta - mark)
    settling = jnp.max(change / (se + tol * (1.0 + jnp.abs(theta))))
    # the noise level: where the estimate puts the backlash at rest the error is the
    # output's step, e(t) - e(t-1) if it does rest (lower quartile: robust to samples
    # put there wrongly); and the output's smallest steps, whatever the estimate
    # (exactly 0 noise-free wherever the output rests)
    steps = jnp.sort(jnp.where(dead, jnp.abs(errors), jnp.inf))
    at_rest = steps[jnp.maximum(n_dead - 1, 0) // 4] / _step_quantile(0.25)
    n = y.shape[0] - 1
    k = max(int(_RESTING * n), 1)
    smallest = jnp.sort(jnp.abs(jnp.diff(y)))[k - 1] / _step_quantile((k - 0.5) / n)
    noise_level = jnp.where(n_dead >= _MIN_DEAD, jnp.minimum(at_rest, smallest), 0.0)
    # the prediction error: RMS over the window, a step (two noise samples) counted half
    normalised = jnp.where(active, errors**2, jnp.where(dead, 0.5 * errors**2, 0.0))
    prediction_error = jnp.sqrt(jnp.sum(normalised) / jnp.maximum(n_active + n_dead, 1))
    scale = jnp.sqrt(jnp.mean(y[1:] ** 2))
    return _Check(
        settling=settling,
        noise_ratio=prediction_error / (noise_level + tol * scale),
        noise_level=noise_level,
        prediction_error=prediction_error,
        spread=jnp.std(y[1:]),
        updates=n_active,
    )


def _unit_slopes(params: CascadeParams) -> CascadeParams:
    """`params` with every slope increment 1 (the first iteration's switching functions)."""
    vector = params.to_vector()
    s = params.orders.slices
    vector = vector.at[s["MR"]].set(1.0).at[s["ML"]].set(1.0)
    return CascadeParams.from_vector(vector, params.orders, check=False)


# The settings for a noise-free record (module docstring, **Noise-free settings**).
NOISE_FREE = {"gradient": True, "lam": 0.95}

# `recursive`'s settings and their defaults: the one place they are written down.
_RECURSIVE = keyword_defaults(recursive)


class Recursive(Estimator):
    """The recursive least-squares form of the paper's estimator (`recursive`), one pass
    over the record, from the paper's initial values (`input_range` as for `Literal`).
    The settings are `recursive`'s; `every > 0` keeps the estimate every `every` samples
    in `Solution.history`."""

    name: ClassVar[str] = "recursive"
    summary: ClassVar[str] = (
        "the key-term regression (eqs. 16-18) by recursive least squares with forgetting"
    )
    # the settings `jaxcascade reproduce --snr inf` uses (module docstring)
    noise_free: ClassVar[dict] = NOISE_FREE

    lam: float = setting(_RECURSIVE["lam"])
    memory0: float = setting(_RECURSIVE["memory0"])
    growth: float = setting(_RECURSIVE["growth"])
    acceleration: float = setting(_RECURSIVE["acceleration"])
    first_samples: int = setting(_RECURSIVE["first_samples"])
    anti_windup: str = setting(_RECURSIVE["anti_windup"])
    delta: float = setting(_RECURSIVE["delta"])
    divergence_bound: float = setting(_RECURSIVE["divergence_bound"])
    project: bool = setting(_RECURSIVE["project"])
    passes: int = setting(_RECURSIVE["passes"])
    gradient: bool = setting(_RECURSIVE["gradient"])
    every: int = setting(_RECURSIVE["every"])
    settle_window: int = setting(_RECURSIVE["settle_window"])
    settle_tolerance: float = setting(_RECURSIVE["settle_tolerance"])
    noise_tolerance: float = setting(_RECURSIVE["noise_tolerance"])

    def __check_init__(self):
        check_settings(
            self.lam,
            self.memory0,
            self.growth,
            self.first_samples,
            self.anti_windup,
            self.delta,
            self.every,
            self.passes,
            self.acceleration,
            self.settle_window,
            self.settle_tolerance,
            self.noise_tolerance,
        )

    def __call__(
        self,
        u: Float[Array, " T"],
        y: Float[Array, " T"],
        orders: Orders,
        *,
        key: PRNGKeyArray | None = None,
        input_range: tuple[float, float] | None = None,
    ) -> Solution:
        del key  # deterministic
        u, y = record(u, y, orders=orders, where="Recursive", curved=True)
        if input_range is not None and not any(is_traced(b) for b in input_range):
            if not float(input_range[0]) < 0 < float(input_range[1]):
                raise ValueError(
                    f"Recursive: the input range {tuple(map(float, input_range))} must "
                    "contain 0 strictly (the initial breakpoints split each side of 0)."
                )
        return recursive(
            u,
            y,
            orders,
            lam=self.lam,
            memory0=self.memory0,
            growth=self.growth,
            acceleration=self.acceleration,
            first_samples=self.first_samples,
            anti_windup=self.anti_windup,
            delta=self.delta,
            divergence_bound=self.divergence_bound,
            project=self.project,
            passes=self.passes,
            gradient=self.gradient,
            every=self.every,
            input_range=input_range,
            settle_window=self.settle_window,
            settle_tolerance=self.settle_tolerance,
            noise_tolerance=self.noise_tolerance,
        ).solution
