"""Boundary conditions and scenes: which degrees of freedom are free, how imposed twist enters,
which energy terms are summed.

A scene maps a flat vector of free degrees of freedom ``q`` and the imposed twist ``phi`` to the
full rod state (nodes ``x`` (N,3), edge twist angles ``theta`` (M,)) and to its energy. All its
methods are pure JAX functions of ``(q, phi)``; the scene object itself only holds constants, so
``scene.energy`` can be passed to ``jax.jit``/``jax.grad``/``jax.hessian`` directly.

Imposed twist without hidden state
----------------------------------
Reference frames are space-parallel (``jaxrod.model.geometry``), so the only geometric twist is the
holonomy of parallel transport, which is known from atan2 only modulo 2 pi. Its branch is fixed
by the Calugareanu-White relation Lk = Wr + Tw: for a closed rod the joint's reference twist
must equal 2 pi (Lk0 - Wr(x)) up to rounding, with Wr the exact polygon writhe. The code takes the
atan2 value plus 2 pi times the integer nearest to the difference (with the gradient stopped;
an integer has none). The result is single-valued and smooth in (x, theta, phi) for any phi,
as long as the rod does not pass through itself, and its derivatives stay local and cheap
(the writhe itself is never differentiated). A clamped rod uses the writhe of the rod extended
by two long rays along the clamp axis (the standard closure for a rod held at both ends).
"""
from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np

from . import energy as E
from .geometry import (
    closest_approach,
    edges,
    material_directors,
    node_directors,
    perpendicular_unit,
    resample_closed,
    tantrix_holonomy,
    transport_along,
    unit,
    voronoi_lengths,
)
from .material import Material
from ..validation import check_finite, check_int_at_least, check_positive
from .contact import contact_energy
from .neighbourhood import Neighbourhood, build_neighbourhood
from .topology import writhe

__all__ = [
    "Scene",
    "ClosedRod",
    "ClampedRod",
    "FreeRod",
    "ring",
    "michell_ring",
    "closed_curve",
    "clamped_rod",
    "free_rod",
    "michell_critical_twist",
    "clamped_critical_twist",
    "trefoil",
    "knot",
    "knot_points",
    "IDEAL_ROPELENGTH",
    "trefoil_points",
    "torus_knot",
    "IDEAL_TREFOIL_ROPELENGTH",
]

TWO_PI = 2.0 * math.pi


def michell_critical_twist(nu):
    """Michell's critical total twist of a ring: 2 pi sqrt(3) B/C = 2 pi sqrt(3) (1 + nu)."""
    return TWO_PI * math.sqrt(3.0) * (1.0 + nu)


def clamped_critical_twist(B, C):
    """Critical twist of a straight rod clamped at both ends at fixed distance (no tension):
    the end moment M = C phi / L reaches M L / B = 8.9868 (twice the first positive root of
    tan x = x), so phi* = 8.9868 B / C."""
    x = 4.493409457909064  # first positive root of tan x = x
    return 2.0 * x * B / C


def _lift(raw, target):
    """raw + 2 pi k with k the integer nearest (target - raw)/(2 pi); k carries no gradient."""
    k = jnp.round(jax.lax.stop_gradient((target - raw) / TWO_PI))
    return raw + TWO_PI * k


def _scale_vector(xp, length_scale, n_x, n_dof):
    """The per-DOF scale (n_dof,): the n_x node coordinates scaled by length_scale, angles by 1;
    built with the array module xp (numpy on the host, jax.numpy otherwise)."""
    return xp.concatenate([xp.full(n_x, 1.0) * length_scale, xp.ones(n_dof - n_x)])


# ``Scene.dof_scale`` as one compiled program per shape (it is also built outside jit).
_scale_vector_jit = jax.jit(functools.partial(_scale_vector, jnp), static_argnums=(1, 2))


def _pytree(data_fields, meta_fields=()):
    """Register a frozen dataclass as a JAX pytree: array fields are leaves (so scenes of equal
    shapes share compiled code, and material parameters can be differentiated), the rest is
    static. Unflattening bypasses __init__ so validation never sees tracers."""

    def wrap(cls):
        def flatten(obj):
            return [getattr(obj, f) for f in data_fields], tuple(getattr(obj, f) for f in meta_fields)

        def unflatten(aux, children):
            obj = object.__new__(cls)
            for f, v in zip(data_fields, children):
                object.__setattr__(obj, f, v)
            for f, v in zip(meta_fields, aux):
                object.__setattr__(obj, f, v)
            return obj

        jax.tree_util.register_pytree_node(cls, flatten, unflatten)
        return cls

    return wrap


