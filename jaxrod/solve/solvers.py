"""Minimisers that take a function and return a result object (generic: no rod physics here).

``minimise(fun, y0, args, solver=...)`` minimises ``fun(y, args)`` (scalar) over y (n,):

* ``LBFGS``: optax's L-BFGS with a zoom line search in one jitted ``lax.while_loop``; robust far
  from equilibrium, slow near a bifurcation (critical slowing down).
* ``Newton``: Newton on grad f = 0 with the exact Hessian in one jitted ``lax.while_loop``; zero
  modes get a positive multiple of their projector, and a backtracking line search on |grad f|
  converges to the nearest stationary point, stable or not (a continuation corrector).
* ``DampedNewton`` / ``HostDampedNewton``: shifted Newton descent (below).

Every run returns a ``Solution`` (converged?, iterations, max-abs gradient norm, why it stopped);
with ``throw=True`` (default) an unconverged run raises ``ConvergenceError``.
"""
from __future__ import annotations

import enum
import functools
from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import optax
import optax.tree_utils as otu

from ..aot import cached_jit
from ..linalg.zero_modes import orthonormal_columns

__all__ = ["LBFGS", "Newton", "DampedNewton", "HostDampedNewton", "Solution", "StopReason", "ConvergenceError", "minimise"]


class StopReason(str, enum.Enum):
    """Why a solver stopped (integer codes inside the jitted loops). A str enum: it compares
    equal to its value, so ``sol.reason == "converged"`` also works."""

    CONVERGED = "converged"  # max |grad| <= gtol
    MAX_STEPS = "max_steps"  # iteration budget spent
    NONFINITE = "nonfinite"  # a NaN or inf appeared
    STALLED = "stalled"  # the line search found no acceptable step
    LEFT_REGION = "left_region"  # the caller's ``leave`` test fired (e.g. a stale contact list)

    def __str__(self):
        return self.value

    def __format__(self, spec):
        return format(self.value, spec)


_REASONS = {0: StopReason.CONVERGED, 1: StopReason.MAX_STEPS, 2: StopReason.NONFINITE, 3: StopReason.STALLED,
            4: StopReason.LEFT_REGION}


class ConvergenceError(RuntimeError):
    """A solver stopped without meeting its tolerance. ``solution`` / ``q``: where it stopped
    (its ``Solution`` and the physical DOFs), when the raiser knows them (else None)."""

    def __init__(self, message, solution=None, q=None):
        super().__init__(message)
        self.solution = solution
        self.q = q


@dataclass(frozen=True)
class LBFGS:
    """optax L-BFGS. ``memory``: number of stored updates; ``max_linesearch_steps``: zoom steps."""

    memory: int = 20
    max_linesearch_steps: int = 40


@dataclass(frozen=True)
class Newton:
    """Exact-Hessian Newton. ``zero_modes(y, args) -> (n, k)`` spans symmetry directions that the
    Hessian leaves singular (None if there are none); ``max_backtracks`` halvings per step.
    ``near_null_tol`` > 0 treats eigen-directions with |lambda| below it like the symmetry modes
    (e.g. a loose knot's sliding strands), which Newton would divide by; the gradient along them
    is left as it is (and still counts in the convergence test)."""

    zero_modes: object = None
    max_backtracks: int = 40
    near_null_tol: float = 0.0
    hessian: object = None
    direction: object = None  # (y, args, g) -> Newton step dy, replacing the dense solve (static)


