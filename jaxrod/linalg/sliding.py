"""Material sliding of a knot's near-null modes: how far a mode is from strands slipping along
the centreline, and the slide split off a span of eigenvectors (the eigenvalue band that the
stability analyses keep for loose knots' sliding modes)."""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .tolerances import scaled_negative_tol

__all__ = ["SLIDING_FRACTION", "CLEAN_SLIDE_FRACTION", "sliding_fields", "sliding_fraction", "split_slide",
           "without_slide", "band_shape_modes", "shape_modes_in_band"]


# A mode counts as material sliding when less than this fraction of it (squared norm, scaled DOFs)
# is left once tangential node motions and a rigid motion are fitted to it (sliding modes leave
# < 1e-3, shape modes >= ~0.4, twist-only modes ~1).
SLIDING_FRACTION = 0.05


def sliding_fields(scene, q):
    """(perp (n, 3, 3), rigid (3n, 6)) at the state q of a rod whose nodes are all free: perp[i]
    takes out the motion along node i's tangent (central differences, one-sided at open ends) and
    rigid holds the 6 rigid motions with that part taken out. A field of node motions slides
    (``sliding_fraction``) when its perp part is a combination of rigid's columns."""
    n = int(scene.n_nodes)
    if int(scene.n_free_nodes) != n:
        raise ValueError("sliding_fraction: the rod must have all its nodes free (a closed or free rod)")
    x = np.asarray(scene.unpack(jnp.asarray(q), 0.0)[0])
    closed = bool(getattr(scene, "closed", True))
    t = np.roll(x, -1, axis=0) - np.roll(x, 1, axis=0)
    if not closed:
        t[0], t[-1] = x[1] - x[0], x[-1] - x[-2]
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    xc = x - x.mean(axis=0)
    perp = np.eye(3)[None] - t[:, :, None] * t[:, None, :]             # (n, 3, 3): off the tangent
    skew = np.zeros((n, 3, 3))                                            # skew[i] w = x_i x w
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -xc[:, 2], xc[:, 1], -xc[:, 0]
    skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = xc[:, 2], -xc[:, 1], xc[:, 0]
    rigid = np.concatenate([perp, np.einsum("nij,njk->nik", perp, skew)], axis=2).reshape(3 * n, 6)
    return perp, rigid


def sliding_fraction(scene, q, vectors):
    """How far each mode is from material sliding along the centreline: (m,) fractions in [0, 1] for
    the modes ``vectors`` (n, m) in scaled DOFs at the state ``q`` (physical DOFs) of a rod. A loose
    knot's near-null modes move material along its own centreline: node i moves by alpha_i t_i plus
    a rigid motion a + w x x_i. The fraction is what is left of the mode once the best such field is
    subtracted from its node motions, its twist-angle part counted as left over too: ~0 for sliding,
    O(1) for a shape or twist mode. Rods whose nodes are all free only."""
    vec = np.asarray(vectors, dtype=float)
    if vec.ndim == 1:
        vec = vec[:, None]
    n = int(scene.n_nodes)
    perp, rigid = sliding_fields(scene, q)
    out = np.empty(vec.shape[1])
    for j in range(vec.shape[1]):
        v = vec[:, j]
        dx = v[:3 * n].reshape(n, 3)  # node coordinates first, then the twist angles
        b = np.einsum("nij,nj->ni", perp, dx).reshape(3 * n)
        coef, *_ = np.linalg.lstsq(rigid, b, rcond=None)
        moved = float(np.sum(v[:3 * n] ** 2))
        total = float(np.sum(v ** 2))
        out[j] = (float(np.sum((b - rigid @ coef) ** 2)) + (total - moved)) / total if total > 0.0 else 0.0
    return out


# The stable-only engine splits a slide off its computed eigenpairs only when the span holds one
# this clean (a pure slide leaves < 1e-3) and near-null: a less clean one can carry a crossing
# shape mode with it.
CLEAN_SLIDE_FRACTION = 5e-3


