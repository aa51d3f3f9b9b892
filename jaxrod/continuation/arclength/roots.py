"""An equilibrium, a fold or a simple branch point of a problem, as a root that moves with the
problem's parameters theta (k,) and that JAX differentiates (``jaxrod.solve.implicit``).

Each is the root of a system that is regular there (locate.py):

- an equilibrium at fixed p: F(u, p, args(theta)) = 0 in x = u;
- a fold: (F, sigma) = 0 in x = (u, p), sigma from [[J, b], [b^T, 0]] [w; sigma] = [0; 1];
- a simple branch point: (F + beta v0, sigma, tau = w^T F_p) = 0 in x = (u, p, beta) (Moore's
  unfolding; beta = 0 at the root while the symmetry that makes the branch point persists).

A ``RootSystem`` holds the traceable residual G(x, theta) with its Jacobian in x, the root x0 at
the base values theta0, and ``solve(theta)``: Newton's method on the same system on the host, from
x0, with the problem's own compiled programs (``fold_newton``, ``unfolded_newton``, its
linearisation) and its args at theta (a knot's neighbourhood refreshed by ``update_args`` until
it holds at the root). The traced residual is evaluated with ``exact_args`` (for a knot, the args
without a neighbourhood: the exact energy, which the neighbourhood's equals wherever it is valid),
so its derivatives hold wherever the contact set has moved. The borders b and v0 are held fixed:
the root does not depend on them while the bordered matrix stays regular.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from .locate import fold_newton, unfolded_newton
from .scales import scaled_options

__all__ = ["RootSystem", "equilibrium_root", "fold_root", "branch_point_root"]


@dataclass(frozen=True)
class RootSystem:
    """kind: 'equilibrium', 'fold' or 'branch_point'; x0 (m,): the root at theta0 (k,); residual,
    jacobian: traceable (x, theta) -> (m,), (m, m); solve: numpy theta (k,) -> numpy x (m,) (raises
    RuntimeError where Newton finds no root); p_index: the index of p in x (None for an
    equilibrium); n: the length of u."""

    kind: str
    x0: np.ndarray
    theta0: np.ndarray
    residual: Callable
    jacobian: Callable
    solve: Callable
    p_index: int | None
    n: int


def _bordered(J, b):
    """(w (n,), sigma) with [[J, b], [b^T, 0]] [w; sigma] = [0; 1] (dense, traceable)."""
    n = J.shape[0]
    M = jnp.block([[J, b[:, None]], [b[None, :], jnp.zeros((1, 1))]])
    z = jnp.linalg.solve(M, jnp.zeros(n + 1).at[n].set(1.0))
    return z[:n], z[n]


def _bordered_solve(J, b, f):
    """y (n,) with [[J, b], [b^T, 0]] [y; eta] = [f; 0] (dense, traceable)."""
    n = J.shape[0]
    M = jnp.block([[J, b[:, None]], [b[None, :], jnp.zeros((1, 1))]])
    return jnp.linalg.solve(M, jnp.append(f, 0.0))[:n]


def _contracted_gradient(F, u, p, theta, a, c, t):
    """The gradient in (u, p) ((n + 1,)) of a^T (J(u, p) c + t F_p(u, p)), a, c and t held fixed.

    With w and y from the bordered systems (the w and y of ``_bordered``, ``_bordered_solve``),
    d sigma = -w^T dJ w and d tau = w^T d(F_p - J y) hold at every (u, p), not only at the root
    (differentiate M [w; sigma] = [0; 1] and multiply by [w; sigma]^T, M symmetric): so these
    gradients, with w and y computed from (u, p) by the caller, are sigma's and tau's gradients as
    functions, and differentiating them again gives the higher derivatives. They cost one reverse
    pass each, against one per DOF through the assembled J."""
    def contracted(y):
        return jnp.dot(a, jax.jvp(lambda v, q: F(v, q, theta), (y[:-1], y[-1]), (c, jnp.asarray(t, y.dtype)))[1])

    return jax.grad(contracted)(jnp.append(u, p))


import os
structured = os.environ.get('STRUCT') == '1'
def _linear_parts(problem, set_values, exact_args):
    """F(u, p, theta) and (F, J, F_p)(u, p, theta), traceable, with args = set_values(exact_args, theta)."""
    def F(u, p, theta):
        return problem.F(u, p, set_values(exact_args, theta))

    def linear(u, p, theta):
        f, fp = jax.jvp(lambda q: F(u, q, theta), (p,), (jnp.ones_like(p),))
        if problem.jacobian is not None and structured:
            return f, problem.jacobian(u, p, set_values(exact_args, theta)), fp
        return f, jax.jacfwd(lambda y: F(y, p, theta))(u), fp

    return F, linear


def _host_solve(kind, problem, set_values, x0, theta0, newton, tol):
    """solve(theta) -> x: Newton (``newton(args, x_start) -> (x, u, p, residual)``) at the problem's
    args with the values theta (concrete: ``scene.with_params`` checks them), from the nearest root
    found so far; where it fails, the way from that root is halved (4 times at most). A knot's
    neighbourhood is refreshed at each root until it holds. RuntimeError where no root is found."""
    found = [(np.asarray(theta0, dtype=float), np.asarray(x0, dtype=float))]

    def at(theta, x_start):
        args = set_values(problem.args, [float(v) for v in theta])
        for _ in range(3):
            x, u, p, res = newton(args, x_start)
            if not (np.all(np.isfinite(x)) and np.isfinite(res)) or problem.update_args is None:
                break
            fresh = problem.update_args(u, p, args)
            if fresh is args:
                break
            args, x_start = fresh, x
        return x, res

    def solve(theta):
        theta = np.asarray(theta, dtype=np.float64)
        near_theta, x = min(found, key=lambda item: float(np.linalg.norm(item[0] - theta)))
        way, res = [theta], math.inf
        while way:
            x_new, res = at(way[-1], x)
            if np.isfinite(res) and res <= tol:
                near_theta, x = way.pop(), x_new
                found.append((near_theta, x))
            elif len(way) < 5:
                way.append(0.5 * (near_theta + way[-1]))
            else:
                raise RuntimeError(f"the {kind} was not found at parameter values {theta.tolist()}: Newton's "
                                   f"residual {res:.3e} > {tol:.1e} (the values are too far from the base values for "
                                   "this root to be followed, or it ceased to exist)")
        del found[1:-32]  # the base root and the last 32
        return x

    return solve


def equilibrium_root(problem, u, p, set_values, theta0, exact_args=None):
    """The equilibrium u (n,) of ``problem`` at the twist p as a RootSystem in x = u.

    set_values(args, theta) -> args, traceable, sets the parameters theta (k,) (theta0 gives the
    problem's own args); exact_args: the args the residual is evaluated with (default problem.args).
    The problem's backend must give a dense J (``DenseBackend``).
    """
    F, _ = _linear_parts(problem, set_values, problem.args if exact_args is None else exact_args)
    opts = scaled_options(problem, None, np.asarray(u), float(p))
    u0, p = np.asarray(u, dtype=float), float(p)

    def residual(x, theta):
        return F(x, jnp.asarray(p, jnp.float64), theta)

    def newton(args, x):
        res, prev = math.inf, math.inf
        for _ in range(opts.locate_max_iter + 1):
            f, J, _ = problem.linearise(x, p, args)
            res, prev = float(np.linalg.norm(np.asarray(f))), res
            if not np.isfinite(res) or (res <= opts.newton_tol and (prev <= opts.newton_tol or res <= 1e-3 * opts.newton_tol)):
                break
            x = x - np.linalg.solve(np.asarray(J), np.asarray(f))
        return x, x, p, res

    solve = _host_solve("equilibrium", problem, set_values, u0, theta0, newton, opts.newton_tol)
    return RootSystem("equilibrium", u0, np.asarray(theta0, dtype=float), residual, jax.jacfwd(residual), solve, None,
                      u0.size)


def fold_root(problem, u, p, v, set_values, theta0, exact_args=None):
    """The fold at (u (n,), p) with critical vector v (n,) as a RootSystem in x = (u, p); arguments
    as ``equilibrium_root``."""
    F, linear = _linear_parts(problem, set_values, problem.args if exact_args is None else exact_args)
    b = np.asarray(v, dtype=float) / np.linalg.norm(v)
    opts = scaled_options(problem, None, np.asarray(u), float(p))

    def residual(x, theta):
        f, J, _ = linear(x[:-1], x[-1], theta)
        return jnp.append(f, _bordered(J, b)[1])

    def jacobian(x, theta):
        _, J, fp = linear(x[:-1], x[-1], theta)
        w, _ = _bordered(J, b)
        sigma_x = -_contracted_gradient(F, x[:-1], x[-1], theta, w, w, 0.0)
        return jnp.vstack([jnp.hstack([J, fp[:, None]]), sigma_x[None, :]])

    def newton(args, x):
        u1, p1, _, _, res, _ = fold_newton(problem, opts, x[:-1], x[-1], b, args=args)
        return np.append(u1, p1), u1, p1, res

    solve = _host_solve("fold", problem, set_values, np.append(u, p), theta0, newton, opts.newton_tol)
    n = int(np.size(u))
    return RootSystem("fold", np.append(u, p), np.asarray(theta0, dtype=float), residual, jacobian, solve, n, n)


def branch_point_root(problem, u, p, v, set_values, theta0, exact_args=None):
    """The simple branch point at (u (n,), p) with critical vector v (n,) as a RootSystem in
    x = (u, p, beta); arguments as ``equilibrium_root``."""
    F, linear = _linear_parts(problem, set_values, problem.args if exact_args is None else exact_args)
    v0 = np.asarray(v, dtype=float) / np.linalg.norm(v)
    opts = scaled_options(problem, None, np.asarray(u), float(p))

    def residual(x, theta):
        f, J, fp = linear(x[:-2], x[-2], theta)
        w, sigma = _bordered(J, v0)
        return jnp.concatenate([f + x[-1] * v0, jnp.stack([sigma, jnp.dot(w, fp)])])

    def jacobian(x, theta):
        u, p = x[:-2], x[-2]
        _, J, fp = linear(u, p, theta)
        w, _ = _bordered(J, v0)
        y = _bordered_solve(J, v0, fp)
        sigma_x = -_contracted_gradient(F, u, p, theta, w, w, 0.0)
        tau_x = _contracted_gradient(F, u, p, theta, w, -y, 1.0)
        top = jnp.hstack([J, fp[:, None], v0[:, None]])
        rows = jnp.stack([sigma_x, tau_x])
        return jnp.vstack([top, jnp.hstack([rows, jnp.zeros((2, 1))])])

    def newton(args, x):
        u1, p1, beta, _, res, _ = unfolded_newton(problem, opts, x[:-2], x[-2], v0, args=args)
        return np.concatenate([u1, [p1, beta]]), u1, p1, res

    solve = _host_solve("branch point", problem, set_values, np.concatenate([u, [p, 0.0]]), theta0, newton,
                        opts.newton_tol)
    n = int(np.size(u))
    return RootSystem("branch_point", np.concatenate([u, [p, 0.0]]), np.asarray(theta0, dtype=float), residual,
                      jacobian, solve, n, n)
