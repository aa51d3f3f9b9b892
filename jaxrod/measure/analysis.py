"""Analysis of measured (or simulated) rod shapes: frames, curvature and twist profiles, Wr, Tw, Lk.

This is the analysis of the seed paper (Goto, Nomura, Sano, "Twist deformation of physical trefoil
knots") applied to two polylines: the rod's centreline and an *eccentric line*, a line drawn on the
rod surface (e.g. both extracted as skeletons from X-ray tomography).

Frames and profiles (paper's definitions)
-----------------------------------------
* d3 = unit tangent of the centreline;
* d1 = unit vector from the centreline towards the eccentric line, projected on the plane normal to
  d3; d2 = d3 x d1 (right-handed);
* kappa1 = d2'.d3, kappa2 = d3'.d1, tau = d1'.d2, kappa = sqrt(kappa1^2 + kappa2^2), ' = d/ds.

With the Darboux vector Omega (d_i' = Omega x d_i) these say Omega = kappa1 d1 + kappa2 d2 + tau d3:
(kappa1, kappa2) are the components of the curvature binormal kappa*b = d3 x d3' on (d1, d2), and
tau is the rate at which d1 turns about d3 (right-handed positive), the same sign convention as
``jaxrod.model.topology`` and the rod scenes.

Pipeline of :func:`analyze`
---------------------------
1. Both polylines are interpolated by cubic splines in their cumulative chord length (periodic for
   closed curves, not-a-knot for open ones), so that resampling keeps second-order (in fact
   fourth-order in position) accuracy: a *linear* resampling would put kinks of size h^2 kappa into
   the curve, which second differences turn into O(1) curvature errors.
2. Optional smoothing (``smoothing_modes=K``, off by default; both curves get the same K), a
   least-squares fit: closed curves by a Fourier series with the modes |k| <= K (a periodic
   low-pass: a mode k has wavelength L/k); open curves by a cubic spline with K equal knot
   intervals (a regression spline: local, so the ends are not plagued by the Runge/Gibbs noise
   amplification of a high-degree polynomial or of a truncated Fourier series of a non-periodic
   signal; the ends remain the noisiest part, as with any estimate of derivatives there).
   Parameters: first the chord length of the noisy points, then corrected three times by
   projecting each point on the previous fit (arc length of its nearest point, searched locally).
   Without the correction the random chord lengths of noisy points act as a tangential jitter that
   the truncation turns into shape noise (it doubled the curvature error in the tests). Choose K
   from the physics: large enough to resolve the features (for a trefoil with a few turns of twist,
   K ~ 12-16), small enough to reject the noise; the curvature noise grows like K^2.5, the twist
   noise like K^1.5 (white noise: amplitude x sqrt((2K+1)/n) x (2 pi K/L)^p / sqrt(2p+1) for the
   p-th derivative).
3. The centreline is resampled to ``n_samples`` nodes equally spaced in arc length (the arc length
   of the interpolant, by Simpson quadrature of its speed and Newton refinement, to ~1e-12).
4. Pairing: for each node x_i the eccentric point is where the eccentric curve (its spline, or its
   smoothed version) crosses the normal plane {p : (p - x_i).d3_i = 0}; if it crosses it several times
   (the plane also cuts other strands of a knot) the crossing *nearest to x_i* is taken. It is found
   on a dense polyline sampled from the interpolant and refined by Newton's method on the
   interpolant itself. Where the plane is not crossed at all (near the ends of open data) the
   nearest point of the eccentric curve is used (flagged in ``RodAnalysis.paired``). In both
   cases d1 is the projection of (point - x_i) on the normal plane, normalised. The rule assumes
   that the line is nearer to its own strand than to any other, which holds for a line on the
   surface of a rod that does not interpenetrate itself (own surface at D/2, any other strand's
   surface at >= D/2).
5. Derivatives on the equal-arc-length grid, second order: the tangent by central differences
   (x_{i+1} - x_{i-1})/2h, the curvature vector d3' = x'' by the compact second difference
   (x_{i+1} - 2x_i + x_{i-1})/h^2, so kappa1 = d2'.d3 = -d2.x'' and kappa2 = x''.d1; tau = d1'.d2 with
   d1' by central differences. Closed curves are periodic; open curves use second-order one-sided
   stencils at the ends.
6. Wr: exact polygon writhe (:func:`jaxrod.model.topology.writhe`) of the resampled centreline.
   Tw: (1/2pi) x the sum of the signed angles (right-hand rule about the tangent) between d1 and its
   parallel transport from the previous frame. For a closed curve the frames used are the node d1
   carried to the *edges* of the resampled polygon (averaged, projected normal to each edge); the
   holonomy of transport round a polygon equals -2pi Wr(polygon) modulo 2pi exactly, so Wr + Tw is
   then an integer to rounding (provided each step turns by less than pi). For an open curve the
   sequence is node 0, edges 0..N-2, node N-1. Tw_integral = (1/2pi) int tau ds (periodic
   trapezoid / trapezoid rule), which agrees with Tw to the order of the discretisation.
7. Lk (closed curves only; NaN for open ones): the Gauss linking number of the resampled
   centreline with the eccentric polyline (as given, or the smoothed one sampled at as many points
   as given), exactly (:func:`jaxrod.model.topology.linking_number`, an integer) and by the paper's
   midpoint-rule quadrature (:func:`jaxrod.model.topology.gauss_linking_quadrature`); the eccentric line
   is oriented along the centreline first (its orientation flips the sign of Lk). Lk_frames = Wr + Tw.
   Note the paper writes its Gauss integrals with the opposite orientation; the values here follow
   jaxrod's standard convention (a right-handed ribbon has positive Lk).
8. The joint of a twisted closed rod (closed curves only). A rod whose ends were turned relative to
   each other by phi before gluing carries a line drawn on its surface that does not close unless
   phi is a whole number of turns: at the joint its angle about the centreline jumps by -phi
   (mod 2pi). The frames of step 6 then miss that fractional turn (Wr + Tw is an integer), tau
   spikes at the joint, and the Gauss linking number of step 7 is not defined. The jump is found
   as the largest localised excess of the turning angles of step 6 over their smooth trend; a
   jump of more than 0.01 turn that stands out of the step-to-step variation gives a warning,
   and Lk_exact, Lk_quadrature are NaN. With ``joint_twist=phi`` the jump is accounted for: the
   turn it hides, phi - 2pi m (m the integer that leaves the joint step nearest the trend), is
   added to Tw (so Lk_frames = Wr + Tw = Lk0 + phi/2pi for a simulated state), and tau at the
   nodes spanning the jump is replaced by the trend (interpolated from the neighbouring nodes)
   plus whatever twist the joint step has beyond it, spread over those nodes.

Cost: the writhe and linking number are O(N^2) in time and memory (all segment pairs); for
skeletons of many thousand points pass a smaller ``n_samples`` (a few hundred resolve a knot).

Input files: :func:`load_polyline` (CSV with an x,y,z header or three bare columns; .npy (N,3);
an array of an .npz, e.g. ``x`` and ``eccentric`` of a study's step file ``steps/*.npz``) and
:func:`load_joint_twist` (the step file's imposed twist ``phi``, for ``joint_twist``).
Output: :func:`write_profiles_csv`.

Shape descriptors of a closed curve's periodic profile (e.g. ``RodAnalysis.kappa``):
:func:`symmetry_order` (the dominant Fourier harmonic) and :func:`count_peaks` (prominent maxima).
"""
from __future__ import annotations

