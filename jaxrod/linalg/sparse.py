"""O(N) stability, Newton steps, eigenpairs and branch tangents from the rod's block structure.

The dense path (``jaxrod.linalg.stability``) assembles the n x n Hessian and calls ``eigh``: O(n^3).
This module never forms an n x n array. It reorders the DOFs node by node, so that the local part
of the Hessian (``jaxrod.model.hessian``: everything except the rank-one holonomy term and contact)
becomes block-tridiagonal (cyclic for closed rods), and hands it, with the rank-one term
``w a a^T``, to the block LDL^T of ``jaxrod.linalg.banded``: O(N) per factorisation.

Scope: scenes WITHOUT the "contact" term (contact pair blocks couple distant nodes), of kind
``ClosedRod``, ``ClampedRod`` (and ``FreeRod``).

Public functions (all pure; the scene is a pytree argument, vectors are JAX arrays):

* :func:`block_layout` (numpy, cached): the node-interleaved block order of the DOFs.
* :func:`block_hessian`: (diag, off, a, w), the Hessian of the scaled energy in that order.
* :func:`gauge_pins`: the 7 DOFs pinned to fix the symmetries of a closed (or free) rod.
* :func:`inertia_at_equilibrium`: number of eigenvalues of the projected Hessian below -tol.
* :func:`projected_count_below`: the same count without gauge pinning (bordered inertia), exact
  at any state but less well conditioned for shifts very close to 0.
* :func:`newton_direction`: the Newton step with the gauge pinned.
* :func:`lowest_eigenpairs_projected`: the k lowest eigenpairs of the projected Hessian.
* :func:`tangent`: the branch tangent du/dphi.
* :func:`gradient_and_phi_derivative`: the gradient of the scaled energy and its phi derivative.

Compilation: the energy-heavy pieces (``block_hessian``, ``gradient_and_phi_derivative``) and the
block linear algebra are separately jitted, so each is compiled once per scene shape and shared by
all the public functions; the public functions are plain compositions of them (still pure, and
traceable inside a user's ``jax.jit``).

Variables: everything is in the scaled DOFs u = q / scene.dof_scale and the scaled energy
``scene.scaled_energy`` (as ``jaxrod.linalg.stability``), vectors in q's layout unless said otherwise.
"Projected Hessian" means P H P on the orthogonal complement Z-perp of the symmetry generators
Z = ``scene.scaled_zero_modes`` (what ``jaxrod.linalg.stability.spectrum`` diagonalises; for a clamped
rod Z is empty and it is H itself).

Gauge pinning (closed and free rods)
------------------------------------
H is singular along the 7 symmetry generators Z (3 translations, 3 rotations, the uniform twist
shift): at an equilibrium H Z = 0 exactly for translations and the twist shift, and H z = Omega g
(the rotated gradient, O(|g|)) for a rotation. Instead of projecting (a dense rank-7 term) we fix
the gauge: 7 DOFs P (3 coordinates of node 0, 2 of node ~N/3, 1 of node ~2N/3, the twist angle
of edge 0) are pinned, i.e. their rows and columns are replaced by the identity and the rank-one
vector a is zeroed there. Write F for the other DOFs and V_F = {v : v_P = 0}. With Q an
orthonormal basis of span(Z), V_F + span(Z) = R^n exactly when the 7 x 7 matrix Q_P (rows P of Q)
is invertible; the coordinate components are chosen (from the current geometry) to maximise its
smallest singular value s. Then J v = v - Q Q_P^{-1} v_P maps Z-perp one-to-one onto V_F, and
if H Z = 0, v^T H v = (Jv)^T H (Jv): H_FF is congruent to the projected Hessian, so it has the
same inertia (Sylvester), and solving with H_FF is solving with H modulo the symmetries.
The metric of the two is not the same: for v in Z-perp, |v|^2 <= |Jv|^2 <= kappa |v|^2 with
kappa = 1 + 1/s^2 (the *metric distortion* of the gauge). The translations are spread evenly over
the N nodes, so s <= ~1/sqrt(N) whatever 7 DOFs are pinned (s = 1/sqrt(N) for a ring): kappa ~ N
in the worst case. For a given direction v the factor is 1 + |Q_P^{-1} v_P|^2 / |v|^2, which is
O(1) for modes spread over the rod (|v_P| ~ sqrt(7/n) |v|); only a mode concentrated on the pinned
DOFs sees the full kappa.
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

__all__ = [
    "BlockLayout",
    "block_layout",
    "block_hessian",
    "gauge_pins",
    "inertia_at_equilibrium",
    "newton_direction",
    "lowest_eigenpairs_projected",
    "ProjectedEigenpairs",
    "tangent",
    "gradient_and_phi_derivative",
    "projected_count_below",
]


# ------------------------------------------------------------------------------------------------
# Hessian in blocks (the block order: ``jaxrod.linalg.block_layout``)


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
    block-tridiagonal + rank one:  H[perm, perm] = T + w a a^T  (dummies: identity in T).

    The local part comes straight from the coloured Hessian-vector products of
    ``jaxrod.model.hessian`` (about 36 of them whatever N), each entry gathered into its block
    (symmetrised: (H[r, c] + H[c, r]) / 2, like ``scaled_hessian``); no n x n array is formed.

    Args: scene (no contact term), u (n,) scaled DOFs, phi, nbr (``scene.neighbourhood``).
    Returns: diag (K, b, b), off (K, b, b) (``jaxrod.linalg.banded`` conventions, cyclic for closed rods),
    a (n_pad,) the rank-one vector in block order (zero on dummies), w scalar.
    """
    return _block_hessian(scene, u, phi, nbr)


