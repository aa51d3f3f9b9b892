"""O(N) linear algebra for block-tridiagonal (optionally cyclic) plus low-rank symmetric matrices.

Rod Hessians are block-tridiagonal (cyclic for closed rods) plus a few dense rank-one terms;
everything here costs O(K b^3 + n r^2) and never builds an n x n array.

The matrix is ::

    M = T + U diag(c) U^T          (n x n, n = K b)

* ``diag`` (K, b, b): the symmetric diagonal blocks ``T[k, k]``.
* ``off``  (K, b, b): ``off[k] = T[k, k+1]`` for k = 0..K-2.  If ``cyclic``, ``off[K-1] =
  T[K-1, 0]`` is the corner coupling (and ``T[0, K-1] = off[K-1]^T``); otherwise ``off[K-1]`` is
  ignored.  (For K = 2 cyclic, both couplings land on the same block pair and are added:
  ``T[1, 0] = off[0]^T + off[1]``.)
* ``U`` (n, r), ``c`` (r,): the low-rank term; ``c`` of either sign, r may be 0 (or pass None).

Public functions (all pure and jittable; ``cyclic``, ``k``, ``iterations``, ``block`` are static):
:func:`factor`, :func:`inertia`, :func:`solve`, :func:`matvec`, :func:`lowest_eigenpairs`.

Caveat (stability): there is no pivoting *across* blocks, so a nearly singular pivot block D_k
(possible for indefinite T) loses accuracy and an exactly singular one gives inf/nan; Woodbury and
the bordered solves go through T^{-1}, so accuracy follows T's (or T - sigma I's) condition number.
Nothing here checks: look at the residual (:func:`matvec`) if in doubt.
"""
from __future__ import annotations

import functools
from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jax import lax

__all__ = ["BlockFactor", "factor", "inertia", "solve", "matvec", "lowest_eigenpairs"]


class BlockFactor(NamedTuple):
    """Block LDL^T factorisation of a block-tridiagonal T (see :func:`factor`).

    The *chain* is the blocks eliminated in order: all K (Kc = K) when not cyclic, else blocks
    1..K-1 (Kc = K-1; block 0 is the border, eliminated last, chain index j = block j+1).

    In chain-then-border ordering T = F diag(D_0, ..., D_{Kc-1}, S) F^T, F = [[L, 0], [G^T, I]],
    with L unit block-lower-bidiagonal, D_j the Schur-complement pivot blocks and (cyclic only)
    G = D^{-1} L^{-1} E for the border columns E = T[chain, block 0], S = T[0, 0] - E^T T_chain^{-1} E.

    Fields:
        evals (Kc, b):   eigenvalues w_j of the pivot blocks D_j (their signs give the inertia).
        evecs (Kc, b, b): orthonormal eigenvectors Q_j, D_j = Q_j diag(w_j) Q_j^T.
        lower (Kc, b, b): L_j = T[j, j-1] D_{j-1}^{-1} (chain indices); lower[0] = 0.
        spike (Kc, b, b) or None: G_j (cyclic only).
        border_evals (b,), border_evecs (b, b) or None: eigen-decomposition of S (cyclic only).

    D^{-1} is always applied as Q (Q^T x / w), never as an explicit inverse (less backward stable).
    """

    evals: jax.Array
    evecs: jax.Array
    lower: jax.Array
    spike: Optional[jax.Array] = None
    border_evals: Optional[jax.Array] = None
    border_evecs: Optional[jax.Array] = None

    @property
    def cyclic(self) -> bool:
        return self.spike is not None

    @property
    def block_size(self) -> int:
        return self.evals.shape[-1]

    @property
    def num_blocks(self) -> int:
        return self.evals.shape[0] + (1 if self.cyclic else 0)

    @property
    def size(self) -> int:
        return self.num_blocks * self.block_size


def _sym(a):
    return 0.5 * (a + jnp.swapaxes(a, -1, -2))


def _apply_inv(w, q, x):
    """D^{-1} x for D = q diag(w) q^T; w (b,), q (b, b), x (b, m). eigh of the pivot block is
    backward stable for indefinite blocks and gives its inertia for free."""
    return q @ ((q.T @ x) / w[:, None])


