"""The first instability of a branch followed in a second parameter, through changes of its kind.

``fold_curve`` and ``branch_point_curve`` continue one event on its own extended system. On a
loose knot that is not enough to draw phi*(D/L): the knot has a sliding mode
whose eigenvalue (~1e-9 in scaled units) is far below the fold system's conditioning, so Newton on
(F, sigma) = 0 at a new D drifts onto the slide's singular set (measured at N = 128: after one
step of 0.001 L in D, a "fold" with a negative shape eigenvalue -6e-6 and the slide at 2e-9), and
over the range the first instability changes kind (a fold, then a branch point where a second
shape mode comes down first).

``event_curve`` therefore corrects along the branch itself, where the soft-aware locators of
``continuation`` work: at each new mu it

1. predicts the state a distance ``delta`` before the event from the last one, shifted in p by
   (mu - mu_prev) dp*/dmu (the implicit function theorem on the last event's extended system), so
   that the gap to the event is kept;
2. corrects it at that p with the args at the new mu (a knot's neighbourhood rebuilt for the new
   diameter), checks that it is still on the stable part of the branch (Morse index 0), and
   backs off (4 delta, 16 delta) if an event has already passed it;
3. runs the pseudo-arclength continuation in p from there until the first event that changes the
   Morse index of the shape modes: a fold (F, sigma) = 0 or a branch point (F + beta v, sigma, tau)
   = 0, each located by Newton on its own extended system (soft folds of the slide are crossed, not
   counted);
4. takes dp*/dmu at the located event from the implicit function theorem on that event's system
   (``fold_sensitivity``, ``branch_point_sensitivity``).

It is natural-parameter continuation in mu whose corrector is the event locator on the branch in
p, and nothing assumes the kind stays the same: a change of kind, or a jump of the first
instability to another event (two event curves crossing), shows in the rows (``kind``, and p*
against the prediction). It follows the branch through its start, not the branch from p = 0 at
each mu: where the problem has many nearly equal equilibria (a loose knot's placements of its
nodes along the slide) the two can differ, so it does not guarantee a point study's value at each
mu (``jaxrod.studies.critical_curve`` runs a point study per ratio for that).
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

    path: the ContinuationOptions of the short runs in p (ds, whose sign is the direction in p
    towards the event, ds_max, tolerances, p bounds); algorithm: their PseudoArclength; delta: the
    gap in p kept between the start of each run and the event (> 0); max_jump: a start that
    relaxes further than this (max-norm in u) from the last one has left the branch (buckled,
    being past the event) and is refused (the start backs off); chunk / max_points: continuation
    points per call / at most per try.
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

    kind ("fold" or "branch_point"), p (the critical p), morse_before/after across it,
    critical_eigenvalue and residual of its extended system, dp_dmu from the implicit function
    theorem, u (n,) the located state, predicted: the p the curve's predictor gave, seconds: wall
    time for this point, back_offs: how often the start had to back off, points: continuation
    points computed; anchor_u (n,), anchor_p: the stable state before the event from which the
    next mu starts (a start for a point study next to this one); predictor: what moved the start
    to this mu: "ift" (the last point's dp*/dmu), "secant" (the last two points' p*) or "none"
    (the last point's anchor as it is: the first point, or the two others failed); symmetric: the
    start was projected onto the problem's symmetric states (``BifurcationProblem.symmetrize``; False
    where the problem has none, the last anchor was off it, or no event was located on it).
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
    implicit function theorem on the unfolded system (F + beta v0, sigma, tau) = 0 in (u, p, beta)
    (see ``branch_point_curve``), one solve with its Jacobian."""
    v0 = np.asarray(event.v[:, 0]) / np.linalg.norm(event.v[:, 0])
    _, A, a, _ = _branch_point_system(problem, set_mu, problem.args, event.u, event.p, 0.0, mu0, v0, v0)
    dx = np.linalg.solve(np.asarray(A), -np.asarray(a))
    return float(dx[problem.n])


def first_event(branch):
    """The first located shape event (fold or branch point that changes the Morse index) of a
    Branch, or None."""
    for ev in branch.events:
        if ev.kind in SHAPE_EVENTS and ev.converged and ev.morse_before != ev.morse_after:
            return ev
    return None


def _shorter(opts, factor=4.0):
    ds_max = opts.ds_max / factor
    return replace(opts, ds_max=ds_max, ds=float(np.sign(opts.ds)) * min(abs(opts.ds), ds_max))


