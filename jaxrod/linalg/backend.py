"""One interface to the linear algebra of a rod's Hessian, with dense, banded and sparse backends.

A backend factorises the Hessian of ``scene.scaled_energy`` at a state (u, phi, nbr) into a
``Factorisation``: ``inertia(shift)`` (counts below/at or above ``shift`` and the zero modes
removed), ``solve(rhs)`` (x on Z-perp with P H P x = P rhs), ``lowest_eigenpairs(k)`` and
``bordered_solve(b, c, d, f, g)`` ([[A, b], [c^T, d]] [x; y] = [f; g], A the projected Hessian).
"Projected Hessian" is the same for every backend: P H P on the orthogonal complement of the
symmetry generators Z, of dimension n - z; the zero modes are never returned nor counted. Backends:
``Dense`` (n x n, LAPACK, O(n^3)), ``Banded`` (block LDL^T of ``jaxrod.linalg.sparse``, O(N), no
contact) and ``Sparse`` (``jaxrod.linalg.sparse_contact``, O(N), any rod); ``choose_backend(scene,
options)`` picks one for a scene and says why."""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from .options import BACKEND_NAMES, SPARSE_MIN_DOF, LinalgOptions, backend_name, has_contact  # noqa: F401

__all__ = ["LinalgOptions", "Inertia", "Eigenpairs", "Factorisation", "LinalgBackend", "Dense", "Banded", "Sparse",
           "BackendChoice", "choose_backend", "BACKEND_NAMES", "SPARSE_MIN_DOF"]

class Inertia(NamedTuple):
    """Counts of the projected Hessian's eigenvalues below a shift (negative), at or above it
    (positive), and the symmetry modes removed (zero); negative + zero + positive = n."""

    negative: int
    zero: int
    positive: int


class Eigenpairs(NamedTuple):
    """values (k,) ascending; vectors (n, k) orthonormal, orthogonal to the zero modes (scaled
    DOFs, q order), each with its largest-magnitude entry positive."""

    values: np.ndarray
    vectors: np.ndarray


class Factorisation(Protocol):
    """The Hessian at one state, factorised by a backend (see module docstring)."""

    n: int
    n_zero: int

    def inertia(self, shift: float = 0.0) -> Inertia: ...

    def solve(self, rhs) -> np.ndarray: ...

    def lowest_eigenpairs(self, k: int) -> Eigenpairs: ...

    def bordered_solve(self, b, c, d, f, g): ...


class LinalgBackend(Protocol):
    """A way to factorise a scene's Hessian; ``structured``: O(n) (no n x n array)."""

    name: str
    structured: bool

    def supports(self, scene) -> bool: ...

    def factorise(self, scene, u, phi, nbr) -> Factorisation: ...


def _fix_signs(vec):
    """Eigenvectors (n, m) with their largest-magnitude entry positive."""
    big = np.take_along_axis(vec, np.argmax(np.abs(vec), axis=0)[None, :], axis=0)
    return vec * np.where(big < 0.0, -1.0, 1.0)


def _as_columns(v):
    v = np.asarray(v, dtype=float)
    return (v[:, None], True) if v.ndim == 1 else (v, False)


class _Projected:
    """What every factorisation shares: the zero-mode basis z (n, z), the projector off it, and a
    bordered solve by block elimination through ``solve`` (Keller's bordering algorithm: exact
    where the projected Hessian is regular)."""

    z: np.ndarray

    @property
    def n(self):
        return self.z.shape[0]

    @property
    def n_zero(self):
        return int(np.sum(np.any(self.z != 0.0, axis=0)))

    def project(self, v):
        v = np.asarray(v, dtype=float)
        return v - self.z @ (self.z.T @ v)

    def _inertia(self, negative):
        negative = int(negative)
        return Inertia(negative, self.n_zero, self.n - self.n_zero - negative)

    def bordered_solve(self, b, c, d, f, g):
        """(x, y) of [[A, b], [c^T, d]] [x; y] = [f; g], A the projected Hessian; b, c (n,) with
        d, g scalars, or (n, k) with d (k, k), g (k,)."""
        B, vector = _as_columns(b)
        C, _ = _as_columns(c)
        D, G = np.atleast_2d(np.asarray(d, float)), np.atleast_1d(np.asarray(g, float))
        xf = self.solve(f)
        xb = np.column_stack([self.solve(B[:, j]) for j in range(B.shape[1])])
        y = np.linalg.solve(D - C.T @ xb, G - C.T @ xf)
        x = xf - xb @ y
        return (x, float(y[0])) if vector else (x, y)


