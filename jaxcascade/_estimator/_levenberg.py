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
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

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
    state = (
        z0,
        jnp.zeros(
            (residual_size,) if residual_size else jax.eval_shape(evaluate, z0)[0].shape, dtype
        ),
        jnp.asarray(jnp.inf, dtype),
        jnp.eye(size, dtype=dtype),
        jnp.zeros((size,), dtype),
        damping * one,
        2 * one,
        jnp.zeros((), jnp.int32),
        jnp.asarray(_RUNNING, jnp.int32),
    )
    # max_steps counts the steps after the start's evaluation
    z, r, cost, _, _, _, _, steps, status = jax.lax.while_loop(running, body, state)
    steps = jnp.maximum(steps - 1, 0)
    status = jnp.where(status == _RUNNING, Status.max_iterations, status).astype(jnp.int32)
    mean = cost / r.shape[0]
    return z, jnp.where(jnp.isfinite(mean), mean, jnp.inf), status, steps
