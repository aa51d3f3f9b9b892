"""Rods as bifurcation problems: the scene's scaled energy with its gauge pinned.

A closed rod's Hessian is singular along its 7 symmetry generators, so (as in
``jaxrod.linalg.sparse``) 7 DOFs chosen by ``gauge_pins`` are pinned at their reference values:
E_pinned(u_free, phi) = scene.scaled_energy(embed(u_free), phi). At an equilibrium the pinned
Hessian is congruent to the projected one (same Morse index and zero crossings), and every
solution is an equilibrium of the rod (``full_gradient`` checks it, and measures the force that
``extra_pins`` hold).

``pinned_problem`` uses the exact O(N^2) energy and a dense J (N up to ~100); ``knot_problem``
evaluates through a neighbourhood (O(N)) and takes ``SparseBackend`` from ``SPARSE_MIN_DOF`` DOFs
on. From N ~ 250 on a knot's material slide is numerically exact and must be pinned too.
"""
from __future__ import annotations

import copy
import functools
import weakref
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ...aot import cached_jit
from ...model.geometry import closest_approach
from ...model.hessian import scaled_hessian as structured_scaled_hessian
from ...linalg.sparse import gauge_pins
from ...model.symmetry import has_joint_symmetry, symmetrize_pinned, two_fold_asymmetry
from ...linalg.stability import (CLEAN_SLIDE_FRACTION, scene_bilinear_gradient, scene_linearisation, sliding_fraction,
                         split_slide)
from ...model.topology import writhe
from ...linalg.backend import choose_backend
from ...linalg.sparse_contact import assemble, hessian_parts
from ...linalg.bordered import DenseBackend, HostMatrix, SparseBackend
from .problem import BifurcationProblem
from ..kinds import EventKind
from .results import Event

__all__ = ["PinnedRod", "RodArgs", "pinned_problem", "knot_problem", "split_sliding", "sliding_slice", "set_poisson_ratio",
           "set_diameter", "assemble_pinned_hessian"]


class RodArgs(NamedTuple):
    """The args pytree of a pinned rod's problem: scene; u_ref (n,) the scaled reference state
    whose pinned entries are held; free (n - k,) int, the free DOFs' indices; nbr, the knot's
    ``Neighbourhood`` (None without contact). Arguments, not closure constants, so that problems
    of the same shape share compiled programs.
    """

    scene: Any
    u_ref: Any
    free: Any
    nbr: Any = None


def _with_material(args, B, C, EA, D):
    # rebuilt without __init__ (its leaves may be tracers); nothing else in a scene derives from it
    material = jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(args.scene.material), [B, C, EA, D])
    scene = copy.copy(args.scene)
    object.__setattr__(scene, "material", material)
    return args._replace(scene=scene)


def set_poisson_ratio(args, nu):
    """RodArgs with the twist stiffness C = B/(1 + nu), B, EA and D kept. Traceable: a ``set_mu``
    for ``fold_curve``, ``fold_at`` and ``fold_sensitivity`` (mu = nu)."""
    m = args.scene.material
    return _with_material(args, m.B, m.B / (1.0 + nu), m.EA, m.D)


def set_diameter(args, D):
    """RodArgs with the rod's diameter D at fixed Young's modulus, Poisson ratio and length (mu = D):
    B and C scale as D^4, EA as D^2. Traceable; the neighbourhood in args is kept (valid near the
    D it was built with)."""
    m = args.scene.material
    r = D / m.D
    return _with_material(args, m.B * r ** 4, m.C * r ** 4, m.EA * r ** 2, D)


def _embedded(u_free, args):
    return args.u_ref.at[args.free].set(u_free)


def _pinned_energy(u_free, phi, args):
    if args.nbr is None:
        return args.scene.scaled_energy(_embedded(u_free, args), phi)
    return args.scene.scaled_energy(_embedded(u_free, args), phi, args.nbr)


def _pinned_structured_hessian(u_free, phi, args):
    """The structured Hessian (local blocks + contact pairs), pinned rows and columns dropped."""
    h = structured_scaled_hessian(args.scene, _embedded(u_free, args), phi, args.nbr)
    return h[args.free][:, args.free]


