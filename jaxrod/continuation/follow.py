"""``follow_twist``: follow a stable branch through its instabilities, with branch switching, as a
loop of ``_Follower.advance`` over ``PathState`` (``ends``: where a branch ends; ``switching``).

Predictor: the branch tangent dq/dphi. Corrector: the damped-Newton minimiser of ``relax``,
which cannot wander onto an unstable branch.
A step is accepted when the corrector converges, the state stays within ``jump_tol`` of the
predicted shape, the linking number is Lk0 + phi/2 pi (closed rods), no eigenvalue is below
-negative_tol (``ContinuationEngine``) and no low shape mode is predicted to cross zero inside
the step (``branch_check``). Otherwise the step is halved; once the failing twist is within
``tol`` of the last accepted one, the branch has ended there.

Branch switching (``switching``, at most options.max_switches times): the predicted state at the
nearest lost twist is pushed by +-``perturbation`` along the critical eigenvector and relaxed;
the lower-energy stable state away from the old branch is the new branch ("buckled",
"buckled2", ...; the direction's sign appended). The run is deterministic, so a resumed run
reports exactly what the uninterrupted one reports after that state.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

from ..solve.equilibrium import Equilibrium, relax
from ..validation import check_finite
from .engine import StepFailure, ContinuationEngine, _Refusal, uses_sparse
from .ends import (_band_detail, _critical_mode, _hidden_refusal, _hidden_shape_modes, branch_end_in_bracket,
                   eigenvalue_past_zero, end_estimate, end_trial, negative_modes, warn_if_band_hides_shape_modes)
from .memory import check_dense_memory
from .options import Task, checked_options, observed
from .kinds import EventKind
from .results import PathPoint, PathStop, TwistPath
from .state import PathState, Phase, _StoredPathState
from .switching import _next_branch_name, _switch_branch


# A step whose corrected state's spectrum is not the predicted one is halved down to the largest
# step over this (``BranchModel.departure``); below, it is accepted with a warning.
DEPARTURE_REFINE = 8.0


def _follow_engine(scene, opts):
    """follow_twist's engine: sparse where ``follows_sparse``, else dense."""
    return ContinuationEngine(scene, Task.FOLLOW_TWIST, opts, follows_sparse(scene, opts.linear_algebra))


def follows_sparse(scene, linear_algebra="auto"):
    """Whether ``follow_twist`` takes the O(n) path on ``scene`` for ``ContinuationOptions.linear_algebra``
    (rods with contact only; else the dense path, whose Hessian must fit in memory)."""
    return scene.has_term("contact") and uses_sparse(scene, linear_algebra)


