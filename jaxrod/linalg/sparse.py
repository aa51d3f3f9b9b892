"""O(N) stability, Newton steps, eigenpairs and branch tangents from the rod's block structure.

Unlike the dense path (``jaxrod.linalg.stability``, O(n^3)), no n x n array is formed: the DOFs are
reordered node by node so that the local Hessian (``jaxrod.model.hessian``) is block-tridiagonal
(cyclic for closed rods), and it goes with the rank-one term ``w a a^T`` to the block LDL^T of
``jaxrod.linalg.banded``: O(N) per factorisation. Scope: scenes WITHOUT contact (pair blocks
couple distant nodes). The public functions (pure; the scene a pytree argument) are plain,
traceable compositions of separately jitted pieces, each compiled once per scene shape.

Variables: scaled DOFs u = q / scene.dof_scale and ``scene.scaled_energy``, vectors in q's layout
unless said otherwise. "Projected Hessian" means P H P on Z-perp, Z = ``scene.scaled_zero_modes``
(what ``jaxrod.linalg.stability.spectrum`` diagonalises; H itself for a clamped rod).

Gauge pinning (closed and free rods)
------------------------------------
H is singular along the 7 symmetry generators Z (translations, rotations, uniform twist shift).
Instead of projecting (a dense rank-7 term) we pin 7 DOFs P (3 coordinates of node 0, 2 of node
~N/3, 1 of node ~2N/3, the twist angle of edge 0): their rows and columns become the identity and
a is zeroed there. With Q an orthonormal basis of span(Z), the pins fix the gauge when Q_P (rows P
of Q) is invertible; the coordinates are chosen to maximise its smallest singular value s. Then
J v = v - Q Q_P^{-1} v_P maps Z-perp onto V_F = {v : v_P = 0} and, if H Z = 0, H_FF is congruent to
the projected Hessian (same inertia, Sylvester). The metric is distorted by up to
kappa = 1 + 1/s^2 (~N at worst), per direction 1 + |Q_P^{-1} v_P|^2 / |v|^2, O(1) for modes spread
over the rod.
"""
from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..aot import cached_jit
from . import banded
from ..model.hessian import local_products, pattern_of
from ..model.layout import layout_of
from .block_layout import BlockLayout, block_layout, from_blocks, to_blocks  # noqa: F401  (re-exported)
from .zero_modes import orthonormal_columns
from .tolerances import DEFAULT_NEGATIVE_TOL

__all__ = ["BlockLayout", "block_layout", "block_hessian", "gauge_pins", "inertia_at_equilibrium", "newton_direction",
           "lowest_eigenpairs_projected", "ProjectedEigenpairs", "tangent", "gradient_and_phi_derivative",
           "projected_count_below"]


def _check_scene(scene):
    if scene.has_term("contact"):
        raise ValueError("the block-tridiagonal path does not handle contact: use jaxrod.linalg.stability")


def _block_hessian(scene, u, phi, nbr):
    _check_scene(scene)
    lay = block_layout(scene)
    pat = pattern_of(layout_of(lay.kind, lay.n_nodes))
    hv, w, a = local_products(scene, u, phi, nbr, pat)
    flat = hv.ravel()

    def gather(src, ok):
        return jnp.where(jnp.asarray(ok), 0.5 * (flat[jnp.asarray(src[0])] + flat[jnp.asarray(src[1])]), 0.0)

    b, K = lay.block_size, lay.num_blocks
    dummy_eye = jnp.asarray(np.eye(b)[None] * lay.dummy.reshape(K, b)[:, :, None])
    diag = gather(lay.diag_src, lay.diag_ok) + dummy_eye
    off = gather(lay.off_src, lay.off_ok)
    return diag, off, to_blocks(lay, a), jnp.asarray(w, dtype=diag.dtype)


@jax.jit
def block_hessian(scene, u, phi, nbr):
    """The exact Hessian of ``scene.scaled_energy(u, phi, nbr)`` in block order, as
    block-tridiagonal + rank one:  H[perm, perm] = T + w a a^T  (dummies: identity in T). The local
    part is gathered from the coloured products of ``jaxrod.model.hessian`` (symmetrised like
    ``scaled_hessian``). Args: scene (no contact term), u (n,) scaled DOFs, phi, nbr. Returns: diag
    (K, b, b), off (K, b, b) (``banded`` conventions), a (n_pad,) the rank-one vector in block order
    (zero on dummies), w scalar."""
    return _block_hessian(scene, u, phi, nbr)


