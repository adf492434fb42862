"""The linear output-error model (`_measured/_oe.py`) and the loop's linear floor."""

import jax
import numpy as np
import pytest
import scipy.signal

import jaxcascade as jc
from jaxcascade._measured._loop import LINEAR_FLOOR, floor_model, model_error_loop, simulated_output
from jaxcascade._measured._oe import OE, cascade_vector, fit_oe, linear_floor
from jaxcascade._measured._testing import UNDECLARED, undeclared_record
from jaxcascade._system._model import Orders

B, F, C = (
    [0.5, 0.3],
    [-1.2, 0.5],
    0.2,
)  # y = (0.5 q^-1 + 0.3 q^-2) / (1 - 1.2 q^-1 + 0.5 q^-2) u + c


def _record(seed, n=3000, sigma=0.05):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=n)
    y = scipy.signal.lfilter([0.0, *B], [1.0, *F], u) + C
    return u, y + sigma * rng.normal(size=n)


def test_fit_oe_recovers_an_output_error_system():
    # white output noise of 0.05 against an output of spread about 1: the estimates
    # within 0.02 of the truth (their standard errors are a few thousandths)
    u, y = _record(0)
    model = fit_oe([u], [y], 2, 2)
    np.testing.assert_allclose(model.b, B, atol=0.02)
    np.testing.assert_allclose(model.f, F, atol=0.02)
    assert abs(model.c - C) < 0.02
    # the integrated criterion (outputs that are differences) finds the same system
    assert np.allclose(fit_oe([u], [y], 2, 2, integrated=True).f, F, atol=0.03)


def test_linear_floor_chooses_the_orders_on_validation():
    u, y = _record(1)
    u_val, y_val = _record(2)
    model, error = linear_floor([u], [y], [u_val], [y_val])
    assert model.orders == (2, 2)  # higher orders are no better by 0.1 %: the fewest win
    assert error < 0.1


def test_cascade_form_is_the_linear_model():
    # the cascade of orders (1, 1, nb, nf) with equal slopes, no gap and the offset as an
    # output offset simulates the output-error model
    oe = OE(np.array(B), np.array(F), C)
    u = np.random.default_rng(3).uniform(-2, 2, 500)
    model = floor_model(oe)
    np.testing.assert_allclose(simulated_output(model, u), oe.simulate(u), atol=1e-7)
    # inside larger orders: the same vector, zeros beyond, breakpoints where asked
    vector = cascade_vector(oe, Orders(2, 2, 3, 3), {"DR1": 0.7})
    values = dict(zip(Orders(2, 2, 3, 3).names, vector, strict=True))
    assert values["MR1"] == values["ML1"] == B[0] and values["MR2"] == 0.0
    assert values["DR1"] == 0.7 and values["a3"] == 0.0 and values["b3"] == 0.0
    # no gain at lag 1 (a delay the cascade's normalisation cannot hold): no cascade form
    assert cascade_vector(OE(np.array([0.0, 1.0]), np.array(F), 0.0), Orders(1, 1, 2, 2)) is None
    assert cascade_vector(oe, Orders(1, 1, 1, 2)) is None  # more zeros than the orders


@pytest.mark.parametrize("max_effects", [0])
def test_final_model_never_worse_than_the_linear_floor(max_effects):
    # Example 1 behind an input delay of two samples, declared without it: the declared
    # cascade misses the delay (validation NRMSE about 0.6) and the linear output-error
    # model of four zeros holds it (about 0.4); with no effect allowed, the floor
    # replaces the final model
    model, ar = UNDECLARED["input_delay"]()
    u, y = undeclared_record(model, jax.random.PRNGKey(1), 1024, 20.0, ar)
    u_val, y_val = undeclared_record(model, jax.random.PRNGKey(2), 1024, 20.0, ar)
    result = model_error_loop(u, y, u_val, y_val, jc.Orders(), max_effects=max_effects)
    assert result.floor is not None
    assert result.added == [LINEAR_FLOOR]
    assert result.actions[-1]["action"] == "floor"
    assert result.after.error < result.before.error
    assert result.after.error <= result.floor.host_error * 1.05
    assert result.to_dict()["linear_floor"]["orders"]["nb"] == result.floor.oe.orders[0]
