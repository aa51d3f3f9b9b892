"""The first instability of a branch followed in a second parameter, through changes of its kind.

On a loose knot, Newton on one event's extended system (``fold_curve``) drifts onto the slide's
singular set, and the first instability changes kind. ``event_curve`` instead works along the
branch: at each new mu it starts ``delta`` before the event, shifted by (mu - mu_prev) dp*/dmu,
continues in p to the first shape event (located on its own system) and takes dp*/dmu there. It
follows the branch through its start, which can differ from a point study's branch at each mu.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import jax.numpy as jnp
import numpy as np

from ...model.symmetry import SYMMETRIC_TOL
from ..kinds import SHAPE_EVENTS, EventKind
from .continuation import continuation
from ..algorithms import PseudoArclength
from ..options import ContinuationOptions, arclength_options
from .results import Result
from .two_parameter import _branch_point_system, fold_sensitivity

__all__ = ["EventCurve", "EventCurveOptions", "EventCurvePoint", "event_curve", "branch_point_sensitivity",
           "first_event"]


@dataclass(frozen=True)
class EventCurveOptions:
    """Settings of ``event_curve``.

    path: the ContinuationOptions of the runs in p (sign of ds: towards the event); algorithm:
    their PseudoArclength; delta: the gap in p kept before the event (> 0); max_jump: a start that
    relaxes further (max-norm in u) has left the branch; chunk / max_points: points per call / per try.
    """

    path: ContinuationOptions
    delta: float
    algorithm: PseudoArclength = PseudoArclength()
    max_jump: float = float("inf")
    chunk: int = 8
    max_points: int = 60

    def __post_init__(self):
        object.__setattr__(self, "path", arclength_options(self.path))
        if not self.delta > 0:
            raise ValueError(f"delta must be > 0, got {self.delta!r}")
        if not self.max_jump > 0:
            raise ValueError(f"max_jump must be > 0, got {self.max_jump!r}")
        if self.chunk < 2 or self.max_points < self.chunk:
            raise ValueError(f"need chunk >= 2 and max_points >= chunk, got {self.chunk}, {self.max_points}")


@dataclass
class EventCurvePoint:
    """One point of an event curve: the first instability at mu.

    kind, p (the critical p), morse_before/after, critical_eigenvalue and residual of its extended
    system, dp_dmu (implicit function theorem), u (n,) the located state, predicted: the predictor's
    p, seconds, back_offs, points: continuation points computed; anchor_u (n,), anchor_p: where
    the next mu starts; predictor: "ift", "secant" or "none"; symmetric: the start was projected
    onto the problem's symmetric states.
    """

    mu: float
    p: float
    kind: str
    morse_before: int
    morse_after: int
    critical_eigenvalue: float
    residual: float
    dp_dmu: float
    u: np.ndarray
    predicted: float
    seconds: float
    back_offs: int = 0
    points: int = 0
    anchor_u: np.ndarray = None
    anchor_p: float = float("nan")
    predictor: str = "none"
    symmetric: bool = False


@dataclass
class EventCurve:
    """The rows of an event curve in the order computed, and how the curve ended (``result``:
    BOUNDARY when every mu asked for was done, else why not; ``message``)."""

    points: list = field(default_factory=list)
    result: Result = Result.BOUNDARY
    message: str = ""

    def column(self, name):
        return np.array([getattr(q, name) for q in self.points])

    @property
    def mu(self):
        return self.column("mu")

    @property
    def p(self):
        return self.column("p")

    @property
    def dp_dmu(self):
        return self.column("dp_dmu")

    @property
    def kind(self):
        return [q.kind for q in self.points]


def branch_point_sensitivity(problem, event, set_mu, mu0):
    """dp*/dmu at the located simple branch point ``event`` of ``problem`` (args at mu = mu0): the
    implicit function theorem on the unfolded system of ``branch_point_curve``."""
    v0 = np.asarray(event.v[:, 0]) / np.linalg.norm(event.v[:, 0])
    _, A, a, _ = _branch_point_system(problem, set_mu, problem.args, event.u, event.p, 0.0, mu0, v0, v0)
    dx = np.linalg.solve(np.asarray(A), -np.asarray(a))
    return float(dx[problem.n])


def first_event(branch):
    """A Branch's first located fold or branch point that changes the Morse index, or None."""
    for ev in branch.events:
        if ev.kind in SHAPE_EVENTS and ev.converged and ev.morse_before != ev.morse_after:
            return ev
    return None


def _shorter(opts, factor=4.0):
    ds_max = opts.ds_max / factor
    return replace(opts, ds_max=ds_max, ds=float(np.sign(opts.ds)) * min(abs(opts.ds), ds_max))