def _lowrank(U, c, n, dtype):
    """Rescale the low-rank term to U~ diag(s) U~^T with U~ = U sqrt|c|, s = sign(c) in {-1, +1}.

    The signs make the Woodbury capacitance and the Haynsworth border both diag(s) + U~^T T^{-1} U~
    without any 1/c (so c = 0 is harmless: its column of U~ is zero and s = +1 decouples it).
    Returns (Ut (n, r), s (r,)); r = 0 when U is None.
    """
    if U is None or c is None or U.shape[-1] == 0:
        return jnp.zeros((n, 0), dtype), jnp.zeros((0,), dtype)
    U = jnp.asarray(U, dtype)
    c = jnp.asarray(c, dtype)
    s = jnp.where(c < 0, -1.0, 1.0).astype(dtype)
    return U * jnp.sqrt(jnp.abs(c))[None, :], s


def _chain_scan(A, Bsub, E=None):
    """Forward block elimination of a block-tridiagonal chain, optionally carrying a border spike.

    A (m, b, b) diagonal blocks; Bsub (m, b, b) sub-diagonal blocks Bsub[j] = T[j, j-1]
    (Bsub[0] must be zero); E (m, b, nb) or None: border columns T[j, border].
    Returns evals (m, b), evecs (m, b, b), lower (m, b, b), G (m, b, nb) = D^{-1} L^{-1} E and
    E^T T_chain^{-1} E = sum_j W_j^T D_j^{-1} W_j (nb, nb), where W = L^{-1} E.
    """
    m, b, _ = A.shape
    if E is None:
        E = jnp.zeros((m, b, 0), A.dtype)
    nb = E.shape[-1]

    def step(carry, xs):
        w_prev, q_prev, W_prev, acc = carry
        a, bsub, e = xs
        # L_j = T[j, j-1] D_{j-1}^{-1}; D_j = A_j - L_j T[j-1, j]  (Schur complement, symmetrised
        # so that eigh sees an exactly symmetric block despite round-off).
        lj = _apply_inv(w_prev, q_prev, bsub.T).T
        w, q = jnp.linalg.eigh(_sym(a - lj @ bsub.T))
        Wj = e - lj @ W_prev          # forward substitution of the border columns
        Gj = _apply_inv(w, q, Wj)
        return (w, q, Wj, acc + Wj.T @ Gj), (w, q, lj, Gj)

    # Starting carry D_{-1} = I is harmless because Bsub[0] = 0 makes L_0 = 0.
    eye = jnp.eye(b, dtype=A.dtype)
    init = (jnp.ones((b,), A.dtype), eye, jnp.zeros((b, nb), A.dtype), jnp.zeros((nb, nb), A.dtype))
    (_, _, _, acc), (w, q, L, G) = lax.scan(step, init, (A, Bsub, E))
    return w, q, L, G, acc


def _factor(diag, off, cyclic: bool) -> BlockFactor:
    diag = jnp.asarray(diag)
    dtype = jnp.result_type(diag.dtype, jnp.float64)
    diag = _sym(diag.astype(dtype))
    off = jnp.asarray(off, dtype)
    K, b, _ = diag.shape
    zero = jnp.zeros((1, b, b), dtype)
    offT = jnp.swapaxes(off, -1, -2)
    if not cyclic:
        Bsub = jnp.concatenate([zero, offT[: K - 1]], axis=0)  # T[k, k-1] = off[k-1]^T
        w, q, L, _, _ = _chain_scan(diag, Bsub)
        return BlockFactor(w, q, L)
    if K < 2:
        raise ValueError("cyclic factorisation needs at least 2 blocks")
    # Chain = blocks 1..K-1 (chain index j = block j+1); its sub-diagonal T[j+1, j] = off[j]^T.
    Bsub = jnp.concatenate([zero, offT[1 : K - 1]], axis=0)
    # Border columns T[block j+1, block 0]: T[1, 0] = off[0]^T, T[K-1, 0] = off[K-1].
    E = jnp.zeros((K - 1, b, b), dtype).at[0].add(offT[0]).at[K - 2].add(off[K - 1])
    w, q, L, G, acc = _chain_scan(diag[1:], Bsub, E)
    sw, sq = jnp.linalg.eigh(_sym(diag[0] - acc))
    return BlockFactor(w, q, L, G, sw, sq)


