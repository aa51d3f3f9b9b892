"""Stability by autodiff: Hessian, zero modes removed, lowest eigenpairs, negative count.

Everything works on ``scene.scaled_energy`` (``Scene.scaled_energy``), so eigenvalues are
dimensionless; the negative count does not depend on the variables (Sylvester). Zero modes
(translations, rotations, the uniform twist shift) are projected out and lifted to the top of the
spectrum, so none can be mistaken for a soft or unstable mode."""
from __future__ import annotations

import functools
from dataclasses import dataclass
import jax
import jax.numpy as jnp
import numpy as np

from ..aot import cached_jit
from ..model.hessian import eigenvalue_branch_derivative, project_out, scaled_hessian as structured_scaled_hessian
from ..validation import check_finite, refuse_knot
from .lapack import LAPACK_LOCK
from .options import backend_name
from .zero_modes import orthonormal_columns
from .tolerances import CONTACT_NEGATIVE_TOL, DEFAULT_NEGATIVE_TOL, scaled_negative_tol  # noqa: F401  (re-exported)
from .sliding import (CLEAN_SLIDE_FRACTION, SLIDING_FRACTION, band_shape_modes, shape_modes_in_band,  # noqa: F401
                      sliding_fields, sliding_fraction, split_slide, without_slide)

__all__ = ["Stability", "scaled_hessian", "spectrum", "stability", "eigenvalue_phi_derivative", "branch_analysis",
           "critical_twist_derivative", "DEFAULT_NEGATIVE_TOL", "sliding_fraction", "sliding_fields",
           "shape_modes_in_band", "band_shape_modes", "split_slide", "without_slide", "SLIDING_FRACTION"]


@dataclass(frozen=True)
class Stability:
    """Lowest eigenpairs of the Hessian with zero modes removed.

    eigenvalues: (k,) ascending, dimensionless (see module docstring); eigenvectors: (n, k) unit
    vectors in the scaled DOFs; n_negative: count of eigenvalues below -tol over the whole spectrum;
    n_zero_modes: number of symmetry directions removed; stable: n_negative == 0."""

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    n_negative: int
    n_zero_modes: int
    stable: bool
    tol: float

    def __repr__(self):
        lam = ", ".join(f"{v:.3e}" for v in self.eigenvalues[:6])
        return (
            f"Stability(stable={self.stable}, n_negative={self.n_negative}, "
            f"n_zero_modes={self.n_zero_modes}, lowest=[{lam}])"
        )


def scaled_hessian(scene, u, phi, nbr=None):
    """Exact Hessian (n, n) of scene.scaled_energy at scaled DOFs u (structured assembly, see
    ``jaxrod.model.hessian``; the neighbourhood is built at u when not given)."""
    if nbr is None:
        nbr = scene.neighbourhood(scene.from_scaled(u), phi)
    return structured_scaled_hessian(scene, u, phi, nbr)


# Eigenpairs computed by the continuation: the lowest LOWEST_COUNT of the projected Hessian, enough
# for the k <= 8 reported, the tracked mode and its degenerate partners.
LOWEST_COUNT = 24


# One LAPACK call at a time (``jaxrod.linalg.lapack.LAPACK_LOCK``).
_LAPACK_LOCK = LAPACK_LOCK


def _fix_signs(vec, xp=jnp):
    """Eigenvectors (n, m) with their largest-magnitude entry positive, whatever the LAPACK
    routine. xp: jax.numpy (traced) or numpy (host)."""
    big = xp.take_along_axis(vec, xp.argmax(xp.abs(vec), axis=0)[None, :], axis=0)
    return vec * xp.where(big < 0.0, -1.0, 1.0)


@functools.partial(jax.jit, static_argnames="m")
def _lowest_of_small(hp, tol, m):
    lam, vec = jnp.linalg.eigh(hp)
    return lam[:m], _fix_signs(vec[:, :m]), jnp.sum(lam < -tol)


def _lowest_of(hp, tol):
    """(lam (m,), vec (n, m), count of eigenvalues below -tol) of the symmetric hp (n, n): the m =
    LOWEST_COUNT lowest eigenpairs, ascending, each eigenvector's largest entry positive. For m much
    smaller than n, LAPACK's dsyevr with an index range on the host (JAX has no partial eigensolver
    on CPU), called outside jit: ``jax.pure_callback`` from two threads deadlocked. The count comes
    from the m lowest, unless all are below -tol (then the whole spectrum). Otherwise (2 m >= n) the
    full ``eigh``, jitted."""
    n = hp.shape[0]
    m = min(LOWEST_COUNT, n)
    if 2 * m >= n:
        return _lowest_of_small(hp, tol, m)
    from .lapack import lowest_eigenpairs

    h = np.asarray(hp)
    with _LAPACK_LOCK:
        lam, vec = lowest_eigenpairs(h, m)  # scipy's dsyevr, without holding the GIL
    vec = _fix_signs(vec, np)
    neg = int(np.sum(lam < -tol))
    if neg == m:
        with _LAPACK_LOCK:
            neg = int(np.sum(np.linalg.eigvalsh(h) < -tol))
    return lam, vec, neg