def _pinned_parts(u_free, phi, args):
    """``sparse_contact.hessian_parts`` of the embedded state, for ``SparseBackend``."""
    return hessian_parts(args.scene, _embedded(u_free, args), phi, args.nbr)


def assemble_pinned_hessian(parts, args):
    """The pinned Hessian as a ``HostMatrix`` (S restricted to the free DOFs, a restricted)."""
    S, w, a = assemble(args.scene, parts)
    free = np.asarray(args.free)
    return HostMatrix(S.tocsr()[free][:, free].tocsc(), w, a[free])


class _ScenePrograms:
    """``BifurcationProblem``'s ``programs`` hook: (F, J, F_p) and contracted third derivatives from
    the whole scene's programs (``stability.scene_linearisation``, ``scene_bilinear_gradient``)
    restricted to the free DOFs, exactly; a study has compiled those already."""

    @staticmethod
    def _full(vector, args, fill):
        full = np.array(args.u_ref, dtype=float) if fill is None else np.zeros(np.shape(args.u_ref))
        full[np.asarray(args.free)] = np.asarray(vector, dtype=float)
        return full

    def linearise(self, u, p, args):
        free = np.asarray(args.free)
        g, h, g_p = scene_linearisation(args.scene, self._full(u, args, None), float(p), args.nbr)
        return np.asarray(g)[free], np.asarray(h)[np.ix_(free, free)], np.asarray(g_p)[free]

    def bilinear_gradient(self, u, p, args, a, c, t):
        gu, gp = scene_bilinear_gradient(args.scene, self._full(u, args, None), float(p), args.nbr,
                                         self._full(a, args, 0.0), self._full(c, args, 0.0), float(t))
        return np.asarray(gu)[np.asarray(args.free)], float(gp)


@dataclass(frozen=True, eq=False)
class PinnedRod:
    """A rod scene as a ``BifurcationProblem`` (u = free scaled DOFs, p = phi, args = a ``RodArgs``);
    pins (k,) and free (n - k,) index the scene's DOFs q; u_ref (n,) holds the pinned values."""

    problem: BifurcationProblem
    scene: object
    pins: np.ndarray
    free: np.ndarray
    u_ref: np.ndarray
    slide_pin: object = None  # the DOF pinned along an exact slide (``knot_problem``), or None

    def embed(self, u_free):
        """Full scaled DOFs (n,) from the free ones (n - k,): pinned entries from u_ref. Traceable."""
        return jnp.asarray(self.u_ref).at[jnp.asarray(self.free)].set(u_free)

    def restrict(self, u):
        """The free entries (n - k,) of full scaled DOFs u (n,) (numpy)."""
        return np.asarray(u)[self.free]

    def _host_embed(self, u_free):
        """``embed`` on the host (numpy): eager JAX would load more executables."""
        full = np.array(self.u_ref, dtype=float)
        full[np.asarray(self.free)] = np.asarray(u_free, dtype=float)
        return full

    def q(self, u_free):
        """Physical DOFs q (n,) (numpy) of free scaled DOFs."""
        return np.asarray(self.scene.from_scaled(self._host_embed(u_free)))

    def nodes(self, u_free):
        """Node positions x (N, 3) (physical units, numpy)."""
        return np.asarray(self.scene.positions(self.q(u_free)))

    def full_gradient(self, u_free, phi):
        """Max-norm of the scaled gradient over ALL DOFs, pinned ones included (~roundoff at an equilibrium)."""
        g = _scaled_gradient(self.scene, jnp.asarray(self._host_embed(u_free)), jnp.asarray(phi, dtype=jnp.float64))
        return float(np.max(np.abs(np.asarray(g))))

    def writhe(self, u_free):
        """Exact polygon writhe of the centreline (``jaxrod.model.topology.writhe``)."""
        return float(_writhe(jnp.asarray(self.nodes(u_free))))

    def min_distance(self, u_free, exclude=2):
        """Closest approach between segments more than ``exclude`` apart (physical units,
        ``jaxrod.model.geometry.closest_approach``)."""
        return closest_approach(self.nodes(u_free), closed=True, exclude=exclude)


