"""jaxrod.linalg.sparse: the O(N) block path against the dense one (jaxrod.linalg.stability).

Compilation dominates the run time (each scene shape compiles the dense Newton loop, the dense
spectrum, the block Hessian, ...), so every test works on the same two small scenes: a Michell ring
of N = 24 nodes and a clamped rod of N = 24 nodes (different materials share compiled code).
"""
import os
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.linalg import sparse as ss
from jaxrod.linalg.stability import DEFAULT_NEGATIVE_TOL, spectrum, stability

N = 24
RING_NUS = (0.0, 0.25, 0.5)
CLAMPED_NUS = (0.0, 0.5)
N_GRID = 38  # twists per scene in (0, 2 phi*]
NEAR = (-5e-4, -1e-4, 1e-4, 5e-4)  # offsets from the (discrete) critical twist


def ring_scene(nu):
    return jr.michell_ring(N=N, nu=nu)


def clamped_scene(nu):
    return jr.clamped_rod(N=N, length=1.0, material=jr.Material(B=1.0, C=1.0 / (1.0 + nu), EA=1e4))


def dense_blocks(lay, diag, off, a, w):
    """The (n, n) matrix T + w a a^T in q order, from the blocks (numpy)."""
    diag, off, a = np.asarray(diag), np.asarray(off), np.asarray(a)
    K, b, _ = diag.shape
    T = np.zeros((K * b, K * b))
    for k in range(K):
        T[k * b:(k + 1) * b, k * b:(k + 1) * b] += diag[k]
    for k in range(K if lay.cyclic else K - 1):
        j = (k + 1) % K
        T[k * b:(k + 1) * b, j * b:(j + 1) * b] += off[k]
        T[j * b:(j + 1) * b, k * b:(k + 1) * b] += off[k].T
    T += float(w) * np.outer(a, a)
    return T[np.ix_(lay.position, lay.position)]


# ------------------------------------------------------------------------------------------------
# equilibria


class State:
    def __init__(self, scene, phi, q, nbr, dense):
        self.scene, self.phi, self.q, self.nbr, self.dense = scene, phi, q, nbr, dense

    @property
    def u(self):
        return self.scene.to_scaled(jnp.asarray(self.q))


def ring_state(scene, phi):
    eq = jr.solve_equilibrium(scene, phi, options=jr.EquilibriumOptions(method="newton"))
    assert eq.solution.converged
    return State(scene, phi, eq.q, eq.neighbourhood, eq.stability)


def clamped_state(scene, phi):
    """The twisted straight clamped rod, solved by the pinned Newton of the block path (nothing
    is pinned on a clamped rod) -- so that the dense Newton loop is compiled for one shape only;
    the dense count below is still ``jaxrod.linalg.stability.stability``."""
    q = jnp.asarray(scene.q_init)
    nbr = scene.neighbourhood(q, phi)
    u = scene.to_scaled(q)
    for _ in range(10):
        g, _ = ss.gradient_and_phi_derivative(scene, u, phi, nbr)
        if float(jnp.max(jnp.abs(g))) < 1e-11:
            break
        u = u + ss.newton_direction(scene, u, phi, nbr, g)
    assert float(jnp.max(jnp.abs(g))) < 1e-11
    q = np.asarray(scene.from_scaled(u))
    return State(scene, phi, q, nbr, stability(scene, q, phi, nbr=nbr))


def discrete_critical(make_state, scene, guess):
    """Twist where the lowest dense eigenvalue crosses zero (secant on lambda_1(phi))."""
    a, b = 0.9 * guess, 1.1 * guess
    fa, fb = (float(make_state(scene, p).dense.eigenvalues[0]) for p in (a, b))
    assert fa > 0 > fb
    for _ in range(30):
        c = b - fb * (b - a) / (fb - fa)
        a, fa, b, fb = b, fb, c, float(make_state(scene, c).dense.eigenvalues[0])
        if abs(b - a) < 1e-12 * guess:
            break
    return b


