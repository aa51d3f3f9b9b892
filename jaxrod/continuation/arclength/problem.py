"""The problem: a smooth gradient system F(u, p) = grad_u E(u, p, args) = 0.

Shapes: u (n,), p a scalar, F and F_p = dF/dp (n,), J = dF/du (n, n) for the dense backend.
J is symmetric (a Hessian), which the event tests and the branch switching use.
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ...aot import cached_jit
from ...linalg.bordered import DenseBackend


class BifurcationProblem:
    """F(u, p, args) = 0 as pure JAX functions, with its start (u0, p0) and linear-algebra backend.

    Give ``energy(u, p, args) -> scalar`` (F = grad_u E) or ``residual(u, p, args) -> (n,)`` (the
    gradient itself; its Jacobian must be symmetric). ``args`` is any pytree of further parameters
    (a second continuation parameter lives there, see ``fold_curve``). ``n_zero_modes`` eigenvalues
    of smallest |lambda| (gauge modes) are excluded from the Morse index and the tracked spectrum;
    the dense corrector and locators still need J regular away from events, i.e. a pinned gauge.

    Optional hooks: ``update_args(u, p, args) -> args``, called after every accepted point, must
    return args that give the same F near (u, p) (e.g. a rebuilt neighbourhood);
    ``soft_modes(u, p, values (m,), vectors (n, m)) -> (values, vectors, soft (m,) bool)`` splits
    soft directions (e.g. material sliding) off the span of the lowest eigenvectors, left out of
    the Morse index and the event tests (``Point.soft``); ``jacobian(u, p, args) -> J (n, n)``,
    traceable, equal to dF/du, replaces the backend's autodiff J where a structured one is cheaper;
    ``programs``, an object with host-level ``linearise(u, p, args) -> (F, J, F_p)`` and
    ``bilinear_gradient(u, p, args, a, c, t)`` (the gradient in (u, p) of a^T (J c + t F_p)),
    replaces the problem's own jitted forms of both (the traced forms still use energy/jacobian);
    ``symmetrize(u, tol) -> u or None``: the projection of u onto the problem's symmetric states,
    or None where u is further than tol (scaled units) from them (used by ``event_curve``).
    """

    def __init__(self, energy=None, u0=None, p0=0.0, args=None, *, residual=None, n_zero_modes=0, backend=None,
                 update_args=None, soft_modes=None, jacobian=None, programs=None, symmetrize=None):
        if (energy is None) == (residual is None):
            raise ValueError("give exactly one of energy= or residual=")
        self.energy = energy
        self.u0 = jnp.asarray(u0, dtype=jnp.float64).ravel()
        self.p0 = float(p0)
        self.args = args
        self.n_zero_modes = int(n_zero_modes)
        self.backend = backend if backend is not None else DenseBackend()
        self.n = int(self.u0.size)
        self.update_args = update_args
        self.soft_modes = soft_modes
        self.symmetrize = symmetrize
        self.jacobian = jacobian
        # jitted once per (energy, residual, jacobian, backend), shared by every problem built from them
        fns = problem_functions(energy, residual, jacobian, self.backend)
        self.F, self.hvp = fns.F, fns.hvp
        self.traced_linearise, self.traced_singular_tests = fns.traced_linearise, fns.traced_singular_tests
        self.energy_value, self.linearise, self.bilinear_gradient = fns.energy_value, fns.linearise, fns.bilinear_gradient
        self.hvp_derivative, self.directional_derivatives = fns.hvp_derivative, fns.directional_derivatives
        self.scene_programs = programs
        if programs is not None:
            self.linearise = programs.linearise
        elif getattr(self.backend, "host", False):
            # J leaves the jitted linearisation as parts, assembled on the host by the backend
            self.linearise = fns.host_linearise

    def wjw_gradient(self, u, p, args, w):
        """Gradient of w^T J(u, p) w in (u, p): (E'''[w, w, .] (n,), w^T J_p w); exact, by JAX."""
        return self.contracted(u, p, args, w, w, 0.0)

    def contracted(self, u, p, args, a, c, t):
        """``bilinear_gradient`` with a and c as host arrays and t as a float64 scalar (one jit
        signature, not one per kind of input array)."""
        if self.scene_programs is not None:
            return self.scene_programs.bilinear_gradient(u, p, args, a, c, t)
        return self.bilinear_gradient(u, p, args, np.asarray(a, dtype=float), np.asarray(c, dtype=float),
                                      jnp.asarray(t, dtype=jnp.float64))

    def singular_tests(self, u, p, args, b):
        """The branch-point test functions' Jacobian in (u, p), ((2, n), (2,)), with aux (value (2,),
        F, J, F_p, w). With M = [[J, b], [b^T, 0]] symmetric, M [w; sigma] = [0; 1] and M [y; eta] = [F_p; 0]:
        d sigma = -w^T dJ w and d tau = w^T d(J (-y) + F_p), both gradients of w^T (J c + t F_p)
        (O(n) each, where reverse mode through the assembled J costs n passes)."""
        F, J, Fp = self.linearise(u, p, args)
        n = np.shape(b)[0]
        w, sigma = self.backend.bordered_solve(J, b, b, 0.0, np.zeros(n), 1.0)
        y, _ = self.backend.bordered_solve(J, b, b, 0.0, np.asarray(Fp), 0.0)
        w, y = np.asarray(w), np.asarray(y)
        g0u, g0p = self.contracted(u, p, args, w, w, 0.0)
        g1u, g1p = self.contracted(u, p, args, w, -y, 1.0)
        gu = np.stack([-np.asarray(g0u), np.asarray(g1u)])
        gp = np.array([-float(g0p), float(g1p)])
        st = np.array([float(sigma), float(np.dot(w, np.asarray(Fp)))])
        return (gu, gp), (st, F, J, Fp, w)

    def relax(self, u, p, args, *, gtol, max_step=float("inf")):
        """A minimum of E(., p) from u with ``args``: damped Newton (the structured ``jacobian`` if
        given, steps capped at max_step), the args refreshed by ``update_args`` at the minimum and
        the relaxation repeated while they change (at most 8 times). -> (Solution, args)."""
        from ...solve.solvers import DampedNewton, HostDampedNewton, minimise

        if getattr(self.backend, "host", False):
            solver = HostDampedNewton(direction=self._host_direction, max_step=max_step)
        else:
            hessian = in_minimise_form(self.jacobian) if self.jacobian is not None else None
            solver = DampedNewton(hessian=hessian, max_step=max_step)
        p = jnp.asarray(p, dtype=jnp.float64)
        y = u
        for _ in range(8):
            sol = minimise(in_minimise_form(self.energy), y, (p, args), solver, gtol=gtol, throw=False)
            fresh = self.update_args(sol.y, float(p), args) if self.update_args is not None else args
            if fresh is args:
                break
            args, y = fresh, sol.y
        return sol, args

    def _host_direction(self, y, p_args, g, mu_prev):
        """``HostDampedNewton``'s step on the host backend: J assembled from its parts, then
        ``backend.damped_step``."""
        p, args = p_args
        _, J, _ = self.linearise(y, p, args)
        return self.backend.damped_step(J, np.asarray(g), mu_prev)


@functools.lru_cache(maxsize=64)
def in_minimise_form(fn):
    """``fn(u, p, args)`` as ``jaxrod.solve.solvers.minimise`` takes it, ``fun(u, (p, args))`` (the
    energy, or its structured ``jacobian`` as the ``hessian`` hook). One wrapper per function: every
    problem built from the same energy reaches one compiled solver loop, where a bound method of
    each problem would be a new static argument, traced and compiled again."""
    def at(u, p_args):
        return fn(u, p_args[0], p_args[1])

    return at


@functools.lru_cache(maxsize=64)
def problem_functions(energy, residual, jacobian, backend):
    return _Functions(energy, residual, jacobian, backend)


def _in_u_p(program, statics):
    """program(u, p, *rest, **statics) with u and p as float64 arrays (u (n,), p ()): one program,
    whether p comes as a Python float or an array."""
    def call(u, p, *rest):
        return program(jnp.asarray(u, dtype=jnp.float64), jnp.asarray(p, dtype=jnp.float64), *rest, **statics)

    return call


_STATICS = ("energy", "residual", "jacobian", "backend")


@cached_jit(static_argnames=_STATICS)
def linearise_program(u, p, args, energy, residual, jacobian, backend):
    return problem_functions(energy, residual, jacobian, backend).traced_linearise(u, p, args)


@cached_jit(static_argnames=_STATICS)
def _bilinear_gradient_program(u, p, args, a, c, t, energy, residual, jacobian, backend):
    return problem_functions(energy, residual, jacobian, backend)._bilinear_gradient(u, p, args, a, c, t)


@cached_jit(static_argnames=_STATICS)
def _hvp_derivative_program(u, p, args, w, du, dp, energy, residual, jacobian, backend):
    return problem_functions(energy, residual, jacobian, backend)._hvp_derivative(u, p, args, w, du, dp)


@cached_jit(static_argnames=_STATICS)
def _directional_derivatives_program(u, p, args, h, energy, residual, jacobian, backend):
    return problem_functions(energy, residual, jacobian, backend)._directional_derivatives(u, p, args, h)


class _Functions:
    """F = grad_u E (or the residual), J and the extended systems' derivatives as functions of
    (u, p, args), with their jitted forms (args traced)."""

    def __init__(self, energy, residual, jacobian, backend):
        self.F = residual if residual is not None else jax.grad(energy, argnums=0)
        self.jacobian = jacobian
        self.backend = backend
        self.energy_value = _in_u_p(jax.jit(energy), {}) if energy is not None else None
        # module-level programs keyed on the problem's functions, so ``jaxrod.aot`` keeps them across processes
        statics = {"energy": energy, "residual": residual, "jacobian": jacobian, "backend": backend}
        self.linearise = _in_u_p(linearise_program, statics)
        self.bilinear_gradient = _in_u_p(_bilinear_gradient_program, statics)
        self.hvp_derivative = _in_u_p(_hvp_derivative_program, statics)
        self.directional_derivatives = _in_u_p(_directional_derivatives_program, statics)

    def host_linearise(self, u, p, args):
        """(F, J, F_p) with J assembled on the host by the backend (``SparseBackend``)."""
        F, parts, Fp = self.linearise(u, p, args)
        return F, self.backend.matrix(jax.device_get(parts), args), Fp

    def _bilinear_gradient(self, u, p, args, a, c, t):
        """Gradient in (u, p) of a^T (J(u, p) c + t F_p(u, p)), ((n,), ()): a jvp of F in the
        direction (c, t), contracted with a and differentiated in reverse mode; exact, by JAX."""
        def contracted(x, q):
            return jnp.dot(a, jax.jvp(lambda y, r: self.F(y, r, args), (x, q), (c, t))[1])

        return jax.grad(contracted, argnums=(0, 1))(u, p)

    def hvp(self, u, p, args, w):
        """J(u, p) w (n,), by a jvp of F: never forms J."""
        return jax.jvp(lambda x: self.F(x, p, args), (u,), (w,))[1]

    def _hvp_derivative(self, u, p, args, w, du, dp):
        """d/ds [J(u + s du, p + s dp) w] at s = 0 (n,): a jvp of the Hessian-vector product."""
        return jax.jvp(lambda x, q: self.hvp(x, q, args, w), (u, p), (du, dp))[1]

    def _directional_derivatives(self, u, p, args, h):
        """(E'''[h, h, .] (n,), E''''[h, h, h, .] (n,)) at (u, p): nested jvps of F."""
        d1 = lambda x: jax.jvp(lambda y: self.F(y, p, args), (x,), (h,))[1]  # noqa: E731
        d2 = lambda x: jax.jvp(d1, (x,), (h,))[1]  # noqa: E731
        f2, f3 = jax.jvp(d2, (u,), (h,))
        return f2, f3

    def traced_linearise(self, u, p, args):
        """(F (n,), J (n, n), F_p (n,)) at (u, p)."""
        F, Fp = jax.jvp(lambda q: self.F(u, q, args), (p,), (jnp.ones_like(p),))
        if self.jacobian is not None:
            return F, self.jacobian(u, p, args), Fp
        return F, self.backend.jacobian(lambda x: self.F(x, p, args), u), Fp

    def traced_singular_tests(self, u, p, args, b):
        """(sigma, tau) (2,): sigma vanishes iff J is singular, tau = w^T F_p also at a branch
        point. The traceable form of ``singular_tests``, differentiable in reverse mode."""
        # J by autodiff even with a structured ``jacobian``, which may not support reverse mode
        F, Fp = jax.jvp(lambda q: self.F(u, q, args), (p,), (jnp.ones_like(p),))
        J = self.backend.jacobian(lambda x: self.F(x, p, args), u)
        w, sigma = self.backend.bordered_solve(J, b, b, 0.0, jnp.zeros_like(u), 1.0)
        st = jnp.stack([sigma, jnp.dot(w, Fp)])
        return st, (st, F, J, Fp, w)