# The analyses below are Python compositions of separately jitted pieces, so that each heavy
# program (``scene_linearisation``, ``scene_bilinear_gradient``) is compiled once per scene shape
# and shared by every analysis and a knot's bifurcation problem.
@cached_jit
def _scene_linearisation(scene, u, phi, nbr):
    grad = jax.grad(scene.scaled_energy)
    g, g_phi = jax.jvp(lambda p: grad(u, p, nbr), (phi,), (jnp.ones_like(phi),))
    return g, structured_scaled_hessian(scene, u, phi, nbr), g_phi


@cached_jit
def _scene_bilinear_gradient(scene, u, phi, nbr, a, c, t):
    def contracted(x, p):
        return jnp.dot(a, jax.jvp(lambda y, r: jax.grad(scene.scaled_energy)(y, r, nbr), (x, p), (c, t))[1])

    return jax.grad(contracted, argnums=(0, 1))(u, phi)


def _host_vector(v):
    return np.asarray(v, dtype=float)


def scene_linearisation(scene, u, phi, nbr=None):
    """(g (n,), H (n, n), g_phi (n,)) of ``scene.scaled_energy(u, phi, nbr)`` at the scaled DOFs u:
    its gradient, its exact structured Hessian (``jaxrod.model.hessian.scaled_hessian``) and the
    gradient's derivative in phi; one compiled program per scene shape (u, phi passed as host values)."""
    return _scene_linearisation(scene, _host_vector(u), float(phi), nbr)


def scene_bilinear_gradient(scene, u, phi, nbr, a, c, t):
    """((n,), scalar): the gradient in (u, phi) of a^T (H(u, phi) c + t g_phi(u, phi)), H and g_phi
    as in ``scene_linearisation``, a and c (n,) fixed: third derivatives of the energy contracted
    with fixed vectors, by reverse mode over a jvp of the gradient (O(n), exact)."""
    return _scene_bilinear_gradient(scene, _host_vector(u), float(phi), nbr, _host_vector(a), _host_vector(c), float(t))


@cached_jit
def _zero_mode_basis(scene, u, phi):
    z = orthonormal_columns(scene.scaled_zero_modes(u, phi))
    return z, jnp.sum(jnp.any(z != 0.0, axis=0))


def _projected(scene, u, phi, nbr):
    """(hp (n, n): H with the zero modes projected out and lifted to the top, z (n, k) their
    orthonormal basis, n_zero, g_phi (n,) the gradient's phi-derivative), on the host."""
    _, h, g_phi = scene_linearisation(scene, u, phi, nbr)
    z, n_zero = _zero_mode_basis(scene, _host_vector(u), float(phi))
    z = np.asarray(z)
    return project_out(np.asarray(h), z, xp=np), z, int(n_zero), np.asarray(g_phi)


def _projected_hessian(scene, u, phi, nbr):
    """(H projected and lifted as in ``_projected``, z (n, k), n_zero)."""
    return _projected(scene, u, phi, nbr)[:3]


def _lowest_spectrum(scene, u, phi, nbr, tol):
    """(lam (m,), vec (n, m), n_zero, n_negative): the lowest eigenpairs of the projected Hessian
    and the count of its eigenvalues below -tol."""
    hp, _, n_zero = _projected_hessian(scene, u, phi, nbr)
    lam, vec, n_neg = _lowest_of(hp, tol)
    return lam, vec, n_zero, n_neg


_eigh = jax.jit(jnp.linalg.eigh)


def _spectrum(scene, u, phi, nbr):
    hp, _, n_zero = _projected_hessian(scene, u, phi, nbr)
    lam, vec = _eigh(hp)
    return lam, vec, n_zero


def spectrum(scene, u, phi, nbr=None):
    """Full spectrum with zero modes removed: (eigenvalues (n,), eigenvectors (n, n), n_zero),
    ascending, the n_zero symmetry directions lifted to the top."""
    if nbr is None:
        nbr = scene.neighbourhood(scene.from_scaled(u), phi)
    return _spectrum(scene, u, phi, nbr)


