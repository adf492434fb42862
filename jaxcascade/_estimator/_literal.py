"""The paper's iterative least-squares estimator (Vörös 2016, eqs. 19-28): `voros`, and
`Literal`, the registered estimator that runs it from the paper's initial values."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from .._compile import carried_like, jit
from .._status import Status
from .._system._model import CascadeParams, Orders, is_admissible
from .._system._validate import is_traced, record
from ._base import Estimator, curved_form, keyword_defaults, setting
from ._normal_equations import (
    FIRST_STEPS,
    from_regression,
    normal_equations,
    resolve,
    solve_first,
    solve_step,
    step_regression,
)
from ._solution import PATH_ONLY, Solution, finite

_RUNNING = -1
# A revisited neighbourhood whose iterates all lie within this many tolerances of each
# other is convergence (an oscillating approach), not a cycle (`voros`).
_TIGHT_CYCLE = 10.0


def initial_guess(orders: Orders, u_min, u_max, dtype=None) -> CascadeParams:
    """The paper's initial values, generalised to any orders.

    Slopes and linear-block coefficients 0; breakpoints evenly spaced over the input
    range (`DR_i = i u_max / nR`, `DL_j = j u_min / nL`, which gives the paper's
    DR1 = 1.0, DL1 = -1.0 for nR = nL = 2 and |u| < 2); `mR = 0.5`, `cL = cR = 0.001`.
    """
    dtype = dtype or jnp.result_type(float)
    u_min, u_max = jnp.asarray(u_min, dtype), jnp.asarray(u_max, dtype)
    o = orders
    return CascadeParams(
        MR=jnp.zeros((o.nR,), dtype),
        DR=jnp.arange(1, o.nR, dtype=dtype) * u_max / o.nR,
        ML=jnp.zeros((o.nL,), dtype),
        DL=jnp.arange(1, o.nL, dtype=dtype) * u_min / o.nL,
        a=jnp.zeros((o.r - 1,), dtype),
        b=jnp.zeros((o.p,), dtype),
        cL=jnp.asarray(0.001, dtype),
        mR=jnp.asarray(0.5, dtype),
        cR=jnp.asarray(0.001, dtype),
        orders=o,
        curveL=jnp.zeros((o.degree - 1,), dtype),  # straight branches (curvature 0)
        curveR=jnp.zeros((o.degree - 1,), dtype),
    )


def first_iteration(init: CascadeParams, u, y, reading: str = "full", backend: str = "xla"):
    """The paper's first iteration: v ~ u, x ~ y, and only the NS and LD estimates kept.

    The paper: "In the first iteration, only the parameters of nonlinear static block and
    the linear dynamic block are estimated where v(t-i) is approximated by u(t-i) and
    x(t-j) by y(t-j) ... nonzero initial values of the backlash parameters mR, cL and cR
    have to be considered for evaluation of g1(t), g2(t) and yc(t)". `reading` says which
    regression is solved (`_normal_equations.solve_first`): `"full"` (eq. 27 whole, the
    backlash estimates discarded), `"fixed"` (backlash columns held at `init`) or
    `"drop"` (backlash columns left out). In every reading the backlash keeps its initial
    values for step 2. The switching functions use unit slopes (the all-zero initial
    slopes would zero the breakpoint regressors), so the breakpoint coefficients estimate
    `D * M`; they are divided by the new slopes here.
    """
    o = init.orders
    bl = o.backlash
    ne = normal_equations(init, u, y, first=True, backend=backend)
    coef, singular, cost = solve_first(ne, init, u.shape[0], reading)
    vector = jnp.concatenate([coef, init.to_vector()[bl].astype(coef.dtype)])
    params = CascadeParams.from_vector(vector, o, check=False)
    params = eqx.tree_at(
        lambda p: (p.DR, p.DL),
        params,
        (_safe_divide(params.DR, params.MR[1:]), _safe_divide(params.DL, params.ML[1:])),
    )
    return params.to_vector(), singular, cost


def _safe_divide(num, den):
    # A zero slope increment leaves its breakpoint undefined: report it through a
    # non-finite value, which the caller turns into a status, not a NaN estimate.
    return jnp.where(den != 0, num / jnp.where(den != 0, den, 1.0), jnp.inf)


def voros_step(params: CascadeParams, u, y, backend: str = "xla"):
    """One iteration s -> s+1 (steps a and b of the paper).

    **Returns:** `(vector, singular, cost, standard_errors)`: the new estimate in
    `Orders.names` order, whether the regression was singular, its cost J (eq. 28) and
    the least-squares standard errors of theta (eq. 18 order, so the last entry is that
    of `C = cR mR`), `sqrt(J N / (N - P) diag((phi^T phi)^-1))`.

    `backend`: `"xla"` solves the regression from its materialised regressors (cost J
    from the residual); `"fused"` from the native kernel's normal equations (cost J
    from them, accurate to about `eps |yc|^2 / N`); `"auto"` picks (`_normal_equations`).
    """
    o = params.orders
    n = u.shape[0]
    if resolve(backend, o, u.dtype) == "fused":
        theta, singular, cost, inverse = solve_step(
            normal_equations(params, u, y, backend="fused"), n
        )
    else:
        reg = step_regression(params, u, y)
        theta, singular, _, inverse = solve_step(from_regression(reg, o), n)
        cost = jnp.mean((reg.yc - reg.phi @ theta) ** 2)
    new = CascadeParams.from_theta(theta, o, check=False)
    return new.to_vector(), singular, cost, standard_errors(cost, inverse, n, o.size)


def standard_errors(cost, inverse_diagonal, n: int, size: int):
    """Least-squares standard errors `sqrt(J N / (N - P) diag((phi^T phi)^-1))` of a step
    (`voros_step`) from its cost J and the inverse Gram matrix's diagonal."""
    variance = cost * n / max(n - size, 1)
    return jnp.sqrt(jnp.maximum(variance * inverse_diagonal, 0.0))