def follow_twist(scene, phi_start=0.0, phi_stop=None, options=None, *, start=None, observer=None, resume=None):
    """Follow the stable equilibrium branch from phi_start towards phi_stop; where it ends (an
    eigenvalue crosses zero or the branch folds), locate the end to ``options.tol`` and switch
    to the stable buckled branch along the critical eigenvector, then go on.

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod.
    phi_start : float, optional
        Twist of the first state (rad; default 0).
    phi_stop : float, optional
        Twist to reach (rad; default 8 pi); must differ from phi_start.
    options : ContinuationOptions, optional
        step, tol, negative_tol, gtol, jump_tol, k, corrector_max_steps, branch, switch,
        max_switches, perturbation (None: the scene-aware defaults defined there).
    start : Equilibrium or array_like of shape (n_dof,), optional
        An ``Equilibrium`` to begin from (used as is; phi_start is then its phi), or an initial
        guess of the DOFs at phi_start (relaxed first; default ``scene.q_init``).
    observer : Observer, optional
        Its progress, on_point, on_instability and on_state are called.
    resume : PathState, optional
        A state (or ``PathState.from_arrays``) to go on from, in place of phi_start, start and
        options.branch (the same scene, phi_stop and options must be given).

    Returns
    -------
    TwistPath
        ``points`` (a ``PathPoint`` per accepted step), ``instabilities`` (an ``Instability`` per
        branch end met), ``stop`` and ``reason`` (why the path stopped), ``seconds``. A branch
        that cannot be continued ends the path; it does not raise.

    Raises
    ------
    ValueError
        phi_stop equal to phi_start, an unstable starting state, an option out of range or not
        read by this algorithm, or, on the dense path, a scene whose n x n Hessian does not fit
        in memory (``check_dense_memory``, naming N).
    TypeError
        ``options`` or ``observer`` of the wrong type.
    ConvergenceError
        The starting state could not be relaxed.

    Notes
    -----
    The predictor, corrector, step acceptance and branch switching are described in the module
    docstring (``jaxrod.continuation.follow``).
    """
    t0 = time.perf_counter()
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    observer = observed(observer, "follow_twist", ("progress", "on_point", "on_instability", "on_state"))
    opts = checked_options(options)
    if not follows_sparse(scene, opts.linear_algebra or "auto"):
        check_dense_memory(scene)  # the dense path: refuse before anything is compiled
    if resume is not None:
        engine, state = _resumed(scene, opts, phi_stop, resume)
        direction = 1.0 if state.branch.endswith("+") else -1.0
        log = _PathLog(scene, engine.opts, direction, observer)
    else:
        given = isinstance(start, Equilibrium)  # else None or an initial guess of the DOFs
        phi_start = check_finite("phi_start", start.phi if given else phi_start)
        if phi_stop == phi_start:
            raise ValueError("phi_stop must differ from phi_start")
        direction = 1.0 if phi_stop > phi_start else -1.0
        engine = _follow_engine(scene, opts.resolved(scene, Task.FOLLOW_TWIST, abs(phi_stop - phi_start)))
        s = _stable_start(engine, start, phi_start, given)
        log = _PathLog(scene, engine.opts, direction, observer)
        state = log.emit(PathState(phase=Phase.FOLLOW, branch=f"{engine.opts.branch}{'+' if direction > 0 else '-'}",
                                   prev=s.equilibrium, tangent=s.tangent, h=engine.opts.step), s)
        if observer.on_state is not None:
            observer.on_state(state)
    follower = _Follower(engine, phi_stop, direction, log.emit, log.record, observer.say)
    while state.phase is not Phase.DONE:
        state = follower.advance(state)
        if observer.on_state is not None:
            observer.on_state(state)
    return TwistPath(points=log.points, instabilities=log.instabilities, reason=state.reason,
                     seconds=time.perf_counter() - t0, stop=state.stop)


class _PathLog:
    """What a ``follow_twist`` run reports: its points and instabilities, passed on to the
    observer as they come (``warn_if_band_hides_shape_modes`` once per branch)."""

    def __init__(self, scene, opts, direction, observer):
        self.scene, self.opts, self.direction, self.observer = scene, opts, direction, observer
        self.points, self.instabilities = [], []
        self.warned = set()

    def emit(self, state, s):
        """Report the accepted step s as the branch's next point; -> state counting it."""
        e = s.equilibrium
        point = PathPoint(branch=state.branch, equilibrium=e, tangent=s.tangent, scene=self.scene,
                          direction="plus" if self.direction > 0 else "minus")
        self.points.append(point)
        if self.observer.on_point is not None:
            self.observer.on_point(point)
        lam = e.stability.eigenvalues
        self.observer.say(f"[{state.branch}] phi = {e.phi / math.pi:+.5f} pi: E = {e.energy:.6g}, Wr = {e.Wr:.4f}, "
                          f"Tw = {e.Tw:.4f}, {e.stability.n_negative} negative, lowest "
                          + " ".join(f"{v:.2e}" for v in lam[:3]))
        warn_if_band_hides_shape_modes(self.scene, state.branch, e, self.opts, self.warned)
        return replace(state, n_points=state.n_points + 1)

    def record(self, state, inst):
        """Report the instability inst; -> state counting it."""
        self.instabilities.append(inst)
        if self.observer.on_instability is not None:
            self.observer.on_instability(inst)
        return replace(state, n_instabilities=state.n_instabilities + 1)


def _resumed(scene, opts, phi_stop, resume):
    """(engine, state) of a resumed ``follow_twist``; the span only sizes the default step, which
    must match the first run's (same phi_stop)."""
    stored_phi = float(resume.arrays["prev_phi"]) if isinstance(resume, _StoredPathState) else resume.prev.phi
    engine = _follow_engine(scene, opts.resolved(scene, Task.FOLLOW_TWIST, abs(phi_stop - stored_phi) or 1.0))
    return engine, resume.restore(engine) if isinstance(resume, _StoredPathState) else resume


