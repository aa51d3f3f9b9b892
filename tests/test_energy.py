"""Acceptance 1 and 2: derivatives of every energy term against finite differences; invariants."""
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod import EquilibriumOptions, Material, clamped_rod, free_rod, ring, solve_equilibrium
from helpers import MAT, random_clamped_state, random_closed_state, random_free_state

BUILDERS = {
    "closed": random_closed_state,
    "clamped": random_clamped_state,
    "free": random_free_state,
}


def _term_fn(scene, name, phi):
    return jax.jit(lambda q: scene.energy_terms(q, phi)[name])


def _fd_gradient(f, q, h):
    eye = jnp.eye(q.shape[0])
    return jnp.stack([(f(q + h * e) - f(q - h * e)) / (2 * h) for e in eye])


def _fd_hessian(g, q, h):
    eye = jnp.eye(q.shape[0])
    cols = [(g(q + h * e) - g(q - h * e)) / (2 * h) for e in eye]
    return jnp.stack(cols, axis=1)


@pytest.mark.parametrize("kind", ["closed", "clamped", "free"])
@pytest.mark.parametrize("term", ["stretch", "bend", "twist"])
def test_gradient_and_hessian_match_central_differences(kind, term):
    # Central differences have error O(h^2 f''') + O(eps f / h): h = 1e-5 puts both near 1e-10
    # relative, far below the 1e-6 asked. Twist 2.5 pi makes the holonomy lift matter.
    scene, q = BUILDERS[kind]()
    phi = 2.5 * math.pi
    f = _term_fn(scene, term, phi)
    g = jax.jit(jax.grad(f))
    h_ad = jax.jit(jax.hessian(f))(q)
    g_ad = g(q)
    g_fd = _fd_gradient(f, q, 1e-5)
    h_fd = _fd_hessian(g, q, 1e-5)
    assert float(jnp.linalg.norm(g_ad)) > 0.0
    assert float(jnp.linalg.norm(g_ad - g_fd) / jnp.linalg.norm(g_ad)) < 1e-6
    assert float(jnp.linalg.norm(h_ad - h_fd) / jnp.linalg.norm(h_ad)) < 1e-6
    assert float(jnp.max(jnp.abs(h_ad - h_ad.T))) <= 1e-9 * float(jnp.max(jnp.abs(h_ad)))


def _random_rotation(seed):
    a = np.random.default_rng(seed).normal(size=(3, 3))
    qm, r = np.linalg.qr(a)
    qm = qm * np.sign(np.diag(r))
    if np.linalg.det(qm) < 0:
        qm[:, 0] *= -1
    return qm


@pytest.mark.parametrize("kind", ["closed", "free"])
def test_energy_invariant_under_rigid_motions(kind):
    scene, q = BUILDERS[kind](seed=3)
    n = scene.n_nodes
    x, rest = np.asarray(q[: 3 * n]).reshape(n, 3), np.asarray(q[3 * n:])
    for seed in range(3):
        rot = _random_rotation(seed)
        shift = np.random.default_rng(seed).normal(size=3) * 5.0
        q2 = jnp.asarray(np.concatenate([(x @ rot.T + shift).ravel(), rest]))
        for phi in (0.0, 3.0 * math.pi, -17.0):
            e1, e2 = float(scene.energy(q, phi)), float(scene.energy(q2, phi))
            assert abs(e1 - e2) <= 1e-11 * abs(e1)


def test_energy_zero_for_straight_untwisted_rod():
    s = clamped_rod(N=12, length=2.0, material=MAT)
    assert float(s.energy(jnp.asarray(s.q_init), 0.0)) == pytest.approx(0.0, abs=1e-14)
    f = free_rod(N=12, length=2.0, material=MAT)
    assert float(f.energy(jnp.asarray(f.q_init), 0.0)) == pytest.approx(0.0, abs=1e-14)


def test_twisted_straight_clamped_rod_energy_is_exact():
    # C phi^2 / (2 L) for the clamp midpoints L apart, whatever N and however many turns.
    L = 2.0
    s = clamped_rod(N=20, length=L, material=MAT)
    for phi in (2 * math.pi, -9.0 * math.pi):
        eq = solve_equilibrium(s, phi, options=EquilibriumOptions(method="newton", with_stability=False))
        assert eq.energy == pytest.approx(MAT.C * phi**2 / (2 * L), rel=1e-10)


def _uniform_ring_state(scene, radius_scale, phi):
    n = scene.n_nodes
    x = np.asarray(scene.q_init[: 3 * n]).reshape(n, 3) * radius_scale
    theta = phi * np.arange(n) / n  # every vertex carries twist phi/N, the joint included
    return jnp.asarray(np.concatenate([x.ravel(), theta]))


@pytest.mark.parametrize("phi", [0.0, 3.0 * math.pi, -40.0 * math.pi, 40.0 * math.pi])
def test_circle_with_uniform_twist_is_an_equilibrium(phi):
    mat = Material(B=1.0, C=1.0 / 1.5, EA=1e3)
    scene = ring(N=24, material=mat, radius=2.0)
    # Gradient of the scaled energy: forces in units of B/l^2, moments in units of B/l.
    grad = jax.jit(jax.grad(scene.scaled_energy))
    q = _uniform_ring_state(scene, 1.0, phi)
    assert float(jnp.max(jnp.abs(grad(scene.to_scaled(q), phi)))) < 1e-8
    # Control: the same ring with its twist not uniform, or not circular, is far from equilibrium.
    q_bad = q.at[-1].add(0.1)
    assert float(jnp.max(jnp.abs(grad(scene.to_scaled(q_bad), phi)))) > 1e-3
    q_oval = q.at[0].multiply(1.05)
    assert float(jnp.max(jnp.abs(grad(scene.to_scaled(q_oval), phi)))) > 1e-3
    # The twist stored is exactly C phi^2 / (2 L): no turn slips, even at +-40 pi.
    tw = float(scene.energy_terms(q, phi)["twist"])
    assert tw == pytest.approx(mat.C * phi**2 / (2 * float(scene.length)), rel=1e-12, abs=1e-14)
