"""The rod scenes: which degrees of freedom are free, how imposed twist enters, which energy
terms are summed. ``ClosedRod`` (rings, knots), ``ClampedRod`` (both ends clamped), ``FreeRod``.

A scene maps the free DOFs ``q`` and the imposed twist ``phi`` to the rod state (nodes ``x`` (N,3),
edge twist angles ``theta`` (M,)) and to its energy, the sum of its terms (``jaxrod.model.terms``);
its methods are pure JAX functions of ``(q, phi)`` (the scene holds only constants).
Imposed twist without hidden state
----------------------------------
Reference frames are space-parallel (``jaxrod.model.geometry``), so the only geometric twist is the
holonomy of parallel transport, known from atan2 only modulo 2 pi. Its branch is fixed by
Calugareanu-White, Lk = Wr + Tw: the joint's reference twist is the atan2 value plus 2 pi times the
integer nearest to (2 pi (Lk0 - Wr(x)) - atan2 value) / 2 pi (gradient stopped), with Wr the exact
polygon writhe (never differentiated). The result is smooth in (x, theta, phi) for any phi while
the rod does not pass through itself. A clamped rod uses the writhe of the rod extended by two
long rays along the clamp axis.
"""
from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np

from .geometry import (
    edges,
    material_directors,
    node_directors,
    perpendicular_unit,
    tantrix_holonomy,
    transport_along,
    unit,
    voronoi_lengths,
)
from .material import Material, strong_leaf
from .neighbourhood import build_neighbourhood
from .terms import Bend, Coupling, Stretch, Twist, as_terms
from .topology import writhe
from ..validation import check_poisson_ratio, check_positive, is_traced

__all__ = ["Scene", "ClosedRod", "ClampedRod", "FreeRod"]

TWO_PI = 2.0 * math.pi


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


class _Label:
    """A scene's name as its pytree structure holds it: equal to every other label, so that scenes
    differing only in their name (the trefoil drawn by ``trefoil`` and by ``knot('3_1')``, the
    knots of an atlas at one N) reach the same compiled programs. The name is never traced; a jitted
    function that returned a scene would give it the name of the scene first traced."""

    __slots__ = ("text",)

    def __init__(self, text):
        self.text = text

    def __eq__(self, other):
        return isinstance(other, _Label)

    def __hash__(self):
        return 0

    def __repr__(self):
        return "name"