@dataclass(frozen=True)
class DampedNewton:
    """A minimiser with the exact Hessian: each step solves (H + mu I) dy = -g with mu just large
    enough to make H + mu I positive definite (so every step descends, also across saddles and
    near bifurcations), caps max |dy| at ``max_step``, and backtracks until the energy decreases
    (Armijo). ``zero_modes`` as in ``Newton``. ``leave(y, args) -> bool`` (optional) stops the run
    with reason 'left_region' (e.g. a contact list to rebuild); the caller refreshes and calls again.
    ``hessian(y, args) -> (n, n)`` (optional, both Newton solvers, static like ``fun``): an exact
    Hessian cheaper than ``jax.hessian`` of ``fun`` (e.g. ``jaxrod.model.hessian.scaled_hessian``).

    The shift is found by Cholesky attempts on H + mu I, without an eigen-decomposition (schedule:
    ``_SHIFT_DOWN``, ``_SHIFT_UP``, ``_SHIFT_REFINE``)."""

    zero_modes: object = None
    max_step: float = float("inf")
    leave: object = None
    max_backtracks: int = 40
    hessian: object = None


@dataclass(frozen=True)
class HostDampedNewton:
    """``DampedNewton`` with its linear algebra on the host (e.g. SciPy's sparse factorisations,
    ``jaxrod.linalg.sparse_contact``): ``direction(y, args, g, mu_prev) -> (dy, mu_used)`` gives the
    shifted Newton step (mu_prev: the shift the last iteration used, 0 for none) and is called
    from a Python loop; energy, gradient and ``leave`` are jitted. Same step cap, Armijo
    backtracking, stop codes and shift schedule as ``DampedNewton``. For large sparse systems;
    not inside ``jit`` (and not ``jax.pure_callback``, which can deadlock: ``stability._lowest_of``)."""

    direction: object
    max_step: float = float("inf")
    leave: object = None
    max_backtracks: int = 40


@dataclass(frozen=True)
class Solution:
    """Outcome of a minimisation.

    y: (n,) final point; value: f(y); grad_norm: max |grad f(y)|; iterations; converged; reason:
    'converged' | 'max_steps' | 'nonfinite' | 'stalled' | 'left_region'; solver: its name; gtol
    used."""

    y: np.ndarray
    value: float
    grad_norm: float
    iterations: int
    converged: bool
    reason: str
    solver: str
    gtol: float

    def __repr__(self):
        return (
            f"Solution(solver={self.solver}, converged={self.converged}, reason={str(self.reason)!r}, "
            f"iterations={self.iterations}, grad_norm={self.grad_norm:.3e}, value={self.value:.12g})"
        )


@partial(jax.jit, static_argnames=("fun", "memory", "max_ls"))
def _lbfgs_loop(fun, y0, args, gtol, memory, max_ls, max_steps):
    f = lambda y: fun(y, args)
    opt = optax.lbfgs(memory_size=memory, linesearch=optax.scale_by_zoom_linesearch(max_linesearch_steps=max_ls))
    value_and_grad = optax.value_and_grad_from_state(f)

    def state_grad_norm(state):
        return jnp.max(jnp.abs(otu.tree_get(state, "grad")))

    def cond(carry):
        y, state, it, moved = carry
        g = state_grad_norm(state)
        value = otu.tree_get(state, "value")
        first = it == 0
        ok = jnp.isfinite(value) & jnp.all(jnp.isfinite(y))
        return first | ((it < max_steps) & (g > gtol) & ok & moved)

    def body(carry):
        y, state, it, _ = carry
        value, grad = value_and_grad(y, state=state)
        updates, state = opt.update(grad, state, y, value=value, grad=grad, value_fn=f)
        y_new = optax.apply_updates(y, updates)
        moved = jnp.any(y_new != y)
        return y_new, state, it + 1, moved

    state = opt.init(y0)
    y, state, it, moved = jax.lax.while_loop(cond, body, (y0, state, 0, True))
    value, grad = jax.value_and_grad(f)(y)
    gnorm = jnp.max(jnp.abs(grad))
    finite = jnp.isfinite(value) & jnp.isfinite(gnorm)
    code = jnp.where(~finite, 2, jnp.where(gnorm <= gtol, 0, jnp.where(moved, 1, 3)))
    return y, value, gnorm, it, code


def _hessian_of(f, hessian, args):
    if hessian is None:
        return jax.hessian(f)
    return lambda y: hessian(y, args)


