"""jaxrod.linalg.banded: block-tridiagonal (+ cyclic corner, + low rank) factor/inertia/solve/eigenpairs.

Everything is checked against the same matrix assembled densely in numpy.  Shapes are few and
reused on purpose: every distinct (K, b, r, cyclic) compiles the scans again.
"""
import functools
import time

import jax
import numpy as np
import pytest

from jaxrod.linalg import banded


def dense(diag, off, cyclic, U=None, c=None):
    """The (n, n) matrix T + U diag(c) U^T, following the block conventions of jaxrod.linalg.banded."""
    K, b, _ = diag.shape
    T = np.zeros((K * b, K * b))
    for k in range(K):
        T[k * b:(k + 1) * b, k * b:(k + 1) * b] += diag[k]
    for k in range(K if cyclic else K - 1):
        j = (k + 1) % K
        T[k * b:(k + 1) * b, j * b:(j + 1) * b] += off[k]
        T[j * b:(j + 1) * b, k * b:(k + 1) * b] += off[k].T
    if U is not None:
        T = T + (U * c) @ U.T
    return T


def random_blocks(rng, K, b, kind):
    """Symmetric indefinite block-tridiagonal T.

    "tame": diagonal entries of random sign and size 3..5 plus moderate random coupling -- still
    indefinite in every block, but with M well conditioned, so a forward-error comparison with
    np.linalg.solve at 1e-10 is meaningful.  "wild": plain Gaussian blocks (condition numbers up to
    ~1e8 for K = 200), checked through inertia and backward error instead.
    """
    G = rng.standard_normal((K, b, b))
    if kind == "wild":
        return G + np.swapaxes(G, 1, 2), rng.standard_normal((K, b, b))
    d = rng.choice([-1.0, 1.0], size=(K, b)) * rng.uniform(3.0, 5.0, size=(K, b))
    diag = 0.2 * (G + np.swapaxes(G, 1, 2)) + d[:, :, None] * np.eye(b)
    return diag, 0.3 * rng.standard_normal((K, b, b))


def random_lowrank(rng, n, r):
    U = 2.0 * rng.standard_normal((n, r)) / np.sqrt(n)
    c = rng.choice([-1.0, 1.0], size=r) * rng.uniform(0.5, 3.0, size=r)
    if r >= 8:
        c[3] = 0.0  # a zero weight must be harmless
    return U, c


def counts(ev):
    return int(np.sum(ev < 0)), int(np.sum(ev > 0))


@functools.partial(jax.jit, static_argnames="cyclic")
def all_ops(diag, off, U, c, rhs, cyclic):
    """factor + inertia + solve + matvec under one jit: one compilation per shape instead of four
    (compiling dominates this file's run time).  The separately jitted public entry points are
    exercised by the K = 2 and timing tests."""
    fac = banded.factor(diag, off, cyclic)
    return (banded.inertia(fac, U, c), banded.solve(fac, rhs, U, c),
            banded.matvec(diag, off, cyclic, rhs, U, c))


# (K, b, cyclic, r): K from 3 to 200, b = 4 and 8, r = 0, 1, 8, cyclic and not.
CASES = [
    (3, 4, True, 1),
    (3, 4, False, 0),
    (200, 4, True, 8),
    (100, 8, False, 1),
    (64, 8, True, 8),
]