@cached_jit
def _gauge(scene, u, phi):
    """(Q (n, z) orthonormal symmetry generators, pins (7,) q indices or (0,), s)."""
    lay = block_layout(scene)
    Q = orthonormal_columns(scene.scaled_zero_modes(u, phi))
    if lay.pin_candidates.shape[0] == 0 or Q.shape[1] == 0:
        return Q, jnp.zeros((0,), jnp.int32), jnp.asarray(1.0, u.dtype)
    cand = jnp.asarray(lay.pin_candidates, jnp.int32)
    smin = jnp.linalg.svd(Q[cand], compute_uv=False)[:, -1]  # (m,) per candidate
    best = jnp.argmax(smin)
    return Q, cand[best], smin[best]


def gauge_pins(scene, u, phi):
    """The 7 DOFs pinned to fix the gauge of a closed (or free) rod at state u. Candidates: x, y, z
    of node 0, two coordinates of node N//3, one of node 2N//3, the twist angle of edge 0; of the 9
    choices, the one whose 7 x 7 restriction Q_P of the generators has the largest smallest singular
    value s. Returns (pins (7,) q indices, s); (0,) and 1.0 for a clamped rod. The gauge's metric
    distortion is kappa = 1 + 1/s^2; s = 0: the pins do not fix the gauge."""
    _, pins, s = _gauge(scene, u, phi)
    return pins, s


@functools.partial(jax.jit, static_argnames=("lay",))
def _pin(lay, diag, off, a, w, pins, shift):
    """The pinned system: rows and columns of the pins replaced by the identity in T, a zeroed
    there, and T shifted by shift * I. Returns (diag, off, U (n_pad, 1), c (1,), keep (n_pad,):
    0 on pins, 1 elsewhere)."""
    keep = jnp.ones(lay.n_pad, diag.dtype)
    if pins.shape[0] > 0:
        pin = jnp.zeros(lay.n_pad, diag.dtype).at[jnp.asarray(lay.position)[pins]].set(1.0)
        keep = 1.0 - pin
        K, b = lay.num_blocks, lay.block_size
        kb, pb = keep.reshape(K, b), pin.reshape(K, b)
        diag = diag * kb[:, :, None] * kb[:, None, :] + jnp.eye(b, dtype=diag.dtype)[None] * pb[:, :, None]
        off = off * kb[:, :, None] * jnp.roll(kb, -1, axis=0)[:, None, :]
        a = a * keep
    diag = diag + shift * jnp.eye(lay.block_size, dtype=diag.dtype)
    return diag, off, a[:, None], jnp.reshape(w, (1,)), keep


def inertia_at_equilibrium(scene, u, phi, nbr, tol=DEFAULT_NEGATIVE_TOL):
    """Number of eigenvalues of the projected Hessian below -tol at an equilibrium u: the dense
    ``stability(...).n_negative``, in O(N).

    Counts the negative eigenvalues of H_FF + tol I (the gauge-pinned Hessian, shifted; pins and
    dummies add only positive eigenvalues) from one block LDL^T and the Haynsworth correction for
    w a a^T. Through J (module docstring), I <= J^T J <= kappa I, so

        #{lambda(A) < -kappa tol}  <=  returned count  <=  #{lambda(A) < -tol},

    A the projected Hessian: exact unless an eigenvalue lies within ~kappa of -tol
    (``projected_count_below`` has no distortion), and exact for tol = 0 or a clamped rod. Off
    equilibrium, eigenvalues within O(|g| / s) of -tol may be counted differently.

    Args: scene (no contact), u (n,), phi, nbr, tol. Returns: int32 scalar (a JAX array). No
    pivoting across blocks: a pivot block singular to round-off spoils the count.
    """
    lay = block_layout(scene)
    diag, off, a, w = block_hessian(scene, u, phi, nbr)
    _, pins, _ = _gauge(scene, u, phi)
    diag, off, U, c, _ = _pin(lay, diag, off, a, w, pins, jnp.asarray(tol, diag.dtype))
    return banded.inertia(banded.factor(diag, off, cyclic=lay.cyclic), U, c)[0]


@functools.partial(jax.jit, static_argnames=("lay",))
def _rhs_to_blocks(lay, rhs, keep):
    return to_blocks(lay, rhs) * keep


