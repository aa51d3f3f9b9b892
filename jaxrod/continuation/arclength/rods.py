"""Rods as bifurcation problems: the scene's scaled energy with its gauge pinned.

A closed rod's Hessian is singular everywhere along its 7 symmetry generators (3 translations, 3
rotations, the uniform shift of the twist angles), but the continuation's corrector and locators
need J regular away from events. As on jaxrod's O(N) path (``jaxrod.linalg.sparse``), the gauge
is fixed by pinning 7 DOFs -- 3 coordinates of node 0, 2 of node ~N/3, 1 of node ~2N/3 and the twist
angle of edge 0, the coordinates chosen by ``gauge_pins`` -- at their values in a reference state.
The problem's unknowns are the other (free) DOFs, in the scene's scaled units (node coordinates in
edge lengths, energy in B/l):

    E_pinned(u_free, phi) = scene.scaled_energy(embed(u_free), phi),

so that F = grad E_pinned is the full gradient with the pinned rows dropped. At an equilibrium the
pinned Hessian is congruent to the Hessian projected off the symmetries (see the module docstring
of ``jaxrod.linalg.sparse``): same inertia, hence the same Morse index, and its eigenvalues cross
zero at the same parameters (not with the same values away from zero: the metric differs).

Those 7 pins remove exact symmetries, so every solution of the pinned problem is an equilibrium of
the rod (the gradient along each generator vanishes identically, and the pinned DOFs move the rod
along the generators): ``full_gradient`` checks it. ``extra_pins`` fixes further DOFs the same way;
that is a gauge only for a further (exact or numerically exact) symmetry -- e.g. the material
sliding along a buckled ring, see ``benchmarks/bifurcation_michell.py`` -- and ``full_gradient``
then measures how exact it is (the force the extra pin holds).

The exact energy (the writhe that fixes the holonomy's branch, contact over all pairs) is O(N^2)
and ``pinned_problem`` assembles J densely (``DenseBackend``): meant for N up to ~100.
``knot_problem`` evaluates through a neighbourhood (O(N)) and, from ``SPARSE_MIN_DOF`` DOFs on,
takes ``SparseBackend`` (SciPy's sparse factorisations on the host): the fold of the trefoil at
N = 481 is located in ~40 s (``benchmarks/sparse_fold.py``). From N ~ 250 on the knot's material
slide is a numerically exact symmetry (pinned eigenvalue ~1e-12 at N = 481): pin one more DOF
along it (``pins=``), or Newton's corrector steps by edge lengths along it and stalls.
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
    ``Neighbourhood`` (None without contact).

    The reference and the indices travel as arguments, not as constants of the energy's closure:
    two problems of the same shape (another start, another reference state) then lower to the
    same program, which the compilation cache reuses instead of compiling again (measured: 4 s
    per function at N = 121). Vary a material parameter with ``args._replace(scene=...)``.
    """

    scene: Any
    u_ref: Any
    free: Any
    nbr: Any = None


