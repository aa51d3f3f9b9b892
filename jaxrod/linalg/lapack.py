"""The dense path's host LAPACK calls, made without holding Python's GIL.

SciPy's LAPACK wrappers (f2py) keep the GIL while LAPACK runs, which stopped the other threads of a
study (its two directions, the CLI's branch-end workers) during every partial eigensolve. Here the
same routine is called through SciPy's C-level table (``scipy.linalg.cython_lapack``), its function
pointer wrapped by ``ctypes.CFUNCTYPE``, whose calls release the GIL. The arguments are those
SciPy's ``eigh(..., subset_by_index=..., driver="evr")`` passes, so the results are the same to the
last bit (tested). Where the table is missing or not 32-bit-integer LAPACK, SciPy's wrapper is used
instead."""
from __future__ import annotations

import ctypes
import functools
import threading

import numpy as np

__all__ = ["lowest_eigenpairs", "cholesky_solve", "lapack_routine", "LAPACK_LOCK"]

_c_int = ctypes.c_int

# One host LAPACK call at a time in this process (a multi-threaded OpenBLAS must not be entered
# twice at once from ``twist_study``'s two threads). Every caller of the dense path's LAPACK takes it.
LAPACK_LOCK = threading.Lock()


@functools.lru_cache(maxsize=None)
def lapack_routine(name, n_args):
    """SciPy's LAPACK routine ``name`` as a ctypes function of n_args pointers (None where the
    table does not have it with 32-bit integers)."""
    try:
        from scipy.linalg import cython_lapack

        capsule = cython_lapack.__pyx_capi__[name]
        get_name = ctypes.pythonapi.PyCapsule_GetName
        get_name.restype, get_name.argtypes = ctypes.c_char_p, [ctypes.py_object]
        get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
        get_pointer.restype, get_pointer.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
        signature = get_name(capsule)
        args = signature.decode().split("(", 1)[1].rsplit(")", 1)[0].split(",")
        # every argument a pointer; the integers 32-bit ("int *", not an ILP64 build's int64)
        if len(args) != n_args or any("int *" not in a and "char *" not in a and "_d *" not in a for a in args):
            return None
        pointer = get_pointer(capsule, signature)
        return ctypes.CFUNCTYPE(None, *([ctypes.c_void_p] * n_args))(pointer)
    except Exception:  # noqa: BLE001 -- any surprise: SciPy's own wrapper instead
        return None


@functools.lru_cache(maxsize=32)
def _syevr_workspace(n):
    """(lwork, liwork): dsyevr's optimal workspace for order n (its workspace query)."""
    f = lapack_routine("dsyevr", 21)
    work, iwork = np.zeros(1), np.zeros(1, np.int32)
    _call_syevr(f, np.zeros((n, n), order="F"), n, 1, np.zeros(n), np.zeros((n, 1), order="F"),
                np.zeros(2, np.int32), work, -1, iwork, -1)
    return max(int(work[0]), 26 * n, 1), max(int(iwork[0]), 10 * n, 1)


def _call_syevr(f, a, n, m, w, z, isuppz, work, lwork, iwork, liwork):
    ref = ctypes.byref
    jobz, rng, uplo = ctypes.c_char(b"V"), ctypes.c_char(b"I"), ctypes.c_char(b"L")
    vl, vu, abstol = ctypes.c_double(0.0), ctypes.c_double(1.0), ctypes.c_double(0.0)
    N, il, iu, found, info = _c_int(n), _c_int(1), _c_int(m), _c_int(0), _c_int(0)
    LW, LIW = _c_int(lwork), _c_int(liwork)
    ptr = lambda x: ctypes.c_void_p(x.ctypes.data)  # noqa: E731
    f(ref(jobz), ref(rng), ref(uplo), ref(N), ptr(a), ref(N), ref(vl), ref(vu), ref(il), ref(iu), ref(abstol),
      ref(found), ptr(w), ptr(z), ref(N), ptr(isuppz), ptr(work), ref(LW), ptr(iwork), ref(LIW), ref(info))
    return found.value, info.value


def lowest_eigenpairs(h, m):
    """(lam (m,), vec (n, m)): the m lowest eigenpairs of the symmetric h (n, n) (lower triangle
    read), ascending, as ``scipy.linalg.eigh(h, subset_by_index=[0, m - 1], driver="evr")`` gives
    them, with the GIL released."""
    h = np.asarray(h, dtype=np.float64)
    n = h.shape[0]
    f = lapack_routine("dsyevr", 21)
    if f is None or not 1 <= m <= n:
        import scipy.linalg

        return scipy.linalg.eigh(h, subset_by_index=[0, m - 1], driver="evr", check_finite=False)
    a = np.array(h, order="F")  # dsyevr overwrites it
    lwork, liwork = _syevr_workspace(n)
    w, z = np.empty(n), np.empty((n, m), order="F")
    found, info = _call_syevr(f, a, n, m, w, z, np.empty(2 * m, np.int32), np.empty(lwork), lwork,
                              np.empty(liwork, np.int32), liwork)
    if info != 0 or found != m:
        raise np.linalg.LinAlgError(f"LAPACK dsyevr failed (info {info}, {found} of {m} eigenvalues)")
    return w[:m], z


def cholesky_solve(h, b):
    """x (n,) with h x = b, for the symmetric positive definite h (n, n) (lower triangle read), by
    dpotrf and dpotrs as ``scipy.linalg.cho_solve(cho_factor(h, lower=True), b)``, with the GIL
    released; ``numpy.linalg.LinAlgError`` where h is not positive definite (as SciPy raises)."""
    h = np.asarray(h, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    n = h.shape[0]
    potrf, potrs = lapack_routine("dpotrf", 5), lapack_routine("dpotrs", 8)
    if potrf is None or potrs is None or b.shape != (n,):
        import scipy.linalg

        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(h, lower=True, check_finite=False), b, check_finite=False)
    ref = ctypes.byref
    ptr = lambda x: ctypes.c_void_p(x.ctypes.data)  # noqa: E731
    a, x = np.array(h, order="F"), np.array(b)
    uplo, N, one, info = ctypes.c_char(b"L"), _c_int(n), _c_int(1), _c_int(0)
    potrf(ref(uplo), ref(N), ptr(a), ref(N), ref(info))
    if info.value > 0:
        raise np.linalg.LinAlgError(f"{info.value}-th leading minor not positive definite")
    if info.value < 0:
        raise ValueError(f"LAPACK dpotrf: illegal value in argument {-info.value}")
    potrs(ref(uplo), ref(N), ref(one), ptr(a), ref(N), ptr(x), ref(N), ref(info))
    if info.value != 0:
        raise ValueError(f"LAPACK dpotrs: illegal value in argument {-info.value}")
    return x