@functools.partial(jax.jit, static_argnames=("lay",))
def _solution_from_blocks(lay, x, Q, keep=None):
    """Block order -> q order (zeroed where keep is 0: pinned entries come out at round-off level),
    then (if Q is not None) projected on Q-perp."""
    if keep is not None:
        x = x * (keep if x.ndim == 1 else keep[:, None])
    x = from_blocks(lay, x)
    if Q is not None and Q.shape[1] > 0:
        x = x - Q @ (Q.T @ x)
    return x


def _pinned_solve(lay, diag, off, a, w, pins, Q, rhs):
    """x (n,) in q order with x_P = 0 and H_FF x_F = rhs_F; then, if Q is not None, x projected
    on Q-perp. (Separately jitted pieces: ``banded`` is compiled once per shape for every caller.)"""
    diag, off, U, c, keep = _pin(lay, diag, off, a, w, pins, jnp.asarray(0.0, diag.dtype))
    fac = banded.factor(diag, off, cyclic=lay.cyclic)
    x = banded.solve(fac, _rhs_to_blocks(lay, rhs, keep), U, c)
    return _solution_from_blocks(lay, x, Q, keep)


def newton_direction(scene, u, phi, nbr, g):
    """The Newton step d (n,) (scaled DOFs, q order) for the gradient g (n,) of the scaled energy at
    u:  H_FF d_F = -g_F,  d_P = 0 on the gauge pins (nothing pinned for a clamped rod). The energy
    is invariant under the symmetries, so g is orthogonal to Z; at an equilibrium-like state the
    solutions of H d = -g are d0 + Z c, and the pinned one is the usual Newton step up to a symmetry
    motion. Away from equilibrium it is the Newton step restricted to the slice {u_P fixed}, whose
    critical points are equilibria, so u <- u + d converges (quadratically once close). No line
    search here. Costs one block factorisation and one solve, O(N)."""
    lay = block_layout(scene)
    diag, off, a, w = block_hessian(scene, u, phi, nbr)
    _, pins, _ = _gauge(scene, u, phi)
    return _pinned_solve(lay, diag, off, a, w, pins, None, -jnp.asarray(g))


@jax.jit
def gradient_and_phi_derivative(scene, u, phi, nbr):
    """(g, dg/dphi), both (n,): the gradient of ``scene.scaled_energy`` at (u, phi) and its
    derivative in phi (one forward-mode jvp through the gradient)."""
    phi = jnp.asarray(phi, dtype=u.dtype)
    grad = jax.grad(lambda uu, p: scene.scaled_energy(uu, p, nbr))
    return jax.jvp(lambda p: grad(u, p), (phi,), (jnp.ones_like(phi),))


def tangent(scene, u, phi, nbr):
    """The branch tangent du/dphi = -H^+ d(grad)/dphi (n,) (scaled DOFs, q order) at an equilibrium
    u, on Z-perp: the pinned solve (``newton_direction`` with g = d(grad)/dphi, by a jvp) projected
    on Z-perp = range(H), the minimum-norm solution (exact when H Z = 0; to O(|g|) for rotations)."""
    lay = block_layout(scene)
    diag, off, a, w = block_hessian(scene, u, phi, nbr)
    Q, pins, _ = _gauge(scene, u, phi)
    _, dg = gradient_and_phi_derivative(scene, u, phi, nbr)
    return _pinned_solve(lay, diag, off, a, w, pins, Q, -dg)


class ProjectedEigenpairs(NamedTuple):
    """values (k,) ascending; vectors (n, k) orthonormal, orthogonal to Z (scaled DOFs, q order);
    residuals (k,) ||A x - lambda x|| (A the projected Hessian); sigma: the shift used."""

    values: jax.Array
    vectors: jax.Array
    residuals: jax.Array
    sigma: jax.Array


def _norm_bound(diag, off, cyclic, a, w):
    """Upper bound on ||T + w a a^T||_2 (block-row sums of Frobenius norms + |w| |a|^2)."""
    K = diag.shape[0]
    if not cyclic:
        off = off.at[K - 1].set(0.0)
    fd = jnp.sqrt(jnp.sum(diag**2, axis=(1, 2)))
    fo = jnp.sqrt(jnp.sum(off**2, axis=(1, 2)))
    return jnp.max(fd + fo + jnp.roll(fo, 1)) + jnp.abs(w) * jnp.sum(a**2)