def _with_material(args, B, C, EA, D):
    # jax.tree_util rebuilds the material without __init__ (its leaves may be tracers), and a
    # shallow copy of the frozen scene takes it: nothing else in a scene derives from the material
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
    B and C scale as D^4, EA as D^2, and the contact distance is D. Traceable (see
    ``set_poisson_ratio``). The neighbourhood (contact candidates) is the one in args: valid for
    a D near the one it was built with."""
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
    """The pinned Hessian's parts (``sparse_contact.hessian_parts`` of the embedded state), for
    ``SparseBackend``: traceable, O(N)."""
    return hessian_parts(args.scene, _embedded(u_free, args), phi, args.nbr)


def assemble_pinned_hessian(parts, args):
    """The pinned Hessian as a ``HostMatrix`` (S restricted to the free DOFs, a restricted)."""
    S, w, a = assemble(args.scene, parts)
    free = np.asarray(args.free)
    return HostMatrix(S.tocsr()[free][:, free].tocsc(), w, a[free])


class _ScenePrograms:
    """A pinned rod's (F, J, F_p) and contracted third derivatives (``BifurcationProblem``'s
    ``programs`` hook) from the whole scene's programs (``stability.scene_linearisation`` and
    ``stability.scene_bilinear_gradient``), restricted to the free DOFs: E_pinned(u_free) =
    E(embed(u_free)), so F, F_p and the gradients are the scene's free rows and J its free rows and
    columns, exactly. A study compiled those programs for its stability analysis already (same
    scene, same shapes): its diagram then compiles none of its own for them (command 1, cold:
    ~4.5 s of XLA at N = 121)."""

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
    """A rod scene as a ``BifurcationProblem`` in its free DOFs.

    problem: the BifurcationProblem (u = free scaled DOFs, p = phi, args = a ``RodArgs``, a pytree,
    so ``fold_curve`` can vary a material parameter through ``set_mu``); scene; pins (k,) and free
    (n - k,) indices into the scene's DOFs q; u_ref (n,) the scaled reference state whose pinned
    values are held.
    """

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
        """``embed`` on the host (numpy): as eager JAX operations it would be a handful more
        executables for every process to load."""
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
        """Max-norm of the gradient of the scaled energy over ALL DOFs, pinned ones included:
        ~ roundoff at an equilibrium of the rod (scaled units)."""
        g = _scaled_gradient(self.scene, jnp.asarray(self._host_embed(u_free)), jnp.asarray(phi, dtype=jnp.float64))
        return float(np.max(np.abs(np.asarray(g))))

    def writhe(self, u_free):
        """Exact polygon writhe of the centreline (``jaxrod.model.topology.writhe``)."""
        return float(_writhe(jnp.asarray(self.nodes(u_free))))

    def min_distance(self, u_free, exclude=2):
        """Closest approach between segments more than ``exclude`` apart along the rod (physical
        units, ``jaxrod.model.geometry.closest_approach``); self-contact when it reaches the diameter D."""
        return closest_approach(self.nodes(u_free), closed=True, exclude=exclude)


_writhe = jax.jit(functools.partial(writhe, closed=True))


@cached_jit
def _scaled_gradient(scene, u, phi):
    return jax.grad(scene.scaled_energy)(u, phi)


def pinned_problem(scene, q_ref, phi0, *, pins=None, extra_pins=(), backend=None):
    """The rod ``scene`` as a BifurcationProblem with its gauge pinned at the state ``q_ref``.

    scene: a closed rod without contact (e.g. ``jaxrod.michell_ring``); q_ref (n,): physical DOFs of
    the reference state (an equilibrium at phi0, or a guess the first corrector converges from);
    pins: q indices to pin (default ``gauge_pins(scene, u_ref, phi0)``: the 7 gauge DOFs chosen for
    the best-conditioned gauge at that state); extra_pins: further q indices (see the module
    docstring); backend: default ``DenseBackend()``. The problem starts at (restrict(u_ref), phi0)
    with n_zero_modes = 0 (nothing singular is left in the pinned Hessian). Returns a PinnedRod.
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
    """rod, its problem given the ``symmetrize`` hook where the scene has the joint's two-fold
    symmetry (``jaxrod.model.symmetry``) and exactly the 7 gauge DOFs are pinned (a pin along a slide or
    an extra pin is no gauge of the symmetric states: no hook then)."""
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


# A soft mode of the pinned Hessian that slides (``split_sliding``) with |lambda| at most this, in
# scaled units, is a numerically exact symmetry of the discrete knot: the trefoil (8, 292) has
# ~1e-7 at N = 121 and -2.3e-12 at N = 481. Along such a mode Newton's corrector steps by edge
# lengths and stalls at a residual of ~6e-8, above newton_tol (measured with either backend at
# N = 481 and 961; benchmarks/sparse_fold.py); ``knot_problem`` then pins it like a gauge.
EXACT_SLIDE_TOL = 1e-9


