"""Two-parameter continuation: a located fold followed in a second parameter mu.

The fold curve is the solution set of the minimally augmented system G(u, p, mu) = (F, sigma) = 0
(see locate.py), followed by the same pseudo-arclength core with x = (u, p) and lam = mu; its
Jacobian is assembled densely. At each point the implicit function theorem gives dp*/dmu from one
bordered solve  [[J, F_p], [sigma_u^T, sigma_p]] [du; dp] = -[F_mu; sigma_mu].
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .corrector import advance, correct, tangent
from .locate import _fold_newton
from .results import ContinuationError, Event, Result
from .scales import scaled_options


@dataclass
class FoldCurve:
    """Fold (or branch) points along mu: mu, p, dp_dmu (IFT), residual (m,); u, v (m, n); result, message."""

    mu: np.ndarray
    p: np.ndarray
    u: np.ndarray
    v: np.ndarray
    dp_dmu: np.ndarray
    residual: np.ndarray
    result: Result
    message: str


class FoldPoint(NamedTuple):
    """A fold located at a given mu: u (n,), p, mu, v (n,) its unit critical vector, its dp*/dmu
    (IFT), the residual of (F, sigma), the Newton iterations, converged."""

    u: np.ndarray
    p: float
    mu: float
    v: np.ndarray
    dp_dmu: float
    residual: float
    iterations: int
    converged: bool


class _Traced(NamedTuple):
    """What the extended systems' jitted blocks use of a problem: its functions of (u, p, args),
    shared by every problem of the same energy, jacobian and backend, so that the blocks compile
    once per rod and shape, not once per problem."""

    F: object
    hvp: object
    linearise: object
    singular_tests: object
    backend: object


def _traced(problem):
    return _Traced(problem.F, problem.hvp, problem.traced_linearise, problem.traced_singular_tests, problem.backend)


@functools.partial(jax.jit, static_argnames=("problem", "set_mu"))
def _fold_blocks_jit(problem, set_mu, args0, u, p, mu, b):
    be, n = problem.backend, u.shape[0]
    args = set_mu(args0, mu)
    F, J, Fp = problem.linearise(u, p, args)
    Fmu = jax.jvp(lambda m: problem.F(u, p, set_mu(args0, m)), (mu,), (jnp.ones_like(mu),))[1]
    w, sigma = be.bordered_solve(J, b, b, 0.0, jnp.zeros(n), 1.0)
    grads = jax.grad(lambda x, q, m: jnp.dot(w, problem.hvp(x, q, set_mu(args0, m), w)), argnums=(0, 1, 2))
    gu, gp, gm = grads(u, p, mu)
    return F, J, Fp, Fmu, sigma, -gu, -gp, -gm, w


def _fold_blocks(problem, set_mu, base=None):
    """(u, p, mu, b) -> (F, J, F_p, F_mu, sigma, sigma_u, sigma_p, sigma_mu, w): the fold system
    (locate.py) and its derivatives, with args = set_mu(args0, mu), args0 the problem's args or
    base[0] at call time (base: a one-element list, rebased along a fold curve)."""
    base = [problem.args] if base is None else base
    f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
    traced = _traced(problem)
    return lambda u, p, mu, b: _fold_blocks_jit(traced, set_mu, base[0], f64(u), f64(p), f64(mu), f64(b))


def _fold_system(problem, blocks, border):
    """lin(x = (u, p), mu) for the corrector: G = (F, sigma), its Jacobian in x and in mu. ``border``
    is a one-element list holding the current border b (refreshed by the caller)."""

    def lin(x, mu):
        F, J, Fp, Fmu, s, su, sp, sm, _ = blocks(x[:-1], x[-1], mu, border[0])
        A = jnp.block([[J, Fp[:, None]], [su[None, :], jnp.reshape(sp, (1, 1))]])
        return jnp.append(F, s), A, jnp.append(Fmu, sm)

    return lin


def _ift_slope(problem, blocks, u, p, mu, b):
    """(du*/dmu (n,), dp*/dmu, w) at a fold: [[J, F_p], [sigma_u^T, sigma_p]] [du; dp] = -[F_mu; sigma_mu]."""
    F, J, Fp, Fmu, s, su, sp, sm, w = blocks(u, p, mu, b)
    du, dp = problem.backend.bordered_solve(J, Fp, su, sp, -Fmu, -sm)
    return np.asarray(du), float(dp), np.asarray(w) / np.linalg.norm(w)


def fold_at(problem, fold, set_mu, mu0, mu, opts, *, predict=True):
    """The fold ``fold`` (an Event, or a FoldPoint) of ``problem``, located at mu0, moved to mu.

    Newton on the fold system in (u, p) at fixed mu from the implicit function theorem's prediction
    (``predict=False``: from the fold's own (u, p)). set_mu(args, mu) -> args, traceable, with
    problem.args at mu0. Returns a FoldPoint with dp*/dmu at mu.
    """
    opts = scaled_options(problem, opts, fold.u, fold.p)
    v = np.asarray(fold.v[:, 0] if isinstance(fold, Event) else fold.v)
    v = v / np.linalg.norm(v)
    blocks = _fold_blocks(problem, set_mu)
    du, dp, w = _ift_slope(problem, blocks, fold.u, fold.p, float(mu0), v)
    delta = float(mu) - float(mu0) if predict else 0.0
    args = set_mu(problem.args, jnp.asarray(float(mu)))
    u, p, _, _, res, it = _fold_newton(problem, opts, np.asarray(fold.u) + delta * du, float(fold.p) + delta * dp, w,
                                       args=args)
    _, dp, w = _ift_slope(problem, blocks, u, p, float(mu), w)
    _, dp, w = _ift_slope(problem, blocks, u, p, float(mu), w)  # with w at the root: the critical vector
    converged = bool(np.isfinite(res) and res <= opts.newton_tol)
    return FoldPoint(np.asarray(u), float(p), float(mu), w, dp, float(res), int(it), converged)


def fold_sensitivity(problem, fold, set_mu, mu0):
    """dp*/dmu at the located fold ``fold`` (an Event of ``problem``, whose args hold mu = mu0).

    The implicit function theorem on the fold system G(u, p, mu) = (F, sigma) = 0, one bordered
    solve: the derivative of the located critical twist, not of an eigenvalue on a fixed branch.
    set_mu(args, mu) -> args must be traceable (e.g. ``jaxrod.continuation.arclength.rods.set_poisson_ratio``).
    """
    blocks = _fold_blocks(problem, set_mu)
    _, dp, _ = _ift_slope(problem, blocks, fold.u, fold.p, float(mu0), np.asarray(fold.v[:, 0]))
    return dp


def fold_curve(problem, fold, set_mu, mu0, alg, opts, *, throw=True, observer=None):
    """Continue the fold Event ``fold`` of ``problem`` (whose args hold mu = mu0) in mu.

    set_mu(args, mu) -> args must be traceable and set mu absolutely. opts.ds (signed) is the first
    step in mu, [opts.p_min, opts.p_max] bounds mu, the rest as for continuation (report_at: values
    of mu). ``update_args`` (if any) is applied after each point; observer(i, mu, p, residual), if
    given, is called after each point.
    """
    opts = scaled_options(problem, opts, fold.u, fold.p)
    be, n = problem.backend, problem.n
    base = [problem.args]
    blocks = _fold_blocks(problem, set_mu, base)
    border = [np.asarray(fold.v[:, 0])]  # refreshed with w at each point

    lin = _fold_system(problem, blocks, border)
    rows = []

    def record(z, res):
        _, dp, border[0] = _ift_slope(problem, blocks, z[:-2], z[-2], z[-1], border[0])
        rows.append((z[-1], z[-2], z[:-2], border[0], dp, res))
        if problem.update_args is not None:
            base[0] = problem.update_args(z[:-2], float(z[-2]), set_mu(base[0], jnp.asarray(float(z[-1]))))
        if observer is not None:
            observer(len(rows), float(z[-1]), float(z[-2]), float(res))

    t0 = np.zeros(n + 2)
    t0[-1] = np.sign(opts.ds)
    c = correct(be, lin, np.concatenate([fold.u, [fold.p, mu0]]), t0, opts.newton_tol, opts.newton_max_iter)
    return _follow(be, lin, c, t0, record, rows, opts, alg, throw, "fold")


@functools.partial(jax.jit, static_argnames=("problem", "set_mu"))
def _branch_point_blocks_jit(problem, set_mu, args0, u, p, mu, b):
    def tests(x, q, m):
        return problem.singular_tests(x, q, set_mu(args0, m), b)

    (gu, gp, gm), (st, F, J, Fp, w) = jax.jacrev(tests, argnums=(0, 1, 2), has_aux=True)(u, p, mu)
    Fmu = jax.jvp(lambda m: problem.F(u, p, set_mu(args0, m)), (mu,), (jnp.ones_like(mu),))[1]
    return F, J, Fp, Fmu, st, gu, gp, gm, w


def _branch_point_system(problem, set_mu, args0, u, p, beta, mu, v0, b):
    """The unfolded branch-point system at (u, p, beta, mu) with args = set_mu(args0, mu), border b:
    (G = (F + beta v0, sigma, tau) (n+2,), A = dG/d(u, p, beta) (n+2, n+3), a = dG/dmu (n+2,), w)."""
    f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
    F, J, Fp, Fmu, st, gu, gp, gm, w = _branch_point_blocks_jit(_traced(problem), set_mu, args0, f64(u), f64(p),
                                                                f64(mu), f64(b))
    G = jnp.concatenate([F + beta * v0, st])
    A = jnp.block([[J, Fp[:, None], jnp.asarray(v0)[:, None]], [gu, gp[:, None], jnp.zeros((2, 1))]])
    return G, A, jnp.concatenate([Fmu, gm]), w


def branch_point_curve(problem, event, set_mu, mu0, alg, opts, *, throw=True, observer=None):
    """Continue the simple branch point ``event`` of ``problem`` (whose args hold mu = mu0) in mu.

    The branch point is the root of the unfolded system (locate.py, Moore 1980)
        F(u, p, mu) + beta v0 = 0,  sigma(u, p, mu) = 0,  tau(u, p, mu) = w^T F_p = 0
    in x = (u, p, beta), regular at a transversal simple branch point (make a double one simple
    first: ``jaxrod.continuation.arclength.rods.sliding_slice``). Returns a FoldCurve (v: the unit
    kernel vector w). Arguments as ``fold_curve``.
    """
    opts = scaled_options(problem, opts, event.u, event.p)
    be, n = problem.backend, problem.n
    base = [problem.args]
    v0 = np.asarray(event.v[:, 0]) / np.linalg.norm(event.v[:, 0])
    border = [v0]

    def system(x, mu):  # (G, A = dG/dx, a = dG/dmu, w) from one evaluation of the blocks
        return _branch_point_system(problem, set_mu, base[0], x[:n], x[n], x[n + 1], mu, v0, border[0])

    def lin(x, mu):
        return system(x, mu)[:3]

    rows = []

    def record(z, res):
        _, A, a, w = system(z[:-1], z[-1])
        dx = np.linalg.solve(np.asarray(A), -np.asarray(a))
        w = np.asarray(w)
        border[0] = w / np.linalg.norm(w)
        rows.append((z[-1], z[n], z[:n], border[0], float(dx[n]), res))
        if problem.update_args is not None:
            base[0] = problem.update_args(z[:n], float(z[n]), set_mu(base[0], jnp.asarray(float(z[-1]))))
        if observer is not None:
            observer(len(rows), float(z[-1]), float(z[n]), float(res))

    t0 = np.zeros(n + 3)
    t0[-1] = np.sign(opts.ds)
    z0 = np.concatenate([np.asarray(event.u), [float(event.p), 0.0, float(mu0)]])
    c = correct(be, lin, z0, t0, opts.newton_tol, opts.newton_max_iter)
    return _follow(be, lin, c, t0, record, rows, opts, alg, throw, "branch point")


def _follow(be, lin, c, t0, record, rows, opts, alg, throw, what):
    """The pseudo-arclength loop of a two-parameter curve from its first correction c."""
    result, message = Result.MAX_STEPS, f"stopped after max_steps = {opts.max_steps} steps"
    if not c.converged:
        result, message = Result.CORRECTOR_FAILED, f"the {what} did not converge at mu0: residual {c.residual:.3g}"
    else:
        record(c.z, c.residual)
        z, t, ds = c.z, tangent(be, c.lin[1], c.lin[2], t0), abs(opts.ds)
        for _ in range(opts.max_steps):
            step = advance(alg, be, lin, z, t, ds, opts)
            if step is None:
                result = Result.CORRECTOR_FAILED
                message = f"the {what}-curve corrector failed down to ds_min = {opts.ds_min:g} at mu = {z[-1]:.12g}"
                break
            for target in [m for m in opts.report_at if min(z[-1], step.z[-1]) < m < max(z[-1], step.z[-1])]:
                # a point exactly at this mu: corrected from the chord on the hyperplane mu = target
                s_frac = (target - z[-1]) / (step.z[-1] - z[-1])
                e_mu = np.zeros_like(z)
                e_mu[-1] = 1.0
                exact = correct(be, lin, z + s_frac * (step.z - z), e_mu, opts.newton_tol, opts.newton_max_iter)
                if exact.converged:
                    record(exact.z, exact.residual)
            z, t, ds = step.z, step.tangent, step.ds_next
            record(z, step.correction.residual)
            if not opts.p_min <= z[-1] <= opts.p_max:
                result, message = Result.BOUNDARY, f"mu = {z[-1]:.12g} left [{opts.p_min:g}, {opts.p_max:g}]"
                break
    cols = list(zip(*rows)) if rows else [[]] * 6
    curve = FoldCurve(*(np.array(col) for col in cols), result, message)
    if throw and result is Result.CORRECTOR_FAILED:
        raise ContinuationError(f"{result.value}: {message}", curve)
    return curve
