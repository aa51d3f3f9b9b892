"""O(N) continuation steps: the sparse counterparts of the dense Newton corrector
(``solve_equilibrium(..., EquilibriumOptions(method="newton"))``) and of
``jaxrod.linalg.stability.branch_analysis``.

Built on ``jaxrod.linalg.sparse`` (block-tridiagonal Hessian + rank one, gauge pinning), so no
n x n array is ever formed: every piece costs O(N). Scope as there: scenes WITHOUT the "contact"
term. Used by ``jaxrod.critical_twist(..., ContinuationOptions(linear_algebra="sparse"))``.

* :func:`sparse_newton`: ``minimise`` with ``Newton(direction=...)``: the solvers' jitted Newton
  loop (backtracking on |grad|^2) with the pinned block solve as its step, returning a ``Solution``.
* :func:`solve_equilibrium_sparse`: the same wrapped into an ``Equilibrium`` (with its
  neighbourhood, no stability), like ``solve_equilibrium`` with
  ``EquilibriumOptions(with_stability=False)``.
* :func:`sparse_branch_analysis`: (Stability, lam_index, dlam_dphi, v_index, dq_dphi), the tuple of
  ``branch_analysis``.
"""
from __future__ import annotations

from dataclasses import replace

import jax.numpy as jnp
import numpy as np

from ..linalg import sparse as ss
from ..linalg.sparse import EXTRA_PAIRS, eigenvalue_branch_derivative  # noqa: F401  (re-exported)
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
    """Newton's method on grad = 0 from u0 (n,) (scaled DOFs) with the gauge-pinned block solve
    (``sparse_stability.newton_direction``): converges to the nearest stationary point, stable or
    not. gtol bounds max |grad| of the scaled energy. Returns a ``Solution`` (y (n,) scaled DOFs);
    never raises (check ``converged``)."""
    solver = Newton(direction=_pinned_direction, max_backtracks=int(max_backtracks))
    sol = minimise(scaled_energy, u0, (scene, jnp.asarray(phi, jnp.float64), nbr), solver, gtol, int(max_steps),
                   throw=False)
    return replace(sol, solver="sparse_newton")


def solve_equilibrium_sparse(scene, phi, q0=None, gtol=1e-9, max_steps=50, nbr=None, throw=True):
    """``solve_equilibrium(scene, phi, q0, EquilibriumOptions(method="newton", with_stability=False))``
    in O(N).

    q0: (n,) physical DOFs (default scene.q_init). The neighbourhood (frozen writhe) is rebuilt
    around the result and the solve repeated if the writhe drifted out of it, as in the dense
    path. Returns an ``Equilibrium`` with its neighbourhood and stability None; raises
    ``ConvergenceError`` if Newton fails and ``throw``.
    """
    ss._check_scene(scene)
    phi = check_finite("phi", phi)
    q = np.asarray(scene.q_init if q0 is None else q0, dtype=float)
    if nbr is None or scene.needs_neighbourhood:
        nbr = _grown(scene, q, phi, nbr)
    # else: without contact the neighbourhood is only the frozen writhe, and a given one (the
    # previous step's) is checked against the solution's exact writhe below: no rebuild first.
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
    """``jaxrod.linalg.stability.branch_analysis`` in O(N) (no contact): at an equilibrium q (n,)
    (physical DOFs), returns (Stability, lam, dlam_dphi, v (n,) scaled DOFs, dq_dphi (n,)
    physical DOFs).

    n_negative: ``inertia_at_equilibrium`` (the whole spectrum's count below -tol); eigenvalues /
    eigenvectors (m,) / (n, m): ``lowest_eigenpairs_projected``, m = k, or index + 4 where the
    tracked index is not below k. The tracked mode is number
    ``index`` of those m, or with ``ref`` (n,) the one overlapping it most (so it must be among
    the m lowest). The tangent is the minimum-norm one (``sparse_stability.tangent``); the dense
    code also leaves the tracked mode's cluster out of it, which changes nothing on a symmetric
    branch (its tangent has no component along the symmetry-breaking critical modes).
    guess: an estimate of the lowest eigenvalue (the previous step's), which saves 8 of the 9
    factorisations that choose the shift (``lowest_eigenpairs_projected``); never changes the
    result beyond the eigensolver's tolerance. cluster_rtol and pinv_tol are accepted for
    signature compatibility and ignored (no near-null sliding modes without contact).
    """
    from ..linalg.sparse_contact import contact_branch_analysis, tracked_mode_inputs

    if scene.has_term("contact"):
        n_neg, lam, vec, lam_i, dlam, v, dq = contact_branch_analysis(
            scene, q, phi, index, k=k, tol=tol, cluster_rtol=1e-4 if cluster_rtol is None else cluster_rtol, ref=ref,
            pinv_tol=pinv_tol, nbr=nbr, guess=guess)
        return _stability_from_lowest(lam, vec, int(scene.n_zero_modes), n_neg, int(k), tol), lam_i, dlam, v, dq
    u, nbr, index = tracked_mode_inputs(scene, q, phi, nbr, index)
    n_neg = int(ss.inertia_at_equilibrium(scene, u, phi, nbr, tol))
    # The tracked eigenpair must be among those computed: k, or more when the index needs it.
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
