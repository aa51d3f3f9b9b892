"""Where a followed stable branch ends: the critical modes and eigenvalue (``_critical_mode``),
the next twist to try while the end is bracketed (``end_trial``), phi* in the bracket
(``branch_end_in_bracket``), and the near-zero band of a knot's sliding modes, which must not
hide a mode that changes the shape (``_hidden_shape_modes``, ``eigenvalue_past_zero``)."""
from __future__ import annotations

import math
import warnings

import numpy as np

from ..linalg.stability import DEFAULT_NEGATIVE_TOL, band_shape_modes, shape_modes_in_band, without_slide
from .engine import StepFailure, _Refusal
from .results import Instability


# A state's eigenvector belongs to the critical modes when its projection on them has at least
# this norm (the overlap the end locator uses to match eigenvectors between states).
_CRITICAL_OVERLAP = 0.5


def warn_if_band_hides_shape_modes(scene, branch, e, opts, warned):
    """Warn (once per branch) when a state reported stable has a negative eigenvalue inside the
    near-zero band whose mode changes the shape instead of sliding material along the knot
    (``stability.shape_modes_in_band``): the band, there for sliding modes, may hide a real
    instability, and the branch may have ended before this state."""
    if branch in warned or not opts.negative_tol > DEFAULT_NEGATIVE_TOL:
        return
    hidden = shape_modes_in_band(scene, e, opts.negative_tol)
    if hidden:
        warned.add(branch)
        lam, frac = hidden[0]
        warnings.warn(
            f"{branch} at phi = {e.phi / math.pi:+.5f} pi is reported stable, but {len(hidden)} mode(s) that change "
            f"the shape (not material sliding: sliding fraction {frac:.2f}) have negative eigenvalues inside the "
            f"near-zero band kept for sliding modes (lowest {lam:.2e} > -{opts.negative_tol:.0e}): the branch may "
            "have ended before here, unnoticed", stacklevel=4)


def _hidden_refusal(lam):
    return _Refusal(StepFailure.UNSTABLE, f"a shape mode's eigenvalue {lam:.3e} < 0 inside the near-zero band kept "
                                          "for sliding modes")


def _hidden_shape_modes(engine, e):
    """(lowest eigenvalue, eigenvectors (n, m)) of the equilibrium e's modes that change the
    shape and are negative inside the near-zero band (``stability.shape_modes_in_band``), or None
    (no such mode, no band, no state or stability, or a scene without contact)."""
    if e is None or e.stability is None or not engine.contact or not engine.opts.negative_tol > DEFAULT_NEGATIVE_TOL:
        return None
    values, _, vectors = band_shape_modes(engine.scene, e, engine.opts.negative_tol)
    if not values.size:
        return None
    return float(np.min(values)), vectors.copy()


def negative_modes(e, negative_tol):
    """(n, m) eigenvectors of the equilibrium e's eigenvalues below -negative_tol (the modes that
    made it unstable), or None."""
    if e is None or e.stability is None:
        return None
    st = e.stability
    neg = np.asarray(st.eigenvalues) < -negative_tol
    if not np.any(neg):
        return None
    return np.asarray(st.eigenvectors)[:, neg].copy()


def eigenvalue_past_zero(critical_modes, e, scene=None, band=None):
    """The eigenvalue of the equilibrium e that is negative along ``critical_modes`` ((n, m), or
    None), or None: e is then past the zero of the critical eigenvalue, though the stability test
    (lambda < -negative_tol) passed it. The near-zero band is there for the sliding modes of a
    loose knot (|lambda| ~ 1e-7, changing sign from step to step); the mode that made the branch
    unstable is not one of them, and where it crosses zero is where the branch ends (e.g.
    a critical eigenvalue of slope -1.2e-5 per rad passes -1e-6 only 0.085 rad after zero).
    With ``scene`` (a knot with contact) and ``band`` (the near-zero band's width) the slide is
    split off e's eigenpairs first (``stability.without_slide``): critical modes captured where the
    buckling mode and the slide were mixed must not find the slide itself negative at the next
    state and call it past the end (the trefoil at N = 121 with --step 0.25pi: its tightening end came out at -11.10996 pi,
    0.074 pi before the branch point that the other steps and the extended system locate)."""
    if critical_modes is None or e is None or e.stability is None:
        return None
    st = e.stability
    lam, vec = np.asarray(st.eigenvalues), np.asarray(st.eigenvectors)
    if scene is not None:
        lam, vec = without_slide(scene, e.q, lam, vec, band)
    for j in np.nonzero(lam < 0.0)[0]:
        if np.linalg.norm(critical_modes.T @ vec[:, j]) > _CRITICAL_OVERLAP:
            return float(lam[j])
    return None


