"""The two-fold symmetry through a closed rod's joint (jaxrod.model.symmetry), and the stable-only
continuation keeping a symmetric branch on it (``ContinuationOptions.keep_symmetry``)."""
import math
from dataclasses import replace

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod.continuation import ContinuationOptions
from jaxrod.continuation.engine import ROUND_OFF_ASYMMETRY, SYMMETRIC_TOL, ContinuationEngine
from jaxrod.continuation.options import Task
from jaxrod.solve.equilibrium import relax
from jaxrod.model.geometry import resample_closed
from jaxrod.model.scenes import clamped_rod, trefoil
from jaxrod.model.symmetry import joint_two_fold, symmetrize, two_fold_asymmetry

N = 41


@pytest.fixture(scope="module")
def knot():
    return trefoil(D=8.0, L=292.0, N=N)


def _image(scene, q, sym):
    n = scene.n_nodes
    x, theta = q[:3 * n].reshape(n, 3), q[3 * n:]
    return np.concatenate([sym.map_positions(x).ravel(), -theta[::-1] + 2.0 * theta.mean()])


def test_the_energy_is_invariant_under_the_map_for_any_state(knot):
    # Not only at symmetric states: the map is a symmetry of the discrete energy (stretch, bend,
    # twist with the joint's holonomy, contact), so E(S q) = E(q) for a random state.
    q0 = np.asarray(knot.q_init)
    sym = two_fold_asymmetry(np.asarray(knot.positions(q0)))
    q = q0 + 0.05 * np.random.default_rng(0).standard_normal(q0.shape)
    for phi in (0.0, 3.3, -7.0 * math.pi):
        e, e_image = float(knot.energy(jnp.asarray(q), phi)), float(knot.energy(jnp.asarray(_image(knot, q, sym)), phi))
        assert abs(e_image - e) <= 1e-13 * abs(e), (phi, e, e_image)
    # and a wrong map is not a symmetry: twist angles reversed but not negated (the twist density
    # would change sign)
    n = knot.n_nodes
    wrong = _image(knot, q, sym)
    wrong[3 * n:] = q[3 * n:][::-1]
    assert abs(float(knot.energy(jnp.asarray(wrong), 3.3)) - float(knot.energy(jnp.asarray(q), 3.3))) > 1e-6


def test_the_drawn_trefoil_is_symmetric_and_a_slid_one_is_not(knot):
    q0 = np.asarray(knot.q_init)
    edge = knot.length / N
    assert joint_two_fold(knot, q0, 1e-12 * edge) is not None
    # The same curve with its nodes slid a quarter edge along it: node 0 is off the axis.
    x = np.asarray(knot.positions(q0))
    dense = resample_closed(x, 40 * N)
    slid = np.roll(dense, -10, axis=0)[::40]
    assert two_fold_asymmetry(slid).asymmetry > 1e-3 * edge
    q_slid = np.concatenate([slid.ravel(), q0[3 * N:]])
    assert joint_two_fold(knot, q_slid, 1e-6 * edge) is None
    # The projection: symmetric result, idempotent, identity on a symmetric state.
    qs = symmetrize(knot, q_slid)
    assert two_fold_asymmetry(qs[:3 * N].reshape(N, 3)).asymmetry < 1e-12 * edge
    np.testing.assert_allclose(symmetrize(knot, qs), qs, atol=1e-12 * edge)
    np.testing.assert_allclose(symmetrize(knot, q0), q0, atol=1e-12 * edge)


def test_rods_without_the_symmetry_are_left_alone():
    from jaxrod.model.material import Material

    rod = clamped_rod(N=12, length=1.0, material=Material(B=1.0, C=1.0, EA=1e3))
    assert joint_two_fold(rod, np.asarray(rod.q_init), 1.0) is None


