"""Topological measures of discrete rods: writhe, linking number, ribbon edges.

All functions are pure ``jax.numpy`` code, jittable and differentiable, vectorised
over segment pairs by broadcasting (memory O(N*M), no Python loops over vertices).

Sign convention (standard Gauss orientation, right-hand rule):

* A right-handed helix has positive writhe.
* For a ribbon whose edge ``x + eps*d1`` turns once right-handedly about the
  tangent of a planar circle, ``linking_number(x, x + eps*d1) == +1``
  (twist +1, writhe 0), consistent with Calugareanu's ``Lk = Wr + Tw``.
* ``linking_number(x, y) == linking_number(y, x)``.

Exact polygon formulas use the solid-angle expression of Klenin & Langowski,
Biopolymers 54 (2000) 307: for two straight segments the Gauss double integral
equals the signed solid angle ``Omega`` of the quadrilateral they span, divided
by ``4 pi``.  Summing over segment pairs gives the writhe of a polygon exactly
(up to rounding) and the linking number of two disjoint closed polygons as an
integer.  Internally each segment pair's Omega is evaluated as the solid angle
of two triangles (Van Oosterom & Strackee 1983), which equals the literal KL
asin/sign expression to rounding but is smooth for coplanar pairs, so
gradients and Hessians of the writhe are also correct at planar curves
(``solid_angle_literal`` keeps the literal formula as a tested reference).
The ``*_quadrature`` functions are the plain midpoint-rule
discretisation of the same integrals; they converge only with resolution and
are kept for cross-checks against the literature that uses them.
"""
import math
from functools import partial

import jax
import jax.numpy as jnp
from jax import lax
import numpy as np

from .geometry import safe_norm

__all__ = [
    "writhe",
    "linking_number",
    "gauss_linking_quadrature",
    "writhe_quadrature",
    "eccentric_line",
    "is_whole_turns",
    "solid_angle",
    "solid_angle_literal",
]

_FOUR_PI = 4.0 * np.pi

# A fixed, non-degenerate tetrahedron substituted for masked segment pairs
# (adjacent or identical segments) *before* any arithmetic: those pairs would
# otherwise produce zero-length cross products, whose norms have NaN gradients
# that leak through a plain ``where`` into jax.grad ("double-where" trick).
# Plain numpy constants so that importing this module creates no JAX arrays.
_DUMMY = (
    np.array([0.0, 0.0, 0.0]),
    np.array([1.0, 0.0, 0.0]),
    np.array([0.0, 1.0, 0.0]),
    np.array([0.0, 0.0, 1.0]),
)


def _angle_term(a, b):
    """``asin(a_hat . b_hat)`` for non-normalised vectors a, b: (..., 3) -> (...,).

    Equal to ``asin(clip(n_a . n_b, -1, 1))`` with unit normals n, written as
    ``atan2(a.b, |a x b|)`` because
      * it is invariant under positive rescaling of a and b, so the four
        normals of the Klenin-Langowski formula need not be normalised (no
        division by possibly tiny norms);
      * asin loses accuracy and has an infinite derivative at +-1 (nearly
        coplanar segment pairs, e.g. planar curves), whereas atan2 is well
        conditioned everywhere except at a == 0 or b == 0.
    """
    dot = jnp.sum(a * b, axis=-1)
    crs = safe_norm(jnp.cross(a, b))
    # atan2(0, 0) has a NaN gradient; it only occurs for degenerate (collinear)
    # configurations, which we map to the value 0 with a zero gradient.
    degenerate = (dot == 0.0) & (crs == 0.0)
    safe_dot = jnp.where(degenerate, 1.0, dot)
    safe_crs = jnp.where(degenerate, 1.0, crs)
    return jnp.where(degenerate, 0.0, jnp.arctan2(safe_dot, safe_crs))