def _band_detail(lam):
    return f"the critical eigenvalue is {lam:.3e} < 0 (inside the near-zero band)"


def _critical_candidates(older, prev, negative_tol, candidates=5, critical_modes=None):
    """(lambda_prev, lambda_older, eigenvector) of the lowest eigen-modes of ``prev`` above the
    near-zero band (or inside it, when along ``critical_modes``: the mode that made the branch
    unstable, about to cross zero), each matched in ``older`` by eigenvector overlap (no new
    spectrum needed)."""
    st, so = prev.stability, older.stability
    if st is None or so is None:
        return []
    out = []
    for j in range(min(candidates, len(st.eigenvalues))):
        lam = float(st.eigenvalues[j])
        if abs(lam) <= negative_tol and (critical_modes is None or np.linalg.norm(
                critical_modes.T @ np.asarray(st.eigenvectors[:, j])) <= _CRITICAL_OVERLAP):
            continue
        v = np.asarray(st.eigenvectors[:, j])
        ov = np.abs(np.asarray(so.eigenvectors).T @ v)
        out.append((lam, float(so.eigenvalues[int(np.argmax(ov))]), v))
    return out


def end_trial(older, prev, phi_lost, lost_eq, direction, tol, negative_tol, failures, probe_held, successes=0,
               critical_modes=None):
    """The next twist to try when locating where a branch ends, between the last stable state
    ``prev`` and the nearest twist ``phi_lost`` where the branch was lost. Returns (phi, probe).

    Model: near a fold the critical eigenvalue goes like sqrt(phi* - phi), so lambda^2 is linear
    in phi; its secant through ``older`` and ``prev`` (the mode that reaches zero first) gives
    phi*, never beyond it at a transversal crossing (where it lands short). When the lost state
    is an equilibrium with a negative critical eigenvalue (a crossing), lambda is interpolated
    linearly between the two ends instead, to its zero (``critical_modes``: the modes that made
    the branch unstable, whose eigenvalue is a candidate even inside the near-zero band). The
    trial aims 0.3 tol short of phi*, or, when the stable end is already there, probes 0.9 tol
    beyond it (probe = True), so that a good model closes the bracket to tol in two solves. Safeguards: bisection when there is no model, after two
    failures or two successes in a row (a model that keeps landing short converges on a point
    that is not the end: the stable end would creep towards it), after a probe that held, or
    when the model lands outside the inner 90% of the bracket."""
    width = direction * (phi_lost - prev.phi)
    mid = prev.phi + 0.5 * direction * width
    if failures >= 2 or successes >= 2 or probe_held or older is None or older.phi == prev.phi:
        return mid, False
    estimates = []
    for lam, lam_old, v in _critical_candidates(older, prev, negative_tol, critical_modes=critical_modes):
        if lam <= 0.0:
            continue
        if lost_eq is not None and lost_eq.stability is not None:
            ov = np.abs(np.asarray(lost_eq.stability.eigenvectors).T @ v)
            lam_lost = float(lost_eq.stability.eigenvalues[int(np.argmax(ov))])
            if lam_lost < 0.0 and ov.max() > _CRITICAL_OVERLAP:
                # The branch is lost where lambda passes zero: a state whose critical eigenvalue
                # is negative, even inside the near-zero band, is past the end (``eigenvalue_past_zero``).
                estimates.append(prev.phi + (phi_lost - prev.phi) * lam / (lam - lam_lost))
                continue
        slope = (lam**2 - lam_old**2) / (prev.phi - older.phi)  # d(lambda^2)/dphi
        if direction * slope < 0.0 and lam < lam_old:
            estimates.append(prev.phi - lam**2 / slope)
    if not estimates:
        return mid, False
    est = min(estimates, key=lambda p: direction * (p - prev.phi))
    trial, probe = est - direction * 0.3 * tol, False
    if direction * (trial - prev.phi) < 0.5 * tol:
        trial, probe = prev.phi + direction * 0.9 * tol, True
    inside = direction * (trial - prev.phi) > 0.0 and direction * (phi_lost - trial) > 0.0
    lo, hi = prev.phi + direction * 0.05 * width, phi_lost - direction * 0.05 * width
    if direction * (trial - lo) >= 0.0 and direction * (hi - trial) >= 0.0:
        return trial, probe
    if inside and width < 4.0 * tol:
        return trial, probe
    return mid, False