@functools.partial(jax.jit, static_argnames=("cyclic",))
def factor(diag, off, cyclic: bool = False) -> BlockFactor:
    """Block LDL^T factorisation of the symmetric block-tridiagonal T.

    Args:
        diag: (K, b, b) symmetric diagonal blocks (symmetrised here).
        off: (K, b, b), off[k] = T[k, k+1]; off[K-1] = T[K-1, 0] if cyclic, else ignored.
        cyclic: static; closed chain with a corner coupling.

    Returns:
        :class:`BlockFactor`.  Cyclic: blocks 1..K-1 are eliminated as a chain with block 0 as a
        border carried along as a dense spike, then block 0's b x b Schur complement is
        decomposed.  O(K b^3), one ``lax.scan``; no pivoting across blocks.
    """
    return _factor(diag, off, cyclic)


def _forward(fac: BlockFactor, R):
    """Y = F^{-1} R (the unit-triangular half of T = F diag(D, S) F^T); R, Y (K, b, m). Layout is
    the natural block order (for cyclic, Y[0] is the border block).  One scan."""
    L = fac.lower
    m = R.shape[-1]
    if fac.cyclic:
        r_border, R = R[0], R[1:]
        G = fac.spike
    else:
        G = jnp.zeros(L.shape[:2] + (0,), R.dtype)

    # y_j = r_j - L_j y_{j-1}; the border row accumulates t = sum_j G_j^T y_j.
    def fwd(carry, xs):
        y_prev, t = carry
        r, lj, gj = xs
        y = r - lj @ y_prev
        return (y, t + gj.T @ y), y

    init = (jnp.zeros(R.shape[1:], R.dtype), jnp.zeros((G.shape[-1], m), R.dtype))
    (_, t), Y = lax.scan(fwd, init, (R, L, G))
    if fac.cyclic:
        Y = jnp.concatenate([(r_border - t)[None], Y], axis=0)
    return Y


def _backward(fac: BlockFactor, Y):
    """X = F^{-T} diag(D, S)^{-1} Y, so T^{-1} R = _backward(_forward(R)); (K, b, m).  One scan."""
    w, q, L = fac.evals, fac.evecs, fac.lower
    m = Y.shape[-1]
    if fac.cyclic:
        x_border = _apply_inv(fac.border_evals, fac.border_evecs, Y[0])
        Y = Y[1:]
        G = fac.spike
    else:
        x_border = jnp.zeros((0, m), Y.dtype)
        G = jnp.zeros(L.shape[:2] + (0,), Y.dtype)

    # x_j = D_j^{-1} y_j - G_j x_border - L_{j+1}^T x_{j+1}.
    Lnext = jnp.concatenate([L[1:], jnp.zeros_like(L[:1])], axis=0)

    def bwd(x_next, xs):
        y, ln, wj, qj, gj = xs
        x = _apply_inv(wj, qj, y) - gj @ x_border - ln.T @ x_next
        return x, x

    _, X = lax.scan(bwd, jnp.zeros(Y.shape[1:], Y.dtype), (Y, Lnext, w, q, G), reverse=True)
    if fac.cyclic:
        X = jnp.concatenate([x_border[None], X], axis=0)
    return X


def _dquad(fac: BlockFactor, Y1, Y2):
    """Y1^T diag(D, S)^{-1} Y2 for Y1 (K, b, m1), Y2 (K, b, m2) from :func:`_forward`; (m1, m2).
    With Y = F^{-1} V this is V1^T T^{-1} V2 from the forward sweep alone, as a sum of small block
    products (batched, no scan) -- and exactly symmetric in structure when V1 = V2."""
    w, q = fac.evals, fac.evecs
    if fac.cyclic:
        w = jnp.concatenate([fac.border_evals[None], w], axis=0)
        q = jnp.concatenate([fac.border_evecs[None], q], axis=0)
    A1 = jnp.einsum("kji,kjm->kim", q, Y1)
    A2 = jnp.einsum("kji,kjm->kim", q, Y2) / w[:, :, None]
    return jnp.einsum("kim,kil->ml", A1, A2)


def _as_blocks(b, rhs):
    """(n,) or (n, m) -> (K, b, m) and a function undoing it."""
    vec = rhs.ndim == 1
    R = rhs[:, None] if vec else rhs
    K = R.shape[0] // b
    R = R.reshape(K, b, R.shape[1])

    def back(X):
        X = X.reshape(K * b, X.shape[-1])
        return X[:, 0] if vec else X

    return R, back


