"""Structured Hessian assembly (jaxrod.model.hessian) against jax.hessian of the exact energy, and the
neighbourhood (frozen writhe, contact candidates) against the exact energy."""
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.model.hessian import dense_autodiff_hessian, hessian_pattern, project_out, scaled_hessian
from helpers import random_clamped_state, random_closed_state, random_free_state

BUILDERS = {"closed": random_closed_state, "clamped": random_clamped_state, "free": random_free_state}


@pytest.mark.parametrize("kind", sorted(BUILDERS))
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_structured_hessian_equals_autodiff_hessian(kind, seed):
    scene, q = BUILDERS[kind](n=11, seed=seed)
    nbr = scene.neighbourhood(q)
    u = scene.to_scaled(q)
    phi = 0.7 + seed
    fast = np.asarray(scaled_hessian(scene, u, phi, nbr))
    ref = np.asarray(dense_autodiff_hessian(scene, u, phi, None))  # exact energy, writhe computed
    assert np.max(np.abs(fast - ref)) < 1e-12 * np.max(np.abs(ref))


def test_colouring_needs_a_fixed_number_of_products():
    # The local part couples DOFs within three consecutive nodes: the number of colours (Hessian-
    # vector products) does not grow with N.
    # (The greedy colouring varies a little with N mod 5, where the closed rod wraps round.)
    counts = {N: hessian_pattern(jr.michell_ring(N=N)).n_colours for N in (16, 17, 18, 64, 255, 256)}
    assert max(counts.values()) <= 32


@pytest.fixture(scope="module")
def knot():
    scene = jr.trefoil(D=8.0, L=292.0, N=61)
    rng = np.random.default_rng(3)
    q = np.asarray(scene.q_init) + np.concatenate([0.3 * rng.normal(size=3 * 61), 0.2 * rng.normal(size=61)])
    return scene, jnp.asarray(q)


def test_knot_hessian_with_contact_blocks(knot):
    scene, q = knot
    nbr = scene.neighbourhood(q)
    assert nbr.n_candidates > 0
    u = scene.to_scaled(q)
    fast = np.asarray(scaled_hessian(scene, u, -2.0, nbr))
    # jax.hessian of the same energy (the neighbourhood's equals the exact one: next test).
    ref = np.asarray(dense_autodiff_hessian(scene, u, -2.0, nbr))
    assert np.max(np.abs(fast - ref)) < 1e-12 * np.max(np.abs(ref))


def test_neighbourhood_energy_equals_exact_energy(knot):
    scene, q = knot
    nbr = scene.neighbourhood(q)
    for phi in (0.0, 7.0, -30.0):
        exact = float(scene.energy(q, phi))
        assert float(scene.energy(q, phi, nbr)) == pytest.approx(exact, rel=1e-13)
    # Still exact after a small move (within the skin, writhe drift < 1/2) ...
    q2 = q + 0.05 * jnp.sin(jnp.arange(q.shape[0]))
    assert float(scene.energy(q2, 1.0, nbr)) == pytest.approx(float(scene.energy(q2, 1.0)), rel=1e-12)
    assert not bool(nbr.stale(scene.positions(q2)))
    # ... and the list says when it no longer is.
    assert bool(nbr.stale(scene.positions(q + 0.6 * float(nbr.skin))))


def test_clamped_neighbourhood_keeps_the_twist_branch():
    scene = jr.clamped_rod(N=21, length=1.0, material=jr.Material(B=1.0, C=1.0, EA=100.0))
    q = scene.q_init
    nbr = scene.neighbourhood(q)
    for phi in (0.0, 3.0, 40.0, -40.0):
        assert float(scene.energy(q, phi, nbr)) == pytest.approx(float(scene.energy(q, phi)), rel=1e-13)


def test_projection_matches_dense_projector():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(30, 30))
    h = a + a.T
    z, _ = np.linalg.qr(rng.normal(size=(30, 4)))
    p = np.eye(30) - z @ z.T
    lift = 2.0 * np.max(np.sum(np.abs(h), axis=1)) + 1.0
    ref = p @ h @ p + lift * z @ z.T
    np.testing.assert_allclose(np.asarray(project_out(jnp.asarray(h), jnp.asarray(z))), ref, atol=1e-12)