def knot_problem(scene, q_ref, phi0, *, pins=None, capacity=None, sliding=CLEAN_SLIDE_FRACTION, backend=None,
                 slide_tol=EXACT_SLIDE_TOL):
    """A knot (a closed rod with soft self-contact) as a BifurcationProblem, at O(N) per energy.

    As ``pinned_problem`` (7 gauge DOFs pinned at the state q_ref (n,), physical DOFs, at phi0),
    but the energy is evaluated through a ``Neighbourhood`` (contact candidates and the writhe
    that fixes the holonomy's branch, ``jaxrod.model.neighbourhood``) carried in the problem's args
    (``RodArgs.nbr``): the same value as the exact energy while the state stays inside it, O(N) instead
    of O(N^2). After every accepted point the neighbourhood is rebuilt if it went stale (the
    problem's ``update_args``; its capacity, padded to ``capacity`` pairs, is kept so that
    nothing recompiles).

    Soft modes: a loose knot has near-null modes that move material along its own centreline
    (strands slipping; ~1e-11 to 1e-7 in scaled units, of either sign, depending on N). They are
    told apart by their shape, not by a band of eigenvalues: a mode whose ``sliding_fraction``
    (what is left of it once the best sliding field plus a rigid motion is taken out) is below
    ``sliding`` (default ``jaxrod.linalg.stability.CLEAN_SLIDE_FRACTION``, 5e-3) is a soft mode, left out
    of the Morse index and of the event tests. A buckling mode changes the shape: its fraction is
    O(1). The slides split off in the tests and in command 1 leave at most 1.2e-4; the looser 0.05
    let the least sliding mix of the span pass for a slide (0.04 on the trefoil at N = 241, mostly
    a stiff mode with some of the nearly degenerate buckling pair), and splitting it off made the
    states past the tightening fold look stable (``tests/test_bifurcation_knots.py``).
    backend: default ``SparseBackend`` (SciPy's sparse factorisations on the host, O(N)) from
    ``linalg.backend.SPARSE_MIN_DOF`` DOFs on, else ``DenseBackend``.
    Exact slides: with ``pins`` None, if the softest sliding mode of the gauge-pinned Hessian at
    q_ref has |lambda| <= ``slide_tol`` (default ``EXACT_SLIDE_TOL``; 0 never pins), it is a
    numerically exact symmetry (large N), which stalls the corrector; it is then fixed like the
    gauge by one more pin, the free node coordinate that moves most along it (``PinnedRod.slide_pin``;
    check ``full_gradient`` at the results: the force that pin holds, ~roundoff when the symmetry
    is exact).
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
    # the diameter each neighbourhood was built for: its candidates are the pairs closer than
    # D_built + skin, valid for a diameter D while no node moved more than (skin - (D - D_built)) / 2
    # (a fold curve in D: ``set_diameter``)
    built_for = weakref.WeakKeyDictionary({nbr0: float(scene.material.D)})
    holder = {}

    def update_args(u_free, phi, args):
        sc, nbr = args.scene, args.nbr
        q = holder["rod"].q(u_free)
        D = float(sc.material.D)
        upd = nbr.update(sc, q, float(phi), grown=max(0.0, D - built_for.get(nbr, D)))
        if not upd.outdated:  # still exact here: keep it (the same args, nothing to re-trace)
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
    """Split the material-sliding direction off the span of the lowest eigenvectors of a pinned
    knot (``jaxrod.linalg.stability.split_slide`` on the vectors embedded in all n_full DOFs).

    values (m,), vectors (n_free, m): the lowest eigenpairs of the pinned Hessian; q: the state.
    Returns (values, vectors, soft): the slide, if its fraction is below ``threshold``, as one
    soft direction with its Rayleigh quotient, and the rest of the span as Ritz pairs (ascending).
    """
    V = np.asarray(vectors, dtype=float)
    full = np.zeros((n_full, V.shape[1]))
    full[np.asarray(free)] = V
    vals, coef, soft = split_slide(scene, q, values, full, threshold)
    if soft.any() and _split_hides_a_shape_instability(scene, q, np.asarray(values, dtype=float), full, vals, soft):
        return np.asarray(values, dtype=float), V, np.zeros(V.shape[1], dtype=bool)
    return vals, V @ coef, soft


# Eigenvalues within this of zero (scaled units; round-off is ~1e-14 at N = 121) count as neither sign
# when a split is checked against the inertia.
SPLIT_SIGN_TOL = 1e-14
# A negative direction of J that the split hides counts as a shape instability above this sliding
# fraction. Measured where the split hid one: 0.20-0.28 at crossings (the trefoil's buckled+ branch
# at N = 121, its tightening curve at N = 128 and D/L = 0.021); slide-dominated mixes that are saddles
# of the sliding landscape: 0.05-0.06 (the tightening curve at D/L = 0.020, where counting them lost
# the branch point's location). SLIDING_FRACTION (0.05) separates a clean mode from a slide.
HIDDEN_SHAPE_FRACTION = 0.15


def _split_hides_a_shape_instability(scene, q, values, full, split_values, soft):
    """Whether splitting the slide off hides a negative direction of J that changes the shape.

    The split counts the Morse index on the Ritz values of the complement of the slide direction s.
    Where the slide couples strongly to a shape mode near zero, J can have a negative direction that
    neither s's Rayleigh quotient nor the complement's Ritz values show (Haynsworth: n_neg(J) =
    [s^T J s < 0] + n_neg(Schur complement), and the complement's count can fall below the Schur
    complement's). So J's negative eigenvectors are counted too, those that change the shape
    (sliding fraction above HIDDEN_SHAPE_FRACTION = 0.15: a slide leaves < 1e-3, the hidden
    crossings seen 0.20 and more); if they outnumber the complement's negative Ritz values, the
    split is not made (J's eigenpairs stay as they are, none soft). Measured on the trefoil at
    N = 121 (--step 0.25pi): on its buckled+ branch the slide sat at 2.1e-7, the shape Ritz value
    at 1.7e-7 and J's lowest eigenvalue at -1.3e-9 (7.0411 pi, fraction 0.20), and the split hid
    the branch point at 7.041 pi (the path ended at a fold at 7.069 pi); at the opening fold J's
    negative direction -1.4e-8 is the slide (fraction 3e-4), and the split stands."""
    tol = SPLIT_SIGN_TOL
    negative = np.flatnonzero(values < -tol)
    counted = int(np.sum(split_values[~soft] < -tol))
    if negative.size <= counted:
        return False
    return int(np.sum(sliding_fraction(scene, q, full[:, negative]) > HIDDEN_SHAPE_FRACTION)) > counted


def sliding_slice(rod, event, *, candidates=None):
    """Pick one member of the circle of buckled branches at a ring's double branch point.

    At the O(2)-symmetric double branch point of a ring (``event``: multiplicity 2, kernel V
    (n, 2), on the trivial branch of ``rod``) the emanating solutions form a circle family: the
    buckled shape slid along its own centreline (material relabelling), which for a uniform rod is
    a symmetry -- exact in the continuum; of the discrete ring's D_N symmetry, the lowest invariant
    of the mode-2 amplitude z that is not O(2)-invariant is Re z^(N/2) (N even), so the slide is
    broken only at that order, i.e. to roundoff for N >= 24. Each buckled solution carries a
    (numerically) zero eigenvalue, which the pinned Hessian keeps: the corrector's tangent drifts
    along it and the path stalls. Like the rigid motions it is a gauge, fixed by one more pin: the
    coordinate k of a free node (default candidates: all free node coordinates) whose row of V is
    largest, held at its value on the trivial branch (constant there: the circle does not move with
    phi). The buckled branch kept is the one along V eta with eta orthogonal to V[k] (u_k = u_ref[k]
    on it to first order).

    Returns (rod8, event8): the PinnedRod with the extra pin and the event as a simple branch point
    of it (u, v (n-1, 1) = the restricted V eta, normalised, tangent restricted, Morse index after
    = before + 1: one of the crossing pair is left, by interlacing), so that ``switch_branches`` or
    a ``continuation`` started at u + r v follows that buckled branch with the slide pinned.
    Check ``rod8.full_gradient`` along it: the force the extra pin holds, ~roundoff when the
    sliding symmetry is exact.
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
