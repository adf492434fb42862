"""The output-error Cramér-Rao bound: how precisely a record can determine the cascade.

For the output-error model `y(t) = simulate(theta, u)(t) + e(t)` with `e` white Gaussian
of standard deviation `sigma`, the Fisher information of theta (the parameter vector in
`Orders.names` order, with `cR`, not `C`) is

    F = J^T J / sigma^2,    J(t, i) = d simulate(theta, u)(t) / d theta_i,

and no unbiased estimator has a variance below `diag(F^-1)` (the bound). `J` is exact
forward-mode differentiation (`jax.jacfwd`) through the simulator's `lax.scan`s: the
backlash and the piecewise-linear block are piecewise smooth, so the derivative exists
except where a sample sits exactly on a switching threshold (a set of measure zero).

**A sweep cell** has many input records. Its bound is the average of the per-record
bounds, `crlb_std = sqrt(mean_k diag(F_k^-1))`, not the bound of the average information
`sqrt(diag((mean_k F_k)^-1))`: the Monte-Carlo variance of an estimator over records is
`E[Var(theta_hat | u)] + Var(E[theta_hat | u]) >= E[diag(F_u^-1)]`, so the average of the
per-record bounds is the tighter of the two valid bounds (by Jensen's inequality for the
matrix inverse, `E[F^-1] >= (E F)^-1`); for long records they agree (`F_k / N`
concentrates). `fisher_information` accepts a batch of records for the other one.

**Coloured noise** (`poles`, `zeros`: `e = C(q)/A(q) w`, `w` white Gaussian,
`_noise_filter`): the log-likelihood is that of the one-step-ahead prediction errors
`w = A(q)/C(q) (y - simulate(theta, u))`, so the information is the whitened Jacobian's,

    F = J_w^T J_w / sigma_w^2,    J_w = A(q)/C(q) J,    sigma_w^2 = sigma^2 / sum h_k^2,

with `sigma` the standard deviation of the noise as added (the SNR's) and `h` the
impulse response of `C/A`. The noise model's own coefficients, estimated with theta,
do not change theta's bound: their information is block-diagonal with theta's when the
noise is independent of the input (Ljung 1999, sec. 9.3). Output error under coloured
noise does not reach this bound; a prediction-error estimator (`pem`) does.

**Heavy tails.** `crlb` is the bound of Gaussian noise with the noise's variance and
spectrum: the smallest covariance attainable from second-order statistics, which least
squares and prediction error with a quadratic criterion attain. The exact bound of a
non-Gaussian density is lower: its information per sample is `information_factor /
sigma_w^2` (`information_factor`: Student-t with `nu` degrees of freedom `nu (nu + 1) /
((nu - 2)(nu + 3))`, 2 at `nu = 3`), so its bound on a standard deviation is
`crlb / sqrt(information_factor)`. Sweep tables report the Gaussian (second-order) one.

**A general output backlash** (`backlash=`, `_general_backlash`): theta continues with
the branches' curvature terms (`curveL`, then `curveR`) after the cascade's parameters,
whose `cL`, `mR`, `cR` are the curved block's; the same output-error information through
the simulator with curved branches.

**Measured records** (`standard_errors`): the same information at the estimate, with
`sigma^2` estimated from the residual (`sum r^2 / (N - P)`), and, when a noise model
whitens the residual, the whitened Jacobian (generalised least squares): the estimated
standard errors of the estimate, as MATLAB's `getcov` reports them.

**Identifiability** (`not_identifiable`): which parameters of a fit the record does not
determine, each with the reason, for the reports of a fit (host side).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .. import _linalg
from .._experiment._noise_filter import coefficients, variance_ratio, whiten
from .._system._general_backlash import GeneralBacklash, general_signals
from .._system._model import CascadeParams
from .._system._simulate import simulate


def _parameterised(params: CascadeParams, backlash: GeneralBacklash | None, dtype):
    """`(theta, simulate_theta)`: the parameter vector (`Orders.names` order, then a
    general backlash's `curveL` and `curveR`) and the noise-free output as a function
    `simulate_theta(theta, u)`.
    With `backlash`, `params`' `cL`, `mR`, `cR` are the backlash's (as in
    `_general_refine`'s fits) and only its curvature is taken from it."""
    orders = params.orders
    vector = params.to_vector().astype(dtype)
    if backlash is None:
        return vector, lambda v, u: simulate(CascadeParams.from_vector(v, orders, check=False), u)
    size, q1 = orders.size, backlash.degree - 1
    theta = jnp.concatenate(
        [vector, jnp.asarray(backlash.curveL, dtype), jnp.asarray(backlash.curveR, dtype)]
    )

    def simulate_theta(v, u):
        p = CascadeParams.from_vector(v[:size], orders, check=False)
        curved = GeneralBacklash.unchecked(
            p.cL, p.mR, p.cR, v[size : size + q1], v[size + q1 : size + 2 * q1]
        )
        return general_signals(p, curved, u).y

    return theta, simulate_theta


def jacobian(
    params: CascadeParams, u: Float[Array, " T"], backlash: GeneralBacklash | None = None
) -> Float[Array, "T P"]:
    """`d simulate(params, u) / d theta` (theta in `Orders.names` order; with a general
    `backlash`, its `curveL` and `curveR` follow), by forward-mode differentiation
    through the simulator (all P tangents in one pass)."""
    theta, simulate_theta = _parameterised(params, backlash, u.dtype)
    return jax.jacfwd(lambda v: simulate_theta(v, u))(theta)


def _sigma(params, u, snr, sigma, backlash=None):
    if (snr is None) == (sigma is None):
        raise ValueError("Give the noise level as exactly one of snr or sigma.")
    if sigma is not None:
        return jnp.asarray(sigma, u.dtype)
    # the paper's SNR is an amplitude ratio to the noise-free output (as `add_noise`)
    if backlash is None:
        return jnp.std(simulate(params, u)) / jnp.asarray(snr, u.dtype)
    theta, simulate_theta = _parameterised(params, backlash, u.dtype)
    return jnp.std(simulate_theta(theta, u)) / jnp.asarray(snr, u.dtype)


def _whitened(params, u, snr, sigma, poles, zeros, backlash=None):
    """The whitened Jacobian `J_w` and the innovations' standard deviation `sigma_w`."""
    J = jacobian(params, u, backlash)
    sigma = _sigma(params, u, snr, sigma, backlash)
    if not len(poles) and not len(zeros):
        return J, sigma
    c, d = coefficients(tuple(poles), tuple(zeros))
    ratio = variance_ratio(jnp.asarray(c, u.dtype), jnp.asarray(d, u.dtype))
    return whiten(J, c, d), sigma / jnp.sqrt(ratio)


def fisher_information(
    params: CascadeParams,
    u: Float[Array, "... T"],
    *,
    snr=None,
    sigma=None,
    poles=(),
    zeros=(),
    backlash: GeneralBacklash | None = None,
) -> Float[Array, "P P"]:
    """Fisher information `J_w^T J_w / sigma_w^2` of theta for the record(s) `u`; a batch
    of records (leading axis) gives their average information. The noise level is
    `sigma`, or `std(simulate(params, u)) / snr` (the paper's amplitude SNR), the
    standard deviation of the noise as added; `poles` and `zeros` (real numbers or
    `[radius, angle]` pairs, `_noise_filter.roots`; poles inside the unit circle) make it
    coloured (module docstring); none: white. `backlash`: a general backlash
    (`_general_backlash`) in place of the straight one, whose curvature terms follow the
    cascade's parameters in theta."""
    options = dict(snr=snr, sigma=sigma, poles=poles, zeros=zeros, backlash=backlash)
    if u.ndim == 2:
        return jnp.mean(jax.vmap(lambda one: fisher_information(params, one, **options))(u), 0)
    J, sigma_w = _whitened(params, u, snr, sigma, poles, zeros, backlash)
    return J.T @ J / sigma_w**2


def crlb(
    params: CascadeParams,
    u: Float[Array, "... T"],
    *,
    snr=None,
    sigma=None,
    poles=(),
    zeros=(),
    backlash: GeneralBacklash | None = None,
):
    """The Cramér-Rao bound on the standard deviation of every parameter (`Orders.names`
    order) for record `u`; with a batch of records, the average of the per-record bounds
    (module docstring). `inf` for a parameter the record does not determine (singular
    information, e.g. a segment never visited), 0 noise-free. Coloured noise: `poles`,
    `zeros` of `e = C(q)/A(q) w` (`fisher_information`); heavy tails: the Gaussian
    bound of the same variance (module docstring, `information_factor`); `backlash`: the
    general backlash's model, its curvature terms after the cascade's (`jacobian`).
    Traceable."""
    options = dict(snr=snr, sigma=sigma, poles=poles, zeros=zeros, backlash=backlash)
    if u.ndim == 2:
        variances = jax.vmap(lambda one: crlb(params, one, **options) ** 2)(u)
        return jnp.sqrt(jnp.mean(variances, 0))
    return _bound(*_whitened(params, u, snr, sigma, poles, zeros, backlash))


def noise_bound_options(noise=None) -> dict:
    """The keywords of `crlb` for a noise model: `poles` and `zeros` of linear noise (any
    object with those attributes, e.g. the sweep's `ar` and `arma` noise kinds); none for
    white or heavy-tailed noise, whose table bound is the Gaussian one of the noise's
    variance (module docstring). Host side: `crlb(truth, u, snr=snr,
    **noise_bound_options(noise))`."""
    if noise is None:
        return {}

    def plain(value):  # a real root, or a [radius, angle] pair (`_noise_filter.roots`)
        return tuple(float(v) for v in value) if isinstance(value, tuple | list) else float(value)

    return {
        "poles": tuple(plain(p) for p in getattr(noise, "poles", ())),
        "zeros": tuple(plain(z) for z in getattr(noise, "zeros", ())),
    }


def information_factor(kind: str = "gaussian", **settings) -> float:
    """Fisher information of a noise density about its location, times its variance: 1
    for Gaussian noise (the largest: every other density of that variance carries more),
    `nu (nu + 1) / ((nu - 2)(nu + 3))` for Student-t with `nu > 2` degrees of freedom
    (`dof`; 2 at `nu = 3`), and by numerical integration for Gaussian noise with
    outliers (`fraction` of the samples shifted by +-`size` standard deviations of the
    Gaussian part: `(1 - f) N(0, 1) + f/2 (N(size, 1) + N(-size, 1))`). The exact
    Cramér-Rao bound of that noise is `crlb / sqrt(information_factor)` (module
    docstring). Host side."""
    import numpy as np

    if kind == "gaussian":
        return 1.0
    if kind == "student_t":
        nu = float(settings["dof"])
        if not nu > 2:
            raise ValueError(f"Student-t noise needs dof > 2 for a finite variance, got {nu}.")
        return nu * (nu + 1) / ((nu - 2) * (nu + 3))
    if kind == "outliers":
        from scipy.integrate import quad

        f, k = float(settings["fraction"]), float(settings["size"])

        def parts(x):
            phi = [np.exp(-0.5 * (x - m) ** 2) / np.sqrt(2 * np.pi) for m in (0.0, k, -k)]
            p = (1 - f) * phi[0] + 0.5 * f * (phi[1] + phi[2])
            dp = -(1 - f) * x * phi[0] - 0.5 * f * ((x - k) * phi[1] + (x + k) * phi[2])
            return p, dp

        def integrand(x):
            p, dp = parts(x)
            return dp**2 / p if p > 0 else 0.0

        edges = [-np.inf, *sorted({-k, 0.0, k}), np.inf]  # one piece per bump
        pieces = zip(edges[:-1], edges[1:], strict=True)
        information = sum(quad(integrand, a, b, limit=400)[0] for a, b in pieces)
        return information * (1 + f * k**2)
    raise ValueError(
        f"No information factor for noise {kind!r}; known: gaussian, student_t, outliers."
    )


def _bound(J, sigma):
    """`sigma sqrt(diag((J^T J)^-1))` by a Jacobi-scaled Cholesky factorisation; `inf`
    for a parameter the record does not determine (a zero column, or one whose scaled
    variance exceeds 1e10: it loads on a direction of the information with eigenvalue
    below ~1e-10 of the largest; a ridge of 1e-12 keeps the factorisation finite)."""
    scale = jnp.sqrt(jnp.sum(J**2, axis=0))
    zero = scale <= jnp.finfo(J.dtype).tiny
    scaled = J / jnp.where(zero, 1.0, scale)
    identity = jnp.eye(J.shape[1], dtype=J.dtype)
    gram = scaled.T @ scaled + jnp.diag(zero.astype(J.dtype)) + 1e-12 * identity
    factor, _ = _linalg.cholesky(gram)
    scaled_variance = _linalg.inverse_diagonal(factor)
    undetermined = zero | ~jnp.isfinite(scaled_variance) | (scaled_variance > 1e10)
    bound = sigma * jnp.sqrt(scaled_variance) / jnp.where(zero, 1.0, scale)
    return jnp.where(undetermined, jnp.inf, bound)


def standard_errors(
    simulate_theta, theta: Float[Array, " P"], y: Float[Array, " T"], whiten=None
) -> tuple[Float[Array, " P"], Float[Array, ""]]:
    """Estimated standard errors of an output-error estimate `theta` of record `y`.

    - `simulate_theta`: `theta -> simulated output` (any model: the cascade, or a cascade
      with effects);
    - `whiten`: the noise model's inverse filter (`ARNoise.innovations`), applied to the
      residual and to every column of the Jacobian; default white noise.

    **Returns:** `(standard_errors, sigma)` with `sigma^2 = sum(w^2) / (N - P)` from the
    (whitened) residual `w`.
    """
    whiten = whiten or (lambda signal: signal)
    residual = whiten(y - simulate_theta(theta))
    J = jax.vmap(whiten, in_axes=1, out_axes=1)(jax.jacfwd(simulate_theta)(theta))
    n, p = J.shape
    sigma = jnp.sqrt(jnp.sum(residual**2) / max(n - p, 1))
    return _bound(J, sigma), sigma


# A breakpoint needs input samples on both sides of it: with fewer than this many on one
# side its hinge is (almost) linear over the record, and neither the breakpoint nor the
# change of slope at it is determined (the README's 10 samples per parameter).
MIN_SAMPLES_BEYOND = 10


def not_identifiable(params: CascadeParams, errors: dict, u) -> dict[str, str]:
    """The parameters of the estimate `params` that the record (input `u`) does not
    determine, by name, each with the reason in a phrase (an empty dict when all are):

    - a parameter whose standard error (`errors`, by name, from `standard_errors`) is
      infinite: the information is singular in its direction (e.g. two breakpoints that
      coincide, so that their slopes act as one);
    - a breakpoint (`DR_i`, `DL_i`) with fewer than `MIN_SAMPLES_BEYOND` input samples
      on one side, and the change of slope at it (`MR_{i+1}`, `ML_{i+1}`): the record
      holds (almost) no data beyond it, as when the true breakpoint lies outside the
      input's range;
    - a breakpoint whose change of slope is within two standard errors of zero: the
      record shows no kink there to place it by.
    """
    import numpy as np

    u = np.asarray(u, float)
    values = params.to_dict()
    reasons = {
        name: "its standard error is infinite (the record does not separate it from the "
        "other parameters)"
        for name, error in errors.items()
        if not np.isfinite(error)
    }
    for side in ("R", "L"):
        for i in range(1, getattr(params.orders, f"n{side}")):
            breakpoint_, slope = f"D{side}{i}", f"M{side}{i + 1}"
            at = values[breakpoint_]
            beyond = int(min(np.sum(u < at), np.sum(u > at)))
            if beyond < MIN_SAMPLES_BEYOND:
                why = (
                    f"{breakpoint_} = {at:.4g} has {beyond} input sample(s) on one side "
                    f"(input range [{u.min():.4g}, {u.max():.4g}])"
                )
                reasons.setdefault(breakpoint_, why)
                reasons.setdefault(slope, why)
            elif not abs(values[slope]) > 2 * errors[slope]:
                reasons.setdefault(
                    breakpoint_,
                    f"the change of slope at it ({slope} = {values[slope]:.3g} +- "
                    f"{errors[slope]:.2g}) is not distinguishable from zero",
                )
    return {name: reasons[name] for name in params.names if name in reasons}
