"""Forward sensitivities: the output's Jacobian equals `jax.jacfwd` of the simulator."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcascade as jc
from jaxcascade._compile import jit
from jaxcascade._estimator._sensitivity import output_jacobian
from jaxcascade._system._model import CascadeParams
from jaxcascade._system._simulate import signals

POINTS = [
    (jc.Orders(), lambda o: jc.example(1).params()),
    (jc.Orders(), lambda o: jc.example(2).params()),
    (jc.Orders(), lambda o: jc.random_system(jax.random.PRNGKey(0), o)),
    (jc.Orders(3, 2, 3, 3), lambda o: jc.random_system(jax.random.PRNGKey(7), o)),
    (jc.Orders(1, 1, 1, 0), lambda o: jc.random_system(jax.random.PRNGKey(3), o)),
]


@pytest.mark.parametrize("orders, draw", POINTS)
def test_output_jacobian_equals_jacfwd(orders, draw):
    params = draw(orders)
    u = jc.uniform_input(jax.random.key(1), 300)

    def output(vector):
        return signals(CascadeParams.from_vector(vector, orders, check=False), u).y

    # compiled: eager `lax.scan`s under `jacfwd` compile a program per primitive call
    want = jit(jax.jacfwd(output))(params.to_vector())
    y, J = jit(output_jacobian)(params, u)
    assert J.shape == (300, orders.size)
    # exact up to rounding: the same switching decisions, the same arithmetic up to order
    np.testing.assert_allclose(y, jit(output)(params.to_vector()), rtol=0, atol=1e-12)
    np.testing.assert_allclose(J, want, rtol=0, atol=1e-8)
    assert float(jnp.max(jnp.abs(want))) > 0.5  # a Jacobian worth comparing
