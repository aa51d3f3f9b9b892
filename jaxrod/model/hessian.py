"""Structured Hessians of rod energies: exact, without differentiating the whole energy n times.

The Hessian of a rod's scaled energy (``scene.scaled_energy``) has three parts:

* **local**: stretch, bend, twist and the holonomy's own second derivative couple only DOFs within
  a window of three consecutive nodes. Recovered from a few Hessian-vector products with
  *coloured* probes (Curtis-Powell-Reid): ~36 products whatever N, instead of n = 4N.
* **rank one**: the holonomy vertex stores C m^2 / (2 l) with m depending on every tangent: the
  dense term w a a^T, a = grad m, kept as a vector and subtracted from the probes.
* **contact**: one 12 x 12 block per candidate segment pair, from the pair-coupled terms
  (``Term.pair_hessian``; contact's in closed form, ``contact.contact_pair_hessian``).

``scaled_hessian(scene, u, phi, nbr)`` assembles them densely (tested against ``jax.hessian``);
``dense_autodiff_hessian`` is that reference.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from .layout import dof_layout, layout_of
from .terms import Coupling

__all__ = ["HessianPattern", "hessian_pattern", "pattern_of", "scaled_hessian", "dense_autodiff_hessian",
           "holonomy_rank_one", "project_out", "contact_blocks", "contact_hessian_times", "contact_pairs_in_reach", "local_entries", "eigenvalue_branch_derivative"]


@dataclass(frozen=True)
class HessianPattern:
    """Static (numpy) structure of the local Hessian of one scene layout.

    n: number of DOFs; colour: (n,) colour of each DOF; n_colours; mask: (n, n) bool, the local
    sparsity pattern (symmetric); probes: (n_colours, n) 0/1 probe vectors; x_dof: (N, 3) index of
    each node coordinate in q (-1 where the node is clamped, from the scene's ``DofLayout``); rows,
    cols: (nnz,) the pattern's non-zero positions, row-major; transpose: (nnz,) the index, in
    rows/cols, of each entry's transposed entry (the pattern is symmetric)."""

    n: int
    colour: np.ndarray
    n_colours: int
    mask: np.ndarray
    probes: np.ndarray
    x_dof: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    transpose: np.ndarray


@functools.lru_cache(maxsize=64)
def _pattern(kind, n_nodes, window=3):
    lay = layout_of(kind, n_nodes)
    spans, cyclic = lay.spans, lay.cyclic
    n = lay.n
    # Window w covers nodes w .. w+window-1 (mod N when cyclic). A DOF spanning nodes lo..hi
    # (hi = lo or lo + 1, cyclically) lies in the windows w = hi - window + 1 .. lo.
    n_win = n_nodes if cyclic else n_nodes - window + 1
    rows, cols = [], []
    for d, (lo, hi) in enumerate(spans):
        length = (hi - lo) % n_nodes if cyclic else hi - lo
        for w in range(lo - (window - 1) + length, lo + 1):
            if cyclic:
                rows.append(d)
                cols.append(w % n_nodes)
            elif 0 <= w < n_win:
                rows.append(d)
                cols.append(w)
    inc = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n_win))
    pattern = (inc @ inc.T) > 0  # DOFs sharing a window: a possibly non-zero entry
    colour = _greedy_colouring((pattern @ pattern) > 0)  # columns sharing a row cannot share a colour
    n_colours = int(colour.max()) + 1
    probes = np.zeros((n_colours, n))
    probes[colour, np.arange(n)] = 1.0
    mask = pattern.toarray()
    rows, cols = (v.astype(np.int32) for v in np.nonzero(mask))
    keys = rows.astype(np.int64) * n + cols  # row-major: sorted
    transpose = np.searchsorted(keys, cols.astype(np.int64) * n + rows)
    return HessianPattern(n=n, colour=colour, n_colours=n_colours, mask=mask, probes=probes,
                          x_dof=lay.x_dof, rows=rows, cols=cols, transpose=transpose)