@dataclass(frozen=True, eq=False)
class Scene:
    """Base class. Subclasses define the DOF layout and the vertex twists.

    Attributes
    ----------
    material: Material (a pytree: B, C, EA, D are leaves)
    rest_lengths: (M,) rest length of each edge.
    q_init: (n,) an initial state of the free DOFs.
    terms: names of the energy terms this scene sums.
    """

    # Gauss points per segment in the contact integral (``contact.contact_energy``). 2 suffices
    # where strands touch along lengths of several edges; scenes with short crossing contacts at
    # edges near D (an open knot pulled tight) set 3 (``endloads.shortened_rod(contact_quadrature=3)``).
    contact_quadrature = 2

    material: Material
    rest_lengths: np.ndarray
    q_init: np.ndarray
    terms: tuple = ("stretch", "bend", "twist")
    name: str = "rod"

    closed = False  # class constants, not fields
    n_zero_modes = 0

    # ------------------------------------------------------------------ layout
    @property
    def n_nodes(self):
        m = self.rest_lengths.shape[0]
        return m if self.closed else m + 1

    @property
    def length(self):
        """Rest length of the rod."""
        return jnp.sum(self.rest_lengths)

    @property
    def voronoi(self):
        """(K,) rest length attached to each bending/twist vertex."""
        return voronoi_lengths(self.rest_lengths, self.closed)

    @property
    def n_dof(self):
        return int(self.q_init.shape[0])

    @property
    def length_scale(self):
        """Mean edge length: unit of node displacements in the scaled variables."""
        return jnp.mean(self.rest_lengths)

    @property
    def energy_scale(self):
        """B / (edge length): unit of energy in the scaled variables."""
        return self.material.B / self.length_scale

    def unpack(self, q, phi, nbr=None):
        """Full state: x (N,3), theta (M,). ``nbr`` (a ``Neighbourhood``), where given, supplies
        the writhe that fixes the holonomy's 2 pi branch instead of computing it (O(N^2))."""
        raise NotImplementedError

    def vertex_twists(self, q, phi, nbr=None):
        """Twist angle m (K,) across each vertex (radians), the imposed twist included."""
        raise NotImplementedError

    def positions(self, q):
        """Node positions x (N,3) of the state q (no twist angles, no holonomy: cheap)."""
        n = self.n_nodes
        return q[: 3 * n].reshape(n, 3)

    def _writhe_for_lift(self, x, nbr):
        """The writhe that fixes the holonomy's branch: frozen in ``nbr`` or computed exactly."""
        return self.exact_writhe(x) if nbr is None else nbr.wr_ref

    def exact_writhe(self, x):
        """Exact polygon writhe of the nodes x (N,3) (closed) or of the extended centreline (clamped)."""
        return writhe(x, closed=self.closed)

    # ------------------------------------------------------------------ neighbourhood
    def neighbourhood(self, q, phi=0.0, skin=None, capacity=None):
        """The ``Neighbourhood`` of state q (physical DOFs): contact candidate pairs (if the scene
        has contact) and the exact writhe, built outside jit. ``capacity``: pad the pair list to
        at least this many rows (reuse compiled code across rebuilds)."""
        x = np.asarray(self.positions(np.asarray(q)))
        wr = float(self.exact_writhe(jnp.asarray(x)))
        D = None if self.material.D is None else float(self.material.D)
        return build_neighbourhood(x, wr, self.closed, float(np.mean(np.asarray(self.rest_lengths))), D,
                                   "contact" in self.terms, skin=skin, capacity=capacity)

    @property
    def n_free_nodes(self):
        return self.n_nodes

    @property
    def dof_scale(self):
        """Per-DOF scale (n,): free node coordinates in units of edge length, angles in radians."""
        return _scale_vector_jit(self.length_scale, 3 * self.n_free_nodes, self.n_dof)

    # ------------------------------------------------------------------ energy
    def energy_terms(self, q, phi, nbr=None, terms=None):
        """Dict of the scene's energy terms at (q, phi). Without ``nbr`` the exact energy (writhe
        computed, contact over all pairs: O(N^2)); with a valid ``nbr`` the same value in O(N)
        (see ``jaxrod.model.neighbourhood``). ``terms``: a subset of the scene's terms to evaluate."""
        terms = self.terms if terms is None else terms
        x, _ = self.unpack(q, phi, nbr)
        m = self.material
        vor = self.voronoi
        out = {}
        if "stretch" in terms:
            out["stretch"] = E.stretch_energy(x, self.rest_lengths, m.EA, self.closed)
        if "bend" in terms:
            out["bend"] = E.bend_energy(x, vor, m.B, self.closed)
        if "twist" in terms:
            out["twist"] = E.twist_energy(self.vertex_twists(q, phi, nbr), vor, m.C)
        if "contact" in terms and "contact" in self.terms:
            pairs, mask = self.contact_candidates(nbr)
            out["contact"] = contact_energy(x, pairs, mask, self.closed, m.D, m.B, self.contact_stiffness,
                                            self.contact_quadrature)
        return out

    def contact_candidates(self, nbr=None):
        """(pairs (P,2), mask (P,)): the neighbourhood's candidate list, or every pair further
        apart along the rod than pi D/2 (the exact energy's list) when nbr is None."""
        if nbr is not None:
            return nbr.pairs, nbr.mask
        n_edges = self.rest_lengths.shape[0]
        i, j = np.triu_indices(n_edges, k=1)
        sep = np.abs(i - j)
        if self.closed:
            sep = np.minimum(sep, n_edges - sep)
        gap = jnp.maximum(1.0, jnp.ceil(math.pi * self.material.D / 2.0 / self.length_scale))
        return jnp.asarray(np.stack([i, j], axis=1), dtype=jnp.int32), jnp.asarray(sep) > gap

    def energy(self, q, phi, nbr=None):
        """Total energy (scalar) at free DOFs q (n,) and imposed twist phi (``nbr``: see energy_terms)."""
        return sum(self.energy_terms(q, phi, nbr).values())

    def scaled_energy(self, u, phi, nbr=None):
        """Energy in units of ``energy_scale`` of scaled DOFs u = q / dof_scale.

        Solvers and the stability analysis work on this function, so that their tolerances
        and eigenvalues are dimensionless and comparable across materials and resolutions.
        """
        return self.energy(u * self.dof_scale, phi, nbr) / self.energy_scale

    def _host_dof_scale(self):
        """``dof_scale`` as a numpy array, or None inside a trace (the scene's arrays abstract)."""
        try:
            h = float(np.mean(np.asarray(self.rest_lengths)))
        except jax.errors.TracerArrayConversionError:
            return None
        return _scale_vector(np, h, 3 * self.n_free_nodes, self.n_dof)

    def to_scaled(self, q):
        """Scaled DOFs u = q / dof_scale (numpy in, numpy out: no device dispatch per call)."""
        if isinstance(q, np.ndarray):
            scale = self._host_dof_scale()
            if scale is not None:
                return q / scale
        return q / self.dof_scale

    def from_scaled(self, u):
        """Physical DOFs q = u * dof_scale (numpy in, numpy out)."""
        if isinstance(u, np.ndarray):
            scale = self._host_dof_scale()
            if scale is not None:
                return u * scale
        return u * self.dof_scale

    # ------------------------------------------------------------------ frames, topology
    def reference_directors(self, x):
        """Space-parallel reference directors u (M,3) of the edges."""
        raise NotImplementedError

    def material_frames(self, q, phi, nbr=None):
        """Material frames (d1, d2, d3), each (M,3), of the edges."""
        x, theta = self.unpack(q, phi, nbr)
        t = unit(edges(x, self.closed))
        return material_directors(t, self.reference_directors(x), theta)

    def eccentric_line(self, q, phi, offset=None, nbr=None):
        """A line drawn on the rod surface: nodes displaced by ``offset`` (default D/2, or a
        tenth of the mean edge if D is unknown) along the material director d1 carried to the
        nodes. (N,3). With the centreline it forms the ribbon whose Gauss linking number is Lk."""
        x, _ = self.unpack(q, phi, nbr)
        d1, _, _ = self.material_frames(q, phi, nbr)
        if offset is None:
            offset = 0.1 * self.length_scale if self.material.D is None else 0.5 * self.material.D
        return x + offset * node_directors(x, d1, self.closed)

    def writhe(self, q, phi=0.0):
        """Writhe of the centreline (closed rods) or of the centreline extended along the clamps."""
        return self.exact_writhe(self.positions(q))

    def twist(self, q, phi, nbr=None):
        """Total twist Tw = sum of vertex twists / 2 pi."""
        return jnp.sum(self.vertex_twists(q, phi, nbr)) / TWO_PI

    def linking_number(self, q, phi, nbr=None):
        """Lk = Wr + Tw: Lk0 + phi/(2 pi) while the rod does not pass through itself."""
        return self.writhe(q, phi) + self.twist(q, phi, nbr)

    # ------------------------------------------------------------------ zero modes
    def zero_modes(self, q, phi):
        """Generators (n, k) of exact symmetries (rigid motions, uniform twist shift) in the
        physical DOFs; k = 0 for clamped rods."""
        return jnp.zeros((self.n_dof, 0))

    def scaled_zero_modes(self, u, phi):
        """Zero-mode generators in the scaled DOFs (a change of variables divides by the scale)."""
        z = self.zero_modes(self.from_scaled(u), phi)
        return z / self.dof_scale[:, None]


