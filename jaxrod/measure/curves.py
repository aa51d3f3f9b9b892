"""Smooth curves through measured points: cubic splines in the chord length, least-squares
low-pass fits (Fourier modes for closed curves, a regression spline for open ones) with their
parameters corrected onto the fit, and the parameters of points equally spaced in arc length
(steps 1-3 of ``jaxrod.measure.analysis.analyze``)."""
from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicSpline, make_lsq_spline  # scipy is a dependency of jax itself


class _FourierCurve:
    """Closed curve r(t) = a_0 + sum_{k=1..K} a_k cos(2 pi k t/T) + b_k sin(2 pi k t/T), fitted by
    least squares to points at given parameters. ``__call__(t, nu)`` evaluates the nu-th
    derivative (like scipy's CubicSpline)."""

    def __init__(self, t, points, modes, period):
        self.T = float(period)
        self.w = 2.0 * math.pi * np.arange(modes + 1) / self.T
        design = self._basis(np.asarray(t, dtype=float), 0)
        self.coef = np.linalg.lstsq(design, points, rcond=None)[0]  # (2K+1, 3)

    def _basis(self, t, nu):
        ph = np.outer(t, self.w[1:])
        w = self.w[1:] ** nu
        # d^nu/dt^nu of cos(w t) = w^nu cos(w t + nu pi/2), likewise for sin.
        shift = nu * math.pi / 2.0
        const = np.ones((t.size, 1)) if nu == 0 else np.zeros((t.size, 1))
        return np.hstack([const, w * np.cos(ph + shift), w * np.sin(ph + shift)])

    def __call__(self, t, nu=0):
        t = np.asarray(t, dtype=float)
        return (self._basis(t.ravel(), nu) @ self.coef).reshape(t.shape + (3,))


class _SplineFitCurve:
    """Open curve r(t), t in [0, T]: least-squares cubic spline with ``intervals`` equal knot
    intervals, fitted to points at given parameters (regression spline: local, so, unlike a
    high-degree polynomial fit, it does not amplify noise at the ends)."""

    def __init__(self, t, points, intervals, period):
        self.T = float(period)
        knots = np.concatenate([[0.0] * 3, np.linspace(0.0, self.T, intervals + 1), [self.T] * 3])
        order = np.argsort(t, kind="stable")
        try:
            self.spline = make_lsq_spline(np.clip(t[order], 0.0, self.T), points[order], knots, k=3)
        except (np.linalg.LinAlgError, ValueError) as err:
            raise ValueError(
                f"smoothing_modes={intervals}: the least-squares spline is undetermined for these "
                f"points ({err}); use fewer modes"
            ) from None

    def __call__(self, t, nu=0):
        return self.spline(np.asarray(t, dtype=float), nu)


def _chord_parameters(points, closed):
    """Cumulative chord length at each point (and, closed, at the repeated first point)."""
    loop = np.vstack([points, points[:1]]) if closed else points
    chord = np.linalg.norm(np.diff(loop, axis=0), axis=1)
    return loop, np.concatenate([[0.0], np.cumsum(chord)])


def _arclength_table(curve, T, n):
    """Arc length of ``curve`` on a fine grid of [0, T] (Simpson on each cell).
    Returns (tf, sf, speed at tf, speed function)."""
    F = max(8 * n, 2048)
    tf = np.linspace(0.0, T, F + 1)
    speed = lambda u: np.linalg.norm(curve(u, 1), axis=-1)  # noqa: E731
    sp = speed(tf)
    sm = speed(0.5 * (tf[1:] + tf[:-1]))
    sf = np.concatenate([[0.0], np.cumsum((tf[1] - tf[0]) / 6.0 * (sp[:-1] + 4.0 * sm + sp[1:]))])
    return tf, sf, sp, speed