def _theta(vectors):
    """`Orders.names` vectors (any leading axes) -> theta (eq. 18): `cR` -> `C = cR mR`."""
    return vectors.at[..., -1].multiply(vectors[..., -2])


def stopping_rule(theta_new, theta, se, cost, new_cost, tol, se_tol, cost_tol):
    """`(converged, tolerance)` of a step theta -> theta_new (eq. 18 order): every
    parameter's change within `tolerance = se_tol se + tol (1 + |theta_new|)`, or the cost
    J settled (`voros`, "Stopping")."""
    tolerance = se_tol * se + tol * (1 + jnp.abs(theta_new))
    converged = jnp.all(jnp.abs(theta_new - theta) <= tolerance)
    # the paper's step c: the cost J no longer changes (relative, > 0: a cost at the
    # rounding floor of the normal equations is clipped to 0 and says nothing)
    settled = (cost > 0) & (jnp.abs(new_cost - cost) <= cost_tol * cost)
    return converged | ((cost_tol >= 0) & settled), tolerance


def cycle_detection(theta_new, thetas, k, tolerance, cycle_period: int):
    """`(revisited, tight, spread)`: whether iterate k + 1 (`theta_new`) lies within
    `tolerance` of iterate k + 1 - j for a period 2 <= j <= `cycle_period` (`thetas`:
    the iterates so far in eq. 18 order, row i iterate i; row 0, the initial values, is
    no iterate of the map), whether the cycle's iterates spread over at most
    `_TIGHT_CYCLE` tolerances in every parameter (an oscillating approach to a fixed
    point), and that spread (`voros`, "Stopping")."""
    last = thetas.shape[0] - 1
    rows = jnp.arange(last + 1)
    periods = jnp.arange(2, max(cycle_period, 2) + 1)  # 0 or 1: masked below
    earlier = jnp.clip(k + 1 - periods, 0, last)
    close = jnp.all(jnp.abs(theta_new - thetas[earlier]) <= tolerance, axis=1)
    close = close & (k + 1 - periods >= 1) & (cycle_period >= 2)
    period = jnp.where(jnp.any(close), periods[jnp.argmax(close)], 0)
    in_cycle = (rows > k + 1 - period) & (rows <= k)
    spread_max = jnp.max(jnp.where(in_cycle[:, None], thetas, -jnp.inf), axis=0)
    spread_min = jnp.min(jnp.where(in_cycle[:, None], thetas, jnp.inf), axis=0)
    spread = jnp.maximum(spread_max, theta_new) - jnp.minimum(spread_min, theta_new)
    # An iteration that converges while oscillating (an eigenvalue of the map near
    # -1) also revisits a neighbourhood; its "cycle" spans a few tolerances only.
    tight = jnp.all(spread <= _TIGHT_CYCLE * tolerance)
    return jnp.any(close), tight, spread


