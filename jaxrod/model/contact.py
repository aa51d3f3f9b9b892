"""Soft self-contact between non-neighbouring parts of a rod of diameter D.

Energy: a quadrature of the double integral

    E_c = kappa_c * (B / D^3) * sum over candidate segment pairs of
          integral over both segments of phi(|r(s) - r(s')| / D) ds ds',
    phi(rho) = (1 - rho)^3 for rho < 1, 0 beyond,

so two strands overlapping at full depth store kappa_c * B / D^3 per unit length of overlap per
unit length of the other strand. phi, phi' and phi'' vanish at rho = 1: the energy is C2 (a
clamped segment-segment distance is only C1 and makes Hessians jump), and integrating along both
segments (Gauss-Legendre points) keeps the energy from catching on the beads when strands slide.

Pairs closer along the rod than ``exclude`` (default pi D / 2: the tightest tube stays within D of
itself over that arc) are never in contact. Candidate pairs come from a k-d tree on segment
midpoints with a skin: the list stays valid while no node moves by more than skin/2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from .geometry import safe_norm

__all__ = ["ContactList", "all_pairs", "candidate_pairs", "contact_energy", "contact_count", "contact_pair_hessian"]

_GAUSS = {
    1: (np.array([0.5]), np.array([1.0])),
    2: (np.array([0.5 - 0.5 / math.sqrt(3.0), 0.5 + 0.5 / math.sqrt(3.0)]), np.array([0.5, 0.5])),
    3: (
        np.array([0.5 - 0.5 * math.sqrt(0.6), 0.5, 0.5 + 0.5 * math.sqrt(0.6)]),
        np.array([5.0, 8.0, 5.0]) / 18.0,
    ),
}


@dataclass(frozen=True)
class ContactList:
    """Candidate segment pairs (P, 2) padded to a fixed capacity, a validity mask (P,), and the
    node positions (N, 3) they were built from (to decide when to rebuild)."""

    pairs: np.ndarray
    mask: np.ndarray
    x_built: np.ndarray
    skin: float

    @property
    def n_candidates(self):
        return int(np.sum(self.mask))


def _segment_endpoints(x, closed):
    if closed:  # numpy for host arrays (no eager JAX program), jax.numpy when traced
        return x, (np if isinstance(x, np.ndarray) else jnp).roll(x, -1, axis=0)
    return x[:-1], x[1:]


def _arc_separation(i, j, n_edges, closed):
    d = np.abs(i - j)
    return np.minimum(d, n_edges - d) if closed else d


def all_pairs(n_nodes, closed, rest_length, D, exclude=None):
    """Every segment pair (i < j) further apart along the rod than ``exclude`` (default pi D/2),
    as (P, 2) ints. For small rods, or as the reference for candidate lists."""
    n_edges = n_nodes if closed else n_nodes - 1
    exclude = math.pi * D / 2.0 if exclude is None else exclude
    gap = max(1, int(math.ceil(exclude / rest_length)))
    i, j = np.triu_indices(n_edges, k=1)
    keep = _arc_separation(i, j, n_edges, closed) > gap
    return np.stack([i[keep], j[keep]], axis=1)


def candidate_pairs(x, closed, rest_length, D, skin=None, exclude=None, capacity=None):
    """Segment pairs that may come within D of each other while no node moves more than skin/2:
    a k-d tree on the midpoints of x (N,3) (numpy) with radius D + skin + the longest segment.
    Returns a ``ContactList`` padded to ``capacity`` (default: generous, see below)."""
    from scipy.spatial import cKDTree

    x = np.asarray(x, dtype=float)
    skin = 0.5 * D if skin is None else float(skin)
    exclude = math.pi * D / 2.0 if exclude is None else exclude
    a, b = (np.asarray(v) for v in _segment_endpoints(x, closed))
    mid = 0.5 * (a + b)
    seg_len = np.linalg.norm(b - a, axis=1)
    n_edges = mid.shape[0]
    radius = D + skin + float(seg_len.max())
    found = cKDTree(mid).query_pairs(radius, output_type="ndarray")
    if found.size == 0:
        found = np.zeros((0, 2), dtype=int)
    i, j = np.minimum(found[:, 0], found[:, 1]), np.maximum(found[:, 0], found[:, 1])
    gap = max(1, int(math.ceil(exclude / rest_length)))
    keep = _arc_separation(i, j, n_edges, closed) > gap
    pairs = np.stack([i[keep], j[keep]], axis=1)
    # Default capacity: generous (24 candidates per segment or 3x the count, at most all possible
    # pairs): a new capacity is a new array shape, which recompiles; padding costs little.
    sep = np.arange(1, n_edges)  # |i - j|, met by n_edges - sep pairs i < j
    n_possible = int(np.sum((n_edges - sep)[_arc_separation(sep, 0, n_edges, closed) > gap]))
    if capacity is None:
        cap = max(16, 3 * len(pairs), min(24 * n_edges, n_possible))
    else:
        cap = int(capacity)
    if cap < len(pairs):
        cap = 2 * len(pairs)
    padded = np.zeros((cap, 2), dtype=np.int32)
    padded[: len(pairs)] = pairs
    mask = np.zeros(cap, dtype=bool)
    mask[: len(pairs)] = True
    return ContactList(pairs=padded, mask=mask, x_built=x.copy(), skin=skin)


def _pair_quadrature(x, pairs, closed, n_gauss):
    """Distances (P, g, g) between Gauss points of paired segments, and weights (P, g, g) l_a l_b w w."""
    g, w = _GAUSS[n_gauss]
    a0, a1 = _segment_endpoints(x, closed)
    pa0, pa1 = a0[pairs[:, 0]], a1[pairs[:, 0]]
    pb0, pb1 = a0[pairs[:, 1]], a1[pairs[:, 1]]
    ga = pa0[:, None, :] + (pa1 - pa0)[:, None, :] * g[None, :, None]  # (P, g, 3)
    gb = pb0[:, None, :] + (pb1 - pb0)[:, None, :] * g[None, :, None]
    r = safe_norm(ga[:, :, None, :] - gb[:, None, :, :])  # (P, g, g)
    la = jnp.linalg.norm(pa1 - pa0, axis=-1)
    lb = jnp.linalg.norm(pb1 - pb0, axis=-1)
    weights = (la * lb)[:, None, None] * (w[:, None] * w[None, :])[None]
    return r, weights


def contact_energy(x, pairs, mask, closed, D, B, stiffness, n_gauss=2):
    """Soft contact energy (scalar) over the candidate pairs. x (N,3); pairs (P,2) segment indices;
    mask (P,) which pairs are real (padding is False); D diameter; B bending stiffness; stiffness:
    kappa_c (dimensionless, see module docstring)."""
    r, weights = _pair_quadrature(x, jnp.asarray(pairs), closed, n_gauss)
    overlap = jnp.clip(1.0 - r / D, 0.0, None)
    density = jnp.sum(weights * overlap**3, axis=(1, 2))
    return stiffness * B / D**3 * jnp.sum(jnp.where(jnp.asarray(mask), density, 0.0))


def contact_count(x, pairs, mask, closed, D, n_gauss=2):
    """Number of candidate segment pairs with at least one Gauss-point pair closer than D."""
    r, _ = _pair_quadrature(x, jnp.asarray(pairs), closed, n_gauss)
    touching = jnp.any(r < D, axis=(1, 2)) & jnp.asarray(mask)
    return jnp.sum(touching)


def contact_pair_hessian(y, D, B, stiffness, n_gauss=2):
    """Exact Hessians of the contact energy of single segment pairs, in closed form.

    y: (P, 12), per pair the nodes a0, a1 (segment a) and b0, b1 (segment b) -> (P, 12, 12), each
    the Hessian of ``contact_energy`` of that pair alone (the same quadrature); equal to
    ``jax.hessian`` of it (tested to roundoff) at a third of the cost.

    How: E = k la lb F with k = stiffness B / D^3, la, lb the segment lengths and
    F = sum_ij w_i w_j phi(r_ij) over the Gauss points; each point pair contributes
    c c^T (x) [phi'' n n^T + phi'/r (I - n n^T)] (c: its weights on the four nodes, n the unit
    vector from q_j to p_i), and the product rule adds the lengths' gradients and Hessians."""
    g, w = (jnp.asarray(v) for v in _GAUSS[n_gauss])
    P = y.shape[0]
    a0, a1, b0, b1 = y[:, 0:3], y[:, 3:6], y[:, 6:9], y[:, 9:12]
    da, db = a1 - a0, b1 - b0
    la, lb = jnp.linalg.norm(da, axis=1), jnp.linalg.norm(db, axis=1)
    ta, tb = da / la[:, None], db / lb[:, None]
    p = a0[:, None, :] + g[None, :, None] * da[:, None, :]  # (P, g, 3)
    q = b0[:, None, :] + g[None, :, None] * db[:, None, :]
    d = p[:, :, None, :] - q[:, None, :, :]  # (P, g, g, 3)
    r = jnp.sqrt(jnp.sum(d * d, axis=-1))
    rs = jnp.where(r > 0.0, r, 1.0)  # coincident points: no direction, phi' n taken as 0
    s = jnp.where(r < D, 1.0 - r / D, 0.0)
    ww = w[:, None] * w[None, :]
    f0, f1, f2 = ww * s**3, ww * (-3.0 / D) * s**2, ww * (6.0 / D**2) * s  # phi, phi', phi'' weighted
    n = d / rs[..., None]
    k = g.size
    c = jnp.stack([jnp.broadcast_to((1.0 - g)[:, None], (k, k)), jnp.broadcast_to(g[:, None], (k, k)),
                   -jnp.broadcast_to((1.0 - g)[None, :], (k, k)), -jnp.broadcast_to(g[None, :], (k, k))], -1)
    F = jnp.sum(f0, axis=(1, 2))
    grad_F = jnp.einsum("ijk,Pij,Pija->Pka", c, f1, n).reshape(P, 12)
    eye = jnp.eye(3)
    nn = n[..., :, None] * n[..., None, :]
    h_point = f2[..., None, None] * nn + jnp.where(r > 0.0, f1 / rs, 0.0)[..., None, None] * (eye - nn)
    hess_F = jnp.einsum("ijk,ijl,Pijab->Pkalb", c, c, h_point).reshape(P, 12, 12)
    z = jnp.zeros((P, 3))
    grad_la = jnp.concatenate([-ta, ta, z, z], 1)
    grad_lb = jnp.concatenate([z, z, -tb, tb], 1)
    two_nodes = jnp.array([[1.0, -1.0], [-1.0, 1.0]])

    def length_hessian(t, l):  # (P, 6, 6): Hessian of |x1 - x0| in (x0, x1)
        m = (eye - t[:, :, None] * t[:, None, :]) / l[:, None, None]
        return jnp.einsum("kl,Pab->Pkalb", two_nodes, m).reshape(P, 6, 6)

    hess_la = jnp.zeros((P, 12, 12), y.dtype).at[:, 0:6, 0:6].set(length_hessian(ta, la))
    hess_lb = jnp.zeros((P, 12, 12), y.dtype).at[:, 6:12, 6:12].set(length_hessian(tb, lb))

    def sym(u, v):
        return u[:, :, None] * v[:, None, :] + v[:, :, None] * u[:, None, :]

    col = (lambda v: v[:, None, None])
    h = (col(la * lb) * hess_F + col(lb * F) * hess_la + col(la * F) * hess_lb + col(F) * sym(grad_la, grad_lb)
         + col(lb) * sym(grad_la, grad_F) + col(la) * sym(grad_lb, grad_F))
    return (stiffness * B / D**3) * h
