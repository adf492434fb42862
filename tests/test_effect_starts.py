"""Every effect's starts on records unlike the paper's (Hypothesis): inputs that never
cross zero, constant stretches, quantised and clipped outputs, an offset of 1e3, a record
of the minimum length. Real records are like this (a pump voltage, a level, a sign-blind
speed sensor); the loop's candidate stage must get finite starts from them, or none for
an effect that cannot apply (a segment where the input never goes), never a traceback.
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jaxcascade as jc
from jaxcascade._data import Scaling
from jaxcascade._measured._effects import EFFECTS, plain

ORDERS = jc.Orders(2, 2, 2, 2)


def _record(draw_kind, seed, length, offset, quantum, clip, constant):
    """A measured-looking record in physical units from a few drawn traits."""
    rng = np.random.default_rng(seed)
    t = np.arange(length)
    u = np.sin(2 * np.pi * t / 37.0) + 0.5 * rng.standard_normal(length)
    if draw_kind == "positive":
        u = np.abs(u) + 0.1  # never crosses zero (a pump voltage)
    elif draw_kind == "negative":
        u = -np.abs(u) - 0.1
    elif draw_kind == "mostly_positive":
        u = u + 2.0
    if constant:
        u[length // 4 : length // 2] = u[length // 4]  # a constant stretch
    u = u + offset
    y = np.convolve(np.tanh(u - offset), [0.5, 0.3, 0.2], mode="same")
    y = y + 0.05 * rng.standard_normal(length) + offset
    if quantum:
        y = np.round(y / quantum) * quantum
    if clip:
        y = np.clip(y, np.quantile(y, 0.1), np.quantile(y, 0.9))
    if np.ptp(y) == 0:
        y = y + 1e-3 * t
    return u, y


records = st.builds(
    _record,
    st.sampled_from(["positive", "negative", "mostly_positive", "both"]),
    st.integers(0, 2**16),
    st.sampled_from([ORDERS.min_samples, 300]),
    st.sampled_from([0.0, 1e3]),
    st.sampled_from([0.0, 0.05]),
    st.booleans(),
    st.booleans(),
)


def _model(u, y):
    """The declared cascade in model units, as the loop starts from it."""
    p = jc.example(1).params()
    return plain(p)


@pytest.mark.parametrize("name", sorted(EFFECTS))
@settings(
    max_examples=3,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(record=records)
def test_every_effect_starts_on_any_record(name, record):
    u, y = record
    scaling = Scaling.from_data(u, y, "auto")
    u, y = scaling.to_model(u, y)
    model = _model(u, y)
    residual = y - np.asarray(jc.simulate(model.params, u))
    starts = EFFECTS[name].starts_records(model, [(u, y, residual)])
    assert isinstance(starts, list)
    for start in starts:
        assert np.all(np.isfinite(start.vectors)), start.label
        for value in start.effect.parameters().values():
            assert np.all(np.isfinite(value)), start.label


@pytest.mark.parametrize("side", ["positive", "negative"])
def test_one_sided_input_gets_segments_on_its_side_only(side):
    u, y = _record(side, 0, 300, 0.0, 0.0, False, False)
    model = plain(jc.example(1).params())
    starts = EFFECTS["pwl_segment"].starts(model, u, y, y)
    assert [s.label for s in starts] == [f"pwl_segment:{'right' if side == 'positive' else 'left'}"]


def test_auto_scaling_centres_an_input_that_never_crosses_zero():
    u = np.linspace(1.0, 3.0, 200)
    y = np.sin(u)
    assert Scaling.from_data(u, y, "auto").method == "standard"
    assert Scaling.from_data(u - 2.0, y, "auto").method == "scale"
    # 4 % of the samples below zero: still one-sided for the rule
    v = np.where(np.arange(200) < 8, -1.0, 1.0)
    assert Scaling.from_data(v, y, "auto").method == "standard"