def _rigid_and_twist_modes(x, n_theta):
    """3 translations, 3 rotations about the centroid, and the uniform shift of all twist angles,
    for a rod whose nodes x (N,3) are all free. Returns (3N + n_theta, 7)."""
    n = x.shape[0]
    cols = []
    eye = jnp.eye(3, dtype=x.dtype)
    r = x - jnp.mean(x, axis=0)
    for k in range(3):
        cols.append(jnp.concatenate([jnp.tile(eye[k], n), jnp.zeros(n_theta)]))
    for k in range(3):
        cols.append(jnp.concatenate([jnp.cross(eye[k], r).ravel(), jnp.zeros(n_theta)]))
    cols.append(jnp.concatenate([jnp.zeros(3 * n), jnp.ones(n_theta)]))
    return jnp.stack(cols, axis=1)


@_pytree(["material", "rest_lengths", "q_init", "Lk0", "contact_stiffness"], ["terms", "name"])
@dataclass(frozen=True, eq=False)
class ClosedRod(Scene):
    """Closed rod (ring, knot). DOFs: q = [x.ravel() (3N), theta (N)].

    Lk0 is the linking number of the ribbon at phi = 0; the rod is cut at the joint (vertex 0,
    between edge N-1 and edge 0), twisted by phi and glued, so Lk = Lk0 + phi / (2 pi).
    contact_stiffness: kappa_c of soft self-contact (in units of B/D^3, the prefactor of the contact integral) when "contact" is a term.
    The contact candidate list is not part of the scene: it lives in a ``Neighbourhood`` passed
    to the energy (``scene.neighbourhood(q)``), rebuilt by the solvers when it goes stale.
    """

    Lk0: float = 0.0
    contact_stiffness: float = 0.0

    closed = True
    n_zero_modes = 7

    def unpack(self, q, phi, nbr=None):
        n = self.n_nodes
        return q[: 3 * n].reshape(n, 3), q[3 * n:]

    def reference_directors(self, x):
        t = unit(edges(x, True))
        return transport_along(perpendicular_unit(t[0]), t)

    def raw_holonomy(self, x):
        """Reference twist at the joint modulo 2 pi: the angle, about t[0], from the reference
        director carried once round the rod by parallel transport to the one it started from."""
        return tantrix_holonomy(unit(edges(x, True)))

    def joint_reference_twist(self, x, nbr=None):
        """The holonomy lifted to the branch 2 pi (Lk0 - Wr(x)) (see module docstring)."""
        return _lift(self.raw_holonomy(x), TWO_PI * (self.Lk0 - self._writhe_for_lift(x, nbr)))

    def vertex_twists(self, q, phi, nbr=None):
        x, theta = self.unpack(q, phi)
        m = theta - jnp.roll(theta, 1)
        return m.at[0].add(self.joint_reference_twist(x, nbr) + phi)

    def holonomy_vertex(self):
        """Index of the vertex whose twist carries the holonomy (a dense rank-1 Hessian term)."""
        return 0

    def zero_modes(self, q, phi):
        x, theta = self.unpack(q, phi)
        return _rigid_and_twist_modes(x, theta.shape[0])


