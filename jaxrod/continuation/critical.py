"""``critical_twist``: the first twist where the negative count of the equilibrium branch changes.

It follows the branch in phi (``engine.ContinuationEngine``) and watches the negative count over
the whole spectrum, so a mode that comes down from high up is caught. When the count changes, the
crossing eigenvalue is driven to zero by Newton's method in phi with its derivative along the
branch (``stability.branch_analysis``), safeguarded by the bracket.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..solve.equilibrium import EquilibriumOptions, RelaxOptions, relax, solve_equilibrium
from ..solve.solvers import ConvergenceError
from .sparse_branch import solve_equilibrium_sparse
from ..validation import check_finite, refuse_knot
from .engine import _SPARSE_MIN_DOF, ContinuationEngine, grown_engine, uses_sparse
from .memory import check_dense_memory
from .options import Task, checked_options, observed
from .results import CriticalPoint, NoCrossingError


def critical_twist(scene, phi_start=0.0, phi_stop=None, options=None, *, q0=None, observer=None):
    """First phi beyond ``phi_start`` (in the direction of ``phi_stop``, default 8 pi) where the
    negative count of the equilibrium branch changes.

    scene: a scene (not a knot); options: a ``ContinuationOptions`` (None: the defaults); q0:
    initial guess at phi_start (default scene.q_init, relaxed first); observer: an ``Observer``
    whose ``progress`` and ``on_step`` (phi, n_negative after every equilibrium) are called.
    The scan steps at most ``options.step``, shorter where the tracked eigenvalue, extrapolated,
    is about to cross. Near-zero modes (|lambda| < negative_tol) never count. On the sparse path k
    grows where the crossing mode must be among the computed eigenpairs (``grown_engine``). The
    dense path refuses a scene whose Hessian does not fit in memory (``check_dense_memory``).
    Returns a ``CriticalPoint``; raises ``NoCrossingError`` if the count never changes before
    phi_stop. Refuses knots (``jaxrod.validation.refuse_knot``).
    """
    t0 = time.perf_counter()
    phi_start = check_finite("phi_start", phi_start)
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    if phi_stop == phi_start:
        raise ValueError("phi_stop must differ from phi_start")
    refuse_knot(scene, "critical_twist")
    observer = observed(observer, "critical_twist", ("progress", "on_step"))
    opts = checked_options(options).resolved(scene, Task.CRITICAL_TWIST, abs(phi_stop - phi_start))
    sparse = uses_sparse(scene, opts.linear_algebra)
    if not sparse:
        check_dense_memory(scene)
    search = _CrossingSearch(ContinuationEngine(scene, Task.CRITICAL_TWIST, opts, sparse),
                             1.0 if phi_stop > phi_start else -1.0, observer.say,
                             observer.on_step or (lambda phi, n_negative: None), opts.k)
    relaxed = _relaxed_start(scene, phi_start, q0, opts.gtol, sparse)
    start, count0, index = search.tracking_start(relaxed)
    before, prev, cur, scan = search.scan(start, count0, index, phi_start, phi_stop)
    bracket_ends = search.bracket_ends(before, prev, cur, count0)
    newton, s, bracket, phi_error, evals = search.refine(*bracket_ends)
    # the last Newton update, whose error is quadratically smaller than the bound phi_error
    return CriticalPoint(
        phi=float(newton),
        eigenvalue=float(s.eigenvalue),
        dlambda_dphi=float(s.dlambda_dphi),
        mode=s.mode,
        equilibrium=s.equilibrium,
        multiplicity=abs(cur.stability.n_negative - count0),
        bracket=bracket,
        phi_error=float(phi_error),
        hessian_evaluations=evals,
        scan=scan,
        seconds=time.perf_counter() - t0,
        scene=scene,
    )


def _relaxed_start(scene, phi_start, q0, gtol, sparse):
    """The equilibrium at phi_start that the scan starts from, relaxed or solved from q0."""
    if scene.has_term("contact"):
        return relax(scene, phi_start, q0, RelaxOptions(gtol=gtol, with_stability=False))
    if sparse and scene.n_dof >= _SPARSE_MIN_DOF:
        # large n: Newton from q0, no dense relaxation
        return solve_equilibrium_sparse(scene, phi_start, q0, gtol=gtol)
    return solve_equilibrium(scene, phi_start, q0, EquilibriumOptions(gtol=gtol, with_stability=False))


def _newton_or_secant(lo, hi, f_lo, f_hi, d_lo):
    """The first guess of the crossing in the bracket (lo, hi): Newton from the stable end lo if
    it stays inside the bracket, else the secant."""
    a, b = sorted((lo.phi, hi.phi))
    phi_c = lo.phi - f_lo / d_lo if d_lo != 0.0 else math.nan
    if not (math.isfinite(phi_c) and a < phi_c < b):
        phi_c = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)
    return phi_c


def _safeguarded_newton(phi_c, f_c, d_c, lo, hi, f_lo, f_hi):
    """The next Newton iterate from phi_c, or regula falsi (then bisection) where it leaves the
    bracket (lo, hi)."""
    newton = phi_c - f_c / d_c if d_c != 0.0 else math.nan
    a, b = sorted((lo.phi, hi.phi))
    if not (math.isfinite(newton) and a <= newton <= b):
        newton = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)  # regula falsi fallback
        if not (a < newton < b):
            newton = 0.5 * (a + b)
    return newton


def _crossing_index(cur, count0, negative_tol):
    """The crossing mode's index at the far end cur of the bracket: the negative eigenvalue
    nearest zero where the count went up, else the lowest one clearly above zero."""
    ev_hi = cur.stability.eigenvalues
    neg = np.nonzero(ev_hi < -negative_tol)[0]
    if cur.stability.n_negative > count0 and neg.size:
        return int(neg[-1])
    return int(np.sum(ev_hi < negative_tol))  # the count went down: a negative eigenvalue became positive


@dataclass
class _CrossingSearch:
    """``critical_twist``'s scan and refinement along one branch. ``engine`` grows (more
    eigenpairs, sparse path) where the crossing mode must be among the computed ones."""

    engine: ContinuationEngine
    direction: float
    say: object
    stepped: object
    k_scan: int  # eigenvalues kept per scan entry (the engine may compute more)

    def tracking_start(self, relaxed):
        """(analysed start, negative count, tracked index: the lowest eigenvalue clearly above zero)."""
        start = self.engine.analysed(relaxed)
        while True:
            count0 = int(start.equilibrium.stability.n_negative)
            ev0 = start.equilibrium.stability.eigenvalues
            index = int(np.sum(ev0 < self.engine.opts.negative_tol)) if ev0.size else 0
            grown = grown_engine(self.engine, max(index, count0))
            if grown is self.engine:
                break
            self.engine, start = grown, grown.analysed(relaxed)
        if index != 0:
            start = self.engine.analysed(relaxed, index)
        return start, count0, index

    def scan(self, start, count0, index, phi_start, phi_stop):
        """Step until the negative count changes. -> (before, prev, cur, scan): the state before prev
        (or None), the last state with the start's count, the first with another, and the
        (phi, n_negative, lowest eigenvalues) entries."""
        max_step = self.engine.opts.step
        min_step, direction, k_scan = max_step / 16.0, self.direction, self.k_scan
        prev, dq, lam_t, dlam_t = start.equilibrium, start.tangent, start.eigenvalue, start.dlambda_dphi
        scan = [(prev.phi, count0, prev.stability.eigenvalues[:k_scan].copy())]
        self.say(f"phi = {prev.phi / math.pi:+.4f} pi: {count0} negative, lowest {prev.stability.eigenvalues[0]:.3e}")
        h, before = max_step, None
        while True:
            phi_next = prev.phi + direction * h
            if direction * (phi_next - phi_stop) > 1e-12:
                raise NoCrossingError(
                    f"negative count stayed {count0} from phi = {phi_start / math.pi:+.6f} pi "
                    f"to {phi_stop / math.pi:+.6f} pi"
                )
            s = self.engine.step(prev, dq, phi_next, index,
                                 guess=min(prev.stability.eigenvalues[0], lam_t + dlam_t * (phi_next - prev.phi)))
            if not s.ok:
                h = self._halved(h, prev, phi_next)
                continue
            s = self._grown_for(s, index)
            cur = s.equilibrium
            self.stepped(cur.phi, int(cur.stability.n_negative))
            scan.append((cur.phi, cur.stability.n_negative, cur.stability.eigenvalues[:k_scan].copy()))
            self.say(
                f"phi = {cur.phi / math.pi:+.4f} pi: {cur.stability.n_negative} negative, "
                f"lowest {cur.stability.eigenvalues[:3]}"
            )
            if cur.stability.n_negative != count0:
                return before, prev, cur, scan
            # Newton-extrapolated crossing of the tracked eigenvalue: aim 10% past it.
            h = max_step
            if s.dlambda_dphi != 0.0:
                ahead = -s.eigenvalue / s.dlambda_dphi * direction
                if ahead > 0.0:
                    h = min(max_step, max(min_step, 1.1 * ahead))
            before, prev, dq, lam_t, dlam_t = prev, cur, s.tangent, s.eigenvalue, s.dlambda_dphi

    def _halved(self, h, prev, phi_next):
        """The step halved after a failed corrector; ConvergenceError once even tiny steps fail (a fold)."""
        h *= 0.5
        if h < self.engine.opts.step / 1024.0:
            raise ConvergenceError(
                f"the equilibrium branch could not be followed beyond phi = {prev.phi / math.pi:+.8f} pi: "
                f"steps down to {2 * h:.2e} failed (a fold or a jump?)"
            ) from None
        self.say(f"corrector failed at phi = {phi_next / math.pi:+.4f} pi: step halved to {h:.3e}")
        return h

    def _grown_for(self, s, index):
        """s, analysed again by a grown engine where its negative count needs more eigenpairs."""
        cur = s.equilibrium
        grown = grown_engine(self.engine, int(cur.stability.n_negative))
        if grown is self.engine:
            return s
        self.engine = grown
        return self.engine.analysed(cur, index, guess=cur.stability.eigenvalues[0])

    def bracket_ends(self, before, prev, cur, count0):
        """The bracket (lo, hi) of the crossing, each end analysed on the crossing mode (followed by
        eigenvector overlap). -> (lo, hi, hi's eigenvalue, lo's ``analyse``, Hessian evaluations)."""
        engine, negative_tol = self.engine, self.engine.opts.negative_tol
        lo, hi, evals = prev, cur, 2
        idx_hi = _crossing_index(cur, count0, negative_tol)
        ref = cur.stability.eigenvectors[:, idx_hi]
        _, f_hi, _, v_hi, _ = engine.analyse(hi, idx_hi, ref=ref, guess=hi.stability.eigenvalues[0])
        at_lo = engine.analyse(lo, ref=v_hi, guess=lo.stability.eigenvalues[0])
        if np.sign(at_lo[1]) == np.sign(f_hi) and before is not None:
            # already past zero at lo, inside the near-zero band: the state before is the stable end
            lo, evals = before, 3
            at_lo = engine.analyse(lo, ref=v_hi, guess=lo.stability.eigenvalues[0])
        f_lo = at_lo[1]
        if np.sign(f_lo) == np.sign(f_hi):
            # no sign change: a refinement would converge on a bracket end and report it as phi*
            raise ConvergenceError(
                f"critical twist: the crossing eigenvalue has the same sign ({f_lo:.3e}, {f_hi:.3e}) at both ends "
                f"of the bracket [{lo.phi / math.pi:+.8f}, {hi.phi / math.pi:+.8f}] pi where the negative count "
                f"changed: negative_tol = "
                f"{negative_tol:.3g} is not small against the eigenvalues")
        return lo, hi, f_hi, at_lo, evals

    def refine(self, lo, hi, f_hi, at_lo, evals):
        """Newton on the crossing eigenvalue in phi, safeguarded by the bracket. -> (the last Newton
        update, the last step, the bracket, the last update's size, Hessian evaluations)."""
        engine, opts = self.engine, self.engine.opts
        _, f_lo, d_lo, v_lo, dq_lo = at_lo
        bracket = (lo.phi, hi.phi)
        phi_c = _newton_or_secant(lo, hi, f_lo, f_hi, d_lo)
        base, base_dq, v_ref, f_base, d_base = lo, dq_lo, v_lo, f_lo, d_lo
        for _ in range(opts.max_refine):
            s = engine.step(base, base_dq, phi_c, ref=v_ref,
                            guess=min(base.stability.eigenvalues[0], f_base + d_base * (phi_c - base.phi)))
            if not s.ok:
                raise ConvergenceError(f"critical twist refinement: no equilibrium at phi = {phi_c / math.pi:+.10f} pi "
                                       f"({s.refusal.detail})")
            e, f_c, d_c = s.equilibrium, s.eigenvalue, s.dlambda_dphi
            self.stepped(e.phi, int(e.stability.n_negative))
            evals += 1
            if np.sign(f_c) == np.sign(f_lo):
                lo, f_lo = e, f_c
            else:
                hi, f_hi = e, f_c
            newton = _safeguarded_newton(phi_c, f_c, d_c, lo, hi, f_lo, f_hi)
            phi_error = abs(newton - phi_c)
            base, base_dq, v_ref, f_base, d_base = e, s.tangent, s.mode, f_c, d_c
            self.say(f"refine: phi = {phi_c / math.pi:.12f} pi, eigenvalue {f_c:+.3e}, next step {phi_error:.2e}")
            if phi_error < opts.tol or f_c == 0.0:
                return newton, s, bracket, phi_error, evals
            phi_c = newton
        raise ConvergenceError(
            f"critical twist refinement did not reach tol = {opts.tol:.3g} in {opts.max_refine} steps")