@functools.partial(jax.jit, static_argnames=("lay",))
def _eig_setup(lay, diag, off, a, w, Q):
    """(diag with dummies at 4 bound + 1, U, c, Zr (n_pad, z) generators in block order,
    Z (n_pad, z + n_dummy) with the dummies' unit columns, bound >= ||M||)."""
    K, b = lay.num_blocks, lay.block_size
    bound = _norm_bound(diag, off, lay.cyclic, a, w)
    dmask = jnp.asarray(np.eye(b)[None] * lay.dummy.reshape(K, b)[:, :, None])
    diag = diag + (4.0 * bound) * dmask
    Zr = to_blocks(lay, Q)
    dummies = np.nonzero(lay.dummy)[0]
    Zd = jnp.zeros((lay.n_pad, dummies.size), diag.dtype).at[dummies, np.arange(dummies.size)].set(1.0)
    return diag, a[:, None], jnp.reshape(w, (1,)), Zr, jnp.concatenate([Zr, Zd], axis=1), bound


@jax.jit
def _shifted(diag, s):
    return diag - s * jnp.eye(diag.shape[-1], dtype=diag.dtype)


@jax.jit
def _border_count(neg, Zr, Y):
    """neg(M - s) + #{eig(Zr^T (M - s)^{-1} Zr) > 0} - z, Y = (M - s)^{-1} Zr."""
    G = Zr.T @ Y
    return neg + jnp.sum(jnp.linalg.eigvalsh(0.5 * (G + G.T)) > 0) - Zr.shape[1]


def _projected_count(diag, off, cyclic, U, c, Zr, s):
    """#{eigenvalues of P M P on Zr-perp below s}, M = T + U diag(c) U^T, by Haynsworth on
    [[M - s, Zr], [Zr^T, 0]]: In(M - s) + In(-Zr^T (M - s)^{-1} Zr). One factorisation, one solve."""
    fac = banded.factor(_shifted(diag, s), off, cyclic=cyclic)
    neg = banded.inertia(fac, U, c)[0]
    if Zr.shape[1] == 0:
        return neg
    return _border_count(neg, Zr, banded.solve(fac, Zr, U, c))


_SIGMA_STEPS = 9
_SIGMA_RANGE = 12.5  # decades: s(t) spans about [-3 bound, 3 bound]


def _auto_sigma(diag, off, cyclic, U, c, Zr, bound):
    """A shift just below the lowest projected eigenvalue lambda_1, by Sylvester counts. Bisection
    on t for the count at s(t) = 2 delta sinh(t ln 10), delta = 1e-12 ||M|| (bound): a relative
    bracket on either side of 0, linear across [-delta, delta]. 9 counts bracket lambda_1 within a
    factor ~1.12; sigma = s_lo - (s_hi - s_lo) lies 1 to 2 bracket widths below it. (A fixed number
    of steps and jnp.where: traceable under jit.)"""
    delta = 1e-12 * bound
    s_of = lambda t: 2.0 * delta * jnp.sinh(t * jnp.log(10.0))  # noqa: E731
    lo = jnp.asarray(-_SIGMA_RANGE, diag.dtype)
    hi = jnp.asarray(_SIGMA_RANGE + 0.0371, diag.dtype)  # asymmetric: no midpoint lands on s = 0
    for _ in range(_SIGMA_STEPS):
        mid = 0.5 * (lo + hi)
        bad = _projected_count(diag, off, cyclic, U, c, Zr, s_of(mid)) > 0
        lo, hi = jnp.where(bad, lo, mid), jnp.where(bad, mid, hi)
    s_lo, s_hi = s_of(lo), s_of(hi)
    return 2.0 * s_lo - s_hi


def _sigma_below(diag, off, cyclic, U, c, Zr, bound, guess):
    """A shift below lambda_1 near an estimate ``guess`` of it (e.g. the previous continuation
    step's): s = guess - max(|guess| / 2, delta) (delta = 1e-12 ||M||, |s| >= delta), accepted
    if one Sylvester count shows no projected eigenvalue below s; otherwise ``_auto_sigma`` (9
    counts). One factorisation instead of nine along a smooth branch."""
    delta = 1e-12 * bound
    s = guess - jnp.maximum(0.5 * jnp.abs(guess), delta)
    s = jnp.where(jnp.abs(s) < delta, -delta, s)
    ok = jnp.isfinite(s) & (_projected_count(diag, off, cyclic, U, c, Zr, s) == 0)
    if bool(ok):
        return s
    return _auto_sigma(diag, off, cyclic, U, c, Zr, bound)


