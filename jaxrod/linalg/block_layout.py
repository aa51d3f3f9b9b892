"""The node-interleaved block order of a rod's DOFs, in which its local Hessian is block-tridiagonal
(cyclic for closed rods): what ``jaxrod.linalg.sparse`` hands to the block LDL^T of
``jaxrod.linalg.banded``. Static (numpy), cached per scene kind and number of nodes; built from the
scene's ``jaxrod.model.layout.DofLayout`` and checked against its Hessian pattern."""
from __future__ import annotations

import functools
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from ..model.hessian import pattern_of
from ..model.layout import dof_layout, layout_of

__all__ = ["BlockLayout", "block_layout", "to_blocks", "from_blocks"]


@dataclass(frozen=True, eq=False)
class BlockLayout:
    """Static (numpy) description of the block order of one scene layout (kind, N).

    n: number of real DOFs; block_size b; num_blocks K; n_pad = K b >= n (the excess are dummy DOFs:
    identity on the diagonal, zero elsewhere); cyclic: closed rods (corner block couples the last
    block to the first). perm: (n_pad,) q index of each block-order slot, -1 for a dummy; position:
    (n,) block-order slot of each q index (perm[position] = arange(n)); dummy: (n_pad,) bool.
    diag_src, off_src: (2, K, b, b) flat indices, into the (n_colours, n) array of coloured
    Hessian-vector products, of H[r, c] and H[c, r] for the entry (r, c) that lands at diag[k, i, j]
    (r = perm[k b + i], c = perm[k b + j]) resp. off[k, i, j] (c = perm[((k+1) mod K) b + j]);
    diag_ok, off_ok: (K, b, b) bool, the entries that are structurally non-zero (and, for off,
    stored there: a non-cyclic corner and, for K = 2 cyclic, off[1] stay zero). pin_candidates: (m,
    7) q indices of the candidate gauge pins ((0, 0) without zero modes)."""

    kind: str
    n_nodes: int
    n: int
    block_size: int
    num_blocks: int
    cyclic: bool
    perm: np.ndarray
    position: np.ndarray
    dummy: np.ndarray
    diag_src: np.ndarray
    diag_ok: np.ndarray
    off_src: np.ndarray
    off_ok: np.ndarray
    pin_candidates: np.ndarray

    @property
    def n_pad(self):
        return self.num_blocks * self.block_size


@functools.lru_cache(maxsize=32)
def _layout(kind, N):
    dofs = layout_of(kind, N)
    pat = pattern_of(dofs)
    n = pat.n
    groups, cyclic = dofs.node_groups, dofs.cyclic
    if not cyclic or N % 2 == 0:
        # 2 nodes per block (b = 8), dummies at the end (none for an even closed rod).
        b = 8
        seq = [d for g in groups for d in g]
        K = -(-len(seq) // b)
        perm = np.array(seq + [-1] * (K * b - len(seq)))
    else:
        # Odd closed rod: no placement of dummies makes 2-node blocks of 8 close the cycle. Blocks
        # of 3 nodes (b = 12), the last 3K - N of them holding 2 nodes and 4 dummies.
        b = 12
        K = -(-N // 3)
        short = 3 * K - N
        sizes = [3] * (K - short) + [2] * short
        perm, i = [], 0
        for s in sizes:
            blk = [d for g in groups[i:i + s] for d in g]
            perm += blk + [-1] * (b - len(blk))
            i += s
        perm = np.array(perm)
    n_pad = K * b
    dummy = perm < 0
    position = np.empty(n, dtype=np.int64)
    position[perm[~dummy]] = np.nonzero(~dummy)[0]
    mask, colour = pat.mask, pat.colour

    def tables(rows, cols):
        valid = (rows >= 0) & (cols >= 0)
        rs, cs = np.where(valid, rows, 0), np.where(valid, cols, 0)
        ok = valid & mask[rs, cs]
        src = np.stack([colour[cs] * n + rs, colour[rs] * n + cs])
        return np.where(ok, src, 0), ok

    P = perm.reshape(K, b)
    diag_src, diag_ok = tables(P[:, :, None], P[:, None, :])
    off_src, off_ok = tables(P[:, :, None], np.roll(P, -1, axis=0)[:, None, :])
    if not cyclic:
        off_ok[K - 1] = False
    elif K == 2:
        off_ok[1] = False  # T[1, 0] = off[0]^T + off[1]: store the coupling once
    if int(diag_ok.sum() + 2 * off_ok.sum()) != int(mask.sum()):
        raise AssertionError(f"block layout of {kind} N={N} does not hold the Hessian pattern")
    if kind in ("closed", "free"):
        a, c = N // 3, (2 * N) // 3
        th0 = 3 * N
        cand = [[0, 1, 2, 3 * a + i, 3 * a + j, 3 * c + m, th0]
                for (i, j) in ((0, 1), (0, 2), (1, 2)) for m in range(3)]
        pins = np.array(cand)
    else:
        pins = np.zeros((0, 0), dtype=np.int64)
    return BlockLayout(kind=kind, n_nodes=N, n=n, block_size=b, num_blocks=K, cyclic=cyclic, perm=perm,
                       position=position, dummy=dummy, diag_src=diag_src, diag_ok=diag_ok, off_src=off_src,
                       off_ok=off_ok, pin_candidates=pins)


def block_layout(scene):
    """The :class:`BlockLayout` of a scene (numpy, cached per kind and N). DOFs are interleaved node
    by node (the ``node_groups`` of the scene's ``DofLayout``) and grouped 2 nodes per block (b =
    8), so that the local Hessian is block-tridiagonal (a corner block for closed rods), padded with
    dummy DOFs to a multiple of b; a closed rod with an odd number of nodes uses 3-node blocks (b =
    12, see ``_layout``). Checked against the Hessian's sparsity pattern when built."""
    dofs = dof_layout(scene)
    return _layout(dofs.kind, dofs.n_nodes)


def to_blocks(lay, v):
    """q order (n, ...) -> block order (n_pad, ...), zero on dummies."""
    perm = jnp.asarray(np.where(lay.perm >= 0, lay.perm, 0))
    keep = jnp.asarray(~lay.dummy).reshape((-1,) + (1,) * (v.ndim - 1))
    return jnp.where(keep, v[perm], 0.0)


def from_blocks(lay, v):
    """block order (n_pad, ...) -> q order (n, ...)."""
    return v[jnp.asarray(lay.position)]