def voros(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    init: CascadeParams | None = None,
    *,
    first_step: str = "full",
    max_iterations: int = 50,
    tol: float = 1e-8,
    se_tol: float = 1e-3,
    cost_tol: float = 1e-12,
    cycle_period: int = 16,
    domain_stop: bool = False,
    divergence_bound: float = 1e6,
    backend: str = "auto",
) -> Solution:
    """The paper's iterative least-squares estimator, literally (eqs. 19-28).

    Step 1 is the paper's first iteration (`first_step`, below); each later step rebuilds
    v, x, g1, g2 and yc from the current estimate and solves the full regression.

    **The first step.** The paper's text admits three readings (`first_iteration`);
    the default `"full"` solves the whole regression (eq. 27) with v ~ u and x ~ y and
    keeps only its NS and LD estimates. It is the only reading that reproduces the
    paper's report that both examples reach the true values "after about 6 iterations":
    noise-free, it recovers Example 2 from nearly every input record, the `"fixed"`
    reading (the backlash columns held at their initial values, this package's reading
    until version 0.1) and `"drop"` from about half (METHOD.md;
    `results/literal_readings.md` has the measured rates).

    **Stopping.** The paper stops when "the error is less than a predetermined value"
    (step c). Under noise the switching pattern can settle into a short cycle between
    neighbouring estimates, all at the statistical precision, where a fixed tolerance
    on the parameter change never triggers. So each parameter's change is judged
    against its own precision, `tol_i = se_tol * se_i + tol * (1 + |theta_i|)` with
    `se_i` the step's least-squares standard error (`voros_step`; zero noise-free, where
    the rounding floor `tol` decides):

    - `converged`: every `|theta_i(s+1) - theta_i(s)| <= tol_i`, or the cost J
      (eq. 28) changed by at most `cost_tol` (relative) from the previous step;
    - `cycled`: the new iterate is within `tol_i` of iterate `s + 1 - k` for a period
      `2 <= k <= cycle_period` (the iterates revisit a small neighbourhood) and the
      cycle's iterates spread over more than `10 tol_i` in some parameter (a smaller
      spread is an oscillating approach to a fixed point: `converged`); the estimate is
      the last iterate, and `cycle_amplitude` the largest spread of one parameter
      (theta, eq. 18) over the cycle's iterates;
    - `max_iterations`: neither after `max_iterations` steps.

    **No domain stop.** The paper has none: an intermediate iterate may leave the model's
    domain (a breakpoint outside the input range, `mR <= 0`, an unstable linear block)
    and come back. The iteration runs on unless a step is non-finite or larger than
    `divergence_bound` (`diverged`, or `singular` when the step was singular; that step
    is not accepted). A singular step (a regime or segment that the current estimate
    never visits) gets the near minimum-norm solution of `_regression.solve_gram` and
    the iteration goes on. The
    final estimate is judged: `left_domain` if it is inadmissible, `singular` if its
    own step was. `domain_stop=True` is the safeguarded variant: it stops at the first
    singular (`singular`) or inadmissible (`left_domain`) iterate, not accepted.

    **Arguments:**

    - `u`, `y`: `Float[Array, " T"]` input and measured output of one record (lists and
      NumPy arrays are converted, to the default float dtype; `_validate.record` says
      what is refused, with a `ValueError` or `TypeError`, before anything is compiled).
    - `orders`: static model orders.
    - `init`: initial values; default `initial_guess(orders, min(u), max(u))`.
    - `first_step`: `"full"` (default), `"fixed"` or `"drop"` (above).
    - `tol`, `se_tol`, `cost_tol`: the stopping tolerances (above); negative values never
      stop early.
    - `cycle_period`: longest cycle detected (0 or 1: none). Default 16: cycles of period
      10 occur (an Example 1 record at SNR 25, `benchmarks/literal_criterion.py`), and a
      cycle longer than the window reads as `max_iterations`.
    - `backend`: how each step's normal equations are formed: `"xla"` (materialised
      regressors), `"fused"` (the native CPU kernel, float64) or `"auto"` (fused where
      it applies); the same estimates up to rounding (`_normal_equations`).
    """
    u, y = record(u, y, orders=orders, where="voros")
    if init is not None:
        if not isinstance(init, CascadeParams):
            raise TypeError(f"voros: init must be CascadeParams, got {type(init).__name__}.")
        if init.orders != orders:
            raise ValueError(f"voros: init has orders {init.orders}, the fit {orders}.")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int | np.integer):
        raise TypeError(f"voros: max_iterations must be an integer, got {max_iterations!r}.")
    if max_iterations < 1:
        raise ValueError(f"voros: max_iterations must be at least 1, got {max_iterations}.")
    return _voros(
        u,
        y,
        orders,
        init,
        first_step=first_step,
        max_iterations=max_iterations,
        tol=tol,
        se_tol=se_tol,
        cost_tol=cost_tol,
        cycle_period=cycle_period,
        domain_stop=domain_stop,
        divergence_bound=divergence_bound,
        backend=backend,
    )