_writhe = jax.jit(functools.partial(writhe, closed=True))


@cached_jit
def _scaled_gradient(scene, u, phi):
    return jax.grad(scene.scaled_energy)(u, phi)


def pinned_problem(scene, q_ref, phi0, *, pins=None, extra_pins=(), backend=None):
    """The rod ``scene`` as a BifurcationProblem with its gauge pinned at the state ``q_ref``.

    scene: a closed rod without contact; q_ref (n,): physical DOFs of the reference state; pins: q
    indices to pin (default ``gauge_pins``); extra_pins: further q indices; backend: default
    ``DenseBackend()``. Starts at (restrict(u_ref), phi0), n_zero_modes = 0. Returns a PinnedRod.
    """
    u_ref = np.asarray(scene.to_scaled(np.asarray(q_ref, dtype=float)), dtype=float)
    if pins is None:
        pins, _ = gauge_pins(scene, jnp.asarray(u_ref), float(phi0))
    return _build(scene, u_ref, phi0, np.concatenate([np.asarray(pins).ravel(), np.asarray(extra_pins).ravel()]),
                  backend)


def _build(scene, u_ref, phi0, pins, backend):
    pins = np.unique(np.asarray(pins, dtype=np.int64))
    free = np.setdiff1d(np.arange(u_ref.size), pins)
    args = RodArgs(scene, jnp.asarray(u_ref), jnp.asarray(free))
    prob = BifurcationProblem(_pinned_energy, u_ref[free], phi0, args, n_zero_modes=0, backend=backend)
    return _with_symmetry(PinnedRod(prob, scene, pins, free, u_ref))


def _with_symmetry(rod):
    """rod, given the ``symmetrize`` hook where the scene has the joint's two-fold symmetry and
    exactly the 7 gauge DOFs are pinned (other pins are no gauge of the symmetric states)."""
    if not has_joint_symmetry(rod.scene) or rod.pins.size != 7:
        return rod
    edge = float(np.mean(np.asarray(rod.scene.rest_lengths)))
    scale = np.asarray(rod.scene.to_scaled(np.ones(rod.u_ref.size)))  # 1 / dof_scale

    def symmetrize(u_free, tol):
        q = rod.q(u_free)
        sym = two_fold_asymmetry(np.asarray(rod.scene.positions(q)))
        # tol is in scaled units: node coordinates in edge lengths
        if not sym.asymmetry <= tol * edge:
            return None
        q_sym = symmetrize_pinned(rod.scene, q, rod.pins, rod.u_ref[rod.pins], sym)
        return (q_sym * scale)[rod.free]

    rod.problem.symmetrize = symmetrize
    return rod


# A sliding soft mode with |lambda| at most this (scaled units) is a numerically exact symmetry,
# along which Newton's corrector stalls: ``knot_problem`` pins it like a gauge.
EXACT_SLIDE_TOL = 1e-9