def relax_problem(problem, u, p, symmetric=False):
    """A minimum of E(., p) with the problem's args, from u (``problem.relax``; u as it is
    without an energy): the start at a new mu, where Newton on F = 0 can fail as the new diameter
    pushes strands into contact. symmetric: u is on the symmetric states; the result is projected
    back onto them, so the minimiser's drift along a loose knot's odd slide does not move the event."""
    if problem.update_args is not None:
        problem.args = problem.update_args(u, p, problem.args)
    if problem.energy is None:
        return u
    sol, problem.args = problem.relax(jnp.asarray(u), p, problem.args, gtol=1e-10)
    y = np.asarray(sol.y)
    if symmetric:
        projected = problem.symmetrize(y, np.inf)
        if projected is not None and np.all(np.isfinite(projected)):
            y = projected
            if problem.update_args is not None:
                problem.args = problem.update_args(y, p, problem.args)
    return y


def _run_to_event(problem, alg, opts, u, p, direction, chunk, max_points):
    """Continue from (u, p) (corrected at that p) towards ``direction`` in p until the first shape
    event; -> (event or None, points, first point's Morse index, message)."""
    t0 = np.zeros(problem.n + 1)
    t0[-1] = direction
    start, points = (u, p, t0), []
    while len(points) < max_points:
        br = continuation(problem, alg, replace(opts, max_steps=chunk), start=start, throw=False)
        if not br.points:
            return None, points, None, br.message
        if not points and br.points[0].morse_index != 0:
            return None, br.points, br.points[0].morse_index, "start past an event"
        offset = len(points) - (1 if points else 0)
        points += br.points[1:] if points else br.points
        ev = first_event(br)
        if ev is not None:
            return replace(ev, step=ev.step + offset), points, points[0].morse_index, ""
        if br.result is not Result.MAX_STEPS:
            return None, points, points[0].morse_index, br.message
        last = points[-1]
        start = (last.u, last.p, last.tangent)
    return None, points, points[0].morse_index, f"no event within {max_points} points"


def _tries(history, mu, mu_prev, slope, delta):
    """The starts tried at a new mu, in order: (predictor, shift in p, gap back from it, shorter
    steps). The implicit-function shift (mu - mu_prev) dp*/dmu with growing back-offs, then (for a
    nearly singular event system, whose slope throws the start off the branch) the secant of the
    last two events, then no shift."""
    h = mu - mu_prev
    first = "ift" if h != 0.0 else "none"  # the first mu: its own start, nothing to predict
    tries = [(first, h * slope, 0.0, False), (first, h * slope, 3.0 * delta, False),
             (first, h * slope, 3.0 * delta, True), (first, h * slope, 15.0 * delta, True)]
    if len(history) >= 2:
        a, b = history[-2], history[-1]
        if b.mu != a.mu:
            secant = h * (b.p - a.p) / (b.mu - a.mu)
            tries += [("secant", secant, 0.0, False), ("secant", secant, 15.0 * delta, True)]
    if h != 0.0:
        tries += [("none", 0.0, 0.0, False), ("none", 0.0, 15.0 * delta, True)]
    return tries


def event_curve(problem, start, set_mu, mu0, mus, options, *, observer=None, progress=None):
    """The first instability of the branch through ``start`` followed over the values ``mus``.

    problem: a BifurcationProblem whose args hold mu = mu0 (e.g. ``knot_problem(...).problem``);
    its args are left at the last mu done. start: (u (n,), p) on the stable part of the branch
    at mu0, before its first event in the direction sign(options.path.ds). set_mu(args, mu) -> args,
    as for ``fold_curve`` (e.g. ``jaxrod.continuation.arclength.rods.set_diameter``). mus: the values
    of mu to visit, in order. options: an ``EventCurveOptions``. observer(EventCurvePoint), if
    given, after each point; progress(str), if given, a line per try that found no event.
    To resume, give as ``start`` the ``EventCurvePoint`` list of an earlier run (at least its last
    two rows) and as ``mus`` the values after it. Returns an EventCurve; a mu at which no event is found (or the start cannot be corrected) ends
    the curve there, with ``result`` and ``message`` saying why.
    """
    delta, direction = options.delta, 1.0 if options.path.ds > 0 else -1.0
    curve = EventCurve()
    history, u_b, p_b, mu_prev, slope, p_star, todo = _starting_anchor(start, mu0, mus)
    for mu in todo:
        t = time.perf_counter()
        found = _event_at(problem, set_mu, mu, u_b, p_b, _tries(history, mu, mu_prev, slope, delta), options,
                          direction, progress)
        ev, points = found.event, found.points
        if ev is None:
            curve.result = Result.CORRECTOR_FAILED if found.morse0 is None else Result.LOCATION_FAILED
            curve.message = f"at mu = {mu:.12g}: {found.message}"
            break
        sens = fold_sensitivity if ev.kind == EventKind.FOLD else branch_point_sensitivity
        slope = sens(problem, ev, set_mu, mu)
        anchor = _next_anchor(points, ev, direction, delta)
        u_b, p_b = np.asarray(anchor.u), float(anchor.p)
        row = EventCurvePoint(mu, float(ev.p), ev.kind, int(ev.morse_before), int(ev.morse_after),
                              float(ev.critical_eigenvalue), float(ev.residual), float(slope), np.asarray(ev.u),
                              p_star + found.shift, time.perf_counter() - t, found.back_offs, len(points), u_b.copy(),
                              p_b, found.predictor, found.symmetric)
        p_star = float(ev.p)
        curve.points.append(row)
        history.append(row)
        if observer is not None:
            observer(row)
        mu_prev = mu
    return curve


