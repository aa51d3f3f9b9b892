"""The whole bifurcation diagram of a twist study: every stable branch's end located exactly, as a
fold or a branch point of the extended system, and the unstable branch beyond it.

A twist study only brackets each branch end to its ``tol``. ``unstable_branches`` follows each
end from the study's last stable state by pseudo-arclength continuation through the end, locates
it by Newton on an extended system (fold or branch point) to ``event_tol``, and goes on along the
unstable branch for ``DiagramOptions.unstable_points`` points.

With the study's folder (``study.out``), it writes there:

* ``branch.csv``: the unstable branches' rows appended (``branch`` 'unstable <from branch>',
  ``morse_index`` counting shape modes only), each with ``branch_id`` and ``arclength`` from the end;
* ``critical.json``: ``events``, one per branch end (kind, phi, critical eigenvalue, residual,
  Morse index before and after, ``state_file`` ``event_<direction>_<i>.npz`` with q, phi, ``mode_q``);
* ``diagram.json``: how each end's path went (points, result, seconds).

A resumed study drops these rows and events (``twist_study``), and they are computed again.
"""
from __future__ import annotations

import copy
import csv
import math
import os
import threading
import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from ..io.atomic import savez as _savez, write_json as _write_json, write_rows as _write_rows
from ..continuation.end_check import VANISHING_EIGENVALUE, study_mode, verify_end
from ..continuation.kinds import SHAPE_EVENTS

__all__ = ["DiagramOptions", "BranchEnd", "EndNotFound", "Diagram", "follow_branch_end", "locate_end", "end_capacity",
           "end_rows", "unstable_branches", "in_bracket", "UNSTABLE_PREFIX", "START_TOL", "twist_message",
           "end_message"]

from ..solve.equilibrium import RelaxOptions, equilibrium_from_solution
from ..io.records import step_record
from ..solve.solvers import Solution
from ..linalg.stability import DEFAULT_NEGATIVE_TOL
from .critical_summary import summarise_critical
from .path_messages import end_message, extra_crossings, twist_message
from .study_files import UNSTABLE_PREFIX, critical_mode, final_header, is_unstable, read_table
from .threads import Cancelled, run_all


# points kept past the event where a followed unstable branch restabilises (DiagramOptions.until_restable)
RESTABLE_KEEP = 3


