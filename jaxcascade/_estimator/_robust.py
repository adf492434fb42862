"""Robust estimation: the literal iteration refined by output-error least squares, with a
multi-start fallback, batched.

The paper's iteration is a fixed-point map without a convergence guarantee; the
simulation-error landscape is friendlier (METHOD.md). This estimator

1. (adaptive path) runs the literal iteration (`voros`, 30 iterations) and refines its
   estimate, or its second iterate where the iteration ended unusable (`_ITERATE`), by
   Levenberg-Marquardt on the simulation error of the whole record (`adaptive_steps`
   steps at most: under `vmap` every record runs as many steps as the slowest, and the
   fits that pass need few, at most 21 on Example 1's benchmark records). The fit
   passes if it converged, explains the output and its residual looks like
   measurement noise (`_basin.residual_statistic <= threshold`, half of it for a fit
   from the iterate: white and uncorrelated with the input), or the fit is exact to
   rounding: then it is the estimate, `Solution.path == PATH_ADAPTIVE`. The iterate
   matters where the literal iteration drifts away from the true basin after a few
   steps (Example 2 under noise, most random systems): on the benchmark's records the
   adaptive path accepts 162 of 256 Example 2 fits instead of 89, 87 random-family
   fits instead of 68. Calibration of the bound, on the literal estimate's fits, 32
   records each of both examples (SNR 25) and the random family (SNR 30): the 48
   true-basin fits of the examples gave at most 3.3; the 16 wrong-basin fits of Example
   2, 47 or more; of the 23 random-family fits not within 0.05 of the truth, 21 gave 24
   or more, two 2.3 and 4.5 (accepted, not recovered);
2. otherwise (`PATH_MULTISTART`) it draws `n_starts` initial values from the random-
   system prior in one draw (`_prior.random_systems`, with the breakpoints scaled to the
   record's input range), adds the estimate of step 1 as one more start
   (`literal_start`), refines every start on the simulation error of the first `subset`
   samples (`vmap` over starts), keeps the `n_refine` best by simulation error on the
   whole record and refines them on the whole record;
3. restarts that refinement once from the best and keeps the lower cost, with its
   status, except that the fit counts as converged when the restart moved neither the
   estimate nor the cost by more than `rtol` (relative);
4. submits that estimate to step 1's basin test and, while it fails, repeats steps 2-3
   from fresh draws of the prior (`retries` times at most), keeping an estimate that
   passes, or else the cheapest. On 256 random-family records (N 3000, SNR 30) four of
   the 13 estimates not within 0.05 of the truth came from a multi-start that ended in
   a wrong basin (NRMSE 0.035-0.54 against a noise floor of 0.033, statistic 6-4850);
   the others were at the noise floor (pole-zero near-cancellations) or accepted in
   step 1. With two retries the benchmark's random family (`jaxcascade bench
   --estimator robust --system random`) recovered 244 of 256 instead of 243 (one of the
   four), and 245 with the starts of step 2 drawn at once (other draws);
5. says `converged` only where the data say the estimate is theirs (`_basin.claim`):
   an estimate that never passed the basin test (the cheapest of the attempts is still
   returned) is `local_minimum` unless its residual, whitened by an AR model, passes
   Billings and Voon's correlation tests (the coloured noise `robust` is consistent
   under, but whose residual is not white); one with a breakpoint on the edge of the
   input's range is `on_edge`. Noise-free, 2 of 300 records of `results/status_honesty.md`
   were `converged` up to 1.9e3 from the truth before this step.

Batching. Under `vmap` the multi-start of step 2 runs only for the records whose step 1
failed: a batching rule (`jax.custom_batching.custom_vmap`) gathers them, `fallback_batch`
at a time, into a smaller batch inside the compiled program (a `while_loop` over rounds,
as many as needed, a retry of step 4 queued like a first attempt), and scatters the
results back. Without `vmap` a `lax.cond` skips it. Every attempt runs the same
compiled multi-start: retries cost run time on the records that need them, no compile
time.

Levenberg-Marquardt is this package's (`_levenberg`, on normal equations formed by
forward sensitivities, `_sensitivity`). Tolerances: it stops after an accepted step that
moves every (unconstrained) parameter by less than `atol + rtol |z|` and every residual
sample by less than `atol + rtol |residual|`, or that changed the sum of squares by less
than `rtol` (relative, as predicted); the defaults, `rtol = 1e-6` and `atol = 1e-9`, are
those of MATLAB's `lsqnonlin` (StepTolerance and FunctionTolerance 1e-6) and lie three
orders of magnitude below the statistical precision of the estimates (standard
deviations >= 1e-3 at SNR 50). With the backlash's switching instants moving under every
step the cost is piecewise smooth: without the cost test the fit creeps along a kink at
its minimum until `max_steps` (`_levenberg`).

Every iterate is admissible by construction (`_refine.from_unconstrained`), so the
result is never NaN; a start that fails is simply outranked.
"""

