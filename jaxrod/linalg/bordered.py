"""Linear-algebra backends: everything the continuation does with the Jacobian goes through one.

A backend is chosen once, on the problem. ``DenseBackend`` assembles J (n, n) with ``jax.jacfwd``
and uses ``jnp.linalg``; ``SparseBackend`` works on the host with SciPy's sparse factorisations (a
knot's pinned Hessian at O(n), ``bifurcation.rods.knot_problem`` for large N). Both provide the same
three methods."""
from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np


@jax.jit
def _bordered(A, B, C, D, f, g):
    M = jnp.block([[A, B], [C.T, D]])
    z = jnp.linalg.solve(M, jnp.concatenate([f, g]))
    return z[: A.shape[0]], z[A.shape[0]:]


@dataclass(frozen=True)
class DenseBackend:
    """Dense J from ``jax.jacfwd``; solves and eigenpairs by ``jnp.linalg``. Stateless: every
    instance is equal (a problem's jitted functions are shared per backend, see ``problem``)."""

    def jacobian(self, f, u):
        """J = df/du (n, n) of f: (n,) -> (n,); traceable (called inside jit)."""
        return jax.jacfwd(f)(u)

    def bordered_solve(self, A, b, c, d, f, g):
        """Solve [[A, b], [c^T, d]] [x; y] = [f; g]. A (m, m); b, c (m,) with d, g scalars (y
        scalar), or b, c (m, k) with d (k, k), g (k,) (y (k,)). Traceable. The bordered matrix is
        regular at a fold, where A alone is singular."""
        # On the host the borders are shaped with numpy (no eager JAX programs), in a trace with jnp.
        host = not any(isinstance(v, jax.core.Tracer) for v in (A, b, c, d, f, g))
        xp = np if host else jnp
        if jnp.ndim(b) == 1:
            x, y = _bordered(A, xp.asarray(b)[:, None], xp.asarray(c)[:, None], xp.reshape(xp.asarray(d), (1, 1)), f,
                             xp.reshape(xp.asarray(g), (1,)))
            return x, (np.asarray(y)[0] if host else y[0])
        return _bordered(A, b, c, xp.asarray(d), f, xp.asarray(g))

    def spectrum(self, J, n_keep, n_zero, rtol):
        """(values (n_keep,), vectors (n, n_keep), Morse index) of the symmetric J. The n_zero
        eigenvalues of smallest |lambda| (gauge zero modes) are removed first. The Morse index
        counts lambda < -rtol * ||J||_2 over the whole spectrum (the band scales with J)."""
        partial = lowest_pairs_spectrum(J, n_keep, n_zero, rtol)
        if partial is not None:
            return partial
        vals, vecs = (np.asarray(a) for a in jnp.linalg.eigh(J))
        if n_zero:
            keep = np.sort(np.argsort(np.abs(vals))[n_zero:])
            vals, vecs = vals[keep], vecs[:, keep]
        scale = max(float(np.max(np.abs(vals), initial=0.0)), 1e-300)
        return vals[:n_keep], vecs[:, :n_keep], int(np.sum(vals < -rtol * scale))


# From this size on, ``DenseBackend.spectrum`` computes only the lowest eigenpairs (LAPACK dsyevr
# on an index range); smaller problems (the analytic test systems) keep the full one.
PARTIAL_MIN_SIZE = 200


def lowest_pairs_spectrum(J, n_keep, n_zero, rtol):
    """``DenseBackend.spectrum`` from the m = n_keep + n_zero lowest eigenpairs only, with the same
    result as the full decomposition; None where that cannot be told from them (a small or many
    times unstable J, or gauge modes not among the lowest): the caller then decomposes J whole. The
    Morse index counts the kept eigenvalues below -rtol ||J||_2, bracketed by max(|lambda_min|, max
    |J_ii|) and ||J||_F; lambda_max is computed only when they disagree."""
    import scipy.linalg

    J = np.asarray(J, dtype=float)
    n = J.shape[0]
    m = int(n_keep) + int(n_zero)
    if n < PARTIAL_MIN_SIZE or 3 * m >= n or not np.all(np.isfinite(J)):
        return None
    from .lapack import LAPACK_LOCK as _LAPACK_LOCK, lowest_eigenpairs

    with _LAPACK_LOCK:
        lam, vec = lowest_eigenpairs(J, m)  # scipy's dsyevr, without holding the GIL
    if lam[-1] < 0.0:  # negative eigenvalues beyond the m lowest: count them all
        return None
    if n_zero:
        by_size = np.argsort(np.abs(lam))
        if np.abs(lam[by_size[n_zero - 1]]) > lam[-1]:  # a gauge mode may lie above the m lowest
            return None
        keep = np.sort(by_size[n_zero:])
        lam, vec = lam[keep], vec[:, keep]
    low = max(abs(float(lam[0])), float(np.max(np.abs(np.diag(J)))), 1e-300)
    high = max(float(np.linalg.norm(J)), 1e-300)
    morse = int(np.sum(lam < -rtol * high))
    if morse != int(np.sum(lam < -rtol * low)):
        with _LAPACK_LOCK:
            top = scipy.linalg.eigh(J, eigvals_only=True, subset_by_index=[n - 1, n - 1], driver="evr",
                                    check_finite=False)
        morse = int(np.sum(lam < -rtol * max(abs(float(lam[0])), abs(float(top[0])), 1e-300)))
    return lam[:n_keep], vec[:, :n_keep], morse


