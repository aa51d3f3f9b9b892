"""Knots with self-contact: relaxation without strand passage (issue 3 groundwork)."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod import DampedNewton, minimise


@pytest.fixture(scope="module")
def relaxed():
    scene = jr.trefoil(D=8.0, L=292.0, N=61)
    eq = jr.relax(scene, 0.0)
    return eq, scene


def _min_nonlocal_distance(x, gap):
    n = len(x)
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    i = np.arange(n)
    sep = np.minimum(np.abs(i[:, None] - i[None]), n - np.abs(i[:, None] - i[None]))
    return d[sep > gap].min()


def test_too_tight_trefoil_is_refused():
    with pytest.raises(ValueError, match="ropelength"):
        jr.trefoil(D=8.0, L=120.0, N=61)
    with pytest.raises(ValueError, match="coprime"):
        jr.torus_knot(2, 4, D=1.0, L=100.0, N=60)


def test_relaxed_trefoil_is_a_stable_knot_in_contact(relaxed):
    eq, scene = relaxed
    assert eq.solution.converged and eq.solution.grad_norm <= 1e-9
    assert eq.stable
    assert scene.Lk0 == 3  # right-handed
    assert eq.Lk == pytest.approx(3.0, abs=1e-8)
    assert 2.9 < eq.Wr < 3.3  # a loose right-handed trefoil: writhe close to 3
    assert eq.energy_terms["contact"] > 0.0  # strands touch
    # Penetration stays small at the default stiffness (kappa_c = 100 B/D^2): > 0.95 D apart.
    assert _min_nonlocal_distance(eq.x, gap=6) > 0.95 * 8.0


def test_forced_strand_passage_is_refused(relaxed):
    eq, scene = relaxed
    x = eq.x.copy()
    n = len(x)
    # The closest non-local pair of nodes (a crossing): push a window of strand i through strand j.
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    i_idx = np.arange(n)
    sep = np.minimum(np.abs(i_idx[:, None] - i_idx[None]), n - np.abs(i_idx[:, None] - i_idx[None]))
    d[sep <= 6] = np.inf
    i, j = np.unravel_index(np.argmin(d), d.shape)
    push = 2.0 * (x[j] - x[i])
    window = [(i + k) % n for k in range(-3, 4)]
    weights = np.array([0.25, 0.6, 0.9, 1.0, 0.9, 0.6, 0.25])
    x_forced = x.copy()
    x_forced[window] += weights[:, None] * push
    q_forced = eq.q.copy()
    q_forced[: 3 * n] = x_forced.ravel()
    with pytest.raises(jr.TopologyChangeError):
        jr.relax(scene, 0.0, q_forced, previous=eq)
    # Control: a small step of the same shape is accepted and relaxes back to the same knot.
    q_small = eq.q.copy()
    x_small = x.copy()
    x_small[window] += weights[:, None] * 0.05 * push
    q_small[: 3 * n] = x_small.ravel()
    eq2 = jr.relax(scene, 0.0, q_small, previous=eq)
    assert eq2.Wr == pytest.approx(eq.Wr, abs=1e-3)


def test_damped_newton_minimises_from_far_where_newton_stalls():
    def rosenbrock(y, a):
        return jnp.sum(a * (y[1:] - y[:-1] ** 2) ** 2 + (1 - y[:-1]) ** 2)

    sol = minimise(rosenbrock, jnp.zeros(6), 100.0, DampedNewton(max_step=0.5), gtol=1e-10)
    assert sol.converged
    np.testing.assert_allclose(sol.y, np.ones(6), atol=1e-8)


def test_fast_stability_equals_dense_spectrum_on_knots_with_contact(relaxed):
    # Issue 7, acceptance 4 for knots: the per-step analysis takes the lowest 24 eigenpairs of the
    # projected Hessian (LAPACK dsyevr) and counts negative eigenvalues from them, falling back to
    # the whole spectrum only when all 24 are below the threshold. Against the full eigh, on 126
    # states of the N = 61 trefoil in contact: the relaxed knot and random perturbations of it
    # (0 to 60 negative eigenvalues), at twists it is not relaxed for (-12 pi ... 14 pi).
    from jaxrod.linalg.stability import spectrum, stability

    eq, scene = relaxed
    rng = np.random.default_rng(7)
    n_x = 3 * scene.n_nodes
    counts = set()
    checked = 0
    for phi in np.linspace(-12.0, 14.0, 7) * np.pi:
        for amp in (0.0, 0.02, 0.1, 0.3, 0.6, 1.0):
            for _ in range(3):
                noise = np.concatenate([amp * rng.normal(size=n_x), 0.5 * amp * rng.normal(size=scene.n_dof - n_x)])
                q = np.asarray(eq.q) + noise
                nbr = scene.neighbourhood(q, phi)
                u = scene.to_scaled(q)
                lam, _, n0 = (np.asarray(a) for a in spectrum(scene, u, phi, nbr))
                physical = lam[: lam.size - int(n0)]
                scale = np.max(np.abs(physical))
                # Thresholds: the study's (-1e-6), and near-critical ones sitting 1e-9 |H| above
                # and below an eigenvalue (the count must flip exactly there).
                j = int(rng.integers(0, 30))
                for tol in (1e-6, -(physical[j] - 1e-9 * scale), -(physical[j] + 1e-9 * scale)):
                    stab = stability(scene, q, phi, k=24, tol=tol, nbr=nbr, linear_algebra="dense")
                    low, nz, neg = stab.eigenvalues, stab.n_zero_modes, stab.n_negative
                    assert int(nz) == int(n0)
                    assert int(neg) == int(np.sum(physical < -tol)), (phi, amp, tol)
                    counts.add(int(neg))
                low = np.asarray(low)
                assert np.max(np.abs(low - lam[: low.size])) <= 1e-8 * scale
                checked += 1
    assert checked == 126
    assert min(counts) == 0 and max(counts) > 24  # stable states, and the whole-spectrum fallback


def _mixed_state(eq, scene, mu_slide, mu_shape, angle, third=None):
    """The relaxed trefoil's state with a fabricated low spectrum: its slide s and its lowest shape
    mode v (both real eigenvectors there) mixed by ``angle`` into two eigenpairs (mu_slide, w1),
    (mu_shape, w2), as nearly degenerate modes come out of an eigensolver next to a crossing; with
    ``third`` = (value, weight) the slide is instead mixed into a mode at that value as well."""
    from types import SimpleNamespace

    from jaxrod.linalg.stability import sliding_fraction

    vec = np.asarray(eq.stability.eigenvectors)
    frac = sliding_fraction(scene, eq.q, vec)
    s, v = vec[:, int(np.argmin(frac))], vec[:, int(np.argmax(frac))]
    c, si = np.cos(angle), np.sin(angle)
    w1, w2 = c * s + si * v, -si * s + c * v
    values, vectors = [mu_slide, mu_shape], [w1, w2]
    if third is not None:
        others = [j for j in range(vec.shape[1]) if j not in (int(np.argmin(frac)), int(np.argmax(frac)))]
        u = vec[:, others[0]]
        a = third[1]
        values, vectors = [mu_shape, third[0]], [np.sqrt(1 - a * a) * v + a * s, -a * v + np.sqrt(1 - a * a) * s]
        values, vectors = values + [third[0] * 2], vectors + [u]
    stab = SimpleNamespace(eigenvalues=np.array(values), eigenvectors=np.stack(vectors, axis=1))
    return SimpleNamespace(q=eq.q, stability=stab), float(frac.min()), float(frac.max())


def test_a_buckling_mode_mixed_with_the_slide_is_judged_by_its_own_eigenvalue(relaxed):
    # Next to the trefoil's tightening branch point (N = 121, --step 0.25pi) the lowest eigenvector
    # was half slide, half buckling mode, at -1.9e-7: judged as one mode it looked like a buckling
    # mode negative inside the sliding band, and the study ended 0.074 pi early. With the slide split
    # off the span, the buckling direction's own Ritz value (here +8.75e-8) decides.
    from jaxrod.linalg.stability import band_shape_modes, shape_modes_in_band

    eq, scene = relaxed
    e, slide_frac, shape_frac = _mixed_state(eq, scene, -2.5e-7, 2.0e-7, np.pi / 6)
    assert slide_frac < 1e-3 and shape_frac > 0.37
    assert shape_modes_in_band(scene, e, 1e-6) == []
    e, _, _ = _mixed_state(eq, scene, -2.5e-7, -1.0e-7, np.pi / 6)  # the buckling mode itself negative
    values, fractions, vectors = band_shape_modes(scene, e, 1e-6)
    assert values.size == 1 and values[0] == pytest.approx(0.25 * -2.5e-7 + 0.75 * -1.0e-7, rel=1e-9)
    assert fractions[0] > 0.37
    # A slide mixed into a mode far above the band (2.3e-6) is no near-null slide: not split off,
    # and the buckling mode crossing zero (-6.8e-8, mixed with it by 0.3) still counts (the trefoil's
    # buckled+ branch point at +7.041 pi).
    e, _, _ = _mixed_state(eq, scene, None, -6.8e-8, 0.0, third=(2.3e-6, 0.3))
    assert [round(v, 12) for v, _ in shape_modes_in_band(scene, e, 1e-6)] == [-6.8e-8]