from __future__ import annotations

import functools
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.custom_batching import custom_vmap
from jaxtyping import Array, Float, PRNGKeyArray

from .._compile import exported
from .._status import Status
from .._system import _scans
from .._system._model import CascadeParams, Orders, is_admissible
from .._system._prior import random_systems
from .._system._validate import record
from . import _fused
from ._base import Estimator, curved_form, keyword_defaults, setting
from ._basin import claim, residual_statistic
from ._literal import initial_guess, voros
from ._refine import refine, simulation_error
from ._sensitivity import output_jacobian
from ._solution import PATH_ADAPTIVE, PATH_MULTISTART, Solution, finite

# Step 1's start where the literal iteration ends unusable (singular, out of the domain,
# out of iterations): its second iterate (history row; 1 is the paper's first
# iteration), whose fit must pass the basin test with this fraction of its bound.
# Measured on the benchmark's 256 records (seed 0) of Example 2 (SNR 25) and of the
# random family (SNR 30), where the iteration ends unusable on 203 and 217: the fits
# from the literal estimate passed on 89 and 68 (at most 50 steps), from this start
# 162 and 87 (at most 20 steps). The iteration drifts away from the true basin after
# its first steps. Iterate fits that pass with the full bound but end in a neighbouring
# minimum (12-30% above the truth's cost, statistic 2.7-4.9) cost the random family 3
# recovered records; with half the bound 2 of the 87 accepted fits are not within 0.05
# of the truth (4 of the 68 before).
_ITERATE = 2
_ITERATE_BOUND = 0.5
# The fewest records of a multi-start round under `vmap` on an accelerator
# (`_scans.parallel`), whatever `fallback_batch`: there a round of 64 records costs
# about what a round of 4 does, and each round is a sequence of loops whose steps are
# kernel launches. The records and their estimates are the same; only how many run
# side by side changes.
ACCELERATOR_ROUND = 64


def _best(costs, k):
    costs = jnp.where(jnp.isfinite(costs), costs, jnp.inf)
    return jnp.argsort(costs)[:k]


def _take(tree, index):
    return jax.tree_util.tree_map(lambda leaf: leaf[index], tree)