@jit(
    static_argnames=(
        "orders",
        "max_iterations",
        "first_step",
        "cycle_period",
        "domain_stop",
        "backend",
    ),
)
def _voros(
    u: Float[Array, " T"],
    y: Float[Array, " T"],
    orders: Orders,
    init: CascadeParams | None,
    *,
    first_step: str,
    max_iterations: int,
    tol: float,
    se_tol: float,
    cost_tol: float,
    cycle_period: int,
    domain_stop: bool,
    divergence_bound: float,
    backend: str,
) -> Solution:
    # The jitted core of `voros`, which checks the record first; the defaults are
    # `voros`'s (and `Literal`'s, which reads them from there).
    dtype = u.dtype
    y = y.astype(dtype)
    u_min, u_max = jnp.min(u), jnp.max(u)
    if init is None:
        init = initial_guess(orders, u_min, u_max, dtype)
    init = init.astype(dtype)
    start = init.to_vector()

    def admissible(vector):
        safe = jnp.where(jnp.isfinite(vector), vector, 0.0)
        return is_admissible(CascadeParams.from_vector(safe, orders, check=False), u_min, u_max)

    def classify(new, singular):
        diverged = ~jnp.all(jnp.isfinite(new)) | (jnp.max(jnp.abs(new)) > divergence_bound)
        # a singular step that cannot go on (non-finite) is reported as singular: that
        # is the cause; the safeguarded variant stops at any singular step
        stop_singular = singular & (diverged | domain_stop)
        status = jnp.where(
            stop_singular, Status.singular, jnp.where(diverged, Status.diverged, _RUNNING)
        )
        if domain_stop:
            status = jnp.where((status == _RUNNING) & ~admissible(new), Status.left_domain, status)
        return status

    first, singular, cost = first_iteration(init, u, y, first_step, backend)
    status = classify(first, singular)
    accepted = status == _RUNNING
    vector = jnp.where(accepted, first, start)
    status = jnp.where(accepted & (max_iterations <= 1), Status.max_iterations, status)
    history = jnp.broadcast_to(start, (max_iterations + 1, orders.size))
    history = history.at[1].set(vector)
    # the amplitude a value of the start: under `vmap` the loop's body is traced once
    # less (`_compile.carried_like`)
    zero = carried_like(vector, jnp.zeros((), dtype))
    carry = (jnp.asarray(1) * accepted, vector, history, status, cost, zero, singular & accepted)
    rows = jnp.arange(max_iterations + 1)

    def running(carry):
        return carry[3] == _RUNNING

    def body(carry):
        k, vector, history, status, cost, amplitude, was_singular = carry
        new, singular, new_cost, se = voros_step(
            CascadeParams.from_vector(vector, orders, check=False), u, y, backend
        )
        new_status = classify(new, singular)
        accepted = new_status == _RUNNING
        theta_new = _theta(new)
        converged, tolerance = stopping_rule(
            theta_new, _theta(vector), se, cost, new_cost, tol, se_tol, cost_tol
        )
        revisited, tight, spread = cycle_detection(
            theta_new, _theta(history), k, tolerance, cycle_period
        )
        revisited = ~converged & revisited
        converged = converged | (revisited & tight)
        cycled = revisited & ~tight
        new_status = jnp.where(accepted & converged, Status.converged, new_status)
        new_status = jnp.where(accepted & cycled, Status.cycled, new_status)
        new_status = jnp.where(
            accepted & (new_status == _RUNNING) & (k + 1 >= max_iterations),
            Status.max_iterations,
            new_status,
        )
        amplitude = jnp.where(accepted & cycled, jnp.max(spread), amplitude)
        k = jnp.where(accepted, k + 1, k)
        vector = jnp.where(accepted, new, vector)
        history = jnp.where(accepted, history.at[k].set(new), history)
        cost = jnp.where(accepted, new_cost, cost)
        was_singular = jnp.where(accepted, singular, was_singular)
        return k, vector, history, new_status, cost, amplitude, was_singular

    k, vector, history, status, cost, amplitude, singular = jax.lax.while_loop(running, body, carry)
    if not domain_stop:
        # Judged on the final estimate: outside the domain, or from a singular step
        # (a regime or segment the record never visits at this estimate).
        ended = (
            (status == Status.converged)
            | (status == Status.cycled)
            | (status == Status.max_iterations)
        )
        status = jnp.where(ended & singular, Status.singular, status)
        status = jnp.where(ended & ~admissible(vector), Status.left_domain, status)
    history = jnp.where(rows[:, None] > k, vector[None, :], history)
    solution = Solution(
        params=CascadeParams.from_vector(vector, orders, check=False),
        history=history,
        iterations=k,
        cost=cost,
        status=status.astype(jnp.int32),
        cycle_amplitude=amplitude,
        path=jnp.asarray(PATH_ONLY, jnp.int32),
    )
    return finite(solution, start)


