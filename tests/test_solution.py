"""`solution_table`: a `Solution` of any batch shape as a DataFrame, one row per record."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcascade as jc
from jaxcascade._estimator._solution import PATH_ADAPTIVE, PATH_MULTISTART


def batch_of(shape) -> jc.Solution:
    # A Solution as nested vmaps return it: every field with leading axes `shape`;
    # record k (in C order) has every parameter k + (its position)/100.
    orders = jc.Orders()
    size = int(np.prod(shape, dtype=int))
    vector = np.arange(size)[:, None] + np.arange(orders.size)[None, :] / 100
    params = jc.CascadeParams.from_vector(
        jnp.asarray(vector.reshape(*shape, -1)), orders, check=False
    )
    codes = np.arange(size) % len(jc.Status)
    paths = np.arange(size) % 3

    def field(values, dtype):
        return jnp.asarray(np.asarray(values, dtype).reshape(shape))

    return jc.Solution(
        params=params,
        history=jnp.zeros((*shape, 2, orders.size)),
        iterations=field(np.arange(size) + 1, np.int32),
        cost=field(np.arange(size) / 10, float),
        status=field(codes, np.int32),
        cycle_amplitude=field(np.zeros(size), float),
        path=field(paths, np.int32),
    )


@pytest.mark.parametrize("shape", [(5,), (2, 3), (2, 1, 2)])
def test_one_row_per_record_in_batch_order(shape):
    table = jc.solution_table(batch_of(shape))
    size = int(np.prod(shape))
    names = list(jc.Orders().names)
    assert len(table) == size
    assert list(table.columns) == [
        *names,
        "status",
        "iterations",
        "cost",
        "cycle_amplitude",
        "path",
    ]
    np.testing.assert_array_equal(table[names[0]], np.arange(size))
    np.testing.assert_array_equal(table[names[-1]], np.arange(size) + (len(names) - 1) / 100)
    assert list(table["status"]) == [jc.Status(k % len(jc.Status)).name for k in range(size)]
    assert list(table["path"]) == [("only", "adaptive", "multistart")[k % 3] for k in range(size)]
    assert (PATH_ADAPTIVE, PATH_MULTISTART) == (1, 2)
    np.testing.assert_array_equal(table["iterations"], np.arange(size) + 1)
    # the index is the position in the batch
    if len(shape) == 1:
        assert table.index.name == "record"
    else:
        assert table.index.names == [f"axis{k}" for k in range(len(shape))]
        assert table.index[-1] == tuple(s - 1 for s in shape)


def test_an_unbatched_solution_is_one_row_and_params_alone_work():
    one = jc.solution_table(batch_of(()))
    assert len(one) == 1 and one["status"].iloc[0] == jc.Status(0).name
    params = jc.solution_table(batch_of((2, 2)).params)
    assert list(params.columns) == list(jc.Orders().names) and len(params) == 4


def test_to_series_of_a_batch_points_to_the_table():
    with pytest.raises(ValueError, match="solution_table"):
        batch_of((3,)).params.to_series()
    with pytest.raises(TypeError, match="Solution or CascadeParams"):
        jc.solution_table(np.zeros(3))