def robust(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    key: PRNGKeyArray | None = None,
    *,
    n_starts: int = 16,
    n_refine: int = 3,
    subset: int = 1000,
    max_steps: tuple[int, int] = (30, 100),
    literal_start: bool = True,
    rtol: float = 1e-6,
    atol: float = 1e-9,
    adaptive: bool = True,
    threshold: float = 5.0,
    adaptive_steps: int = 20,
    fallback_batch: int = 4,
    retries: int = 2,
) -> Solution:
    """Output-error estimate of one record (see module docstring).

    **Arguments:**

    - `u`, `y`: `Float[Array, " T"]` input and measured output (lists and NumPy arrays
      are converted, to the default float dtype; `_validate.record` says what is
      refused, with a `ValueError` or `TypeError`, before anything is compiled).
    - `orders`: static model orders.
    - `key`: PRNG key for the starts; a fixed default keeps the estimator deterministic.
    - `rtol`, `atol`: Levenberg-Marquardt's termination tolerances (module docstring).
    - `adaptive`: try step 1 first (default); `False` always runs the multi-start.
    - `threshold`: the residual statistic's acceptance bound of step 1.
    - `fallback_batch`: records per multi-start round under `vmap`. A round runs as long
      as its slowest fit, and as wide as `fallback_batch` whatever the number of records
      still pending: on the random family's benchmark (256 records, 168 of them on the
      multi-start) 4 gave 1.3 times the fits per CPU second of 8 (alternated runs), 2
      about the same as 4. On an accelerator a round is at least `ACCELERATOR_ROUND`
      (64) records wide.
    - `retries`: further multi-starts, each from fresh draws, for a record whose
      multi-start estimate fails the basin test (module docstring, step 4).
    - `max_steps`: Levenberg-Marquardt's budgets on the subset and on the whole record
      (multi-start path). Under `vmap` a batch runs as long as its slowest member, so
      the budgets set the multi-start's cost. On 32 random-family records (27 on this
      path) (30, 50) recovered the same 27 as the earlier (60, 150) at about twice the
      speed, one of them out of steps; (30, 100) gives the whole-record stage room.

    **Returns:** a `Solution` whose `history` has three rows (chosen start, after the
    subset stage or after the literal iteration, final), `iterations` the
    Levenberg-Marquardt steps of the chosen start, `cost` the mean squared simulation
    error and `path` the path taken (`PATH_ADAPTIVE`, `PATH_MULTISTART`). The status is
    `no_improvement` where the fit would otherwise count as usable but explains none of
    the output (cost not below `var(y)`, NRMSE >= 1) or never moved from a random start
    (`judge`).
    """
    u, y = record(u, y, orders=orders, where="robust")
    for name, value in (
        ("n_starts", n_starts),
        ("n_refine", n_refine),
        ("subset", subset),
        ("adaptive_steps", adaptive_steps),
        ("fallback_batch", fallback_batch),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"robust: {name} must be an integer >= 1, got {value!r}.")
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ValueError(f"robust: retries must be an integer >= 0, got {retries!r}.")
    return _robust(
        u,
        y,
        orders,
        key,
        n_starts=n_starts,
        n_refine=n_refine,
        subset=subset,
        max_steps=tuple(max_steps),
        literal_start=literal_start,
        rtol=rtol,
        atol=atol,
        adaptive=adaptive,
        threshold=float(threshold),
        adaptive_steps=adaptive_steps,
        fallback_batch=fallback_batch,
        retries=retries,
    )


# `robust`'s keyword defaults: the one place they are written (`_robust`, `Robust`)
DEFAULTS = keyword_defaults(robust)


class _Stage(eqx.Module):
    # what step 1 hands on: its fit and whether it is accepted
    solution: Solution
    accepted: Array
    start: Array  # the estimate of step 1: a start of the multi-start
    usable: Array  # whether that estimate is an estimate itself (`_adaptive`)


def _robust(u, y, orders: Orders, key: PRNGKeyArray | None = None, **settings) -> Solution:
    """The jitted core of `robust`, which checks the record first; a setting not given
    takes `robust`'s default."""
    return _core(u, y, orders, key, **{**DEFAULTS, **settings})


@exported(custom_calls=(_fused.TARGET,), prepare=_fused.available)
def _core(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    key: PRNGKeyArray | None,
    *,
    n_starts: int,
    n_refine: int,
    subset: int,
    max_steps: tuple[int, int],
    literal_start: bool,
    rtol: float,
    atol: float,
    adaptive: bool,
    threshold: float,
    adaptive_steps: int,
    fallback_batch: int,
    retries: int,
) -> Solution:
    dtype = u.dtype
    y = y.astype(dtype)
    key = jax.random.PRNGKey(0) if key is None else key
    settings = dict(
        n_starts=n_starts,
        n_refine=n_refine,
        subset=subset,
        max_steps=max_steps,
        literal_start=literal_start,
        rtol=rtol,
        atol=atol,
    )
    stage = _adaptive(u, y, orders, rtol=rtol, atol=atol, steps=adaptive_steps, bound=threshold)
    if not adaptive:
        stage = eqx.tree_at(lambda s: s.accepted, stage, jnp.zeros((), bool))
    multistart = functools.partial(_tested, orders=orders, threshold=threshold, **settings)
    fit = _fallback(multistart, fallback_batch, retries)
    solution = fit(u, y, key, stage)
    # never `converged` outside the model's domain (the literal start can end on its edge)
    inside = is_admissible(solution.params, jnp.min(u), jnp.max(u))
    status = jnp.where(inside | _failed(solution.status), solution.status, Status.left_domain)
    # nor where the data do not say it is their estimate (step 5, `_basin.claim`)
    simulated, jacobian = output_jacobian(solution.params, u)
    status = claim(status, solution.params, simulated - y, u, y, threshold, jacobian=jacobian)
    return eqx.tree_at(lambda s: s.status, solution, status.astype(solution.status.dtype))


