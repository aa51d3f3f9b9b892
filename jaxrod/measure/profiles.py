"""Shape descriptors of a closed curve's periodic profile (e.g. ``RodAnalysis.kappa``): the
dominant Fourier harmonic (``symmetry_order``) and the prominent maxima (``count_peaks``); and the
m-fold pattern of a mode of the curve (``mode_pattern``)."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["count_peaks", "symmetry_order", "mode_pattern"]

_MIN_PROFILE = 8


def _check_profile(kappa):
    """1-D finite float array of length >= 8, else ValueError naming ``kappa``."""
    try:
        k = np.asarray(kappa, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("kappa: could not be read as an array of numbers") from None
    if k.ndim != 1:
        raise ValueError(f"kappa: must be a 1-D array (one value per node), got shape {k.shape}")
    if k.size < _MIN_PROFILE:
        raise ValueError(f"kappa: at least {_MIN_PROFILE} samples are needed, got {k.size}")
    if not np.all(np.isfinite(k)):
        bad = np.flatnonzero(~np.isfinite(k))
        shown = ", ".join(str(i) for i in bad[:5]) + (", ..." if bad.size > 5 else "")
        raise ValueError(f"kappa: non-finite values (nan or inf) at {bad.size} index(es) {shown}")
    return k


def symmetry_order(kappa, max_order=8):
    """Dominant harmonic of a periodic profile: the m in 1..max_order for which the Fourier
    amplitude |sum_i (kappa_i - mean) exp(-2 pi i m j/n)| is largest.

    ``kappa`` (n,) is sampled at equal arc length round a closed curve (as ``RodAnalysis.kappa``,
    ``.tau``, ...). A profile with m-fold rotational symmetry (period L/m) only has harmonics that
    are multiples of m, and for a bump-like profile the lowest of them dominates: a symmetric
    trefoil gives 3, a profile with 4 equal bumps 4. Harmonics above the Nyquist limit n//2 are
    aliases and are not considered (``max_order`` is capped at n//2). Ties go to the smaller m.

    Returns 0 for a constant profile (all amplitudes below 1e-12 of the profile's magnitude: no
    dominant harmonic, e.g. the curvature of a circle).

    Raises ValueError (naming ``kappa``) for an input that is not 1-D, has fewer than 8 samples or
    non-finite values, and (naming ``max_order``) for a max_order that is not an integer >= 1.
    """
    k = _check_profile(kappa)
    try:
        integral = not isinstance(max_order, bool) and int(max_order) == max_order
    except (TypeError, ValueError):
        integral = False
    if not integral or int(max_order) < 1:
        raise ValueError(f"max_order must be an integer >= 1, got {max_order!r}")
    top = min(int(max_order), k.size // 2)
    amp = np.abs(np.fft.rfft(k - k.mean()))[1: top + 1]
    scale = max(float(np.max(np.abs(k))), np.finfo(float).tiny) * k.size
    if np.max(amp) <= 1e-12 * scale:
        return 0
    return int(np.argmax(amp)) + 1


def count_peaks(kappa, prominence=0.1):
    """Number of local maxima of a periodic profile whose prominence exceeds
    ``prominence * (max(kappa) - min(kappa))``.

    ``kappa`` (n,) is sampled round a closed curve (the last sample is followed by the first).
    The profile is rotated to start at its global minimum and that minimum is appended at the end,
    so that :func:`scipy.signal.find_peaks` sees every maximum once, including one across the
    wrap, with its periodic prominence (the highest maximum gets max - min). A plateau counts once.
    Returns 0 for a constant profile.

    Raises ValueError (naming ``kappa``) for an input that is not 1-D, has fewer than 8 samples or
    non-finite values, and (naming ``prominence``) for a negative or non-finite prominence.
    """
    from scipy.signal import find_peaks

    k = _check_profile(kappa)
    try:
        frac = float(prominence)
    except (TypeError, ValueError):
        frac = float("nan")
    if isinstance(prominence, bool) or not math.isfinite(frac) or frac < 0.0:
        raise ValueError(f"prominence must be a finite number >= 0, got {prominence!r}")
    span = float(np.max(k) - np.min(k))
    if span == 0.0:
        return 0
    start = int(np.argmin(k))
    wrapped = np.concatenate([np.roll(k, -start), k[start: start + 1]])
    _, props = find_peaks(wrapped, prominence=0.0)
    return int(np.count_nonzero(props["prominences"] > frac * span))


def _curvature_binormal(x):
    """Discrete curvature binormal at each node of the closed polygon x (N, 3), (N, 3): the discrete
    elastic rod's (``geometry.curvature_binormals``) over the mean length of the two edges, and the
    node tangent (N, 3)."""
    from ..model.geometry import curvature_binormals  # noqa: PLC0415  (jax loads only where this is used)

    e = np.roll(x, -1, axis=0) - x
    prev = np.roll(e, 1, axis=0)
    la, lb = np.linalg.norm(prev, axis=1), np.linalg.norm(e, axis=1)
    kb = np.asarray(curvature_binormals(prev, e))
    tangent = prev / la[:, None] + e / lb[:, None]
    return kb / (0.5 * (la + lb))[:, None], tangent / np.linalg.norm(tangent, axis=1)[:, None]


def mode_pattern(x, dx, max_order=8):
    """The m-fold pattern of a mode dx (N, 3) of the closed polygon x (N, 3): the dominant harmonic
    (``symmetry_order``) of how the mode bends the curve. The change of the curvature binormal,
    d(kappa b)_i / d epsilon at x + epsilon dx (central differences), is split along the curve's
    own normal and binormal; the larger of the two signed profiles is analysed. A mode that keeps
    a knot's three-fold symmetry gives 3 (or a multiple); Michell's ring buckles with 2."""
    x, dx = np.asarray(x, dtype=float), np.asarray(dx, dtype=float)
    if x.shape != dx.shape or x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"x and dx must both be (N, 3) arrays, got {x.shape} and {dx.shape}")
    size = float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1)))
    eps = 1e-6 * size / max(float(np.max(np.linalg.norm(dx, axis=1))), 1e-300)
    kb, tangent = _curvature_binormal(x)
    change = (_curvature_binormal(x + eps * dx)[0] - _curvature_binormal(x - eps * dx)[0]) / (2.0 * eps)
    b = kb / np.maximum(np.linalg.norm(kb, axis=1), 1e-300)[:, None]
    n = np.cross(b, tangent)
    along_n, along_b = np.sum(change * n, axis=1), np.sum(change * b, axis=1)
    profile = along_n if np.linalg.norm(along_n) >= np.linalg.norm(along_b) else along_b
    return symmetry_order(profile, max_order)
