"""Soft self-contact: smoothness (C2 at activation), derivatives, candidate lists."""
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod.model.contact import all_pairs, candidate_pairs, contact_count, contact_energy, contact_pair_hessian
from jaxrod.model.neighbourhood import build_neighbourhood
from helpers import trefoil_points


def two_strands(gap, angle=math.pi / 2, n=12, D=1.0):
    """Two straight strands (an open polyline folded far away) crossing at ``angle``, centrelines
    ``gap`` apart at the crossing. Returns x (2n, 3) as one open rod: strand A then strand B."""
    s = np.linspace(-3.0, 3.0, n)
    a = np.stack([s, np.zeros(n), np.zeros(n)], axis=1)
    b = np.stack([s * math.cos(angle), s * math.sin(angle), np.full(n, gap)], axis=1)
    return np.concatenate([a, b[::-1] + np.array([0.0, 0.0, 0.0])])


def _energy(x, pairs, D=1.0):
    mask = np.ones(len(pairs), dtype=bool)
    return contact_energy(x, pairs, mask, False, D, 1.0, 100.0)


def _pairs(x, D=1.0):
    n = x.shape[0]
    l = float(np.mean(np.linalg.norm(np.diff(x, axis=0), axis=1)))
    return all_pairs(n, False, l, D, exclude=3.0 * D)


def test_zero_when_apart_positive_when_overlapping():
    x = two_strands(1.2)
    p = _pairs(x)
    assert float(_energy(jnp.asarray(x), p)) == 0.0
    assert float(_energy(jnp.asarray(two_strands(0.8)), p)) > 0.0


def test_energy_is_C2_across_activation():
    # E(gap) near gap = D: E, dE/dgap and d2E/dgap2 all tend to 0 from below (continuous).
    def e(gap):
        x = jnp.asarray(two_strands(1.0)).at[12:, 2].set(gap)
        return _energy(x, _pairs(two_strands(1.0)))

    d1 = jax.grad(e)
    d2 = jax.grad(d1)
    e, d1, d2 = jax.jit(e), jax.jit(d1), jax.jit(d2)  # compiled once each, not operation by operation
    below = [abs(float(f(1.0 - 1e-4))) for f in (e, d1, d2)]
    at = [abs(float(f(1.0 + 1e-9))) for f in (e, d1, d2)]
    assert all(v == 0.0 for v in at)
    assert below[0] < 1e-14 and below[1] < 1e-10 and below[2] < 1e-5
    # and it grows smoothly: d2E > 0 just inside
    assert float(d2(0.9)) > 0.0


def test_gradient_and_hessian_match_central_differences():
    x = jnp.asarray(two_strands(0.7, angle=1.1) + 0.05 * np.random.default_rng(0).normal(size=(24, 3)))
    p = _pairs(np.asarray(x))
    f = jax.jit(lambda v: _energy(v.reshape(-1, 3), p))
    v = x.ravel()
    g = jax.grad(f)(v)
    h = jax.hessian(f)(v)
    eye = jnp.eye(v.shape[0])
    step = 1e-6
    g_fd = jnp.stack([(f(v + step * e_) - f(v - step * e_)) / (2 * step) for e_ in eye])
    gf = jax.jit(jax.grad(f))
    h_fd = jnp.stack([(gf(v + step * e_) - gf(v - step * e_)) / (2 * step) for e_ in eye], axis=1)
    assert float(jnp.linalg.norm(g - g_fd) / jnp.linalg.norm(g)) < 1e-6
    assert float(jnp.linalg.norm(h - h_fd) / jnp.linalg.norm(h)) < 1e-6


