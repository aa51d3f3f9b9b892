"""The two-fold symmetry through a closed rod's joint (jaxrod.symmetry), and the stable-only
continuation keeping a symmetric branch on it (``ContinuationOptions.keep_symmetry``)."""
import math
from dataclasses import replace

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod.continuation import ContinuationOptions
from jaxrod.continuation.engine import ROUND_OFF_ASYMMETRY, SYMMETRIC_TOL, _Engine
from jaxrod.continuation.options import Task
from jaxrod.equilibrium import relax
from jaxrod.geometry import resample_closed
from jaxrod.scenes import clamped_rod, trefoil
from jaxrod.symmetry import joint_two_fold, symmetrize, two_fold_asymmetry

N = 41


@pytest.fixture(scope="module")
def knot():
    return trefoil(8.0, 292.0, N)


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
    from jaxrod.material import Material

    rod = clamped_rod(12, 1.0, Material(B=1.0, C=1.0, EA=1e3))
    assert joint_two_fold(rod, np.asarray(rod.q_init), 1.0) is None


def test_a_corrected_state_that_slid_is_brought_back_to_the_symmetric_branch(knot):
    # The engine's projection after the corrector: a state pushed off the symmetry by a small
    # antisymmetric displacement (what the corrector leaves along the nearly null sliding modes)
    # comes back symmetric and converged, near where it was.
    opts = ContinuationOptions().resolved(knot, Task.FOLLOW_TWIST, 1.0)
    engine = _Engine(knot, Task.FOLLOW_TWIST, opts)
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
    back = engine._kept_symmetric(e0, slid, phi)
    assert back is not slid
    assert two_fold_asymmetry(back.x).asymmetry < 1e-11 * edge
    assert back.solution.grad_norm <= opts.gtol
    assert np.max(np.abs(back.x - e0.x)) < 1e-3 * edge
    # keep_symmetry=False: the state is left as the corrector gave it
    off = _Engine(knot, Task.FOLLOW_TWIST, ContinuationOptions(keep_symmetry=False).resolved(knot, Task.FOLLOW_TWIST, 1.0))
    assert off._kept_symmetric(e0, slid, phi) is slid


def test_a_diagram_path_starts_where_the_critical_eigenvalue_is_resolved(knot):
    # diagram.backed_off_start: the study's last stable state as it is where its critical
    # eigenvalue is resolved (or the model says nothing), else relaxed at the twist where the
    # linear model puts the eigenvalue at START_EIGENVALUE, keeping the joint's symmetry.
    from jaxrod.diagram import MAX_START_BACK, START_EIGENVALUE, backed_off_start
    from jaxrod.equilibrium import solve_equilibrium

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
    from jaxrod.equilibrium import EquilibriumOptions

    return EquilibriumOptions(method="newton", with_stability=False)
