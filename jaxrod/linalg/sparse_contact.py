"""O(N) linear algebra for rods WITH self-contact: a sparse LDL^T (QDLDL) and its inertia.

The scaled Hessian of a knot is H = S + w a a^T: S sparse (the local part, ~20 entries per row,
plus one 12 x 12 block per contact pair in reach, ``jaxrod.model.hessian``) and the holonomy's dense
rank-one term, kept as the vector a. Nothing of size n x n is formed:

* **Factorisation with inertia.** ``jaxrod.linalg.ldlt`` (QDLDL, SuperLU in symmetric mode as a
  fallback): the signs of the pivots give the inertia (Sylvester).
* **The dense columns as a border.** The 7 gauge pins (``sparse.gauge_pins``), the rank-one vector
  a and, where needed, the zero modes Z and deflated eigenvectors are the border of
  [[A, E], [E^T, D]], solved by the Schur complement. Haynsworth: In = In(A) + In(D - E^T A^-1 E).
* **Counts below a shift.** With the border [pins, a, Z], the bordered H - s I has the inertia of
  the projected H - s I plus (7, 7) and one negative (-1/w): an exact count, for any s, at O(N).
* **Lowest eigenpairs.** ARPACK shift-invert (``eigsh``) through the same bordered solve, at a
  shift proven below the spectrum by the count; then Rayleigh-Ritz on the returned vectors.
* **Newton steps and the branch tangent** are pinned solves (zero-mode part removed afterwards),
  with the near-null sliding modes of a loose knot deflated as border columns.

Entry points: ``sparse_hessian``, ``count_below``, ``lowest_eigenpairs``, ``contact_spectrum``,
``contact_branch_analysis`` and ``damped_newton_direction`` (for ``solvers.HostDampedNewton``).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from ..model.hessian import (contact_blocks, contact_hessian_times, contact_pairs_in_reach, hessian_pattern,
                             local_entries)
from .ldlt import FactorisationError, ldlt, negative_count  # noqa: F401  (re-exported)
from .sparse import EXTRA_PAIRS, _gauge, gradient_and_phi_derivative
from ..model.hessian import eigenvalue_branch_derivative

__all__ = ["hessian_parts", "host_hessian_parts", "hessian_times_vectors", "assemble", "node_pair_entries", "negative_count", "deflated_newton_direction", "SparseHessian", "sparse_hessian",
           "count_below", "lowest_eigenpairs", "contact_spectrum", "contact_branch_analysis", "damped_newton_direction",
           "FactorisationError"]


@functools.partial(jax.jit, static_argnames="rows")
def _parts(scene, u, phi, nbr, rows=None):
    pat = hessian_pattern(scene)
    _, _, values, w, a = local_entries(scene, u, phi, nbr, pat)
    if scene.has_term("contact") and nbr.pairs.shape[0] > 0:
        blocks, dofs, count = contact_blocks(scene, u, nbr, pat, rows)
    else:
        blocks, dofs, count = jnp.zeros((0, 12, 12), u.dtype), jnp.zeros((0, 12), jnp.int32), jnp.asarray(0)
    return values, w, a, blocks, dofs, count


@jax.jit
def _zero_basis(scene, u, phi):
    """(Z (n, z) orthonormal zero modes, pins (7,) the gauge DOFs)."""
    Q, pins, _ = _gauge(scene, u, phi)
    return Q, pins


@dataclass(frozen=True, eq=False)
class SparseHessian:
    """H = S + w a a^T. S: (n, n) scipy CSC (local part + contact blocks, symmetric); w: float;
    a: (n,); Z: (n, z) orthonormal zero modes; pins: (z,) gauge DOFs (q indices)."""

    S: sp.csc_matrix
    w: float
    a: np.ndarray
    Z: np.ndarray
    pins: np.ndarray

    @property
    def n(self):
        return self.S.shape[0]

    def matvec(self, x):
        return self.S @ x + self.w * self.a * (self.a @ x)

    def diagonal(self):
        return self.S.diagonal() + self.w * self.a**2

    @functools.cached_property
    def free(self):
        """(n - z,) the unpinned DOFs."""
        mask = np.ones(self.n, bool)
        mask[self.pins] = False
        return np.flatnonzero(mask)

    @functools.cached_property
    def blocks(self):
        """(S_ff CSC, S_fp dense (n_f, z), S_pp dense (z, z)): S split by free / pinned DOFs, once
        per Hessian (every factorisation at another shift reuses them)."""
        S = self.S.tocsr()
        rows_f, rows_p = S[self.free], S[self.pins]
        return (rows_f[:, self.free].tocsc(), rows_f[:, self.pins].toarray(), rows_p[:, self.pins].toarray())


@jax.jit
def _pairs_in_reach(scene, u, nbr):
    return contact_pairs_in_reach(scene, u, nbr, hessian_pattern(scene))


def _block_rows(count):
    """Rows of contact blocks for ``count`` pairs in reach: the next power of two, at least 256
    (a few array shapes, so a few compiled programs, along a continuation)."""
    return max(256, 1 << (max(int(count), 1) - 1).bit_length())


def _contact_rows(scene, u, nbr):
    """The static ``rows`` of ``_parts`` at u: the pairs in reach rounded up (``_block_rows``), or
    None (one row per candidate) where that is no fewer."""
    if not (scene.has_term("contact") and nbr.pairs.shape[0] > 0):
        return None
    rows = _block_rows(_pairs_in_reach(scene, u, nbr))
    return None if rows >= nbr.pairs.shape[0] else rows


def host_hessian_parts(scene, u, phi, nbr):
    """``hessian_parts`` on the host (numpy), with only as many contact-block rows as there are
    pairs in reach (rounded up, ``_block_rows``) instead of one per candidate."""
    u = jnp.asarray(u)
    parts = jax.device_get(_parts(scene, u, phi, nbr, _contact_rows(scene, u, nbr)))
    if int(parts[5]) > parts[3].shape[0]:  # more in reach than counted apart (roundoff at the edge)
        parts = jax.device_get(_parts(scene, u, phi, nbr, None))
    return parts


@jax.jit
def _hessian_times(scene, u, phi, nbr, V):
    pat = hessian_pattern(scene)
    _, _, values, w, a = local_entries(scene, u, phi, nbr, pat)
    local = 0.5 * (values + values[jnp.asarray(pat.transpose)])  # (H + H^T)/2, as ``assemble``
    hv = jnp.zeros((pat.n, V.shape[1]), V.dtype).at[jnp.asarray(pat.rows)].add(local[:, None] * V[jnp.asarray(pat.cols)])
    return hv + contact_hessian_times(scene, u, nbr, pat, V) + w * jnp.outer(a, a @ V)


def hessian_times_vectors(scene, u, phi, nbr, V):
    """H V (n, m) for the scaled Hessian H = S + w a a^T at (u (n,), phi) and V (n, m), O(N m):
    one program forms the products on the device from the Hessian's parts (local entries, then
    the contact blocks of the pairs in reach chunk by chunk), with no sparse matrix assembled and
    nothing but the result copied to the host. Equal to ``sparse_hessian``'s ``S @ V + w a (a^T V)``
    but for the order of summation (roundoff)."""
    return np.asarray(_hessian_times(scene, jnp.asarray(u), phi, nbr, jnp.asarray(V, dtype=jnp.float64)))


def sparse_hessian(scene, u, phi, nbr):
    """The scaled Hessian of ``scene.scaled_energy`` at (u (n,), phi) as a ``SparseHessian``:
    the local part's ~20 n entries and the contact blocks (``host_hessian_parts``, O(N)),
    assembled into CSC on the host (duplicates summed)."""
    parts = host_hessian_parts(scene, u, phi, nbr)
    Z, pins = jax.device_get(_zero_basis(scene, jnp.asarray(u), phi))
    S, w, a = assemble(scene, parts)
    return SparseHessian(S=S, w=w, a=a, Z=np.asarray(Z, float), pins=np.asarray(pins, dtype=np.int64))


def hessian_parts(scene, u, phi, nbr):
    """The Hessian's parts as device arrays (values (nnz,), w, a (n,), blocks (P, 12, 12), dofs
    (P, 12), count): one jitted call, traceable (for ``assemble`` on the host)."""
    return _parts(scene, u, phi, nbr)


def assemble(scene, parts):
    """(S (n, n) CSC, w, a (n,)) on the host from ``hessian_parts``: (H + H^T)/2 of the local
    entries and the contact blocks in reach (first summed per node pair, ``node_pair_entries``),
    exactly symmetric (as the inertia needs)."""
    values, w, a, blocks, dofs, count = (np.asarray(x) for x in parts)
    pat = hessian_pattern(scene)
    n = pat.n
    rows, cols, transpose = pat.rows, pat.cols, pat.transpose
    local = 0.5 * (values + values[transpose])  # (H + H^T)/2 entry by entry: v[k] == v[transpose[k]]
    count = int(count)
    R, C, V = node_pair_entries(blocks[:count], dofs[:count], n)
    S = sp.csc_matrix((np.concatenate([local, V]), (np.concatenate([rows, R]), np.concatenate([cols, C]))),
                      shape=(n, n))
    return S, float(w), np.asarray(a, float)


def node_pair_entries(blocks, dofs, n):
    """COO entries (rows, cols, values) of the contact blocks blocks (P, 12, 12) on dofs (P, 12)
    (DOF n: a clamped node), summed per unordered pair of nodes: each pair {a, b} appears once as
    (a, b) and once as (b, a), each diagonal node block once (symmetrised). Only node blocks
    (k, l) with node k <= node l are summed (the blocks are exactly symmetric), each of their 9
    entries by one ``np.bincount`` over the node pairs (numbered by ``np.unique``)."""
    P = blocks.shape[0]
    if P == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    node_dofs = dofs.reshape(P, 4, 3)
    node = node_dofs[:, :, 0].astype(np.int64) // 3  # a node by its first DOF (n // 3: clamped)
    free = node_dofs[:, :, 0] < n
    keep = free[:, :, None] & free[:, None, :] & (node[:, :, None] <= node[:, None, :])
    p, kl = np.divmod(np.flatnonzero(keep), 16)  # node blocks (k, l) of pair p, node k <= node l, neither clamped
    k, l = np.divmod(kl, 4)
    n_nodes = n // 3 + 1
    pairs, inverse = np.unique(node[p, k] * n_nodes + node[p, l], return_inverse=True)
    inverse = inverse.ravel()
    base = p * 144 + k * 36 + l * 3  # entry (a, b) of node block (k, l) of pair p: blocks.flat[base + 12 a + b]
    values = blocks.reshape(-1)
    summed = np.empty((pairs.size, 3, 3))
    for a in range(3):
        for b in range(3):
            summed[:, a, b] = np.bincount(inverse, weights=values[base + (12 * a + b)], minlength=pairs.size)
    first = np.empty(pairs.size, np.int64)
    first[inverse[::-1]] = np.arange(inverse.size)[::-1]  # an entry of each node pair
    rd, cd = node_dofs[p[first], k[first]], node_dofs[p[first], l[first]]  # (U, 3)
    diagonal = (pairs // n_nodes) == (pairs % n_nodes)
    summed[diagonal] = 0.5 * (summed[diagonal] + np.swapaxes(summed[diagonal], -1, -2))
    r = np.broadcast_to(rd[:, :, None], summed.shape)
    c = np.broadcast_to(cd[:, None, :], summed.shape)
    off = ~diagonal
    R = np.concatenate([r.ravel(), c[off].ravel()])
    C = np.concatenate([c.ravel(), r[off].ravel()])
    V = np.concatenate([summed.ravel(), summed[off].ravel()])
    return R, C, V


class _Bordered:
    """[[A, E], [E^T, D]] with A = (S + shift I) on the free (unpinned) DOFs, factorised once;
    E (n_free, r) and D (r, r) dense. ``negative``: its count of negative eigenvalues."""

    def __init__(self, hs, shift, E_cols, D):
        self.free = hs.free
        A = hs.blocks[0]
        if shift != 0.0:
            A = A + shift * sp.identity(A.shape[0], format="csc")
        lu, pivots = ldlt(A)
        self.lu = lu
        self.E = np.asarray(E_cols, float).reshape(self.free.size, -1)
        AE = lu.solve(self.E) if self.E.shape[1] else self.E
        self.AE = AE
        self.schur = np.asarray(D, float).reshape(self.E.shape[1], self.E.shape[1]) - self.E.T @ AE
        self.schur = 0.5 * (self.schur + self.schur.T)
        neg_border = int(np.sum(np.linalg.eigvalsh(self.schur) < 0.0)) if self.E.shape[1] else 0
        self.negative = int(np.sum(pivots < 0.0)) + neg_border

    def solve(self, b_free, b_border=None):
        """(x_free, x_border) of [[A, E], [E^T, D]] [x; y] = [b_free; b_border]."""
        y0 = self.lu.solve(np.asarray(b_free, float))
        r = self.E.shape[1]
        if r == 0:
            return y0, np.zeros(0)
        rhs = (np.zeros(r) if b_border is None else np.asarray(b_border, float)) - self.E.T @ y0
        y = np.linalg.solve(self.schur, rhs)
        return y0 - self.AE @ y, y


def _constrained(hs, shift, C):
    """The bordered matrix of H + shift I with the border [pins, a, C], C (n, c) constraint
    columns (the zero modes Z, and deflated eigenvectors): its solutions are those of
    P (H + shift I) P x = P b with x orthogonal to C (P the projector off C), the pins and the
    rank-one term entering through the Schur complement. -> _Bordered."""
    p, f = hs.pins, hs.free
    _, S_fp, S_pp = hs.blocks
    cols, top = [S_fp], [S_pp + shift * np.eye(p.size)]
    rank_one = hs.w != 0.0
    if rank_one:
        cols.append(hs.a[f, None])
        top.append(hs.a[p, None])
    cols.append(C[f])
    top.append(C[p])
    E = np.concatenate(cols, axis=1)
    r = E.shape[1]
    D = np.zeros((r, r))
    D[: p.size] = np.concatenate(top, axis=1)
    D[:, : p.size] = D[: p.size].T
    k = p.size
    if rank_one:
        D[k, k] = -1.0 / hs.w
        D[k, k + 1:] = 0.0
        D[k + 1:, k] = 0.0
        k += 1
    D[k:, k:] = 0.0
    return _Bordered(hs, shift, E, D)


def _constrained_solve(fac, hs, off, b):
    """x (n,) from a ``_constrained`` factorisation, b and x projected off the constraint columns
    by ``off`` (v -> v without its part along them)."""
    bp = off(b)
    p = hs.pins
    x_f, y = fac.solve(bp[hs.free], np.concatenate([bp[p], np.zeros(fac.E.shape[1] - p.size)]))
    x = np.zeros(hs.n)
    x[hs.free] = x_f
    x[p] = y[: p.size]
    return off(x)


def _projected_border(hs, shift):
    """The bordered matrix of H + shift I with the border [pins, a, Z] (see module docstring):
    (factorisation, count offset, free DOFs) so that the count of projected eigenvalues below
    -shift = factorisation.negative - offset."""
    offset = hs.Z.shape[1] + (1 if hs.w > 0.0 else 0)  # the Z border adds z negatives, -1/w one more
    return _constrained(hs, shift, hs.Z), offset, hs.free


def count_below(hs, s):
    """Number of eigenvalues of the projected Hessian (zero modes removed) below s: exact
    (Sylvester), one factorisation."""
    fac, offset, _ = _projected_border(hs, -float(s))
    return fac.negative - offset


def _projected_solve(fac, f, hs, b):
    """x (n,) on Z-perp with P (H + shift I) P x = P b, from the bordered factorisation."""
    return _constrained_solve(fac, hs, lambda v: v - hs.Z @ (hs.Z.T @ v), b)


def _fix_signs(vec):
    big = np.take_along_axis(vec, np.argmax(np.abs(vec), axis=0)[None, :], axis=0)
    return vec * np.where(big < 0.0, -1.0, 1.0)


def _start_vector(hs):
    # Deterministic (a resumed run must reproduce the uninterrupted one bit for bit).
    v = np.cos(0.7 * np.arange(hs.n) + 0.3) + 0.5
    return v - hs.Z @ (hs.Z.T @ v)


def lowest_eigenpairs(hs, m, guess=None, tol=1e-6, start=None):
    """(values (m,) ascending, vectors (n, m) on Z-perp, shift): the m lowest eigenpairs of the
    projected Hessian, by ARPACK shift-invert at a shift s pushed down until ``count_below(s) ==
    0``. guess: an estimate of the lowest eigenvalue, to start the shift there; start: (s,
    factorisation, free) of ``_projected_border`` already known to count 0 below s (reused)."""
    m = int(min(m, hs.n - hs.Z.shape[1] - 1))
    scale = float(np.max(np.abs(hs.diagonal()))) + 1.0
    if start is None:
        start = -tol if guess is None or not np.isfinite(guess) else min(float(guess), 0.0) - tol
    s, fac, f = (start, None, None) if not isinstance(start, tuple) else start
    tries = 0
    while fac is None:
        trial, offset, f_trial = _projected_border(hs, -s)
        if trial.negative - offset == 0:
            fac, f = trial, f_trial
            break
        tries += 1
        if tries >= 60:
            raise FactorisationError("no shift below the spectrum found")
        s = max(s - 4.0 * max(abs(s), tol), -4.0 * scale)
    # (H - s I)^-1 on Z-perp: positive definite there, since s is below every eigenvalue.
    n = hs.n
    op = spl.LinearOperator((n, n), matvec=lambda b: _projected_solve(fac, f, hs, np.ravel(b)), dtype=float)
    a_op = spl.LinearOperator((n, n), matvec=lambda x: hs.matvec(np.ravel(x)), dtype=float)
    ncv = min(n - 1, max(2 * m + 1, 20))
    nu, vec = spl.eigsh(a_op, k=m, sigma=s, which="LM", OPinv=op, v0=_start_vector(hs), ncv=ncv, tol=1e-13)
    vec = vec - hs.Z @ (hs.Z.T @ vec)
    vec, _ = np.linalg.qr(vec)
    hv = np.column_stack([hs.matvec(vec[:, j]) for j in range(vec.shape[1])])
    lam_small, rot = np.linalg.eigh(0.5 * (vec.T @ hv + hv.T @ vec))  # Rayleigh-Ritz on the subspace
    vec = _fix_signs(vec @ rot)
    return lam_small, vec, s


def contact_spectrum(scene, q, phi, k=8, tol=1e-6, nbr=None, guess=None):
    """What ``jaxrod.linalg.stability.stability`` reports, at O(N): (n_negative, eigenvalues (m,),
    eigenvectors (n, m)): the exact count of the projected Hessian's eigenvalues below -tol and its
    m >= k lowest eigenpairs (more where the count needs them)."""
    u = scene.to_scaled(np.asarray(q, dtype=float))
    if nbr is None:
        nbr = scene.neighbourhood(jnp.asarray(q), phi)
    hs = sparse_hessian(scene, u, phi, nbr)
    n_neg, start = _count_and_start(hs, tol)
    lam, vec, _ = lowest_eigenpairs(hs, max(int(k), n_neg + EXTRA_PAIRS), guess=guess, tol=tol, start=start)
    return n_neg, lam, vec


def _count_and_start(hs, tol):
    """(count below -tol, the eigensolver's start): that factorisation itself when the count is 0."""
    fac, offset, f = _projected_border(hs, tol)
    n_neg = fac.negative - offset
    return n_neg, ((-tol, fac, f) if n_neg == 0 else None)


def _deflated_tangent(hs, b, skip_vecs):
    """x = -H_def^+ b on Z-perp with the flagged eigenvectors (n, r) left out: the constrained
    solve [[H, Z, V], [Z^T, 0, 0], [V^T, 0, 0]] (exact: V are eigenvectors of the projected
    Hessian, so the complement is invariant)."""
    C = np.concatenate([hs.Z, skip_vecs], axis=1)
    return -_constrained_solve(_constrained(hs, 0.0, C), hs, lambda v: v - C @ np.linalg.lstsq(C, v, rcond=None)[0], b)


def tracked_mode_inputs(scene, q, phi, nbr, index):
    """(u, nbr, index) for a branch analysis at q: the scaled DOFs, the neighbourhood (built at q
    when None) and the tracked mode's index, checked to be >= 0."""
    u = scene.to_scaled(np.asarray(q, dtype=float))
    if nbr is None:
        nbr = scene.neighbourhood(jnp.asarray(q), phi)
    index = int(index)
    if index < 0:
        raise ValueError(f"index must be >= 0, got {index}")
    return u, nbr, index


def contact_branch_analysis(scene, q, phi, index, k=8, tol=1e-6, cluster_rtol=1e-4, ref=None, pinv_tol=0.0, nbr=None,
                            guess=None):
    """What ``jaxrod.linalg.stability.branch_analysis`` computes, for rods with contact at O(N):
    (n_negative, eigenvalues (m,), eigenvectors (n, m), lam, dlam_dphi, v (n,) scaled DOFs,
    dq_dphi (n,) physical DOFs), m >= k. The tracked mode is number ``index`` of the lowest
    pairs, or with ``ref`` the one overlapping it most; the tangent leaves out the tracked mode's
    cluster and the near-null modes |lambda| <= pinv_tol, as the dense analysis does."""
    u, nbr, index = tracked_mode_inputs(scene, q, phi, nbr, index)
    hs = sparse_hessian(scene, u, phi, nbr)
    n_neg, start = _count_and_start(hs, tol)
    m = max(int(k), index + EXTRA_PAIRS, n_neg + EXTRA_PAIRS)
    lam, vec, _ = lowest_eigenpairs(hs, m, guess=guess, tol=tol, start=start)
    if ref is not None and np.any(np.asarray(ref) != 0.0):
        index = int(np.argmax(np.abs(vec.T @ np.asarray(ref))))
    if not index < lam.shape[0]:
        raise ValueError(f"index {index}: only {lam.shape[0]} eigenpairs computed")
    lam_i = lam[index]
    skip = (np.abs(lam - lam_i) <= cluster_rtol * max(abs(lam_i), 1e-12) + 1e-14) | (np.abs(lam) <= pinv_tol)
    _, dg = gradient_and_phi_derivative(scene, jnp.asarray(u), phi, nbr)
    du = _deflated_tangent(hs, np.asarray(dg), vec[:, skip])
    v = vec[:, index]
    dlam = float(eigenvalue_branch_derivative(scene, jnp.asarray(u), jnp.asarray(phi, jnp.float64), jnp.asarray(v),
                                              jnp.asarray(du), nbr))
    return n_neg, lam, vec, float(lam_i), dlam, v, np.asarray(scene.from_scaled(du))


# The shift schedule of ``solvers._damped_newton_loop`` (same constants, same meaning).
_SHIFT_DOWN, _SHIFT_UP, _SHIFT_REFINE = 0.1, 4.0, 2


def _pinned_definite(hs, mu):
    """The pinned system (H + mu I) on the free DOFs, the rank-one term as a border; None if it is
    not positive definite."""
    f = hs.free
    if hs.w != 0.0:
        E, D = hs.a[f, None], np.array([[-1.0 / hs.w]])
        expected = 1 if hs.w > 0.0 else 0
    else:
        E, D, expected = np.zeros((f.size, 0)), np.zeros((0, 0)), 0
    try:
        fac = _Bordered(hs, mu, E, D)
    except FactorisationError:
        return None
    return (fac, f) if fac.negative == expected else None


def damped_newton_direction(y, args, g, mu_prev):
    """The step of ``solvers.HostDampedNewton`` for ``equilibrium.scaled_energy``: (H + mu I) dy =
    -g on the gauge-pinned DOFs (dy = 0 on the 7 pins), mu just large enough for the pinned system
    to be positive definite (inertia, not eigenvalues), chosen as the dense loop chooses it.
    Returns (dy (n,), mu used: 0 where none was needed)."""
    scene, phi, nbr = args
    hs = sparse_hessian(scene, y, phi, nbr)
    scale = float(np.max(np.abs(hs.diagonal()))) + 1.0
    # Unlike the dense loop, the shift keeps falling by _SHIFT_DOWN per iteration with no floor
    # at 1e-6: a floor above the sliding modes' curvature makes the last iterations crawl along them.
    mu0, mu1 = 1e-10 * scale, 1e-6 + 1e-10 * scale
    mu_a = mu0 if mu_prev <= 0.0 else max(mu0, _SHIFT_DOWN * mu_prev)
    got = _pinned_definite(hs, mu_a)
    mu = mu_a
    if got is None:
        lo, hi = mu_a, max(mu1, _SHIFT_UP * mu_a)
        for _ in range(60):
            got = _pinned_definite(hs, hi)
            if got is not None:
                break
            lo, hi = hi, _SHIFT_UP * hi
        else:
            return np.full(hs.n, np.nan), hi
        for _ in range(_SHIFT_REFINE):
            mid = float(np.sqrt(lo * hi))
            trial = _pinned_definite(hs, mid)
            if trial is None:
                lo = mid
            else:
                hi, got = mid, trial
        mu = hi
    fac, f = got
    x_f, _ = fac.solve(-np.asarray(g)[f])
    dy = np.zeros(hs.n)
    dy[f] = x_f
    # Without its rigid-motion (and gauge) part: same energy slope (g is orthogonal to Z), but
    # fewer neighbourhood rebuilds.
    dy = dy - hs.Z @ (hs.Z.T @ dy)
    mu_used = 0.0 if (mu == mu_a and mu_a <= mu0) else mu
    return dy, mu_used


def deflated_newton_direction(y, args, g, mu_prev, near_null_tol=1e-6):
    """A Newton step that leaves the near-null modes alone (as ``Newton(near_null_tol=...)``):
    dy = -H_def^+ g with the eigen-directions |lambda| <= near_null_tol (a loose knot's sliding
    strands) deflated, for a minimiser stalled on them next to an equilibrium. Returns (dy, 0.0)."""
    scene, phi, nbr = args
    hs = sparse_hessian(scene, y, phi, nbr)
    lam, vec, _ = lowest_eigenpairs(hs, 8, tol=near_null_tol)
    skip = np.abs(lam) <= near_null_tol
    return _deflated_tangent(hs, np.asarray(g), vec[:, skip]), 0.0
