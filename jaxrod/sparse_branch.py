"""O(N) continuation steps: the sparse counterparts of the dense Newton corrector
(``solve_equilibrium(..., method="newton")``) and of ``jaxrod.stability.branch_analysis``.

Built on ``jaxrod.sparse_stability`` (block-tridiagonal Hessian + rank one, gauge pinning), so no
n x n array is ever formed: every piece costs O(N). Scope as there: scenes WITHOUT the "contact"
term. Used by ``jaxrod.critical_twist(..., linear_algebra="sparse")``.

* :func:`sparse_newton`: a jitted ``lax.while_loop`` of pinned Newton steps with backtracking on
  |grad|^2 (the merit of ``jaxrod.solvers._newton_loop``), returning a ``Solution``.
* :func:`solve_equilibrium_sparse`: the same wrapped into an ``Equilibrium`` (with its
  neighbourhood, no stability), like ``solve_equilibrium(..., with_stability=False)``.
* :func:`sparse_branch_analysis`: (Stability, lam_index, dlam_dphi, v_index, dq_dphi), the tuple of
  ``branch_analysis``.
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import sparse_stability as ss
from .equilibrium import _grown, equilibrium_from_solution
from .material import check_finite
from .neighbourhood import WRITHE_DRIFT_LIMIT
from .solvers import ConvergenceError, Solution, _REASONS
from .stability import DEFAULT_NEGATIVE_TOL, Stability

__all__ = ["sparse_newton", "solve_equilibrium_sparse", "sparse_branch_analysis", "eigenvalue_branch_derivative"]


# ------------------------------------------------------------------------------------------------
# Newton corrector


@functools.partial(jax.jit, static_argnames=("max_steps", "max_backtracks"))
def _newton_loop(scene, u0, phi, nbr, gtol, max_steps, max_backtracks):
    """(u, value, max|g|, iterations, reason code) -- codes as ``jaxrod.solvers._REASONS``."""
    f = lambda y: scene.scaled_energy(y, phi, nbr)  # noqa: E731
    grad = jax.grad(f)

    def g2(y):
        g = grad(y)
        return jnp.where(jnp.all(jnp.isfinite(g)), jnp.sum(g * g), jnp.inf)

    def cond(carry):
        _, it, gnorm, code = carry
        return (it < max_steps) & (gnorm > gtol) & (code == 0)

    def body(carry):
        y, it, _, _ = carry
        g = grad(y)
        dy = ss.newton_direction(scene, y, phi, nbr, g)
        g2_0 = jnp.sum(g * g)

        # Backtrack on |grad|^2 (not the energy): the corrector must also converge to saddles.
        def ls_cond(c):
            alpha, k, g2_new = c
            return (k < max_backtracks) & ~(g2_new < (1.0 - 1e-4 * alpha) * g2_0)

        def ls_body(c):
            alpha, k, _ = c
            return 0.5 * alpha, k + 1, g2(y + 0.5 * alpha * dy)

        alpha, _, g2_new = jax.lax.while_loop(ls_cond, ls_body, (1.0, 0, g2(y + dy)))
        accepted = g2_new < (1.0 - 1e-4 * alpha) * g2_0
        y_new = jnp.where(accepted, y + alpha * dy, y)
        code = jnp.where(~jnp.all(jnp.isfinite(dy)), 2, jnp.where(accepted, 0, 3))
        return y_new, it + 1, jnp.max(jnp.abs(grad(y_new))), code

    gnorm0 = jnp.max(jnp.abs(grad(u0)))
    y, it, gnorm, code = jax.lax.while_loop(cond, body, (u0, 0, gnorm0, jnp.where(jnp.isfinite(gnorm0), 0, 2)))
    value = f(y)
    code = jnp.where(~(jnp.isfinite(value) & jnp.isfinite(gnorm)), 2,
                     jnp.where(gnorm <= gtol, 0, jnp.where(code == 0, 1, code)))
    return y, value, gnorm, it, code


def sparse_newton(scene, u0, phi, nbr, gtol=1e-9, max_steps=50, max_backtracks=40):
    """Newton's method on grad = 0 from u0 (n,) (scaled DOFs) with the gauge-pinned block solve
    (``sparse_stability.newton_direction``): converges to the nearest stationary point, stable or
    not. gtol bounds max |grad| of the scaled energy. Returns a ``Solution`` (y (n,) scaled DOFs);
    never raises (check ``converged``)."""
    u0 = jnp.asarray(u0, dtype=jnp.float64)
    y, value, gnorm, it, code = _newton_loop(scene, u0, jnp.asarray(phi, jnp.float64), nbr, gtol, int(max_steps),
                                             int(max_backtracks))
    code = int(code)
    return Solution(y=np.asarray(y), value=float(value), grad_norm=float(gnorm), iterations=int(it),
                    converged=code == 0, reason=_REASONS[code], solver="sparse_newton", gtol=float(gtol))


def solve_equilibrium_sparse(scene, phi, q0=None, gtol=1e-9, max_steps=50, nbr=None, throw=True):
    """``solve_equilibrium(scene, phi, q0, method="newton", with_stability=False)`` in O(N).

    q0: (n,) physical DOFs (default scene.q_init). The neighbourhood (frozen writhe) is rebuilt
    around the result and the solve repeated if the writhe drifted out of it, as in the dense
    path. Returns an ``Equilibrium`` with its neighbourhood and stability None; raises
    ``ConvergenceError`` if Newton fails and ``throw``.
    """
    ss._check_scene(scene)
    phi = check_finite("phi", phi)
    q = np.asarray(scene.q_init if q0 is None else q0, dtype=float)
    nbr = _grown(scene, q, phi, nbr)
    for _ in range(20):
        sol = sparse_newton(scene, scene.to_scaled(jnp.asarray(q)), phi, nbr, gtol, max_steps)
        if not np.all(np.isfinite(sol.y)):
            break
        q = np.asarray(scene.from_scaled(jnp.asarray(sol.y)))
        nbr_new = _grown(scene, q, phi, nbr)
        drifted = abs(float(nbr_new.wr_ref) - float(nbr.wr_ref)) > WRITHE_DRIFT_LIMIT
        nbr = nbr_new
        if not drifted:
            break
    if throw and not sol.converged:
        raise ConvergenceError(f"sparse_newton did not converge: {sol!r}")
    return equilibrium_from_solution(scene, phi, sol, nbr, with_stability=False)


# ------------------------------------------------------------------------------------------------
# branch analysis


@jax.jit
def eigenvalue_branch_derivative(scene, u, phi, v, du, nbr):
    """d lambda/d phi = v^T (dH/du[du] + dH/dphi) v along the branch, for the eigenvector v (n,)
    and the branch tangent du (n,) (scaled DOFs): nested forward-mode jvps of the scaled energy
    (Hellmann-Feynman plus the branch's own motion; no Hessian or third-order tensor formed)."""
    f = lambda uu, pp: scene.scaled_energy(uu, pp, nbr)  # noqa: E731

    def vhv(uu, pp):
        first = lambda w: jax.jvp(lambda y: f(y, pp), (w,), (v,))[1]  # noqa: E731
        return jax.jvp(first, (uu,), (v,))[1]

    phi = jnp.asarray(phi, u.dtype)
    return jax.jvp(vhv, (u, phi), (du, jnp.ones_like(phi)))[1]


def sparse_branch_analysis(scene, q, phi, index, k=8, tol=DEFAULT_NEGATIVE_TOL, cluster_rtol=None, ref=None,
                           pinv_tol=0.0, nbr=None):
    """``jaxrod.stability.branch_analysis`` in O(N) (no contact): at an equilibrium q (n,)
    (physical DOFs), returns (Stability, lam, dlam_dphi, v (n,) scaled DOFs, dq_dphi (n,)
    physical DOFs).

    n_negative: ``inertia_at_equilibrium`` (the whole spectrum's count below -tol); eigenvalues /
    eigenvectors (k,) / (n, k): ``lowest_eigenpairs_projected``. The tracked mode is number
    ``index`` of those k, or with ``ref`` (n,) the one overlapping it most (so it must be among
    the k lowest). The tangent is the minimum-norm one (``sparse_stability.tangent``); the dense
    code also leaves the tracked mode's cluster out of it, which changes nothing on a symmetric
    branch (its tangent has no component along the symmetry-breaking critical modes).
    cluster_rtol and pinv_tol are accepted for signature compatibility and ignored (no near-null
    sliding modes without contact).
    """
    u = scene.to_scaled(jnp.asarray(q))
    if nbr is None:
        nbr = scene.neighbourhood(jnp.asarray(q), phi)
    n_neg = int(ss.inertia_at_equilibrium(scene, u, phi, nbr, tol))
    pairs = ss.lowest_eigenpairs_projected(scene, u, phi, nbr, k)
    lam, vec = np.asarray(pairs.values), np.asarray(pairs.vectors)
    if ref is not None and np.any(np.asarray(ref) != 0.0):
        index = int(np.argmax(np.abs(vec.T @ np.asarray(ref))))
    if not 0 <= index < lam.shape[0]:
        raise ValueError(f"index {index} outside the {lam.shape[0]} eigenpairs computed (raise k)")
    du = ss.tangent(scene, u, phi, nbr)
    v = jnp.asarray(vec[:, index])
    dlam = float(eigenvalue_branch_derivative(scene, u, jnp.asarray(phi, u.dtype), v, du, nbr))
    stab = Stability(eigenvalues=lam, eigenvectors=vec, n_negative=n_neg, n_zero_modes=int(scene.n_zero_modes),
                     stable=n_neg == 0, tol=tol)
    return stab, float(lam[index]), dlam, vec[:, index], np.asarray(scene.from_scaled(du))