import csv
import math
import warnings
import os
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline, make_lsq_spline  # scipy is a dependency of jax itself

from ..model.geometry import parallel_transport, signed_angle
from ..model.topology import gauss_linking_quadrature, is_whole_turns, linking_number, writhe

__all__ = ["RodAnalysis", "analyze", "count_peaks", "load_joint_twist", "load_polyline", "symmetry_order",
           "write_profiles_csv"]

TWO_PI = 2.0 * math.pi
_MIN_POINTS = 4


# ---------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class RodAnalysis:
    """Result of :func:`analyze`. N = number of (resampled) centreline nodes.

    Attributes
    ----------
    s: (N,) arc length of the nodes (closed: 0, h, ..., L - h; open: 0 ... L).
    kappa1, kappa2: (N,) curvature components d2'.d3 and d3'.d1 (1/length).
    tau: (N,) twist density d1'.d2 (radians/length, right-handed positive).
    kappa: (N,) curvature sqrt(kappa1^2 + kappa2^2).
    d1, d2, d3: (N,3) the frame at the nodes (d3 tangent, d1 towards the eccentric line).
    x: (N,3) the resampled (and smoothed, if asked) centreline nodes.
    eccentric: (N,3) the eccentric-line point paired with each node.
    paired: (N,) bool, True where that point is a crossing of the node's normal plane; False where
      the plane misses the eccentric line (e.g. beyond its ends in open data) and the nearest point
      was used instead: d1, tau, kappa1, kappa2 are unreliable there.
    length: total arc length L of the centreline.
    closed: whether the curves were treated as closed.
    Wr: writhe of the resampled centreline (exact polygon writhe; open writhe if not closed).
    Tw: total twist of the frame (turns), from transported frames; Wr + Tw is an integer for a
      closed ribbon.
    Tw_integral: (1/2pi) * integral of tau ds.
    Lk_exact: exact Gauss linking number of the centreline and the eccentric line (NaN if open).
    Lk_quadrature: midpoint-rule Gauss linking integral, the paper's estimate (NaN if open).
    Lk_frames: Wr + Tw.
    joint_jump: closed curves: the jump (turns) of the eccentric line's angle at a place where it
      does not close onto itself smoothly (the joint of a rod twisted by a non-whole number of
      turns), 0.0 if none was found; NaN for open curves.
    joint_twist: the ``joint_twist`` given to :func:`analyze` (radians), or None.
    warnings: what looked wrong with the data (each also issued as a ``UserWarning``): a curve
      closed although its ends are far apart, an eccentric line much shorter or longer than the
      centreline, nodes paired with a far point (another strand's line), nodes whose normal
      plane misses the eccentric line, Lk from the frames disagreeing with the Gauss linking
      number, an eccentric line that does not close at the joint (no ``joint_twist`` given) or
      whose jump there does not match the ``joint_twist`` given. Empty when nothing did.
    """

    s: np.ndarray
    kappa1: np.ndarray
    kappa2: np.ndarray
    tau: np.ndarray
    kappa: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    d3: np.ndarray
    x: np.ndarray
    eccentric: np.ndarray
    paired: np.ndarray
    length: float
    closed: bool
    Wr: float
    Tw: float
    Tw_integral: float
    Lk_exact: float
    Lk_quadrature: float
    Lk_frames: float
    warnings: tuple = ()
    joint_jump: float = math.nan
    joint_twist: float | None = None