def knot_problem(scene, q_ref, phi0, *, pins=None, capacity=None, sliding=CLEAN_SLIDE_FRACTION, backend=None,
                 slide_tol=EXACT_SLIDE_TOL):
    """A knot (a closed rod with soft self-contact) as a BifurcationProblem, at O(N) per energy.

    As ``pinned_problem``, but the energy is evaluated at O(N) through a ``Neighbourhood`` in
    ``RodArgs.nbr``, rebuilt after an accepted point where stale (``update_args``; padded to
    ``capacity`` pairs). A mode whose ``sliding_fraction`` is below ``sliding`` (a slide) is left
    out of the Morse index and the event tests. backend: default ``SparseBackend`` from
    ``SPARSE_MIN_DOF`` DOFs on, else ``DenseBackend``. Exact slides: with ``pins`` None, if the softest sliding mode at q_ref has |lambda| <=
    ``slide_tol`` (default ``EXACT_SLIDE_TOL``; 0 never pins), the free node coordinate that moves
    most along it is pinned too (``PinnedRod.slide_pin``; ``full_gradient`` shows the force it holds).
    Returns a PinnedRod (its problem's args are a ``RodArgs`` with the neighbourhood).
    """
    q_ref = np.asarray(q_ref, dtype=float)
    u_ref = np.asarray(scene.to_scaled(q_ref), dtype=float)
    if pins is None:
        pins, _ = gauge_pins(scene, jnp.asarray(u_ref), float(phi0))
        if slide_tol > 0.0:
            rod = knot_problem(scene, q_ref, phi0, pins=pins, capacity=capacity, sliding=sliding, backend=backend)
            extra = _exact_slide_pin(rod, q_ref, sliding, slide_tol)
            if extra is None:
                return rod
            rod = knot_problem(scene, q_ref, phi0, pins=np.append(np.asarray(pins), extra), capacity=capacity,
                               sliding=sliding, backend=rod.problem.backend)
            return replace(rod, slide_pin=extra)
    pins = np.unique(np.asarray(pins, dtype=np.int64).ravel())
    free = np.setdiff1d(np.arange(u_ref.size), pins)
    nbr0 = scene.neighbourhood(q_ref, float(phi0), capacity=capacity)
    # the diameter each neighbourhood was built for (a fold curve in D grows it: ``set_diameter``)
    built_for = weakref.WeakKeyDictionary({nbr0: float(scene.material.D)})
    holder = {}

    def update_args(u_free, phi, args):
        sc, nbr = args.scene, args.nbr
        q = holder["rod"].q(u_free)
        D = float(sc.material.D)
        upd = nbr.update(sc, q, float(phi), grown=max(0.0, D - built_for.get(nbr, D)))
        if not upd.outdated:  # still exact: the same args, nothing to re-trace
            return args
        built_for[upd.nbr] = D
        return args._replace(nbr=upd.nbr)

    def soft_modes(u_free, phi, values, vectors):
        rod = holder["rod"]
        return split_sliding(scene, rod.q(u_free), free, u_ref.size, values, vectors, sliding)

    args = RodArgs(scene, jnp.asarray(u_ref), jnp.asarray(free), nbr0)
    if backend is None:
        backend = SparseBackend(assemble_pinned_hessian) if choose_backend(scene).backend.structured else DenseBackend()
    host = getattr(backend, "host", False)
    jacobian = _pinned_parts if host else _pinned_structured_hessian
    prob = BifurcationProblem(_pinned_energy, u_ref[free], phi0, args, n_zero_modes=0, backend=backend,
                              update_args=update_args, soft_modes=soft_modes, jacobian=jacobian,
                              programs=None if host else _ScenePrograms())
    rod = _with_symmetry(PinnedRod(prob, scene, pins, free, u_ref))
    holder["rod"] = rod
    return rod


def _exact_slide_pin(rod, q_ref, sliding, slide_tol):
    """The DOF to pin along an exactly soft slide of ``rod`` at its reference state, or None."""
    prob = rod.problem
    _, J, _ = prob.linearise(np.asarray(prob.u0), prob.p0, prob.args)
    values, vectors, _ = prob.backend.spectrum(J, 4, 0, 1e-13)
    if not np.all(np.isfinite(values)):
        return None
    values, vectors, soft = split_sliding(rod.scene, q_ref, rod.free, rod.u_ref.size, values, vectors, sliding)
    if not soft.any() or abs(float(values[soft][0])) > slide_tol:
        return None
    free = np.asarray(rod.free)
    nodes = np.flatnonzero(free < 3 * int(rod.scene.n_nodes))  # node coordinates (a slide moves nodes)
    return int(free[nodes[np.argmax(np.abs(vectors[nodes, np.flatnonzero(soft)[0]]))]])


