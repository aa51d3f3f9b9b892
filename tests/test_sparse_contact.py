"""O(N) linear algebra with self-contact (jaxrod.linalg.sparse_contact) against the dense path, on a trefoil
small enough for both (N = 61, n = 244), at a state with contact pairs in reach and a slightly
negative eigenvalue."""
import math

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp

import jaxrod as jr
from jaxrod.linalg import sparse_contact as spc
from jaxrod.continuation import ContinuationOptions, follow_twist
from jaxrod.linalg import ldlt as ldl
from jaxrod.linalg.backend import Dense, choose_backend
from jaxrod.model.hessian import scaled_hessian
from jaxrod.continuation.sparse_branch import sparse_branch_analysis
from jaxrod.solve.solvers import HostDampedNewton, StopReason, minimise
from jaxrod.linalg.stability import branch_analysis, stability

N = 61
PHI = 3.0 * math.pi


@pytest.fixture(scope="module")
def knot():
    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    e0 = jr.relax(scene, 0.0, options=jr.RelaxOptions(with_stability=False, linear_algebra="dense"))
    e = jr.relax(scene, PHI, e0.q, jr.RelaxOptions(with_stability=False, linear_algebra="dense"))
    u = scene.to_scaled(e.q)
    hp = Dense().factorise(scene, u, PHI, e.neighbourhood).hp  # zero modes projected out, lifted on top
    lam = np.linalg.eigvalsh(hp)[: 4 * N - int(scene.n_zero_modes)]
    return scene, e0, e, u, lam, spc.sparse_hessian(scene, u, PHI, e.neighbourhood)


def test_sparse_hessian_equals_the_dense_structured_hessian(knot):
    scene, _, e, u, _, hs = knot
    dense = np.asarray(scaled_hessian(scene, jnp.asarray(u), PHI, e.neighbourhood))
    assembled = hs.S.toarray() + hs.w * np.outer(hs.a, hs.a)
    assert np.max(np.abs(assembled - dense)) <= 1e-12 * np.max(np.abs(dense))
    # contact blocks are in it: entries far off the local band
    i, j = hs.S.nonzero()
    assert np.max(np.minimum(np.abs(i - j), hs.n - np.abs(i - j))) > 50
    assert hs.S.nnz < 40 * hs.n  # sparse: ~20 entries per row plus the contact blocks
    # exactly symmetric (the inertia needs it), and the COO -> CSC reference assembly to roundoff:
    # the contact blocks summed per node pair first must lose no entry and count none twice
    assert (hs.S - hs.S.T).count_nonzero() == 0
    values, w, a, blocks, dofs, count = (np.asarray(x) for x in spc.hessian_parts(scene, jnp.asarray(u), PHI,
                                                                                   e.neighbourhood))
    assert int(count) > 50
    pat = spc.hessian_pattern(scene)
    rows, cols = pat.rows, pat.cols
    b, d = blocks[: int(count)], dofs[: int(count)]
    r, c = (np.broadcast_to(d[:, :, None], b.shape).ravel(), np.broadcast_to(d[:, None, :], b.shape).ravel())
    R, C, V = np.concatenate([rows, r]), np.concatenate([cols, c]), np.concatenate([values, b.ravel()])
    reference = sp.coo_matrix((V, (R, C)), shape=(hs.n, hs.n)).toarray()
    assert np.max(np.abs(hs.S.toarray() - 0.5 * (reference + reference.T))) <= 1e-14 * np.max(np.abs(reference))
    # on the host, only as many block rows as there are pairs in reach (rounded up): the same blocks
    host = spc.host_hessian_parts(scene, u, PHI, e.neighbourhood)
    assert int(host[5]) == int(count) and int(count) <= host[3].shape[0] < blocks.shape[0]
    assert np.array_equal(host[4][: int(count)], d)
    assert np.max(np.abs(host[3][: int(count)] - b)) <= 1e-14 * np.max(np.abs(b))
    # the node pairs' entries summed by node pair: each pair's entries sum to its blocks' (k, l) parts
    R2, C2, V2 = spc.node_pair_entries(b, d, hs.n)
    summed_dense = sp.coo_matrix((V2, (R2, C2)), shape=(hs.n, hs.n)).toarray()
    direct = sp.coo_matrix((b.ravel(), (r, c)), shape=(hs.n, hs.n)).toarray()
    assert np.max(np.abs(summed_dense - 0.5 * (direct + direct.T))) <= 1e-14 * np.max(np.abs(direct))