@_pytree(["material", "rest_lengths", "q_init", "x_clamped", "director_start", "Lk0"], ["terms", "name"])
@dataclass(frozen=True, eq=False)
class ClampedRod(Scene):
    """Open rod clamped at both ends: nodes 0, 1 and N-2, N-1 fixed (so the first and last edges,
    and their tangents, are fixed), the first material director fixed, the last one rotated by
    phi about the clamp axis. DOFs: q = [x[2:N-2].ravel(), theta[1:M-1]].

    The clamps are coaxial (both edges along the same axis); the end twist's 2 pi branch is fixed
    by the writhe of the centreline extended by rays along the axis (see module docstring).
    """

    x_clamped: np.ndarray = None  # (4,3): x[0], x[1], x[N-2], x[N-1]
    director_start: np.ndarray = None  # (3,) material director of edge 0
    Lk0: float = 0.0

    @property
    def n_free_nodes(self):
        return self.n_nodes - 4

    @property
    def axis(self):
        return unit(self.x_clamped[1] - self.x_clamped[0])

    def interior(self, q):
        n_free = self.n_nodes - 4
        return q[: 3 * n_free].reshape(n_free, 3), q[3 * n_free:]

    def nodes(self, q):
        xi, _ = self.interior(q)
        c = self.x_clamped
        return jnp.concatenate([c[:2], xi, c[2:]], axis=0)

    def reference_directors(self, x):
        return transport_along(self.director_start, unit(edges(x, False)))

    def positions(self, q):
        return self.nodes(q)

    def exact_writhe(self, x):
        """The ray-closed writhe (the centreline extended to infinity along the clamp axis at both
        ends), exact to roundoff: its fractional part from the tantrix holonomy (the writhe of a
        polygon is -holonomy / 2 pi modulo 1 exactly, and the rays add no tantrix), its integer
        part from the writhe of the centreline extended by finite rays (``extended_writhe``, whose
        truncation error, O(L / ray length), only has to stay below 1/2)."""
        fraction = -tantrix_holonomy(unit(edges(x, False))) / TWO_PI
        return fraction + jnp.round(self.extended_writhe(x) - fraction)

    def holonomy_vertex(self):
        return self.rest_lengths.shape[0] - 2

    def extended_writhe(self, x):
        """Writhe of the centreline extended at both ends by rays along the clamp axis of length
        100 L: the ray-closed writhe to O(L / 100 L) (measured: 1e-6 on a loop of height 0.3 L),
        used only for the integer part of ``exact_writhe``."""
        a = self.axis
        far = 100.0 * self.length
        ext = jnp.concatenate([(x[0] - far * a)[None], x, (x[-1] + far * a)[None]], axis=0)
        return writhe(ext, closed=False)

    def end_angle(self, x, nbr=None):
        """theta_end - phi: the twist angle of the last edge, measured from its space-parallel
        reference director, at which its material director is the clamp's director turned by phi.

        Parallel transport along the rod (the tantrix starts and ends on the clamp axis, so it is
        closed) turns the first director by alpha = -holonomy about the axis; the clamp asks for
        d1 = R(phi) d_start = R(theta_end + alpha) d_start, so theta_end = phi + holonomy, lifted
        to the branch 2 pi (Lk0 - Wr(x)): then Tw = Lk0 + phi / 2 pi - Wr exactly. (Before issue 19
        the sign of the holonomy was the other one: a buckled rod then met its far clamp turned by
        phi - 4 pi Wr and reported Lk = Lk0 + phi / 2 pi + 2 Wr; straight rods, with Wr = 0, and
        the onset of buckling, symmetric in the sign of phi, did not show it.)"""
        raw = tantrix_holonomy(unit(edges(x, False)))
        return _lift(raw, TWO_PI * (self.Lk0 - self._writhe_for_lift(x, nbr)))

    def unpack(self, q, phi, nbr=None):
        x = self.nodes(q)
        _, theta_free = self.interior(q)
        theta_end = phi + self.end_angle(x, nbr)
        theta = jnp.concatenate([jnp.zeros(1, dtype=q.dtype), theta_free, jnp.reshape(theta_end, (1,))])
        return x, theta

    def vertex_twists(self, q, phi, nbr=None):
        _, theta = self.unpack(q, phi, nbr)
        return theta[1:] - theta[:-1]