@partial(jax.jit, static_argnames=("fun", "zero_modes", "max_backtracks", "near_null", "hessian",
                                   "direction"))
def _newton_loop(fun, zero_modes, y0, args, gtol, max_steps, max_backtracks, near_null=False, near_null_tol=0.0,
                 hessian=None, direction=None):
    f = lambda y: fun(y, args)
    grad = jax.grad(f)
    hess = _hessian_of(f, hessian, args)

    def newton_step(y, g):
        if direction is not None:  # a structured solve supplied by the caller (e.g. O(N) banded)
            return direction(y, args, g)
        h = hess(y)
        if zero_modes is not None:
            z = orthonormal_columns(zero_modes(y, args))
            # A positive multiple of the projector on the symmetry directions: the system becomes
            # regular and the step has no component along them (g is orthogonal to them).
            shift = jnp.max(jnp.abs(jnp.diag(h))) + 1.0
            h = h + shift * (z @ z.T)
        if near_null:
            lam, vec = jnp.linalg.eigh(0.5 * (h + h.T))
            weak = jnp.abs(lam) < near_null_tol
            shift = jnp.max(jnp.abs(lam)) + 1.0
            lam = jnp.where(weak, shift, lam)
            return -vec @ ((vec.T @ g) / lam)
        return -jnp.linalg.solve(h, g)

    def cond(carry):
        y, it, gnorm, code, _ = carry
        return (it < max_steps) & (gnorm > gtol) & (code == 0)

    def body(carry):
        # g: the gradient at y, carried over; written once in the loop (each copy compiles separately).
        y, it, _, _, g = carry
        dy = newton_step(y, g)
        g2 = jnp.sum(g * g)

        # Backtrack on the merit |grad f|^2: the full step, then halved (max_backtracks times).
        def ls_cond(c):
            alpha, k, g2_new, _, first = c
            return first | ((k < max_backtracks) & ~(g2_new < (1.0 - 1e-4 * alpha) * g2))

        def ls_body(c):
            alpha, k, _, _, first = c
            alpha = jnp.where(first, alpha, 0.5 * alpha)
            gn = grad(y + alpha * dy)
            return alpha, jnp.where(first, k, k + 1), jnp.where(jnp.all(jnp.isfinite(gn)), jnp.sum(gn * gn), jnp.inf), \
                gn, False

        alpha, k, g2_new, g_trial, _ = jax.lax.while_loop(ls_cond, ls_body, (1.0, 0, jnp.inf, g, True))
        accepted = g2_new < (1.0 - 1e-4 * alpha) * g2
        y_new = jnp.where(accepted, y + alpha * dy, y)
        g_new = jnp.where(accepted, g_trial, g)
        gnorm_new = jnp.max(jnp.abs(g_new))
        code = jnp.where(~jnp.all(jnp.isfinite(dy)), 2, jnp.where(accepted, 0, 3))
        return y_new, it + 1, gnorm_new, code, g_new

    g0 = grad(y0)
    gnorm0 = jnp.max(jnp.abs(g0))
    code0 = jnp.where(jnp.isfinite(gnorm0), 0, 2)
    y, it, gnorm, code, _ = jax.lax.while_loop(cond, body, (y0, 0, gnorm0, code0, g0))
    value = f(y)
    code = jnp.where(
        ~(jnp.isfinite(value) & jnp.isfinite(gnorm)),
        2,
        jnp.where(gnorm <= gtol, 0, jnp.where(code == 0, 1, code)),
    )
    return y, value, gnorm, it, code


# Damped-Newton shift control (see ``_damped_newton_loop``): an iteration after one that needed
# a shift mu first tries _SHIFT_DOWN * mu; on failure the shift grows by _SHIFT_UP per attempt,
# and the bracket found is narrowed geometrically _SHIFT_REFINE times (so the shift exceeds the
# needed one by at most _SHIFT_UP ** (1 / 2 ** _SHIFT_REFINE) ~ 1.4).
_SHIFT_DOWN, _SHIFT_UP, _SHIFT_REFINE = 0.1, 4.0, 2


