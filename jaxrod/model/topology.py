"""Topological measures of discrete rods: writhe, linking number, ribbon edges.

All functions are pure ``jax.numpy`` code, jittable and differentiable. Sign convention (right-hand
rule): a right-handed helix has positive writhe; a ribbon edge ``x + eps*d1`` turning once
right-handedly about a planar circle has ``linking_number(x, x + eps*d1) == +1``.

Exact polygon formulas use the solid-angle expression of Klenin & Langowski, Biopolymers 54
(2000) 307: the Gauss double integral over two straight segments is their signed solid angle
``Omega`` / 4 pi, so the writhe of a polygon is exact and the linking number of disjoint closed
polygons an integer. Omega is evaluated as two Van Oosterom-Strackee triangles, smooth for
coplanar pairs (``solid_angle_literal`` keeps the literal formula as a tested reference). The
``*_quadrature`` functions are midpoint-rule discretisations, kept for cross-checks.
"""
import math
from functools import partial

import jax
import jax.numpy as jnp
from jax import lax
import numpy as np

from .geometry import safe_norm

__all__ = ["writhe", "linking_number", "gauss_linking_quadrature", "writhe_quadrature", "eccentric_line",
           "is_whole_turns", "solid_angle", "solid_angle_literal"]

_FOUR_PI = 4.0 * np.pi

# A fixed, non-degenerate tetrahedron substituted for masked segment pairs before any arithmetic
# (their zero cross products would leak NaN gradients through a plain ``where``). Plain numpy.
_DUMMY = (np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))


def _angle_term(a, b):
    """``asin(a_hat . b_hat)`` for non-normalised vectors a, b: (..., 3) -> (...,), as ``atan2(a.b,
    |a x b|)``: scale-invariant (no normalisation) and well conditioned near +-1."""
    dot = jnp.sum(a * b, axis=-1)
    crs = safe_norm(jnp.cross(a, b))
    # atan2(0, 0) has a NaN gradient: degenerate (collinear) configurations give 0, zero gradient.
    degenerate = (dot == 0.0) & (crs == 0.0)
    safe_dot = jnp.where(degenerate, 1.0, dot)
    safe_crs = jnp.where(degenerate, 1.0, crs)
    return jnp.where(degenerate, 0.0, jnp.arctan2(safe_dot, safe_crs))


def solid_angle_literal(p1, p2, p3, p4):
    """Signed solid angle of segment pairs, literal Klenin-Langowski formula. p1, p2, p3, p4:
    broadcastable (..., 3) arrays (segments p1->p2, p3->p4) -> Omega (...,). Reference
    implementation for the tests: exact, but its sign(h) factor gives wrong gradients for coplanar
    segment pairs (planar curves); ``solid_angle`` computes the same number smoothly."""
    r13 = p3 - p1
    r14 = p4 - p1
    r23 = p3 - p2
    r24 = p4 - p2
    n1 = jnp.cross(r13, r14)
    n2 = jnp.cross(r14, r24)
    n3 = jnp.cross(r24, r23)
    n4 = jnp.cross(r23, r13)
    omega_star = (_angle_term(n1, n2) + _angle_term(n2, n3) + _angle_term(n3, n4) + _angle_term(n4, n1))
    r34 = p4 - p3
    r12 = p2 - p1
    # The triple product fixes the orientation to match the standard Gauss integrand.
    s = jnp.sign(jnp.sum(jnp.cross(r34, r12) * r13, axis=-1))
    return omega_star * s


def _triangle_solid_angle(a, b, c, xp=jnp):
    """Signed solid angle subtended at the origin by the triangle (a, b, c). a, b, c: (..., 3) ->
    (...,), in (-2 pi, 2 pi), with the sign of a.(b x c). Van Oosterom & Strackee (1983):
    tan(Omega/2) = a.(b x c) / (|a||b||c| + (a.b)|c| + (a.c)|b| + (b.c)|a|), via atan2; smooth
    wherever the triangle does not contain the origin. ``xp``: jax.numpy, or numpy on the host."""
    norm = safe_norm if xp is jnp else (lambda v: np.sqrt(np.sum(v * v, axis=-1)))
    la, lb, lc = norm(a), norm(b), norm(c)
    num = xp.sum(a * xp.cross(b, c), axis=-1)
    den = (la * lb * lc + xp.sum(a * b, axis=-1) * lc + xp.sum(a * c, axis=-1) * lb + xp.sum(b * c, axis=-1) * la)
    # (num, den) == (0, 0) only for degenerate triangles (touching segments): 0, zero gradient.
    degenerate = (num == 0.0) & (den == 0.0)
    return xp.where(
        degenerate,
        0.0,
        2.0 * xp.arctan2(xp.where(degenerate, 0.0, num), xp.where(degenerate, 1.0, den)),
    )


