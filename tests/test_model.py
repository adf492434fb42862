"""Parameters and orders: names, conversions, invariants, stability test."""

import jax
import jax.numpy as jnp
import numpy as np
import oracle
import pytest

from jaxcascade import CascadeParams, Orders, example, is_stable

ORDERS = [Orders(2, 2, 2, 2), Orders(1, 1, 1, 0), Orders(3, 2, 3, 1), Orders(2, 3, 1, 2)]


def test_names_follow_theta_order():
    assert Orders(2, 2, 2, 2).names == (
        "MR1", "MR2", "DR1", "ML1", "ML2", "DL1", "a2", "b1", "b2", "cL", "mR", "cR"
    )  # fmt: skip
    assert Orders(1, 1, 1, 0).names == ("MR1", "ML1", "cL", "mR", "cR")
    for orders in ORDERS:
        assert list(orders.names) == oracle.names(orders)
        assert orders.size == len(orders.names)


@pytest.mark.parametrize("orders", ORDERS, ids=str)
def test_roundtrips(orders):
    vector = oracle.random_system(np.random.default_rng(1), orders)
    params = CascadeParams.from_vector(jnp.asarray(vector), orders)
    # conversions only copy and reorder, except C = cR mR and back (one rounding each)
    np.testing.assert_array_equal(params.to_vector(), vector)
    theta = params.to_theta()
    assert theta[-1] == pytest.approx(vector[-1] * vector[-2], rel=1e-15)
    np.testing.assert_array_equal(theta[:-1], vector[:-1])
    np.testing.assert_allclose(
        CascadeParams.from_theta(theta, orders).to_vector(), vector, rtol=1e-15
    )
    values = params.to_dict()
    assert list(values) == list(orders.names)
    assert values == dict(zip(oracle.names(orders), vector.tolist(), strict=True))
    for given in (orders, None):  # orders inferred from the names when not given
        again = CascadeParams.from_dict(values, given)
        assert again.orders == orders
        np.testing.assert_array_equal(again.to_vector(), vector)
    series = params.to_series()
    assert list(series.index) == list(orders.names)
    np.testing.assert_array_equal(series.to_numpy(), vector)


def test_example_values():
    params = example(1).params()
    assert params.to_dict()["b1"] == -0.2 and params.to_dict()["b2"] == 0.35
    assert params.to_vector().dtype == jnp.float64


def test_batched_params():
    rng = np.random.default_rng(2)
    orders = Orders(2, 2, 2, 2)
    vectors = np.stack([oracle.random_system(rng, orders) for _ in range(4)])
    params = CascadeParams.from_vector(jnp.asarray(vectors), orders)
    assert params.MR.shape == (4, 2) and params.mR.shape == (4,)
    np.testing.assert_array_equal(params.to_vector(), vectors)
    with pytest.raises(ValueError, match="single parameter set"):
        params.to_dict()
    bad = vectors.copy()
    bad[2, orders.names.index("mR")] = -1.0  # one bad member of a batch is refused
    with pytest.raises(ValueError, match="mR must be positive"):
        CascadeParams.from_vector(jnp.asarray(bad), orders)


def test_no_check_under_jit():
    # Tier 3: traced values are never checked (an estimator reports, it does not raise).
    orders = Orders(2, 2, 2, 2)
    bad = oracle.random_system(np.random.default_rng(3), orders)
    bad[orders.names.index("mR")] = -1.0
    out = jax.jit(lambda v: CascadeParams.from_vector(v, orders).to_vector())(jnp.asarray(bad))
    np.testing.assert_array_equal(out, bad)


WIDE = Orders(3, 3, 2, 2)


def _valid():
    return oracle.unpack(oracle.random_system(np.random.default_rng(4), WIDE), WIDE)


def _build(P):
    return CascadeParams(
        MR=jnp.asarray(P["MR"]),
        DR=jnp.asarray(P["DR"]),
        ML=jnp.asarray(P["ML"]),
        DL=jnp.asarray(P["DL"]),
        a=jnp.asarray(P["a"]),
        b=jnp.asarray(P["b"]),
        cL=jnp.asarray(P["cL"]),
        mR=jnp.asarray(P["mR"]),
        cR=jnp.asarray(P["cR"]),
        orders=WIDE,
    )