def solid_angle_literal(p1, p2, p3, p4):
    """Signed solid angle of segment pairs, literal Klenin-Langowski formula.

    p1, p2, p3, p4: broadcastable (..., 3) arrays (segments p1->p2, p3->p4)
    -> Omega (...,).  ``Omega / (4 pi)`` is the exact Gauss double integral
    over the two segments.

    Reference implementation only (used by the tests): its value is exact, but
    ``Omega* * sign(h)`` is a product of a cone ``|h|`` and a step in the
    out-of-plane height h, so automatic differentiation returns 0 instead of
    the true derivative for coplanar segment pairs -- i.e. wrong gradients and
    Hessians of the writhe of *planar* curves, exactly where ring buckling
    starts.  ``solid_angle`` computes the same number smoothly.
    """
    r13 = p3 - p1
    r14 = p4 - p1
    r23 = p3 - p2
    r24 = p4 - p2
    n1 = jnp.cross(r13, r14)
    n2 = jnp.cross(r14, r24)
    n3 = jnp.cross(r24, r23)
    n4 = jnp.cross(r23, r13)
    omega_star = (
        _angle_term(n1, n2) + _angle_term(n2, n3) + _angle_term(n3, n4) + _angle_term(n4, n1)
    )
    r34 = p4 - p3
    r12 = p2 - p1
    # The triple product fixes the orientation; with this sign the result
    # matches the standard Gauss integrand (r_i - r_j).(dr_i x dr_j)/|r_i - r_j|^3
    # (checked against the midpoint quadrature and the helix/ribbon tests).
    s = jnp.sign(jnp.sum(jnp.cross(r34, r12) * r13, axis=-1))
    return omega_star * s


def _triangle_solid_angle(a, b, c):
    """Signed solid angle subtended at the origin by the triangle (a, b, c).

    a, b, c: (..., 3) -> (...,), in (-2 pi, 2 pi), with the sign of a.(b x c).
    Van Oosterom & Strackee (1983):
        tan(Omega/2) = a.(b x c) / (|a||b||c| + (a.b)|c| + (a.c)|b| + (b.c)|a|),
    evaluated with atan2 so the full range is covered.  Smooth wherever the
    triangle does not contain the origin: the numerator carries the sign
    linearly, so coplanar configurations are not special.
    """
    la, lb, lc = safe_norm(a), safe_norm(b), safe_norm(c)
    num = jnp.sum(a * jnp.cross(b, c), axis=-1)
    den = (
        la * lb * lc
        + jnp.sum(a * b, axis=-1) * lc
        + jnp.sum(a * c, axis=-1) * lb
        + jnp.sum(b * c, axis=-1) * la
    )
    # (num, den) == (0, 0) only for degenerate triangles (origin on an edge:
    # touching segments); give them 0 with a finite (zero) gradient.
    degenerate = (num == 0.0) & (den == 0.0)
    return jnp.where(
        degenerate,
        0.0,
        2.0 * jnp.arctan2(jnp.where(degenerate, 0.0, num), jnp.where(degenerate, 1.0, den)),
    )


def solid_angle(p1, p2, p3, p4):
    """Signed Klenin-Langowski solid angle Omega of segment pairs, smooth form.

    p1, p2, p3, p4: broadcastable (..., 3) arrays (segments p1->p2 and p3->p4)
    -> Omega (...,), identical in value to ``solid_angle_literal`` (tested to
    1e-12) so that ``Omega / (4 pi)`` is the exact Gauss double integral.

    Why a different expression: the Gauss integral over two segments is the
    signed solid angle, seen from the origin, of the parallelogram of
    difference vectors {q - p : p on segment 1, q on segment 2}, with corners
    r13, r14, r24, r23 -- the same quadrilateral whose spherical angles the KL
    formula sums.  Splitting it into the triangles (r13, r14, r24) and
    (r13, r24, r23) and using the Van Oosterom-Strackee formula gives the same
    number, but the orientation sign enters through a triple product
    (linearly) rather than through sign(), so the result is analytic for all
    disjoint segment pairs, including coplanar ones, and jax.grad / jax.hessian
    are correct for planar curves.  For disjoint segments the parallelogram
    does not contain the origin, so neither triangle does either (no branch
    cut of atan2 is crossed).
    """
    r13 = p3 - p1
    r14 = p4 - p1
    r23 = p3 - p2
    r24 = p4 - p2
    # Orientation: the parallelogram traversed r13 -> r14 -> r24 -> r23 has
    # the orientation that makes the result equal to the KL Omega with the
    # sign sign((r34 x r12).r13); hence the overall minus (checked in tests).
    return -(_triangle_solid_angle(r13, r14, r24) + _triangle_solid_angle(r13, r24, r23))