@_pytree(["material", "rest_lengths", "q_init"], ["terms", "name"])
@dataclass(frozen=True, eq=False)
class FreeRod(Scene):
    """Open rod with free ends. DOFs: q = [x.ravel() (3N), theta (N-1)]. phi plays no role."""

    n_zero_modes = 7

    def unpack(self, q, phi, nbr=None):
        n = self.n_nodes
        return q[: 3 * n].reshape(n, 3), q[3 * n:]

    def holonomy_vertex(self):
        return None

    def reference_directors(self, x):
        t = unit(edges(x, False))
        return transport_along(perpendicular_unit(t[0]), t)

    def vertex_twists(self, q, phi, nbr=None):
        _, theta = self.unpack(q, phi)
        return theta[1:] - theta[:-1]

    def zero_modes(self, q, phi):
        x, theta = self.unpack(q, phi)
        return _rigid_and_twist_modes(x, theta.shape[0])


# ---------------------------------------------------------------------- factories
def _check_material(material):
    if not isinstance(material, Material):
        raise TypeError(f"material must be a jaxrod.Material, got {type(material).__name__}")
    return material


# A drawn curve's writhe this far from the nearest integer leaves Lk0 = round(writhe) in doubt
# (a warning); the standard trefoil drawing sits at 3.35 and relaxes to 3.05 with Lk0 = 3.
AMBIGUOUS_WRITHE = 0.4


