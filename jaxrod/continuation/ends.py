"""Where a followed stable branch ends: the critical modes and eigenvalue (``_critical_mode``),
the next twist to try while the end is bracketed (``end_trial``, from ``end_estimate``), phi* in
the bracket (``branch_end_in_bracket``), and the near-zero band of a knot's sliding modes, which
must not hide a mode that changes the shape (``_hidden_shape_modes``, ``eigenvalue_past_zero``)."""
from __future__ import annotations

import math
import warnings

import numpy as np

from ..linalg.stability import DEFAULT_NEGATIVE_TOL, band_shape_modes, shape_modes_in_band, without_slide
from .engine import StepFailure, _Refusal
from .results import Instability


# A state's eigenvector belongs to the critical modes when its projection on them has at least this norm.
_CRITICAL_OVERLAP = 0.5


def warn_if_band_hides_shape_modes(scene, branch, e, opts, warned):
    """Warn (once per branch) when a state reported stable has a shape mode (not a slide) negative
    inside the near-zero band (``stability.shape_modes_in_band``): the branch may have ended."""
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
    """(lowest eigenvalue, eigenvectors (n, m)) of the equilibrium e's shape modes negative inside
    the near-zero band, or None (none, no band, no stability, or no contact)."""
    if e is None or e.stability is None or not engine.contact or not engine.opts.negative_tol > DEFAULT_NEGATIVE_TOL:
        return None
    values, _, vectors = band_shape_modes(engine.scene, e, engine.opts.negative_tol)
    if not values.size:
        return None
    return float(np.min(values)), vectors.copy()


def negative_modes(e, negative_tol):
    """(n, m) eigenvectors of the equilibrium e's eigenvalues below -negative_tol, or None."""
    if e is None or e.stability is None:
        return None
    st = e.stability
    neg = np.asarray(st.eigenvalues) < -negative_tol
    if not np.any(neg):
        return None
    return np.asarray(st.eigenvectors)[:, neg].copy()


def eigenvalue_past_zero(critical_modes, e, scene=None, band=None):
    """The eigenvalue of the equilibrium e that is negative along ``critical_modes`` ((n, m), or
    None), or None: e is then past the zero of the critical eigenvalue, though the near-zero band
    (there for a loose knot's sliding modes) let it pass the stability test. With ``scene`` (a
    knot with contact) and ``band`` the slide is split off e's eigenpairs first
    (``stability.without_slide``), so that critical modes mixed with the slide do not find the
    slide itself negative."""
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
    """(lambda_prev, lambda_older, eigenvector) of the lowest modes of ``prev`` above the near-zero
    band (or inside it, along ``critical_modes``), each matched in ``older`` by eigenvector overlap."""
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


def end_estimate(older, prev, phi_lost, lost_eq, direction, negative_tol, critical_modes=None):
    """The nearest twist at which a critical eigenvalue of the last stable state ``prev`` is
    modelled to reach zero, or None (no model). Near a fold lambda^2 is linear in phi: its secant
    through ``older`` and ``prev`` gives phi* (short of it at a transversal crossing). Where the
    lost state at ``phi_lost`` has that eigenvalue negative (a crossing), lambda is interpolated
    linearly between the two ends instead."""
    if older is None or older.phi == prev.phi:
        return None
    estimates = []
    for lam, lam_old, v in _critical_candidates(older, prev, negative_tol, critical_modes=critical_modes):
        if lam <= 0.0:
            continue
        if lost_eq is not None and lost_eq.stability is not None:
            ov = np.abs(np.asarray(lost_eq.stability.eigenvectors).T @ v)
            lam_lost = float(lost_eq.stability.eigenvalues[int(np.argmax(ov))])
            if lam_lost < 0.0 and ov.max() > _CRITICAL_OVERLAP:
                # past the end, even inside the near-zero band (``eigenvalue_past_zero``)
                estimates.append(prev.phi + (phi_lost - prev.phi) * lam / (lam - lam_lost))
                continue
        slope = (lam**2 - lam_old**2) / (prev.phi - older.phi)  # d(lambda^2)/dphi
        if direction * slope < 0.0 and lam < lam_old:
            estimates.append(prev.phi - lam**2 / slope)
    return min(estimates, key=lambda p: direction * (p - prev.phi)) if estimates else None


def end_trial(older, prev, phi_lost, lost_eq, direction, tol, negative_tol, failures, probe_held, successes=0,
               critical_modes=None):
    """The next twist to try between the last stable state ``prev`` and the nearest lost twist
    ``phi_lost``. Returns (phi, probe). The trial aims 0.3 tol short of the modelled zero
    (``end_estimate``), or, when the stable end is already there, probes 0.9 tol beyond it
    (probe = True). Bisection when there is no model, after two failures or two successes in a
    row, after a probe that held, or when the model lands outside the inner 90% of the bracket."""
    width = direction * (phi_lost - prev.phi)
    mid = prev.phi + 0.5 * direction * width
    if failures >= 2 or successes >= 2 or probe_held:
        return mid, False
    est = end_estimate(older, prev, phi_lost, lost_eq, direction, negative_tol, critical_modes)
    if est is None:
        return mid, False
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
    nearest lost twist ``phi_lost``: the Newton extrapolation phi_stable - lam/dlam where it lands
    inside the bracket, else the midpoint; the error is the distance to the bracket's far end."""
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
    eigenvalues, the one that reaches zero first extrapolated with its secant rate from ``older``
    (which also holds at a fold), else with the autodiff derivative. multiplicity: how many reach
    zero within a factor 3. Returns an Instability with dlambda_dphi and dlambda_dphi_secant."""
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