# ---------------------------------------------------------------------------- validation
def _check_points(name, points, source=None):
    """(N,3) finite float array with N >= 4, else ValueError naming ``name`` (and the file)."""
    where = f"{name}" if source is None else f"{source}"
    try:
        p = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: could not be read as an array of numbers") from None
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{where}: points must have shape (N, 3), got shape {p.shape}")
    if p.shape[0] < _MIN_POINTS:
        raise ValueError(f"{where}: at least {_MIN_POINTS} points are needed, got {p.shape[0]}")
    bad = ~np.all(np.isfinite(p), axis=1)
    if np.any(bad):
        rows = np.flatnonzero(bad)
        shown = ", ".join(str(r) for r in rows[:5]) + (", ..." if rows.size > 5 else "")
        raise ValueError(
            f"{where}: non-finite values (nan or inf) in {rows.size} point(s), rows {shown}"
        )
    return p


def _clean(name, p, closed):
    """Drop exact consecutive duplicates and, for a closed curve, a last point repeating the first
    (common in data files); check that enough points remain."""
    keep = np.ones(p.shape[0], dtype=bool)
    keep[1:] = np.any(p[1:] != p[:-1], axis=1)
    p = p[keep]
    if closed and p.shape[0] > 1:
        scale = np.max(np.ptp(p, axis=0))
        if np.linalg.norm(p[-1] - p[0]) <= 1e-12 * scale:
            p = p[:-1]
    if p.shape[0] < _MIN_POINTS:
        raise ValueError(f"{name}: at least {_MIN_POINTS} distinct points are needed, got {p.shape[0]}")
    if np.max(np.ptp(p, axis=0)) == 0.0:
        raise ValueError(f"{name}: all points coincide")
    return p


# ---------------------------------------------------------------------------- curves
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


def _interpolant(points, closed, modes):
    """Curve through (or, if smoothing, near) ``points``.

    Without smoothing: a cubic spline (periodic / not-a-knot) in the cumulative chord length.
    With smoothing: :func:`_smooth_fit`. Returns (curve, T): curve(t, nu) evaluates the nu-th
    derivative, t in [0, T] (closed: periodic with period T)."""
    if modes is not None:
        return _smooth_fit(points, closed, modes)
    loop, t = _chord_parameters(points, closed)
    return CubicSpline(t, loop, bc_type="periodic" if closed else "not-a-knot"), float(t[-1])


def _arclength_parameters(curve, T, n, closed):
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