# `voros`'s settings and their defaults: the one place they are written down.
_VOROS = keyword_defaults(voros)


class Literal(Estimator):
    """The paper's iteration (`voros`) from the paper's initial values.

    With `input_range = (-2, 2)` (the Monte-Carlo engine passes the input
    distribution's range) the initial breakpoints are exactly the paper's DR1 = 1.0,
    DL1 = -1.0 (`initial_guess`); without it they follow the sample range of `u`, which
    is slightly narrower and differs between records. The settings are `voros`'s: the
    first-step reading, the stopping rule, and `domain_stop` for the safeguarded variant.

    For orders with curved backlash branches (`Orders.degree > 1`) it runs the general
    backlash's key-term iteration (`_general_keyterm.key_term_solution`) with the same
    stopping settings, from the paper's initial values on the record's own range
    (`first_step`, `domain_stop` and `input_range` do not apply there).
    """

    name: ClassVar[str] = "literal"
    summary: ClassVar[str] = "the paper's iteration (eqs. 19-28) from its initial values"

    first_step: str = setting(_VOROS["first_step"])
    max_iterations: int = setting(_VOROS["max_iterations"])
    tol: float = setting(_VOROS["tol"])
    se_tol: float = setting(_VOROS["se_tol"])
    cost_tol: float = setting(_VOROS["cost_tol"])
    cycle_period: int = setting(_VOROS["cycle_period"])
    domain_stop: bool = setting(_VOROS["domain_stop"])
    divergence_bound: float = setting(_VOROS["divergence_bound"])

    def stopping(self) -> dict:
        """The stopping settings, which the key-term iteration of curved branches shares."""
        names = ("max_iterations", "tol", "se_tol", "cost_tol", "cycle_period", "divergence_bound")
        return {name: getattr(self, name) for name in names}

    def __check_init__(self):
        if self.first_step not in FIRST_STEPS:
            raise ValueError(
                f"Unknown first-step reading {self.first_step!r}; known: {', '.join(FIRST_STEPS)}."
            )
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be at least 1, got {self.max_iterations}.")

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
        u, y = record(u, y, orders=orders, where="Literal", curved=True)
        if orders.degree > 1:
            # curved branches: the key-term iteration of the general backlash
            return curved_form(self.name)(u, y, orders, None, **self.stopping())
        if input_range is None:
            u_min, u_max = jnp.min(u), jnp.max(u)
        else:
            u_min, u_max = input_range
        if not is_traced(u_min) and not is_traced(u_max) and not float(u_min) < 0 < float(u_max):
            # the initial breakpoints split each side of 0 (`initial_guess`)
            raise ValueError(
                f"Literal: the input range ({float(u_min):g}, {float(u_max):g}) must contain 0 "
                "strictly: the piecewise-linear block has segments on both sides of u = 0; "
                "centre the input (e.g. scaling 'standard')."
            )
        init = initial_guess(orders, u_min, u_max, u.dtype)
        return voros(
            u,
            y,
            orders,
            init,
            first_step=self.first_step,
            max_iterations=self.max_iterations,
            tol=self.tol,
            se_tol=self.se_tol,
            cost_tol=self.cost_tol,
            cycle_period=self.cycle_period,
            domain_stop=self.domain_stop,
            divergence_bound=self.divergence_bound,
        )