def _adaptive(u, y, orders, *, rtol, atol, steps, bound) -> _Stage:
    """Step 1: the literal iteration, refined on the whole record from its estimate, or
    from an early iterate (`_ITERATE`) where it ended unusable, and the basin test."""
    dtype = u.dtype
    init = initial_guess(orders, jnp.min(u), jnp.max(u), dtype)
    literal = voros(u, y, orders, init, max_iterations=30)
    ended = ~_failed(literal.status)
    # the iterates past the iteration's end repeat its estimate (`voros`)
    candidate = jnp.where(ended, literal.params.to_vector(), literal.history[_ITERATE])
    finite_start = jnp.all(jnp.isfinite(candidate))
    start = jnp.where(finite_start, candidate, init.to_vector())
    fit = refine(
        CascadeParams.from_vector(start, orders, check=False),
        u,
        y,
        max_steps=steps,
        rtol=rtol,
        atol=atol,
    )
    # the start is an estimate (the literal one, one of its iterates, or the paper's
    # initial values): a fit that stays there is not stuck at a random draw
    status = judge(fit.status, fit.cost, y, start, fit.params.to_vector(), True, rtol)
    accepted = _in_basin(
        fit.params, status, fit.cost, u, y, jnp.where(ended, 1.0, _ITERATE_BOUND) * bound
    )
    # the multi-start's literal start (this fit's estimate) is an estimate itself: the
    # fit started from the literal estimate of an iteration that ended usable, or from
    # an iterate (not a random draw)
    usable = finite_start
    estimate = fit.params.to_vector()
    solution = Solution(
        params=fit.params,
        history=jnp.stack([init.to_vector(), start, estimate]),
        iterations=fit.steps.astype(jnp.int32),
        cost=fit.cost,
        status=status,
        cycle_amplitude=jnp.zeros((), dtype),
        path=jnp.asarray(PATH_ADAPTIVE, jnp.int32),
    )
    return _Stage(finite(solution, start), accepted, estimate, usable)


def _in_basin(params, status, cost, u, y, bound):
    """The basin test: a converged fit inside the domain whose residual looks like
    measurement noise (`_basin.residual_statistic <= bound`), or that is exact."""
    statistic = residual_statistic(simulation_error(params, u, y), u)
    # a fit to rounding (NRMSE <= 1e-10, noise-free records) is exact: its residual is
    # rounding error, whose whiteness says nothing
    exact = cost <= 1e-20 * jnp.var(y)
    # an estimate on the domain's edge (a breakpoint at 0 where the literal estimate had
    # the wrong sign) is not a fit in the true basin, whatever its residual
    admissible = is_admissible(params, jnp.min(u), jnp.max(u))
    return (status == Status.converged) & ((statistic <= bound) | exact) & admissible


def _tested(u, y, key, stage, *, threshold, **settings):
    """The multi-start (`_multistart`) and whether its estimate passes the basin test."""
    solution = _multistart(u, y, key, stage, **settings)
    passed = _in_basin(solution.params, solution.status, solution.cost, u, y, threshold)
    return solution, passed


def _keep(old, old_passed, new, new_passed, first):
    """Which of two multi-start results to keep: the first attempt's always (it replaces
    step 1's rejected fit), later the one that passes the basin test, else the cheaper."""
    better = new.cost < old.cost
    take = first | (new_passed & ~old_passed) | ((new_passed == old_passed) & better)
    kept = jax.tree_util.tree_map(lambda n, o: jnp.where(take, n, o), new, old)
    return kept, jnp.where(take, new_passed, old_passed)


def _attempt_key(key, attempt):
    # attempt 0 uses the record's key itself (the draws of a single multi-start)
    return jnp.where(attempt == 0, key, jax.random.fold_in(key, attempt))


