"""Small dense symmetric positive-definite algebra in plain `jnp` (loops over the static
size P, a few tens at most).

Why not `jnp.linalg.cholesky` and `jax.scipy.linalg.solve_triangular`: on CPU, jaxlib
(0.10) runs a batched LAPACK call by splitting its batch over XLA's intra-op thread pool
and waiting for the pieces. Two such calls that XLA schedules at the same time (for
instance two independent branches of one `vmap`-ed program) can each wait for pool
threads the other holds: on a 2-core machine the program deadlocks at 0% CPU (seen with
`cholesky` and `eigh` beside the fused kernel: every thread in a futex wait). For the
P x P systems of this package (P <= ~70) a plain loop costs about the same.
`fori_loop` keeps the traced program, and the compile time, small.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def cholesky(matrix):
    """Lower Cholesky factor `L` of a symmetric positive-definite matrix, and whether every
    pivot was positive and finite. A non-positive pivot is replaced by 1 (the flag says
    so), so `L` is always finite where `matrix` is."""
    size = matrix.shape[-1]
    rows = jnp.arange(size)

    def body(j, carry):
        factor, ok = carry
        row = factor[j]
        pivot = matrix[j, j] - row @ row
        good = jnp.isfinite(pivot) & (pivot > 0)
        root = jnp.sqrt(jnp.where(good, pivot, 1.0))
        column = (matrix[:, j] - factor @ row) / root
        column = jnp.where(rows > j, column, jnp.where(rows == j, root, 0.0))
        return factor.at[:, j].set(column), ok & good

    return jax.lax.fori_loop(0, size, body, (jnp.zeros_like(matrix), jnp.ones((), bool)))


def solve_lower(factor, rhs):
    """`L^-1 rhs` for lower-triangular `L` (forward substitution); `rhs` a vector."""
    size = factor.shape[-1]

    def body(i, z):
        return z.at[i].set((rhs[i] - factor[i] @ z) / factor[i, i])

    return jax.lax.fori_loop(0, size, body, jnp.zeros_like(rhs))


def solve_upper_transposed(factor, rhs):
    """`L^-T rhs` for lower-triangular `L` (back substitution); `rhs` a vector."""
    size = factor.shape[-1]

    def body(k, x):
        i = size - 1 - k
        return x.at[i].set((rhs[i] - factor[:, i] @ x) / factor[i, i])

    return jax.lax.fori_loop(0, size, body, jnp.zeros_like(rhs))


def cho_solve(factor, rhs):
    """`(L L^T)^-1 rhs`."""
    return solve_upper_transposed(factor, solve_lower(factor, rhs))


def inverse_diagonal(factor):
    """`diag((L L^T)^-1)`: the column sums of squares of `L^-1`."""
    identity = jnp.eye(factor.shape[-1], dtype=factor.dtype)
    inverse = jax.vmap(lambda e: solve_lower(factor, e), out_axes=1)(identity)
    return jnp.sum(inverse**2, axis=0)


def gauss_jordan(matrix, rhs):
    """`(matrix^-1 rhs, pivots)` by Gauss-Jordan elimination without pivoting, for a
    symmetric positive-definite `matrix` (stable there: its pivots are the squared
    diagonal of its Cholesky factor) and `rhs` a matrix (one right-hand side per
    column). A pivot that is not positive and finite is replaced by 1 (the returned
    `pivots` keep the value found), so the result is finite where the inputs are. One
    loop: the compile time of a call site is mostly its loops' bodies, and this one
    replaces the three of `cholesky` and `cho_solve`."""
    size = matrix.shape[-1]
    rows = jnp.arange(size)

    def body(j, carry):
        augmented, pivots = carry
        pivot = augmented[j, j]
        good = jnp.isfinite(pivot) & (pivot > 0)
        row = augmented[j] / jnp.where(good, pivot, 1.0)
        factors = jnp.where(rows == j, 0.0, augmented[:, j])
        augmented = (augmented - factors[:, None] * row[None, :]).at[j].set(row)
        return augmented, pivots.at[j].set(pivot)

    augmented = jnp.concatenate([matrix, rhs], axis=1)
    augmented, pivots = jax.lax.fori_loop(
        0, size, body, (augmented, jnp.zeros((size,), matrix.dtype))
    )
    return augmented[:, size:], pivots


def positive(pivots):
    """Whether every pivot of `gauss_jordan` was positive and finite."""
    return jnp.all(jnp.isfinite(pivots) & (pivots > 0))


def spd_solve(matrix, rhs):
    """`matrix^-1 rhs` for a symmetric positive-definite `matrix` and a vector `rhs`, and
    whether every pivot was positive and finite (`gauss_jordan`)."""
    solution, pivots = gauss_jordan(matrix, rhs[:, None])
    return solution[:, 0], positive(pivots)