@dataclass(frozen=True)
class DiagramOptions:
    """How far and how finely each branch end's path is followed.

    unstable_points: points kept on the unstable branch beyond the located end; ds_max: largest
    pseudo-arclength step (scaled DOFs and phi in rad); newton_tol: the corrector's and the
    locators' residual (scaled units), tight because an end next to another singular point is
    ill-conditioned (both it and event_tol raised where the problem's roundoff floor lies above
    them); event_tol: a located end must have its residual and critical eigenvalue below this;
    max_points: points followed before the end, at most; n_eig: eigenpairs kept per point.
    until_restable: instead, follow the unstable branch until its Morse index comes back to 0
    (RESTABLE_KEEP points kept past it, ``BranchEnd.restabilised``) or for ``max_unstable_points``.
    """

    unstable_points: int = 8
    ds_max: float = 0.5
    newton_tol: float = 1e-13
    event_tol: float = 1e-10
    max_points: int = 60
    n_eig: int = 6
    chunk: int = 10
    until_restable: bool = False
    max_unstable_points: int = 400

    def __post_init__(self):
        if not isinstance(self.until_restable, (bool, np.bool_)):
            raise ValueError(f"until_restable must be True or False, got {self.until_restable!r}")
        for name in ("unstable_points", "max_points", "n_eig", "chunk", "max_unstable_points"):
            value = getattr(self, name)
            if not (isinstance(value, (int, np.integer)) and value >= 1):
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("ds_max", "newton_tol", "event_tol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


class EndNotFound(LookupError):
    """A path met no branch end: ``end`` is the ``BranchEnd`` with its points and the reason
    (``end.message``)."""

    def __init__(self, message, end):
        super().__init__(message)
        self.end = end


@dataclass
class BranchEnd:
    """One stable branch's end and the unstable branch beyond it.

    direction: 'plus' or 'minus' (the study's direction); from_branch: the stable branch's name;
    event: the located ``jaxrod.continuation.arclength.Event`` (kind 'fold' or 'branch_point'), or None when
    the path met none (``message`` says why); points: the path's ``jaxrod.continuation.arclength.Point``
    list, from the last stable state through the end onto the unstable branch; rod: the
    ``PinnedRod`` (``rod.q(u)`` gives a point's physical DOFs); seconds: wall time.
    """

    direction: str
    from_branch: str
    event: object
    points: list = field(repr=False)
    rod: object = field(repr=False)
    message: str = ""
    seconds: float = 0.0
    within_bracket: bool | None = None  # whether the located end lies in the study's bracket
    verified: dict | None = None  # ``end_check.verify_end`` at the located state
    confirmed: bool = False  # located, in the study's bracket, and the study's critical mode (``end_check``)
    restabilised: object = None  # with until_restable: the Event where the unstable branch regains stability
    rows: list | None = field(default=None, repr=False)  # ``end_rows``, once computed
    rows_k: tuple | None = field(default=None, repr=False)  # (k, negative_tol) they were computed with

    @property
    def located(self):
        """Whether the end was met and located to the event tolerance."""
        return self.event is not None and bool(self.event.converged)

    def _event_or_reason(self):
        if self.event is None:
            raise EndNotFound(f"no branch end on this path: {self.message or 'none met'}", self)
        return self.event

    @property
    def kind(self):
        """The ``EventKind`` of the end met; raises ``EndNotFound`` (with ``message``) without one."""
        return self._event_or_reason().kind

    @property
    def phi(self):
        """The twist of the end met (rad); raises ``EndNotFound`` (with ``message``) without one."""
        return float(self._event_or_reason().p)

    @property
    def unstable(self):
        """The points beyond the end (Morse index >= 1 right after it)."""
        return [] if self.event is None else self.points[self.event.step:]


@dataclass
class Diagram:
    """ends: a ``BranchEnd`` per instability of the study (critical.json's order); rows: the
    unstable branches' rows (dicts, branch.csv's columns); study: the ``StudyResult`` with them,
    its critical dict holding the located ``events`` and ends (``summarise_critical``)."""

    ends: list
    rows: list = field(repr=False)
    study: object = field(repr=False)
    seconds: float = 0.0


# The smallest step (scaled arclength) down to which a step whose Morse index changes by more than 1
# is halved (``jaxrod.ContinuationOptions.resolve_crossings``).
RESOLVE_CROSSINGS = 1e-5

# The path starts where the study's critical eigenvalue is at least START_EIGENVALUE (scaled units):
# study states are converged to a gradient of 1e-9 only, and Newton moves along a mode by up to
# gradient / eigenvalue, so a smaller eigenvalue could carry the start onto another state.
START_EIGENVALUE = 1e-7
# ... stepping back from the study's last stable state by at most this much twist (rad).
MAX_START_BACK = 0.05 * math.pi

# The residual (scaled units) at which a path's start is accepted when Newton's roundoff floor lies
# above ``DiagramOptions.newton_tol``: the equilibrium solver's own test, so a converged state is a valid start.
START_TOL = RelaxOptions.gtol


def backed_off_start(scene, q, phi, eigenvalue, rate, sign):
    """(q, phi) to start an end's path from: the state itself where ``eigenvalue`` >= START_EIGENVALUE,
    else relaxed at the twist where the linear model (``rate`` = dlambda/dphi) puts it there, stepped
    back against ``sign`` by at most MAX_START_BACK (keeping a joint two-fold symmetry)."""
    from ..continuation.follow import _follow_engine
    from ..continuation.options import ContinuationOptions, Task
    from ..solve.equilibrium import LeftBranchError, TopologyChangeError, relax
    from ..solve.solvers import ConvergenceError
    from ..model.symmetry import SYMMETRIC_TOL, joint_two_fold, symmetrize

    if not (math.isfinite(eigenvalue) and math.isfinite(rate)) or eigenvalue >= START_EIGENVALUE or rate * sign >= 0.0:
        return q, phi
    back = min((START_EIGENVALUE - eigenvalue) / abs(rate), MAX_START_BACK)
    phi_back = phi - sign * back
    edge = float(scene.length) / scene.n_nodes
    # the study's own corrector (the same compiled programs), projected back onto the symmetry
    options = _follow_engine(scene, ContinuationOptions().resolved(scene, Task.FOLLOW_TWIST, 1.0)).corrector_options
    try:
        e = relax(scene, phi_back, np.asarray(q), options)
        if joint_two_fold(scene, q, SYMMETRIC_TOL * edge) is not None:
            e = relax(scene, phi_back, symmetrize(scene, e.q), options, nbr=e.neighbourhood)
    except (ConvergenceError, LeftBranchError, TopologyChangeError) as exc:
        warnings.warn(f"the path to the end is started from the study's last stable state at {phi / math.pi:+.6f} pi, "
                      f"whose critical eigenvalue {eigenvalue:.2g} is below {START_EIGENVALUE:g}: relaxing at "
                      f"{phi_back / math.pi:+.6f} pi failed ({exc}); Newton from it may move onto another state",
                      stacklevel=2)
        return q, phi
    return np.asarray(e.q), float(phi_back)


def follow_branch_end(scene, q, phi, sign, options=None, *, p_min=-math.inf, p_max=math.inf, capacity=None,
                      observer=None):
    """Follow a stable branch from the state (q (n,) physical DOFs, phi) towards its end (phi
    growing when sign > 0, falling when sign < 0) by pseudo-arclength continuation, locate the end
    (the first fold or branch point at which the Morse index grows) and follow the unstable branch
    beyond it for ``options.unstable_points`` points. capacity: the contact list's padded size
    (default: the neighbourhood's own); observer(point): called after each accepted point (raising
    stops the run). The start is corrected to ``options.newton_tol``, or to START_TOL where Newton's
    floor lies above it. Returns a ``BranchEnd`` (direction and from_branch empty); where no end was
    located, ``located`` is False and ``message`` says why."""
    from ..continuation import ContinuationOptions
    from ..continuation.arclength import PseudoArclength, continuation_until, \
        restabilisation
    from ..continuation.arclength.rods import knot_problem

    o = options or DiagramOptions()
    t0 = time.perf_counter()
    rod = knot_problem(scene, np.asarray(q), float(phi), capacity=capacity)
    newton_tol, event_tol = _above_floor(rod.problem, o)
    opts = ContinuationOptions(ds=math.copysign(min(0.05, o.ds_max), sign), ds_min=1e-6, ds_max=o.ds_max,
                            max_steps=o.chunk, newton_tol=newton_tol, eig_rtol=1e-13, k=o.n_eig,
                            event_tol=event_tol, p_min=p_min, p_max=p_max,
                            # retry smaller a step whose Morse index changes by > 1, to separate close events
                            resolve_crossings=RESOLVE_CROSSINGS)
    def stop(points, events):
        end = _first_end(events)
        if end is None:
            return f"no fold or branch point within {len(points)} points" if len(points) >= o.max_points else ""
        past = len(points) - end.step
        if o.until_restable:
            back = restabilisation(events, end.step)
            if back is not None and len(points) - back.step >= RESTABLE_KEEP:
                return f"followed past the end until it restabilised at {back.p / math.pi:+.8f} pi ({back.kind})"
            return f"still unstable {past} points past the end" if past >= o.max_unstable_points else ""
        return "followed past the end" if past >= o.unstable_points else ""

    br = continuation_until(rod.problem, PseudoArclength(), opts, stop, observer=observer,
                            start_tol=max(o.newton_tol, START_TOL))
    points, events, message = br.points, br.events, twist_message(br)
    end = _first_end(events)
    if end is not None and not end.converged:
        if end.residual <= o.event_tol and end.critical_eigenvalue <= o.event_tol:
            # the fold system converged along a sliding mode, not the shape mode that changed the index
            message = (f"the end was detected near {end.p / math.pi:+.8f} pi but not located: the extended system "
                       "converged to a singular point along a sliding mode, not to the shape instability that "
                       "changes the Morse index there")
        else:
            message = (f"the end was detected near {end.p / math.pi:+.8f} pi but not located to event_tol "
                       f"{o.event_tol:.0e} (residual {end.residual:.1e}, eigenvalue {end.critical_eigenvalue:.1e})")
    elif end is not None:
        message = end_message(end, br)
        back = restabilisation(events, end.step) if o.until_restable else None
        if back is not None:  # (a later chunk may have ended otherwise, e.g. at a soft fold past it)
            message = f"followed past the end until it restabilised at {back.p / math.pi:+.8f} pi ({back.kind})"
        points = points[:back.step + RESTABLE_KEEP] if back is not None else points[:end.step + (
            o.max_unstable_points if o.until_restable else o.unstable_points)]
        return BranchEnd("", "", end, points, rod, message, time.perf_counter() - t0, restabilised=back)
    return BranchEnd("", "", end, points, rod, message, time.perf_counter() - t0)


def _above_floor(problem, options):
    """(newton_tol, event_tol): the options' values, raised where the problem's roundoff floor at its
    start lies above them (a loose knot's: eps ||J|| |u| ~ 1e-12 at D/L = 0.01, N = 121), by the rule
    of ``continuation.arclength.scales``; below that floor no corrector step converges."""
    from ..continuation.arclength.scales import EVENT_FLOOR_FACTOR, NEWTON_FLOOR_FACTOR, residual_floor

    floor, _ = residual_floor(problem, problem.u0, problem.p0)
    return max(options.newton_tol, NEWTON_FLOOR_FACTOR * floor), max(options.event_tol, EVENT_FLOOR_FACTOR * floor)


def in_bracket(phi, inst):
    """Whether phi lies where the study places the instability ``inst`` (a critical.json dict):
    within its phi +- phi_error (the whole bracket), to roundoff, or before it on the stable side by
    no more than the eigenvalue band. The study counts a mode negative only below -negative_tol,
    so an eigenvalue crossing zero at the rate dlambda_dphi is seen up to negative_tol /
    |dlambda_dphi| after its zero; twice that is allowed, the rate being itself an estimate. After
    a jump (kind 'jump': the corrector left the branch, no eigenvalue was seen crossing zero), up
    to one bracket width past the twist where the branch was lost is allowed too: the basin of
    the stable state shrinks to nothing at a fold, so a corrector is drawn off a little before it."""
    phi0 = inst["phi"]
    tol = inst["phi_error"] * (1.0 + 1e-9) + 1e-12 * max(1.0, abs(phi0))
    if abs(phi - phi0) <= tol:
        return True
    stable, lost = (list(inst.get("bracket") or ()) + [0.0, 0.0])[:2]
    past_lost = (phi - lost) * math.copysign(1.0, lost - stable)
    if str(inst.get("kind")) == "jump" and 0.0 < past_lost <= abs(lost - stable):
        return True
    rate = abs(float(inst.get("dlambda_dphi") or 0.0))
    band = float(inst.get("negative_tol") or 0.0)
    if stable == lost or not (math.isfinite(rate) and rate > 0.0 and band > 0.0):
        return False
    toward_stable = (phi - phi0) * math.copysign(1.0, stable - lost)
    return 0.0 < toward_stable <= tol + 2.0 * band / rate


def _first_end(events):
    """The first event that costs the branch its stability: a fold or a branch point at which the
    Morse index grows (soft folds of the sliding landscape are crossed, not ends)."""
    return next((e for e in events if e.kind in SHAPE_EVENTS and e.morse_after > e.morse_before), None)


def locate_end(scene, inst, state, options=None, *, p_min, p_max, capacity=None, progress=None, observer=None,
               mode=None):
    """One branch end of a twist study, located exactly, and the unstable branch beyond it.

    inst: the end's critical.json entry; state: (q (n,), phi) the study's last stable state before it
    (None: nothing to start from); p_min, p_max: the study's twist range (widened by 0.5 pi);
    capacity: the contact list's padded size (one per study, to avoid recompiling); mode: (n,) the
    study's critical eigenvector at ``state`` (scaled), checked against the located null vector
    (None: computed there). Warns where the located end lies outside the study's bracket, or is not
    the study's critical mode. Returns a ``BranchEnd``."""
    o = options or DiagramOptions()
    say = progress or (lambda line: None)
    if state is None:
        return BranchEnd(inst["direction"], inst["from_branch"], None, [], None, "no state on file")
    q, phi = state
    lo, hi = inst["bracket"][0], inst["bracket"][1]
    sign = 1.0 if hi > lo else -1.0
    reference = mode if mode is not None else study_mode(scene, q, phi, float(inst.get("eigenvalue", 0.0)))
    q, phi = backed_off_start(scene, q, phi, float(inst.get("eigenvalue", math.nan)),
                              float(inst.get("dlambda_dphi", math.nan)), sign)
    say(f"{inst['direction']}: locating the end of {inst['from_branch']} (bracketed at "
        f"{inst['phi'] / math.pi:+.6f} pi) on the extended system, then its unstable branch")
    end = follow_branch_end(scene, q, phi, sign, o, p_min=min(p_min, phi) - 0.5 * math.pi,
                            p_max=max(p_max, phi) + 0.5 * math.pi, capacity=capacity, observer=observer)
    end.direction, end.from_branch = inst["direction"], inst["from_branch"]
    if end.event is None or not end.event.converged:
        say(f"{inst['direction']}: {end.message}")
        return end
    ev = end.event
    say(f"{inst['direction']}: {ev.kind} at {ev.p / math.pi:+.10f} pi (critical eigenvalue "
        f"{ev.critical_eigenvalue:.1e}, residual {ev.residual:.1e}; the study's bracket said "
        f"{inst['phi'] / math.pi:+.6f} +- {inst['phi_error'] / math.pi:.1e} pi), "
        f"{len(end.unstable)} unstable points, {end.seconds:.1f} s")
    end.within_bracket = in_bracket(ev.p, inst)
    end.verified = verify_end(scene, end.rod.q(ev.u), float(ev.p), reference,
                              band=float(inst.get("negative_tol") or VANISHING_EIGENVALUE))
    v = end.verified
    end.confirmed = bool(end.within_bracket and v["vanishes"] and v["first"])
    if end.within_bracket and not end.confirmed:
        why = "another mode is negative there already" if v["vanishes"] else \
            f"no eigenvalue of the study's Hessian vanishes there (nearest {v['eigenvalue']:.1e})"
        warnings.warn(f"{inst['direction']}: the {ev.kind} located at {ev.p / math.pi:+.8f} pi is not the branch's "
                      f"first instability ({why}): two events lie within the study's bracket; the study's estimate "
                      f"{inst['phi'] / math.pi:+.8f} pi is kept as the onset and both are reported", stacklevel=3)
    extra = extra_crossings(ev)
    if extra:
        warnings.warn(f"{inst['direction']}: {extra}", stacklevel=3)
    if not end.within_bracket:
        message = (f"{inst['direction']}: the end of {inst['from_branch']} located on the extended system, "
                   f"{ev.kind} at {ev.p / math.pi:+.8f} pi, lies outside the study's bracket "
                   f"{inst['phi'] / math.pi:+.8f} +- {inst['phi_error'] / math.pi:.1e} pi: the two methods "
                   "disagree on where the branch ends (a mode the study counted negative that the "
                   "path's shape classification does not, or the path left the study's branch); the "
                   "study's value is kept as phi*")
        warnings.warn(message, stacklevel=3)
    return end


def end_capacity(scene, states):
    """The contact list's padded size for the ends of a study: the largest that any of the end
    states (q, phi) asks for (None entries skipped; None without contact pairs)."""
    return max((scene.neighbourhood(q, phi).capacity for q, phi in filter(None, states)), default=None)


def unstable_branches(scene, study, options=None, *, progress=None, parallel=True, located=None):
    """Locate each branch end of a twist study exactly and follow the unstable branch beyond it.

    study: the ``StudyResult``, whose ``end_states`` hold the last stable state before each
    instability; parallel: the two directions in two threads (same results); located: ends already
    located by ``locate_end``, {(direction, index within direction): BranchEnd}. With ``study.out``
    writes the files of the module docstring. Returns a ``Diagram`` (``study`` itself is unchanged).
    """
    o = options or DiagramOptions()
    say = progress or (lambda line: None)
    t0 = time.perf_counter()
    instabilities = study.critical.get("instabilities", [])
    phis = np.asarray(study.table.get("phi", [0.0]), dtype=float)
    p_min, p_max = float(np.min(phis)), float(np.max(phis))
    cancel = threading.Event()
    located = dict(located or {})

    def stop_if_cancelled(point):
        if cancel.is_set():
            raise Cancelled()

    # the two directions in two threads (XLA and LAPACK release the GIL); Ctrl-C stops both
    ends = [None] * len(instabilities)
    todo, seen = {}, {"plus": 0, "minus": 0}
    for i, (inst, state) in enumerate(zip(instabilities, study.end_states)):
        key = (inst["direction"], seen[inst["direction"]])
        seen[inst["direction"]] += 1
        if key in located:
            ends[i] = located[key]
        else:
            todo.setdefault(inst["direction"], []).append((i, inst, state))
    # one contact-list size for every end: each new array shape compiles every function again
    capacity = end_capacity(scene, study.end_states) if todo else None

    def run_direction(items):
        for i, inst, state in items:
            ends[i] = locate_end(scene, inst, state, o, p_min=p_min, p_max=p_max, capacity=capacity,
                                 progress=say, observer=stop_if_cancelled, mode=critical_mode(study.out, inst))

    run_all(run_direction, [(items,) for items in todo.values()], parallel, cancel)
    rows, table = _unstable_rows(scene, study, ends)
    study = replace(study, table=table, critical=copy.deepcopy(study.critical))
    _write_events(study, ends)
    diagram = Diagram(ends, rows, study, time.perf_counter() - t0)
    if study.out:
        _write_json(os.path.join(study.out, "diagram.json"), _diagram_dict(diagram, o))
    return diagram


def _event_dict(end, index):
    ev = end.event
    d = {"direction": end.direction, "from_branch": end.from_branch, "instability": index,
         "located": ev is not None and bool(ev.converged), "message": end.message}
    if ev is None:
        return d
    d.update({"kind": ev.kind, "phi": float(ev.p), "phi_over_pi": float(ev.p) / math.pi,
              "critical_eigenvalue": ev.critical_eigenvalue, "residual": float(ev.residual),
              "iterations": int(ev.iterations), "multiplicity": int(ev.multiplicity),
              "morse_before": int(ev.morse_before), "morse_after": int(ev.morse_after),
              "full_gradient": end.rod.full_gradient(ev.u, ev.p), "within_bracket": end.within_bracket,
              # the DOF pinned along an exact material slide (large N; full_gradient: its force), or None
              "slide_pin": end.rod.slide_pin,
              # more than the multiplicity: another crossing within the same step (a near-double event)
              "morse_jump": int(ev.morse_after) - int(ev.morse_before),
              "unstable_branch": UNSTABLE_PREFIX + end.from_branch,
              "verified": end.verified, "confirmed": bool(end.confirmed)})
    return d


def _write_events(study, ends):
    """critical.json's ``events`` (and the located states' files), with ``study.out``; the
    study's own critical dict gets them in any case, and its phi_plus/phi_minus become the located values."""
    import json

    events = []
    per_direction = {"plus": 0, "minus": 0}
    for index, end in enumerate(ends):
        d = _event_dict(end, index)
        if end.event is not None:
            i = per_direction[end.direction]
            per_direction[end.direction] += 1
            name = f"event_{end.direction}_{i}.npz"
            ev, rod = end.event, end.rod
            if not study.out:
                events.append(d)
                continue
            v = np.asarray(ev.v)
            full = np.zeros((rod.u_ref.size, v.shape[1]))
            full[np.asarray(rod.free)] = v
            mode_q = np.stack([np.asarray(rod.scene.from_scaled(full[:, j])) - np.asarray(rod.scene.from_scaled(
                np.zeros(rod.u_ref.size))) for j in range(v.shape[1])], axis=1)
            _savez(os.path.join(study.out, name), q=rod.q(ev.u), phi=np.asarray(float(ev.p)), mode_q=mode_q,
                   kind=np.asarray(ev.kind))
            d["state_file"] = name
        events.append(d)
    if not study.out:
        study.critical["events"] = events
        summarise_critical(study.critical, study.table)
        return
    path = os.path.join(study.out, "critical.json")
    with open(path) as f:
        critical = json.load(f)
    for c in (critical, study.critical):
        c["events"] = events
        summarise_critical(c, study.table)
    _write_json(path, critical)


def _diagram_dict(diagram, options):
    from dataclasses import asdict

    def end(e):
        row = {"direction": e.direction, "from_branch": e.from_branch, "kind": None if e.event is None else e.kind,
               "phi_over_pi": None if e.event is None else e.phi / math.pi, "points": len(e.points),
               "unstable_points": len(e.unstable), "message": e.message, "seconds": e.seconds,
               # whether this end is the study's instability, confirmed (``end_check``), and what vanishes there
               "located": e.event is not None and bool(e.event.converged), "confirmed": bool(e.confirmed),
               "verified": e.verified}
        if options.until_restable:
            back = e.restabilised
            row["restabilised"] = None if back is None else {
                "kind": back.kind, "phi_over_pi": float(back.p) / math.pi, "morse_before": int(back.morse_before),
                "critical_eigenvalue": float(np.max(np.abs(back.critical_eigenvalue))), "residual": float(back.residual)}
        return row

    critical = diagram.study.critical
    # each side's first instability, as critical.json and the summary give it (``end_check.onset_events``)
    onsets = {side: (critical.get(f"phi_{side}_events") or [None])[0] for side in ("plus", "minus")}
    return {"options": asdict(options), "seconds": diagram.seconds, "onsets": onsets,
            "ends": [end(e) for e in diagram.ends]}


def end_rows(scene, end, k, negative_tol):
    """The rows of a located end's unstable branch (the end itself at arclength 0, then the path
    beyond it), in branch.csv's columns but ``branch_id``: each state's ``step_record``, with
    ``morse_index``, ``n_negative`` and ``stable`` from the path. Kept on ``end.rows``; returns them."""
    rod, ev = end.rod, end.event
    before = end.points[ev.step - 1]
    s_end = before.arclength + float(np.linalg.norm(np.append(ev.u - before.u, ev.p - before.p)))
    path = [(ev.u, float(ev.p), 0.0, ev.morse_before, 0, float(rod.full_gradient(ev.u, ev.p)))]
    path += [(pt.u, float(pt.p), pt.arclength - s_end, pt.morse_index, pt.iterations,
              float(rod.full_gradient(pt.u, pt.p))) for pt in end.unstable]
    name = UNSTABLE_PREFIX + end.from_branch
    rows = []
    for u, phi, s, morse, iterations, grad in path:
        q = rod.q(u)
        nbr = scene.neighbourhood(q, phi, capacity=rod.problem.args.nbr.capacity)
        sol = Solution(y=np.asarray(scene.to_scaled(q)), value=math.nan, grad_norm=grad, iterations=int(iterations),
                       converged=True, reason="converged", solver="pseudo-arclength", gtol=math.nan)
        e = equilibrium_from_solution(scene, phi, sol, nbr, k=k, negative_tol=negative_tol)
        row, _ = step_record(scene, e, branch=name)
        row.update(direction=end.direction, arclength=s, morse_index=int(morse), n_negative=int(morse),
                   stable=int(morse == 0))
        rows.append(row)
    end.rows, end.rows_k = rows, (k, negative_tol)
    return rows


def _unstable_rows(scene, study, ends):
    """The unstable branches' rows (``end_rows``), appended to branch.csv with ``study.out``.
    Returns (rows, ``study.table`` with them)."""
    k = sum(1 for key in study.table if key.startswith("lambda_"))
    header = final_header(k)
    ids = study.table.get("branch_id")
    next_id = int(np.nanmax(ids)) + 1 if ids is not None and len(ids) else 0
    negative_tol = study.critical.get("negative_tol", DEFAULT_NEGATIVE_TOL)
    rows = []
    for end in ends:
        if end.event is None or not end.event.converged:
            continue
        if end.rows is None or end.rows_k != (k, negative_tol):
            end_rows(scene, end, k, negative_tol)
        for row in end.rows:
            rows.append(dict(row, branch_id=next_id))
        next_id += 1
    if study.out:
        csv_path = os.path.join(study.out, "branch.csv")
        with open(csv_path, newline="") as f:
            kept = [r for r in csv.DictReader(f) if not is_unstable(r)]
        _write_rows(csv_path, header, kept + [{key: "" if isinstance(v, float) and math.isnan(v) else v
                                               for key, v in r.items()} for r in rows])
        return rows, read_table(csv_path)
    table = study.table
    return rows, {key: np.concatenate([np.asarray(table[key]), np.array([r.get(key, math.nan) for r in rows])])
                  for key in table}