def _segments(x, closed):
    """Segment start and end points of a polygon.

    x: (N, 3) -> (start, end), each (N, 3) if closed else (N-1, 3).
    """
    if closed:
        return x, jnp.roll(x, -1, axis=0)
    return x[:-1], x[1:]


def _pair_sum(a0, a1, b0, b1, mask):
    """Sum of Omega over all pairs (segment i of a, segment j of b) not masked.

    a0, a1: (N, 3); b0, b1: (M, 3); mask: (N, M) bool (True = skip) or None.
    Returns a scalar: sum_ij Omega_ij (not yet divided by 4 pi).
    """
    p1 = a0[:, None, :]
    p2 = a1[:, None, :]
    p3 = b0[None, :, :]
    p4 = b1[None, :, :]
    shape = (a0.shape[0], b0.shape[0], 3)
    p1, p2, p3, p4 = (jnp.broadcast_to(p, shape) for p in (p1, p2, p3, p4))
    if mask is None:
        return jnp.sum(solid_angle(p1, p2, p3, p4))
    m = mask[:, :, None]
    # Double-where: masked pairs are evaluated on a harmless dummy geometry so
    # neither the value nor the gradient of the discarded branch can be NaN.
    q = [jnp.where(m, d, p) for d, p in zip(_DUMMY, (p1, p2, p3, p4))]
    omega = solid_angle(*q)
    return jnp.sum(jnp.where(mask, 0.0, omega))


# Offsets per lax.map block in ``writhe``: 64 x N pairs at a time (~6 MB at N = 1024) keeps the
# working set in cache; a single (N, N) block was 4.5x slower at N = 1024 (memory bound).
_WRITHE_CHUNK = 64