def branch_end_in_bracket(phi_stable, phi_lost, lam, dlam, direction):
    """(phi*, error) for a branch end bracketed by the last stable twist ``phi_stable`` and the
    nearest twist ``phi_lost`` where the branch was lost: the critical eigenvalue's Newton
    extrapolation phi_stable - lam/dlam from the stable end where it lands inside the bracket (at
    a crossing it is exact to second order; at a fold, where lambda goes like a square root, it
    lands short, inside), otherwise the bracket's midpoint. The end lies in the bracket, so the
    error bound is the distance from phi* to the bracket's far end (half the bracket at the
    midpoint). (An extrapolation behind the stable end, from a critical eigenvalue already
    negative there, used to be taken up to 0.1 pi back: phi* came 0.085 rad before a bracket
    of 4e-4 rad. The end locator now keeps such states out of the stable end: ``eigenvalue_past_zero``.)"""
    a, b = sorted((phi_stable, phi_lost))
    mid = 0.5 * (a + b)
    phi = mid
    if dlam != 0.0 and math.isfinite(dlam) and math.isfinite(lam):
        newton = phi_stable - lam / dlam
        if a <= newton <= b:
            phi = newton
    return phi, max(phi - a, b - phi)


def _critical_mode(engine, prev, older, kind, direction, candidates=5):
    """The critical eigenpair at the last stable state ``prev``: of its lowest ``candidates``
    eigenvalues, the one that reaches zero first when extrapolated with its secant rate from the
    state before (``older``, matched by eigenvector overlap); without ``older``, with the
    autodiff derivative along the branch. The secant also holds at a fold, where the autodiff
    derivative of the fixed-branch linearisation does not (dlambda/dphi diverges there).
    Near-zero sliding modes hardly move with phi, so they lose to the mode really going soft.
    multiplicity: how many approach zero together (within a factor 3 in reach).
    Returns an Instability with dlambda_dphi (autodiff) and dlambda_dphi_secant."""
    st = prev.stability
    ev = st.eigenvalues
    found = []
    for j in range(min(candidates, len(ev))):
        _, lam_j, dlam_j, v_j, _ = engine.analyse(prev, j)
        secant = math.nan
        if older is not None and older.stability is not None and older.phi != prev.phi:
            ov = np.abs(np.asarray(older.stability.eigenvectors).T @ np.asarray(v_j))
            secant = (lam_j - float(older.stability.eigenvalues[int(np.argmax(ov))])) / (prev.phi - older.phi)
        rate = -direction * (secant if math.isfinite(secant) else dlam_j)
        reach = (abs(lam_j) + 1e-12) / rate if rate > 0 else math.inf
        found.append((reach, lam_j, dlam_j, secant, v_j))
    found.sort(key=lambda f: f[0])
    reach, lam, dlam, secant, v = found[0]
    multiplicity = sum(1 for f in found if f[0] <= 3.0 * reach) if math.isfinite(reach) else 1
    return Instability(phi=prev.phi, phi_error=0.0, bracket=(prev.phi, prev.phi), kind=kind,
                       multiplicity=multiplicity, eigenvalue=float(lam), dlambda_dphi=float(dlam),
                       dlambda_dphi_secant=float(secant), mode=np.asarray(v), equilibrium=prev)