@pytest.mark.parametrize(
    "change, message",
    [
        ({"DR": [1.2, 0.8]}, "DR must be positive and increasing"),
        ({"DR": [-0.1, 0.8]}, "DR must be positive and increasing"),
        ({"DL": [-1.2, -0.8]}, "DL must be negative and decreasing"),
        ({"DL": [0.2, -0.8]}, "DL must be negative and decreasing"),
        ({"mR": 0.0}, "mR must be positive"),
        ({"mR": -0.5}, "mR must be positive"),
        ({"cL": -0.1}, "gaps must be non-negative"),
        ({"cR": -0.1}, "gaps must be non-negative"),
        ({"MR": [1.0, 2.0]}, "MR must have length"),
        ({"DL": [-1.0]}, "DL must have length"),
        ({"a": [0.1, 0.2]}, "a must have length"),
        ({"b": []}, "b must have length"),
        ({"cL": float("nan")}, "finite"),
        ({"DR": [0.5, float("inf")]}, "finite"),
    ],
)
def test_invalid_params_refused(change, message):
    P = _valid()
    _build(P)  # the unchanged draw is valid
    with pytest.raises(ValueError, match=message):
        _build({**P, **change})


def test_invalid_vectors_and_dicts_refused():
    orders = Orders(2, 2, 2, 2)
    values = CascadeParams.from_vector(
        jnp.asarray(oracle.random_system(np.random.default_rng(5), orders)), orders
    ).to_dict()
    with pytest.raises(ValueError, match="must have 12 entries"):
        CascadeParams.from_vector(jnp.zeros(11), orders)
    with pytest.raises(ValueError, match="missing \\['cR'\\]"):
        CascadeParams.from_dict({k: v for k, v in values.items() if k != "cR"}, orders)
    with pytest.raises(ValueError, match="unexpected \\['b3'\\]"):
        CascadeParams.from_dict({**values, "b3": 0.1}, orders)


def test_orders_parse_and_validation():
    assert Orders.parse("2,3,1,0") == Orders(nR=2, nL=3, r=1, p=0)
    assert Orders.parse(" 1, 1 ,2,2 ") == Orders(1, 1, 2, 2)
    assert Orders.parse(str(Orders(3, 2, 1, 4))) == Orders(3, 2, 1, 4)
    assert Orders.parse("2,2,2,2,3") == Orders(2, 2, 2, 2, degree=3)
    for text in ("2,2,2", "2,2,2,2,2,2", "a,2,2,2", "2.5,2,2,2", ""):
        with pytest.raises(ValueError, match="four integers"):
            Orders.parse(text)
    for text, field in (("0,2,2,2", "nR"), ("2,0,2,2", "nL"), ("2,2,0,2", "r"), ("2,2,2,-1", "p")):
        with pytest.raises(ValueError, match=f"Order {field} must be an integer"):
            Orders.parse(text)
    with pytest.raises(ValueError, match="Order nR must be an integer"):
        Orders(nR=1.5)


@pytest.mark.parametrize("p", [1, 2, 3, 4])
def test_is_stable_matches_roots(p):
    rng = np.random.default_rng(10 + p)
    b = rng.uniform(-1.5, 1.5, (300, p))
    radius = np.array([np.max(np.abs(np.roots(np.concatenate([[1.0], row])))) for row in b])
    keep = np.abs(radius - 1) > 1e-6  # roots on the circle are a tie; rounding decides
    expected = radius[keep] < 1
    assert min(expected.sum(), (~expected).sum()) >= 10  # the draw tests both answers
    got = np.asarray(jax.vmap(is_stable)(jnp.asarray(b[keep])))
    np.testing.assert_array_equal(got, expected)


def test_is_stable_edge_cases():
    assert bool(is_stable(jnp.zeros((0,))))  # p = 0: no poles
    assert bool(is_stable(jnp.asarray([-0.2, 0.35])))  # the paper's b
    assert not bool(is_stable(jnp.asarray([0.0, 1.0])))  # poles at +-i
    assert not bool(is_stable(jnp.asarray([-2.0, 1.0])))  # double pole at 1