def _shifted_newton_direction(hess, zero_modes, args, max_step):
    """The damped-Newton step of ``_damped_newton_loop``: direction(y, g, mu_prev) -> (dy, mu_used),
    (H + mu I) dy = -g with mu just large enough for H + mu I to be positive definite, max |dy|
    capped at max_step. Traceable (built inside the jitted loop)."""

    def direction(y, g, mu_prev):
        h = hess(y)
        h = 0.5 * (h + h.T)
        if zero_modes is not None:
            z = orthonormal_columns(zero_modes(y, args))
            h = h + (jnp.max(jnp.abs(jnp.diag(h))) + 1.0) * (z @ z.T)
        scale = jnp.max(jnp.abs(jnp.diag(h))) + 1.0
        eye = jnp.eye(h.shape[0])
        # Shift mu just large enough to make H + mu I positive definite, by Cholesky attempts only
        # (a failure gives NaNs): mu0 = 1e-10 scale after an unshifted iteration, else _SHIFT_DOWN *
        # mu_prev but at least mu1 = 1e-6 (sliding modes sit at ~ -1e-7); if that fails, ``search``.
        mu0, mu1 = 1e-10 * scale, 1e-6 + 1e-10 * scale
        mu_a = jnp.where(mu_prev <= 0.0, mu0, jnp.maximum(mu1, _SHIFT_DOWN * mu_prev))
        chol_a = jnp.linalg.cholesky(h + mu_a * eye)
        ok_a = jnp.all(jnp.isfinite(chol_a))

        def attempt(mu):
            c = jnp.linalg.cholesky(h + mu * eye)
            return c, jnp.all(jnp.isfinite(c))

        def search():
            # Grow from the failed mu_a by _SHIFT_UP until a factorisation succeeds, then narrow
            # the bracket (lo fails, hi succeeds) geometrically _SHIFT_REFINE times.
            def failing(state):
                _, _, _, ok, j = state
                return ~ok & (j < 60)

            def grow(state):
                _, hi, c, _, j = state
                mu = jnp.where(j == 0, jnp.maximum(mu1, _SHIFT_UP * mu_a), _SHIFT_UP * hi)
                c, ok = attempt(mu)
                return hi, mu, c, ok, j + 1

            lo, hi, c, _, _ = jax.lax.while_loop(failing, grow, (mu_a, mu_a, chol_a, False, 0))

            def narrow(_, state):
                lo, hi, c = state
                mid = jnp.sqrt(lo * hi)
                cm, ok = attempt(mid)
                return jnp.where(ok, lo, mid), jnp.where(ok, mid, hi), jnp.where(ok, cm, c)

            _, hi, c = jax.lax.fori_loop(0, _SHIFT_REFINE, narrow, (lo, hi, c))
            return hi, c

        mu, chol = jax.lax.cond(ok_a, lambda: (mu_a, chol_a), search)
        mu_used = jnp.where(ok_a & (mu_prev <= 0.0), 0.0, mu)
        dy = -jax.scipy.linalg.cho_solve((chol, True), g)
        big = jnp.max(jnp.abs(dy))
        return jnp.where(big > max_step, dy * (max_step / big), dy), mu_used

    return direction