def test_hessian_times_vectors_equals_the_dense_product(knot):
    """H V formed on the device from the Hessian's parts (no assembly) is the dense H V to roundoff."""
    scene, _, e, u, _, _ = knot
    V = np.random.default_rng(3).standard_normal((u.size, 4))
    dense = np.asarray(scaled_hessian(scene, jnp.asarray(u), PHI, e.neighbourhood)) @ V
    hv = spc.hessian_times_vectors(scene, u, PHI, e.neighbourhood, V)
    assert hv.shape == V.shape
    assert np.max(np.abs(hv - dense)) <= 1e-12 * np.max(np.abs(dense))


def test_polyline_distance_is_exact_on_large_rods():
    """The KD-tree path of ``polyline_distance`` (large rods, O(N log N)) gives exactly the
    all-pairs value: the candidate radius d + h/2 keeps every segment that can be nearest."""
    from jaxrod.model.geometry import point_polyline_distances, polyline_distance

    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 2 * np.pi, 400, endpoint=False)
    b = np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)], axis=1)
    for closed in (True, False):
        for scale in (0.0, 1e-3, 0.05, 1.0):
            a = (np.roll(b, 3, axis=0) + scale * rng.normal(size=b.shape))[:390]
            brute = np.max(point_polyline_distances(a, np.arange(len(a)), b, None, closed))
            assert polyline_distance(a, b, closed) == brute


def test_counts_below_any_shift_match_the_dense_spectrum(knot):
    *_, lam, hs = knot
    assert lam[0] < -1e-6  # the state has one negative (sliding-type) eigenvalue: the count is not trivial
    shifts = [lam[0] - 1e-3, 0.0, -1e-6] + list(0.5 * (lam[:12] + lam[1:13]))
    for s in shifts:
        assert spc.count_below(hs, s) == int(np.sum(lam < s)), s


def test_lowest_eigenpairs_match_the_dense_ones(knot):
    scene, _, e, u, lam, hs = knot
    values, vectors, shift = spc.lowest_eigenpairs(hs, 10)
    assert shift < lam[0]
    np.testing.assert_allclose(values, lam[:10], rtol=0, atol=1e-13)
    assert np.max(np.abs(vectors.T @ hs.Z)) < 1e-12  # on Z-perp
    residual = np.column_stack([hs.matvec(vectors[:, j]) - values[j] * vectors[:, j] for j in range(10)])
    assert np.max(np.linalg.norm(residual, axis=0)) < 1e-10
    st = stability(scene, e.q, PHI, k=8, tol=1e-6, nbr=e.neighbourhood, linear_algebra="sparse")
    dense = stability(scene, e.q, PHI, k=8, tol=1e-6, nbr=e.neighbourhood, linear_algebra="dense")
    assert st.n_negative == dense.n_negative == 1
    np.testing.assert_allclose(st.eigenvalues, dense.eigenvalues, rtol=0, atol=1e-13)
    overlaps = np.abs(np.sum(st.eigenvectors * dense.eigenvectors, axis=0))
    assert np.all(overlaps[:1] > 1 - 1e-9)  # the simple lowest mode (degenerate pairs may rotate)


def test_branch_analysis_matches_the_dense_one(knot):
    scene, _, e, _, _, _ = knot
    for ref_mode in (None, 2):
        dense = branch_analysis(scene, e.q, PHI, 0, k=8, tol=1e-6, pinv_tol=1e-6, nbr=e.neighbourhood)
        ref = None if ref_mode is None else dense[0].eigenvectors[:, ref_mode]
        if ref is not None:
            dense = branch_analysis(scene, e.q, PHI, 0, k=8, tol=1e-6, pinv_tol=1e-6, nbr=e.neighbourhood, ref=ref)
        sparse = sparse_branch_analysis(scene, e.q, PHI, 0, k=8, tol=1e-6, pinv_tol=1e-6, nbr=e.neighbourhood, ref=ref)
        assert sparse[0].n_negative == dense[0].n_negative
        assert sparse[1] == pytest.approx(dense[1], abs=1e-13)
        assert sparse[2] == pytest.approx(dense[2], rel=1e-8, abs=1e-14)
        assert abs(np.dot(sparse[3], dense[3])) == pytest.approx(1.0, abs=1e-9)
        assert np.linalg.norm(sparse[4] - dense[4]) <= 1e-9 * np.linalg.norm(dense[4])