def _greedy_colouring(conflict):
    """(n,) colour of each DOF, DOFs in rod order, no two conflicting DOFs sharing a colour."""
    conflict = conflict.tolil()
    n = conflict.shape[0]
    colour = -np.ones(n, dtype=int)
    for d in range(n):
        used = {colour[j] for j in conflict.rows[d] if colour[j] >= 0}
        c = 0
        while c in used:
            c += 1
        colour[d] = c
    return colour


def pattern_of(layout):
    """The ``HessianPattern`` of a ``DofLayout`` (cached per kind and N)."""
    return _pattern(layout.kind, layout.n_nodes)


def hessian_pattern(scene):
    """The ``HessianPattern`` of a scene's layout (cached per kind and N)."""
    return pattern_of(dof_layout(scene))


def holonomy_rank_one(scene, u, phi, nbr):
    """(w, a): the dense rank-one part w a a^T of the scaled Hessian (a (n,), w scalar), from the
    vertex whose twist carries the holonomy (``Term.rank_one``); w = 0 for scenes without one."""
    for term in scene.terms:
        part = term.rank_one(scene, u, phi, nbr)
        if part is not None:
            return part
    return jnp.asarray(0.0), jnp.zeros_like(u)


def local_products(scene, u, phi, nbr, pat):
    """(hv, w, a): hv (colours, n), row c = H_local @ probe_c (every local entry can be read from
    it), and the rank-one term (w, a) subtracted from the full products."""
    local = scene.local_terms

    def f(uu):
        q = uu * scene.dof_scale
        return sum(scene.energy_terms(q, phi, nbr, terms=local).values()) / scene.energy_scale

    g = jax.grad(f)
    probes = jnp.asarray(pat.probes)
    hv = jax.vmap(lambda p: jax.jvp(g, (u,), (p,))[1])(probes)  # (colours, n)
    w, a = holonomy_rank_one(scene, u, phi, nbr)
    return hv - w * (probes @ a)[:, None] * a[None, :], w, a


def local_entries(scene, u, phi, nbr, pat):
    """(rows, cols, values, w, a): the local part's non-zero entries (rows, cols static numpy
    (nnz,), values (nnz,)) and the rank-one term w a a^T, for sparse assembly."""
    hv, w, a = local_products(scene, u, phi, nbr, pat)
    rows, cols = pat.rows, pat.cols
    return rows, cols, hv[jnp.asarray(pat.colour[cols]), jnp.asarray(rows)], w, a


def _local_block(scene, u, phi, nbr, pat):
    """The local part (n, n) dense, from coloured Hessian-vector products of the elastic energy."""
    hv, w, a = local_products(scene, u, phi, nbr, pat)
    # Entry (r, c) of the local part is row r of the product with c's colour; only the pattern's
    # entries are gathered and scattered.
    rows, cols = pat.rows, pat.cols
    values = hv[jnp.asarray(pat.colour[cols]), jnp.asarray(rows)]
    h_local = jnp.zeros((pat.n, pat.n), hv.dtype).at[jnp.asarray(rows), jnp.asarray(cols)].set(
        values, indices_are_sorted=True, unique_indices=True)
    return h_local, w, a


def _pair_terms(scene):
    """The scene's terms coupled through segment pairs (``Coupling.PAIRS``: contact)."""
    return tuple(t for t in scene.terms if t.coupling is Coupling.PAIRS)


