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
    ExtendedModel,
    InputDelay,
    OutputDrift,
    OutputFeedthrough,
    OutputOffset,
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
    None: lambda: (plain(_example1()), None),
}


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
