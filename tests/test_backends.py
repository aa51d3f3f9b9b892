"""One problem through every linear-algebra backend (jaxrod.linalg.backend): a trefoil with its
contact active (N = 61, n = 244) through dense and sparse (banded cannot hold contact and says so),
and a twisted ring without contact through all three. Inertia equal, lowest eigenvalues equal to
1e-10 relative, and the same solves."""
import math

import numpy as np
import pytest

import jaxrod as jr
from jaxrod.linalg.backend import Banded, Dense, LinalgOptions, Sparse, choose_backend

K = 6


def _factorisations(scene, q, phi, nbr, backends):
    u = scene.to_scaled(np.asarray(q, dtype=float))
    return {b.name: b.factorise(scene, u, phi, nbr) for b in backends}


def _agree(facs, shift):
    """Every backend's inertia at shift and its K lowest eigenvalues equal the dense ones."""
    dense = facs["dense"]
    inertia = dense.inertia(shift)
    low = dense.lowest_eigenpairs(K)
    for name, fac in facs.items():
        assert fac.inertia(shift) == inertia, name
        pairs = fac.lowest_eigenpairs(K)
        scale = np.max(np.abs(low.values))
        assert np.max(np.abs(pairs.values - low.values)) <= 1e-10 * scale, (name, pairs.values, low.values)
        assert np.allclose(pairs.vectors.T @ pairs.vectors, np.eye(K), atol=1e-10)
        assert np.max(np.abs(np.asarray(dense.z).T @ pairs.vectors)) < 1e-8  # zero modes deflated
    return inertia, low


@pytest.fixture(scope="module")
def knot():
    scene = jr.trefoil(D=8.0, L=292.0, N=61)
    phi = 3.0 * math.pi
    opts = jr.RelaxOptions(with_stability=False, linear_algebra="dense")
    e = jr.relax(scene, phi, jr.relax(scene, 0.0, options=opts).q, opts)
    return scene, e, phi


def test_a_knot_with_contact_through_every_backend(knot):
    scene, e, phi = knot
    u = scene.to_scaled(e.q)
    from jaxrod.linalg.sparse_contact import hessian_parts

    assert int(hessian_parts(scene, u, phi, e.neighbourhood)[-1]) > 50  # contact pairs in reach
    assert not Banded().supports(scene)
    with pytest.raises(ValueError, match="contact"):
        choose_backend(scene, "banded")
    facs = _factorisations(scene, e.q, phi, e.neighbourhood, [Dense(), Sparse()])
    inertia, low = _agree(facs, -1e-10)
    assert inertia.zero == int(scene.n_zero_modes) and sum(inertia) == scene.n_dof
    # a shift between two eigenvalues: both backends count the same
    mid = 0.5 * (low.values[2] + low.values[3])
    assert facs["sparse"].inertia(mid) == facs["dense"].inertia(mid)
    _same_solves(facs, np.random.default_rng(3).normal(size=scene.n_dof))


def _same_solves(facs, rhs):
    dense = facs["dense"]
    x = dense.solve(rhs)
    c = np.cos(np.arange(rhs.size))
    xb, yb = dense.bordered_solve(rhs, c, 1.0, c, 0.5)
    for name, fac in facs.items():
        assert np.max(np.abs(fac.solve(rhs) - x)) <= 1e-7 * np.max(np.abs(x)), name
        xs, ys = fac.bordered_solve(rhs, c, 1.0, c, 0.5)
        assert np.max(np.abs(xs - xb)) <= 1e-7 * np.max(np.abs(xb)) and abs(ys - yb) <= 1e-7 * abs(yb), name


def test_a_ring_without_contact_through_every_backend():
    scene = jr.michell_ring(N=48, slenderness=0.05)  # a stiff ring (D/R = 0.01) has ||H|| ~ 1e4: round-off 1e-12
    phi = 1.2 * jr.michell_critical_twist(0.5)  # past Michell's threshold: the round ring is a saddle
    e = jr.solve_equilibrium(scene, phi, options=jr.EquilibriumOptions(method="newton", with_stability=False))
    # the banded eigensolver's residuals driven near round-off (its default stops at 1e-12 ||H||)
    banded = Banded(LinalgOptions(eig_tol=1e-14))
    facs = _factorisations(scene, e.q, phi, e.neighbourhood, [Dense(), banded, Sparse()])
    inertia, _ = _agree(facs, -1e-10)
    assert inertia.negative == 2 and inertia.zero == 7  # the degenerate pair of Michell's mode
    _same_solves(facs, np.sin(np.arange(scene.n_dof)))


def test_choose_backend_says_which_and_why():
    small, big = jr.trefoil(D=8.0, L=292.0, N=121), jr.trefoil(D=8.0, L=292.0, N=251)
    ring = jr.michell_ring(N=256)
    assert choose_backend(small).backend.name == "dense"
    backend, reason = choose_backend(big)
    assert backend.name == "sparse" and backend.structured and "contact" in reason
    assert choose_backend(ring).backend.name == "banded"
    assert choose_backend(ring, "sparse").backend.name == "banded"  # the O(n) path without contact
    assert choose_backend(big, "dense").backend.name == "dense"
    fallback = choose_backend(ring, offered=("dense", "sparse"))
    assert fallback.backend.name == "dense" and "not offered" in fallback.reason
    assert choose_backend(big, LinalgOptions(sparse_min_dof=10 ** 6)).backend.name == "dense"
    with pytest.raises(ValueError, match="backend"):
        LinalgOptions(backend="lapack")


def test_the_dense_inertia_counts_the_eigenvalues_below_each_shift(knot):
    """The dense backend counts the inertia from its Bunch-Kaufman factors (Sylvester's law, 2 x 2
    pivots included where a shift inside the spectrum makes the matrix indefinite): the count below
    each shift between the 8 lowest eigenvalues is that shift's rank among them."""
    scene, e, phi = knot
    fac = _factorisations(scene, e.q, phi, e.neighbourhood, [Dense()])["dense"]
    values = fac.lowest_eigenpairs(8).values
    for j in range(1, 8):
        shift = 0.5 * (values[j - 1] + values[j])
        inertia = fac.inertia(shift)
        assert inertia.negative == j, (j, shift, inertia)
        assert sum(inertia) == scene.n_dof and inertia.zero == int(scene.n_zero_modes)
    x = fac.solve(np.ones(scene.n_dof))  # the solve, from the shift-0 factors, on Z-perp
    assert np.max(np.abs(np.asarray(fac.z).T @ x)) < 1e-8 * np.max(np.abs(x))
