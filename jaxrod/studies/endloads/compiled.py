"""The compiled pieces of an end-loaded rod, shared by Newton, the stability analysis and the end
loads: the energy's gradient with its derivatives in the far clamp's position and in the end
rotation, the structured Hessian, and the end loads T = dE/d(end distance), M = dE/dphi (exact
by autodiff)."""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ...linalg.stability import DEFAULT_NEGATIVE_TOL, _lowest_of, _stability_from_lowest
from ...model.hessian import project_out, scaled_hessian as structured_scaled_hessian
from ...validation import check_finite
from .scene import with_end_offset


@dataclass(frozen=True)
class EndLoads:
    """End loads at an equilibrium: T the axial tension (> 0 pulls the clamps together), M the
    axial twisting moment at the far clamp, force (3,) dE/d(far clamp position) (its component
    along the axis is T), M_twist the twisting moment C * (twist per length) along the rod (equal
    to M at an equilibrium)."""

    T: float
    M: float
    force: np.ndarray
    M_twist: float


# ---------------------------------------------------------------------- compiled pieces
# One compiled program per shape (``rod_all``), shared by Newton, the stability analysis, the
# force-loaded rod and ``straight_buckling_moment``: the Hessian is the costliest to compile.
def f64(x):
    """A float64 array (never weakly typed: one compiled program per shape, whatever the caller passes)."""
    return jnp.asarray(np.asarray(x, dtype=np.float64))


def _offset_scaled_energy(scene, u, off, phi, nbr):
    return with_end_offset(scene, off).scaled_energy(u, phi, nbr)


@jax.jit
def rod_all(scene, u, phi, nbr):
    """Everything Newton, the stability analysis and the end loads need at scaled DOFs u, in one
    program: (scaled energy, its gradient in u (n,), dE/d(far clamp offset) (3,) and dE/dphi in
    physical units, the twisting moment C * twist per length, the structured scaled Hessian
    (n, n), the zero-mode generators (n, k), scaled)."""
    val, (gu, goff, gphi) = jax.value_and_grad(_offset_scaled_energy, argnums=(1, 2, 3))(
        scene, u, scene.end_offset, phi, nbr)
    tw = scene.vertex_twists(u * scene.dof_scale, phi, nbr)
    M_twist = scene.material.C * jnp.sum(tw) / jnp.sum(scene.voronoi)
    es = scene.energy_scale
    return (val, gu, goff * es, gphi * es, M_twist, structured_scaled_hessian(scene, u, phi, nbr),
            scene.scaled_zero_modes(u, phi))


def rod_gradients(scene, u, phi, nbr):
    """(scaled energy, gradient in u, dE/d(offset), dE/dphi, M_twist), host arrays."""
    return jax.device_get(rod_all(scene, f64(u), f64(phi), nbr)[:5])


def rod_hessian(scene, u, phi, nbr):
    """(structured scaled Hessian (n, n), zero-mode generators (n, k)), host arrays."""
    return jax.device_get(rod_all(scene, f64(u), f64(phi), nbr)[5:])


def _project(h, z):
    """(H with the zero modes projected out and lifted to the top, n_zero), on the host: as
    ``jaxrod.linalg.stability``'s projected Hessian (``orthonormal_columns``, ``project_out``)."""
    h, z = np.asarray(h), np.asarray(z)
    if z.shape[1] == 0:
        return h, 0
    uz, sv, _ = np.linalg.svd(z, full_matrices=False)
    keep = sv > 1e-10 * np.max(sv) if np.max(sv) > 0.0 else np.zeros_like(sv, dtype=bool)
    z = uz * keep[None, :]
    return project_out(h, z, xp=np), int(np.sum(keep))


@jax.jit
def offset_coupling(scene, u, phi, nbr):
    """(n + 3, 3): d/d(far clamp offset, physical) of [dE_s/du (n,), dE_s/d(offset) (3,)], E_s the
    scaled energy: the force-loaded rod's end rows and columns, by 3 forward-over-reverse products."""
    def g(off):
        gu, goff = jax.grad(_offset_scaled_energy, argnums=(1, 2))(scene, u, off, phi, nbr)
        return jnp.concatenate([gu, goff])

    return jax.jacfwd(g)(scene.end_offset)


# Eigenvalues of the scaled Hessian are known to ~ eps max|H_ii| only: on a stiff rod that noise
# exceeds DEFAULT_NEGATIVE_TOL and must not count as negative.
EIGEN_ROUNDOFF_ULPS = 256.0


def rod_stability(scene, u, phi, nbr, k, tol=DEFAULT_NEGATIVE_TOL):
    """``jaxrod.linalg.stability.stability`` on the shared compiled Hessian (same projection, same
    lowest-eigenpair routine and tolerance, raised to the Hessian's roundoff,
    EIGEN_ROUNDOFF_ULPS eps max|H_ii|, where that is larger)."""
    h, z = rod_hessian(scene, u, phi, nbr)
    tol = max(float(tol), EIGEN_ROUNDOFF_ULPS * np.finfo(float).eps * float(np.max(np.abs(np.diag(np.asarray(h))))))
    hp, n_zero = _project(h, z)
    lam, vec, n_neg = _lowest_of(hp, tol)
    return _stability_from_lowest(np.asarray(lam), np.asarray(vec), int(n_zero), int(n_neg), k, tol)


def end_loads(scene, q, phi, nbr=None):
    """The ``EndLoads`` of state q (physical DOFs) at end rotation phi: exact partial derivatives of
    the energy in the far clamp's position and in phi (total ones at an equilibrium). ``nbr``: the
    state's neighbourhood (built here if None)."""
    q = np.asarray(q, dtype=float)
    phi = check_finite("phi", phi)
    if nbr is None:
        nbr = scene.neighbourhood(q, phi)
    _, _, f, M, Mt = rod_gradients(scene, scene.to_scaled(q), phi, nbr)
    f = np.asarray(f)
    return EndLoads(float(np.dot(f, np.asarray(scene.axis))), float(M), f, float(Mt))


def rod_evaluate(u, args):
    """(scaled energy, gradient, Hessian, zero modes) of an ``EndLoadedRod``: one program."""
    scene, phi, nbr = args
    val, gu, _, _, _, h, z = jax.device_get(rod_all(scene, f64(u), f64(phi), nbr))
    return float(val), gu, h, z
