"""Records with an effect the declared model lacks, for tests and benchmarks
(`benchmarks/effects_loop.py`): Example 1 (declared orders 2,2,2,2) with one effect of
the library present, and the AR coefficient of the output noise (`None`: white); and
the general-backlash examples' records (`CURVED`, `benchmarks/general_backlash_loop.py`):
the cascade declared with straight branches, the record's curved."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._system._examples import example
from .._system._general_backlash import general_example
from .._system._model import CascadeParams
from .._system._simulate import uniform_input
from ._effects import (
    CurvedBacklash,
    DirectTerm,
    ExtendedModel,
    InnerKink,
    InputDelay,
    NonlinearFeedback,
    OutputDrift,
    OutputDynamics,
    OutputFeedthrough,
    OutputFold,
    OutputOffset,
    OutputPolynomial,
    OutputSaturation,
    plain,
    simulate_extended,
)
from ._noise import ARNoise


def _example1():
    return example(1).params()


def _with(effect):
    return ExtendedModel(_example1(), (effect,), ARNoise.white())


def _changed(**values):
    v = _example1().to_dict()
    v.update(values)
    return plain(CascadeParams.from_dict(v))


def _extra_pole():
    b = np.real(np.poly([0.5, 0.3 + 0.4j, 0.3 - 0.4j]))[1:]
    return _changed(b1=b[0], b2=b[1], b3=b[2])


def _scalar(value):
    return jnp.asarray(value, jnp.result_type(float))


def _vector(*values):
    return jnp.asarray(values, jnp.result_type(float))


# Sizes are identifiable: an output offset within the backlash gaps is exactly a gap
# change (y + d is a backlash with cL + d, cR - d / mR), so the offset here exceeds what
# the gaps can absorb.
UNDECLARED = {
    "output_offset": lambda: (_with(OutputOffset(_scalar(0.6))), None),
    "input_delay": lambda: (_with(InputDelay(_scalar(2.0))), None),
    "dynamics_order": lambda: (_extra_pole(), None),
    "pwl_segment": lambda: (_changed(DR2=1.5, MR3=1.5), None),
    "output_saturation": lambda: (_with(OutputSaturation(_scalar(-0.7), _scalar(0.9))), None),
    "colored_noise": lambda: (plain(_example1()), 0.8),
    "output_drift": lambda: (_with(OutputDrift(_scalar(0.2))), None),
    "output_feedthrough": lambda: (_with(OutputFeedthrough(_scalar(-0.5))), None),
    # what real devices contain (issue 67): a cubic spring in feedback (Example 1's x
    # spans about +-2, so the cubic term moves x by up to about 0.6 there), the input
    # acting within the sample, a square-law output stage, a sign-blind sensor (the
    # magnitude of the output about -0.4: Example 1's output, of mean 0.19 and spread
    # 0.73, crosses that level on about a quarter of its samples, as CED's belt speed
    # crosses zero now and then) and dynamics after the backlash (J. Voros's
    # Wiener-Hammerstein form with backlash)
    "nonlinear_feedback": lambda: (_with(NonlinearFeedback(_vector(0.05, -0.08))), None),
    "direct_term": lambda: (_with(DirectTerm(_vector(0.6))), None),
    "output_polynomial": lambda: (_with(OutputPolynomial(_vector(0.0, 0.15, -0.08))), None),
    "output_fold": lambda: (_with(OutputFold(_vector(0.0, 1.0, 0.0, -0.4))), None),
    "output_dynamics": lambda: (
        _with(OutputDynamics(_vector(0.4), _vector(-0.6), _scalar(0.0))),
        None,
    ),
    None: lambda: (plain(_example1()), None),
}


def _sandwich(static):
    """Example 1, the static map `static` and the second block of `output_dynamics`'s
    record after it: a Wiener-Hammerstein sandwich around the backlash."""
    model, _ = UNDECLARED["output_dynamics"]()
    return model.with_(effects=(static, *model.effects))


# Sandwiches whose static part the loop adds as an inner map (`Effect.inner`): the second
# block may come first and the map then goes between the two blocks. Each entry: the
# model, and the effects that name it, in the order either block may come.
SANDWICHES = {
    "inner_polynomial": lambda: (
        _sandwich(OutputPolynomial(_vector(0.0, 0.15, -0.08))),
        (["output_dynamics", "inner_polynomial"], ["output_polynomial", "output_dynamics"]),
    ),
    "inner_kink": lambda: (
        _sandwich(InnerKink(_vector(0.0, 0.5, 0.0))),
        (["output_dynamics", "inner_kink"],),
    ),
}

# Records whose output integrates its input (`axis_record`): the force and position of
# an axis under proportional control; the loop models the position's difference
# (`model_error_loop(..., integrating=True)`, `_integrating`). Each entry: the axis's
# Coulomb friction forces (up, down), in the velocity's model units.
INTEGRATING = {"velocity_friction": (0.3, 0.4), None: (0.0, 0.0)}


def _curved(name):
    ex = general_example(name)
    dtype = jnp.result_type(float)
    curves = (jnp.asarray(c, dtype) for c in (ex.curveL, ex.curveR))
    return ExtendedModel(ex.params(), (CurvedBacklash(*curves),), ARNoise.white())


# The general-backlash examples (`_general_backlash.GENERAL_EXAMPLES`) as extended models
# (the curved branches as the loop's `general_backlash` effect), with their declared
# orders: `(model, orders)`.
CURVED = {
    name: (lambda name=name: (_curved(name), general_example(name).orders))
    for name in ("general1", "general2")
}


def undeclared_record(model: ExtendedModel, key, n: int, snr: float, ar=None):
    """Input uniform in (-2, 2) and the model's output plus noise at amplitude SNR `snr`
    (white, or AR(1) with coefficient `ar`, scaled to the same variance)."""
    import scipy.signal

    k_input, k_noise = jax.random.split(key)
    u = uniform_input(k_input, n)
    y = simulate_extended(model, u)
    e = np.asarray(jax.random.normal(k_noise, (n,)))
    if ar is not None:
        e = scipy.signal.lfilter([1.0], [1.0, -ar], e)
    e = e / np.std(e) * float(jnp.std(y)) / snr
    return u, y + jnp.asarray(e, y.dtype)


def axis_record(key, n: int, snr: float, friction=(0.3, 0.4)):
    """The force and the measured position of an axis under proportional control (a
    positioning system: EMPS's kind), host side.

    The reference holds zero for 60 samples (the axis at rest), then random levels for
    random spans; the force is
    `F(t) = AXIS_KP (r(t) - y(t))`; the velocity the force and the viscous friction (the
    pole) would give, `w = AXIS_POLE v(t-1) + AXIS_GAIN F(t-1)`, less Coulomb friction,
    `v(t) = w - clip(w, -f-, f+)` (`friction = (f+, f-)`: exactly the loop's
    `velocity_friction` on a linear block of orders (1, 1)); the position `y(t) = y(t-1)
    + v(t)`, read with white noise of amplitude SNR `snr` relative to the velocity (the
    controller acts on the true position, so the force is independent of that noise).
    Returns `(force, measured position)`, NumPy arrays."""
    rng = np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel().tolist())
    r: list[float] = [0.0] * 60  # at rest first: the record starts from rest
    while len(r) < n:
        r += [float(rng.uniform(-AXIS_RANGE, AXIS_RANGE))] * int(rng.integers(60, 240))
    f_up, f_down = (float(f) for f in friction)
    force, velocity, position = np.zeros(n), np.zeros(n), np.zeros(n)
    v = y = f_prev = 0.0
    for t in range(n):
        w = AXIS_POLE * v + AXIS_GAIN * f_prev
        v = w - min(max(w, -f_down), f_up)
        y = y + v
        velocity[t], position[t] = v, y
        force[t] = f_prev = AXIS_KP * (r[t] - y)
    noise = rng.standard_normal(n) * np.std(velocity) / snr
    return force, position + noise


# The axis of `axis_record`: the reference's range, the controller's gain, the velocity's
# pole (viscous friction) and the force's gain on it.
AXIS_RANGE, AXIS_KP, AXIS_POLE, AXIS_GAIN = 40.0, 0.3, 0.8, 1.0