def _pytree(data_fields, meta_fields=()):
    """Register a frozen dataclass as a JAX pytree: array fields are leaves (so scenes of equal
    shapes share compiled code, and material parameters can be differentiated), the rest is
    static, the field ``name`` as a ``_Label``. Unflattening bypasses __init__ so validation never
    sees tracers."""

    def wrap(cls):
        def flatten(obj):
            aux = tuple(_Label(getattr(obj, f)) if f == "name" else getattr(obj, f) for f in meta_fields)
            return [strong_leaf(getattr(obj, f)) for f in data_fields], aux

        def unflatten(aux, children):
            obj = object.__new__(cls)
            for f, v in zip(data_fields, children):
                object.__setattr__(obj, f, v)
            for f, v in zip(meta_fields, aux):
                object.__setattr__(obj, f, v.text if isinstance(v, _Label) else v)
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
    terms: the energy terms this scene sums (``jaxrod.model.terms.Term`` objects; built-in terms
        may be given by name: "stretch", "bend", "twist", "contact"), in the order summed.
    """

    # Gauss points per segment in the contact integral (``contact.contact_energy``); scenes with
    # short crossing contacts (an open knot pulled tight) set 3.
    contact_quadrature = 2

    material: Material
    rest_lengths: np.ndarray
    q_init: np.ndarray
    terms: tuple = (Stretch(), Bend(), Twist())
    name: str = "rod"

    closed = False  # class constants, not fields
    n_zero_modes = 0

    def __post_init__(self):
        object.__setattr__(self, "terms", as_terms(self.terms))

    @property
    def term_names(self):
        """Names of the scene's energy terms, in the order summed (the keys of ``energy_terms``)."""
        return tuple(t.name for t in self.terms)

    def has_term(self, name):
        """Whether the scene sums a term called ``name`` ("contact", "twist", ...)."""
        return name in self.term_names

    @property
    def needs_neighbourhood(self):
        """Whether a term needs the neighbourhood's candidate pair list (contact)."""
        return any(t.needs_neighbourhood for t in self.terms)

    @property
    def local_terms(self):
        """The terms whose Hessian couples DOFs within a window of three nodes (``Coupling.LOCAL``):
        the part of the energy that the coloured Hessian-vector products recover."""
        return tuple(t for t in self.terms if t.coupling is Coupling.LOCAL)

    def with_terms(self, *terms):
        """A copy of the scene that also sums ``terms`` (``Term`` objects or built-in names), after
        its own terms. Raises ValueError for a name the scene already has, or a term that does not
        fit the scene (contact without a diameter)."""
        new = as_terms(terms)
        for term in new:
            term.check(self)
        return replace(self, terms=self.terms + new)

    PARAMETERS = ("B", "C", "EA", "D", "nu", "contact_stiffness", "diameter")

    def parameter(self, name):
        """The value of the continuous parameter ``name`` (one of ``PARAMETERS``): nu = B/C - 1, and
        ``diameter`` is the material's D. ValueError for an unknown name or one the scene lacks."""
        if name not in self.PARAMETERS:
            raise ValueError(f"parameter must be one of {', '.join(self.PARAMETERS)}, got {name!r}")
        m = self.material
        if name == "nu":
            return m.B / m.C - 1.0
        if name == "contact_stiffness":
            if not hasattr(self, "contact_stiffness"):
                raise ValueError(f"a {type(self).__name__} has no contact stiffness: contact is not modelled on it")
            return self.contact_stiffness
        return m.D if name == "diameter" else getattr(m, name)

    def with_params(self, **params):
        """A copy of the scene with continuous parameters replaced: the material's ``B``, ``C``,
        ``EA`` and ``D``, the Poisson ratio ``nu`` (sets C = B/(1+nu), with the new B where given),
        the rod's ``diameter`` at fixed Young's modulus and Poisson ratio (B and C scale as D^4, EA
        as D^2, the contact diameter is D: a thicker rod of the same material and length; with
        ``nu``, C = B/(1+nu) from the new B) and, on
        scenes that model contact, ``contact_stiffness``. The geometry (rest lengths,
        q_init) and the terms are kept; D is the contact diameter only (B and EA stay as they are).
        Concrete values are checked as the constructors check them (ValueError naming the
        parameter); jax tracers pass unchecked, so ``jax.grad``/``jvp``/``vmap`` through
        ``scene.with_params(nu=nu)`` work (with a traced D, evaluate the energy without a
        ``Neighbourhood``)."""
        unknown = sorted(set(params) - set(self.PARAMETERS))
        if unknown:
            raise ValueError(f"with_params sets {', '.join(self.PARAMETERS)}; got {', '.join(unknown)}")
        if "nu" in params and "C" in params:
            raise ValueError("give C or nu, not both: nu sets C = B/(1+nu)")
        m = self.material
        if "diameter" in params:
            if set(params) & {"B", "C", "EA", "D"}:
                raise ValueError("diameter sets B, C, EA and D together: give it without them (nu may go with it)")
            r = check_positive("diameter", params.pop("diameter")) / m.D
            scaled = dict(B=m.B * r ** 4, EA=m.EA * r ** 2, D=m.D * r)
            if "nu" not in params:  # else nu sets C from the new B
                scaled["C"] = m.C * r ** 4
            params = dict(params, **scaled)
        B = check_positive("B", params.get("B", m.B))
        C = params.get("C", m.C)
        if "nu" in params:
            C = B / (1.0 + check_poisson_ratio("nu", params["nu"]))
        D = params.get("D", m.D)
        material = Material(B=B, C=C, EA=params.get("EA", m.EA), D=D)
        new = copy.copy(self)  # a shallow copy: the same static structure, so the same compiled programs
        object.__setattr__(new, "material", material)
        if "contact_stiffness" in params:
            if not hasattr(self, "contact_stiffness"):
                raise ValueError(f"a {type(self).__name__} has no contact stiffness: contact is not modelled on it")
            object.__setattr__(new, "contact_stiffness", check_positive("contact_stiffness", params["contact_stiffness"]))
        return new

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

    def neighbourhood(self, q, phi=0.0, skin=None, capacity=None):
        """The ``Neighbourhood`` of state q (physical DOFs): contact candidates (if any) and the
        exact writhe, built outside jit from concrete values (ValueError for a traced D).
        ``capacity``: pad the pair list to at least this many rows (reuse compiled code)."""
        if is_traced(self.material.D):
            raise ValueError("D must be a concrete value to build a neighbourhood (its candidate list is made on the "
                             "host); inside a function traced over D, evaluate scene.energy(q, phi) without nbr: "
                             "its candidate mask follows D")
        x = np.asarray(self.positions(np.asarray(q)))
        wr = float(self.exact_writhe(jnp.asarray(x)))
        D = None if self.material.D is None else float(self.material.D)
        return build_neighbourhood(x, wr, self.closed, float(np.mean(np.asarray(self.rest_lengths))), D,
                                   self.needs_neighbourhood, skin=skin, capacity=capacity)

    @property
    def n_free_nodes(self):
        return self.n_nodes

    @property
    def dof_scale(self):
        """Per-DOF scale (n,): free node coordinates in units of edge length, angles in radians."""
        return _scale_vector_jit(self.length_scale, 3 * self.n_free_nodes, self.n_dof)

    def energy_terms(self, q, phi, nbr=None, terms=None):
        """Dict name -> energy of the scene's terms at (q, phi), in the scene's order: exact
        without ``nbr`` (O(N^2)), the same in O(N) with a valid one (``jaxrod.model.neighbourhood``).
        ``terms``: evaluate only those of the scene's terms (terms or names)."""
        chosen = self.terms
        if terms is not None:
            wanted = {getattr(t, "name", t) for t in terms}
            chosen = tuple(t for t in self.terms if t.name in wanted)
        x = self.positions(q)
        return {t.name: t.energy_given_nodes(self, x, q, phi, nbr) for t in chosen}

    def contact_candidates(self, nbr=None):
        """(pairs (P,2), mask (P,)): the neighbourhood's candidate list, or every pair further
        apart along the rod than pi D/2 when nbr is None (mask computed with jnp: follows a traced D)."""
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
        """Energy in units of ``energy_scale`` of scaled DOFs u = q / dof_scale (what solvers and
        stability analyses use: dimensionless tolerances and eigenvalues)."""
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
    contact_stiffness: kappa_c of soft self-contact (units of B/D^3) when "contact" is a term; the
    candidate list lives in a ``Neighbourhood`` passed to the energy."""

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
    and their tangents, are fixed), the first material director fixed, the last one rotated by phi
    about the clamp axis. DOFs: q = [x[2:N-2].ravel(), theta[1:M-1]].

    The clamps are coaxial (both edges along the same axis); the end twist's 2 pi branch is fixed by
    the writhe of the centreline extended by rays along the axis (see module docstring)."""

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
        """The ray-closed writhe (centreline extended to infinity along the clamp axis), exact to
        roundoff: its fractional part from the tantrix holonomy (-holonomy / 2 pi modulo 1; the
        rays add no tantrix), its integer part from ``extended_writhe``."""
        fraction = -tantrix_holonomy(unit(edges(x, False))) / TWO_PI
        return fraction + jnp.round(self.extended_writhe(x) - fraction)

    def holonomy_vertex(self):
        return self.rest_lengths.shape[0] - 2

    def extended_writhe(self, x):
        """Writhe of the centreline extended at both ends by rays of length 100 L along the clamp
        axis: the ray-closed writhe to O(1/100), used only for the integer part of ``exact_writhe``."""
        a = self.axis
        far = 100.0 * self.length
        ext = jnp.concatenate([(x[0] - far * a)[None], x, (x[-1] + far * a)[None]], axis=0)
        return writhe(ext, closed=False)

    def end_angle(self, x, nbr=None):
        """theta_end - phi: the last edge's twist angle (from its space-parallel reference
        director) at which its material director is the clamp's turned by phi. Transport along
        the (closed) tantrix turns the first director by -holonomy, so theta_end = phi + holonomy,
        lifted to the branch 2 pi (Lk0 - Wr(x)): then Tw = Lk0 + phi / 2 pi - Wr exactly."""
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