def _stable_start(engine, start, phi_start, given):
    """The analysed stable state a fresh ``follow_twist`` starts from: ``start`` itself if given (an
    ``Equilibrium``), else relaxed at phi_start from it (None: the scene's drawing). ValueError
    when unstable."""
    scene = engine.scene
    if not given:
        q_start = scene.q_init if start is None else start
        e0 = relax(scene, phi_start, q_start, replace(engine.corrector_options, max_steps=None))
        # a start drawn with the joint's two-fold symmetry stays on it (a loose knot's minimiser
        # slides along its near-null slide by round-off, and the events would depend on where)
        kept = engine.kept_symmetric(np.asarray(q_start, dtype=float), e0, phi_start)
    else:
        e0 = kept = start
        if e0.neighbourhood is None:
            e0 = kept = replace(e0, neighbourhood=scene.neighbourhood(e0.q, e0.phi))
    s = engine.analysed(kept)
    if kept is not e0 and s.equilibrium.stability.n_negative:
        # the symmetric state is a saddle of a shape mode: start from the minimum the drift found
        s = engine.analysed(e0)
    if s.equilibrium.stability.n_negative:
        st = s.equilibrium.stability
        raise ValueError(
            f"the starting state at phi = {e0.phi / math.pi:+.6f} pi is unstable ({st.n_negative} negative eigenvalue(s), "
            f"lowest {st.eigenvalues[0]:.3e}): follow_twist follows a stable branch; start from a minimum "
            "(jaxrod.relax_to_minimum)")
    return s