# ---------------------------------------------------------------------------- pairing
def _pair(x, d3, curve, T, closed, n_dense, expected=None, reach=None):
    """Point of the eccentric ``curve`` paired with each node x (N,3) of unit tangent d3 (N,3):
    the crossing of the normal plane nearest to the node (Newton-refined on the curve), or the
    nearest point of the curve if the plane is not crossed. With ``expected`` ((N,) parameters
    on the curve) and ``reach`` (a distance): among the crossings within reach, the one whose
    parameter is nearest the expected one (continuity along the line, where strands touch and
    another strand's line crosses the plane as near as the node's own). Returns (points (N,3),
    params (N,), crossed (N,) bool)."""
    tf = np.linspace(0.0, T, n_dense + 1)
    pf = curve(tf)
    out_t = np.empty(x.shape[0])
    crossed = np.empty(x.shape[0], dtype=bool)
    chunk = max(1, 500_000 // (3 * n_dense))  # bounds the (chunk, n_dense, 3) temporaries
    for lo in range(0, x.shape[0], chunk):
        xs, ts = x[lo: lo + chunk], d3[lo: lo + chunk]
        f = np.einsum("cfk,ck->cf", pf[None, :, :] - xs[:, None, :], ts)  # signed height above plane
        f0, f1 = f[:, :-1], f[:, 1:]
        crosses = (f0 * f1 <= 0.0) & (f0 != f1)
        alpha = np.where(crosses, f0 / np.where(crosses, f0 - f1, 1.0), 0.0)
        q = pf[None, :-1, :] + alpha[:, :, None] * (pf[None, 1:, :] - pf[None, :-1, :])
        dist = np.where(crosses, np.linalg.norm(q - xs[:, None, :], axis=-1), np.inf)
        j = np.argmin(dist, axis=1)
        rows = np.arange(xs.shape[0])
        if expected is not None:
            t_all = tf[None, :-1] + alpha * (tf[None, 1:] - tf[None, :-1])
            gap = t_all - expected[lo: lo + chunk, None]
            if closed:
                gap = (gap + 0.5 * T) % T - 0.5 * T
            score = np.where(dist <= reach, np.abs(gap), np.inf)
            best = np.argmin(score, axis=1)
            j = np.where(np.isfinite(score[rows, best]), best, j)
        found = np.isfinite(dist[rows, j])
        t = tf[j] + alpha[rows, j] * (tf[j + 1] - tf[j])
        a, b = tf[j], tf[j + 1]
        # Newton on g(t) = (r(t) - x).d3, kept inside the bracketing segment.
        for _ in range(4):
            g = np.sum((curve(t) - xs) * ts, axis=-1)
            dg = np.sum(curve(t, 1) * ts, axis=-1)
            ok = np.abs(dg) > 1e-300
            t = np.clip(np.where(ok, t - g / np.where(ok, dg, 1.0), t), a, b)
        if not np.all(found):
            nearest = np.argmin(np.linalg.norm(pf[None, :, :] - xs[:, None, :], axis=-1), axis=1)
            t = np.where(found, t, tf[nearest])
        out_t[lo: lo + chunk] = t
        crossed[lo: lo + chunk] = found
    return curve(out_t), out_t, crossed


# ---------------------------------------------------------------------------- helpers
def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _transport(v, t_from, t_to):
    return np.asarray(parallel_transport(v, t_from, t_to))


def _angles(d_from, t_from, d_to, t_to):
    """Signed angles (about t_to) from transported d_from to d_to. All (M,3) -> (M,)."""
    return np.asarray(signed_angle(_transport(d_from, t_from, t_to), d_to, t_to))


def _check_modes(smoothing_modes, n_points, closed):
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


# ---------------------------------------------------------------------------- the joint
# A jump of the eccentric line's angle at one place (the joint of a closed rod twisted by a
# non-whole number of turns) counts when it exceeds this many turns in all and its largest step
# stands out of the step-to-step variation of the turning angles by this factor (robust scale).
_JUMP_MIN_TURNS = 0.01
_JUMP_CONTRAST = 10.0
# joint_twist given: a jump left over (the line's jump plus the twist accounted for) beyond this
# many turns means joint_twist does not describe this line.
_JUMP_MISMATCH_TURNS = 0.05


def _closure_jump(angles, width):
    """The largest localised jump of the turning angles ``angles`` (n,) of a closed sequence of
    frames (angle i across node i), over their smooth trend.

    The jump is located at the largest three-point spike |a_i - (a_{i-1} + a_{i+1})/2|. Around it,
    a window of half-width w (from ``width``, the expected spread of an interpolant's ringing,
    widened by half at a time until the excess has died out in the window's outer quarter, at most
    (n - 1)/4); the trend is a quadratic fitted to the steps w to 2w away on either side, and the
    jump is the sum of the excess over it within the window. Returns (jump (radians), lo, hi: the
    first and last step (circular indices, lo <= hi) whose excess stands out, peak: the step of
    largest excess (mod n), significant: the jump exceeds 0.01 turn and its spike stands out of the
    step-to-step variation by ``_JUMP_CONTRAST``)."""
    a = np.asarray(angles, dtype=float)
    n = a.size
    if n < 9:
        return 0.0, 0, 0, 0, False
    spike = np.abs(a - 0.5 * (np.roll(a, 1) + np.roll(a, -1)))
    scale = 1.4826 * float(np.median(spike))  # robust scale of the smooth (or noisy) variation
    k = int(np.argmax(spike))
    top = (n - 1) // 4
    w = int(min(max(width, 2), top))
    while True:
        near = np.arange(k - w, k + w + 1)
        flanks = np.concatenate([np.arange(k - 2 * w, k - w), np.arange(k + w + 1, k + 2 * w + 1)])
        trend = np.polyfit(flanks - k, a[flanks % n], 2)
        excess = a[near % n] - np.polyval(trend, near - k)
        biggest = float(np.max(np.abs(excess)))
        level = max(0.5 * _JUMP_CONTRAST * scale, 0.005 * biggest)
        rim = np.abs(excess[np.abs(near - k) > 0.75 * w])
        if w >= top or rim.size == 0 or float(np.max(rim)) <= max(level, 0.02 * biggest):
            break
        w = min(top, max(w + 1, int(1.5 * w)))
    jump = float(np.sum(excess))
    out = np.flatnonzero(np.abs(excess) > level)
    lo, hi = (int(near[out[0]]), int(near[out[-1]])) if out.size else (k, k)
    peak = int(near[np.argmax(np.abs(excess))] % n)
    significant = abs(jump) > TWO_PI * _JUMP_MIN_TURNS and spike[k] > _JUMP_CONTRAST * scale
    return jump, lo, hi, peak, bool(significant)


def _smooth_joint(tau, h, lo, hi, residual):
    """tau with the spike of a jump across steps lo..hi removed: the nodes lo-1..hi+1 get the
    straight line between their neighbours plus ``residual`` (radians: the joint step's twist
    beyond the trend) spread evenly over them; with too few nodes left, ``residual`` is spread
    over all nodes instead."""
    n = tau.size
    tau = np.array(tau)
    nodes = np.arange(lo - 1, hi + 2)
    if nodes.size + 4 > n:
        return tau + residual / (n * h)
    left, right = tau[(lo - 2) % n], tau[(hi + 2) % n]
    w = (nodes - lo + 2) / (nodes.size + 1.0)
    tau[nodes % n] = (1.0 - w) * left + w * right + residual / (nodes.size * h)
    return tau


# ---------------------------------------------------------------------------- analysis
def analyze(centreline, eccentric, closed=True, n_samples=None, smoothing_modes=None, joint_twist=None):
    """Frames, curvature/twist profiles and Wr, Tw, Lk of a rod from two polylines.

    Args:
      centreline: (N0, 3) points along the rod's centreline, in order. For a closed rod the last
        point need not repeat the first (a repeated one is dropped; so are exact duplicates).
      eccentric: (M0, 3) points along a line drawn on the rod surface, in order (either direction;
        not necessarily matching the centreline points in number or position).
      closed: treat both curves as closed loops (a knot, a ring) or as open arcs.
      n_samples: number N of output nodes, equally spaced in arc length (default: N0).
      smoothing_modes: None (default, no smoothing) or K: least-squares fit of each closed curve by
        Fourier modes |k| <= K, of each open curve by a cubic spline with K knot intervals. For
        noisy data; 1 <= K <= (M - 1)//2 (closed) or M - 3 (open), M the fewer of the two point
        counts.
      joint_twist: None (default) or, for a closed rod whose ends were turned by this angle phi
        (radians) relative to each other before gluing (a simulated state: a study's step file
        holds it as ``phi``, see :func:`load_joint_twist`), that angle. Unless phi is a whole
        number of turns the line drawn on such a rod jumps at the joint by -phi (mod 2 pi); the
        turn hidden in the jump is then added to Tw and Lk_frames, and the spike of tau at the
        joint removed (module docstring, step 8). Without it, a line that jumps gives a warning
        and NaN for Lk_exact and Lk_quadrature (not defined for a line that does not close).

    Returns:
      :class:`RodAnalysis` (per-node arrays of length N, see there). The method (interpolation,
      pairing, stencils) is described in the module docstring; profiles are second-order accurate
      in the node spacing for smooth data.

    Raises:
      ValueError: input not of shape (N, 3), non-finite, fewer than 4 points, bad ``n_samples`` or
        ``smoothing_modes`` or ``joint_twist`` (also: given for open curves), or an eccentric
        line that lies on the centreline.
    """
    if not isinstance(closed, (bool, np.bool_)):
        raise ValueError(f"closed must be True or False, got {closed!r}")
    closed = bool(closed)
    if joint_twist is not None:
        try:
            joint_twist = float(joint_twist) if not isinstance(joint_twist, (bool, np.bool_)) else math.nan
        except (TypeError, ValueError):
            raise ValueError(f"joint_twist must be a finite number (radians) or None, got {joint_twist!r}") from None
        if not math.isfinite(joint_twist):
            raise ValueError(f"joint_twist must be a finite number (radians) or None, got {joint_twist!r}")
        if not closed:
            raise ValueError("joint_twist applies to closed rods only (the joint where the ends were glued)")
    c_pts = _clean("centreline", _check_points("centreline", centreline), closed)
    e_pts = _clean("eccentric", _check_points("eccentric", eccentric), closed)
    if n_samples is None:
        n = c_pts.shape[0]
    else:
        try:
            integral = not isinstance(n_samples, bool) and int(n_samples) == n_samples
        except (TypeError, ValueError):
            integral = False
        if not integral:
            raise ValueError(f"n_samples must be an integer or None, got {n_samples!r}")
        n = int(n_samples)
        if n < _MIN_POINTS:
            raise ValueError(f"n_samples must be at least {_MIN_POINTS}, got {n_samples!r}")
    modes = _check_modes(smoothing_modes, min(c_pts.shape[0], e_pts.shape[0]), closed)

    # 1-3: interpolate (and smooth), resample the centreline to equal arc length.
    c_curve, c_T = _interpolant(c_pts, closed, modes)
    e_curve, e_T = _interpolant(e_pts, closed, modes)
    t_nodes, L = _arclength_parameters(c_curve, c_T, n, closed)
    x = c_curve(t_nodes)
    h = L / n if closed else L / (n - 1)

    # 5a: tangent and curvature vector.
    if closed:
        xp, xm = np.roll(x, -1, axis=0), np.roll(x, 1, axis=0)
        d3 = _unit(xp - xm)
        xss = (xp - 2.0 * x + xm) / h**2
    else:
        d3 = _unit(np.gradient(x, h, axis=0, edge_order=2))
        xss = np.empty_like(x)
        xss[1:-1] = (x[2:] - 2.0 * x[1:-1] + x[:-2]) / h**2
        xss[0] = (2.0 * x[0] - 5.0 * x[1] + 4.0 * x[2] - x[3]) / h**2
        xss[-1] = (2.0 * x[-1] - 5.0 * x[-2] + 4.0 * x[-3] - x[-4]) / h**2

    # 4: pairing and the frame.
    n_dense = max(8 * e_pts.shape[0], 4 * n)
    ecc, e_t, crossed = _pair(x, d3, e_curve, e_T, closed, n_dense)
    offset = np.linalg.norm(ecc - x, axis=-1)
    jumps = _pairing_jumps(e_t, e_T, closed) & crossed
    if np.any(jumps) and np.sum(crossed) >= 4:
        # Where strands touch, a node's normal plane may meet another strand's line as near as
        # its own: pair again by continuity, each node with the crossing nearest the parameter
        # interpolated from the nodes whose pairing advanced smoothly.
        expected = _expected_parameters(e_t, crossed, e_T, closed)
        ecc, e_t, crossed = _pair(x, d3, e_curve, e_T, closed, n_dense, expected=expected,
                                  reach=2.0 * float(np.median(offset)))
    w = ecc - x
    w = w - np.sum(w * d3, axis=-1, keepdims=True) * d3
    r = np.linalg.norm(w, axis=-1)
    if np.min(r) <= 1e-9 * L:
        i = int(np.argmin(r))
        raise ValueError(
            f"eccentric: the eccentric line lies on the centreline (offset {r[i]:.3g} at node {i}, "
            f"length {L:.6g}); it must be a line drawn at a distance from the centreline"
        )
    d1 = w / r[:, None]
    d2 = np.cross(d3, d1)

    # 5b: profiles.
    kappa1 = -np.sum(xss * d2, axis=-1)
    kappa2 = np.sum(xss * d1, axis=-1)
    if closed:
        d1s = (np.roll(d1, -1, axis=0) - np.roll(d1, 1, axis=0)) / (2.0 * h)
    else:
        d1s = np.gradient(d1, h, axis=0, edge_order=2)
    tau = np.sum(d1s * d2, axis=-1)
    kappa = np.hypot(kappa1, kappa2)
    s = h * np.arange(n)

    # 6: writhe and twist.
    Wr = float(writhe(x, closed=closed))
    if closed:
        te = _unit(np.roll(x, -1, axis=0) - x)  # edge i: x_i -> x_{i+1}
        d3n, d1n = np.roll(d3, -1, axis=0), np.roll(d1, -1, axis=0)
    else:
        te = _unit(x[1:] - x[:-1])
        d3n, d1n = d3[1:], d1[1:]
    de = _transport(d1[: te.shape[0]], d3[: te.shape[0]], te) + _transport(d1n, d3n, te)
    de = _unit(de - np.sum(de * te, axis=-1, keepdims=True) * te)
    if closed:
        angles = _angles(np.roll(de, 1, axis=0), np.roll(te, 1, axis=0), de, te)
        Tw_integral = float(np.sum(tau) * h / TWO_PI)
    else:
        t_seq = np.concatenate([d3[:1], te, d3[-1:]], axis=0)
        d_seq = np.concatenate([d1[:1], de, d1[-1:]], axis=0)
        angles = _angles(d_seq[:-1], t_seq[:-1], d_seq[1:], t_seq[1:])
        Tw_integral = float(np.sum(0.5 * (tau[1:] + tau[:-1])) * h / TWO_PI)
    Tw = float(np.sum(angles) / TWO_PI)

    # 8: the joint: does the line close onto itself smoothly?
    joint_notes = []
    joint_jump = math.nan
    line_closes = True
    if closed:
        # The jump spreads over the interpolant's ringing: a few eccentric points (or everywhere,
        # for a Fourier fit).
        width = (n - 1) // 4 if modes is not None else math.ceil(4.5 * n / e_pts.shape[0]) + 2
        jump, lo, hi, peak, found = _closure_jump(angles, width)
        joint_jump = jump / TWO_PI if found else 0.0
        line_closes = not found
        where = f"at s = {s[peak]:.4g} (node {peak})"
        if joint_twist is None:
            if found:
                joint_notes.append(
                    f"eccentric: the line does not close onto itself: its angle about the centreline jumps by "
                    f"{jump / TWO_PI:+.4f} turns {where}, far more than between neighbouring nodes (a rod twisted "
                    "by a non-whole number of turns before its ends were glued?); Tw and Lk from the frames miss "
                    "that fractional turn, tau spikes there and the Gauss linking number is not defined (NaN): "
                    "give the imposed twist as joint_twist= (radians; the CLI's --joint-twist, which a step file's phi "
                    "supplies)")
        else:
            turns = joint_twist / TWO_PI
            if not is_whole_turns(joint_twist):
                line_closes = False
            hidden = joint_twist - TWO_PI * math.floor((joint_twist + jump) / TWO_PI + 0.5)
            residual = jump + hidden  # what the joint step still turns beyond the trend
            if abs(residual) > TWO_PI * _JUMP_MISMATCH_TURNS:
                seen = f"jumps by {jump / TWO_PI:+.4f} turns {where}" if found else "closes smoothly"
                joint_notes.append(
                    f"eccentric: joint_twist = {joint_twist:.6g} rad ({turns:.4g} turns) does not match the line, "
                    f"which {seen}: a line on a rod twisted by phi jumps by -phi mod 1 turn at the joint, so "
                    f"{residual / TWO_PI:+.4f} turns are left unexplained; check the value and sign of joint_twist")
            if hidden != 0.0:
                Tw += hidden / TWO_PI
                if found:
                    tau = _smooth_joint(tau, h, lo, hi, residual)
                else:  # nowhere to put it but everywhere
                    tau = tau + hidden / (n * h)
                Tw_integral = float(np.sum(tau) * h / TWO_PI)

    # 7: linking number of the centreline with the eccentric line.
    if closed and not line_closes:
        Lk_exact = Lk_quad = float("nan")  # the Gauss integral of a line that does not close
    elif closed:
        e_poly = e_pts if modes is None else e_curve(e_T * np.arange(e_pts.shape[0]) / e_pts.shape[0])
        if np.mean(np.sum(e_curve(e_t, 1) * d3, axis=-1)) < 0.0:
            e_poly = e_poly[::-1]  # orient the eccentric line along the centreline
        Lk_exact = float(linking_number(x, e_poly))
        Lk_quad = float(gauss_linking_quadrature(x, e_poly))
    else:
        Lk_exact = Lk_quad = float("nan")

    arrays = dict(
        s=s, kappa1=kappa1, kappa2=kappa2, tau=tau, kappa=kappa, d1=d1, d2=d2, d3=d3, x=x, eccentric=ecc,
        paired=crossed,
    )
    for a in arrays.values():
        a.setflags(write=False)
    return RodAnalysis(
        **arrays,
        length=L,
        closed=closed,
        Wr=Wr,
        Tw=Tw,
        Tw_integral=Tw_integral,
        Lk_exact=Lk_exact,
        Lk_quadrature=Lk_quad,
        Lk_frames=Wr + Tw,
        warnings=tuple(_data_warnings(c_pts, e_pts, x, r, crossed, closed, Wr + Tw, Lk_exact, L, e_t, e_T,
                                      joint_notes)),
        joint_jump=joint_jump,
        joint_twist=joint_twist,
    )


# A closed curve's end gap beyond this many times its median point spacing is not a closed loop.
_OPEN_GAP = 5.0
# An eccentric line drawn on a rod is about as long as its centreline (longer where it winds).
_ECCENTRIC_LENGTH_RANGE = (0.8, 2.0)
# A paired point further than this multiple of the median offset belongs to another strand.
_FAR_PAIRING = 2.0


def _expected_parameters(e_t, crossed, e_T, closed):
    """(N,) parameters on the eccentric line expected at each node from continuity: the paired
    parameters follow a straight trend in the node index (one period per loop for a closed line,
    in the direction most pairs run) up to the line's speed variations (a few per cent of its
    length); nodes further than e_T/8 from the trend were paired with another piece of the line
    (another strand's, which lies a good fraction of the length away) and are ignored; the
    others are interpolated linearly."""
    n = e_t.shape[0]
    i = np.arange(n)
    step = np.diff(np.concatenate([e_t, e_t[:1]]) if closed else e_t)
    if closed:
        step = (step + 0.5 * e_T) % e_T - 0.5 * e_T
    slope = float(np.median(step[np.abs(step) < 0.25 * e_T]))  # parameter per node, with its sense
    if closed:
        slope = np.sign(slope) * e_T / n  # exactly one period per loop
    base = e_t - slope * i
    if closed:  # circular median of the offsets: the angle of the mean direction, then refined
        angle = 2.0 * np.pi * base / e_T
        centre = np.angle(np.mean(np.exp(1j * angle[crossed])))
        dev = (angle - centre + np.pi) % (2.0 * np.pi) - np.pi
        centre += float(np.median(dev[crossed]))
        dev = ((angle - centre + np.pi) % (2.0 * np.pi) - np.pi) * e_T / (2.0 * np.pi)
    else:
        dev = base - float(np.median(base[crossed]))
    good = crossed & (np.abs(dev) < 0.125 * e_T)
    idx = np.flatnonzero(good)
    if idx.size < 2:
        return e_t
    if not closed:
        return np.interp(i, idx, e_t[idx])
    # The offsets from the trend, unwrapped along the good nodes, interpolated around the loop.
    offsets = np.unwrap(2.0 * np.pi * base[idx] / e_T) * e_T / (2.0 * np.pi)
    periodic = np.interp(i, idx, offsets, period=n)
    return (periodic + slope * i) % e_T


def _pairing_jumps(e_t, e_T, closed):
    """Nodes where the paired point's parameter on the eccentric line does not advance like its
    neighbours' (it goes back, or leaps ahead): the node was paired with a piece of the line
    that runs along another strand."""
    step = np.diff(np.concatenate([e_t, e_t[:1]]) if closed else e_t)
    if closed:
        step = (step + 0.5 * e_T) % e_T - 0.5 * e_T  # the closed line's parameter wraps at e_T
    typical = float(np.median(step))
    if typical == 0.0:
        return np.ones(e_t.shape[0], dtype=bool)
    odd = (step * np.sign(typical) <= 0.0) | (np.abs(step) > 4.0 * abs(typical))
    nodes = np.zeros(e_t.shape[0], dtype=bool)
    nodes[: odd.shape[0]] |= odd
    nodes[1: odd.shape[0] + 1 if closed else None] |= odd[: e_t.shape[0] - 1]
    if closed:
        nodes[0] |= odd[-1]
    return nodes


def _data_warnings(c_pts, e_pts, x, offset, crossed, closed, lk_frames, lk_exact, L, e_t, e_T, joint_notes=()):
    """Warnings about data that ``analyze`` accepts but whose results are doubtful (issued as
    UserWarning, returned as strings)."""
    found = []

    def polyline_length(p, loop):
        return float(np.sum(np.linalg.norm(np.diff(np.vstack([p, p[:1]]) if loop else p, axis=0), axis=1)))

    if closed:
        for name, pts in (("centreline", c_pts), ("eccentric", e_pts)):
            steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            gap = float(np.linalg.norm(pts[0] - pts[-1]))
            if gap > _OPEN_GAP * float(np.median(steps)):
                found.append(f"{name}: its ends are {gap:.3g} apart ({gap / np.median(steps):.0f} times the point "
                             "spacing), yet the curve was closed: pass closed=False (--open) for an open rod")
    ratio = polyline_length(e_pts, closed) / polyline_length(c_pts, closed)
    lo, hi = _ECCENTRIC_LENGTH_RANGE
    if not lo <= ratio <= hi:
        found.append(f"eccentric: the line is {ratio:.2f} times as long as the centreline (expected {lo}-{hi}): "
                     "it may not follow the whole rod")
    far = offset > _FAR_PAIRING * float(np.median(offset))
    if np.any(far):
        found.append(f"eccentric: at {int(far.sum())} node(s) the paired point is more than {_FAR_PAIRING:g} times "
                     "the median offset from the centreline (another strand's line?): profiles there are unreliable")
    jumps = _pairing_jumps(e_t, e_T, closed) & crossed  # unpaired nodes are reported below
    if np.any(jumps):
        found.append(f"eccentric: at {int(jumps.sum())} node(s) the pairing jumps along the eccentric line (a node "
                     "paired with the line of another strand, or a line drawn in pieces): d1, tau, kappa1, kappa2 "
                     "are unreliable there")
    if not np.all(crossed):
        found.append(f"eccentric: at {int((~crossed).sum())} node(s) the normal plane misses the eccentric line "
                     "(the nearest point was used): d1, tau, kappa1, kappa2 are unreliable there")
    if closed and math.isfinite(lk_exact) and abs(lk_frames - lk_exact) > 0.1:
        found.append(f"Lk from the frames ({lk_frames:.3f}) and the Gauss linking number ({lk_exact:.0f}) disagree: "
                     "the eccentric line may not follow the whole rod, or pairs with another strand")
    found.extend(joint_notes)
    for message in found:
        warnings.warn(message, UserWarning, stacklevel=3)
    return found


# ---------------------------------------------------------------------------- profile descriptors
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


# ---------------------------------------------------------------------------- I/O
def _parse_float(text):
    try:
        return float(text)
    except ValueError:
        return None


def _read_csv(path):
    with open(path, newline="") as fh:
        rows = [
            (lineno, [cell.strip() for cell in row])
            for lineno, row in enumerate(csv.reader(fh), start=1)
            if row and any(cell.strip() for cell in row) and not row[0].lstrip().startswith("#")
        ]
    if not rows:
        raise ValueError(f"{path}: empty file, no points")
    first_line, first = rows[0]
    has_header = any(_parse_float(cell) is None for cell in first)
    if has_header:
        names = [cell.lower() for cell in first]
        missing = [c for c in ("x", "y", "z") if c not in names]
        if missing:
            raise ValueError(
                f"{path}: missing column(s) {', '.join(missing)} in the header {first!r} "
                "(need columns named x, y, z)"
            )
        dup = [c for c in ("x", "y", "z") if names.count(c) > 1]
        if dup:
            raise ValueError(f"{path}: duplicate column(s) {', '.join(dup)} in the header {first!r}")
        cols = [names.index(c) for c in ("x", "y", "z")]
        body = rows[1:]
        width = len(names)
    else:
        cols = [0, 1, 2]
        body = rows
        width = 3
        if len(first) != 3:
            raise ValueError(
                f"{path}: a file without header must have exactly 3 numeric columns (x, y, z), "
                f"line {first_line} has {len(first)}"
            )
    pts = np.empty((len(body), 3))
    for i, (lineno, row) in enumerate(body):
        if len(row) != width:
            raise ValueError(f"{path}: line {lineno} has {len(row)} columns, expected {width}")
        for k, c in enumerate(cols):
            v = _parse_float(row[c])
            if v is None:
                raise ValueError(f"{path}: line {lineno}: value {row[c]!r} is not a number")
            pts[i, k] = v
    return pts


def _read_npz(path):
    """The arrays of a .npz file (no pickles), as a dict; ValueError naming the file if unreadable."""
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: data[name] for name in data.files}
    except (ValueError, zipfile.BadZipFile, EOFError) as err:  # OSError (a missing file): the caller's
        raise ValueError(f"{path}: not a readable .npz archive of numeric arrays ({err})") from None