def _fallback(multistart, size: int, retries: int):
    """`(u, y, key, stage) -> Solution`: the stage's solution where accepted, else the
    multi-start's, repeated from fresh draws (up to `retries` more times) while its
    estimate fails the basin test; under `vmap` the multi-start runs on the failures
    only (module docstring)."""

    @custom_vmap
    def fit(u, y, key, stage):
        def more(carry):
            attempt, _, passed = carry
            return (attempt <= retries) & ~passed

        def attempt(carry):
            i, best, passed = carry
            new, ok = multistart(u, y, _attempt_key(key, i), stage)
            best, passed = _keep(best, passed, new, ok, i == 0)
            return i + 1, best, passed

        def search():
            start = (jnp.zeros((), jnp.int32), stage.solution, jnp.zeros((), bool))
            return jax.lax.while_loop(more, attempt, start)[1]

        return jax.lax.cond(stage.accepted, lambda: stage.solution, search)

    @fit.def_vmap
    def rule(axis_size, in_batched, u, y, key, stage):
        def batched(leaf, flag):
            return leaf if flag else jnp.broadcast_to(leaf, (axis_size, *jnp.shape(leaf)))

        u, y, key, stage = jax.tree_util.tree_map(batched, (u, y, key, stage), tuple(in_batched))
        # on an accelerator a round's width costs little of its time: wider rounds, fewer
        # of them (each a loop over Levenberg-Marquardt steps)
        width = min(max(size, ACCELERATOR_ROUND) if _scans.parallel() else size, axis_size)

        def more(carry):
            return jnp.any(carry[0])

        # Each round takes the first `width` records still pending (the rest of the
        # round points at records it does not change), runs their next attempt and
        # scatters the results back; a record stays pending while its estimate fails
        # the basin test and it has attempts left.
        def one_round(carry):
            pending, attempts, passed, out = carry
            index = jnp.argsort(~pending, stable=True)[:width]
            valid = pending[index]
            chosen_key = jax.vmap(_attempt_key)(key[index], attempts[index])
            result, ok = jax.vmap(multistart)(u[index], y[index], chosen_key, _take(stage, index))
            kept, kept_passed = jax.vmap(_keep)(
                _take(out, index), passed[index], result, ok, attempts[index] == 0
            )
            target = jnp.where(valid, index, axis_size)  # out of range: dropped

            def scatter(whole, part):
                return whole.at[target].set(part, mode="drop")

            out = jax.tree_util.tree_map(scatter, out, kept)
            passed = scatter(passed, kept_passed)
            attempts = scatter(attempts, attempts[index] + 1)
            pending = scatter(pending, ~kept_passed & (attempts[index] <= retries))
            return pending, attempts, passed, out

        start = (
            ~stage.accepted,
            jnp.zeros((axis_size,), jnp.int32),
            jnp.zeros((axis_size,), bool),
            stage.solution,
        )
        out = jax.lax.while_loop(more, one_round, start)[3]
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return fit


def _multistart(
    u,
    y,
    key,
    stage: _Stage,
    *,
    orders,
    n_starts,
    n_refine,
    subset,
    max_steps,
    literal_start,
    rtol,
    atol,
) -> Solution:
    """Steps 2 and 3 (module docstring) for one record."""
    dtype = u.dtype
    tolerances = {"rtol": rtol, "atol": atol}
    u_max = 0.5 * (jnp.max(u) - jnp.min(u))
    starts = (
        random_systems(key, n_starts, orders, 1.0, dtype)
        .to_vector()
        .at[:, jnp.array(orders.breakpoints, int)]
        .multiply(u_max)
    )
    if literal_start:
        starts = jnp.concatenate([starts, stage.start[None].astype(dtype)])
    starts = CascadeParams.from_vector(starts, orders, check=False)

    n = min(subset, u.shape[0])
    first = jax.vmap(lambda p: refine(p, u[:n], y[:n], max_steps=max_steps[0], **tolerances))(
        starts
    )
    full_cost = jax.vmap(lambda p: jnp.mean(simulation_error(p, u, y) ** 2))(first.params)
    chosen = _best(full_cost, n_refine)

    # The refinement of the best and its restart from the best (below) are one call
    # site, a scan of two phases: one compiled copy of Levenberg-Marquardt, not two.
    def phase(carry, _):
        fits = jax.vmap(lambda p: refine(p, u, y, max_steps=max_steps[1], **tolerances))(carry)
        best = _best(fits.cost, 1)[0]
        again = jax.tree_util.tree_map(
            lambda leaf: jnp.broadcast_to(leaf[best], leaf.shape), fits.params
        )
        return again, (fits, best)

    _, (phases, bests) = jax.lax.scan(phase, _take(first.params, chosen), None, length=2)
    second, best = _take(phases, 0), bests[0]
    final = _take(second, best)
    # The backlash makes the simulation error piecewise smooth: one restart from the
    # chosen estimate tells a minimum on a kink (it terminates within a few steps, or
    # moves neither the estimate nor the cost by more than `rtol`, relative, the
    # criterion of MATLAB's lsqnonlin) from a fit that is still going somewhere.
    restart = _take(_take(phases, 1), 0)
    before, after = final.params.to_vector(), restart.params.to_vector()
    moved = jnp.max(jnp.abs(after - before) / (1 + jnp.abs(before)))
    settled = (moved <= rtol) & (jnp.abs(restart.cost - final.cost) <= rtol * final.cost)
    final = jax.tree_util.tree_map(
        lambda again, first: jnp.where(restart.cost <= final.cost, again, first), restart, final
    )
    status = jnp.where(settled, Status.converged, final.status)
    final = eqx.tree_at(lambda r: (r.steps, r.status), final, (final.steps + restart.steps, status))
    history = jnp.stack(
        [
            starts.to_vector()[chosen[best]],
            first.params.to_vector()[chosen[best]],
            final.params.to_vector(),
        ]
    )
    # A start the fit may end on unmoved: step 1's estimate, when it is one itself.
    trusted = (chosen[best] == n_starts) & stage.usable if literal_start else False
    solution = Solution(
        params=final.params,
        history=history,
        iterations=(first.steps[chosen[best]] + final.steps).astype(jnp.int32),
        cost=final.cost,
        status=judge(final.status, final.cost, y, history[0], history[-1], trusted, rtol),
        cycle_amplitude=jnp.zeros((), dtype),
        path=jnp.asarray(PATH_MULTISTART, jnp.int32),
    )
    return finite(solution, history[0])


