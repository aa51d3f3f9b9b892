"""Twist continuation and critical twist.

``critical_twist`` follows an equilibrium branch in phi (tangent predictor, Newton corrector) and
watches the count of negative Hessian eigenvalues over the *whole* spectrum (zero modes removed),
so an unstable mode that comes down from high in the spectrum is caught. When the count changes
between two steps, the crossing eigenvalue (the one with ascending index = the count before) is
driven to zero by Newton's method in phi, using its derivative along the branch from forward-mode
autodiff (``stability.branch_analysis``), safeguarded by the bracket. A handful of
Hessian evaluations reach 1e-10 rad, where bisection would need ~30.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

import jax.numpy as jnp

from .equilibrium import Equilibrium, relax, solve_equilibrium
from .material import check_finite, check_positive
from .solvers import ConvergenceError
from .stability import DEFAULT_NEGATIVE_TOL, branch_analysis

__all__ = ["CriticalPoint", "critical_twist", "NoCrossingError"]


class NoCrossingError(RuntimeError):
    """The negative-eigenvalue count did not change over the scanned range of phi."""


@dataclass(frozen=True)
class CriticalPoint:
    """A twist at which an eigenvalue of the equilibrium branch crosses zero.

    phi: critical twist (rad); eigenvalue: crossing eigenvalue there (~0, dimensionless);
    dlambda_dphi: its derivative along the branch; mode: (n,) critical eigenvector (scaled DOFs);
    equilibrium: the branch state at the last evaluated twist (within phi_error of phi); multiplicity: change of the negative count (2 for a
    degenerate pair, as in the ring); bracket: (phi_a, phi_b) where the count changed;
    phi_error: size of the last Newton correction (an upper bound on the error once converged);
    hessian_evaluations: spectra computed in the refinement (bracket ends included);
    scan: list of (phi, n_negative, lowest eigenvalues), one entry per scan step.
    """

    phi: float
    eigenvalue: float
    dlambda_dphi: float
    mode: np.ndarray
    equilibrium: Equilibrium
    multiplicity: int
    bracket: tuple
    phi_error: float
    hessian_evaluations: int
    scan: list = field(repr=False)
    seconds: float = 0.0
    scene: object = field(default=None, repr=False)  # the scene as used last (fresh contact list)


# Near-zero modes of a loose knot (strands sliding along each other) sit at |lambda| ~ 1e-7 in the
# scaled units and change sign from step to step: with self-contact an eigenvalue counts as
# negative, and enters the branch tangent, only beyond this.
CONTACT_NEGATIVE_TOL = 1e-6
# The corrector's gradient tolerance with contact: the residual along the sliding modes relaxes
# only as fast as their ~1e-8 stiffness allows, and barely couples to the crossing eigenvalue.
# 1e-7 (forces in units of B/l^2) is ~1e-7 of the twist moments in a twisted knot.
CONTACT_GTOL = 1e-7


def _step(scene, phi, q_pred, index, k, negative_tol, fallback_q=None, ref=None, gtol=1e-9):
    """Newton corrector from the predictor (contact list refreshed around the result, and the
    solve repeated if nodes moved beyond the list's skin), then one spectrum. Returns (scene,
    equilibrium with its stability, tracked eigenvalue, its phi-derivative, its eigenvector,
    branch tangent dq/dphi)."""
    contact = "contact" in scene.terms
    near_null = negative_tol if contact else 0.0
    q = q_pred
    for _ in range(20):
        try:
            e = solve_equilibrium(scene, phi, q, method="newton", with_stability=False, near_null_tol=near_null,
                                  gtol=gtol)
        except ConvergenceError:
            if fallback_q is None:
                raise
            e = solve_equilibrium(scene, phi, fallback_q, method="newton", with_stability=False,
                                  near_null_tol=near_null, gtol=gtol)
        if not contact:
            break
        stale = bool(scene.contact_list_stale(jnp.asarray(e.q), phi))
        scene = scene.with_contacts(e.q)
        if not stale:
            break
        q = e.q
    pinv_tol = negative_tol if contact else 0.0
    stab, lam, dlam, v, dq = branch_analysis(
        scene, e.q, phi, index, k=k, tol=negative_tol, ref=ref, pinv_tol=pinv_tol
    )
    return scene, replace(e, stability=stab), lam, dlam, v, dq


def critical_twist(
    scene,
    phi_start=0.0,
    phi_stop=None,
    step=None,
    q0=None,
    tol=1e-6 * math.pi,
    k=8,
    negative_tol=None,
    max_refine=30,
    progress=None,
    gtol=None,
):
    """First phi beyond ``phi_start`` (in the direction of ``phi_stop``) where the negative count
    of the equilibrium branch changes.

    scene: a scene; q0: initial guess at phi_start (default scene.q_init, relaxed first);
    step: largest scan step (default |phi_stop - phi_start|/40); the scan shortens it when the
    tracked eigenvalue, extrapolated with its derivative, is about to cross (never lengthens it:
    a mode from higher up is still caught by the count). tol: requested accuracy in phi.
    negative_tol: an eigenvalue counts as negative below -negative_tol (default 1e-10, or
    CONTACT_NEGATIVE_TOL = 1e-6 for scenes with self-contact, whose sliding modes sit at ~1e-7).
    Scenes with contact get their candidate list rebuilt along the way. gtol: the equilibria's
    gradient tolerance (default 1e-9, or CONTACT_GTOL = 1e-7 with contact).
    progress: optional callable(str) for progress lines. Returns a ``CriticalPoint``; raises
    ``NoCrossingError`` if the count never changes before phi_stop.
    """
    t0 = time.perf_counter()
    phi_start = check_finite("phi_start", phi_start)
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    if phi_stop == phi_start:
        raise ValueError("phi_stop must differ from phi_start")
    tol = check_positive("tol", tol)
    contact = "contact" in scene.terms
    if negative_tol is None:
        negative_tol = CONTACT_NEGATIVE_TOL if contact else DEFAULT_NEGATIVE_TOL
    if gtol is None:
        gtol = CONTACT_GTOL if contact else 1e-9
    direction = 1.0 if phi_stop > phi_start else -1.0
    max_step = abs(phi_stop - phi_start) / 40.0 if step is None else check_positive("step", abs(step))
    min_step = max_step / 16.0
    say = progress or (lambda s: None)

    if contact:
        relaxed, scene = relax(scene, phi_start, q0, with_stability=False, gtol=gtol)
    else:
        relaxed = solve_equilibrium(scene, phi_start, q0, method="auto", with_stability=False, gtol=gtol)
    pinv_tol = negative_tol if contact else 0.0
    st0, _, _, _, dq = branch_analysis(scene, relaxed.q, phi_start, 0, k=k, tol=negative_tol, pinv_tol=pinv_tol)
    count0 = int(st0.n_negative)
    # The eigenvalue that crosses next: the lowest one clearly above zero (near-zero modes skipped).
    index = int(np.sum(st0.eigenvalues < negative_tol)) if st0.eigenvalues.size else 0
    if index != 0:
        st0, _, _, _, dq = branch_analysis(
            scene, relaxed.q, phi_start, index, k=k, tol=negative_tol, pinv_tol=pinv_tol
        )
    prev = replace(relaxed, stability=st0)
    scan = [(prev.phi, count0, prev.stability.eigenvalues.copy())]
    say(f"phi = {prev.phi / math.pi:+.4f} pi: {count0} negative, lowest {prev.stability.eigenvalues[0]:.3e}")

    # Scan with a tangent predictor until the count changes.
    h = max_step
    while True:
        phi_next = prev.phi + direction * h
        if direction * (phi_next - phi_stop) > 1e-12:
            raise NoCrossingError(
                f"negative count stayed {count0} from phi = {phi_start:.6g} to {phi_stop:.6g}"
            )
        try:
            scene, cur, lam_c, dlam_c, _, dq_c = _step(
                scene, phi_next, prev.q + dq * (phi_next - prev.phi), index, k, negative_tol, prev.q, gtol=gtol
            )
        except ConvergenceError:
            # Step-size control: no equilibrium found near the predictor; halve the step. If even
            # tiny steps fail, the branch ends here (a fold: the state must jump elsewhere).
            h *= 0.5
            if h < max_step / 1024.0:
                raise ConvergenceError(
                    f"the equilibrium branch could not be followed beyond phi = {prev.phi:.8g} "
                    f"({prev.phi / math.pi:.6f} pi): steps down to {2 * h:.2e} failed (a fold or a jump?)"
                ) from None
            say(f"corrector failed at phi = {phi_next / math.pi:+.4f} pi: step halved to {h:.3e}")
            continue
        scan.append((cur.phi, cur.stability.n_negative, cur.stability.eigenvalues.copy()))
        say(
            f"phi = {cur.phi / math.pi:+.4f} pi: {cur.stability.n_negative} negative, "
            f"lowest {cur.stability.eigenvalues[:3]}"
        )
        if cur.stability.n_negative != count0:
            break
        # Newton-extrapolated crossing of the tracked eigenvalue: aim 10% past it.
        h = max_step
        if dlam_c != 0.0:
            ahead = -lam_c / dlam_c * direction
            if ahead > 0.0:
                h = min(max_step, max(min_step, 1.1 * ahead))
        prev, dq = cur, dq_c

    # Refine. The crossing mode: at the far end, the negative eigenvalue nearest zero; followed
    # by eigenvector overlap from there on (robust to reordering and to near-zero modes).
    multiplicity = abs(cur.stability.n_negative - count0)
    lo, hi = prev, cur
    ev_hi = cur.stability.eigenvalues
    neg = np.nonzero(ev_hi < -negative_tol)[0]
    if cur.stability.n_negative > count0 and neg.size:
        idx_hi = int(neg[-1])
    else:  # the count went down: a negative eigenvalue became positive
        idx_hi = int(np.sum(ev_hi < negative_tol))
    ref = cur.stability.eigenvectors[:, idx_hi]
    _, f_hi, _, v_hi, _ = branch_analysis(scene, hi.q, hi.phi, idx_hi, k=k, tol=negative_tol, ref=ref,
                                          pinv_tol=negative_tol if contact else 0.0)
    _, f_lo, d_lo, v_lo, dq_lo = branch_analysis(scene, lo.q, lo.phi, 0, k=k, tol=negative_tol, ref=v_hi,
                                                 pinv_tol=negative_tol if contact else 0.0)
    evals = 2
    bracket = (lo.phi, hi.phi)
    # First guess: Newton from the stable end if it stays inside the bracket, else secant.
    a, b = sorted(bracket)
    phi_c = lo.phi - f_lo / d_lo if d_lo != 0.0 else math.nan
    if not (math.isfinite(phi_c) and a < phi_c < b):
        phi_c = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)
    base, base_dq, v_ref = lo, dq_lo, v_lo
    phi_error = abs(hi.phi - lo.phi)
    for _ in range(max_refine):
        scene, e, f_c, d_c, v_c, dq_c = _step(
            scene, phi_c, base.q + base_dq * (phi_c - base.phi), 0, k, negative_tol, base.q, ref=v_ref, gtol=gtol
        )
        evals += 1
        if np.sign(f_c) == np.sign(f_lo):
            lo, f_lo = e, f_c
        else:
            hi, f_hi = e, f_c
        newton = phi_c - f_c / d_c if d_c != 0.0 else math.nan
        a, b = sorted((lo.phi, hi.phi))
        if not (math.isfinite(newton) and a <= newton <= b):
            newton = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)  # regula falsi fallback
            if not (a < newton < b):
                newton = 0.5 * (a + b)
        phi_error = abs(newton - phi_c)
        base, base_dq, v_ref = e, dq_c, v_c
        say(f"refine: phi = {phi_c / math.pi:.12f} pi, eigenvalue {f_c:+.3e}, next step {phi_error:.2e}")
        if phi_error < tol or f_c == 0.0:
            break
        phi_c = newton
    else:
        raise ConvergenceError(f"critical twist refinement did not reach tol = {tol:.3g} in {max_refine} steps")

    # Report the last Newton update: its error is quadratically smaller than phi_error, which
    # stays as a conservative bound.
    return CriticalPoint(
        phi=float(newton),
        eigenvalue=float(f_c),
        dlambda_dphi=float(d_c),
        mode=v_c,
        equilibrium=e,
        multiplicity=multiplicity,
        bracket=bracket,
        phi_error=float(phi_error),
        hessian_evaluations=evals,
        scan=scan,
        seconds=time.perf_counter() - t0,
        scene=scene,
    )