def relax_problem(problem, u, p, symmetric=False):
    """A minimum of E(., p) with the problem's args, from u (damped Newton, the structured
    Hessian if the problem has one; args refreshed by ``update_args`` and the relaxation repeated
    while they change). The start at a new mu: Newton on F = 0 from the old state can fail where
    the new diameter pushes strands into contact; the state is stable there, so a minimiser gets
    it. Returns u as it is when the problem has no energy.

    symmetric: u is on the problem's symmetric states (``_on_symmetry``); the minimiser's result
    is then projected back onto them (the problem's ``symmetrize`` hook). A loose
    knot's slide is odd under the symmetry and nearly null, so the minimiser drifts along it by
    round-off (the trefoil at N = 128, D/L = 0.010: 0.042 edges), onto another placement of the
    nodes along the same shape, where the event lies elsewhere (3e-4 pi on the opening side); the
    projection keeps every mu's event on the one symmetric branch, as a point study finds it."""
    if problem.update_args is not None:
        problem.args = problem.update_args(u, p, problem.args)
    if problem.energy is None:
        return u
    sol, problem.args = problem.relax(jnp.asarray(u), p, problem.args, gtol=1e-10)
    # not converged or not: the run's first corrector puts the start on F = 0 at p, or refuses it
    y = np.asarray(sol.y)
    if symmetric:
        projected = problem.symmetrize(y, np.inf)
        if projected is not None and np.all(np.isfinite(projected)):
            y = projected
            if problem.update_args is not None:
                problem.args = problem.update_args(y, p, problem.args)
    return y


def _on_symmetry(problem, u):
    """Whether u is within SYMMETRIC_TOL of the problem's symmetric states (its ``symmetrize`` hook)."""
    return problem.symmetrize is not None and problem.symmetrize(np.asarray(u), SYMMETRIC_TOL) is not None


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
    steps). First the implicit function theorem's shift (mu - mu_prev) dp*/dmu, that keeps the gap to
    the event, backed off 3 delta, then with shorter steps, then 15 delta back. Where the event's
    system is nearly singular (a branch point of a nearly degenerate pair: the slope measured -7570
    pi on the trefoil's tightening side at D/L = 0.039, N = 128) that shift throws the start far off
    the branch and every back-off keeps it; then the secant of the last two events, then no shift
    at all (the last anchor, delta before the last event), each backed off 15 delta with short steps
    if it fails as well."""
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
    as for ``fold_curve`` (absolute, e.g. ``jaxrod.continuation.arclength.rods.set_diameter``). mus: the values
    of mu to visit, in order (each step from the previous one; start them next to mu0).
    options: an ``EventCurveOptions``. observer(EventCurvePoint), if given, after each point;
    progress(str), if given, a line per try that found no event (why, and what comes next).
    To resume, give as ``start`` the ``EventCurvePoint`` list of an earlier run of the same curve
    (its points on file, in order; at least the last, and the one before it for the secant
    predictor): the run goes on from the last as the earlier run would have (its anchor state,
    event and slope) over ``mus``, the values after it; mu0 is then not visited again.

    Returns an EventCurve; a mu at which no event is found (or the start cannot be corrected) ends
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
    first (each start projected back onto it); where no try locates an event there, all of them
    again without the projection, as the curve was followed before it: the trefoil at N = 128
    has brackets on the symmetric branch where the Morse index changes with no singular point of
    J (the slide split off on one side and not on the other), and the curve from D/L = 0.0274
    stopped at 0.030 on the tightening side with the projection alone. -> _Located."""
    passes = (True, False) if _on_symmetry(problem, u_b) else (False,)
    for keep in passes:
        found = _try_starts(problem, set_mu, mu, u_b, p_b, tries, keep, options, direction, progress)
        if found.event is not None:
            break
        if keep and progress is not None:
            progress(f"mu = {mu:.9g}: no event located on the symmetry; the tries again without the projection")
    return found


def _try_starts(problem, set_mu, mu, u_b, p_b, tries, keep, options, direction, progress):
    """The tries at mu in order until one locates an event. -> _Located of that try, else of the
    last one."""
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
        # a try that found no event (not located next to a slide, or none within max_points)
        # is repeated from a start further back, then with shorter steps: another path to the
        # same event, through other brackets
        ev, points, morse0, message = _run_to_event(problem, options.algorithm, _shorter(opts) if shorter else opts,
                                                     u_start, p_start, direction, options.chunk, options.max_points)
        found = _Located(ev, points, morse0, message, predictor, shift, back_offs, keep)
        if ev is not None:
            break
        if progress is not None:
            progress(f"mu = {mu:.9g}, start p = {p_start:.9g} ({predictor} predictor): {message} "
                     f"({len(points)} points); backing off")
    return found