def _failed(status):
    return (status != Status.converged) & (status != Status.cycled)


def judge(status, cost, y, start, estimate, trusted_start, rtol: float):
    """The final status of a robust fit: `status`, unless it says the estimate is usable
    while the fit explains none of the output (`cost`, the mean squared simulation error,
    not below `var(y)`: NRMSE >= 1, or non-finite) or the estimate never moved (by more
    than `rtol`, relative) from a start that was no estimate itself (`trusted_start`
    False: a random draw, or a failed literal fit). Then `no_improvement`: the
    restart of step 4 counts a fit that does not move as converged, which is right at
    a minimum and wrong at a start Levenberg-Marquardt could not leave. Traceable.
    """
    explains = cost < jnp.var(y)
    moved = jnp.max(jnp.abs(estimate - start) / (1 + jnp.abs(start))) > rtol
    useless = ~explains | (~moved & ~jnp.asarray(trusted_start))
    return jnp.where(~_failed(status) & useless, Status.no_improvement, status).astype(jnp.int32)


class Robust(Estimator):
    """The literal iteration refined by output-error least squares, with a multi-start
    fallback (`robust`, module docstring); the settings are `robust`'s keyword
    arguments. For orders with curved backlash branches (`Orders.degree > 1`) that fit
    is then refined with the branches' curvature (`_general_refine.curved_solution`)."""

    name: ClassVar[str] = "robust"
    summary: ClassVar[str] = (
        "output-error Levenberg-Marquardt from the literal estimate, multi-start fallback"
    )

    n_starts: int = setting(DEFAULTS["n_starts"])
    n_refine: int = setting(DEFAULTS["n_refine"])
    subset: int = setting(DEFAULTS["subset"])
    max_steps: tuple[int, int] = setting(DEFAULTS["max_steps"])
    literal_start: bool = setting(DEFAULTS["literal_start"])
    rtol: float = setting(DEFAULTS["rtol"])
    atol: float = setting(DEFAULTS["atol"])
    adaptive: bool = setting(DEFAULTS["adaptive"])
    threshold: float = setting(DEFAULTS["threshold"])
    adaptive_steps: int = setting(DEFAULTS["adaptive_steps"])
    fallback_batch: int = setting(DEFAULTS["fallback_batch"])
    retries: int = setting(DEFAULTS["retries"])

    def __call__(
        self,
        u: Float[Array, " T"],
        y: Float[Array, " T"],
        orders: Orders,
        *,
        key: PRNGKeyArray | None = None,
        input_range: tuple[float, float] | None = None,
    ) -> Solution:
        del input_range  # the starts are scaled to the record's own range
        u, y = record(u, y, orders=orders, where="Robust", curved=True)
        settings = {name: getattr(self, name) for name in DEFAULTS}
        if orders.degree > 1:
            # curved branches: the straight fit, then the curvature (`_general_refine`)
            return curved_form(self.name)(u, y, orders, key, **settings)
        return robust(u, y, orders, key, **settings)
