"""Roots of smooth systems as JAX-differentiable functions of their parameters.

``implicit_root(residual, solve, size)`` returns ``x(theta)``, the root of residual(x, theta) = 0
found on the host by ``solve``, with its derivatives from the implicit function theorem:

    dx = -A^-1 (d residual / d theta) dtheta,   A = d residual / dx at the root.

The rule is written in JAX and calls ``x(theta)`` itself, so ``jax.jvp``, ``jax.jacfwd``,
``jax.grad`` and their compositions (second derivatives by forward-over-reverse, ...) all go through
it, each order from one more differentiation of the residual. A ``jax.custom_jvp`` rather than a
``custom_vjp`` (as ``jaxopt.implicit_diff.custom_root`` has): JAX derives reverse mode from the
linear rule, while a ``custom_vjp`` would rule out forward mode and forward-over-reverse.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["implicit_root"]


def implicit_root(residual, solve, size, jacobian=None):
    """x(theta): the root of ``residual`` that ``solve`` finds, differentiable to any order.

    Parameters
    ----------
    residual : callable
        ``residual(x (m,), theta (k,)) -> (m,)``, traceable and smooth; A = d residual/dx regular
        at the root (a gauge pinned, an extended system regular at its critical point).
    solve : callable
        ``solve(theta: numpy (k,)) -> x: numpy (m,)``, the root on the host (raises if it has none).
    size : int
        m, the root's length.
    jacobian : callable, optional
        ``jacobian(x, theta) -> A (m, m)``, traceable; default ``jax.jacfwd(residual)``. Give one
        where some rows are cheaper by reverse mode (a scalar test function of a matrix).

    Returns
    -------
    callable
        ``x(theta)``: theta (k,) -> x (m,) float64.
    """
    shape = jax.ShapeDtypeStruct((int(size),), jnp.float64)
    jacobian = jax.jacfwd(residual, argnums=0) if jacobian is None else jacobian

    def host(theta):
        return np.asarray(solve(np.asarray(theta, dtype=np.float64)), dtype=np.float64)

    @jax.custom_jvp
    def root(theta):
        return jax.pure_callback(host, shape, jnp.asarray(theta, jnp.float64), vmap_method="sequential")

    @root.defjvp
    def _root_jvp(primals, tangents):
        theta, dtheta = primals[0], tangents[0]
        x = root(theta)  # itself: the next order differentiates this rule again
        b = jax.jvp(lambda t: residual(x, t), (theta,), (dtheta,))[1]
        return x, -jnp.linalg.solve(jacobian(x, theta), b)

    return root
