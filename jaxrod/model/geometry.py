"""Geometry of discrete curves: edges, tangents, curvature binormals, parallel transport, frames.

Conventions
-----------
* ``x`` has shape (N, 3): node positions. A closed curve has N edges, edge i joins node i to
  node i+1 (mod N); an open curve has N-1 edges.
* Frames are right-handed: reference director u, second director v = t x u, material director
  d1 = cos(theta) u + sin(theta) v; a twist angle increasing along the rod is a positive twist.
* Reference frames are *space-parallel* (u on edge i is u on edge i-1 transported to edge i): all
  twist lives in the angles theta plus the holonomy of the transport.

The small array functions are jitted, so each is one compiled program per shape when called
eagerly (and inlined inside a jitted energy).
"""
from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["edges", "safe_norm", "unit", "curvature_binormals", "parallel_transport", "transport_along",
           "signed_angle", "tantrix_holonomy", "perpendicular_unit", "material_directors", "node_directors",
           "voronoi_lengths", "resample_closed", "polyline_distance", "point_polyline_distances", "segment_distances",
           "closest_approach"]


def safe_norm(v, axis=-1, keepdims=False, eps=1e-300):
    """Euclidean norm whose gradient is finite at v = 0 (returns 0 there)."""
    sq = jnp.sum(v * v, axis=axis, keepdims=keepdims)
    positive = sq > eps
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, sq, 1.0)), 0.0)


@partial(jax.jit, static_argnames="axis")
def unit(v, axis=-1):
    """v / |v| along ``axis``."""
    return v / jnp.linalg.norm(v, axis=axis, keepdims=True)


@partial(jax.jit, static_argnames="closed")
def edges(x, closed):
    """Edge vectors. x (N,3) -> (N,3) if closed else (N-1,3)."""
    if closed:
        return jnp.roll(x, -1, axis=0) - x
    return x[1:] - x[:-1]


@jax.jit
def curvature_binormals(e_prev, e_next):
    """Discrete curvature binormal kb = 2 e_prev x e_next / (|e_prev||e_next| + e_prev.e_next).
    Shapes (M,3), (M,3) -> (M,3). |kb| = 2 tan(turning angle / 2); kb / (Voronoi length) is the
    curvature vector kappa * binormal at the vertex shared by the two edges."""
    cross = jnp.cross(e_prev, e_next)
    denom = jnp.linalg.norm(e_prev, axis=-1) * jnp.linalg.norm(e_next, axis=-1) + jnp.sum(e_prev * e_next, axis=-1)
    return 2.0 * cross / denom[..., None]


@jax.jit
def parallel_transport(v, t_from, t_to):
    """Transport vector(s) v from unit tangent t_from to unit tangent t_to. The rotation about
    t_from x t_to that takes t_from to t_to, without trigonometry: smooth except for antiparallel
    tangents. Shapes broadcast over the leading axes, last axis 3."""
    c = jnp.cross(t_from, t_to)
    d = jnp.sum(t_from * t_to, axis=-1, keepdims=True)
    return v * d + jnp.cross(c, v) + c * jnp.sum(c * v, axis=-1, keepdims=True) / (1.0 + d)


@jax.jit
def transport_along(u0, tangents):
    """Space-parallel reference directors: u0 transported edge by edge along ``tangents``. u0 (3,)
    unit and perpendicular to tangents[0]; tangents (M,3) unit -> (M,3)."""

    def step(u, pair):
        t_from, t_to = pair
        u_next = parallel_transport(u, t_from, t_to)
        return u_next, u_next

    _, rest = jax.lax.scan(step, u0, (tangents[:-1], tangents[1:]))
    return jnp.concatenate([u0[None], rest], axis=0)


@jax.jit
def signed_angle(a, b, axis):
    """Signed angle from a to b about ``axis`` (right-hand rule), in (-pi, pi]."""
    return jnp.arctan2(jnp.sum(jnp.cross(a, b) * axis, axis=-1), jnp.sum(a * b, axis=-1))


# Candidate poles for the tantrix area: 32 well-spread unit vectors (Fibonacci sphere).
_K = 32
_z = 1.0 - (2.0 * np.arange(_K) + 1.0) / _K
_a = np.pi * (3.0 - 5.0**0.5) * np.arange(_K)
_POLES = np.stack([(1 - _z**2) ** 0.5 * np.cos(_a), (1 - _z**2) ** 0.5 * np.sin(_a), _z], axis=1)