@pytest.mark.parametrize("K, b, cyclic, r", CASES)
def test_factor_inertia_solve_matvec_against_dense(K, b, cyclic, r):
    rng = np.random.default_rng(1000 * K + 10 * b + r + cyclic)
    n = K * b
    U, c = random_lowrank(rng, n, r)
    Uarg, carg = (U, c) if r else (None, None)
    rhs = rng.standard_normal((n, 3))
    for kind in ("tame", "wild"):
        diag, off = random_blocks(rng, K, b, kind)
        M = dense(diag, off, cyclic, U, c)
        ev = np.linalg.eigvalsh(M)
        (neg, pos), x, mv = all_ops(diag, off, Uarg, carg, rhs, cyclic)
        assert neg.dtype == np.int32 and pos.dtype == np.int32
        assert (int(neg), int(pos)) == counts(ev), kind
        assert 0 < int(neg) < n  # genuinely indefinite

        np.testing.assert_allclose(mv, M @ rhs, rtol=0, atol=1e-13 * np.abs(M).sum(1).max())
        x = np.asarray(x)
        assert x.shape == rhs.shape
        # Backward error: what a stable solver can promise whatever the conditioning.
        backward = np.linalg.norm(M @ x - rhs) / (np.abs(ev).max() * np.linalg.norm(x))
        assert backward < 1e-13, (kind, backward)
        if kind == "tame":
            x_ref = np.linalg.solve(M, rhs)
            assert np.linalg.norm(x - x_ref) <= 1e-10 * np.linalg.norm(x_ref)


def test_cyclic_with_two_blocks_adds_both_couplings():
    # K = 2 cyclic: off[0] = T[0, 1] and off[1] = T[1, 0] hit the same block pair and add up.
    rng = np.random.default_rng(7)
    diag, off = random_blocks(rng, 2, 4, "wild")
    M = dense(diag, off, True)
    rhs = rng.standard_normal(8)  # (n,) right-hand side through the public entry points
    np.testing.assert_allclose(banded.matvec(diag, off, True, rhs), M @ rhs, atol=1e-13)
    fac = banded.factor(diag, off, True)
    x = banded.solve(fac, rhs)
    assert x.shape == (8,)
    np.testing.assert_allclose(x, np.linalg.solve(M, rhs), rtol=1e-10, atol=1e-12)
    neg, pos = banded.inertia(fac)
    assert neg.dtype == np.int32 and (int(neg), int(pos)) == counts(np.linalg.eigvalsh(M))