@pytest.mark.parametrize("n_gauss", [1, 2, 3])
def test_closed_form_pair_hessian_equals_autodiff(n_gauss):
    # Pairs at every depth: deep overlap, near activation (r ~ D), beyond reach (zero), nearly
    # parallel and crossing; the closed form must equal jax.hessian of the pair's energy.
    rng = np.random.default_rng(n_gauss)
    P, D, B, k = 400, 1.3, 0.7, 50.0
    a0 = rng.normal(size=(P, 3))
    a1 = a0 + rng.normal(size=(P, 3)) * 0.2 + np.array([0.5, 0.0, 0.0])
    b0 = a0 + rng.normal(size=(P, 3)) * rng.uniform(0.1, 1.5, (P, 1))
    b1 = b0 + rng.normal(size=(P, 3)) * 0.2 + np.array([0.0, 0.5, 0.0])
    y = jnp.asarray(np.concatenate([a0, a1, b0, b1], axis=1))

    def pair_energy(v):
        return contact_energy(v.reshape(4, 3), np.array([[0, 2]]), np.array([True]), False, D, B, k, n_gauss)

    # jitted: eagerly, each operation is compiled on its own (16 s for the three cases, 4 s jitted)
    reference = jax.jit(jax.vmap(jax.hessian(pair_energy)))(y)
    closed_form = jax.jit(lambda v: contact_pair_hessian(v, D, B, k, n_gauss))(y)
    energies = jax.jit(jax.vmap(pair_energy))(y)
    assert int(jnp.sum(energies > 0.0)) > P // 4 and int(jnp.sum(energies == 0.0)) > 10  # both kinds met
    scale = float(jnp.max(jnp.abs(reference)))
    assert float(jnp.max(jnp.abs(closed_form - reference))) <= 1e-13 * scale


def test_candidate_list_matches_all_pairs_on_a_knot():
    # Strands of this trefoil come within 1.215 of each other: with D = 1.4 some pairs overlap, and
    # every pair within D must be in the candidate list.
    n = 200
    x = trefoil_points(n)
    l = float(np.mean(np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1)))
    D = 1.4
    ref = all_pairs(n, True, l, D)
    cl = candidate_pairs(x, True, l, D)
    e_all = contact_energy(jnp.asarray(x), ref, np.ones(len(ref), bool), True, D, 1.0, 100.0)
    e_cand = contact_energy(jnp.asarray(x), cl.pairs, cl.mask, True, D, 1.0, 100.0)
    assert float(e_all) > 0.0
    assert float(e_cand) == pytest.approx(float(e_all), rel=1e-12)
    assert cl.n_candidates < 0.2 * len(ref)  # the list is much shorter than all pairs
    touching = int(contact_count(jnp.asarray(x), cl.pairs, cl.mask, True, D))
    assert 0 < touching <= cl.n_candidates
    # The list goes stale (one test, ``Neighbourhood.stale``) once a node moved more than skin/2.
    nbr = build_neighbourhood(x, 0.0, True, l, D, True)
    assert float(nbr.skin) == cl.skin
    assert not bool(nbr.stale(jnp.asarray(x + 0.2 * cl.skin)))  # every node moved 0.35 skin
    assert bool(nbr.stale(jnp.asarray(x + np.array([0.0, 0.0, 0.6 * cl.skin]))))


def test_neighbourhood_update_says_what_changed():
    """``Neighbourhood.update``, the one renewal every solver uses: at the same state nothing is
    stale and the writhe has not drifted; a node moved by more than skin/2 makes the list stale;
    the rebuilt list keeps the capacity (no recompilation) and gives the exact energy."""
    import jaxrod as jr

    knot = jr.trefoil(D=8.0, L=292.0, N=61)
    q = np.asarray(knot.q_init)
    nbr = knot.neighbourhood(q, 0.0)
    same = nbr.update(knot, q, 0.0)
    assert not same.stale and not same.drifted and not same.outdated and abs(same.drift) < 1e-12
    assert same.nbr.capacity == nbr.capacity
    moved = q.copy()
    moved[:3] += 0.6 * float(nbr.skin) * np.array([1.0, 0.0, 0.0])  # node 0 by 0.6 skin
    upd = nbr.update(knot, moved, 0.0)
    assert upd.stale and upd.outdated and upd.nbr.capacity >= nbr.capacity
    assert float(knot.energy(jnp.asarray(moved), 0.0, upd.nbr)) == pytest.approx(
        float(knot.energy(jnp.asarray(moved), 0.0)), rel=1e-12)