# ``lowest_eigenpairs_projected`` drives residuals below this fraction of (max lambda - sigma), but
# not below _EIG_TOL_FLOOR ||M||, about where round-off stops them.
_EIG_SPREAD_RTOL = 1e-2
_EIG_TOL_FLOOR = 2e-15


def lowest_eigenpairs_projected(scene, u, phi, nbr, k, sigma=None, iterations=200, tol=1e-12, block=None,
                                guess=None):
    """The k lowest eigenpairs of the projected Hessian (the first k of the dense
    ``jaxrod.linalg.stability.spectrum``, whose lifted zero modes sit at the top), in O(N) per step.
    ``banded.lowest_eigenpairs`` on the unpinned block Hessian T + w a a^T, Z the orthonormalised
    generators in block order plus a unit column per dummy DOF (dummies sit at 1 + 4 ||M|| on T's
    diagonal, so no shift makes them singular). sigma: the shift; None chooses it by Sylvester
    counts (``_auto_sigma``), or from one count below ``guess`` (``_sigma_below``). k, iterations,
    block static; iterations, tol, block as ``banded.lowest_eigenpairs``; outside a trace the
    iteration goes on until the residuals are also below 1e-2 (max lambda - sigma), down to 2e-15
    ||M||. Returns a :class:`ProjectedEigenpairs`; needs full-rank generators and T - sigma I
    regular."""
    _check_scene(scene)
    lay = block_layout(scene)
    diag, off, a, w = block_hessian(scene, u, phi, nbr)
    Q, _, _ = _gauge(scene, u, phi)
    diag, U, c, Zr, Z, bound = _eig_setup(lay, diag, off, a, w, Q)
    if sigma is None and guess is not None and math.isfinite(float(guess)):
        sigma = _sigma_below(diag, off, lay.cyclic, U, c, Zr, bound, jnp.asarray(float(guess), diag.dtype))
    elif sigma is None:
        sigma = _auto_sigma(diag, off, lay.cyclic, U, c, Zr, bound)
    sigma = jnp.asarray(sigma, diag.dtype)
    lam, X, res = banded.lowest_eigenpairs(diag, off, lay.cyclic, U, c, Z, k, sigma, iterations=iterations,
                                           tol=tol, block=block)
    if not isinstance(res, jax.core.Tracer):
        # tol is relative to ||M||, against which a long rod's wanted eigenvalues are tiny: go on,
        # from the vectors found, until the residuals are small against their spread.
        want = _EIG_SPREAD_RTOL * float(jnp.max(lam) - sigma)
        if want > 0.0 and float(jnp.max(res)) > want:
            n = X.shape[0]
            bound_m = float(banded._norm_bound(diag, off, lay.cyclic, banded._lowrank(U, c, n, diag.dtype)[0]))
            tighter = max(want / bound_m, _EIG_TOL_FLOOR)
            if tighter < tol:
                lam, X, res = banded.lowest_eigenpairs(diag, off, lay.cyclic, U, c, Z, k, sigma,
                                                       iterations=iterations, X0=X, tol=tighter, block=block)
    return ProjectedEigenpairs(lam, _solution_from_blocks(lay, X, None), res, sigma)


def projected_count_below(scene, u, phi, nbr, s):
    """Number of eigenvalues of the projected Hessian below s (any state, no gauge pinning).
    Sylvester and Haynsworth on [[M - s, Z], [Z^T, 0]] (as ``_projected_count``): one factorisation
    of the unpinned T - s I and one solve. Exact, with no metric distortion and no equilibrium
    needed; ``projected_count_below(..., -tol)`` is the dense ``n_negative``. T's exact null vectors
    make the pivots ~|s|, with relative error ~1e-16 ||M|| / |s|, so |s| must not be tiny against
    ||M||. Returns an int32 scalar."""
    _check_scene(scene)
    lay = block_layout(scene)
    diag, off, a, w = block_hessian(scene, u, phi, nbr)
    Q, _, _ = _gauge(scene, u, phi)
    diag, U, c, Zr, _, _ = _eig_setup(lay, diag, off, a, w, Q)
    return _projected_count(diag, off, lay.cyclic, U, c, Zr, jnp.asarray(s, diag.dtype))


# Eigenpairs computed beyond the tracked index or the negative count where k does not reach them
# (room for a degenerate pair crossing and the mode above it); continuation.critical_twist too.
EXTRA_PAIRS = 4
