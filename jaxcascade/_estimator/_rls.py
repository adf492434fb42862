"""One recursive least-squares update with forgetting, and the forgetting schedule.

The regression `yc(t) = phi(t) theta + e(t)` (eq. 16) is solved recursively: with
`P ~ (sum_s w_s phi_s phi_s^T)^-1` the weighted least-squares estimate after sample t is
`theta_t = theta_{t-1} + P_t phi_t (yc_t - phi_t theta_{t-1})`. Old samples lose weight
by the forgetting factor `lam_t`; where `phi_t` is zero (the backlash's dead zone: g1 =
g2 = 0) a sample carries no information, and plain forgetting would still inflate `P`
(estimator windup). The anti-windup variants (`ANTI_WINDUP`):

- `"none"`: exponential forgetting, `P_t = (P - K phi^T P) / lam` on every update;
- `"trace"`: exponential forgetting with the trace of `P` held at most at its initial
  value (constant-trace bound: the gain cannot grow without limit in a stretch of poor
  excitation);
- `"directional"`: forget only along the current regressor (Kulhavý 1987; the form of
  Bittanti, Bolzern and Campi 1990): the information matrix `R = P^-1` becomes
  `R - (1 - lam) phi phi^T / (phi^T P phi) + phi phi^T`, so directions the input does
  not excite keep their information.

The caller applies an update only where the sample informs the block (`active`): the
regressor columns fall into two blocks with disjoint supports in time (g1 and g2,
`_normal_equations`), each block is its own recursion, and a block not active at a
sample is neither updated nor forgotten.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

ANTI_WINDUP = ("none", "trace", "directional")


def forgetting(k, lam, memory0, growth, acceleration=0.0):
    """The forgetting factor after `k` updates: `lam_k = min(lam, 1 - 1 / (memory0 +
    growth k + acceleration k^2))`.

    `1 / (1 - lam_k)` is the recursion's memory in samples: it starts at `memory0` and
    grows until it reaches `1 / (1 - lam)` (never, for `lam = 1`: the factor then tends
    to 1). Early regressors are built from poor estimates, so they must lose weight. A
    memory that grows in proportion to the samples seen (`acceleration = 0`) gives
    sample s at time k the weight `((memory0 + growth s) / (memory0 + growth k))^(1 /
    growth)`: the start is forgotten like a power of the elapsed fraction of the record,
    and so is everything else, at a variance up to `(beta + 1)^2 / (2 beta + 1)` times
    that of least squares over the record (`beta = 1 / growth`: 2.8 at `growth =
    0.25`). A memory that grows like `k^2` forgets sample s by about `exp(-(1/s - 1/k) /
    acceleration)`: the samples before about `1 / acceleration` fade, the later ones tend
    to equal weights. A constant factor `lam < 1` instead forgets everything older than
    its memory: what tracking needs, at a variance of about `(1 - lam) k / 2` times least
    squares.
    """
    k = jnp.asarray(k, jnp.result_type(float))
    memory = memory0 + growth * k + acceleration * k * k
    return jnp.minimum(lam, 1.0 - 1.0 / memory)


def update(
    theta: Float[Array, " B"],
    P: Float[Array, "B B"],
    phi: Float[Array, " B"],
    error: Float[Array, ""],
    lam: Float[Array, ""],
    active: Bool[Array, ""],
    *,
    anti_windup: str,
    trace_max: Float[Array, ""],
) -> tuple[Float[Array, " B"], Float[Array, "B B"]]:
    """One update of a block: `(theta, P)` after the a-priori error `error = yc -
    phi theta` with forgetting factor `lam`; unchanged where not `active`. Never raises;
    `P` is kept symmetric."""
    Pphi = P @ phi
    r = phi @ Pphi
    if anti_windup == "directional":
        # R + beta phi phi^T with beta = 1 - (1 - lam) / r; 1 + beta r = lam + r > 0
        beta = jnp.where(r > 0, 1.0 - (1.0 - lam) / jnp.where(r > 0, r, 1.0), 1.0)
        gain = Pphi / (1.0 + beta * r)
        new_P = P - beta * jnp.outer(gain, Pphi)
    else:
        gain = Pphi / (lam + r)
        new_P = (P - jnp.outer(gain, Pphi)) / lam
        if anti_windup == "trace":
            new_P = new_P * jnp.minimum(1.0, trace_max / jnp.trace(new_P))
    new_P = 0.5 * (new_P + new_P.T)
    new_theta = theta + gain * error
    return jnp.where(active, new_theta, theta), jnp.where(active, new_P, P)