def _negative_pivots(ldu, ipiv):
    """The negative eigenvalues of D in a Bunch-Kaufman A = L D L^T (LAPACK ``dsytrf``, lower):
    by Sylvester's law of inertia, those of A. D has 1 x 1 blocks (ipiv > 0) and 2 x 2 ones (a pair
    of equal negative ipiv)."""
    negative, k, n = 0, 0, ldu.shape[0]
    while k < n:
        if ipiv[k] > 0:
            negative += int(ldu[k, k] < 0.0)
            k += 1
        else:
            block = np.array([[ldu[k, k], ldu[k + 1, k]], [ldu[k + 1, k], ldu[k + 1, k + 1]]])
            negative += int(np.sum(np.linalg.eigvalsh(block) < 0.0))
            k += 2
    return negative


class _DenseFactorisation(_Projected):
    """The projected Hessian (n, n) with its Bunch-Kaufman factorisation (LAPACK ``dsytrf``): solves
    and the inertia at 0 from one factorisation, each other shift factorised once on request."""

    def __init__(self, scene, u, phi, nbr, options):
        from .stability import _projected

        hp, z, _, _ = _projected(scene, u, phi, nbr)
        self.hp, self.z, self.options = np.asarray(hp), np.asarray(z), options
        self._factors = {}

    def _factor(self, shift):
        from scipy.linalg import lapack

        if shift not in self._factors:
            shifted = self.hp - shift * np.eye(self.n) if shift else self.hp
            lwork = int(lapack.dsytrf_lwork(self.n, lower=1)[0])  # the blocked algorithm's workspace
            ldu, ipiv, info = lapack.dsytrf(shifted, lower=1, lwork=max(lwork, self.n))
            if info < 0:
                raise ValueError(f"dsytrf: argument {-info} is invalid")
            self._factors[shift] = (ldu, ipiv, info > 0)  # info > 0: an exactly zero pivot
        return self._factors[shift]

    def inertia(self, shift=0.0):
        # the lifted zero modes lie above every physical eigenvalue: never counted below the shift
        ldu, ipiv, _ = self._factor(float(shift))
        return self._inertia(_negative_pivots(ldu, ipiv))

    def lowest_eigenpairs(self, k):
        from .stability import LOWEST_COUNT, _lowest_of

        if k <= LOWEST_COUNT:
            lam, vec, _ = _lowest_of(self.hp, self.options.negative_tol)
        else:
            lam, vec = np.linalg.eigh(self.hp)
        lam, vec = np.asarray(lam), np.asarray(vec)
        keep = min(int(k), self.n - self.n_zero, lam.shape[0])
        return Eigenpairs(lam[:keep], _fix_signs(vec[:, :keep]))

    def solve(self, rhs):
        from scipy.linalg import lapack

        ldu, ipiv, singular = self._factor(0.0)
        if singular:
            raise np.linalg.LinAlgError("the projected Hessian is singular")
        x, info = lapack.dsytrs(ldu, ipiv, self.project(rhs), lower=1)
        if info != 0:
            raise ValueError(f"dsytrs: argument {-info} is invalid")
        return self.project(x)

    def bordered_solve(self, b, c, d, f, g):
        """As ``_Projected.bordered_solve``, by one LU of the whole bordered matrix (regular at a
        fold of A, where A alone is singular)."""
        from .bordered import DenseBackend

        x, y = DenseBackend().bordered_solve(self.hp, self.project(b), self.project(c), d, self.project(f), g)
        return np.asarray(x), (float(y) if np.ndim(b) == 1 else np.asarray(y))


