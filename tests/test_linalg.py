"""The small SPD algebra without LAPACK, against NumPy."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxcascade import _linalg


def test_cholesky_solves_and_inverse_diagonal_match_numpy():
    rng = np.random.default_rng(0)
    a = rng.standard_normal((30, 7))
    matrix = a.T @ a
    rhs = rng.standard_normal(7)
    factor, ok = _linalg.cholesky(jnp.asarray(matrix))
    assert bool(ok)
    np.testing.assert_allclose(factor, np.linalg.cholesky(matrix), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        _linalg.cho_solve(factor, jnp.asarray(rhs)), np.linalg.solve(matrix, rhs), rtol=1e-10
    )
    np.testing.assert_allclose(
        _linalg.inverse_diagonal(factor), np.diag(np.linalg.inv(matrix)), rtol=1e-10
    )


def test_a_singular_matrix_is_flagged_and_stays_finite():
    matrix = jnp.array([[1.0, 1.0], [1.0, 1.0]])
    factor, ok = _linalg.cholesky(matrix)
    assert not bool(ok) and bool(jnp.all(jnp.isfinite(factor)))


def test_batched_under_vmap():
    rng = np.random.default_rng(1)
    a = rng.standard_normal((5, 20, 4))
    matrices = np.einsum("bti,btj->bij", a, a)
    factors, ok = jax.vmap(_linalg.cholesky)(jnp.asarray(matrices))
    assert bool(jnp.all(ok))
    np.testing.assert_allclose(factors, np.linalg.cholesky(matrices), rtol=1e-12, atol=1e-12)


def test_spd_solve_matches_numpy_and_flags_a_bad_pivot():
    rng = np.random.default_rng(2)
    a = rng.standard_normal((30, 7))
    matrix = a.T @ a
    rhs = rng.standard_normal(7)
    solution, ok = _linalg.spd_solve(jnp.asarray(matrix), jnp.asarray(rhs))
    assert bool(ok)
    np.testing.assert_allclose(solution, np.linalg.solve(matrix, rhs), rtol=1e-10)
    _, ok = _linalg.spd_solve(jnp.array([[1.0, 1.0], [1.0, 1.0]]), jnp.ones(2))
    assert not bool(ok)
    solution, ok = _linalg.spd_solve(-jnp.eye(2), jnp.ones(2))
    assert not bool(ok) and bool(jnp.all(jnp.isfinite(solution)))


def test_gauss_jordan_pivots_are_the_squared_cholesky_diagonal():
    rng = np.random.default_rng(3)
    a = rng.standard_normal((30, 6))
    matrix = a.T @ a
    rhs = np.concatenate([rng.standard_normal((6, 1)), np.eye(6)], axis=1)
    solution, pivots = _linalg.gauss_jordan(jnp.asarray(matrix), jnp.asarray(rhs))
    np.testing.assert_allclose(pivots, np.diag(np.linalg.cholesky(matrix)) ** 2, rtol=1e-12)
    np.testing.assert_allclose(solution, np.linalg.solve(matrix, rhs), rtol=1e-10, atol=1e-12)