class _Bordered(NamedTuple):
    """Precomputed data for solving [[T, V], [V^T, E]] [x; q] = [r; 0] by block elimination."""

    fac: BlockFactor
    YV: jax.Array       # (K, b, p) F^{-1} V, V the (n, p) border columns
    cap_lu: tuple       # LU (with pivoting) of the capacitance V^T T^{-1} V - E  (p, p)


def _bordered_setup(fac, V, E):
    YV, _ = _as_blocks(fac.block_size, V)
    YV = _forward(fac, YV)
    cap = _sym(_dquad(fac, YV, YV) - E)
    return _Bordered(fac, YV, jsl.lu_factor(cap))


def _bordered_solve(bd: _Bordered, X):
    """x for [[T, V], [V^T, E]] [x; q] = [X; 0], X (n, m). q = cap^{-1} V^T T^{-1} X and x =
    T^{-1}(X - V q); since F^{-1} is linear, x is one backward sweep of F^{-1}X - (F^{-1}V) q, so
    each solve costs one forward and one backward sweep."""
    YX, back = _as_blocks(bd.fac.block_size, X)
    YX = _forward(bd.fac, YX)
    if bd.YV.shape[-1] > 0:
        q = jsl.lu_solve(bd.cap_lu, _dquad(bd.fac, bd.YV, YX))
        YX = YX - jnp.einsum("kip,pm->kim", bd.YV, q)
    return back(_backward(bd.fac, YX))


def _tinertia_neg(fac: BlockFactor):
    neg = jnp.sum(fac.evals < 0)
    if fac.cyclic:
        neg = neg + jnp.sum(fac.border_evals < 0)
    return neg


@jax.jit
def inertia(fac: BlockFactor, U=None, c=None):
    """Inertia of M = T + U diag(c) U^T from the factorisation of T.

    Args:
        fac: :func:`factor` of T.
        U: (n, r) or None; c: (r,) or None.

    Returns:
        (n_negative, n_positive), int32 scalars, n_negative + n_positive = n.

    In(T) is the sum of the pivot blocks' inertias (Sylvester).  For the low-rank term, with
    U~ = U sqrt|c| and s = sign(c), the Haynsworth identity on [[T, U~], [U~^T, -diag(s)]] gives
    neg(M) = neg(T) + #{eig(diag(s) + U~^T T^{-1} U~) > 0} - #{s > 0}. An exactly zero eigenvalue
    counts as positive. Costs one forward sweep with r columns.
    """
    n = fac.size
    dtype = fac.evals.dtype
    neg = _tinertia_neg(fac)
    Ut, s = _lowrank(U, c, n, dtype)
    if Ut.shape[1] > 0:
        # U~^T T^{-1} U~ needs only the forward sweep: (F^{-1}U~)^T diag(D, S)^{-1} (F^{-1}U~).
        Y = _forward(fac, _as_blocks(fac.block_size, Ut)[0])
        cap = _sym(jnp.diag(s) + _dquad(fac, Y, Y))
        neg = neg + jnp.sum(jnp.linalg.eigvalsh(cap) > 0) - jnp.sum(s > 0)
    neg = neg.astype(jnp.int32)
    return neg, (jnp.int32(n) - neg).astype(jnp.int32)


@jax.jit
def solve(fac: BlockFactor, rhs, U=None, c=None):
    """M^{-1} rhs for M = T + U diag(c) U^T.

    Args:
        fac: :func:`factor` of T.
        rhs: (n,) or (n, m).
        U: (n, r) or None; c: (r,) or None.

    Returns:
        Array shaped like rhs.  The low-rank term goes through Woodbury,
        M^{-1} = T^{-1} - T^{-1} U~ (diag(s) + U~^T T^{-1} U~)^{-1} U~^T T^{-1}
        (U~ = U sqrt|c|, s = sign(c)); the r x r capacitance is LU-factorised with pivoting.
    """
    n = fac.size
    rhs = jnp.asarray(rhs, fac.evals.dtype)
    Ut, s = _lowrank(U, c, n, rhs.dtype)
    R, back = _as_blocks(fac.block_size, rhs)
    m, r = R.shape[-1], Ut.shape[1]
    if r == 0:
        return back(_backward(fac, _forward(fac, R)))
    # Woodbury as the bordered system [[T, U~], [U~^T, -diag(s)]]: rhs and U~ share one forward
    # sweep, and the correction is applied before the single backward sweep (F^{-1} is linear).
    Y = _forward(fac, jnp.concatenate([R, _as_blocks(fac.block_size, Ut)[0]], axis=-1))
    YR, YU = Y[..., :m], Y[..., m:]
    cap = _sym(jnp.diag(s) + _dquad(fac, YU, YU))
    q = jnp.linalg.solve(cap, _dquad(fac, YU, YR))
    return back(_backward(fac, YR - jnp.einsum("kir,rm->kim", YU, q)))