@pytest.mark.parametrize("K, b, cyclic, r", [CASES[2], CASES[1]])
def test_inertia_of_nearly_singular_matrix(K, b, cyclic, r):
    """Shift T's diagonal so that M has one eigenvalue delta = +-1e-9 / +-1e-10 of ||M||.

    That eigenvalue is far above round-off, so its sign -- and with it the whole inertia -- must
    still come out exactly, even though every solve with M is now ill conditioned.
    """
    rng = np.random.default_rng(99)
    n = K * b
    U, c = random_lowrank(rng, n, r)
    Uarg, carg = (U, c) if r else (None, None)
    diag, off = random_blocks(rng, K, b, "wild")
    rhs = np.zeros((n, 3))  # same shapes as above: reuses that compilation
    ev = np.linalg.eigvalsh(dense(diag, off, cyclic, U, c))
    norm = np.abs(ev).max()
    target = ev[n // 3]  # an interior eigenvalue: the shifted T stays indefinite
    for rel in (1e-9, -1e-9, 1e-10, -1e-10):
        shift = target - rel * norm
        shifted = ev - shift  # eigenvalues of the shifted M, one of them rel * norm
        assert np.min(np.abs(shifted)) == pytest.approx(abs(rel) * norm, rel=1e-3)
        (neg, pos), _, _ = all_ops(diag - shift * np.eye(b), off, Uarg, carg, rhs, cyclic)
        assert (int(neg), int(pos)) == counts(shifted), rel


def test_lowest_eigenpairs_degenerate_pair_with_constraints():
    """Projected problem P M P on Z-perp (z = 7) whose lowest eigenvalue is exactly double.

    The degeneracy is built in: with v1 the lowest projected eigenvector of T + U0 c0 U0^T
    (v1 is orthogonal to Z), adding (lam2 - lam1) v1 v1^T as one more low-rank column lifts lam1
    onto lam2 and leaves everything else alone.
    """
    rng = np.random.default_rng(3)
    K, b, cyclic, z, k = 40, 4, True, 7, 4
    n = K * b
    diag, off = random_blocks(rng, K, b, "wild")
    U0, c0 = random_lowrank(rng, n, 2)
    Z, _ = np.linalg.qr(rng.standard_normal((n, z)))
    Qfull, _ = np.linalg.qr(np.concatenate([Z, rng.standard_normal((n, n - z))], axis=1))
    Q = Qfull[:, z:]  # orthonormal basis of Z-perp
    lam, V = np.linalg.eigh(Q.T @ dense(diag, off, cyclic, U0, c0) @ Q)
    U = np.concatenate([U0, (Q @ V[:, 0])[:, None]], axis=1)
    c = np.concatenate([c0, [lam[1] - lam[0]]])
    lam, V = np.linalg.eigh(Q.T @ dense(diag, off, cyclic, U, c) @ Q)
    V = Q @ V
    norm = np.abs(lam).max()
    assert lam[1] - lam[0] < 1e-12 * norm and lam[2] - lam[1] > 1e-3 * norm  # a clean double pair

    sigma = lam[0] - 0.1 * (lam[5] - lam[0])
    theta, X, res = banded.lowest_eigenpairs(diag, off, cyclic, U, c, Z, k, sigma)
    theta, X, res = np.asarray(theta), np.asarray(X), np.asarray(res)
    assert theta.shape == (k,) and X.shape == (n, k) and res.shape == (k,)
    np.testing.assert_allclose(theta, lam[:k], rtol=0, atol=1e-9 * norm)
    assert np.all(res < 1e-9 * norm)
    np.testing.assert_allclose(X.T @ X, np.eye(k), atol=1e-12)
    assert np.abs(Z.T @ X).max() < 1e-12
    # Eigenvector subspaces: the double pair as a 2-D space, the others one by one (projectors).
    for sl in (slice(0, 2), slice(2, 3), slice(3, 4)):
        Px, Pv = X[:, sl] @ X[:, sl].T, V[:, sl] @ V[:, sl].T
        assert np.linalg.norm(Px - Pv, 2) < 1e-9, sl


def test_timing_K512_b8_cyclic_rank1(capsys):
    """Timings (printed, not asserted) for a rod-sized problem: n = 4096 DOFs."""
    rng = np.random.default_rng(5)
    K, b, cyclic, r = 512, 8, True, 1
    n = K * b
    diag, off = random_blocks(rng, K, b, "tame")
    U, c = random_lowrank(rng, n, r)
    rhs = rng.standard_normal(n)

    def factor_inertia():
        fac = banded.factor(diag, off, cyclic)
        return fac, banded.inertia(fac, U, c)

    t0 = time.perf_counter()
    fac, inert = jax.block_until_ready(factor_inertia())
    t1 = time.perf_counter()
    x = jax.block_until_ready(banded.solve(fac, rhs, U, c))
    t2 = time.perf_counter()
    first = (t1 - t0, t2 - t1)

    reps = 5
    t0 = time.perf_counter()
    for _ in range(reps):
        fac, inert = jax.block_until_ready(factor_inertia())
    t1 = time.perf_counter()
    for _ in range(reps):
        x = jax.block_until_ready(banded.solve(fac, rhs, U, c))
    t2 = time.perf_counter()
    fi, sv = (t1 - t0) / reps, (t2 - t1) / reps

    residual = banded.matvec(diag, off, cyclic, x, U, c) - rhs
    assert np.linalg.norm(residual) < 1e-11 * np.linalg.norm(rhs)
    assert int(inert[0]) + int(inert[1]) == n
    with capsys.disabled():
        print(f"\n[banded timing] K={K} b={b} cyclic r={r} (n={n}): "
              f"factor+inertia {1e3 * fi:.2f} ms, solve {1e3 * sv:.2f} ms; "
              f"first calls incl. compile: factor+inertia {first[0]:.2f} s, solve {first[1]:.2f} s "
              f"(compile ~ {first[0] - fi:.2f} s + {first[1] - sv:.2f} s)")