def split_sliding(scene, q, free, n_full, values, vectors, threshold=CLEAN_SLIDE_FRACTION):
    """``jaxrod.linalg.stability.split_slide`` on a pinned knot's lowest eigenpairs (values (m,),
    vectors (n_free, m)) embedded in all n_full DOFs, at the state q. -> (values, vectors, soft):
    the slide as one soft direction (if below ``threshold``), the rest as ascending Ritz pairs."""
    V = np.asarray(vectors, dtype=float)
    full = np.zeros((n_full, V.shape[1]))
    full[np.asarray(free)] = V
    vals, coef, soft = split_slide(scene, q, values, full, threshold)
    if soft.any() and _split_hides_a_shape_instability(scene, q, np.asarray(values, dtype=float), full, vals, soft):
        return np.asarray(values, dtype=float), V, np.zeros(V.shape[1], dtype=bool)
    return vals, V @ coef, soft


# Eigenvalues within this of zero (scaled units, ~round-off) count as neither sign in the check below.
SPLIT_SIGN_TOL = 1e-14
# A negative direction of J that the split hides is a shape instability above this sliding fraction
# (hidden crossings seen at 0.20 and more; slide-dominated saddles at 0.05-0.06).
HIDDEN_SHAPE_FRACTION = 0.15


def _split_hides_a_shape_instability(scene, q, values, full, split_values, soft):
    """Whether splitting the slide off hides a negative direction of J that changes the shape: where
    the slide couples strongly to a shape mode near zero, J can have a negative direction
    that neither the slide's Rayleigh quotient nor the complement's Ritz values show (Haynsworth).
    So J's negative eigenvectors that change the shape (sliding fraction above
    HIDDEN_SHAPE_FRACTION) are counted too; if they outnumber the complement's negative Ritz
    values, the split is not made."""
    tol = SPLIT_SIGN_TOL
    negative = np.flatnonzero(values < -tol)
    counted = int(np.sum(split_values[~soft] < -tol))
    if negative.size <= counted:
        return False
    return int(np.sum(sliding_fraction(scene, q, full[:, negative]) > HIDDEN_SHAPE_FRACTION)) > counted


def sliding_slice(rod, event, *, candidates=None):
    """Pick one member of the circle of buckled branches at a ring's double branch point.

    At a ring's O(2)-symmetric double branch point (``event``, kernel V (n, 2)) the emanating
    solutions form a circle (the buckled shape slid along its centreline), whose zero eigenvalue
    stalls the corrector. It is fixed like a gauge by one more pin: the free node coordinate k
    (among ``candidates``, default all) whose row of V is largest; the branch kept is along V eta,
    eta orthogonal to V[k]. Returns (rod8, event8): the PinnedRod with the extra pin and the event
    as a simple branch point of it, for ``switch_branches`` or ``continuation``.
    """
    V = np.asarray(event.v)
    if V.shape[1] != 2:
        raise ValueError(f"need a double branch point (a 2-dimensional kernel), got {V.shape[1]}")
    n_pos = 3 * int(rod.scene.n_nodes)
    free = np.asarray(rod.free)
    cand = np.where(free < n_pos)[0] if candidates is None else np.searchsorted(free, np.asarray(candidates))
    j = int(cand[np.argmax(np.linalg.norm(V[cand], axis=1))])
    k = int(free[j])
    eta = np.array([-V[j, 1], V[j, 0]])
    eta /= np.linalg.norm(eta)
    rod8 = _build(rod.scene, np.asarray(rod.u_ref), event.p, np.append(rod.pins, k), rod.problem.backend)
    keep = np.arange(free.size) != j
    v = (V @ eta)[keep]
    v /= np.linalg.norm(v)
    u = np.asarray(event.u)[keep]
    _, J, _ = rod8.problem.linearise(jnp.asarray(u), jnp.asarray(event.p), rod8.problem.args)
    crit = np.array([float(v @ np.asarray(J) @ v)])
    tangent = np.append(np.asarray(event.tangent)[:-1][keep], np.asarray(event.tangent)[-1])
    lo = min(event.morse_before, event.morse_after)
    before, after = (lo, lo + 1) if event.morse_after > event.morse_before else (lo + 1, lo)
    event8 = Event(EventKind.BRANCH_POINT, float(event.p), u, v[:, None], crit, event.residual, event.iterations, 1,
                         before, after, event.step, tangent, event.converged)
    return rod8, event8