def _contact_chunks(scene, u, nbr, pat):
    """The contact pairs within reach, in fixed-size chunks: (count, n_chunks, chunk, blocks_of(k),
    dofs_of(k)): blocks_of(k) (chunk, 12, 12) the scaled Hessian blocks of chunk k (zero past
    ``count``), dofs_of(k) (chunk, 12) their DOF indices (n where a node is clamped). Pairs that may
    be within D (the energy is zero beyond) are gathered to the front, so a loop over ``count``
    costs only the pairs in reach."""
    m = scene.material
    pairs = nbr.pairs
    n_nodes = scene.n_nodes
    x = scene.positions(u * scene.dof_scale)
    nodes = jnp.stack([pairs[:, 0], (pairs[:, 0] + 1) % n_nodes, pairs[:, 1], (pairs[:, 1] + 1) % n_nodes], 1)
    a0, a1, b0, b1 = (x[nodes[:, k]] for k in range(4))
    # Two segments within D of each other have midpoints within D + (|a| + |b|)/2.
    gap = jnp.linalg.norm(0.5 * (a0 + a1 - b0 - b1), axis=1)
    reach = m.D + 0.5 * (jnp.linalg.norm(a1 - a0, axis=1) + jnp.linalg.norm(b1 - b0, axis=1))
    near = nbr.mask & (gap < reach)
    count = jnp.sum(near)
    p = pairs.shape[0]
    # Pairs per loop pass: larger for long lists (fewer passes; measured on the trefoil at N = 961)
    chunk = max(8, min(p, 64 if p <= 8192 else 256))
    n_chunks = -(-p // chunk)
    (order,) = jnp.nonzero(near, size=n_chunks * chunk, fill_value=0)  # pairs in reach first
    scale = scene.length_scale**2 / scene.energy_scale
    x_dof = jnp.asarray(pat.x_dof)

    def chunk_nodes(k):
        return nodes[jax.lax.dynamic_slice(order, (k * chunk,), (chunk,))]

    pair_terms = _pair_terms(scene)

    def blocks_of(k):
        keep = (k * chunk + jnp.arange(chunk)) < count
        segments = x[chunk_nodes(k)].reshape(chunk, 12)
        blocks = pair_terms[0].pair_hessian(scene, segments)
        for term in pair_terms[1:]:  # more than one pair-coupled term: their blocks add up
            blocks = blocks + term.pair_hessian(scene, segments)
        return blocks * (scale * keep)[:, None, None]

    def dofs_of(k):
        dof = x_dof[chunk_nodes(k)].reshape(chunk, 12)
        # clamped nodes have no DOF (-1): sent out of range (a -1 would wrap to the last DOF)
        return jnp.where(dof < 0, pat.n, dof)

    return count, n_chunks, chunk, blocks_of, dofs_of


def _add_contact_hessian(h, scene, u, nbr, pat):
    """h (n, n) plus the contact pairs' scaled Hessian blocks, chunk by chunk, clamped DOFs dropped."""
    count, _, chunk, blocks_of, dofs_of = _contact_chunks(scene, u, nbr, pat)

    def more(c):
        k, _ = c
        return k * chunk < count

    def add_chunk(c):
        k, hh = c
        blocks, dof = blocks_of(k), dofs_of(k)
        rows = jnp.broadcast_to(dof[:, :, None], blocks.shape)
        cols = jnp.broadcast_to(dof[:, None, :], blocks.shape)
        return k + 1, hh.at[rows.ravel(), cols.ravel()].add(blocks.ravel(), mode="drop")

    return jax.lax.while_loop(more, add_chunk, (0, h))[1]


def contact_hessian_times(scene, u, nbr, pat, V):
    """The pair-coupled terms' part (contact) times V (n, m) -> (n, m), chunk by chunk over the
    pairs within reach (no block array kept, no count needed beforehand); clamped DOFs dropped.
    Zero for a scene without such terms or candidate pairs."""
    m = V.shape[1]
    if not (_pair_terms(scene) and nbr.pairs.shape[0] > 0):
        return jnp.zeros((pat.n, m), V.dtype)
    count, _, chunk, blocks_of, dofs_of = _contact_chunks(scene, u, nbr, pat)
    v_ext = jnp.concatenate([V, jnp.zeros((1, m), V.dtype)])  # DOF n: a clamped node

    def more(c):
        return c[0] * chunk < count

    def add_chunk(c):
        k, hv = c
        dof = dofs_of(k)
        products = jnp.einsum("pij,pjm->pim", blocks_of(k), v_ext[dof])  # (chunk, 12, m)
        return k + 1, hv.at[dof.reshape(-1)].add(products.reshape(-1, m))

    hv = jax.lax.while_loop(more, add_chunk, (0, jnp.zeros((pat.n + 1, m), V.dtype)))[1]
    return hv[: pat.n]


def contact_pairs_in_reach(scene, u, nbr, pat):
    """How many of nbr's candidate pairs are within reach at u (the rows ``contact_blocks`` fills)."""
    return _contact_chunks(scene, u, nbr, pat)[0]


def contact_blocks(scene, u, nbr, pat, rows=None):
    """The contact part as blocks for sparse assembly: (blocks (R, 12, 12), dofs (R, 12), count),
    the first ``count`` rows the pairs within reach, the rest zero; dofs: n where a node is clamped.
    R: every candidate (default), or ``rows`` (static) rounded up to the loop's pass: a candidate
    list holds the pairs that may come within reach, a few times those in reach, and a block per
    candidate costs that many times the zeroing and copying. With ``rows``, only the first R pairs
    in reach are filled: the caller checks count <= R."""
    count, n_chunks, chunk, blocks_of, dofs_of = _contact_chunks(scene, u, nbr, pat)
    if rows is not None:
        n_chunks = min(n_chunks, -(-int(rows) // chunk))
    blocks = jnp.zeros((n_chunks * chunk, 12, 12), u.dtype)
    dofs = jnp.full((n_chunks * chunk, 12), pat.n, jnp.int32)

    def more(c):
        return (c[0] * chunk < count) & (c[0] < n_chunks)

    def fill(c):
        k, b, d = c
        b = jax.lax.dynamic_update_slice(b, blocks_of(k), (k * chunk, 0, 0))
        d = jax.lax.dynamic_update_slice(d, dofs_of(k).astype(jnp.int32), (k * chunk, 0))
        return k + 1, b, d

    _, blocks, dofs = jax.lax.while_loop(more, fill, (0, blocks, dofs))
    return blocks, dofs, count


@jax.jit
def scaled_hessian(scene, u, phi, nbr):
    """Exact Hessian (n, n) of ``scene.scaled_energy(u, phi, nbr)``, assembled from its structure
    (local part by coloured products, rank-one holonomy term, contact pair blocks)."""
    pat = hessian_pattern(scene)
    h, w, a = _local_block(scene, u, phi, nbr, pat)
    h = h + w * jnp.outer(a, a)
    if _pair_terms(scene) and nbr.pairs.shape[0] > 0:
        h = _add_contact_hessian(h, scene, u, nbr, pat)
    return 0.5 * (h + h.T)


@jax.jit
def dense_autodiff_hessian(scene, u, phi, nbr=None):
    """Reference: ``jax.hessian`` of the whole scaled energy (n Hessian-vector products)."""
    h = jax.hessian(scene.scaled_energy)(u, phi, nbr)
    return 0.5 * (h + h.T)


def project_out(h, z, xp=jnp):
    """P h P + lift Z Z^T with P = I - Z Z^T for orthonormal columns z (n, k) (zero columns
    allowed), lift above the Gershgorin bound of h: one rank-2k update of h,
    h + [Z, HZ] [[Z^T H Z + lift I, -I], [-I, 0]] [Z, HZ]^T, O(n^2 k). xp: jax.numpy or numpy."""
    hz = h @ z  # (n, k)
    k = z.shape[1]
    lift = 2.0 * xp.max(xp.sum(xp.abs(h), axis=1)) + 1.0
    eye = xp.eye(k)
    core = xp.block([[z.T @ hz + lift * eye, -eye], [-eye, xp.zeros((k, k))]])
    zb = xp.concatenate([z, hz], axis=1)
    hp = h + (zb @ core) @ zb.T
    return 0.5 * (hp + hp.T)


@jax.jit  # one program per scene shape, shared by the dense and the sparse analyses
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