def _gyration(x):
    """The principal moments of a curve's nodes (invariant under rigid motions; under a slide of
    the nodes along the curve to within the discretisation)."""
    xc = x - x.mean(0)
    return np.linalg.eigvalsh(xc.T @ xc / x.shape[0])


def test_sparse_relax_reaches_the_dense_minimum(knot):
    scene, e0, _, _, _, _ = knot
    es = jr.relax(scene, 0.0, options=jr.RelaxOptions(linear_algebra="sparse"))
    assert es.solution.converged and es.solution.solver.startswith("damped_newton_sparse")
    assert es.energy == pytest.approx(e0.energy, rel=1e-10)
    # the same shape up to a rigid motion and a slide of the material along it (the two minimisers
    # take different paths; the 3-fold knot's nodes need not land on the same material points):
    # compared by invariants of both
    assert es.Wr == pytest.approx(e0.Wr, abs=1e-8)
    np.testing.assert_allclose(_gyration(es.x), _gyration(e0.x), rtol=1e-6)
    assert es.stability.n_negative == 0


def test_follow_twist_sparse_equals_dense(knot):
    scene, e0, _, _, _, _ = knot
    paths = {}
    for la in ("dense", "sparse"):
        opts = ContinuationOptions(step=math.pi, switch=False, linear_algebra=la)
        paths[la] = follow_twist(scene, 0.0, 2.0 * math.pi, opts, start=e0)
    d, s = paths["dense"].points, paths["sparse"].points
    assert [p.equilibrium.phi for p in d] == [p.equilibrium.phi for p in s]
    for pd, ps in zip(d, s):
        assert ps.equilibrium.energy == pytest.approx(pd.equilibrium.energy, rel=1e-9)
        assert ps.equilibrium.Lk == pytest.approx(pd.equilibrium.Lk, abs=1e-9)
        assert ps.equilibrium.stability.n_negative == pd.equilibrium.stability.n_negative == 0
        np.testing.assert_allclose(ps.equilibrium.stability.eigenvalues, pd.equilibrium.stability.eigenvalues,
                                   rtol=0, atol=1e-9)


def test_the_choice_is_automatic_and_stated():
    assert not choose_backend(jr.trefoil(D=8.0, L=292.0, N=121), "auto").backend.structured
    big = jr.trefoil(D=8.0, L=292.0, N=251)  # n_dof = 1004
    assert choose_backend(big, "auto").backend.name == "sparse" and not choose_backend(big, "dense").backend.structured
    with pytest.raises(ValueError, match="linear_algebra"):
        jr.RelaxOptions(linear_algebra="cholmod")


