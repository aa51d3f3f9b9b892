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

The steps live in their own modules: the curves (1-3) in ``curves``, the pairing (4) in
``pairing``, the frame, profiles and turning angles (4-6) in ``frames``, the joint (8) in
``joint``, the checks of the inputs in ``inputs``.

Input files: :func:`load_polyline` (CSV with an x,y,z header or three bare columns; .npy (N,3);
an array of an .npz, e.g. ``x`` and ``eccentric`` of a study's step file ``steps/*.npz``) and
:func:`load_joint_twist` (the step file's imposed twist ``phi``, for ``joint_twist``), module
``polyline_files``. Output: :func:`write_profiles_csv`.

Shape descriptors of a closed curve's periodic profile (e.g. ``RodAnalysis.kappa``):
:func:`symmetry_order` (the dominant Fourier harmonic) and :func:`count_peaks` (prominent maxima),
module ``profiles``.
"""
from __future__ import annotations

import csv
import math
import os
import warnings
from dataclasses import dataclass

import numpy as np

from ..model.topology import gauss_linking_quadrature, linking_number, writhe
from .curves import arclength_parameters, interpolant
from .frames import curvature_and_twist, frame_turning_angles, paired_frame, tangent_and_curvature
from .inputs import check_closed, check_joint_twist, check_modes, check_samples, checked_points, clean_points
from .joint import read_joint
from .pairing import pairing_jumps
from .polyline_files import load_joint_twist, load_polyline
from .profiles import count_peaks, symmetry_order

__all__ = ["RodAnalysis", "analyze", "count_peaks", "load_joint_twist", "load_polyline", "symmetry_order",
           "write_profiles_csv"]

TWO_PI = 2.0 * math.pi


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
    closed = check_closed(closed)
    joint_twist = check_joint_twist(joint_twist, closed)
    c_pts = clean_points("centreline", checked_points("centreline", centreline), closed)
    e_pts = clean_points("eccentric", checked_points("eccentric", eccentric), closed)
    n = check_samples(n_samples, c_pts.shape[0])
    modes = check_modes(smoothing_modes, min(c_pts.shape[0], e_pts.shape[0]), closed)

    # 1-3: interpolate (and smooth), resample the centreline to equal arc length.
    c_curve, c_T = interpolant(c_pts, closed, modes)
    e_curve, e_T = interpolant(e_pts, closed, modes)
    t_nodes, L = arclength_parameters(c_curve, c_T, n, closed)
    x = c_curve(t_nodes)
    h = L / n if closed else L / (n - 1)
    # 4-5: the frame and the profiles.
    d3, xss = tangent_and_curvature(x, h, closed)
    ecc, e_t, crossed, r, d1, d2 = paired_frame(x, d3, e_curve, e_T, closed, max(8 * e_pts.shape[0], 4 * n), L)
    kappa1, kappa2, tau = curvature_and_twist(xss, d1, d2, h, closed)
    s = h * np.arange(n)
    # 6: writhe and twist.
    Wr = float(writhe(x, closed=closed))
    angles = frame_turning_angles(x, d1, d3, closed)
    Tw = float(np.sum(angles) / TWO_PI)
    Tw_integral = _twist_integral(tau, h, closed)
    # 8: the joint: does the line close onto itself smoothly? It spreads over the interpolant's
    # ringing: a few eccentric points (or everywhere, for a Fourier fit).
    joint_notes, joint_jump, line_closes = (), math.nan, True
    if closed:
        width = (n - 1) // 4 if modes is not None else math.ceil(4.5 * n / e_pts.shape[0]) + 2
        joint = read_joint(angles, tau, s, h, width, joint_twist)
        joint_notes, joint_jump, line_closes = joint.notes, joint.jump_turns, joint.line_closes
        if joint.hidden != 0.0:
            Tw += joint.hidden / TWO_PI
            tau = joint.tau
            Tw_integral = _twist_integral(tau, h, closed)
    # 7: linking number of the centreline with the eccentric line.
    Lk_exact, Lk_quad = _linking(x, d3, e_pts, e_curve, e_T, e_t, modes) if closed and line_closes \
        else (math.nan, math.nan)
    found = _data_warnings(c_pts, e_pts, x, r, crossed, closed, Wr + Tw, Lk_exact, L, e_t, e_T, joint_notes)
    arrays = dict(s=s, kappa1=kappa1, kappa2=kappa2, tau=tau, kappa=np.hypot(kappa1, kappa2), d1=d1, d2=d2, d3=d3,
                  x=x, eccentric=ecc, paired=crossed)
    for a in arrays.values():
        a.setflags(write=False)
    return RodAnalysis(**arrays, length=L, closed=closed, Wr=Wr, Tw=Tw, Tw_integral=Tw_integral, Lk_exact=Lk_exact,
                       Lk_quadrature=Lk_quad, Lk_frames=Wr + Tw, warnings=tuple(found), joint_jump=joint_jump,
                       joint_twist=joint_twist)


def _twist_integral(tau, h, closed):
    """(1/2 pi) integral of tau ds: the periodic trapezoid rule (closed), the trapezoid rule (open)."""
    if closed:
        return float(np.sum(tau) * h / TWO_PI)
    return float(np.sum(0.5 * (tau[1:] + tau[:-1])) * h / TWO_PI)


def _linking(x, d3, e_pts, e_curve, e_T, e_t, modes):
    """(exact Gauss linking number, midpoint-rule quadrature) of the closed centreline x with the
    eccentric line (as given, or the smoothed one sampled at as many points), the line oriented
    along the centreline first (its orientation flips the sign)."""
    e_poly = e_pts if modes is None else e_curve(e_T * np.arange(e_pts.shape[0]) / e_pts.shape[0])
    if np.mean(np.sum(e_curve(e_t, 1) * d3, axis=-1)) < 0.0:
        e_poly = e_poly[::-1]  # orient the eccentric line along the centreline
    return float(linking_number(x, e_poly)), float(gauss_linking_quadrature(x, e_poly))


# A closed curve's end gap beyond this many times its median point spacing is not a closed loop.
_OPEN_GAP = 5.0
# An eccentric line drawn on a rod is about as long as its centreline (longer where it winds).
_ECCENTRIC_LENGTH_RANGE = (0.8, 2.0)
# A paired point further than this multiple of the median offset belongs to another strand.
_FAR_PAIRING = 2.0


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
    jumps = pairing_jumps(e_t, e_T, closed) & crossed  # unpaired nodes are reported below
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


# ---------------------------------------------------------------------------- output
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