def load_polyline(path, array="x"):
    """Read a polyline (N, 3) from a file.

    * ``.csv``: comma-separated. Either a header row naming columns ``x``, ``y``, ``z`` (any order,
      case-insensitive; other columns are ignored) followed by numeric rows, or exactly three
      numeric columns without header. Blank lines and lines starting with ``#`` are skipped.
    * ``.npy``: a numeric array of shape (N, 3) (no pickles).
    * ``.npz``: the array named ``array`` (default ``"x"``) of the archive, e.g. a study's step
      file ``steps/<direction>_<NNNN>.npz``, which holds the centreline ``x`` and the eccentric
      line ``eccentric`` (and the imposed twist ``phi``, see :func:`load_joint_twist`).
      ``array`` is ignored for the other formats.

    Returns a float array (N, 3). Raises ValueError naming the file and the problem: unknown
    extension, missing x/y/z columns, an .npz without the named array, a non-numeric value, wrong
    shape, fewer than 4 points, non-finite values.
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext == ".csv":
        pts = _read_csv(path)
    elif ext == ".npy":
        try:
            pts = np.load(path, allow_pickle=False)
        except ValueError as err:
            raise ValueError(f"{path}: not a numeric .npy array ({err})") from None
        if pts.dtype.kind not in "biuf":
            raise ValueError(f"{path}: array of dtype {pts.dtype} is not numeric")
    elif ext == ".npz":
        arrays = _read_npz(path)
        if array not in arrays:
            held = ", ".join(sorted(arrays)) or "nothing"
            raise ValueError(f"{path}: no array {array!r} in this .npz (it holds {held}); a study's step file "
                             "(steps/*.npz) holds the centreline 'x' and the eccentric line 'eccentric'")
        pts = arrays[array]
        if pts.dtype.kind not in "biuf":
            raise ValueError(f"{path}: array {array!r} of dtype {pts.dtype} is not numeric")
        return _check_points("polyline", pts, source=f"{path} (array {array!r})")
    else:
        raise ValueError(f"{path}: unknown file extension {ext!r} (expected .csv, .npy or .npz)")
    return _check_points("polyline", pts, source=path)


def load_joint_twist(path):
    """The imposed twist ``phi`` (radians) stored in a study's step file (``steps/*.npz``), for
    :func:`analyze`'s ``joint_twist``; None if ``path`` is not an .npz or holds no ``phi``.
    Raises ValueError (naming the file) for a ``phi`` that is not one finite number."""
    path = os.fspath(path)
    if os.path.splitext(path)[1].lower() != ".npz":
        return None
    arrays = _read_npz(path)
    if "phi" not in arrays:
        return None
    phi = arrays["phi"]
    if phi.dtype.kind not in "biuf" or phi.size != 1 or not np.isfinite(phi).all():
        raise ValueError(f"{path}: array 'phi' must be one finite number (the imposed twist, radians)")
    return float(phi.reshape(()))


def write_profiles_csv(result, path):
    """Write the profiles of a :class:`RodAnalysis` as plain CSV: a header ``s,kappa1,kappa2,tau,kappa``
    and one row per node (17 significant digits, so the numbers round-trip exactly)."""
    if not isinstance(result, RodAnalysis):
        raise TypeError(f"result must be a RodAnalysis, got {type(result).__name__}")
    cols = ("s", "kappa1", "kappa2", "tau", "kappa")
    data = np.stack([np.asarray(getattr(result, c), dtype=float) for c in cols], axis=1)
    with open(os.fspath(path), "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(cols)
        for row in data:
            writer.writerow([repr(float(v)) for v in row])