@jax.jit
def tantrix_holonomy(t):
    """Rotation angle of parallel transport once round the closed tantrix t_0 -> ... -> t_{M-1}
    -> t_0, modulo 2 pi (the value is not reduced: add any multiple of 2 pi).

    t (M,3) unit tangents. By Gauss-Bonnet, transport round a closed chain of great-circle arcs
    rotates the frame by minus the enclosed area, a sum of signed spherical triangles (pole, t_i,
    t_i+1) (Van Oosterom-Strackee). The pole changes the sum only by multiples of 4 pi; it is
    chosen (no gradient) as far as possible from every -t_i, where triangles are ill-conditioned.
    """
    poles = jnp.asarray(_POLES, dtype=t.dtype)
    clearance = jnp.min(1.0 + t @ poles.T, axis=0)  # (K,): how close some t_i gets to -pole
    p = poles[jnp.argmax(clearance)]
    a, b = t, jnp.roll(t, -1, axis=0)
    num = jnp.cross(a, b) @ p
    den = 1.0 + a @ p + b @ p + jnp.sum(a * b, axis=-1)
    return -jnp.sum(2.0 * jnp.arctan2(num, den))


@jax.jit
def perpendicular_unit(t):
    """A unit vector perpendicular to the unit vector t (3,). Built from the coordinate axis least
    aligned with t. The choice jumps between axes, but nothing physical depends on it: energies use
    only twist *differences* and the holonomy, both independent of the starting director."""
    axes = jnp.eye(3, dtype=t.dtype)
    k = jnp.argmin(jnp.abs(t))
    e = axes[k]
    w = e - jnp.dot(e, t) * t
    return w / jnp.linalg.norm(w)


@jax.jit
def material_directors(tangents, u_ref, theta):
    """Material frame per edge from reference directors and twist angles. tangents (M,3), u_ref
    (M,3), theta (M,) -> (d1, d2, d3) each (M,3), d3 = tangent."""
    v_ref = jnp.cross(tangents, u_ref)
    c, s = jnp.cos(theta)[:, None], jnp.sin(theta)[:, None]
    d1 = c * u_ref + s * v_ref
    d2 = -s * u_ref + c * v_ref
    return d1, d2, tangents


@partial(jax.jit, static_argnames="closed")
def node_directors(x, d1_edges, closed):
    """Director d1 at the nodes: the edge directors transported to the vertex tangent and averaged,
    then projected on the plane normal to the vertex tangent and normalised. x (N,3), d1_edges (M,3)
    -> (N,3). End nodes of an open rod take their single edge's director. Used to draw the eccentric
    line (a stripe on the rod surface)."""
    e = edges(x, closed)
    t = unit(e)
    if closed:
        t_prev, d_prev = jnp.roll(t, 1, axis=0), jnp.roll(d1_edges, 1, axis=0)
        t_next, d_next = t, d1_edges
    else:
        t_prev = jnp.concatenate([t[:1], t], axis=0)
        d_prev = jnp.concatenate([d1_edges[:1], d1_edges], axis=0)
        t_next = jnp.concatenate([t, t[-1:]], axis=0)
        d_next = jnp.concatenate([d1_edges, d1_edges[-1:]], axis=0)
    t_node = unit(t_prev + t_next)
    d = parallel_transport(d_prev, t_prev, t_node) + parallel_transport(d_next, t_next, t_node)
    d = d - jnp.sum(d * t_node, axis=-1, keepdims=True) * t_node
    return unit(d)


@partial(jax.jit, static_argnames="closed")
def voronoi_lengths(rest_lengths, closed):
    """Length attached to each vertex that carries bending/twist: mean of its two edges.
    rest_lengths (M,) -> (N,) for a closed rod (vertex i between edges i-1 and i), (M-1,) for an
    open rod (interior vertices 1..M-1)."""
    if closed:
        return 0.5 * (jnp.roll(rest_lengths, 1) + rest_lengths)
    return 0.5 * (rest_lengths[:-1] + rest_lengths[1:])


def radius_of_gyration(x):
    """Root-mean-square distance (numpy float) of the nodes x (N, 3) from their centroid."""
    x = np.asarray(x)
    r = x - x.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum(r * r, axis=1))))