def test_a_pivoting_factorisation_is_refused_not_counted():
    # [[0, 1], [1, 0]] has no LDL^T without pivoting: refused, never given a (wrong) inertia.
    A = sp.csc_matrix(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(spc.FactorisationError):
        spc.negative_count(A, np.zeros((3, 0)), np.zeros((0, 0)))


def test_ldlt_gives_the_inertia_and_falls_back_to_superlu(monkeypatch):
    # A random sparse symmetric indefinite matrix: QDLDL's pivots count the negative eigenvalues,
    # its solves solve, for one and for several right-hand sides.
    rng = np.random.default_rng(3)
    m = 300
    R = sp.random(m, m, density=0.02, random_state=rng, format="csc")
    A = (R + R.T + sp.diags(rng.uniform(-3.0, 3.0, m))).tocsc()
    negatives = int(np.sum(np.linalg.eigvalsh(A.toarray()) < 0.0))
    assert 0 < negatives < m
    fac, pivots = ldl.ldlt(A)
    assert isinstance(fac, ldl.QDLDLFactor) and int(np.sum(pivots < 0.0)) == negatives
    B = rng.standard_normal((m, 3))
    assert np.allclose(A @ fac.solve(B), B, atol=1e-8) and np.allclose(A @ fac.solve(B[:, 0]), B[:, 0], atol=1e-8)
    # Without QDLDL (or where it refuses) SuperLU in symmetric mode gives the same count.
    monkeypatch.setattr(ldl, "_qdldl", None)
    fac, pivots = ldl.ldlt(A)
    assert not isinstance(fac, ldl.QDLDLFactor) and int(np.sum(pivots < 0.0)) == negatives


def _double_well(y, args):
    return (y[0] ** 2 - 1.0) ** 2 + 0.5 * args * y[1] ** 2


def _dense_direction(y, args, g, mu_prev):
    h = np.array([[12.0 * y[0] ** 2 - 4.0, 0.0], [0.0, float(args)]])
    mu = 0.0
    while np.min(np.linalg.eigvalsh(h + mu * np.eye(2))) <= 0.0:
        mu = 1e-6 if mu == 0.0 else 4.0 * mu
    return -np.linalg.solve(h + mu * np.eye(2), g), mu


def test_host_damped_newton_descends_from_a_saddle_and_reports_honestly():
    solver = HostDampedNewton(direction=_dense_direction, max_step=0.5)
    sol = minimise(_double_well, np.array([0.05, 1.0]), 3.0, solver, gtol=1e-12)
    assert sol.converged and sol.reason is StopReason.CONVERGED and sol.solver == "damped_newton_sparse"
    np.testing.assert_allclose(sol.y, [1.0, 0.0], atol=1e-12)
    short = minimise(_double_well, np.array([0.05, 1.0]), 3.0, solver, gtol=1e-12, max_steps=2, throw=False)
    assert not short.converged and short.reason is StopReason.MAX_STEPS and short.iterations == 2
    bad = HostDampedNewton(direction=lambda y, args, g, mu: (np.full(2, np.nan), 0.0))
    stalled = minimise(_double_well, np.array([0.05, 1.0]), 3.0, bad, throw=False)
    assert not stalled.converged and stalled.reason is StopReason.NONFINITE


def test_sparse_bifurcation_backend_equals_the_dense_one(knot):
    # jaxrod.continuation.arclength's host backend (issue 18: the extended-system locators at O(N)) on the
    # knot's pinned problem: solves with vector and matrix borders, the spectrum with its Morse
    # index, and the branch-point test function sigma, against DenseBackend
    from jaxrod.linalg.bordered import DenseBackend, SparseBackend
    from jaxrod.continuation.arclength.rods import assemble_pinned_hessian, knot_problem

    scene, _, e, _, _, _ = knot
    rods = {name: knot_problem(scene, np.asarray(e.q), PHI, backend=be)
            for name, be in (("dense", DenseBackend()), ("sparse", SparseBackend(assemble_pinned_hessian)))}
    lin = {name: r.problem.linearise(r.problem.u0, PHI, r.problem.args) for name, r in rods.items()}
    Fd, Jd, Fpd = (np.asarray(a) for a in lin["dense"])
    Fs, Js, Fps = lin["sparse"]
    np.testing.assert_allclose(np.asarray(Js), Jd, rtol=0, atol=1e-12 * np.max(np.abs(Jd)))
    m = Jd.shape[0]
    rng = np.random.default_rng(0)
    b, c, f = rng.standard_normal((3, m))
    for args in ((b, c, 0.3, f, 1.0), (np.stack([b, c], 1), np.stack([c, b], 1), np.eye(2), f, np.ones(2))):
        xd, yd = DenseBackend().bordered_solve(Jd, *args)
        xs, ys = rods["sparse"].problem.backend.bordered_solve(Js, *args)
        np.testing.assert_allclose(xs, np.asarray(xd), rtol=1e-9, atol=1e-9 * np.max(np.abs(xd)))
        np.testing.assert_allclose(ys, np.asarray(yd), rtol=1e-9, atol=1e-12)
    vd, Vd, md = DenseBackend().spectrum(Jd, 6, 0, 1e-13)
    vs, Vs, ms = rods["sparse"].problem.backend.spectrum(Js, 6, 0, 1e-13)
    lam = np.linalg.eigvalsh(Jd)
    assert ms == md == int(np.sum(lam < -1e-13 * np.max(np.abs(lam))))
    np.testing.assert_allclose(vs, vd, rtol=0, atol=1e-12)
    assert abs(Vs[:, 0] @ Vd[:, 0]) == pytest.approx(1.0, abs=1e-9)
    # the branch-point test functions on the host: sigma from the bordered solve, as the dense
    # backend's (their Jacobian is the jitted adjoint that both backends share)
    bvec = Vd[:, 0]
    (gus, gps), (sts, *_) = rods["sparse"].problem.singular_tests(rods["sparse"].problem.u0, PHI,
                                                                  rods["sparse"].problem.args, bvec)
    _, sigma = DenseBackend().bordered_solve(Jd, bvec, bvec, 0.0, np.zeros(m), 1.0)
    assert sts[0] == pytest.approx(float(sigma), rel=1e-8)
    assert np.all(np.isfinite(gus)) and np.all(np.isfinite(gps))