def _matvec_T(diag, off, cyclic, V):
    """T V for V (K, b, m) without forming T; pure batched block products, no scan needed."""
    K = diag.shape[0]
    if not cyclic:
        off = off.at[K - 1].set(0.0)  # no corner coupling: wrap-around terms vanish
    # T[k, k+1] v_{k+1} and T[k, k-1] v_{k-1} = off[k-1]^T v_{k-1}, block index modulo K.
    up = jnp.einsum("kij,kjm->kim", off, jnp.roll(V, -1, axis=0))
    down = jnp.einsum("kji,kjm->kim", jnp.roll(off, 1, axis=0), jnp.roll(V, 1, axis=0))
    return jnp.einsum("kij,kjm->kim", diag, V) + up + down


@functools.partial(jax.jit, static_argnames=("cyclic",))
def matvec(diag, off, cyclic: bool, v, U=None, c=None):
    """M v for M = T + U diag(c) U^T, without forming M.

    Args:
        diag: (K, b, b); off: (K, b, b) (see module docstring); cyclic: static.
        v: (n,) or (n, m).
        U: (n, r) or None; c: (r,) or None.

    Returns:
        Array shaped like v.  ``diag`` is used as given (not symmetrised).
    """
    diag = jnp.asarray(diag)
    dtype = jnp.result_type(diag.dtype, jnp.float64)
    diag = diag.astype(dtype)
    off = jnp.asarray(off, dtype)
    v = jnp.asarray(v, dtype)
    R, back = _as_blocks(diag.shape[-1], v)
    out = back(_matvec_T(diag, off, cyclic, R))
    if U is not None and c is not None and U.shape[-1] > 0:
        U = jnp.asarray(U, dtype)
        c = jnp.asarray(c, dtype)
        vv = v[:, None] if v.ndim == 1 else v
        lr = U @ (c[:, None] * (U.T @ vv))
        out = out + (lr[:, 0] if v.ndim == 1 else lr)
    return out


def _norm_bound(diag, off, cyclic, Ut):
    """Cheap upper bound on ||M||_2: max block-row sum of block Frobenius norms + sum ||u~_i||^2.
    For symmetric block matrices ||T||_2 <= max_i sum_j ||T_ij||_2 (Schur test on block norms). Used
    only to make the residual tolerance relative."""
    K = diag.shape[0]
    if not cyclic:
        off = off.at[K - 1].set(0.0)
    fd = jnp.sqrt(jnp.sum(diag**2, axis=(1, 2)))
    fo = jnp.sqrt(jnp.sum(off**2, axis=(1, 2)))
    bound = jnp.max(fd + fo + jnp.roll(fo, 1))
    return bound + jnp.sum(Ut**2)


def _eig_inputs(diag, off, Z):
    """(diag symmetrised, off, Z (n, z), dtype) in at least float64; Z None: no columns."""
    diag = jnp.asarray(diag)
    dtype = jnp.result_type(diag.dtype, jnp.float64)
    diag = _sym(diag.astype(dtype))
    n = diag.shape[0] * diag.shape[1]
    Z = jnp.zeros((n, 0), dtype) if Z is None else jnp.asarray(Z, dtype)
    return diag, jnp.asarray(off, dtype), Z, dtype


def _shift_invert(diag, off, cyclic, sigma, Ut, s, Z):
    """The bordered solver of [[M - sigma I, Z], [Z^T, 0]]: the shifted factorisation of T and the
    (r + z)-column border [U~, Z] with E = blockdiag(-diag(s), 0)."""
    b = diag.shape[-1]
    r, z = Ut.shape[1], Z.shape[1]
    fac = _factor(diag - sigma * jnp.eye(b, dtype=diag.dtype), off, cyclic)
    V = jnp.concatenate([Ut, Z], axis=1)
    E = jnp.zeros((r + z, r + z), diag.dtype).at[:r, :r].set(-jnp.diag(s))
    return _bordered_setup(fac, V, E)


