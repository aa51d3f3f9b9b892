"""O(N) continuation steps: the sparse counterparts of the dense Newton corrector
(``solve_equilibrium(..., EquilibriumOptions(method="newton"))``) and of
``jaxrod.linalg.stability.branch_analysis``.

Built on ``jaxrod.linalg.sparse`` (block-tridiagonal Hessian + rank one, gauge pinning): no n x n
array is formed. Scope as there: scenes without the "contact" term.
"""
from __future__ import annotations

from dataclasses import replace

import jax.numpy as jnp
import numpy as np

from ..linalg import sparse as ss
from ..linalg.sparse import EXTRA_PAIRS
from ..model.hessian import eigenvalue_branch_derivative  # noqa: F401  (re-exported)
from ..solve.equilibrium import _grown, equilibrium_from_solution, scaled_energy
from ..validation import check_finite
from ..solve.solvers import ConvergenceError, Newton, minimise
from ..linalg.stability import DEFAULT_NEGATIVE_TOL, Stability, _stability_from_lowest

__all__ = ["sparse_newton", "solve_equilibrium_sparse", "sparse_branch_analysis", "eigenvalue_branch_derivative"]


# ------------------------------------------------------------------------------------------------
# Newton corrector


def _pinned_direction(u, args, g):
    """The Newton step of ``Newton(direction=...)`` by the gauge-pinned block solve."""
    scene, phi, nbr = args
    return ss.newton_direction(scene, u, phi, nbr, g)


def sparse_newton(scene, u0, phi, nbr, gtol=1e-9, max_steps=50, max_backtracks=40):
    """Newton's method on grad = 0 from u0 (n,) (scaled DOFs) with the gauge-pinned block solve, to
    the nearest stationary point. gtol bounds max |grad|. Returns a ``Solution``; never raises."""
    solver = Newton(direction=_pinned_direction, max_backtracks=int(max_backtracks))
    sol = minimise(scaled_energy, u0, (scene, jnp.asarray(phi, jnp.float64), nbr), solver, gtol, int(max_steps),
                   throw=False)
    return replace(sol, solver="sparse_newton")


def solve_equilibrium_sparse(scene, phi, q0=None, gtol=1e-9, max_steps=50, nbr=None, throw=True):
    """``solve_equilibrium(scene, phi, q0, EquilibriumOptions(method="newton", with_stability=False))``
    in O(N).

    q0: (n,) physical DOFs (default scene.q_init); the solve is repeated if the writhe drifted out
    of the neighbourhood. Returns an ``Equilibrium`` with stability None; raises
    ``ConvergenceError`` if Newton fails and ``throw``.
    """
    ss._check_scene(scene)
    phi = check_finite("phi", phi)
    q = np.asarray(scene.q_init if q0 is None else q0, dtype=float)
    if nbr is None or scene.needs_neighbourhood:
        nbr = _grown(scene, q, phi, nbr)
    for _ in range(20):
        sol = sparse_newton(scene, jnp.asarray(scene.to_scaled(q)), phi, nbr, gtol, max_steps)
        if not np.all(np.isfinite(sol.y)):
            break
        q = scene.from_scaled(np.asarray(sol.y))
        upd = nbr.update(scene, q, phi)
        nbr = upd.nbr
        if not upd.drifted:  # (stale needs no repeat: without contact the list is empty)
            break
    if throw and not sol.converged:
        raise ConvergenceError(f"sparse_newton did not converge: {sol!r}")
    return equilibrium_from_solution(scene, phi, sol, nbr, with_stability=False)


# ------------------------------------------------------------------------------------------------
# branch analysis


def sparse_branch_analysis(scene, q, phi, index, k=8, tol=DEFAULT_NEGATIVE_TOL, cluster_rtol=None, ref=None,
                           pinv_tol=0.0, nbr=None, guess=None):
    """``jaxrod.linalg.stability.branch_analysis`` in O(N): at an equilibrium q (n,) (physical
    DOFs), returns (Stability, lam, dlam_dphi, v (n,) scaled DOFs, dq_dphi (n,) physical DOFs).
    n_negative: ``inertia_at_equilibrium``; eigenvalues / eigenvectors (m,) / (n, m):
    ``lowest_eigenpairs_projected``, m = k, or index + EXTRA_PAIRS where the index is not below k.
    The tracked mode is number ``index`` of those, or with ``ref`` (n,) the one overlapping it
    most. The tangent is the minimum-norm one. guess: an estimate of the lowest eigenvalue, which
    saves factorisations. cluster_rtol and pinv_tol are used with contact only.
    """
    from ..linalg.sparse_contact import contact_branch_analysis, tracked_mode_inputs

    if scene.has_term("contact"):
        n_neg, lam, vec, lam_i, dlam, v, dq = contact_branch_analysis(
            scene, q, phi, index, k=k, tol=tol, cluster_rtol=1e-4 if cluster_rtol is None else cluster_rtol, ref=ref,
            pinv_tol=pinv_tol, nbr=nbr, guess=guess)
        return _stability_from_lowest(lam, vec, int(scene.n_zero_modes), n_neg, int(k), tol), lam_i, dlam, v, dq
    u, nbr, index = tracked_mode_inputs(scene, q, phi, nbr, index)
    n_neg = int(ss.inertia_at_equilibrium(scene, u, phi, nbr, tol))
    k = int(k) if index < int(k) else min(index + EXTRA_PAIRS, int(u.shape[0]) - int(scene.n_zero_modes))
    pairs = ss.lowest_eigenpairs_projected(scene, u, phi, nbr, k, guess=guess)
    lam, vec = np.asarray(pairs.values), np.asarray(pairs.vectors)
    if ref is not None and np.any(np.asarray(ref) != 0.0):
        index = int(np.argmax(np.abs(vec.T @ np.asarray(ref))))
    if not index < lam.shape[0]:
        raise ValueError(f"index {index}: the scene has only {lam.shape[0]} eigenpairs")
    du = ss.tangent(scene, u, phi, nbr)
    v = jnp.asarray(vec[:, index])
    dlam = float(eigenvalue_branch_derivative(scene, u, jnp.asarray(phi, u.dtype), v, du, nbr))
    stab = Stability(eigenvalues=lam, eigenvectors=vec, n_negative=n_neg, n_zero_modes=int(scene.n_zero_modes),
                     stable=n_neg == 0, tol=tol)
    return stab, float(lam[index]), dlam, vec[:, index], np.asarray(scene.from_scaled(du))