def test_a_corrected_state_that_slid_is_brought_back_to_the_symmetric_branch(knot):
    # The engine's projection after the corrector: a state pushed off the symmetry by a small
    # antisymmetric displacement (what the corrector leaves along the nearly null sliding modes)
    # comes back symmetric and converged, near where it was.
    opts = ContinuationOptions().resolved(knot, Task.FOLLOW_TWIST, 1.0)
    engine = ContinuationEngine(knot, Task.FOLLOW_TWIST, opts)
    phi = -2.0 * math.pi
    e0 = relax(knot, phi, np.asarray(knot.q_init), replace(engine.corrector_options, max_steps=None))
    edge = knot.length / N
    # relaxed from the symmetric drawing, symmetric to the minimiser's drift along the slide
    assert two_fold_asymmetry(e0.x).asymmetry < SYMMETRIC_TOL * edge
    q = np.asarray(e0.q)
    push = 1e-4 * edge * np.random.default_rng(1).standard_normal(q.shape)
    push = push - symmetrize(knot, push + q) + q  # the antisymmetric part of the push
    slid = replace(e0, q=q + push, x=np.asarray(knot.positions(q + push)))
    assert two_fold_asymmetry(slid.x).asymmetry > ROUND_OFF_ASYMMETRY * edge
    back = engine.kept_symmetric(e0.q, slid, phi, previous=e0)
    assert back is not slid
    assert two_fold_asymmetry(back.x).asymmetry < 1e-11 * edge
    assert back.solution.grad_norm <= opts.gtol
    assert np.max(np.abs(back.x - e0.x)) < 1e-3 * edge
    # keep_symmetry=False: the state is left as the corrector gave it
    off = ContinuationEngine(knot, Task.FOLLOW_TWIST, ContinuationOptions(keep_symmetry=False).resolved(knot, Task.FOLLOW_TWIST, 1.0))
    assert off.kept_symmetric(e0.q, slid, phi, previous=e0) is slid


def test_a_diagram_path_starts_where_the_critical_eigenvalue_is_resolved(knot):
    # diagram.backed_off_start: the study's last stable state as it is where its critical
    # eigenvalue is resolved (or the model says nothing), else relaxed at the twist where the
    # linear model puts the eigenvalue at START_EIGENVALUE, keeping the joint's symmetry.
    from jaxrod.studies.diagram import MAX_START_BACK, START_EIGENVALUE, backed_off_start
    from jaxrod.solve.equilibrium import solve_equilibrium

    q0 = np.asarray(knot.q_init)
    for eigenvalue, rate in ((2 * START_EIGENVALUE, -1e-6), (1e-9, -1e-6 * -1), (math.nan, -1e-6), (1e-9, math.nan)):
        q, phi = backed_off_start(knot, q0, 0.5, eigenvalue, rate, 1.0)
        assert q is q0 and phi == 0.5
    q, phi = backed_off_start(knot, q0, 0.0, 1e-9, -1e-6, 1.0)  # the end lies at phi > 0: back to phi < 0
    assert phi == pytest.approx(-(START_EIGENVALUE - 1e-9) / 1e-6, rel=1e-12) and -phi <= MAX_START_BACK
    edge = knot.length / N
    assert two_fold_asymmetry(np.asarray(knot.positions(q))).asymmetry < 1e-11 * edge
    e = solve_equilibrium(knot, phi, q, replace(_newton_options(), gtol=1e-9))
    assert e.solution.iterations <= 1  # already an equilibrium there
    q, phi = backed_off_start(knot, q0, 0.0, 1e-12, 1e-9, -1.0)  # end at phi < 0, a flat eigenvalue: at most MAX_START_BACK
    assert phi == pytest.approx(MAX_START_BACK)


def _newton_options():
    from jaxrod.solve.equilibrium import EquilibriumOptions

    return EquilibriumOptions(method="newton", with_stability=False)


def _antisymmetric(scene, q, size, seed):
    """A random displacement of rms ``size`` with no symmetric part at the state q."""
    push = np.random.default_rng(seed).standard_normal(q.shape)
    push = push - symmetrize(scene, push + q) + q
    return size * push / np.sqrt(np.mean(push ** 2))