def split_slide(scene, q, values, vectors, threshold=SLIDING_FRACTION, max_value=None):
    """Split the material-sliding direction off the span of a knot's lowest eigenvectors. values
    (m,), vectors (n, m) orthonormal, in the rod's scaled DOFs (a pinned problem embeds its free
    DOFs first: ``jaxrod.continuation.arclength.rods.split_sliding``); q: the state. The sliding
    fraction is a quadratic form whose minimiser within the span is the slide, however nearly
    degenerate eigenvectors mix. If its fraction is below ``threshold`` (and its Rayleigh quotient
    within +-``max_value``, None: no bound) it is one soft direction and the rest of the span Ritz
    pairs. Returns (values (m,) ascending, coefficients C (m, m): the new vectors are ``vectors @
    C``, soft (m,) bool); the input unchanged (C = I, none soft) when nothing slides."""
    V = np.asarray(vectors, dtype=float)
    lam = np.asarray(values, dtype=float)
    m = lam.size
    n = int(scene.n_nodes)
    perp, rigid = sliding_fields(scene, q)
    # the part of each vector's node motion that is no slide: off the tangents, rigid motions out
    B = np.einsum("nij,njm->nim", perp, V[:3 * n].reshape(n, 3, -1)).reshape(3 * n, -1)
    basis, _ = np.linalg.qr(rigid)
    B -= basis @ (basis.T @ B)
    ft = V[3 * n:]
    G = B.T @ B + ft.T @ ft  # (m, m): the fraction's numerator on the span (V orthonormal)
    g, C = np.linalg.eigh(0.5 * (G + G.T))
    if m == 0 or g[0] >= threshold:
        return lam, np.eye(m), np.zeros(m, dtype=bool)
    c, rest = C[:, 0], C[:, 1:]
    if max_value is not None and abs(float(c @ (lam * c))) > max_value:
        return lam, np.eye(m), np.zeros(m, dtype=bool)
    K = rest.T @ (lam[:, None] * rest)
    ritz, R = np.linalg.eigh(0.5 * (K + K.T))
    vals = np.concatenate([[float(c @ (lam * c))], ritz])
    coef = np.concatenate([c[:, None], rest @ R], axis=1)
    order = np.argsort(vals, kind="stable")
    soft = np.zeros(m, dtype=bool)
    soft[0] = True
    return vals[order], coef[:, order], soft[order]


def without_slide(scene, q, values, vectors, band):
    """The computed eigenpairs (values (m,), vectors (n, m)) of a knot at q with a clean, near-null
    slide (fraction below CLEAN_SLIDE_FRACTION, Rayleigh quotient within +-band) split off their
    span: (values (m'), vectors (n, m')) of the rest, Ritz pairs ascending; unchanged where nothing
    slides so, or where the rod has clamped nodes (it cannot slide)."""
    lam, vec = np.asarray(values, dtype=float), np.asarray(vectors, dtype=float)
    if not lam.size or int(scene.n_free_nodes) != int(scene.n_nodes):
        return lam, vec
    vals, coef, soft = split_slide(scene, q, lam, vec, CLEAN_SLIDE_FRACTION, band)
    return vals[~soft], (vec @ coef)[:, ~soft]


def band_shape_modes(scene, e, negative_tol, strict_tol=None):
    """(values (k,), fractions (k,), vectors (n, k)) of the equilibrium e's modes that change the
    shape and lie in the near-zero band [-negative_tol, -strict_tol) kept for loose knots' sliding
    modes: the slide is split off the computed span first (``split_slide``), so a buckling mode
    mixed with it is judged by its own eigenvalue, then each remaining direction whose sliding
    fraction is above SLIDING_FRACTION is kept. Empty arrays without a band."""
    if strict_tol is None:
        strict_tol = scaled_negative_tol(scene)
    lam = np.asarray(e.stability.eigenvalues)
    vec = np.asarray(e.stability.eigenvectors)
    empty = (np.zeros(0), np.zeros(0), np.zeros((vec.shape[0], 0)))
    if not np.any((lam >= -negative_tol) & (lam < -strict_tol)) or int(scene.n_free_nodes) != int(scene.n_nodes):
        return empty
    vals, vecs = without_slide(scene, e.q, lam, vec, negative_tol)
    band = np.nonzero((vals >= -negative_tol) & (vals < -strict_tol))[0]
    if band.size == 0:
        return empty
    frac = sliding_fraction(scene, e.q, vecs[:, band])
    keep = frac > SLIDING_FRACTION
    return vals[band][keep], frac[keep], vecs[:, band][:, keep]


def shape_modes_in_band(scene, e, negative_tol, strict_tol=None):
    """[(eigenvalue, sliding fraction)] of the equilibrium e's computed modes whose eigenvalue lies
    in the near-zero band [-negative_tol, -strict_tol) kept for loose knots' sliding modes but
    which do not slide (``band_shape_modes``): negative eigenvalues of shape-changing modes that
    the band counts as zero. Empty without a band. strict_tol: default
    ``tolerances.scaled_negative_tol(scene)``."""
    values, fractions, _ = band_shape_modes(scene, e, negative_tol, strict_tol)
    return [(float(v), float(f)) for v, f in zip(values, fractions)]