def closed_curve(points, material, N=None, length=None, Lk0=None, name="closed curve", contact_stiffness=None):
    """A closed rod along the closed polyline ``points`` (M,3) (last point not repeating the first).

    The curve is resampled to N nodes equally spaced in arc length (default N = M) and scaled to
    total length ``length`` (default: its own). Every edge gets rest length L/N, so the curve
    starts (almost) unstretched. Lk0 defaults to the integer nearest the writhe (the least-twisted
    closed ribbon; a warning when the writhe is within 0.1 of a half-integer). That is the
    twist-free rod only if the curve is close to its relaxed shape: ``relax_to_minimum`` at phi = 0
    warns when the relaxed rod stores more than a quarter turn of twist; then give Lk0. The twist
    angles start uniform, so the initial twist is spread evenly.
    contact_stiffness: kappa_c (in units of B/D^3, the prefactor of the contact integral) of soft self-contact, which needs the material's
    diameter D; None (default) models no contact (for curves whose strands stay far apart).
    """
    _check_material(material)
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (M, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite")
    N = check_int_at_least("N", pts.shape[0] if N is None else N, 4)
    given = float(np.sum(np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=0 if pts.shape[0] < 2 else 1)))
    if pts.shape[0] < 3 or not given > 0.0:
        raise ValueError(f"points must describe a closed curve of positive length (got {pts.shape[0]} point(s) "
                         f"of total length {given:.3g})")
    x = resample_closed(pts, N)
    perimeter = float(np.sum(np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1)))
    gap = closest_approach(x, closed=True)
    if gap <= 1e-9 * perimeter:
        # Its writhe, and so the holonomy's branch and Lk0, is undefined; a rod cannot lie there.
        raise ValueError(f"points: the curve (resampled to N = {N}) passes through itself "
                         f"(two segments {gap:.2g} apart)")
    if length is not None:
        length = check_positive("length", length)
        x = (x - x.mean(axis=0)) * (length / perimeter)
    else:
        length = perimeter
    rest = np.full(N, length / N)
    wr = float(writhe(jnp.asarray(x), closed=True))
    if Lk0 is None:
        Lk0 = int(round(wr))
        if abs(wr - Lk0) > AMBIGUOUS_WRITHE:
            warnings.warn(f"points: the curve's writhe {wr:.3f} is nearly half-way between two integers: Lk0 = {Lk0} "
                          f"taken (the nearer one); give Lk0 if the untwisted rod has another linking number",
                          stacklevel=2)
    else:
        Lk0 = check_int_at_least("Lk0", Lk0, -10**6)
    probe = ClosedRod(material=material, rest_lengths=jnp.asarray(rest), q_init=jnp.zeros(4 * N), Lk0=float(Lk0), name=name)
    rho = float(probe.joint_reference_twist(jnp.asarray(x)))
    theta = rho * np.arange(N) / N  # every vertex, the joint included, then carries rho / N
    q0 = np.concatenate([x.ravel(), theta])
    scene = ClosedRod(material=material, rest_lengths=jnp.asarray(rest), q_init=jnp.asarray(q0), Lk0=float(Lk0), name=name)
    if contact_stiffness is None:
        return scene
    if material.D is None:
        raise ValueError("contact needs the rod diameter: give the material a D")
    stiffness = check_positive("contact_stiffness", contact_stiffness)
    return replace(scene, terms=scene.terms + ("contact",), contact_stiffness=stiffness)


# Ropelength L/D of the ideal (tightest) trefoil (Baranska, Przybyl, Pieranski 2008: 16.372).
IDEAL_TREFOIL_ROPELENGTH = 16.372

DEFAULT_CONTACT_STIFFNESS = 100.0
# Young's modulus of the seed paper's elastomer rod, 0.474 MPa (= N/mm^2, for lengths in mm): the
# default of every knot factory and of the CLI. It scales energies only; critical twists, shapes
# and the dimensionless eigenvalues do not depend on it.
PAPER_YOUNG_MODULUS = 0.474
# Fewest nodes of a trefoil: three crossings need a few edges each to be resolved at all.
MIN_TREFOIL_NODES = 24
# A knot with L/D below this multiple of its ideal ropelength is "nearly tight" (a warning).
NEARLY_TIGHT = 1.25


def check_knot_resolution(N, D, L, minimum):
    """N as an int, or ValueError naming N: at least ``minimum`` and at least L/D, so that no edge
    is longer than the diameter (self-contact is resolved on segments: with longer edges
    strands fall between the quadrature points and the relaxation fails or passes them
    through each other)."""
    N = check_int_at_least("N", N, minimum)
    need = math.ceil(L / D - 1e-9)
    if N < need:
        raise ValueError(f"N = {N} gives edges of {L / N / D:.2f} D: self-contact needs edges no longer than the "
                         f"diameter, N >= L/D = {need}")
    return N


def trefoil_points(n, chirality="right"):
    """(n,3) points of the trefoil (sin t + 2 sin 2t, cos t - 2 cos 2t, -+sin 3t).

    With -sin 3t this parametrisation is left-handed (writhe ~ -3.35); 'right' flips z."""
    if chirality not in ("right", "left"):
        raise ValueError(f"chirality must be 'right' or 'left', got {chirality!r}")
    t = TWO_PI * np.arange(n) / n
    z = -np.sin(3 * t) if chirality == "left" else np.sin(3 * t)
    return np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), z], axis=1)


def trefoil(D, L, N, E=PAPER_YOUNG_MODULUS, nu=0.5, chirality="right", contact_stiffness=DEFAULT_CONTACT_STIFFNESS):
    """A closed trefoil knot of rod diameter D and length L, N nodes, material (E, nu, D); E in
    MPa for lengths in mm (default 0.474, the seed paper's elastomer), energies then in N mm.

    Refuses a knot shorter than the ideal trefoil (L/D < 16.372), which cannot exist.
    The initial curve is the standard parametrisation scaled to length L (not yet relaxed).
    """
    return _knot_scene("3_1", lambda n: trefoil_points(n, chirality), D, L, N, E, nu, contact_stiffness,
                       f"{chirality}-handed trefoil")


