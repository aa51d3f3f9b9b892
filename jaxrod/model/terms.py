"""Energy terms as objects: what a scene sums, and what each summand tells the solvers.

A scene (``jaxrod.model.scenes``) holds a tuple of terms and sums their energies. Each term knows

* ``energy(scene, q, phi, nbr)``: its energy, a pure JAX function of the free DOFs q (n,), the
  imposed twist phi and, where needed, the ``Neighbourhood`` nbr, reading the rod's geometry from
  the scene (``positions``, ``unpack``, ``vertex_twists``, ``rest_lengths``, ``voronoi``, ``material``);
* ``coupling``: ``Coupling.LOCAL`` (only DOFs within a window of three consecutive nodes, recovered
  exactly by the coloured products of ``jaxrod.model.hessian``) or ``Coupling.PAIRS`` (segment
  pairs from the neighbourhood, assembled from 12 x 12 pair blocks);
* ``needs_neighbourhood``: whether its energy needs the candidate pair list;
* its structured Hessian where it is not local: ``rank_one`` and ``pair_hessian``.

The built-in terms are ``Stretch``, ``Bend``, ``Twist`` and ``Contact``; each compares equal to its
name. A new term subclasses ``Term`` (see docs/extending.md). Terms are static pytree data: they must
be hashable and compare equal exactly when they define the same energy, so compiled code is reused.
"""
from __future__ import annotations

import enum

import jax

from . import energy as E
from .contact import contact_energy, contact_pair_hessian

__all__ = ["Coupling", "Term", "Stretch", "Bend", "Twist", "Contact", "BUILTIN_TERMS", "as_terms"]


class Coupling(str, enum.Enum):
    """Which DOFs a term's Hessian couples (see the module docstring)."""

    LOCAL = "local"
    PAIRS = "pairs"


class Term:
    """Base class of an energy term. Subclasses set ``name`` (unique within a scene; the key of
    ``scene.energy_terms``) and define ``energy``; the defaults describe a local term that needs
    no neighbourhood and has no dense Hessian part."""

    name = "term"
    coupling = Coupling.LOCAL
    needs_neighbourhood = False

    def energy(self, scene, q, phi, nbr=None):
        """The term's energy (scalar) at free DOFs q (n,) and imposed twist phi."""
        raise NotImplementedError

    def energy_given_nodes(self, scene, x, q, phi, nbr=None):
        """The energy, given the node positions x (N, 3) of q (computed once per scene, so the
        gradient goes back through one shared ``positions``). The default ignores x."""
        return self.energy(scene, q, phi, nbr)

    def rank_one(self, scene, u, phi, nbr):
        """(w, a): a dense part w a a^T (a (n,), w scalar) of the term's Hessian in the scaled DOFs
        u that the local window misses, taken out of the coloured products; or None (the
        default). A scene holds at most one term that has one."""
        return None

    def pair_hessian(self, scene, segments):
        """Hessian blocks (P, 12, 12) of the energy of P segment pairs, segments (P, 12) the four
        nodes (a0, a1, b0, b1) of each pair; for ``Coupling.PAIRS`` terms only."""
        raise NotImplementedError(f"{type(self).__name__} couples DOFs locally: it has no pair blocks")

    def check(self, scene):
        """Raise ValueError if the term cannot be added to ``scene`` (the default: it can)."""

    # Two terms are equal when their classes and attributes are, and a term equals its name
    # (dataclass subclasses get their own __eq__ and __hash__).
    def __eq__(self, other):
        if isinstance(other, str):
            return other == self.name
        return type(other) is type(self) and vars(other) == vars(self)

    def __hash__(self):
        hash(tuple(sorted(vars(self).items())))  # TypeError for parameters that cannot be static
        return hash(self.name)  # as the name's: a term equals its name

    def __repr__(self):
        params = ", ".join(f"{k}={v!r}" for k, v in sorted(vars(self).items()))
        return f"{type(self).__name__}({params})"


class Stretch(Term):
    """Hookean axial strain energy, (EA/2) l (|e|/l - 1)^2 summed over edges."""

    name = "stretch"

    def energy(self, scene, q, phi, nbr=None):
        return self.energy_given_nodes(scene, scene.positions(q), q, phi, nbr)

    def energy_given_nodes(self, scene, x, q, phi, nbr=None):
        return E.stretch_energy(x, scene.rest_lengths, scene.material.EA, scene.closed)


