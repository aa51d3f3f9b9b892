"""A sparse symmetric LDL^T with diagonal pivots only, whose pivots give the inertia (Sylvester).

QDLDL (AMD ordering, then P A P^T = L D L^T without pivoting) first, its symbolic factorisation
reused per sparsity pattern (``_SymbolicPool``); at a zero pivot, SuperLU (``splu``) in symmetric
mode with a diagonal pivot threshold of 0; a run that pivoted off the diagonal is refused
(``FactorisationError``). Why QDLDL: a true LDL^T at half SuperLU's work; a Cholesky gives
definiteness, not the count."""
from __future__ import annotations

import collections
import threading
import weakref

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

try:  # a true sparse LDL^T; SuperLU in symmetric mode stands in without it
    import qdldl as _qdldl
except ImportError:  # pragma: no cover
    _qdldl = None

__all__ = ["FactorisationError", "QDLDLFactor", "ldlt", "negative_count"]


class FactorisationError(np.linalg.LinAlgError):
    """The symmetric-mode factorisation pivoted off the diagonal or met a zero pivot: no inertia."""


class _SymbolicPool:
    """Idle QDLDL solvers by sparsity pattern, so that a matrix whose pattern was factorised before
    skips the AMD ordering and elimination tree (``Solver.update`` redoes only the numbers, with
    the same ordering, hence the same factor bit for bit). A solver is lent to one ``QDLDLFactor``
    at a time and comes back when that is freed; a few patterns are kept, least recently used
    dropped. Thread-safe."""

    def __init__(self, patterns=8, per_pattern=3):
        self._idle = collections.OrderedDict()
        self._lock = threading.Lock()
        self._patterns, self._per_pattern = patterns, per_pattern

    @staticmethod
    def key(A):
        return A.shape[0], A.nnz, hash(A.indptr.tobytes()), hash(A.indices.tobytes())

    def factorise(self, A):
        """(key, solver) holding the LDL^T of A (csc, canonical); raises RuntimeError as QDLDL does."""
        key = self.key(A)
        with self._lock:
            idle = self._idle.get(key)
            solver = idle.pop() if idle else None
        if solver is None:
            return key, _qdldl.Solver(A)
        solver.update(A)  # if this raises, the solver (its numbers now invalid) is dropped, not given back
        return key, solver

    def give_back(self, key, solver):
        with self._lock:
            idle = self._idle.setdefault(key, [])
            self._idle.move_to_end(key)
            if len(idle) < self._per_pattern:
                idle.append(solver)
            while len(self._idle) > self._patterns:
                self._idle.popitem(last=False)


_POOL = _SymbolicPool()


class QDLDLFactor:
    """An LDL^T of A from QDLDL (``qdldl.Solver``: AMD ordering, no pivoting): its pivots are D,
    ``solve`` takes (m,) or (m, k) right-hand sides (QDLDL's takes one vector). Its solver goes
    back to the pool when this object is freed."""

    def __init__(self, key, solver):
        self._solver = solver
        weakref.finalize(self, _POOL.give_back, key, solver)

    def solve(self, b):
        b = np.asarray(b, float)
        if b.ndim == 1:
            return self._solver.solve(b)
        out = np.empty_like(b)
        for k in range(b.shape[1]):
            out[:, k] = self._solver.solve(np.ascontiguousarray(b[:, k]))
        return out


def ldlt(A):
    """(factorisation with ``.solve``, pivots (m,)) of the symmetric sparse A with diagonal pivots
    only, i.e. an LDL^T whose pivots' signs give A's inertia (Sylvester). Raises FactorisationError
    where A has no such factorisation (exactly singular, a pivot off the diagonal, a zero or
    non-finite pivot). QDLDL first (a true LDL^T, half SuperLU's work); where it refuses (a zero
    pivot, a diagonal entry missing from the pattern) SuperLU in symmetric mode decides: it may
    still find the diagonal-pivot factorisation, or says why there is none."""
    A = sp.csc_matrix(A)
    if _qdldl is not None:
        A.sort_indices()
        try:
            key, solver = _POOL.factorise(A)
        except RuntimeError:
            solver = None
        if solver is not None:
            fac = QDLDLFactor(key, solver)
            pivots = solver.factors()[1]
            if np.all(np.isfinite(pivots)) and not np.any(pivots == 0.0):
                return fac, pivots
    try:
        lu = spl.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options=dict(SymmetricMode=True, Equil=False))
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise FactorisationError(str(exc)) from None
    if not np.array_equal(lu.perm_r, lu.perm_c):
        raise FactorisationError("the factorisation pivoted off the diagonal")
    pivots = lu.U.diagonal()
    if not np.all(np.isfinite(pivots)) or np.any(pivots == 0.0):
        raise FactorisationError("zero or non-finite pivot")
    return lu, pivots


def negative_count(A, E, D):
    """Number of negative eigenvalues of the symmetric [[A, E], [E^T, D]]: A (m, m) scipy sparse,
    factorised with diagonal pivots only (LDL^T, Sylvester), E (m, r), D (r, r) dense (Haynsworth:
    In = In(A) + In(D - E^T A^-1 E)). Raises FactorisationError where A has no such factorisation."""
    lu, pivots = ldlt(A)
    E = np.asarray(E, float).reshape(A.shape[0], -1)
    if E.shape[1] == 0:
        return int(np.sum(pivots < 0.0))
    schur = np.asarray(D, float) - E.T @ lu.solve(E)
    return int(np.sum(pivots < 0.0)) + int(np.sum(np.linalg.eigvalsh(0.5 * (schur + schur.T)) < 0.0))