def resample_closed(points, n):
    """Resample a closed polyline (given as (M,3) points, last not repeating the first) to n
    points equally spaced in arc length along the polyline. Returns a numpy array (n,3)."""
    import numpy as np

    p = np.asarray(points, dtype=float)
    loop = np.vstack([p, p[:1]])
    seg = np.linalg.norm(np.diff(loop, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    targets = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.stack([np.interp(targets, s, loop[:, k]) for k in range(3)], axis=1)


def polyline_distance(a, b, closed=True):
    """Largest distance from a node of polyline ``a`` (N,3) to polyline ``b`` (M,3) (numpy). A shape
    distance blind to sliding along the centreline (a near-zero mode of loose knots)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape[0] * b.shape[0] <= 40_000:  # small rods: every node against every segment
        return float(np.max(point_polyline_distances(a, np.arange(a.shape[0]), b, None, closed)))
    # Large rods, O(N log N): the nearest segment has an end within d + h/2 of a node (d: distance to
    # b's nearest node, h: longest segment); only segments next to b's nodes within that are measured.
    from scipy.spatial import cKDTree

    tree = cKDTree(b)
    nearest, _ = tree.query(a)
    m = b.shape[0]
    seg_count = m if closed else m - 1
    h = float(np.max(np.linalg.norm(np.diff(np.concatenate([b, b[:1]]) if closed else b, axis=0), axis=1)))
    near = tree.query_ball_point(a, nearest + 0.5 * h * (1.0 + 1e-9) + 1e-300)
    node = np.concatenate([np.asarray(js, dtype=np.int64) for js in near])
    point = np.repeat(np.arange(a.shape[0]), [len(js) for js in near])
    # the segments on either side of each near node (j - 1 -> j and j -> j + 1)
    seg = np.concatenate([node, node - 1])
    point = np.concatenate([point, point])
    if closed:
        seg %= m
    else:
        ok = (seg >= 0) & (seg < seg_count)
        seg, point = seg[ok], point[ok]
    d = point_polyline_distances(a, point, b, seg, closed)
    per_point = np.full(a.shape[0], np.inf)
    np.minimum.at(per_point, point, d)
    return float(np.max(per_point))


def point_polyline_distances(a, point, b, seg, closed):
    """Distances from the nodes a[point] to segments seg of polyline b ((K,) each); seg None:
    every node of a (point = all of them) against every segment, the minimum per node."""
    b1 = np.roll(b, -1, axis=0) if closed else b[1:]
    b0 = b if closed else b[:-1]
    if seg is None:
        s0, sv = b0[None, :, :], (b1 - b0)[None, :, :]  # (1, M, 3)
        rel = a[point][:, None, :] - s0
    else:
        s0, sv = b0[seg], b1[seg] - b0[seg]
        rel = a[point] - s0
    t = np.clip(np.sum(rel * sv, axis=-1) / np.maximum(np.sum(sv * sv, axis=-1), 1e-300), 0.0, 1.0)
    d = np.linalg.norm(rel - t[..., None] * sv, axis=-1)
    return np.min(d, axis=1) if seg is None else d


def segment_distances(p0, p1, q0, q1):
    """Distances between segments [p0, p1] and [q0, q1], row by row (numpy, each (K, 3) -> (K,)):
    the closest points' parameters clamped to the segments (degenerate segments allowed)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e = np.sum(d1 * d1, axis=1), np.sum(d2 * d2, axis=1)
    b, c, f = np.sum(d1 * d2, axis=1), np.sum(d1 * r, axis=1), np.sum(d2 * r, axis=1)
    tiny = 1e-300
    denom = a * e - b * b
    # s on the first segment: unconstrained optimum where the segments are not parallel.
    s = np.where(denom > 1e-12 * np.maximum(a * e, tiny), np.clip((b * f - c * e) / np.maximum(denom, tiny), 0, 1), 0.0)
    t = (b * s + f) / np.maximum(e, tiny)
    # t outside [0, 1]: clamp it and recompute s for that end.
    t_clamped = np.clip(t, 0.0, 1.0)
    s = np.where(t != t_clamped, np.clip((b * t_clamped - c) / np.maximum(a, tiny), 0.0, 1.0), s)
    t = np.where(e > tiny, t_clamped, 0.0)
    gap = (p0 + s[:, None] * d1) - (q0 + t[:, None] * d2)
    return np.linalg.norm(gap, axis=1)


def closest_approach(x, closed=True, exclude=1):
    """Smallest distance between two segments of the polyline x (N, 3) (numpy) that are more than
    ``exclude`` segments apart along it (neighbours share a node, so are always at distance 0).
    0 means the curve passes through itself. O(N^2) time in N/2 vectorised sweeps, O(N) memory."""
    x = np.asarray(x, dtype=float)
    n_seg = x.shape[0] if closed else x.shape[0] - 1
    a0 = x[:n_seg]
    a1 = np.roll(x, -1, axis=0)[:n_seg] if closed else x[1:]
    best = np.inf
    top = n_seg // 2 if closed else n_seg - 1
    for offset in range(exclude + 1, top + 1):
        i = np.arange(n_seg) if closed else np.arange(n_seg - offset)
        j = (i + offset) % n_seg
        if i.size:
            best = min(best, float(np.min(segment_distances(a0[i], a1[i], a0[j], a1[j]))))
    return best