# ------------------------------------------------------------------------------------------------
# gauge


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
    """The 7 DOFs pinned to fix the gauge of a closed (or free) rod at state u.

    Candidates: x, y, z of node 0, two coordinates of node N//3, one of node 2N//3, and the
    twist angle of edge 0; among the 9 choices of coordinates, the one whose 7 x 7 restriction
    Q_P of the orthonormalised generators has the largest smallest singular value s.
    Returns (pins (7,) q indices, s); (0,) and 1.0 for a clamped rod. The metric distortion of
    the gauge (module docstring) is kappa = 1 + 1/s^2; s = 0 means the pins do not fix the gauge
    (degenerate geometry, e.g. generators of lower rank).
    """
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


# ------------------------------------------------------------------------------------------------
# inertia, Newton, tangent


def inertia_at_equilibrium(scene, u, phi, nbr, tol=DEFAULT_NEGATIVE_TOL):
    """Number of eigenvalues of the projected Hessian below -tol at an equilibrium u: the dense
    ``stability(...).n_negative``, in O(N).

    Computed as the number of negative eigenvalues of H_FF + tol I (the gauge-pinned Hessian,
    shifted; pins and dummies are identity rows, so they add only positive eigenvalues), from one
    block LDL^T of T + tol I and the Haynsworth correction for w a a^T (``banded.inertia``).

    Why this is the projected count: with J as in the module docstring, (H_FF + tol I) restricted
    to V_F is congruent (through J) to  A + tol J^T J  on Z-perp, A the projected Hessian, and
    I <= J^T J <= kappa I (kappa = 1 + 1/s^2, s from ``gauge_pins``). Since the negative count
    can only drop when the matrix grows,

        #{lambda(A) < -kappa tol}  <=  returned count  <=  #{lambda(A) < -tol},

    so it equals the projected count #{lambda(A) < -tol} unless an eigenvalue of A lies in
    [-kappa tol, -tol): within a factor ~kappa (the metric distortion) of -tol (per eigenvector
    the relevant factor is 1 + |Q_P^{-1} v_P|^2/|v|^2, O(1) for modes spread over the rod even
    though kappa ~ N; ``projected_count_below`` gives the count without distortion). Without the
    shift (tol = 0) the counts agree exactly (Sylvester). Off equilibrium the rotations are
    null vectors only up to H z = Omega g, which moves the pinned eigenvalues by O(|g| / s):
    eigenvalues within that of -tol may also be counted differently. For a clamped rod nothing
    is pinned and the count is exactly #{lambda(H) < -tol} (up to round-off).

    Args: scene (no contact), u (n,), phi, nbr, tol. Returns: int32 scalar (a JAX array).
    Caveat (``jaxrod.linalg.banded``): T + tol I is factorised without pivoting across blocks; a pivot
    block that is singular to round-off (an isolated accident of the state) spoils the count.
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
    """Block order -> q order (zeroed where keep is 0: the pinned entries come out of the block
    solve at round-off level, ~1e-13, not exactly 0), then (if Q is not None) projected on
    Q-perp."""
    if keep is not None:
        x = x * (keep if x.ndim == 1 else keep[:, None])
    x = from_blocks(lay, x)
    if Q is not None and Q.shape[1] > 0:
        x = x - Q @ (Q.T @ x)
    return x


def _pinned_solve(lay, diag, off, a, w, pins, Q, rhs):
    """x (n,) in q order with x_P = 0 and H_FF x_F = rhs_F; then, if Q is not None, x projected
    on Q-perp. (Composed of separately jitted pieces, so that ``banded.factor`` and
    ``banded.solve`` are compiled once per shape for every caller.)"""
    diag, off, U, c, keep = _pin(lay, diag, off, a, w, pins, jnp.asarray(0.0, diag.dtype))
    fac = banded.factor(diag, off, cyclic=lay.cyclic)
    x = banded.solve(fac, _rhs_to_blocks(lay, rhs, keep), U, c)
    return _solution_from_blocks(lay, x, Q, keep)


def newton_direction(scene, u, phi, nbr, g):
    """The Newton step d (n,) (scaled DOFs, q order) for the gradient g (n,) of the scaled
    energy at u:  H_FF d_F = -g_F,  d_P = 0 on the gauge pins (nothing pinned for a clamped rod).

    Why the pinned system is the right one: the energy is exactly invariant under the symmetries,
    so g . z = 0 for every generator z (the derivative of the energy along a symmetry). At an
    equilibrium-like state (H Z = 0) g is then in range(H) and the solutions of H d = -g are
    d0 + Z c for all c; exactly one of them vanishes on the pins (Q_P invertible), and it is the
    pinned solution: the usual Newton step up to a symmetry motion. Away from equilibrium it is
    the Newton step of the energy restricted to the slice {u_P fixed}, which meets every orbit
    of the symmetry group near u once; a zero of the restricted gradient is a zero of the full
    one (g_F = 0 and Z^T g = 0 give Q_P^T g_P = 0, so g_P = 0). Iterating u <- u + d therefore
    converges to an equilibrium, quadratically once close; the pinned DOFs stay where they are
    as long as the same pins are chosen (they are re-chosen from the geometry at every call).
    The step has large symmetry components (it moves the state along the orbit so that the pins
    stay fixed); they are harmless. Measured: from a random 3e-3 perturbation of a Michell ring
    (N = 24, stiff stretching, EA l^2/B ~ 1e4) about 8 undamped steps to |g| < 1e-11, like the
    dense undamped Newton; no line search here -- add one (e.g. on |g|) far from equilibrium.
    Costs one block factorisation and one solve, O(N). (g: e.g. from
    ``gradient_and_phi_derivative``.)
    """
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
    """The branch tangent du/dphi (n,) (scaled DOFs, q order) at an equilibrium u, on Z-perp:

        du/dphi = -H^+ d(grad)/dphi,

    d(grad)/dphi by a forward-mode jvp of the gradient in phi. Computed as the pinned solve
    (``newton_direction`` with g = d(grad)/dphi) followed by the projection on Z-perp: since
    g(u, phi) . z(u) = 0 for every phi, d(grad)/dphi is orthogonal to Z as well, so the pinned
    solution is a solution of H x = -d(grad)/dphi, and its projection on Z-perp = range(H) is the
    minimum-norm one, -H^+ d(grad)/dphi (exact when H Z = 0; to O(|g|) for the rotations).
    (``jaxrod.linalg.stability.branch_analysis`` returns the same in physical DOFs from the dense
    eigen-decomposition, except that it also leaves out the tracked mode's cluster.)
    """
    lay = block_layout(scene)
    diag, off, a, w = block_hessian(scene, u, phi, nbr)
    Q, pins, _ = _gauge(scene, u, phi)
    _, dg = gradient_and_phi_derivative(scene, u, phi, nbr)
    return _pinned_solve(lay, diag, off, a, w, pins, Q, -dg)


# ------------------------------------------------------------------------------------------------
# eigenpairs


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
    """#{eigenvalues of P M P on Zr-perp below s}, M = T + U diag(c) U^T: from the bordered
    matrix B = [[M - s, Zr], [Zr^T, 0]], In(B) = In(P(M - s)P on Zr-perp) + (z, z), and
    Haynsworth In(B) = In(M - s) + In(-Zr^T (M - s)^{-1} Zr). One factorisation of T - s I, one
    solve with z columns."""
    fac = banded.factor(_shifted(diag, s), off, cyclic=cyclic)
    neg = banded.inertia(fac, U, c)[0]
    if Zr.shape[1] == 0:
        return neg
    return _border_count(neg, Zr, banded.solve(fac, Zr, U, c))


_SIGMA_STEPS = 9
_SIGMA_RANGE = 12.5  # decades: s(t) spans about [-3 bound, 3 bound]


def _auto_sigma(diag, off, cyclic, U, c, Zr, bound):
    """A shift just below the lowest projected eigenvalue lambda_1, by Sylvester counts.

    Bisection on t for the count at s(t) = 2 delta sinh(t ln 10), delta = 1e-12 ||M|| (bound):
    s is ~ -+delta 10^|t| away from 0 (so the bracket is relative, on either side of 0) and
    linear across [-delta, delta]. 9 counts bracket lambda_1 in [s_lo, s_hi) with s_hi/s_lo
    within a factor 10^(25/512) ~ 1.12 (or |s_hi - s_lo| ~ delta near 0); the shift
    sigma = s_lo - (s_hi - s_lo) lies below lambda_1 by 1 to 2 bracket widths: close enough for
    fast shift-invert convergence, far enough for T - sigma I and A - sigma to be regular.
    (A fixed number of steps and jnp.where: no value leaves the device, traceable under jit.)
    """
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


# ``lowest_eigenpairs_projected``: residuals are driven below this fraction of the wanted
# eigenvalues' distance from the shift (max lambda - sigma), not only below tol ||M||; but not
# below _EIG_TOL_FLOOR ||M||, about where round-off stops them (measured ~3e-16 ||M||).
_EIG_SPREAD_RTOL = 1e-2
_EIG_TOL_FLOOR = 2e-15


def lowest_eigenpairs_projected(scene, u, phi, nbr, k, sigma=None, iterations=200, tol=1e-12, block=None,
                                guess=None):
    """The k lowest eigenpairs of the projected Hessian (the first k of the dense
    ``jaxrod.linalg.stability.spectrum``, whose lifted zero modes sit at the top), in O(N) per step.

    ``banded.lowest_eigenpairs`` (shift-invert subspace iteration, Rayleigh-Ritz) on the block
    Hessian T + w a a^T (unpinned), with Z = the orthonormalised symmetry generators in block order
    plus one unit column per dummy DOF (so the dummies' eigenvalue never enters). Dummies sit at
    1 + 4 ||M|| on T's diagonal, so that no shift used here makes them singular.

    sigma: the shift (below the wanted eigenvalues); None chooses it automatically just below the
    lowest eigenvalue from 9 Sylvester counts of the projected matrix (see ``_auto_sigma``; 9
    extra block factorisations), or, given ``guess`` (an estimate of the lowest eigenvalue, e.g.
    the previous continuation step's), from one count below the guess (``_sigma_below``).
    Convergence of pair i goes as |lambda_i - sigma| / |lambda_{block+1} - sigma| per step: with the automatic shift, slow only when the wanted
    eigenvalues are far apart compared with the gap above them (e.g. one strongly negative
    eigenvalue and a dense cluster near zero); check ``residuals``.
    k, iterations, block: static; iterations, tol, block as ``banded.lowest_eigenpairs`` (tol
    relative to a bound on ||M||; outside a trace the iteration goes on, from the vectors found,
    until the residuals are also below 1e-2 (max lambda - sigma), down to 2e-15 ||M||: the
    eigenvalues of a long rod are tiny against ||M||).

    Returns a :class:`ProjectedEigenpairs`. Needs the generators to have full rank (7 for closed
    and free rods), and T - sigma I regular (``jaxrod.linalg.banded`` caveat).
    """
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
        # tol is relative to ||M||; the wanted eigenvalues of a long rod are tiny against it (a
        # ring of N = 10000: ~1e-12 ||M||), and residuals of 1e-12 ||M|| then leave Ritz values
        # far off (measured there: a degenerate pair split by 10%, one partner missed, the
        # lowest 4e-14 above its value at a crossing, phi* 3% off). Go on, from the vectors
        # found, until the residuals are small against the wanted eigenvalues' spread.
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

    Sylvester on the bordered matrix [[M - s, Z], [Z^T, 0]] (M = T + w a a^T the block Hessian,
    Z the orthonormalised generators): its inertia is that of the projected M - s plus (z, z),
    and by Haynsworth it is In(M - s) + In(-Z^T (M - s)^{-1} Z) -- one factorisation of the
    unpinned T - s I and one solve with z columns. Exact: no metric distortion (unlike the pinned
    count of ``inertia_at_equilibrium``) and no equilibrium needed; ``projected_count_below(...,
    -tol)`` is the dense ``n_negative``. Conditioning: T has exact null vectors (translations,
    twist shift), so for |s| tiny compared with ||M|| the pivots along them are ~|s| and carry a
    relative error ~1e-16 ||M|| / |s| (fine for s = -1e-10 and ||M|| up to ~1e4, not far beyond);
    the pinned count has no such limit. Returns an int32 scalar.
    """
    _check_scene(scene)
    lay = block_layout(scene)
    diag, off, a, w = block_hessian(scene, u, phi, nbr)
    Q, _, _ = _gauge(scene, u, phi)
    diag, U, c, Zr, _, _ = _eig_setup(lay, diag, off, a, w, Q)
    return _projected_count(diag, off, lay.cyclic, U, c, Zr, jnp.asarray(s, diag.dtype))


# ------------------------------------------------------------------------------------------------
# the tracked eigenvalue along a branch


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


# Eigenpairs computed beyond the tracked index or the negative count where k does not reach them
# (room for a degenerate pair crossing and the mode above it); continuation.critical_twist too.
EXTRA_PAIRS = 4