@partial(jax.jit, static_argnames="closed")
def writhe(x, closed=True):
    """Exact writhe of a polygon (Klenin & Langowski 2000 solid-angle formula).

    Args:
      x: (N, 3) vertices.  If ``closed`` the N edges are x[k] -> x[k+1] with
        x[N-1] -> x[0]; otherwise the N-1 edges x[k] -> x[k+1].
      closed: static bool.

    Returns:
      scalar Wr = sum over ordered pairs i != j of Omega_ij / (4 pi), adjacent
      segments (sharing a vertex) contributing 0 (their Gauss integral vanishes:
      both lie in one plane).  Positive for a right-handed helix.

    How: Omega is symmetric, so each unordered pair is evaluated once, by cyclic
    offset d = j - i (mod n) over the n segments: offsets 2 ... n // 2 hold every
    non-adjacent pair of a closed polygon once (offset n / 2, n even, twice).  For
    an open polygon the same offsets hold every non-adjacent pair except (0, n-1),
    which is added (cyclic offset d pairs segments d and n - d apart along the rod,
    both >= 2).  O(N^2) time, O(N) memory per block of offsets.
    """
    x = jnp.asarray(x)
    a0, a1 = _segments(x, closed)
    n = a0.shape[0]
    total = jnp.zeros((), x.dtype)
    offsets = np.arange(2, n // 2 + 1)
    if offsets.size:
        # Pairs at offset d are counted for both orders (weight 2), except d = n/2, whose
        # i-sum already holds each pair twice.
        weights = np.where(2 * offsets == n, 1.0, 2.0)
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
    """Exact Gauss linking number of two closed polygons.

    Args:
      x: (N, 3) vertices of the first closed polygon.
      y: (M, 3) vertices of the second closed polygon.

    Returns:
      scalar sum_{i in x, j in y} Omega_ij / (4 pi); an integer (to rounding,
      ~1e-12) when the polygons are disjoint.  Symmetric: Lk(x, y) == Lk(y, x).
    """
    a0, a1 = _segments(jnp.asarray(x), True)
    b0, b1 = _segments(jnp.asarray(y), True)
    return _pair_sum(a0, a1, b0, b1, None) / _FOUR_PI


def _gauss_integrand(x, y):
    """Midpoint-rule Gauss integrand terms for closed polygons x (N,3), y (M,3).

    Returns (num, dist) with num (N, M) = (r_i - r_j).(dr_i x dr_j) and
    dist (N, M) = |r_i - r_j|, r = segment midpoints, dr = segment vectors.
    """
    xa, xb = _segments(x, True)
    ya, yb = _segments(y, True)
    rx, dx = 0.5 * (xa + xb), xb - xa
    ry, dy = 0.5 * (ya + yb), yb - ya
    rij = rx[:, None, :] - ry[None, :, :]
    num = jnp.sum(rij * jnp.cross(dx[:, None, :], dy[None, :, :]), axis=-1)
    return num, rij


@jax.jit
def gauss_linking_quadrature(x, y):
    """Midpoint-rule estimate of the Gauss linking integral of two closed polygons.

    Lk ~= (1/4pi) sum_i sum_j (r_i - r_j).(dr_i x dr_j) / |r_i - r_j|^3 with r
    the segment midpoints and dr the segment vectors.  Not an integer: its error
    is a quadrature error that shrinks (second order) with resolution.

    Args:
      x: (N, 3), y: (M, 3) vertices of closed polygons.

    Returns:
      scalar estimate of Lk(x, y).
    """
    x, y = jnp.asarray(x), jnp.asarray(y)
    num, rij = _gauss_integrand(x, y)
    dist = jnp.linalg.norm(rij, axis=-1)
    return jnp.sum(num / dist**3) / _FOUR_PI


@jax.jit
def writhe_quadrature(x):
    """Midpoint-rule estimate of the writhe of one closed polygon (cross-checks).

    Wr ~= (1/4pi) sum_{i != j} (r_i - r_j).(dr_i x dr_j) / |r_i - r_j|^3.

    Args:
      x: (N, 3) vertices of a closed polygon.

    Returns:
      scalar estimate of Wr(x).
    """
    x = jnp.asarray(x)
    num, rij = _gauss_integrand(x, x)
    n = x.shape[0]
    diag = jnp.eye(n, dtype=bool)
    # i == j has rij == 0: replace the distance before dividing (double-where)
    # so both value and gradient stay finite, then drop the term.
    dist = jnp.where(diag, 1.0, safe_norm(jnp.where(diag[:, :, None], 1.0, rij)))
    return jnp.sum(jnp.where(diag, 0.0, num / dist**3)) / _FOUR_PI


@jax.jit
def eccentric_line(x, d1, offset):
    """Line offset from the centreline along the first director (ribbon edge).

    Args:
      x: (N, 3) centreline nodes.
      d1: (N, 3) unit normal (material) vectors at the nodes.
      offset: scalar (or broadcastable (N, 1)) offset distance.

    Returns:
      (N, 3) array x + offset * d1.
    """
    return jnp.asarray(x) + offset * jnp.asarray(d1)


# phi / 2pi within this many turns of an integer counts as a whole number of turns.
WHOLE_TURN_TOL = 1e-9


def is_whole_turns(phi, tol=WHOLE_TURN_TOL):
    """Whether the imposed twist phi (radians) is a whole number of turns (within ``tol`` turns):
    only then does a line drawn on the rod before its ends were turned and glued close at the
    joint, and its Gauss linking number with the centreline exist."""
    turns = float(phi) / (2.0 * math.pi)
    return abs(turns - round(turns)) <= tol
