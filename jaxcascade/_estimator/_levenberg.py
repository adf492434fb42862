"""A small Levenberg-Marquardt for one record's least-squares problem (`vmap`-able).

Why not optimistix's: the robust estimator runs thousands of small problems (P ~ 13)
side by side under `vmap`, and each of its steps needs only the Gauss-Newton normal
equations `J^T J`, `J^T r`, which `_sensitivity` forms without materialising a
Jacobian-vector product per parameter. The linear algebra is `_linalg`'s plain-loop
Gauss-Jordan solve (`spd_solve`, one loop): batched LAPACK calls deadlock XLA's CPU
thread pool in this jaxlib.

The algorithm (Marquardt 1963 with Nielsen's damping update, as in Madsen, Nielsen and
Tingleff, "Methods for non-linear least squares problems", 2004, sec. 3.2): the step
solves `(J^T J + lam diag(J^T J)) delta = -J^T r`; it is accepted when the cost falls
(gain ratio `rho > 1e-4`), then `lam *= max(1/3, 1 - (2 rho - 1)^3)`, else `lam *= nu`,
`nu *= 2`. A non-finite trial point or a failed factorisation is a rejected step.

Termination (`converged`), with `rtol` and `atol`:

- an accepted step that moves every parameter by at most `atol + rtol |z|` and every
  residual by at most `atol + rtol |r|` (optimistix's Cauchy test);
- or an accepted step that lowered the sum of squares by at most `rtol` (relative) and
  was predicted to lower it by no more (MATLAB `lsqnonlin` stops on either its
  StepTolerance or its FunctionTolerance). This one matters for the backlash: where a
  step moves a switching instant the cost is kinked, and Levenberg-Marquardt creeps
  along the kink with relative cost changes of 1e-8 and steps of a few hundredths of a
  standard error, for tens of steps, without the per-parameter test ever holding;
- or a rejected step that moves no parameter beyond `atol + rtol |z|`: the damped step
  cannot move the estimate beyond the tolerance and still not lower the cost.

Otherwise `max_iterations` when `max_steps` run out, `diverged` when the start's cost is
not finite (the start is returned).

`least_squares` is a second method on the same normal equations, for any residual
function (the model-error loop's): optimistix's Levenberg-Marquardt step for step, with
the Jacobian by forward mode and the normal equations solved by `spd_solve`.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from .._compile import carried_like
from .._linalg import spd_solve
from .._status import Status

_RUNNING = -1


def levenberg_marquardt(
    evaluate: Callable,
    z0,
    *,
    max_steps: int = 100,
    rtol: float = 1e-6,
    atol: float = 1e-9,
    damping: float = 1e-3,
    residual_size: int | None = None,
):
    """Minimise `|r(z)|^2` from `z0`; `evaluate(z) -> (r, JtJ, Jtr)` with `r` the
    residual (`" T"`, `T = residual_size` when given: otherwise `evaluate` is traced
    once more to find it) and `JtJ` (`"P P"`), `Jtr` (`" P"`) its Gauss-Newton normal
    equations. Never raises.

    **Returns:** `(z, cost, status, steps)`: the estimate, its mean squared residual
    (`inf` if non-finite), a `Status` code and the number of steps taken.
    """
    dtype = z0.dtype

    # The start is evaluated by the loop's first pass (a zero step, always accepted when
    # finite): one copy of `evaluate` in the compiled program, not two.
    def running(state):
        return (state[8] == _RUNNING) & (state[7] <= max_steps)  # status, step

    def body(state):
        z, r, cost, JtJ, Jtr, lam, nu, step, status = state
        diagonal = jnp.diag(JtJ)
        scale = jnp.maximum(diagonal, 1e-12 * jnp.max(diagonal) + jnp.finfo(dtype).tiny)
        solution, factored = spd_solve(JtJ + lam * jnp.diag(scale), Jtr)
        first = step == 0
        delta = jnp.where(first, 0.0, -solution)
        z_new = z + delta
        r_new, JtJ_new, Jtr_new = evaluate(z_new)
        cost_new = r_new @ r_new
        predicted = -(delta @ Jtr) - 0.5 * delta @ (JtJ @ delta)
        rho = 0.5 * (cost - cost_new) / predicted
        finite = (
            jnp.isfinite(cost_new)
            & jnp.all(jnp.isfinite(JtJ_new))
            & jnp.all(jnp.isfinite(Jtr_new))
            & jnp.all(jnp.isfinite(delta))
        )
        accept = finite & (first | (factored & (predicted > 0) & (rho > 1e-4)))
        small_step = jnp.all(jnp.abs(delta) <= atol + rtol * jnp.abs(z_new))
        cauchy = small_step & jnp.all(jnp.abs(r_new - r) <= atol + rtol * jnp.abs(r_new))
        flat = (cost - cost_new <= rtol * cost) & (2 * predicted <= rtol * cost)
        done = jnp.where(accept, cauchy | flat, factored & finite & small_step) & ~first
        status = jnp.where(done, Status.converged, status)
        status = jnp.where(first & ~finite, Status.diverged, status).astype(jnp.int32)
        lam_new = jnp.where(accept, lam * jnp.maximum(1 / 3, 1 - (2 * rho - 1) ** 3), lam * nu)
        lam_new = jnp.where(first, lam, lam_new)
        nu_new = jnp.where(accept, 2.0, 2 * nu)

        def pick(new, old):
            return jnp.where(accept, new, old)

        return (
            pick(z_new, z),
            pick(r_new, r),
            pick(cost_new, cost),
            pick(JtJ_new, JtJ),
            pick(Jtr_new, Jtr),
            jnp.clip(lam_new, 1e-12, 1e16).astype(dtype),
            nu_new.astype(dtype),
            step + 1,
            status,
        )

    one = jnp.ones((), dtype)
    size = z0.shape[0]
    # every element of the carry a value of `z0`: under `vmap` the loop's body is traced
    # once less (`_compile.carried_like`)
    state = (
        z0,
        *carried_like(
            z0,
            (
                jnp.zeros(
                    (residual_size,) if residual_size else jax.eval_shape(evaluate, z0)[0].shape,
                    dtype,
                ),
                jnp.asarray(jnp.inf, dtype),
                jnp.eye(size, dtype=dtype),
                jnp.zeros((size,), dtype),
                damping * one,
                2 * one,
                jnp.zeros((), jnp.int32),
                jnp.asarray(_RUNNING, jnp.int32),
            ),
        ),
    )
    # max_steps counts the steps after the start's evaluation
    z, r, cost, _, _, _, _, steps, status = jax.lax.while_loop(running, body, state)
    steps = jnp.maximum(steps - 1, 0)
    status = jnp.where(status == _RUNNING, Status.max_iterations, status).astype(jnp.int32)
    mean = cost / r.shape[0]
    return z, jnp.where(jnp.isfinite(mean), mean, jnp.inf), status, steps


def least_squares(
    residual, z0, args, *, max_steps: int = 100, rtol=1e-8, atol=1e-10, ftol: float | None = None
):
    """Optimistix's Levenberg-Marquardt (`optx.LevenbergMarquardt`: damped Gauss-Newton
    steps in a classical trust region, its Cauchy termination) on any residual
    `residual(z, args)` from `z0`, computed on the normal equations; never raises. The
    model-error loop's refits, initial-state fits and the effects' own fits use it.

    The method is optimistix's, step for step: the step solves
    `(J^T J + I / s) delta = -J^T r` with the trust-region size `s` (1 at the start); a
    trial point is accepted when the cost `|r|^2 / 2` falls by at least 0.01 of the
    fall the Gauss-Newton model predicts, and `s` is multiplied by 3.5 when it falls by
    more than 0.99 of it, by 0.25 when the point is rejected; it stops after an accepted
    step that moves every element of `z` by less than `atol + rtol |z|` and every
    residual by less than `atol + rtol |r|`. Two things differ, in how it is computed,
    not in what: the step solves the normal equations (`_linalg.spd_solve`, as
    `levenberg_marquardt` does) instead of a QR factorisation of `[J; I / sqrt(s)]`,
    and the Jacobian is formed by forward mode in the same pass as the residual (`vmap`
    of `jax.jvp` over the parameters) instead of linearised and transposed: one traced
    copy of the residual per step. The iterates agree to rounding; at a minimum, where
    the step is rounding noise, the loss may rise by rounding where optimistix's fell
    by rounding (its predicted fall is formed from `J delta + r`, this one's from the
    normal equations). A rise within the rounding bound of a sum of T squares (T
    machine epsilons of the loss, T the residual's length) therefore counts as no
    change: the step is accepted and the Cauchy test decides, as it does in optimistix
    when the coin falls the other way. (Without this, a sum of two exponentials took 36
    steps where optimistix took 18, shrinking the trust region until the step was
    zero.) A failed factorisation counts as a rejected step. `ftol` (None: off, as in
    optimistix) adds SciPy's cost test: an accepted step that lowers the loss by at
    most `ftol` times it also ends the fit, `converged` (for residuals with kinks, where
    steps keep moving along a flat cost). With optimistix's the
    loop's cold run on its synthetic input-delay records (`benchmarks/loop_speed.py`)
    took about twice as long, with the same decisions.

    **Returns:** `(z, cost, status, steps)`: the last accepted point, its mean squared
    residual (`inf` if not finite), a `Status` code (`converged`, `max_iterations`, or
    `diverged` where the start's residual is not finite) and the steps taken.
    """
    dtype = z0.dtype
    size = z0.shape[0]

    def evaluate(z):
        def one(tangent):
            return jax.jvp(lambda w: residual(w, args), (z,), (tangent,))

        r, J = jax.vmap(one, out_axes=(None, 1))(jnp.eye(size, dtype=dtype))
        return r, J.T @ J, J.T @ r

    if size == 0:  # nothing to fit: the start's cost
        r = residual(z0, args)
        cost = jnp.mean(r**2)
        finite = jnp.isfinite(cost)
        status = jnp.where(finite, Status.converged, Status.diverged).astype(jnp.int32)
        return z0, jnp.where(finite, cost, jnp.inf), status, jnp.zeros((), jnp.int32)

    T = jax.eval_shape(lambda z: residual(z, args), z0).shape[0]

    # the start is evaluated even with no step allowed (`max_steps` 0: its cost)
    limit = max(int(max_steps), 1)

    def running(state):
        return (state[-1] == _RUNNING) & (state[-2] < limit)  # status, step

    def body(state):
        z, r, JtJ, Jtr, trial, s, step, status = state
        first = step == 0
        r_new, JtJ_new, Jtr_new = evaluate(trial)
        delta = trial - z
        loss, loss_new = 0.5 * (r @ r), 0.5 * (r_new @ r_new)
        # the Gauss-Newton model's change of the loss, `|J delta + r|^2 / 2 - |r|^2 / 2`
        predicted = delta @ Jtr + 0.5 * delta @ (JtJ @ delta)
        finite = jnp.isfinite(loss_new) & jnp.all(jnp.isfinite(JtJ_new))
        finite = finite & jnp.all(jnp.isfinite(Jtr_new))
        # a change within rounding of the loss counts as none (at a minimum the model's
        # predicted fall and the actual change are both rounding: see the docstring)
        rounding = T * jnp.finfo(dtype).eps * loss  # a sum of T squares' rounding bound
        fell = loss_new - loss <= 0.01 * predicted + rounding
        fell = fell & finite & jnp.all(jnp.isfinite(trial))
        accept = first | fell
        good = (loss_new - loss < 0.99 * predicted) & (predicted < 0) & fell & ~first
        s = s * jnp.where(accept, jnp.where(good, 3.5, 1.0), 0.25)
        cauchy = jnp.max(jnp.abs(delta) / (atol + rtol * jnp.abs(trial))) < 1
        cauchy &= jnp.max(jnp.abs(r_new - r) / (atol + rtol * jnp.abs(r_new))) < 1
        status = jnp.where(first & ~finite, Status.diverged, status)
        done = cauchy
        if ftol is not None:  # an accepted step that hardly lowers the loss ends the fit
            done = cauchy | (loss - loss_new <= ftol * loss)
        status = jnp.where(accept & done & ~first, Status.converged, status)

        def pick(new, old):
            return jnp.where(accept, new, old)

        z, r, JtJ, Jtr = pick(trial, z), pick(r_new, r), pick(JtJ_new, JtJ), pick(Jtr_new, Jtr)
        tiny = s <= jnp.finfo(dtype).eps
        damping = jnp.where(tiny, jnp.finfo(dtype).max, 1 / jnp.where(tiny, 1.0, s))
        solution, factored = spd_solve(JtJ + damping * jnp.eye(size, dtype=dtype), Jtr)
        # a failed factorisation proposes no move: the next trial is rejected
        trial = z - jnp.where(factored & jnp.all(jnp.isfinite(solution)), solution, jnp.inf)
        return z, r, JtJ, Jtr, trial, s.astype(dtype), step + 1, status.astype(jnp.int32)

    # every element of the carry a value of `z0`: under `vmap` (the starts side by side)
    # the loop's body is traced once less (`_compile.carried_like`)
    state = (
        z0,
        *carried_like(
            z0,
            (
                jnp.zeros((T,), dtype),
                jnp.zeros((size, size), dtype),
                jnp.zeros((size,), dtype),
            ),
        ),
        z0,
        *carried_like(
            z0,
            (
                jnp.ones((), dtype),
                jnp.zeros((), jnp.int32),
                jnp.asarray(_RUNNING, jnp.int32),
            ),
        ),
    )
    z, r, _, _, _, _, steps, status = jax.lax.while_loop(running, body, state)
    status = jnp.where(status == _RUNNING, Status.max_iterations, status).astype(jnp.int32)
    steps = jnp.minimum(steps, max_steps)
    cost = jnp.mean(r**2)
    return z, jnp.where(jnp.isfinite(cost), cost, jnp.inf), status, steps