@dataclass(frozen=True, eq=False)
class HostMatrix:
    """A symmetric J = S + w a a^T on the host: S (m, m) scipy sparse, a (m,), w a float. Its
    sparse LU (partial pivoting, for solves) is computed once, on first use."""

    S: object
    w: float
    a: np.ndarray

    @property
    def shape(self):
        return self.S.shape

    def matvec(self, x):
        return self.S @ x + self.w * self.a * (self.a @ x)

    def __array__(self, dtype=None, copy=None):  # dense, for small checks (np.asarray(J))
        dense = self.S.toarray() + self.w * np.outer(self.a, self.a)
        return dense if dtype is None else dense.astype(dtype)

    @functools.cached_property
    def lu(self):
        return _splu(self.S)


class _Singular:
    """The factorisation of a singular or non-finite matrix: its solves are NaN (as LAPACK's are),
    so the caller's non-finite-residual test ends that run."""

    def solve(self, b):
        return np.full(np.shape(b), np.nan)


def _splu(S, shift=0.0):
    import scipy.sparse as sp
    import scipy.sparse.linalg as spl

    A = sp.csc_matrix(S)
    if shift:
        A = (A - shift * sp.identity(A.shape[0], format="csc")).tocsc()
    if not np.all(np.isfinite(A.data)):
        return _Singular()
    try:
        return spl.splu(A, permc_spec="MMD_AT_PLUS_A")
    except RuntimeError:  # "Factor is exactly singular"
        return _Singular()


def _border_solve(lu, J, b, c, d, f, g):
    """[[S, a, b], [a^T, -1/w, 0], [c^T, 0, d]] by the Schur complement on S's factorisation
    (the rank-one term of J as one more border): -> (x, y) with y (k,)."""
    B, C = np.asarray(b, float), np.asarray(c, float)
    D, g = np.atleast_2d(np.asarray(d, float)), np.atleast_1d(np.asarray(g, float))
    if J.w != 0.0:
        k = B.shape[1]
        B = np.concatenate([J.a[:, None], B], axis=1)
        C = np.concatenate([J.a[:, None], C], axis=1)
        D = np.block([[np.array([[-1.0 / J.w]]), np.zeros((1, k))], [np.zeros((k, 1)), D]])
        g = np.concatenate([[0.0], g])
    Sf = lu.solve(np.asarray(f, float))
    if B.shape[1] == 0:
        return Sf, np.zeros(0)
    SB = lu.solve(B)
    y = np.linalg.solve(D - C.T @ SB, g - C.T @ Sf)
    x = Sf - SB @ y
    return x, (y[1:] if J.w != 0.0 else y)