def stability(scene, q, phi, k=8, tol=DEFAULT_NEGATIVE_TOL, nbr=None, linear_algebra="auto"):
    """Stability of the state q (physical DOFs) at imposed twist phi: a ``Stability`` (the k lowest
    eigenpairs, zero modes removed, and the count of eigenvalues below -tol). linear_algebra: a
    backend name (``jaxrod.linalg.options.backend_name``): "sparse" (O(n),
    ``jaxrod.linalg.sparse_contact``) where chosen, else the n x n projected Hessian."""
    from . import sparse_contact

    phi = check_finite("phi", phi)
    u = scene.to_scaled(np.asarray(q, dtype=float))
    if nbr is None:
        nbr = scene.neighbourhood(q, phi)
    if backend_name(scene, linear_algebra, offered=("dense", "sparse"))[0] == "sparse":
        n_neg, lam, vec = sparse_contact.contact_spectrum(scene, q, phi, k=k, tol=tol, nbr=nbr)
        return _stability_from_lowest(lam, vec, int(scene.n_zero_modes), n_neg, k, tol)
    lam, vec, n_zero, n_neg = _lowest_spectrum(scene, u, phi, nbr, tol)
    return _stability_from_lowest(np.asarray(lam), np.asarray(vec), int(n_zero), int(n_neg), k, tol)


def _pinv_motion(lam, vec, skip):
    """du(dg) = -H^+ dg over a full eigen-decomposition, the flagged directions left out."""
    safe = jnp.where(skip, 1.0, lam)
    return lambda dg: -vec @ jnp.where(skip, 0.0, (vec.T @ dg) / safe)


@jax.jit
def _branch_sensitivities(scene, u, phi, v, lam, vec, skip, dscene, dphi, nbr):
    """``_branch_motion_sensitivities`` with du* from a full eigen-decomposition (lam, vec)."""
    return _branch_motion_sensitivities(scene, u, phi, v, _pinv_motion(lam, vec, skip), dscene, dphi, nbr)


def _branch_motion_sensitivities(scene, u, phi, v, motion, dscene, dphi, nbr):
    """(d lambda, du*): the derivative of the eigenvalue v^T H v along the equilibrium branch
    u*(scene, phi) in the direction (dscene, dphi) of the scene's parameters (a pytree tangent) and
    of phi: v^T (dH) v with the branch's own motion du* = -H^+ d(grad), the pseudo-inverse over the
    eigenvectors not flagged in ``skip`` (zero modes, the critical mode). Third derivatives by
    nested forward-mode jvps (no third-order tensor)."""
    f = lambda uu, sc, pp: sc.scaled_energy(uu, pp, nbr)  # noqa: E731
    dg = jax.jvp(lambda sc, pp: jax.grad(f)(u, sc, pp), (scene, phi), (dscene, dphi))[1]
    du = motion(dg)

    def vhv(uu, sc, pp):
        first = lambda w: jax.jvp(lambda y: f(y, sc, pp), (w,), (v,))[1]  # noqa: E731
        return jax.jvp(first, (uu,), (v,))[1]

    dlam = jax.jvp(vhv, (u, scene, phi), (du, dscene, dphi))[1]
    return dlam, du


def _zero_tangent(scene):
    """A zero tangent for every leaf of the scene (integer leaves, e.g. contact pair indices,
    take JAX's float0 zeros, as jvp requires)."""

    def zero(a):
        a = jnp.asarray(a)
        if jnp.issubdtype(a.dtype, jnp.integer) or a.dtype == jnp.bool_:
            return np.zeros(a.shape, dtype=jax.dtypes.float0)
        return jnp.zeros_like(a)

    return jax.tree_util.tree_map(zero, scene)


def _skip_mask(lam, n_zero, index, cluster_rtol, pinv_tol=0.0, xp=jnp):
    """Eigen-directions left out of the branch pseudo-inverse: the cluster of the tracked
    eigenvalue (degenerate partners included), the lifted zero modes at the top, and near-zero
    modes |lambda| <= pinv_tol (e.g. strands sliding along each other in a loose knot). xp:
    jax.numpy (traced) or numpy (host)."""
    n = lam.shape[0]
    lam_i = lam[index]
    scale = xp.maximum(xp.abs(lam_i), 1e-12)
    return (
        (xp.abs(lam - lam_i) <= cluster_rtol * scale + 1e-14)
        | (xp.arange(n) >= n - n_zero)
        | (xp.abs(lam) <= pinv_tol)
    )