def test_a_path_from_a_symmetric_drawing_starts_on_the_symmetry(knot):
    # follow_twist's first relaxation, from a start within SYMMETRIC_TOL of the symmetry, is brought
    # back onto it: the minimiser leaves the near-null (odd) slide where round-off put it (the
    # trefoil at N = 128, D/L = 0.010: 0.14 edges from its drawing), and the branch's events then
    # depend on that placement of the nodes. At 4 pi the symmetric state is a minimum at this N.
    from jaxrod.continuation import follow_twist

    edge = knot.length / N
    q0 = np.asarray(knot.q_init)
    start = q0 + _antisymmetric(knot, q0, 1e-7 * edge, 2)
    assert joint_two_fold(knot, start, SYMMETRIC_TOL * edge) is not None
    asym = {}
    for keep in (True, False):
        path = follow_twist(knot, 4.0 * math.pi, 4.2 * math.pi,
                            ContinuationOptions(step=0.2 * math.pi, max_switches=0, keep_symmetry=keep), start=start)
        asym[keep] = two_fold_asymmetry(np.asarray(path.points[0].equilibrium.x)).asymmetry / edge
    assert asym[True] < 1e-11
    assert asym[False] > 1e-10  # without it the slide's share of the push stays


def test_a_symmetric_saddle_is_not_taken_for_the_start():
    # At N = 48 the trefoil relaxed from its drawing leaves the symmetry by 0.28 edges, and rightly:
    # the symmetric state is a saddle of a shape mode (lowest eigenvalue -8.3e-4). The path starts
    # from the minimum the relaxation found, not from the projection.
    from jaxrod.continuation import follow_twist

    n = 48
    knot = trefoil(D=8.0, L=292.0, N=n)
    path = follow_twist(knot, 0.0, 0.1 * math.pi, ContinuationOptions(step=0.1 * math.pi, max_switches=0))
    first = path.points[0].equilibrium
    assert first.stability.n_negative == 0
    assert two_fold_asymmetry(np.asarray(first.x)).asymmetry > 0.1 * knot.length / n


def test_a_pinned_knot_problem_is_projected_onto_the_symmetry_with_its_gauge_kept(knot):
    # knot_problem's symmetrize hook: the state projected in all DOFs, then moved rigidly (and its
    # twist angles shifted) until the 7 pinned DOFs are back at their values, so that the free DOFs
    # alone describe a symmetric state; event_curve's relaxation keeps a symmetric start symmetric
    from jaxrod.continuation.arclength.event_curve import relax_problem
    from jaxrod.continuation.arclength.rods import knot_problem

    edge = knot.length / N
    phi = -2.0 * math.pi
    e0 = relax(knot, phi, np.asarray(knot.q_init))
    q_sym = symmetrize(knot, np.asarray(e0.q))
    rod = knot_problem(knot, q_sym, phi, slide_tol=0.0)
    prob = rod.problem
    u_sym = np.asarray(prob.u0)
    np.testing.assert_allclose(prob.symmetrize(u_sym, SYMMETRIC_TOL), u_sym, atol=1e-12)
    q_off = q_sym + _antisymmetric(knot, q_sym, 1e-6 * edge, 3)
    u_off = rod.restrict(np.asarray(knot.to_scaled(q_off)))
    off = two_fold_asymmetry(rod.nodes(u_off)).asymmetry / edge
    assert off > 1e-7  # the push moved the free DOFs off the symmetry
    assert prob.symmetrize(u_off, 0.1 * off) is None
    back = prob.symmetrize(u_off, SYMMETRIC_TOL)
    assert two_fold_asymmetry(rod.nodes(back)).asymmetry / edge < 1e-12
    assert np.max(np.abs(back - u_off)) < 1e-4  # the push, and the rigid motion that restores the pins
    relaxed = relax_problem(prob, back, phi + 0.1, symmetric=True)
    assert two_fold_asymmetry(rod.nodes(relaxed)).asymmetry / edge < 1e-11
