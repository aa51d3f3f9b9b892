"""``critical_twist``: the first twist where the negative count of the equilibrium branch changes.

It follows the branch in phi (tangent predictor, Newton corrector: ``engine._Engine``) and
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

import numpy as np

from ..solve.equilibrium import EquilibriumOptions, RelaxOptions, relax, solve_equilibrium
from ..solve.solvers import ConvergenceError
from .sparse_branch import solve_equilibrium_sparse
from ..validation import check_finite, refuse_knot
from .engine import _SPARSE_MIN_DOF, _Engine, _grown_engine, _use_sparse
from .memory import check_dense_memory
from .options import Task, checked_options, observed
from .results import CriticalPoint, NoCrossingError


def critical_twist(scene, phi_start=0.0, phi_stop=None, options=None, *, q0=None, observer=None):
    """First phi beyond ``phi_start`` (in the direction of ``phi_stop``, default 8 pi) where the
    negative count of the equilibrium branch changes.

    scene: a scene (not a knot); options: a ``ContinuationOptions`` (step, tol, negative_tol, gtol,
    k, max_refine, linear_algebra; None: the scene-aware defaults defined there); q0: initial
    guess at phi_start (default scene.q_init, relaxed first); observer: an ``Observer`` whose
    ``progress`` (lines) and ``on_step`` (phi, n_negative after every equilibrium of the scan and
    the refinement) are called.

    The scan steps at most ``options.step`` (default |phi_stop - phi_start|/40); it shortens the
    step when the tracked eigenvalue, extrapolated with its derivative, is about to cross (never
    lengthens it: a mode from higher up is still caught by the count). Near-zero modes
    (|lambda| < negative_tol) never count. Scenes with contact get their candidate list rebuilt
    along the way. With linear_algebra "sparse" the stability's eigenvectors are the k lowest
    only, so the crossing mode must be among them: k grows (to the negative count or the tracked
    index plus K_MARGIN) where needed. The dense path refuses a scene whose n x n Hessian does not
    fit in memory (``check_dense_memory``, before anything is compiled). Returns a
    ``CriticalPoint``; raises ``NoCrossingError`` if the count never changes before phi_stop.
    Refuses knots (closed rods with self-contact: ``jaxrod.validation.refuse_knot`` says why and
    what to use instead).
    """
    t0 = time.perf_counter()
    phi_start = check_finite("phi_start", phi_start)
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    if phi_stop == phi_start:
        raise ValueError("phi_stop must differ from phi_start")
    refuse_knot(scene, "critical_twist")
    observer = observed(observer, "critical_twist", ("progress", "on_step"))
    opts = checked_options(options).resolved(scene, Task.CRITICAL_TWIST, abs(phi_stop - phi_start))
    tol, negative_tol, gtol, k, max_step = opts.tol, opts.negative_tol, opts.gtol, opts.k, opts.step
    max_refine = opts.max_refine
    contact = "contact" in scene.terms
    direction = 1.0 if phi_stop > phi_start else -1.0
    min_step = max_step / 16.0
    say = observer.say
    stepped = observer.on_step or (lambda phi, n_negative: None)
    sparse = _use_sparse(scene, opts.linear_algebra)
    if not sparse:
        check_dense_memory(scene)
    engine = _Engine(scene, Task.CRITICAL_TWIST, opts, sparse)
    k_scan = k  # eigenvalues kept per scan entry (the engine may compute more)

    if contact:
        relaxed = relax(scene, phi_start, q0, RelaxOptions(gtol=gtol, with_stability=False))
    elif sparse and scene.n_dof >= _SPARSE_MIN_DOF:
        # Large n: no dense relaxation (O(n^3) per step); Newton from q0 (for rings and straight
        # clamped rods the initial shape already is the equilibrium, up to the twist angles).
        relaxed = solve_equilibrium_sparse(scene, phi_start, q0, gtol=gtol)
    else:
        relaxed = solve_equilibrium(scene, phi_start, q0, EquilibriumOptions(gtol=gtol, with_stability=False))
    start = engine.analysed(relaxed)
    while True:
        count0 = int(start.equilibrium.stability.n_negative)
        # The eigenvalue that crosses next: the lowest one clearly above zero (near-zero modes skipped).
        ev0 = start.equilibrium.stability.eigenvalues
        index = int(np.sum(ev0 < negative_tol)) if ev0.size else 0
        grown = _grown_engine(engine, max(index, count0))
        if grown is engine:
            break
        engine, start = grown, grown.analysed(relaxed)
    if index != 0:
        start = engine.analysed(relaxed, index)
    prev, dq, lam_t, dlam_t = start.equilibrium, start.tangent, start.eigenvalue, start.dlambda_dphi
    scan = [(prev.phi, count0, prev.stability.eigenvalues[:k_scan].copy())]
    say(f"phi = {prev.phi / math.pi:+.4f} pi: {count0} negative, lowest {prev.stability.eigenvalues[0]:.3e}")

    # Scan with a tangent predictor until the count changes.
    h = max_step
    before = None  # the scan state before prev (a fallback stable end for the refinement)
    while True:
        phi_next = prev.phi + direction * h
        if direction * (phi_next - phi_stop) > 1e-12:
            raise NoCrossingError(
                f"negative count stayed {count0} from phi = {phi_start:.6g} to {phi_stop:.6g}"
            )
        s = engine.step(prev, dq, phi_next, index,
                        guess=min(prev.stability.eigenvalues[0], lam_t + dlam_t * (phi_next - prev.phi)))
        if not s.ok:
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
        cur = s.equilibrium
        grown = _grown_engine(engine, int(cur.stability.n_negative))
        if grown is not engine:  # the crossing mode must be among the eigenpairs computed at cur
            engine = grown
            s = engine.analysed(cur, index, guess=cur.stability.eigenvalues[0])
            cur = s.equilibrium
        stepped(cur.phi, int(cur.stability.n_negative))
        scan.append((cur.phi, cur.stability.n_negative, cur.stability.eigenvalues[:k_scan].copy()))
        say(
            f"phi = {cur.phi / math.pi:+.4f} pi: {cur.stability.n_negative} negative, "
            f"lowest {cur.stability.eigenvalues[:3]}"
        )
        if cur.stability.n_negative != count0:
            break
        # Newton-extrapolated crossing of the tracked eigenvalue: aim 10% past it.
        h = max_step
        if s.dlambda_dphi != 0.0:
            ahead = -s.eigenvalue / s.dlambda_dphi * direction
            if ahead > 0.0:
                h = min(max_step, max(min_step, 1.1 * ahead))
        before, prev, dq, lam_t, dlam_t = prev, cur, s.tangent, s.eigenvalue, s.dlambda_dphi

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
    evals = 2
    _, f_hi, _, v_hi, _ = engine.analyse(hi, idx_hi, ref=ref, guess=hi.stability.eigenvalues[0])
    _, f_lo, d_lo, v_lo, dq_lo = engine.analyse(lo, ref=v_hi, guess=lo.stability.eigenvalues[0])
    if np.sign(f_lo) == np.sign(f_hi) and before is not None:
        # The crossing eigenvalue already changed sign at lo but stayed inside the near-zero band
        # (|lambda| < negative_tol, e.g. a soft ring of N ~ 1000, lambda ~ 1e-9): the count missed
        # it there. Take the scan state before as the stable end, so that the bracket holds a sign
        # change (the sign tests below rely on it).
        lo, evals = before, 3
        _, f_lo, d_lo, v_lo, dq_lo = engine.analyse(lo, ref=v_hi, guess=lo.stability.eigenvalues[0])
    if np.sign(f_lo) == np.sign(f_hi):
        # No sign change of the crossing eigenvalue in the bracket: a refinement would converge
        # on a bracket end and report it as phi* (seen: 6.27 pi for 5.20 pi, N = 2000 ring with
        # a fixed negative_tol = 1e-10 far above its eigenvalues).
        raise ConvergenceError(
            f"critical twist: the crossing eigenvalue has the same sign ({f_lo:.3e}, {f_hi:.3e}) at both ends "
            f"of the bracket [{lo.phi:.8g}, {hi.phi:.8g}] where the negative count changed: negative_tol = "
            f"{negative_tol:.3g} is not small against the eigenvalues")
    evals = max(evals, 2)
    bracket = (lo.phi, hi.phi)
    # First guess: Newton from the stable end if it stays inside the bracket, else secant.
    a, b = sorted(bracket)
    phi_c = lo.phi - f_lo / d_lo if d_lo != 0.0 else math.nan
    if not (math.isfinite(phi_c) and a < phi_c < b):
        phi_c = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)
    base, base_dq, v_ref, f_base, d_base = lo, dq_lo, v_lo, f_lo, d_lo
    phi_error = abs(hi.phi - lo.phi)
    for _ in range(max_refine):
        s = engine.step(base, base_dq, phi_c, ref=v_ref,
                        guess=min(base.stability.eigenvalues[0], f_base + d_base * (phi_c - base.phi)))
        if not s.ok:
            raise ConvergenceError(f"critical twist refinement: no equilibrium at phi = {phi_c:.10g} "
                                   f"({s.refusal.detail})")
        e, f_c, d_c, v_c, dq_c = s.equilibrium, s.eigenvalue, s.dlambda_dphi, s.mode, s.tangent
        stepped(e.phi, int(e.stability.n_negative))
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
        base, base_dq, v_ref, f_base, d_base = e, dq_c, v_c, f_c, d_c
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