@dataclass(frozen=True)
class SparseBackend:
    """The same three methods on the host, at O(n) per call, for a structured ``jacobian`` that
    returns parts which ``assemble(parts, args) -> HostMatrix`` turns into sparse + rank one (a
    knot's pinned Hessian). Solves by sparse LU with Schur-complement borders; the Morse index by
    the inertia of an LDL^T (``sparse_contact.negative_count``); eigenpairs by ARPACK shift-invert
    below the spectrum. Frozen and hashable, so a problem's jitted functions are shared."""

    assemble: object
    host = True

    def matrix(self, parts, args):
        return self.assemble(parts, args)

    def jacobian(self, f, u):
        raise NotImplementedError("SparseBackend needs the problem's structured jacobian (parts), not autodiff")

    def bordered_solve(self, A, b, c, d, f, g):
        """As ``DenseBackend.bordered_solve``, A a ``HostMatrix``."""
        if np.ndim(b) == 1:
            x, y = _border_solve(A.lu, A, np.asarray(b)[:, None], np.asarray(c)[:, None], np.reshape(d, (1, 1)), f,
                                 np.reshape(g, (1,)))
            return x, float(y[0])
        return _border_solve(A.lu, A, b, c, d, f, g)

    def damped_step(self, J, g, mu_prev):
        """(dy, mu): (J + mu I) dy = -g with mu just large enough for J + mu I to be positive
        definite, found by the inertia (the shift schedule of ``solvers._damped_newton_loop``, with
        no floor: see ``sparse_contact.damped_newton_direction``)."""
        scale = float(np.max(np.abs(J.S.diagonal() + J.w * J.a**2))) + 1.0
        mu0 = 1e-10 * scale
        mu = mu0 if mu_prev <= 0.0 else max(mu0, 0.1 * mu_prev)
        first = mu
        from .sparse_contact import FactorisationError

        for _ in range(80):
            try:
                if self._count_below(J, -mu) == 0:
                    break
            except FactorisationError:  # no symmetric-mode factorisation at this shift: a larger one
                pass
            mu *= 4.0
        else:
            return np.full(J.shape[0], np.nan), mu
        lu = _splu(J.S, -mu)
        x, _ = _border_solve(lu, J, np.zeros((J.shape[0], 0)), np.zeros((J.shape[0], 0)), np.zeros((0, 0)), -g,
                             np.zeros(0))
        return x, (0.0 if (mu == first and mu <= mu0) else mu)

    def _count_below(self, J, s):
        from .sparse_contact import negative_count

        import scipy.sparse as sp

        A = (sp.csc_matrix(J.S) - s * sp.identity(J.shape[0], format="csc")).tocsc()
        if J.w == 0.0:
            return negative_count(A, np.zeros((J.shape[0], 0)), np.zeros((0, 0)))
        return negative_count(A, J.a[:, None], np.array([[-1.0 / J.w]])) - (1 if J.w > 0.0 else 0)

    def spectrum(self, J, n_keep, n_zero, rtol):
        """As ``DenseBackend.spectrum`` (pinned problems: n_zero must be 0). ||J||_2 by a short
        Lanczos run; the Morse index counts lambda < -rtol ||J||_2 exactly (Sylvester)."""
        import scipy.sparse.linalg as spl

        if n_zero:
            raise NotImplementedError("SparseBackend: pin the gauge (n_zero_modes = 0)")
        m = J.shape[0]
        if not (np.all(np.isfinite(J.S.data)) and np.all(np.isfinite(J.a)) and np.isfinite(J.w)):
            k = int(min(n_keep, m - 1))
            return np.full(k, np.nan), np.full((m, k), np.nan), 0
        op = spl.LinearOperator((m, m), matvec=lambda x: J.matvec(np.ravel(x)), dtype=float)
        v0 = np.cos(0.7 * np.arange(m) + 0.3) + 0.5  # deterministic: resumed runs repeat themselves
        scale = float(abs(spl.eigsh(op, k=1, which="LM", v0=v0, tol=1e-6, return_eigenvectors=False)[0]))
        morse = self._count_below(J, -rtol * scale)
        s = -max(rtol * scale, 1e-14 * scale)
        for _ in range(80):
            if self._count_below(J, s) == 0:
                break
            s *= 4.0
        lu = _splu(J.S, s)
        shifted = HostMatrix(J.S, J.w, J.a)  # the same J; its solves at the shift below

        def inverse(b):
            x, _ = _border_solve(lu, shifted, np.zeros((m, 0)), np.zeros((m, 0)), np.zeros((0, 0)), np.ravel(b),
                                 np.zeros(0))
            return x

        k = int(min(n_keep, m - 1))
        opinv = spl.LinearOperator((m, m), matvec=inverse, dtype=float)
        _, vec = spl.eigsh(op, k=k, sigma=s, which="LM", OPinv=opinv, v0=v0, ncv=min(m - 1, max(2 * k + 1, 20)),
                           tol=1e-13)
        vec, _ = np.linalg.qr(vec)
        hv = np.column_stack([J.matvec(vec[:, j]) for j in range(k)])
        vals, rot = np.linalg.eigh(0.5 * (vec.T @ hv + hv.T @ vec))  # Rayleigh-Ritz: accurate values
        vec = vec @ rot
        return vals, vec, morse
