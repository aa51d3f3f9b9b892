"""Material sliding of a knot's near-null modes: how far a mode is from strands slipping along
the centreline, and the slide split off a span of eigenvectors (the eigenvalue band that the
stability analyses keep for loose knots' sliding modes)."""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .tolerances import scaled_negative_tol

__all__ = ["SLIDING_FRACTION", "CLEAN_SLIDE_FRACTION", "sliding_fields", "sliding_fraction", "split_slide",
           "without_slide", "band_shape_modes", "shape_modes_in_band"]


# A mode counts as material sliding when less than this fraction of it (squared norm, scaled
# DOFs) is left once tangential node motions and a rigid motion are fitted to it: measured on the
# trefoil at N = 61 (0 ... 3 pi), the near-null sliding mode leaves < 1e-3, every shape mode >= 0.37
# and twist-only modes ~1.
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
    """How far each mode is from material sliding along the centreline: (m,) fractions in [0, 1]
    for the modes ``vectors`` (n, m) in scaled DOFs at the state ``q`` (physical DOFs) of a rod.

    A loose knot's near-null modes move material along its own centreline (strands slipping):
    node i moves by alpha_i t_i (t_i its tangent), plus a rigid motion a + w x x_i (projected out of
    the modes, but a slide along a torus knot is mostly a rotation about its axis). The fraction is
    what is left of the mode once the best such field is subtracted from its node motions,
    counting its twist-angle part as left over too: ~0 for sliding, O(1) for a mode that changes
    the shape (a buckling mode) or only the twist. Rods whose nodes are all free (closed and free
    rods: tangents by central differences, one-sided at open ends); a clamped rod cannot slide."""
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
# this clean (a pure slide leaves < 1e-3, see SLIDING_FRACTION) and near-null (inside the band kept
# for the sliding modes): on the trefoil's buckled+ branch at N = 121 the direction of least
# sliding in the span mixed the slide with a mode at 2.3e-6 and with the buckling mode crossing
# zero at +7.041 pi, and splitting it off took the crossing with it.
CLEAN_SLIDE_FRACTION = 5e-3


def split_slide(scene, q, values, vectors, threshold=SLIDING_FRACTION, max_value=None):
    """Split the material-sliding direction off the span of a knot's lowest eigenvectors.

    values (m,), vectors (n, m) orthonormal, in the rod's scaled DOFs (all of them; a pinned
    problem embeds its free DOFs first: ``jaxrod.continuation.arclength.rods.split_sliding``); q: the state.
    The sliding fraction (``sliding_fraction``: 0 for a pure slide of the material along the
    centreline, O(1) for a change of shape) is a quadratic form; its minimiser within the span is
    the slide, whatever the mixing of nearly degenerate eigenvectors (next to a crossing or a fold
    the critical mode and the slide are both near zero and their eigenvectors mix: on the trefoil
    at N = 121, 0.004 pi before its tightening branch point, the lowest eigenvector was half slide,
    half buckling mode). If its fraction is below ``threshold`` it is one soft direction, with its
    Rayleigh quotient, and the rest of the span are Ritz pairs (ascending with it).
    max_value: a slide is near-null; a direction whose Rayleigh quotient exceeds this in modulus is
    not split off (None: no bound).
    Returns (values (m,), coefficients C (m, m): the new vectors are ``vectors @ C``, soft (m,)
    bool: the slide); the input unchanged (C = I, no soft direction) when nothing slides."""
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
    shape and lie in the near-zero band [-negative_tol, -strict_tol) kept for the sliding modes of
    loose knots: its computed eigenpairs with the slide split off their span first
    (``split_slide``), so that a buckling mode mixed with the slide next to its crossing is judged
    by its own eigenvalue, then each remaining direction whose sliding fraction is above
    SLIDING_FRACTION (see ``shape_modes_in_band``). Empty arrays without a band."""
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
    in the near-zero band [-negative_tol, -strict_tol) kept for the sliding modes of loose knots,
    but which do not slide (``sliding_fraction`` above SLIDING_FRACTION): negative eigenvalues of
    shape-changing modes that the band counts as zero (on the trefoil at N = 481 a pair crossing zero
    at -11.09 pi stayed inside the band down to -12.18 pi). Empty without a band. strict_tol:
    default ``tolerances.scaled_negative_tol(scene)``, 1e-10 up to N ~ 600 and falling as N^-4
    beyond, with the shape modes themselves (the trefoil's sit at ~3e-9 at N = 961, where a fixed
    1e-10 would let a shape mode crossing zero at ~3e-9 per rad pass unseen for ~0.01 pi)."""
    values, fractions, _ = band_shape_modes(scene, e, negative_tol, strict_tol)
    return [(float(v), float(f)) for v, f in zip(values, fractions)]
