"""jaxrod.linalg.lapack: SciPy's LAPACK routines called without holding the GIL give SciPy's results to
the last bit (the dense path's eigenpairs and branch tangents must not change with the caller)."""
import numpy as np
import pytest
import scipy.linalg

from jaxrod.linalg import lapack


@pytest.mark.parametrize("n, m", [(484, 12), (120, 6), (40, 1), (9, 9)])
def test_lowest_eigenpairs_equal_scipys_dsyevr_bit_for_bit(n, m):
    rng = np.random.default_rng(n)
    a = rng.standard_normal((n, n))
    for h in (0.5 * (a + a.T), a):  # symmetric, and not: both read the lower triangle
        w0, z0 = scipy.linalg.eigh(h, subset_by_index=[0, m - 1], driver="evr", check_finite=False)
        w, z = lapack.lowest_eigenpairs(h, m)
        assert w.shape == (m,) and z.shape == (n, m)
        assert np.array_equal(w, w0) and np.array_equal(z, z0)
    assert lapack.lapack_routine("dsyevr", 21) is not None  # the GIL-free path was the one tested


def test_cholesky_solve_equals_scipys_and_refuses_an_indefinite_matrix():
    rng = np.random.default_rng(1)
    a = rng.standard_normal((200, 200))
    h = a @ a.T + 200.0 * np.eye(200)
    h[0, 5] += 1e-3  # the upper triangle is not read
    b = rng.standard_normal(200)
    x0 = scipy.linalg.cho_solve(scipy.linalg.cho_factor(h, lower=True, check_finite=False), b, check_finite=False)
    assert np.array_equal(lapack.cholesky_solve(h, b), x0)
    with pytest.raises(np.linalg.LinAlgError, match="positive definite"):
        lapack.cholesky_solve(np.diag([1.0, -1.0, 2.0]), np.ones(3))


def test_a_routine_not_in_the_table_falls_back_to_scipy(monkeypatch):
    monkeypatch.setattr(lapack, "lapack_routine", lambda name, n_args: None)
    h = np.diag([3.0, 1.0, 2.0])
    w, z = lapack.lowest_eigenpairs(h, 2)
    assert np.allclose(w, [1.0, 2.0]) and np.allclose(np.abs(z[:, 0]), [0.0, 1.0, 0.0])
    assert np.allclose(lapack.cholesky_solve(h, np.array([3.0, 1.0, 2.0])), 1.0)