# Ropelength L/D of the ideal (tightest) knots: the trefoil 16.372 (Baranska, Przybyl, Pieranski
# 2008); the figure-eight 21.04, the cinquefoil 23.55 and the three-twist knot 24.68 (Ashton,
# Cantarella, Piatek, Rawdon, "Knot tightening by constrained gradient descent", Experimental
# Mathematics 20 (2011), to the digits quoted here). A shorter rod cannot be tied in that knot.
IDEAL_ROPELENGTH = {"3_1": IDEAL_TREFOIL_ROPELENGTH, "4_1": 21.04, "5_1": 23.55, "5_2": 24.68}
_KNOT_NAMES = {"3_1": "trefoil", "4_1": "figure-eight knot", "5_1": "cinquefoil", "5_2": "three-twist knot"}


def knot_points(name, n):
    """(n, 3) points of a published parametrisation of the knot ``name`` (t = 2 pi k / n):
    3_1 the trefoil (sin t + 2 sin 2t, cos t - 2 cos 2t, sin 3t); 4_1 the figure-eight knot
    ((2 + cos 2t) cos 3t, (2 + cos 2t) sin 3t, sin 4t); 5_1 the cinquefoil, torus knot T(2, 5)
    ((2 + cos 5t) cos 2t, (2 + cos 5t) sin 2t, sin 5t); 5_2 the three-twist knot as the Lissajous
    knot (cos(3t + 0.7), cos(2t + 0.2), cos 7t) (Bogle, Hearst, Jones, Stoilov 1994)."""
    if name not in IDEAL_ROPELENGTH:
        raise ValueError(f"knot must be one of {', '.join(IDEAL_ROPELENGTH)}, got {name!r}")
    t = TWO_PI * np.arange(n) / n
    if name == "3_1":
        return trefoil_points(n)
    if name == "4_1":
        return np.stack([(2 + np.cos(2 * t)) * np.cos(3 * t), (2 + np.cos(2 * t)) * np.sin(3 * t), np.sin(4 * t)], axis=1)
    if name == "5_1":
        return np.stack([(2 + np.cos(5 * t)) * np.cos(2 * t), (2 + np.cos(5 * t)) * np.sin(2 * t), np.sin(5 * t)], axis=1)
    return np.stack([np.cos(3 * t + 0.7), np.cos(2 * t + 0.2), np.cos(7 * t)], axis=1)


def knot(name, D, L, N, E=PAPER_YOUNG_MODULUS, nu=0.5, contact_stiffness=DEFAULT_CONTACT_STIFFNESS, Lk0=None):
    """A closed rod tied in the knot ``name`` ('3_1', '4_1', '5_1', '5_2'; see ``knot_points``)
    of diameter D and length L with N nodes. Refuses L/D below the knot's ideal ropelength
    (``IDEAL_ROPELENGTH``), N below 24 or (with contact) below L/D; warns when L/D is within 25%
    of the ideal. The curve is the parametrisation scaled to length L, not yet relaxed."""
    if name not in IDEAL_ROPELENGTH:
        raise ValueError(f"knot must be one of {', '.join(IDEAL_ROPELENGTH)}, got {name!r}")
    return _knot_scene(name, lambda n: knot_points(name, n), D, L, N, E, nu, contact_stiffness, _KNOT_NAMES[name],
                       Lk0=Lk0)


def _knot_scene(name, points, D, L, N, E, nu, contact_stiffness, title, Lk0=None):
    """The checks every knot shares, then ``closed_curve`` through ``points(n)`` ((n, 3), the
    parametrisation sampled at n = max(4 N, 400) points, finer than the rod)."""
    D = check_positive("D", D)
    L = check_positive("L", L)
    ideal = IDEAL_ROPELENGTH[name]
    if L / D < ideal:
        raise ValueError(
            f"L/D = {L / D:.3f} is below the ideal {_KNOT_NAMES[name]}'s ropelength {ideal}: "
            f"no {_KNOT_NAMES[name]} of this rod can exist (increase L or decrease D)"
        )
    N = check_int_at_least("N", N, MIN_TREFOIL_NODES)
    if contact_stiffness is not None:
        N = check_knot_resolution(N, D, L, minimum=MIN_TREFOIL_NODES)
    if L / D < NEARLY_TIGHT * ideal:
        warnings.warn(
            f"L/D = {L / D:.2f} is within {100 * (NEARLY_TIGHT - 1):.0f}% of the ideal {_KNOT_NAMES[name]}'s "
            f"{ideal}: the knot is nearly tight, and its equilibria depend on the contact stiffness", stacklevel=3)
    mat = Material.from_engineering(E, nu, D)
    return closed_curve(points(max(4 * N, 400)), mat, N=N, length=L, name=title, contact_stiffness=contact_stiffness,
                        Lk0=Lk0)