class Bend(Term):
    """Isotropic bending of a naturally straight rod, B |kb|^2 / (2 l_v) summed over vertices."""

    name = "bend"

    def energy(self, scene, q, phi, nbr=None):
        return self.energy_given_nodes(scene, scene.positions(q), q, phi, nbr)

    def energy_given_nodes(self, scene, x, q, phi, nbr=None):
        return E.bend_energy(x, scene.voronoi, scene.material.B, scene.closed)


class Twist(Term):
    """Twist energy, C m^2 / (2 l_v) summed over vertices, m the vertex twist with the imposed
    twist and the holonomy included. Local, except at the vertex carrying the holonomy (the
    joint of a closed rod, the last vertex of a clamped one), where m depends on every tangent:
    a dense rank-one Hessian part (``rank_one``)."""

    name = "twist"

    def energy(self, scene, q, phi, nbr=None):
        return E.twist_energy(scene.vertex_twists(q, phi, nbr), scene.voronoi, scene.material.C)

    def rank_one(self, scene, u, phi, nbr):
        """(w, a) with a = grad m_v (scaled DOFs) at the holonomy vertex v and w = C / (l_v
        E_scale); None for scenes without such a vertex (free rods)."""
        v = scene.holonomy_vertex()
        if v is None:
            return None
        a = jax.grad(lambda uu: scene.vertex_twists(uu * scene.dof_scale, phi, nbr)[v])(u)
        w = scene.material.C / (scene.voronoi[v] * scene.energy_scale)
        return w, a


class Contact(Term):
    """Soft self-contact (``jaxrod.model.contact``) over the scene's candidate segment pairs, with
    the scene's ``contact_stiffness`` and ``contact_quadrature``; needs the material's D."""

    name = "contact"
    coupling = Coupling.PAIRS
    needs_neighbourhood = True

    def energy(self, scene, q, phi, nbr=None):
        return self.energy_given_nodes(scene, scene.positions(q), q, phi, nbr)

    def energy_given_nodes(self, scene, x, q, phi, nbr=None):
        m = scene.material
        pairs, mask = scene.contact_candidates(nbr)
        return contact_energy(x, pairs, mask, scene.closed, m.D, m.B, scene.contact_stiffness, scene.contact_quadrature)

    def pair_hessian(self, scene, segments):
        m = scene.material
        return contact_pair_hessian(segments, m.D, m.B, scene.contact_stiffness, scene.contact_quadrature)

    def check(self, scene):
        if scene.material.D is None:
            raise ValueError("contact needs the rod diameter: give the material a D")
        if not hasattr(scene, "contact_stiffness"):
            raise ValueError(f"a {type(scene).__name__} has no contact stiffness: contact is not modelled on it")


BUILTIN_TERMS = {t.name: t for t in (Stretch(), Bend(), Twist(), Contact())}


def _as_term(term):
    """A term, or a built-in term's name, as a ``Term`` (TypeError or ValueError otherwise)."""
    if isinstance(term, str):
        if term not in BUILTIN_TERMS:
            raise ValueError(f"unknown energy term {term!r}: the built-in terms are {', '.join(BUILTIN_TERMS)}")
        return BUILTIN_TERMS[term]
    if not isinstance(term, Term):
        raise TypeError(f"an energy term must be a jaxrod.model.terms.Term, got {type(term).__name__}")
    try:
        hash(term)
    except TypeError as err:
        raise TypeError(f"energy term {term!r} must be hashable (it is static data of the scene: give its "
                        f"parameters as floats and tuples, not arrays)") from err
    return term


def _has_rank_one(term):
    return type(term).rank_one is not Term.rank_one


def as_terms(terms):
    """The tuple of ``Term`` objects for ``terms`` (terms or built-in names), checked: names unique,
    at most one term with a rank-one Hessian part."""
    out = tuple(_as_term(t) for t in terms)
    names = [t.name for t in out]
    doubled = sorted({n for n in names if names.count(n) > 1})
    if doubled:
        raise ValueError(f"energy term names must be unique within a scene, got {', '.join(doubled)} twice")
    if sum(_has_rank_one(t) for t in out) > 1:
        raise ValueError("at most one energy term of a scene may have a rank-one Hessian part")
    return out