@cached_jit(static_argnames=("fun", "zero_modes", "leave", "max_backtracks", "hessian"))
def _damped_newton_loop(fun, zero_modes, leave, y0, args, gtol, max_step, max_steps, max_backtracks, hessian=None):
    f = lambda y: fun(y, args)  # noqa: E731
    hess = _hessian_of(f, hessian, args)

    direction = _shifted_newton_direction(hess, zero_modes, args, max_step)
    value_and_grad = jax.value_and_grad(f)

    # The energy and gradient are written once, in the line search's trial (each copy compiles
    # separately). The first pass makes no step and only evaluates the start, accepted if finite.
    def cond(carry):
        y, it, gnorm, code, _, _, _, started = carry
        return ~started | ((it < max_steps) & (gnorm > gtol) & (code == 0))

    def body(carry):
        # g: the gradient at y, carried from the last iteration (one gradient per accepted step).
        y, it, _, _, fy, g, mu_prev, started = carry
        dy, mu_next = jax.lax.cond(started, lambda: direction(y, g, mu_prev), lambda: (jnp.zeros_like(y), mu_prev))
        slope = jnp.dot(g, dy)
        # fy is +inf before the start is evaluated: its trial is then accepted if finite.
        fy = jnp.where(started, fy, jnp.inf)

        def ls_cond(c):
            alpha, k, f_new, _, first = c
            return first | ((k < max_backtracks) & ~(f_new <= fy + 1e-4 * alpha * slope))

        def ls_body(c):
            alpha, k, _, _, first = c
            alpha = jnp.where(first, alpha, 0.5 * alpha)
            fn, gn = value_and_grad(y + alpha * dy)
            return alpha, jnp.where(first, k, k + 1), jnp.where(jnp.isfinite(fn), fn, jnp.inf), gn, False

        alpha, _, f_new, g_trial, _ = jax.lax.while_loop(ls_cond, ls_body, (1.0, 0, jnp.inf, g, True))
        accepted = f_new <= fy + 1e-4 * alpha * slope
        y_new = jnp.where(accepted, y + alpha * dy, y)
        f_y = jnp.where(accepted, f_new, fy)
        g_new = jnp.where(accepted, g_trial, g)
        gnorm = jnp.max(jnp.abs(g_new))
        left = leave(y_new, args) if leave is not None else False
        code = jnp.where(accepted, jnp.where(left & (gnorm > gtol), 4, 0), 3)
        # the start: a non-finite energy or gradient there is code 2 (no step was tried)
        code = jnp.where(started, code, jnp.where(jnp.isfinite(f_new) & jnp.isfinite(gnorm), 0, 2))
        return y_new, jnp.where(started, it + 1, it), gnorm, code, f_y, g_new, mu_next, True

    y, it, gnorm, code, value, _, _, _ = jax.lax.while_loop(
        cond, body, (y0, 0, jnp.inf, 0, jnp.asarray(0.0, y0.dtype), jnp.zeros_like(y0), jnp.asarray(0.0, y0.dtype),
                     False))
    code = jnp.where(
        ~(jnp.isfinite(value) & jnp.isfinite(gnorm)), 2,
        jnp.where(gnorm <= gtol, 0, jnp.where(code == 0, 1, code)),
    )
    return y, value, gnorm, it, code