def _starting_anchor(start, mu0, mus):
    """Where ``event_curve`` starts: (history, anchor u, anchor p, last mu, last slope, last p*,
    the mu to visit), from a state (u, p) at mu0 or from the rows of an earlier run (resume)."""
    if isinstance(start, EventCurvePoint):
        start = [start]
    history = list(start) if start and all(isinstance(q, EventCurvePoint) for q in start) else []
    resume = history[-1] if history else None
    if resume is None:
        u_b, p_b = np.asarray(start[0], dtype=float), float(start[1])
        return history, u_b, p_b, float(mu0), 0.0, float("nan"), [float(mu0)] + [float(m) for m in mus]
    if resume.anchor_u is None or not np.isfinite(resume.anchor_p):
        raise ValueError("resume: the point has no anchor state (anchor_u, anchor_p) to go on from")
    u_b, p_b = np.asarray(resume.anchor_u, dtype=float), float(resume.anchor_p)
    return history, u_b, p_b, float(resume.mu), float(resume.dp_dmu), float(resume.p), [float(m) for m in mus]


def _next_anchor(points, ev, direction, delta):
    """The next mu's start: the last stable point at least delta before the event (else the
    first point of the run)."""
    before = [q for q in points[:ev.step] if q.morse_index == 0 and direction * (ev.p - q.p) >= delta]
    return before[-1] if before else points[0]


@dataclass(frozen=True)
class _Located:
    """What the tries at one mu found: the event (None: none located), the run's points, the
    Morse index of its first point (None: no start was corrected), why it stopped, and the try:
    its predictor, its shift in p, how many tries came before it, whether it kept the symmetry."""

    event: object
    points: list
    morse0: int | None
    message: str
    predictor: str
    shift: float
    back_offs: int
    symmetric: bool


def _event_at(problem, set_mu, mu, u_b, p_b, tries, options, direction, progress):
    """The first event at mu from the anchor (u_b, p_b), over the ``tries``: on the symmetry
    first, then, where none locates one there, without the projection (some symmetric brackets
    change the Morse index with no singular point of J). -> _Located."""
    on_symmetry = problem.symmetrize is not None and problem.symmetrize(np.asarray(u_b), SYMMETRIC_TOL) is not None
    passes = (True, False) if on_symmetry else (False,)
    for keep in passes:
        found = _try_starts(problem, set_mu, mu, u_b, p_b, tries, keep, options, direction, progress)
        if found.event is not None:
            break
        if keep and progress is not None:
            progress(f"mu = {mu:.9g}: no event located on the symmetry; the tries again without the projection")
    return found


def _try_starts(problem, set_mu, mu, u_b, p_b, tries, keep, options, direction, progress):
    """The tries at mu in order until one locates an event. -> _Located of that try (else the last)."""
    opts, max_jump = options.path, options.max_jump
    for back_offs, (predictor, shift, gap, shorter) in enumerate(tries):
        p_start = p_b + shift - direction * gap
        problem.args = set_mu(problem.args, jnp.asarray(mu))
        u_start = relax_problem(problem, u_b, p_start, symmetric=keep)
        jump = float(np.max(np.abs(u_start - u_b))) if np.all(np.isfinite(u_start)) else np.inf
        if not jump <= max_jump:  # relaxed onto another state (past the event): back off
            found = _Located(None, [], None, f"the start relaxed {jump:.3g} away (max_jump {max_jump:g})",
                             predictor, shift, back_offs, keep)
            continue
        ev, points, morse0, message = _run_to_event(problem, options.algorithm, _shorter(opts) if shorter else opts,
                                                     u_start, p_start, direction, options.chunk, options.max_points)
        found = _Located(ev, points, morse0, message, predictor, shift, back_offs, keep)
        if ev is not None:
            break
        if progress is not None:
            progress(f"mu = {mu:.9g}, start p = {p_start:.9g} ({predictor} predictor): {message} "
                     f"({len(points)} points); backing off")
    return found