def solid_angle(p1, p2, p3, p4, xp=jnp):
    """Signed Klenin-Langowski solid angle Omega of segment pairs, smooth form.

    p1, p2, p3, p4: broadcastable (..., 3) arrays (segments p1->p2 and p3->p4) -> Omega (...,),
    equal to ``solid_angle_literal`` (tested to 1e-12). ``xp``: jax.numpy, or numpy on the host.

    The Gauss integral over two segments is the signed solid angle of the parallelogram of
    difference vectors (corners r13, r14, r24, r23); split into two Van Oosterom-Strackee
    triangles, the orientation enters linearly (not through sign()), so the result is analytic
    for all disjoint segment pairs, coplanar ones included, and jax.grad / jax.hessian are
    correct for planar curves.
    """
    r13 = p3 - p1
    r14 = p4 - p1
    r23 = p3 - p2
    r24 = p4 - p2
    # Orientation: the overall minus gives the KL Omega's sign sign((r34 x r12).r13) (tested).
    return -(_triangle_solid_angle(r13, r14, r24, xp) + _triangle_solid_angle(r13, r24, r23, xp))


def _segments(x, closed, xp=jnp):
    """Segment start and end points of a polygon x (N, 3): each (N, 3) if closed else (N-1, 3)."""
    if closed:
        return x, xp.roll(x, -1, axis=0)
    return x[:-1], x[1:]


def _pair_sum(a0, a1, b0, b1, mask):
    """Sum (scalar, not yet divided by 4 pi) of Omega over all pairs (segment i of a, segment j of
    b) not masked; a0, a1: (N, 3); b0, b1: (M, 3); mask: (N, M) bool (True = skip) or None."""
    p1 = a0[:, None, :]
    p2 = a1[:, None, :]
    p3 = b0[None, :, :]
    p4 = b1[None, :, :]
    shape = (a0.shape[0], b0.shape[0], 3)
    p1, p2, p3, p4 = (jnp.broadcast_to(p, shape) for p in (p1, p2, p3, p4))
    if mask is None:
        return jnp.sum(solid_angle(p1, p2, p3, p4))
    m = mask[:, :, None]
    # Double-where: masked pairs are evaluated on a dummy geometry (no NaN value or gradient).
    q = [jnp.where(m, d, p) for d, p in zip(_DUMMY, (p1, p2, p3, p4))]
    omega = solid_angle(*q)
    return jnp.sum(jnp.where(mask, 0.0, omega))


# Up to this many vertices a concrete polygon's writhe is summed by NumPy: 4 ms at N = 121, where
# compiling the JAX program for a new N takes about 150 ms (each node count is its own program);
# at N = 961 NumPy takes 170 ms against 55 ms compiled, so large rods, whose runs are long, compile.
HOST_WRITHE_MAX_NODES = 300

# Offsets per lax.map block in ``writhe``: 64 x N pairs at a time keeps the working set in cache.
_WRITHE_CHUNK = 64