def _start_block(n, p, dtype, X0):
    """(n, p) fixed pseudo-random starting block (a sine hash: cheaper to compile than jax.random),
    its first columns replaced by X0 if given."""
    i = jnp.arange(n, dtype=dtype)[:, None]
    j = jnp.arange(p, dtype=dtype)[None, :]
    h = jnp.sin(12.9898 * i + 78.233 * j + 1.0) * 43758.5453
    start = h - jnp.floor(h) - 0.5
    if X0 is not None:
        X0 = jnp.asarray(X0, dtype)
        start = start.at[:, : X0.shape[1]].set(X0)
    return start


@functools.partial(jax.jit, static_argnames=("cyclic", "k", "iterations", "block"))
def lowest_eigenpairs(diag, off, cyclic: bool, U, c, Z, k: int, sigma, iterations: int = 200,
                      X0=None, tol=1e-12, block: Optional[int] = None):
    """The k eigenpairs of A = P M P on range(P) = Z-perp closest to (and above) the shift sigma.

    Shift-invert subspace iteration with Rayleigh-Ritz: each step solves [[M - sigma I, Z],
    [Z^T, 0]] [x; y] = [v; 0] by the block factorisation of T - sigma I with [U~, Z] as one border.

    Args:
        diag, off, cyclic: T (see module docstring); cyclic static.
        U: (n, r) or None; c: (r,) or None.
        Z: (n, z) orthonormal columns (z may be 0) or None.
        k: static, number of eigenpairs wanted.
        sigma: scalar shift below the wanted eigenvalues (it converges to the k nearest sigma);
            not an eigenvalue of T or A. Pair i converges by |lam_i - sigma| / |lam_{block+1} -
            sigma| per step, so a close sigma converges faster.
        iterations: static, maximum number of inverse steps.
        X0: optional (n, k') starting block (k' <= block); padded with fixed pseudo-random columns.
        tol: stop once every wanted residual ||A x - theta x|| <= tol * ||M|| (cheap bound).
        block: static subspace size, default min(k + 4, n - z).

    Returns:
        (eigenvalues (k,) ascending, eigenvectors (n, k) orthonormal and orthogonal to Z,
        residual norms (k,) ||A x - theta x||); unconverged results are returned as they are.
    """
    diag, off, Z, dtype = _eig_inputs(diag, off, Z)
    K, b, _ = diag.shape
    n = K * b
    z = Z.shape[1]
    p = block if block is not None else min(k + 4, n - z)
    if not k <= p <= n - z:
        raise ValueError(f"need k <= block <= n - z, got k={k}, block={p}, n-z={n - z}")
    sigma = jnp.asarray(sigma, dtype)
    Ut, s = _lowrank(U, c, n, dtype)
    bd = _shift_invert(diag, off, cyclic, sigma, Ut, s, Z)

    def project(X):
        # Twice, so that X stays orthogonal to Z to working precision.
        X = X - Z @ (Z.T @ X)
        return X - Z @ (Z.T @ X)

    def apply_A(X):  # P M P X for X already orthogonal to Z
        return project(matvec(diag, off, cyclic, X, Ut, s))

    thresh = tol * _norm_bound(diag, off, cyclic, Ut)

    X, _ = jnp.linalg.qr(project(_start_block(n, p, dtype, X0)))

    def rayleigh_ritz(Y):
        Y, _ = jnp.linalg.qr(project(Y))
        AY = apply_A(Y)
        theta, G = jnp.linalg.eigh(_sym(Y.T @ AY))
        # Keep the Ritz values nearest the shift first (== ascending when sigma lies below them).
        order = jnp.argsort(jnp.abs(theta - sigma))
        theta, G = theta[order], G[:, order]
        X = Y @ G
        res = jnp.linalg.norm(AY @ G - X * theta[None, :], axis=0)
        return X, theta, res

    def cond(state):
        it, _, _, res = state
        return (it < iterations) & (jnp.max(res[:k]) > thresh)

    def body(state):
        it, X, _, _ = state
        X, theta, res = rayleigh_ritz(_bordered_solve(bd, X))
        return it + 1, X, theta, res

    X, theta, res = rayleigh_ritz(X)
    _, X, theta, res = lax.while_loop(cond, body, (jnp.int32(0), X, theta, res))

    theta, X, res = theta[:k], X[:, :k], res[:k]
    order = jnp.argsort(theta)
    return theta[order], X[:, order], res[order]
