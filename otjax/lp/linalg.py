"""Dense symmetric positive definite solves written in plain XLA operations.

On CPU, JAX sends ``cholesky`` and triangular solves to the OpenBLAS that
SciPy ships, whose worker threads spin against every other process on a
shared machine: 40 Cholesky solves of 128 x 128 took 0.2-2.4 s with its
default threads against 0.02-0.03 s with one thread and 0.07 s here
(``docs/decisions.md#lp_solver``). This block Gauss-Jordan elimination
stays in XLA's own thread pool, spends its time in matrix products, and
vectorises over a ``vmap`` batch.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

# Rows eliminated per block: the products' inner size (docs/decisions.md#lp_solver).
BLOCK = 32


def _invert_small(d: jax.Array) -> jax.Array:
    """``d^-1`` of a small SPD block by unblocked Gauss-Jordan (no pivoting: SPD pivots are positive)."""
    n = d.shape[0]

    def step(k, aug):
        row = aug[k] / aug[k, k]
        factor = aug[:, k].at[k].set(0)
        return (aug - jnp.outer(factor, row)).at[k].set(row)

    aug = jnp.concatenate([d, jnp.eye(n, dtype=d.dtype)], axis=1)
    return jax.lax.fori_loop(0, n, step, aug)[:, n:]


def spd_solve(a: jax.Array, rhs: jax.Array, block: int = BLOCK) -> jax.Array:
    """``a^-1 rhs`` for a symmetric positive definite ``a``.

    Args:
      a: ``(n, n)`` float, symmetric positive definite.
      rhs: ``(n, r)`` float.
      block: rows eliminated per step (the largest divisor of ``n`` up to
        it; capacity classes are powers of two).

    Returns:
      ``(n, r)``: the solution, by block Gauss-Jordan elimination of
      ``[a | rhs]`` (``n / block`` steps of rank-``block`` updates, about
      ``2 n^2 (n + r)`` flops).

    Example:
      >>> a = jnp.array([[4.0, 2.0], [2.0, 3.0]])
      >>> spd_solve(a, jnp.array([[6.0], [5.0]])).ravel().tolist()
      [1.0, 1.0]
    """
    n = a.shape[0]
    nb = max(d for d in range(1, min(block, n) + 1) if n % d == 0)
    width = n + rhs.shape[1]
    idx = jnp.arange(n)

    def eliminate(b, aug):
        k0 = b * nb
        rows = jax.lax.dynamic_slice(aug, (k0, 0), (nb, width))
        pivot = jax.lax.dynamic_slice(rows, (0, k0), (nb, nb))
        rows = _invert_small(pivot) @ rows
        panel = jax.lax.dynamic_slice(aug, (0, k0), (n, nb))
        panel = jnp.where(((idx >= k0) & (idx < k0 + nb))[:, None], 0, panel)
        return jax.lax.dynamic_update_slice(aug - panel @ rows, rows, (k0, 0))

    aug = jnp.concatenate([a, rhs], axis=1)
    return jax.lax.fori_loop(0, n // nb, eliminate, aug)[:, n:]