def writhe(x, closed=True):
    """Exact writhe of a polygon (Klenin & Langowski 2000 solid-angle formula).

    Args:
      x: (N, 3) vertices.  If ``closed`` the N edges are x[k] -> x[k+1] with x[N-1] -> x[0];
        otherwise the N-1 edges x[k] -> x[k+1].
      closed: bool.

    Returns:
      scalar Wr = sum over ordered pairs i != j of Omega_ij / (4 pi), adjacent segments
      contributing 0.  Positive for a right-handed helix.

    How: Omega is symmetric, so each unordered pair is evaluated once, by cyclic offset
    d = j - i (mod n): offsets 2 ... n // 2 hold every non-adjacent pair of a closed polygon once
    (offset n / 2, n even, twice); an open polygon also needs the pair (0, n-1), added.
    O(N^2) time, O(N) memory per block of offsets. Inside a JAX trace (jit, grad, vmap), and for
    polygons of more than ``HOST_WRITHE_MAX_NODES`` vertices, it is compiled JAX code; a smaller
    concrete polygon is summed by NumPy on the host (a float), the same pairs in the same blocks.
    """
    if isinstance(x, jax.core.Tracer) or np.shape(x)[0] > HOST_WRITHE_MAX_NODES:
        return _writhe_traced(x, closed=closed)
    x = np.asarray(x, dtype=float)
    a0, a1 = _segments(x, closed, np)
    n = a0.shape[0]
    i = np.arange(n)
    total = 0.0
    for first in range(2, n // 2 + 1, _WRITHE_CHUNK):
        d = np.arange(first, min(first + _WRITHE_CHUNK, n // 2 + 1))
        j = (i[None, :] + d[:, None]) % n
        omega = solid_angle(a0[None], a1[None], a0[j], a1[j], xp=np)
        total += float(np.sum(omega * _offset_weights(d, n)[:, None]))
    if not closed and n >= 3:
        total += 2.0 * float(solid_angle(a0[0], a1[0], a0[n - 1], a1[n - 1], xp=np))
    return total / _FOUR_PI


def _offset_weights(offsets, n):
    """Pairs at offset d are counted for both orders (weight 2), except d = n/2, whose i-sum
    already holds each pair twice."""
    return np.where(2 * offsets == n, 1.0, 2.0)


@partial(jax.jit, static_argnames="closed")
def _writhe_traced(x, closed=True):
    """``writhe`` as JAX code (differentiable, for traced x)."""
    x = jnp.asarray(x)
    a0, a1 = _segments(x, closed)
    n = a0.shape[0]
    total = jnp.zeros((), x.dtype)
    offsets = np.arange(2, n // 2 + 1)
    if offsets.size:
        weights = _offset_weights(offsets, n)
        pad = (-offsets.size) % _WRITHE_CHUNK
        offsets = np.concatenate([offsets, np.full(pad, 2)]).reshape(-1, _WRITHE_CHUNK)
        weights = np.concatenate([weights, np.zeros(pad)]).reshape(-1, _WRITHE_CHUNK)
        i = np.arange(n)

        def block(args):
            d, w = args
            j = (i[None, :] + d[:, None]) % n
            shape = j.shape + (3,)
            omega = solid_angle(*(jnp.broadcast_to(p, shape) for p in (a0[None], a1[None], a0[j], a1[j])))
            return jnp.sum(omega * w[:, None].astype(x.dtype))

        total = jnp.sum(lax.map(block, (jnp.asarray(offsets), jnp.asarray(weights))))
    if not closed and n >= 3:
        total = total + 2.0 * solid_angle(a0[0], a1[0], a0[n - 1], a1[n - 1])
    return total / _FOUR_PI


@jax.jit
def linking_number(x, y):
    """Exact Gauss linking number (scalar) of two closed polygons x (N, 3), y (M, 3): the sum of
    Omega_ij / (4 pi), an integer (to ~1e-12) when they are disjoint; symmetric in x, y."""
    a0, a1 = _segments(jnp.asarray(x), True)
    b0, b1 = _segments(jnp.asarray(y), True)
    return _pair_sum(a0, a1, b0, b1, None) / _FOUR_PI


def _gauss_integrand(x, y):
    """Midpoint-rule Gauss integrand terms for closed polygons x (N,3), y (M,3): (num, rij), num
    (N, M) = (r_i - r_j).(dr_i x dr_j), rij (N, M, 3) = r_i - r_j (r midpoints, dr segment vectors)."""
    xa, xb = _segments(x, True)
    ya, yb = _segments(y, True)
    rx, dx = 0.5 * (xa + xb), xb - xa
    ry, dy = 0.5 * (ya + yb), yb - ya
    rij = rx[:, None, :] - ry[None, :, :]
    num = jnp.sum(rij * jnp.cross(dx[:, None, :], dy[None, :, :]), axis=-1)
    return num, rij


@jax.jit
def gauss_linking_quadrature(x, y):
    """Midpoint-rule estimate (scalar) of the Gauss linking integral of two closed polygons x (N, 3),
    y (M, 3): Lk ~= (1/4pi) sum_i sum_j (r_i - r_j).(dr_i x dr_j) / |r_i - r_j|^3, r the segment
    midpoints, dr the segment vectors; not an integer (second-order quadrature error)."""
    x, y = jnp.asarray(x), jnp.asarray(y)
    num, rij = _gauss_integrand(x, y)
    dist = jnp.linalg.norm(rij, axis=-1)
    return jnp.sum(num / dist**3) / _FOUR_PI


@jax.jit
def writhe_quadrature(x):
    """Midpoint-rule estimate (scalar) of the writhe of one closed polygon x (N, 3) (cross-checks):
    Wr ~= (1/4pi) sum_{i != j} (r_i - r_j).(dr_i x dr_j) / |r_i - r_j|^3."""
    x = jnp.asarray(x)
    num, rij = _gauss_integrand(x, x)
    n = x.shape[0]
    diag = jnp.eye(n, dtype=bool)
    # i == j has rij == 0: replace the distance before dividing (double-where), then drop the term.
    dist = jnp.where(diag, 1.0, safe_norm(jnp.where(diag[:, :, None], 1.0, rij)))
    return jnp.sum(jnp.where(diag, 0.0, num / dist**3)) / _FOUR_PI


@jax.jit
def eccentric_line(x, d1, offset):
    """Line x + offset * d1 (N, 3) offset from the centreline x (N, 3) along the unit material
    vectors d1 (N, 3) (a ribbon edge); offset a scalar or broadcastable (N, 1)."""
    return jnp.asarray(x) + offset * jnp.asarray(d1)


# phi / 2pi within this many turns of an integer counts as a whole number of turns.
WHOLE_TURN_TOL = 1e-9


def is_whole_turns(phi, tol=WHOLE_TURN_TOL):
    """Whether the imposed twist phi (radians) is a whole number of turns (within ``tol`` turns):
    only then does a line drawn on the rod before its ends were turned and glued close at the
    joint, and its Gauss linking number with the centreline exist."""
    turns = float(phi) / (2.0 * math.pi)
    return abs(turns - round(turns)) <= tol