def minimise(fun, y0, args=None, solver=LBFGS(), gtol=1e-9, max_steps=None, throw=True):
    """Minimise (or, for Newton, find the stationary point nearest to y0 of) ``fun(y, args)``. fun
    must be a stable callable (a module-level function or a bound method of a long-lived object): it
    is a static argument of the jitted loop, so a fresh lambda per call recompiles. gtol bounds max
    |grad f| at the returned point. Returns a ``Solution``; raises ``ConvergenceError`` if it did
    not converge and ``throw`` is True."""
    if not np.all(np.isfinite(np.asarray(y0, dtype=float))):
        raise ValueError("y0 must be finite")
    y0 = jnp.asarray(y0, dtype=jnp.float64)
    if isinstance(solver, LBFGS):
        steps = 20000 if max_steps is None else int(max_steps)
        y, value, gnorm, it, code = _lbfgs_loop(fun, y0, args, gtol, solver.memory, solver.max_linesearch_steps, steps)
        name = "lbfgs"
    elif isinstance(solver, Newton):
        steps = 50 if max_steps is None else int(max_steps)
        y, value, gnorm, it, code = _newton_loop(
            fun, solver.zero_modes, y0, args, gtol, steps, solver.max_backtracks,
            solver.near_null_tol > 0.0, solver.near_null_tol, solver.hessian, solver.direction,
        )
        name = "newton"
    elif isinstance(solver, DampedNewton):
        steps = 500 if max_steps is None else int(max_steps)
        y, value, gnorm, it, code = _damped_newton_loop(
            fun, solver.zero_modes, solver.leave, y0, args, gtol, solver.max_step, steps, solver.max_backtracks,
            solver.hessian,
        )
        name = "damped_newton"
    elif isinstance(solver, HostDampedNewton):
        steps = 500 if max_steps is None else int(max_steps)
        y, value, gnorm, it, code = _host_damped_newton(fun, solver, y0, args, float(gtol), steps)
        name = "damped_newton_sparse"
    else:
        raise TypeError(f"solver must be LBFGS, Newton, DampedNewton or HostDampedNewton, got {type(solver).__name__}")
    sol = Solution(
        y=np.asarray(y),
        value=float(value),
        grad_norm=float(gnorm),
        iterations=int(it),
        converged=int(code) == 0,
        reason=_REASONS[int(code)],
        solver=name,
        gtol=float(gtol),
    )
    if throw and not sol.converged:
        raise ConvergenceError(f"{name} did not converge: {sol!r}")
    return sol


@functools.lru_cache(maxsize=64)
def _host_functions(fun, leave):
    """Jitted energy, gradient, both at once and leave test of one (fun, leave) pair, shared by
    every run."""
    return (jax.jit(fun), jax.jit(jax.grad(fun)), jax.jit(jax.value_and_grad(fun)),
            (jax.jit(leave) if leave is not None else None))


def _host_damped_newton(fun, solver, y0, args, gtol, max_steps):
    """The loop of ``_damped_newton_loop`` in Python around ``solver.direction``; returns
    (y, value, grad_norm, iterations, code) with the same codes."""
    # The first trial of each step is evaluated with its gradient (accepted, it is the next
    # iterate: one evaluation instead of two); a backtracked trial is evaluated alone.
    f, grad, value_and_grad, leave = _host_functions(fun, solver.leave)
    y = np.asarray(y0, dtype=float)
    fy, g = value_and_grad(y, args)
    fy, g = float(fy), np.asarray(g)
    gnorm = float(np.max(np.abs(g)))
    code = 0 if (np.isfinite(gnorm) and np.isfinite(fy)) else 2
    it, mu_prev = 0, 0.0
    while it < max_steps and gnorm > gtol and code == 0:
        dy, mu_prev = solver.direction(y, args, g, mu_prev)
        dy = np.asarray(dy, dtype=float)
        it += 1
        if not np.all(np.isfinite(dy)):
            code = 2  # the linear algebra failed (no shift made the system definite)
            break
        big = float(np.max(np.abs(dy)))
        if big > solver.max_step:
            dy = dy * (solver.max_step / big)
        slope = float(g @ dy)
        f_new, g_new = value_and_grad(y + dy, args)
        alpha, f_new, k = 1.0, float(f_new), 0
        while k < solver.max_backtracks and not (np.isfinite(f_new) and f_new <= fy + 1e-4 * alpha * slope):
            alpha *= 0.5
            f_new, g_new = float(f(y + alpha * dy, args)), None
            k += 1
        accepted = np.isfinite(f_new) and f_new <= fy + 1e-4 * alpha * slope
        if accepted:
            y, fy = y + alpha * dy, f_new
            g = np.asarray(grad(y, args) if g_new is None else g_new)
            gnorm = float(np.max(np.abs(g)))
        left = bool(leave(y, args)) if leave is not None else False
        code = (4 if (left and gnorm > gtol) else 0) if accepted else 3
    if not (np.isfinite(fy) and np.isfinite(gnorm)) or code == 2:
        code = 2
    elif gnorm <= gtol:
        code = 0
    elif code == 0:
        code = 1
    return y, fy, gnorm, it, code
