"""Checks of the inputs of ``jaxrod.measure.analysis.analyze``: point arrays, the sampling, the
smoothing modes, the joint twist; each refusal a ValueError naming the input."""
from __future__ import annotations

import math

import numpy as np

MIN_POINTS = 4


def checked_points(name, points, source=None):
    """(N,3) finite float array with N >= 4, else ValueError naming ``name`` (and the file)."""
    where = f"{name}" if source is None else f"{source}"
    try:
        p = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: could not be read as an array of numbers") from None
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{where}: points must have shape (N, 3), got shape {p.shape}")
    if p.shape[0] < MIN_POINTS:
        raise ValueError(f"{where}: at least {MIN_POINTS} points are needed, got {p.shape[0]}")
    bad = ~np.all(np.isfinite(p), axis=1)
    if np.any(bad):
        rows = np.flatnonzero(bad)
        shown = ", ".join(str(r) for r in rows[:5]) + (", ..." if rows.size > 5 else "")
        raise ValueError(
            f"{where}: non-finite values (nan or inf) in {rows.size} point(s), rows {shown}"
        )
    return p


def clean_points(name, p, closed):
    """Drop exact consecutive duplicates and, for a closed curve, a last point repeating the first
    (common in data files); check that enough points remain."""
    keep = np.ones(p.shape[0], dtype=bool)
    keep[1:] = np.any(p[1:] != p[:-1], axis=1)
    p = p[keep]
    if closed and p.shape[0] > 1:
        scale = np.max(np.ptp(p, axis=0))
        if np.linalg.norm(p[-1] - p[0]) <= 1e-12 * scale:
            p = p[:-1]
    if p.shape[0] < MIN_POINTS:
        raise ValueError(f"{name}: at least {MIN_POINTS} distinct points are needed, got {p.shape[0]}")
    if np.max(np.ptp(p, axis=0)) == 0.0:
        raise ValueError(f"{name}: all points coincide")
    return p


def check_modes(smoothing_modes, n_points, closed):
    if smoothing_modes is None:
        return None
    try:
        integral = not isinstance(smoothing_modes, bool) and int(smoothing_modes) == smoothing_modes
    except (TypeError, ValueError):
        integral = False
    if not integral:
        raise ValueError(f"smoothing_modes must be an integer or None, got {smoothing_modes!r}")
    k = int(smoothing_modes)
    top = (n_points - 1) // 2 if closed else n_points - 3
    if not 1 <= k <= top:
        raise ValueError(
            f"smoothing_modes must lie in [1, {top}] for {n_points} points "
            f"({'closed' if closed else 'open'} curve), got {smoothing_modes!r}"
        )
    return k


def check_closed(closed):
    """``closed`` as a bool, or ValueError unless it is True or False."""
    if not isinstance(closed, (bool, np.bool_)):
        raise ValueError(f"closed must be True or False, got {closed!r}")
    return bool(closed)


def check_joint_twist(joint_twist, closed):
    """``joint_twist`` as a float (radians) or None, or ValueError: not a finite number, or given
    for open curves (the joint is where the ends of a closed rod were glued)."""
    if joint_twist is None:
        return None
    try:
        joint_twist = float(joint_twist) if not isinstance(joint_twist, (bool, np.bool_)) else math.nan
    except (TypeError, ValueError):
        raise ValueError(f"joint_twist must be a finite number (radians) or None, got {joint_twist!r}") from None
    if not math.isfinite(joint_twist):
        raise ValueError(f"joint_twist must be a finite number (radians) or None, got {joint_twist!r}")
    if not closed:
        raise ValueError("joint_twist applies to closed rods only (the joint where the ends were glued)")
    return joint_twist


def check_samples(n_samples, n_points):
    """The number of output nodes: ``n_points`` for None, else ``n_samples`` as an int >= 4, or
    ValueError naming n_samples."""
    if n_samples is None:
        return n_points
    try:
        integral = not isinstance(n_samples, bool) and int(n_samples) == n_samples
    except (TypeError, ValueError):
        integral = False
    if not integral:
        raise ValueError(f"n_samples must be an integer or None, got {n_samples!r}")
    if int(n_samples) < MIN_POINTS:
        raise ValueError(f"n_samples must be at least {MIN_POINTS}, got {n_samples!r}")
    return int(n_samples)