@dataclass(frozen=True)
class _Follower:
    """``follow_twist``'s loop body: ``advance(state)`` -> the next ``PathState``."""

    engine: ContinuationEngine
    phi_stop: float
    direction: float
    emit: object
    record: object
    say: object

    @property
    def _knot(self):
        """The scene if it has contact (for ``eigenvalue_past_zero``), else None."""
        return self.engine.scene if self.engine.contact else None

    def advance(self, state):
        return {Phase.FOLLOW: self._follow, Phase.LOCATE: self._locate, Phase.CONFIRM: self._confirm,
                Phase.END: self._end}[state.phase](state)

    def _accept(self, state, s, **changes):
        state = replace(state, older=state.prev, prev=s.equilibrium, tangent=s.tangent, **changes)
        return self.emit(state, s)

    def _follow(self, state):
        prev, step, direction = state.prev, self.engine.opts.step, self.direction
        if direction * (self.phi_stop - prev.phi) <= 1e-12:
            return replace(state, phase=Phase.DONE, stop=PathStop.PHI_STOP, reason="phi_stop")
        # Steps land on multiples of ``step`` (so whole turns, where the linking number is checked, are visited).
        grid = step * (math.floor(prev.phi / step + 1e-9) + 1 if direction > 0 else math.ceil(prev.phi / step - 1e-9) - 1)
        phi_next = prev.phi + direction * min(state.h, abs(self.phi_stop - prev.phi), abs(grid - prev.phi))
        s = self.engine.step(prev, state.tangent, phi_next)
        hidden = _hidden_shape_modes(self.engine, s.equilibrium) if s.ok else None
        if s.ok and hidden is None:
            gone = s.departure
            if gone is not None and abs(phi_next - prev.phi) > step / DEPARTURE_REFINE:
                self.say(f"[{state.branch}] phi = {phi_next / math.pi:+.5f} pi not as predicted ({gone.detail()}): "
                         "step halved")
                return replace(state, h=0.5 * abs(phi_next - prev.phi))
            self._warn_if_departed(state, s)
            return self._accept(state, s, h=min(step, 2.0 * state.h))
        if hidden is not None:
            # Converged, but a shape mode is negative inside the near-zero band: the branch has ended.
            # Refused as unstable with that mode as the critical one, whose sign the locator tracks.
            s = replace(s, refusal=_hidden_refusal(hidden[0]))
        # Lost at phi_next: shrink the bracket to tol, aiming trials with a model of the critical eigenvalue.
        self.say(f"[{state.branch}] lost at phi = {phi_next / math.pi:+.5f} pi ({s.refusal}); locating the end")
        critical = hidden[1] if hidden is not None else self._critical_modes(s, None)
        band = self.engine.opts.negative_tol
        lam = eigenvalue_past_zero(critical, prev, self._knot, band)
        if lam is not None and state.older is not None and \
                eigenvalue_past_zero(critical, state.older, self._knot, band) is None:
            # The last accepted state is already past zero (inside the band): locate from the one before.
            self.say(f"[{state.branch}] phi = {prev.phi / math.pi:+.5f} pi is past the end already (critical "
                     f"eigenvalue {lam:.3e}); locating it from phi = {state.older.phi / math.pi:+.5f} pi")
            back = self.engine.analysed(state.older)
            return replace(state, phase=Phase.LOCATE, prev=back.equilibrium, tangent=back.tangent, older=None,
                           lost_phi=prev.phi, lost_refusal=_Refusal(StepFailure.UNSTABLE, _band_detail(lam)),
                           lost_equilibrium=prev, lost_from=state.older.phi, failures=0, successes=0,
                           probe_held=False, critical_modes=critical)
        return replace(state, phase=Phase.LOCATE, lost_phi=phi_next, lost_refusal=s.refusal,
                       lost_equilibrium=s.equilibrium, lost_from=prev.phi, failures=0, successes=0, probe_held=False,
                       critical_modes=critical)

    def _warn_if_departed(self, state, s):
        """Warn where the accepted step s departed from the branch (``_Step.departure``)."""
        prev, gone = state.prev, s.departure
        if gone is None:
            return
        phi = s.equilibrium.phi
        warnings.warn(f"[{state.branch}] phi = {prev.phi / math.pi:+.5f} -> {phi / math.pi:+.5f} pi: the corrected state "
                      f"is not the one predicted along the branch ({gone.detail()}) at a step of "
                      f"{abs(phi - prev.phi) / math.pi:.2g} pi; the corrector may have stepped over a fold or slid to "
                      "another placement of the nodes; accepted", stacklevel=3)

    def _critical_modes(self, s, current):
        """``PathState.critical_modes`` after the refused step s: its negative (else hidden shape)
        modes where it converged unstable, else ``current``."""
        if s.refusal is None or s.refusal.failure is not StepFailure.UNSTABLE:
            return current
        if s.refusal.modes is not None:  # predicted to cross zero inside the step (``branch_check``)
            return s.refusal.modes
        found = negative_modes(s.equilibrium, self.engine.opts.negative_tol)
        if found is None:
            hidden = _hidden_shape_modes(self.engine, s.equilibrium)
            found = None if hidden is None else hidden[1]
        return current if found is None else found

    def _unless_past_zero(self, state, s):
        """s, refused (UNSTABLE) if its critical eigenvalue is already negative or a shape mode
        is negative inside the near-zero band."""
        if not s.ok:
            return s
        lam = eigenvalue_past_zero(state.critical_modes, s.equilibrium, self._knot,
                                   self.engine.opts.negative_tol)
        if lam is not None:
            return replace(s, refusal=_Refusal(StepFailure.UNSTABLE, _band_detail(lam)))
        hidden = _hidden_shape_modes(self.engine, s.equilibrium)
        if hidden is not None:
            return replace(s, refusal=_hidden_refusal(hidden[0]))
        return s

    def _bracket_width(self, state):
        """How narrow the bracket of the end being located must get: ``bracket_tol`` where there is
        evidence of a fold or branch point inside it (located exactly afterwards on the extended
        system), else tol. Evidence: the nearest lost twist was measured unstable (an eigenvalue
        past zero), or the corrector left the branch there and the last stable state's critical
        eigenvalue is modelled to reach zero inside the bracket (``end_estimate``: lambda^2 linear
        in phi, a fold). A zero only predicted inside the step is none: the eigenvalue may turn
        before it, as at a slide of the nodes' placement."""
        opts, lost = self.engine.opts, state.lost_refusal
        if opts.bracket_tol == opts.tol or lost.predicted:
            return opts.tol
        if lost.failure is StepFailure.UNSTABLE:
            return opts.bracket_tol
        est = end_estimate(state.older, state.prev, state.lost_phi, state.lost_equilibrium, self.direction,
                           opts.negative_tol, state.critical_modes)
        inside = est is not None and self.direction * (est - state.prev.phi) >= 0.0 and \
            self.direction * (state.lost_phi - est) >= 0.0
        return opts.bracket_tol if inside else opts.tol

    def _locate(self, state):
        tol, prev = self._bracket_width(state), state.prev
        if abs(state.lost_phi - prev.phi) <= tol:
            # Bracketed; a failure met from further back is confirmed from the last stable state.
            return replace(state, phase=Phase.CONFIRM if abs(state.lost_phi - state.lost_from) > tol else Phase.END)
        trial, probe = end_trial(state.older, prev, state.lost_phi, state.lost_equilibrium, self.direction, tol,
                                  self.engine.opts.negative_tol, state.failures, state.probe_held, state.successes,
                                  state.critical_modes)
        s = self._unless_past_zero(state, self.engine.step(prev, state.tangent, trial))
        if s.ok and state.lost_refusal.predicted and \
                self.engine.predicted_crossing(s.equilibrium, s.tangent, state.lost_phi) is None:
            # the predicted zero is no longer predicted: the eigenvalue turned before zero; go on
            self.say(f"[{state.branch}] no zero predicted from phi = {trial / math.pi:+.5f} pi any more: going on")
            self._warn_if_departed(state, s)
            return self._accept(state, s, phase=Phase.FOLLOW, h=self.engine.opts.step, critical_modes=None)
        if s.ok:
            self._warn_if_departed(state, s)
            return self._accept(state, s, failures=0, successes=state.successes + 1, probe_held=probe)
        self.say(f"[{state.branch}] phi = {trial / math.pi:+.5f} pi refused ({s.refusal})")
        return replace(state, lost_phi=trial, lost_refusal=s.refusal, lost_equilibrium=s.equilibrium,
                       lost_from=prev.phi, failures=state.failures + 1, successes=0, probe_held=False,
                       critical_modes=self._critical_modes(s, state.critical_modes))

    def _confirm(self, state):
        s = self._unless_past_zero(state, self.engine.step(state.prev, state.tangent, state.lost_phi))
        if not s.ok:
            return replace(state, phase=Phase.END, lost_refusal=s.refusal, lost_equilibrium=s.equilibrium)
        self._warn_if_departed(state, s)
        self.say(f"[{state.branch}] phi = {state.lost_phi / math.pi:+.5f} pi reached from closer by: going on")
        # The failed step was too long for the predictor, not past the end: go on with half of it.
        h = max(2.0 * self.engine.opts.tol, 0.5 * abs(state.lost_phi - state.lost_from))
        return self._accept(state, s, phase=Phase.FOLLOW, h=h, critical_modes=None)

    def _end(self, state):
        engine, prev, direction, lost_phi = self.engine, state.prev, self.direction, state.lost_phi
        kind = EventKind.UNSTABLE if state.lost_refusal.failure is StepFailure.UNSTABLE else EventKind.JUMP
        inst = _critical_mode(engine, prev, state.older, kind, direction)
        rate = inst.dlambda_dphi if kind is EventKind.UNSTABLE or not math.isfinite(inst.dlambda_dphi_secant) \
            else inst.dlambda_dphi_secant
        phi_c, phi_err = branch_end_in_bracket(prev.phi, lost_phi, inst.eigenvalue, rate, direction)
        inst = replace(inst, phi=phi_c, phi_error=phi_err, bracket=(prev.phi, lost_phi), from_branch=state.branch,
                       negative_tol=engine.opts.negative_tol)
        self.say(f"[{state.branch}] branch ends at phi* = {inst.phi / math.pi:+.6f} pi +- {inst.phi_error / math.pi:.1e} pi "
                 f"({kind}; last: {state.lost_refusal}); critical eigenvalue {inst.eigenvalue:.3e}, "
                 f"d/dphi {inst.dlambda_dphi:.3e}")
        if not engine.opts.switch or state.switches >= engine.opts.max_switches:
            state = self.record(state, inst)
            return replace(state, phase=Phase.DONE, stop=PathStop.BRANCH_ENDED,
                           reason=f"branch ended at phi = {inst.phi / math.pi:+.8f} pi ({kind})")
        found, choice = _switch_branch(engine, prev, state.tangent, lost_phi, inst.mode, state.lost_equilibrium,
                                       self.say)
        inst = replace(inst, switch=choice)
        if found is None:
            state = self.record(replace(state, switches=state.switches + 1), inst)
            return replace(state, phase=Phase.DONE, stop=PathStop.NO_STABLE_BRANCH,
                           reason=f"no stable branch found beyond phi = {lost_phi / math.pi:+.8f} pi")
        new_name = _next_branch_name(state.branch[:-1]) + state.branch[-1]
        state = self.record(state, replace(inst, to_branch=new_name, jumped_to=found.equilibrium))
        state = replace(state, phase=Phase.FOLLOW, branch=new_name, prev=found.equilibrium, tangent=found.tangent,
                        older=None, h=engine.opts.step, switches=state.switches + 1, lost_phi=math.nan,
                        lost_from=math.nan, lost_refusal=None, lost_equilibrium=None, failures=0, successes=0,
                        probe_held=False, critical_modes=None)
        return self.emit(state, found)