def _branch_analysis(scene, u, phi, index, ref, cluster_rtol, pinv_tol, nbr, tol):
    hp, z, n_zero, g_phi = _projected(scene, u, phi, nbr)
    lam, vec, n_neg = _lowest_of(hp, tol)
    dlam, du, index = _branch_tangent(scene, u, phi, index, ref, cluster_rtol, pinv_tol, nbr, hp, z, n_zero, lam, vec,
                                      g_phi)
    return lam, vec, n_zero, n_neg, dlam, du, index


def _tangent_solve(hp, z, n_zero, lam, vec, index, ref, cluster_rtol, pinv_tol, g_phi):
    """(du (n,), index, v (n,)): the tracked mode (by index, or by overlap with ref) and the
    branch tangent du = -H^+ g_phi from the lowest eigenpairs only: the flagged directions and the
    zero modes are removed from g_phi and the flagged eigenvalues moved to the top (deflation), so
    one solve avoids dividing by a near-zero eigenvalue. Cholesky where the deflated matrix is
    positive definite, else LU (host)."""
    import scipy.linalg

    from .lapack import cholesky_solve

    m = lam.shape[0]
    # Lifted zero modes (present when the subset reaches the top of a small spectrum) are never tracked.
    physical = np.arange(m) < hp.shape[0] - n_zero
    # With a reference vector, follow the mode by eigenvector overlap (robust to reordering).
    ref = np.asarray(ref, dtype=float)
    if np.any(ref != 0.0):
        index = int(np.argmax(np.where(physical, np.abs(vec.T @ ref), -1.0)))
    index = int(index)
    skip = _skip_mask(lam, 0, index, cluster_rtol, pinv_tol, xp=np) | ~physical
    top = float(np.max(np.abs(np.diag(hp)))) + 1.0
    vs = vec[:, skip]
    h_def = hp + (vs * (top - lam[skip])[None, :]) @ vs.T
    b = g_phi - z @ (z.T @ g_phi)
    b = b - vs @ (vs.T @ b)
    with _LAPACK_LOCK:
        try:
            du = -cholesky_solve(h_def, b)  # scipy's dpotrf/dpotrs, without holding the GIL
        except np.linalg.LinAlgError:  # indefinite: an unstable state's other negative modes
            du = -scipy.linalg.lu_solve(scipy.linalg.lu_factor(h_def, check_finite=False), b, check_finite=False)
    return du, index, vec[:, index]


def _branch_tangent(scene, u, phi, index, ref, cluster_rtol, pinv_tol, nbr, hp, z, n_zero, lam, vec, g_phi):
    """The tracked mode (by index, or by overlap with ref), its eigenvalue's phi-derivative along
    the branch and the branch tangent du/dphi (deflated solve), from the lowest eigenpairs and the
    gradient's phi-derivative g_phi. -> (dlam, du (n,), index). d lambda = v^T (dH) v along (du, 1),
    by ``model.hessian.eigenvalue_branch_derivative``: forward mode only, the sparse analyses'
    program, about half the tracing and compiling of the reverse-mode ``scene_bilinear_gradient``."""
    lam, vec = np.asarray(lam), np.asarray(vec)
    du, index, v = _tangent_solve(np.asarray(hp), np.asarray(z), int(n_zero), lam, vec, index, ref, cluster_rtol,
                                  pinv_tol, np.asarray(g_phi))
    dlam = eigenvalue_branch_derivative(scene, jnp.asarray(u, jnp.float64), jnp.asarray(phi, jnp.float64),
                                        jnp.asarray(v), jnp.asarray(du), nbr)
    return float(dlam), du, index


def _stability_from_lowest(lam, vec, n_zero, n_negative, k, tol):
    """A ``Stability`` from the lowest eigenpairs of the projected Hessian (lifted zero modes, if
    the range reached them, dropped) and the negative count."""
    n_physical = vec.shape[0] - n_zero
    lam, vec = lam[:n_physical], vec[:, :n_physical]
    k = min(k, lam.shape[0])
    return Stability(
        eigenvalues=lam[:k], eigenvectors=vec[:, :k], n_negative=n_negative,
        n_zero_modes=n_zero, stable=n_negative == 0, tol=tol,
    )


