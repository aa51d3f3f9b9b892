"""An equilibrium, a fold or a simple branch point of a problem, as a root that moves with the
problem's parameters theta (k,) and that JAX differentiates (``jaxrod.solve.implicit``).

Each is the root of a system that is regular there (locate.py):

- an equilibrium at fixed p: F(u, p, args(theta)) = 0 in x = u;
- a fold: (F, sigma) = 0 in x = (u, p), sigma from [[J, b], [b^T, 0]] [w; sigma] = [0; 1];
- a simple branch point: (F + beta v0, sigma, tau = w^T F_p) = 0 in x = (u, p, beta) (Moore's
  unfolding; beta = 0 at the root while the symmetry that makes the branch point persists).

A ``RootSystem`` holds the traceable residual G(x, theta) with its Jacobian in x, the root x0 at
the base values theta0, and ``solve(theta)``: Newton's method on the same system on the host, from
the nearest root found so far, with the problem's own compiled programs (its linearisation and
contracted third derivatives, as the locators use them) and its args at theta (a knot's
neighbourhood refreshed by ``update_args`` until it holds at the root), to the tolerances the
locators use (an equilibrium to ``newton_tol``; a fold or branch point to ``event_tol``, its
residual's floor being higher: sigma and tau come from bordered solves). The steps backtrack
(halved until the residual falls): a knot's nearly free slide along its centreline makes these
systems ill-conditioned (condition numbers 1e5-1e8 at N = 41), and full Newton steps from a root
at nearby values were seen to diverge. The traced residual is evaluated with ``exact_args`` (for a knot, the args
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


def _bordered_matrix(J, b):
    """[[J, b], [b^T, 0]] (n + 1, n + 1)."""
    return jnp.block([[J, b[:, None]], [b[None, :], jnp.zeros((1, 1))]])


def _bordered(J, b, f=None):
    """(y (n,), eta) with [[J, b], [b^T, 0]] [y; eta] = [f; g] (dense, traceable): by default f = 0,
    g = 1 (w and sigma); with f given, g = 0."""
    n = J.shape[0]
    rhs = jnp.zeros(n + 1).at[n].set(1.0) if f is None else jnp.append(f, 0.0)
    z = jnp.linalg.solve(_bordered_matrix(J, b), rhs)
    return z[:n], z[n]


def _bordered_pair(J, b, f):
    """(w, y) of ``_bordered(J, b)`` and ``_bordered(J, b, f)`` from one factorisation of the
    bordered matrix (both right-hand sides at once)."""
    n = J.shape[0]
    rhs = jnp.stack([jnp.zeros(n + 1).at[n].set(1.0), jnp.append(f, 0.0)], axis=1)
    z = jnp.linalg.solve(_bordered_matrix(J, b), rhs)
    return z[:n, 0], z[:n, 1]


def _contracted_gradient(F, u, p, theta, a, c, t):
    """The gradient in (u, p) ((n + 1,)) of a^T (J(u, p) c + t F_p(u, p)), a, c and t held fixed.

    With w and y from the bordered systems (the w and y of ``_bordered``),
    d sigma = -w^T dJ w and d tau = w^T d(F_p - J y) hold at every (u, p), not only at the root
    (differentiate M [w; sigma] = [0; 1] and multiply by [w; sigma]^T, M symmetric): so these
    gradients, with w and y computed from (u, p) by the caller, are sigma's and tau's gradients as
    functions, and differentiating them again gives the higher derivatives. They cost one reverse
    pass each, against one per DOF through the assembled J."""
    def contracted(y):
        return jnp.dot(a, jax.jvp(lambda v, q: F(v, q, theta), (y[:-1], y[-1]), (c, jnp.asarray(t, y.dtype)))[1])

    return jax.grad(contracted)(jnp.append(u, p))


def _linear_parts(problem, set_values, exact_args):
    """F(u, p, theta) and (F, J, F_p)(u, p, theta), traceable, with args = set_values(exact_args, theta)."""
    def F(u, p, theta):
        return problem.F(u, p, set_values(exact_args, theta))

    def linear(u, p, theta):
        f, fp = jax.jvp(lambda q: F(u, q, theta), (p,), (jnp.ones_like(p),))
        return f, jax.jacfwd(lambda y: F(y, p, theta))(u), fp

    return F, linear


def _backtracking_newton(step_at, x, tol, max_iterations=40):
    """Newton's method with backtracking from x: ``step_at(x) -> (residual norm, Newton step)``.
    A step is halved until the residual falls (10 times at most); below tol, steps go on while each
    cuts the residual more than tenfold (to the roundoff floor, so the root does not depend on the
    start). -> (x, residual)."""
    res, dx = step_at(x)
    alpha = 1.0
    for _ in range(max_iterations):
        if not np.isfinite(res):
            break
        trial = x + alpha * dx
        r, d = step_at(trial)
        if np.isfinite(r) and r < res:
            at_floor = res <= tol and r > 0.1 * res
            x, res, dx, alpha = trial, r, d, 1.0
            if at_floor:
                break
        elif res <= tol or alpha < 2.0 ** -10:
            break
        else:
            alpha *= 0.5
    return x, res


def _on_the_curve(x, x_predicted, x_near):
    """Whether Newton's root x is the continuation of x_near: its correction to the prediction is
    at most half the predicted move (it is second order in the step); else Newton has jumped to
    another root, or the curve turned back (a cusp), and the way is halved."""
    moved = float(np.linalg.norm(x_predicted - x_near))
    # the floor admits the polish of a start that was converged less tightly (a relaxed equilibrium)
    return float(np.linalg.norm(x - x_predicted)) <= 0.5 * moved + 1e-6 * (1.0 + float(np.linalg.norm(x)))


def _host_solve(kind, problem, set_values, x0, theta0, step, tol, u_and_p):
    """solve(theta) -> x: ``_backtracking_newton`` with ``step(args) -> step_at`` at the problem's
    args with the values theta (concrete: ``scene.with_params`` checks them), from the implicit
    function theorem's prediction from the nearest root found so far (the tangent: along a nearly
    free slide the root moves far for a small change of theta, its curve bends sharply, and Newton
    from x_near, or from the chord x_near - A^-1 G(x_near, theta), was seen to diverge);
    where Newton fails, the way from that root is halved (4 times at most), and so is a root that
    is not the continuation of the last one (``_on_the_curve``). A knot's neighbourhood is
    refreshed at each root until it holds (``u_and_p(x) -> (u, p)``). RuntimeError where no root is
    found."""
    found = [(np.asarray(theta0, dtype=float), np.asarray(x0, dtype=float), problem.args)]

    def predicted(theta, near):
        """x_near + dx/dtheta (theta - theta_near): the tangent, its G_theta (theta - theta_near) by
        a second-order difference of G at x_near, forward along the way (steps 1e-3 and 2e-3 of
        it, so that a value at its bound, nu = 0.5, is not stepped over): the second-order term,
        which the near-singular A would amplify, cancels."""
        theta_near, x_near, args_near = near
        eps = 1e-3
        at_values = [set_values(args_near, [float(v) for v in theta_near + k * eps * (theta - theta_near)])
                     for k in (1, 2)]
        one, two = (step(args_near, a)(x_near)[1] for a in at_values)
        zero = step(args_near)(x_near)[1]
        return x_near + (4.0 * one - two - 3.0 * zero) / (2.0 * eps)

    def at(theta, x_start):
        args = set_values(problem.args, [float(v) for v in theta])
        for _ in range(3):
            x, res = _backtracking_newton(step(args), x_start, tol)
            if not (np.all(np.isfinite(x)) and np.isfinite(res)) or problem.update_args is None:
                break
            fresh = problem.update_args(*u_and_p(x), args)
            if fresh is args:
                break
            args, x_start = fresh, x
        return x, res, args

    def solve(theta):
        theta = np.asarray(theta, dtype=np.float64)
        near = min(found, key=lambda item: float(np.linalg.norm(item[0] - theta)))
        way, res = [theta], math.inf
        while way:
            x_start = predicted(way[-1], near)
            x, res, args = at(way[-1], x_start)
            if np.isfinite(res) and res <= tol and _on_the_curve(x, x_start, near[1]):
                near = (way.pop(), x, args)
                found.append(near)
            elif len(way) < 5:
                way.append(0.5 * (near[0] + way[-1]))
            else:
                raise RuntimeError(f"the {kind} was not found at parameter values {theta.tolist()}: Newton's "
                                   f"residual {res:.3e} > {tol:.1e} (the values are too far from the base values for "
                                   "this root to be followed, or it ceased to exist)")
        del found[1:-32]  # the base root and the last 32
        return near[1]

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

    def step(args, args_residual=None):  # A from args, G from args_residual (default args)
        def step_at(x):
            f, J, _ = problem.linearise(x, p, args)
            if args_residual is not None:
                f = problem.linearise(x, p, args_residual)[0]
            return float(np.linalg.norm(np.asarray(f))), -np.linalg.solve(np.asarray(J), np.asarray(f))

        return step_at

    solve = _host_solve("equilibrium", problem, set_values, u0, theta0, step, opts.newton_tol, lambda x: (x, p))
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

    be, zeros = problem.backend, np.zeros(np.size(u))

    def step(args, args_residual=None):  # A from args, G from args_residual (default args)
        def step_at(x):  # as locate's fold Newton, with the border held
            f, J, fp = problem.linearise(x[:-1], x[-1], args)
            w, sigma = be.bordered_solve(J, b, b, 0.0, zeros, 1.0)
            gu, gp = problem.wjw_gradient(x[:-1], x[-1], args, w)
            if args_residual is not None:
                f, J_residual, _ = problem.linearise(x[:-1], x[-1], args_residual)
                sigma = be.bordered_solve(J_residual, b, b, 0.0, zeros, 1.0)[1]
            du, dp = be.bordered_solve(J, fp, -np.asarray(gu), -float(gp), -np.asarray(f), -float(sigma))
            return float(np.linalg.norm(np.append(np.asarray(f), sigma))), np.append(du, dp)

        return step_at

    n = int(np.size(u))
    solve = _host_solve("fold", problem, set_values, np.append(u, p), theta0, step, opts.event_tol,
                        lambda x: (x[:n], float(x[n])))
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
        w, y = _bordered_pair(J, v0, fp)
        # sigma's and tau's gradients in one vmapped pass: the program (and its derivatives, for
        # second derivatives of phi*) holds the third-derivative contraction once, not twice
        cw = jax.vmap(lambda c, t: _contracted_gradient(F, u, p, theta, w, c, t))(jnp.stack([w, -y]),
                                                                                 jnp.array([0.0, 1.0]))
        top = jnp.hstack([J, fp[:, None], v0[:, None]])
        rows = cw * jnp.array([-1.0, 1.0])[:, None]
        return jnp.vstack([top, jnp.hstack([rows, jnp.zeros((2, 1))])])

    be = problem.backend

    def step(args, args_residual=None):  # A from args, G from args_residual (default args)
        def step_at(x):  # as locate's unfolded Newton, with the border held at v0
            (gu, gp), (st, f, J, fp, _) = problem.singular_tests(x[:-2], x[-2], args, v0)
            if args_residual is not None:
                _, (st, f, _, _, _) = problem.singular_tests(x[:-2], x[-2], args_residual, v0)
            G, gp = np.asarray(f) + x[-1] * v0, np.asarray(gp)
            D = np.array([[gp[0], 0.0], [gp[1], 0.0]])
            du, dy = be.bordered_solve(J, np.stack([fp, v0], axis=1), np.asarray(gu).T, D, -G, -np.asarray(st))
            return float(np.linalg.norm(np.append(G, st))), np.concatenate([du, dy])

        return step_at

    n = int(np.size(u))
    solve = _host_solve("branch point", problem, set_values, np.concatenate([u, [p, 0.0]]), theta0, step,
                        opts.event_tol, lambda x: (x[:n], float(x[n])))
    return RootSystem("branch_point", np.concatenate([u, [p, 0.0]]), np.asarray(theta0, dtype=float), residual,
                      jacobian, solve, n, n)