@pytest.fixture(scope="module")
def states():
    """Equilibria (with their dense stability) over twists 0 .. 2 phi*, near-critical included.
    Returns {(kind, nu): (phi_crit, [State, ...])}."""
    out = {}
    for kind, nus, make_scene, make_state, guess in (
        ("ring", RING_NUS, ring_scene, ring_state, lambda nu: jr.michell_critical_twist(nu)),
        ("clamped", CLAMPED_NUS, clamped_scene, clamped_state,
         lambda nu: jr.clamped_critical_twist(1.0, 1.0 / (1.0 + nu))),
    ):
        for nu in nus:
            scene = make_scene(nu)
            pc = discrete_critical(make_state, scene, guess(nu))
            phis = list(np.linspace(2.0 / N_GRID, 2.0, N_GRID) * pc) + [pc + d for d in NEAR]
            out[kind, nu] = pc, [make_state(scene, float(p)) for p in phis]
    return out


# ------------------------------------------------------------------------------------------------
# layout and block Hessian


def test_layouts_hold_the_hessian_pattern():
    # block_layout checks the pattern itself when built (and raises otherwise); odd closed rods
    # need 3-node blocks.
    for scene, b, K in ((ring_scene(0.5), 8, N // 2), (clamped_scene(0.5), 8, 11),
                        (jr.michell_ring(N=9), 12, 3), (jr.michell_ring(N=11), 12, 4), (jr.michell_ring(N=4), 8, 2)):
        lay = ss.block_layout(scene)
        assert (lay.block_size, lay.num_blocks) == (b, K)
        assert np.array_equal(lay.perm[lay.position], np.arange(scene.n_dof))
        assert lay.n_pad - scene.n_dof == int(np.sum(lay.dummy))


def test_block_hessian_equals_dense_hessian_on_a_wobbly_twisted_ring():
    # Against the dense path without compiling anything new (``scaled_hessian`` alone would cost
    # another ~5 s of compilation): M - H is symmetric, so it vanishes if it vanishes (i) on
    # Z-perp x Z-perp and (ii) on the generators Z. (i): P H P is what ``spectrum`` diagonalises,
    # V diag(lambda) V^T over its physical eigenpairs (eigh round-off ~1e-15). (ii): exact
    # symmetry identities of the energy, valid at any state: H z = 0 for the translations and the
    # twist shift, H (Omega u) = Omega g for the rotations (differentiate g(R u) = R g(u)).
    scene = ring_scene(0.3)
    rng = np.random.default_rng(0)
    s = 2 * np.pi * np.arange(N) / N
    x = np.asarray(scene.q_init[:3 * N]).reshape(N, 3)
    x = x + 0.1 * np.stack([np.cos(2 * s), np.sin(3 * s), np.cos(3 * s) + np.sin(2 * s)], 1)
    x = x + 0.01 * rng.normal(size=x.shape)
    q = jnp.asarray(np.concatenate([x.ravel(), 0.4 * rng.normal(size=N)]))
    phi = 5.0
    nbr = scene.neighbourhood(q, phi)
    u = scene.to_scaled(q)
    diag, off, a, w = ss.block_hessian(scene, u, phi, nbr)
    M = dense_blocks(ss.block_layout(scene), diag, off, a, w)
    scale = np.max(np.abs(M))
    lam, vec, n_zero = spectrum(scene, u, phi, nbr)
    m = lam.shape[0] - int(n_zero)
    PHP = (np.asarray(vec[:, :m]) * np.asarray(lam[:m])) @ np.asarray(vec[:, :m]).T
    Z = np.asarray(scene.scaled_zero_modes(u, phi))
    Q, _ = np.linalg.qr(Z)
    P = np.eye(4 * N) - Q @ Q.T
    assert np.max(np.abs(P @ M @ P - PHP)) < 1e-12 * scale
    g, _ = ss.gradient_and_phi_derivative(scene, u, phi, nbr)
    gx = np.asarray(g)[:3 * N].reshape(N, 3)
    HZ = np.zeros_like(Z)
    for k in range(3):
        HZ[:3 * N, 3 + k] = np.cross(np.eye(3)[k], gx).ravel()
    assert np.max(np.abs(HZ)) > 1e-3 * scale  # far from equilibrium: the identity is not trivial
    assert np.max(np.abs(M @ Z - HZ)) < 1e-12 * scale * np.max(np.abs(Z))
    assert np.max(np.abs(np.asarray(diag) - np.swapaxes(np.asarray(diag), 1, 2))) == 0.0


def test_block_hessian_equals_dense_hessian_on_a_clamped_rod():
    # The dense reference is the structured Hessian that jaxrod.linalg.stability diagonalises: without
    # zero modes, V diag(lambda) V^T of ``spectrum`` is that matrix (eigh round-off ~1e-15), and
    # ``spectrum`` is compiled for this shape anyway (a separate ``scaled_hessian`` would cost
    # another compilation).
    scene = clamped_scene(0.25)
    rng = np.random.default_rng(1)
    q = jnp.asarray(np.asarray(scene.q_init) + np.concatenate(
        [0.03 * rng.normal(size=3 * (N - 4)), 0.3 * rng.normal(size=N - 3)]))
    nbr = scene.neighbourhood(q, 2.0)
    u = scene.to_scaled(q)
    lam, vec, n_zero = spectrum(scene, u, 2.0, nbr)
    assert int(n_zero) == 0
    ref = np.asarray((vec * lam[None, :]) @ vec.T)
    diag, off, a, w = ss.block_hessian(scene, u, 2.0, nbr)
    fast = dense_blocks(ss.block_layout(scene), diag, off, a, w)
    assert np.max(np.abs(fast - ref)) < 1e-12 * np.max(np.abs(ref))


# ------------------------------------------------------------------------------------------------
# inertia: the acceptance test


def test_inertia_matches_dense_negative_count(states):
    compared, seen = 0, set()
    for (kind, nu), (pc, sts) in states.items():
        for st in sts:
            fast = int(ss.inertia_at_equilibrium(st.scene, st.u, st.phi, st.nbr, DEFAULT_NEGATIVE_TOL))
            assert fast == st.dense.n_negative, (kind, nu, st.phi / pc, fast, st.dense.n_negative,
                                                 st.dense.eigenvalues[:4])
            # The bordered count factors T - s I with s = -1e-10: its pivots along T's exact null
            # vectors are ~|s| with round-off ~1e-16 ||M|| (see its docstring), so it is only
            # compared where no eigenvalue lies within 1e-9 of the threshold (at the critical
            # twist itself the lowest pair is +8e-12 and the bordered count is round-off).
            if np.min(np.abs(np.asarray(st.dense.eigenvalues) + DEFAULT_NEGATIVE_TOL)) > 1e-9:
                bordered = int(ss.projected_count_below(st.scene, st.u, st.phi, st.nbr, -DEFAULT_NEGATIVE_TOL))
                assert bordered == fast, (kind, nu, st.phi / pc, bordered, fast)
            compared += 1
            seen.add(fast)
        near = [st.dense.n_negative for st in sts[-len(NEAR):]]
        assert near == [0, 0, 2, 2], (kind, nu, near)  # both sides of the threshold, within 5e-4
    print(f"\nnegative counts equal on {compared} equilibria; counts seen: {sorted(seen)}")
    assert compared >= 200
    assert {0, 2, 4} <= seen


def test_ring_threshold_is_michells(states):
    # Sanity of the states themselves: the discrete threshold is close to Michell's.
    for nu in RING_NUS:
        pc, _ = states["ring", nu]
        assert pc == pytest.approx(jr.michell_critical_twist(nu), rel=0.1)


# ------------------------------------------------------------------------------------------------
# eigenpairs


def test_lowest_eigenpairs_match_dense_spectrum(states):
    pc, sts = states["ring", 0.5]
    for frac in (0.5, 1.3, 1.9):  # stable; one unstable pair; two unstable pairs
        st = min(sts, key=lambda s: abs(s.phi / pc - frac))
        ep = ss.lowest_eigenpairs_projected(st.scene, st.u, st.phi, st.nbr, 4)
        lam_d = st.dense.eigenvalues[:4]
        assert np.all(np.abs(np.asarray(ep.values) - lam_d) <= 1e-8 * np.abs(lam_d)), (ep.values, lam_d)
        assert abs(lam_d[1] - lam_d[0]) < 1e-8 * abs(lam_d[0])  # a degenerate pair (to eigh's round-off) ...
        V, Vd = np.asarray(ep.vectors[:, :2]), st.dense.eigenvectors[:, :2]
        assert np.linalg.norm(V @ V.T - Vd @ Vd.T, 2) < 1e-6  # ... spanning the same plane
        assert float(ep.sigma) < lam_d[0]


# ------------------------------------------------------------------------------------------------
# Newton and tangent


def test_pinned_newton_converges_to_the_dense_equilibrium():
    scene = ring_scene(0.5)
    phi = 0.6 * jr.michell_critical_twist(0.5)
    rng = np.random.default_rng(2)
    q0 = np.asarray(scene.q_init) + np.concatenate([3e-3 * rng.normal(size=3 * N), 7.5e-3 * rng.normal(size=N)])
    nbr = scene.neighbourhood(jnp.asarray(q0), phi)
    u = u0 = scene.to_scaled(jnp.asarray(q0))
    norms = []
    for _ in range(15):
        g, _ = ss.gradient_and_phi_derivative(scene, u, phi, nbr)
        norms.append(float(jnp.max(jnp.abs(g))))
        if norms[-1] < 1e-11:
            break
        pins, s = ss.gauge_pins(scene, u, phi)
        d = ss.newton_direction(scene, u, phi, nbr, g)
        assert np.all(np.asarray(d)[np.asarray(pins)] == 0.0) and float(s) > 0.1
        u = u + d
    assert norms[-1] < 1e-11, norms
    assert len(norms) <= 12, norms
    eq = jr.solve_equilibrium(scene, phi, q0, jr.EquilibriumOptions(method="newton"))
    # The energy of our state through the same (compiled) diagnostics: a Newton solve from it
    # has nothing left to do.
    ours = jr.solve_equilibrium(scene, phi, np.asarray(scene.from_scaled(u)),
                                jr.EquilibriumOptions(method="newton", with_stability=False))
    assert ours.solution.iterations == 0
    assert ours.energy == pytest.approx(eq.energy, rel=1e-12)
    assert not np.allclose(np.asarray(u), np.asarray(u0))


def dense_tangent(st):
    """-H^+ d(grad)/dphi from the dense projected spectrum (lifted zero modes left out)."""
    lam, vec, n_zero = spectrum(st.scene, st.u, st.phi, st.nbr)
    lam, vec = np.asarray(lam)[: lam.shape[0] - int(n_zero)], np.asarray(vec)[:, : lam.shape[0] - int(n_zero)]
    _, dg = ss.gradient_and_phi_derivative(st.scene, st.u, st.phi, st.nbr)
    return -vec @ ((vec.T @ np.asarray(dg)) / lam)


@pytest.mark.parametrize("kind, frac", [("ring", 0.63), ("ring", 1.41), ("clamped", 0.77)])
def test_tangent_matches_dense_pseudo_inverse(states, kind, frac):
    # (jaxrod.linalg.stability.branch_analysis gives the same tangent, in physical DOFs, with the tracked
    # mode left out -- here it is formed from the dense spectrum to save its compilation.)
    nu = 0.5 if kind == "ring" else 0.0
    pc, sts = states[kind, nu]
    st = min(sts, key=lambda s: abs(s.phi / pc - frac))
    t = np.asarray(ss.tangent(st.scene, st.u, st.phi, st.nbr))
    ref = dense_tangent(st)
    assert np.max(np.abs(t - ref)) < 1e-8 * np.max(np.abs(ref))
    z = np.asarray(st.scene.scaled_zero_modes(st.u, st.phi))
    if z.shape[1]:
        assert np.max(np.abs(z.T @ t)) < 1e-10 * np.linalg.norm(z, axis=0).max() * np.linalg.norm(t)


# ------------------------------------------------------------------------------------------------
# timing


@pytest.mark.parametrize("kind", ["ring", "clamped"])
def test_critical_twist_sparse_equals_dense(kind):
    if kind == "ring":
        scene, guess = ring_scene(0.5), jr.michell_critical_twist(0.5)
    else:
        mat = jr.Material.from_ratio(B=1.0, nu=0.5, D=0.01)
        scene, guess = jr.clamped_rod(N=N, length=1.0, material=mat), jr.clamped_critical_twist(mat.B, mat.C)
    run = lambda la: jr.critical_twist(scene, 0.0, 2 * guess,  # noqa: E731
                                   jr.ContinuationOptions(step=guess / 8, linear_algebra=la))
    sparse, dense = run("sparse"), run("dense")
    assert sparse.phi == pytest.approx(dense.phi, rel=1e-9)
    assert guess < sparse.phi < 1.1 * guess  # the discrete threshold (N = 24), from above
    assert sparse.multiplicity == dense.multiplicity == 2  # degenerate pairs (rotation symmetry)
    assert sparse.dlambda_dphi == pytest.approx(dense.dlambda_dphi, rel=1e-6)
    assert abs(sparse.eigenvalue) < 1e-9 and sparse.phi_error < 1e-6 * np.pi
    assert sparse.equilibrium.solution.solver == "sparse_newton"


def test_sparse_branch_analysis_matches_dense():
    from jaxrod.continuation.sparse_branch import solve_equilibrium_sparse, sparse_branch_analysis
    from jaxrod.linalg.stability import branch_analysis

    scene = ring_scene(0.5)
    phi = 0.9 * jr.michell_critical_twist(0.5)
    e = solve_equilibrium_sparse(scene, phi)
    assert e.solution.converged and e.neighbourhood is not None and e.stability is None
    sp = sparse_branch_analysis(scene, e.q, phi, 0, nbr=e.neighbourhood)
    de = branch_analysis(scene, e.q, phi, 0, nbr=e.neighbourhood)
    assert sp[0].n_negative == de[0].n_negative == 0 and sp[0].n_zero_modes == de[0].n_zero_modes
    np.testing.assert_allclose(sp[0].eigenvalues, de[0].eigenvalues, rtol=1e-8)
    assert sp[1] == pytest.approx(de[1], rel=1e-8) and sp[2] == pytest.approx(de[2], rel=1e-8)
    np.testing.assert_allclose(sp[4], de[4], atol=1e-9)  # tangent dq/dphi (physical DOFs)
    # The tracked mode by overlap with a reference vector: its degenerate partner is found too.
    sp1 = sparse_branch_analysis(scene, e.q, phi, 0, ref=sp[0].eigenvectors[:, 1], nbr=e.neighbourhood)
    assert abs(np.dot(sp1[3], sp[0].eigenvectors[:, 1])) == pytest.approx(1.0, abs=1e-8)


def test_linear_algebra_choice():
    from jaxrod.linalg.backend import choose_backend

    assert not choose_backend(ring_scene(0.5), "auto").backend.structured
    assert choose_backend(jr.michell_ring(N=256), "auto").backend.name == "banded"
    assert not choose_backend(jr.michell_ring(N=256), "dense").backend.structured
    with pytest.raises(ValueError):
        choose_backend(ring_scene(0.5), "lapack")