def _project(points, curve, t, window, closed, T):
    """Parameters of the points of ``curve`` nearest to ``points`` (n,3), searched within
    +-window of the current parameters t (n,) (local: never jumps to another strand), then refined
    by Newton's method on the squared distance."""
    offsets = np.linspace(-window, window, 17)
    cand = t[:, None] + offsets[None, :]
    if not closed:
        cand = np.clip(cand, 0.0, T)
    d = np.linalg.norm(curve(cand) - points[:, None, :], axis=-1)
    t = cand[np.arange(t.size), np.argmin(d, axis=1)]
    lo, hi = t - window / 8.0, t + window / 8.0
    for _ in range(3):
        r, r1, r2 = curve(t) - points, curve(t, 1), curve(t, 2)
        g = np.sum(r * r1, axis=-1)
        dg = np.sum(r1 * r1, axis=-1) + np.sum(r * r2, axis=-1)
        ok = dg > 0.0
        t = np.clip(np.where(ok, t - g / np.where(ok, dg, 1.0), t), lo, hi)
    return np.clip(t, 0.0, T) if not closed else t


def _smooth_fit(points, closed, modes, iterations=3):
    """Least-squares low-pass fit of noisy points: Fourier modes |k| <= ``modes`` (closed) or a
    cubic spline with ``modes`` equal knot intervals (open), with iterative parameter correction.

    A fit in the chord-length parameter of noisy points inherits the noise of the chord lengths (a
    random tangential jitter that the truncation turns into shape errors, roughly doubling the noise
    of the curvature). So the parameters are corrected: each point gets the arc length, along the
    previous fit, of its nearest point on it (a local search), and the fit is redone. Tangential
    noise is thereby absorbed into the parameters; only normal noise is left to the low-pass.
    Returns (curve, T)."""
    n = points.shape[0]
    _, t = _chord_parameters(points, closed)
    T = float(t[-1])
    t = t[:n]
    make = _FourierCurve if closed else _SplineFitCurve
    curve = make(t, points, modes, T)
    for _ in range(iterations):
        t = _project(points, curve, t, 4.0 * T / n, closed, T)
        tf, sf, _, _ = _arclength_table(curve, T, n)
        if closed:
            wraps = np.floor(t / T)
            s = np.interp(t - wraps * T, tf, sf) + wraps * sf[-1]
        else:
            s = np.interp(t, tf, sf)
        T = float(sf[-1])
        t = s
        curve = make(t, points, modes, T)
    return curve, T


def interpolant(points, closed, modes):
    """Curve through (or, if smoothing, near) ``points``.

    Without smoothing: a cubic spline (periodic / not-a-knot) in the cumulative chord length.
    With smoothing: :func:`_smooth_fit`. Returns (curve, T): curve(t, nu) evaluates the nu-th
    derivative, t in [0, T] (closed: periodic with period T)."""
    if modes is not None:
        return _smooth_fit(points, closed, modes)
    loop, t = _chord_parameters(points, closed)
    return CubicSpline(t, loop, bc_type="periodic" if closed else "not-a-knot"), float(t[-1])


def arclength_parameters(curve, T, n, closed):
    """Parameters t_i at which ``curve`` has arc length s_i, equally spaced (closed: s_i = i L/n,
    i < n; open: s_i = i L/(n-1)). Simpson quadrature of the speed on a fine grid, then two Newton
    steps on the exact arc-length function. Returns (t (n,), L)."""
    tf, sf, sp, speed = _arclength_table(curve, T, n)
    F = tf.size - 1
    L = float(sf[-1])
    target = L * np.arange(n) / n if closed else np.linspace(0.0, L, n)
    t = np.interp(target, sf, tf)
    for _ in range(2):
        k = np.clip(np.searchsorted(tf, t, side="right") - 1, 0, F - 1)
        a = tf[k]
        s_t = sf[k] + (t - a) / 6.0 * (sp[k] + 4.0 * speed(0.5 * (a + t)) + speed(t))
        t = np.clip(t - (s_t - target) / speed(t), 0.0, T)
    return t, L