class _BandedFactorisation(_Projected):
    def __init__(self, scene, u, phi, nbr, options):
        from . import sparse as banded_path

        banded_path._check_scene(scene)
        self.args, self.options = (scene, u, phi, nbr), options
        self.lay = banded_path.block_layout(scene)
        self.parts = banded_path.block_hessian(scene, u, phi, nbr)
        Q, self.pins, _ = banded_path._gauge(scene, u, phi)
        self.Q, self.z = Q, np.asarray(Q)
        self.setup = banded_path._eig_setup(self.lay, *self.parts, Q)

    def inertia(self, shift=0.0):
        import jax.numpy as jnp

        from .sparse import _projected_count

        diag, U, c, Zr, _, _ = self.setup
        return self._inertia(_projected_count(diag, self.parts[1], self.lay.cyclic, U, c, Zr,
                                              jnp.asarray(shift, diag.dtype)))

    def lowest_eigenpairs(self, k):
        from .sparse import lowest_eigenpairs_projected

        pairs = lowest_eigenpairs_projected(*self.args, int(k), tol=self.options.eig_tol)
        return Eigenpairs(np.asarray(pairs.values), _fix_signs(np.asarray(pairs.vectors)))

    def solve(self, rhs):
        import jax.numpy as jnp

        from .sparse import _pinned_solve

        # The pinned solve equals the projected one for a rhs orthogonal to Z: project it first.
        rhs = jnp.asarray(self.project(rhs))
        return np.asarray(_pinned_solve(self.lay, *self.parts, self.pins, self.Q, rhs))


class _SparseFactorisation(_Projected):
    def __init__(self, scene, u, phi, nbr, options):
        from .sparse_contact import sparse_hessian

        self.hs, self.options = sparse_hessian(scene, np.asarray(u, float), phi, nbr), options
        self.z = self.hs.Z

    def inertia(self, shift=0.0):
        from .sparse_contact import count_below

        return self._inertia(count_below(self.hs, shift))

    def lowest_eigenpairs(self, k):
        from .sparse_contact import lowest_eigenpairs

        lam, vec, _ = lowest_eigenpairs(self.hs, int(k), tol=self.options.negative_tol)
        return Eigenpairs(lam, _fix_signs(vec))

    def solve(self, rhs):
        from .sparse_contact import _constrained, _projected_solve

        return _projected_solve(_constrained(self.hs, 0.0, self.hs.Z), None, self.hs, np.asarray(rhs, float))


@dataclass(frozen=True)
class Dense:
    """The n x n projected Hessian and LAPACK (``jaxrod.linalg.stability``): any scene, O(n^3)."""

    options: LinalgOptions = LinalgOptions()
    name = "dense"
    structured = False

    def supports(self, scene):
        return True

    def factorise(self, scene, u, phi, nbr):
        return _DenseFactorisation(scene, u, phi, nbr, self.options)


@dataclass(frozen=True)
class Banded:
    """Block LDL^T of the block-tridiagonal + rank-one Hessian (``jaxrod.linalg.sparse``,
    ``jaxrod.linalg.banded``): O(N), rods without contact (contact couples distant nodes)."""

    options: LinalgOptions = LinalgOptions()
    name = "banded"
    structured = True

    def supports(self, scene):
        return not has_contact(scene)

    def factorise(self, scene, u, phi, nbr):
        return _BandedFactorisation(scene, u, phi, nbr, self.options)


@dataclass(frozen=True)
class Sparse:
    """Sparse LDL^T (QDLDL) with the rank-one term and zero modes as a border, ARPACK for the
    eigenpairs (``jaxrod.linalg.sparse_contact``): O(N), any rod, contact included."""

    options: LinalgOptions = LinalgOptions()
    name = "sparse"
    structured = True

    def supports(self, scene):
        return True

    def factorise(self, scene, u, phi, nbr):
        return _SparseFactorisation(scene, u, phi, nbr, self.options)


_BY_NAME = {"dense": Dense, "banded": Banded, "sparse": Sparse}


class BackendChoice(NamedTuple):
    """The backend chosen for a scene, and why (one sentence)."""

    backend: LinalgBackend
    reason: str


def choose_backend(scene, options=None, offered=("dense", "banded", "sparse")):
    """The backend for ``scene`` under ``options`` (a ``LinalgOptions``, or just a backend name;
    None: the defaults), and why: a ``BackendChoice`` (backend, reason), which unpacks as a pair.
    offered: the backends the caller implements; where the preferred one is not among them the
    choice falls back to dense and the reason says so. ``backend.structured``: an O(n) choice."""
    if options is None:
        options = LinalgOptions()
    elif isinstance(options, str):
        options = LinalgOptions(backend=options)
    name, reason = backend_name(scene, options, offered)
    return BackendChoice(_BY_NAME[name](options), reason)