def torus_knot(p, q, D, L, N, E=PAPER_YOUNG_MODULUS, nu=0.5, radii=(2.0, 1.0), contact_stiffness=DEFAULT_CONTACT_STIFFNESS):
    """The (p, q) torus knot ((R + r cos qt) cos pt, (R + r cos qt) sin pt, r sin qt), scaled to
    length L, as a closed rod of diameter D with N nodes. p and q must be coprime integers."""
    p = check_int_at_least("p", p, 1)
    q = check_int_at_least("q", q, 1)
    if math.gcd(p, q) != 1:
        raise ValueError(f"p and q must be coprime for a knot, got p={p}, q={q}")
    D = check_positive("D", D)
    L = check_positive("L", L)
    N = check_int_at_least("N", N, 4)
    if contact_stiffness is not None:
        N = check_knot_resolution(N, D, L, minimum=4)
    R, r = radii
    t = TWO_PI * np.arange(max(4 * N, 400)) / max(4 * N, 400)
    pts = np.stack([(R + r * np.cos(q * t)) * np.cos(p * t), (R + r * np.cos(q * t)) * np.sin(p * t), r * np.sin(q * t)], axis=1)
    mat = Material.from_engineering(E, nu, D)
    return closed_curve(pts, mat, N=N, length=L, name=f"T({p},{q}) torus knot", contact_stiffness=contact_stiffness)


def ring(N, material, radius=1.0, Lk0=0):
    """A planar circular ring of N nodes, rest length 2 pi radius; the initial polygon is the
    regular N-gon whose edges have the rest length."""
    _check_material(material)
    N = check_int_at_least("N", N, 4)
    radius = check_positive("radius", radius)
    edge = TWO_PI * radius / N
    r_poly = edge / (2.0 * math.sin(math.pi / N))
    s = TWO_PI * np.arange(N) / N
    x = np.stack([r_poly * np.cos(s), r_poly * np.sin(s), np.zeros(N)], axis=1)
    q0 = np.concatenate([x.ravel(), np.zeros(N)])
    return ClosedRod(material=material, rest_lengths=jnp.full(N, edge), q_init=jnp.asarray(q0), Lk0=float(Lk0), name="ring")


def michell_ring(N, nu=0.5, slenderness=0.01, radius=1.0):
    """Michell's ring: B = 1, C = B/(1+nu), diameter D = slenderness * radius (EA = 16 B/D^2).

    Thin enough (D/R = 0.01) that extensibility shifts the threshold by ~1e-5 relative or less.
    """
    nu = check_finite("nu", nu)
    slenderness = check_positive("slenderness", slenderness)
    radius = check_positive("radius", radius)
    mat = Material.from_ratio(B=1.0, nu=nu, D=slenderness * radius)
    return ring(N, mat, radius=radius)


def clamped_rod(N, length, material, axis=(0.0, 0.0, 1.0)):
    """Straight rod of N nodes along ``axis``, clamped at both ends.

    The clamped first and last edges are rigid; the material frame of an edge lives at its
    midpoint, so the clamps act at the midpoints of the end edges, and those are ``length`` apart
    (edge length = length/(N-2)). The twisted straight rod then stores exactly C phi^2/(2 length).
    """
    _check_material(material)
    N = check_int_at_least("N", N, 5)
    length = check_positive("length", length)
    a = np.asarray(axis, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
        raise ValueError(f"axis must be a finite non-zero 3-vector, got {axis!r}")
    a = a / np.linalg.norm(a)
    edge = length / (N - 2)
    x = (np.arange(N) - 0.5)[:, None] * edge * a[None, :]
    d0 = np.asarray(perpendicular_unit(jnp.asarray(a)))
    q0 = np.concatenate([x[2:-2].ravel(), np.zeros(N - 3)])
    return ClampedRod(
        material=material,
        rest_lengths=jnp.full(N - 1, edge),
        q_init=jnp.asarray(q0),
        x_clamped=jnp.asarray(x[[0, 1, -2, -1]]),
        director_start=jnp.asarray(d0),
        name="clamped rod",
    )


def free_rod(N, length, material):
    """Straight free rod of N nodes along z."""
    _check_material(material)
    N = check_int_at_least("N", N, 4)
    length = check_positive("length", length)
    edge = length / (N - 1)
    x = np.zeros((N, 3))
    x[:, 2] = np.arange(N) * edge
    q0 = np.concatenate([x.ravel(), np.zeros(N - 1)])
    return FreeRod(material=material, rest_lengths=jnp.full(N - 1, edge), q_init=jnp.asarray(q0), name="free rod")