def branch_analysis(scene, q, phi, index, k=8, tol=DEFAULT_NEGATIVE_TOL, cluster_rtol=1e-4, ref=None, pinv_tol=0.0,
                    nbr=None, guess=None):
    """One Hessian and one eigen-decomposition at an equilibrium q, giving everything a continuation
    step needs: its ``Stability``; eigenvalue number ``index`` (ascending, zero modes removed; or,
    given ``ref`` (scaled DOFs), the mode overlapping it most), its phi-derivative along the branch
    and eigenvector (scaled DOFs); and the branch tangent dq/dphi (physical DOFs), modes |lambda| <=
    pinv_tol left out. ``guess``: for signature compatibility with ``sparse_branch_analysis``.
    Returns (stability, lam, dlam_dphi, v, dq_dphi)."""
    u = scene.to_scaled(np.asarray(q, dtype=float))
    ref = jnp.zeros_like(u) if ref is None else jnp.asarray(ref)
    if nbr is None:
        nbr = scene.neighbourhood(q, phi)
    if not 0 <= int(index) < min(LOWEST_COUNT, u.shape[0]):
        raise ValueError(f"index must be in 0..{min(LOWEST_COUNT, u.shape[0]) - 1}, got {index!r}")
    lam, vec, n_zero, n_neg, dlam, du, index = _branch_analysis(scene, u, phi, index, ref, cluster_rtol, pinv_tol,
                                                                nbr, tol)
    lam, vec, n_zero, index = np.asarray(lam), np.asarray(vec), int(n_zero), int(index)
    stab = _stability_from_lowest(lam, vec, n_zero, int(n_neg), k, tol)
    return stab, float(lam[index]), float(dlam), vec[:, index], np.asarray(scene.from_scaled(du))


def eigenvalue_phi_derivative(scene, q, phi, index, cluster_rtol=1e-4, nbr=None):
    """Eigenvalue number ``index`` (ascending, zero modes removed) of the Hessian at an equilibrium
    q, its derivative along the branch in phi (Hellmann-Feynman plus the branch's own motion, by
    forward-mode autodiff), its eigenvector (scaled DOFs) and the branch tangent dq/dphi (physical
    DOFs). Returns (lam, dlam_dphi, v, dq_dphi)."""
    _, lam, dlam, v, dq = branch_analysis(scene, q, phi, index, cluster_rtol=cluster_rtol, nbr=nbr)
    return lam, dlam, v, dq


def _parameter_tangent(scene, parameter):
    """The scene's tangent (a pytree like the scene) along one continuous parameter: a name in
    ``scene.PARAMETERS`` (changed as ``scene.with_params`` changes it), or a callable ``scene ->
    tangent scene``."""
    if callable(parameter):
        return parameter(scene)
    names = tuple(getattr(scene, "PARAMETERS", ()))
    if parameter not in names:
        raise ValueError(f"parameter must be one of {', '.join(names)} or a callable scene -> tangent scene, "
                         f"got {parameter!r}")
    value = jnp.asarray(scene.parameter(parameter), dtype=float)
    return jax.jvp(lambda t: scene.with_params(**{parameter: value + t}), (jnp.zeros(()),), (jnp.ones(()),))[1]


def critical_twist_derivative(scene, critical, parameter, cluster_rtol=1e-4, pinv_tol=0.0):
    """d phi* / d(parameter) at a critical point, by the implicit function theorem on lambda(q*(phi,
    p), phi, p) = 0:  d phi*/dp = -(d lambda/dp) / (d lambda/d phi). critical: a ``CriticalPoint``
    of ``scene``; parameter: a name in ``scene.PARAMETERS`` ('B', 'C', 'EA', 'D', 'nu',
    'contact_stiffness', changed as ``scene.with_params`` changes it: nu sets C = B/(1+nu) at fixed
    B) or a callable ``scene -> tangent scene`` giving any direction in the scene's parameters.
    Refuses knots (``jaxrod.validation.refuse_knot``)."""
    refuse_knot(scene, "critical_twist_derivative")
    dscene = _parameter_tangent(scene, parameter)
    eq = critical.equilibrium
    u = scene.to_scaled(np.asarray(eq.q, dtype=float))
    nbr = eq.neighbourhood if eq.neighbourhood is not None else scene.neighbourhood(eq.q, eq.phi)
    lam, vec, n_zero = spectrum(scene, u, eq.phi, nbr)
    n = lam.shape[0]
    overlap = np.abs(np.asarray(vec).T @ np.asarray(critical.mode))
    overlap[n - int(n_zero):] = -1.0
    index = int(np.argmax(overlap))  # the critical mode itself (not a near-zero sliding mode)
    skip = _skip_mask(lam, n_zero, index, cluster_rtol, pinv_tol)
    v = vec[:, index]
    dlam_dp, _ = _branch_sensitivities(scene, u, eq.phi, v, lam, vec, skip, dscene, jnp.asarray(0.0), nbr)
    dlam_dphi, _ = _branch_sensitivities(scene, u, eq.phi, v, lam, vec, skip, _zero_tangent(scene), jnp.asarray(1.0),
                                         nbr)
    return -float(dlam_dp) / float(dlam_dphi)
