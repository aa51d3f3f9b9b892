"""The entry point: ``continuation(problem, algorithm, options)`` -> Branch; and
``continuation_until(problem, algorithm, options, stop)``, the same in chunks until a rule says stop."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..kinds import SHAPE_EVENTS, SOFT_EVENTS
from .corrector import advance, correct, tangent
from .events import find_events
from .results import Branch, ContinuationError, Point, Result, Slide
from .scales import scaled_options


def _point(problem, opts, c, t, ds, arclength):
    spectrum = problem.backend.spectrum
    vals, vecs, morse = spectrum(c.lin[1], opts.k, problem.n_zero_modes, opts.eig_rtol)
    if morse + 2 > opts.k:  # keep the eigenpairs that can cross next (the locators start from them)
        vals, vecs, morse = spectrum(c.lin[1], morse + 2, problem.n_zero_modes, opts.eig_rtol)
    u, p = c.z[:-1].copy(), float(c.z[-1])
    soft = np.zeros(vals.shape, dtype=bool)
    if problem.soft_modes is not None:
        # all negative eigenvalues lie in the computed span (k >= Morse index + 2), so the Morse index
        # on the complement of the soft directions counts the negative Ritz values there
        vals, vecs, soft = (np.asarray(a) for a in problem.soft_modes(u, p, vals, vecs))
        soft = soft.astype(bool)
        # the negative band relative to max |J_ii| (<= ||J||_2: no wider than the backend's band)
        band = opts.eig_rtol * max(float(np.max(np.abs(np.diag(np.asarray(c.lin[1]))))), 1e-300)
        morse = int(np.sum(vals[~soft] < -band))
    return Point(u, p, t, vals, vecs, morse, c.iterations, ds, arclength, soft)


def continuation(problem, alg, opts, *, observer=None, start=None, throw=True, known=(), start_tol=None):
    """Follow the branch of F(u, p) = 0 through (problem.u0, problem.p0) by ``alg`` (PseudoArclength).

    start: optional (u (n,), p, tangent (n+1,)): a predicted point and direction (a branch switch), the first
    point corrected on the hyperplane through it orthogonal to the tangent (else on p = p0, towards sign(opts.ds)).
    start_tol: the first point is accepted at a residual up to this. observer(point) is called after each
    accepted point. Folds and branch points are located (``Branch.events``); known: events located before on
    the same path, not taken for new ones. throw=True raises ContinuationError (``.branch``) when the corrector
    fails or an event is not located to ``opts.event_tol``; throw=False returns the branch with ``result`` and
    ``message`` saying so. opts: a ``ContinuationOptions`` (None: the defaults); newton_tol, event_tol and
    eig_rtol left None follow from the problem's scale (``scales``).
    """
    opts = scaled_options(problem, opts, *_start_state(problem, start))
    be = problem.backend

    def lin(u, p):
        return problem.linearise(u, p, problem.args)  # args may be updated between points

    if start is None:
        z_pred = np.append(np.asarray(problem.u0), problem.p0)
        t0 = np.zeros(problem.n + 1)
        t0[-1] = np.sign(opts.ds)
    else:
        z_pred = np.append(np.asarray(start[0], dtype=float), float(start[1]))
        t0 = np.asarray(start[2], dtype=float) / np.linalg.norm(start[2])
    c = _accepted_start(correct(be, lin, z_pred, t0, opts.newton_tol, opts.newton_max_iter), start_tol)
    if not c.converged:
        return _finish(Branch([], [], Result.CORRECTOR_FAILED, f"the start did not converge: residual "
                              f"{c.residual:.3g} after {c.iterations} Newton iterations"), throw)
    points = [_point(problem, opts, c, tangent(be, c.lin[1], c.lin[2], t0), 0.0, 0.0)]
    events, slides, ds = [], [], abs(opts.ds)
    result, message = Result.MAX_STEPS, f"stopped after max_steps = {opts.max_steps} steps"
    for _ in range(opts.max_steps):
        step = advance(alg, be, lin, points[-1].z, points[-1].tangent, ds, opts)
        if step is None:
            result = Result.CORRECTOR_FAILED
            message = (f"the corrector failed at every step size down to ds_min = {opts.ds_min:g} from "
                       f"p = {points[-1].p:.12g} (point {len(points) - 1})")
            break
        new = _point(problem, opts, step.correction, step.tangent, step.ds, points[-1].arclength + step.ds)
        if abs(new.morse_index - points[-1].morse_index) > 1 and step.ds / 2 >= opts.resolve_crossings > 0:
            ds = step.ds / 2  # several eigenvalues crossed within the step: retry smaller, to separate them
            continue
        ds = step.ds_next
        if problem.update_args is not None:  # e.g. a rebuilt contact list: the same F, new args
            problem.args = problem.update_args(step.correction.z[:-1], float(step.correction.z[-1]), problem.args)
        points.append(new)
        if observer is not None:
            observer(points[-1])
        if opts.detect_events:
            found = find_events(problem, opts, points[-2], points[-1], len(points) - 1,
                                [e for e in list(known) + events if e.converged])
            events += found
            soft = next((e for e in found if e.kind in SOFT_EVENTS and e.converged), None)
            if soft is not None and opts.soft_folds == "slide":
                points.pop()  # past the soft fold: on the sliding saddles, not kept
                direction = 1.0 if points[-1].tangent[-1] > 0 else -1.0
                slid = _slide(problem, opts, soft, direction, len(points))
                if slid is None:
                    result = Result.CORRECTOR_FAILED
                    message = f"no minimum found past the soft fold at p = {soft.p:.12g} (slide_dp = {opts.slide_dp:g})"
                    break
                slide, c = slid
                t0 = np.zeros(problem.n + 1)
                t0[-1] = direction
                jump = float(np.linalg.norm(c.z - points[-1].z))
                points.append(_point(problem, opts, c, tangent(be, c.lin[1], c.lin[2], t0), jump,
                                     points[-1].arclength + jump))
                slides.append(slide)
                if observer is not None:
                    observer(points[-1])
        if not opts.p_min <= points[-1].p <= opts.p_max:
            result, message = Result.BOUNDARY, f"p = {points[-1].p:.12g} left [{opts.p_min:g}, {opts.p_max:g}]"
            break
    failed = [e for e in events if not e.converged]
    if failed and result is not Result.CORRECTOR_FAILED:
        result = Result.LOCATION_FAILED
        message = "; ".join(why_not_located(e, opts.event_tol) for e in failed)
    return _finish(Branch(points, events, result, message, slides=slides), throw)


def continuation_until(problem, alg, opts, stop, *, start=None, observer=None, start_tol=None):
    """``continuation`` in chunks of ``opts.max_steps`` steps, until ``stop(points, events)``
    returns a non-empty message or a chunk ends otherwise; each chunk goes on from the last point,
    tangent and step, and the Branch covers the whole path. start, start_tol: as for
    ``continuation`` (start_tol: the first point only). ``result`` is Result.STOPPED with stop's
    message, or the last chunk's. Never raises for a failed chunk."""
    opts = scaled_options(problem, opts, *_start_state(problem, start))
    points, events, slides = [], [], []
    while True:
        br = continuation(problem, alg, opts, start=start, throw=False, observer=observer, known=events,
                          start_tol=None if points else start_tol)
        offset = len(points) - (1 if points else 0)
        if points:  # a chunk restarts its arclength at 0: carry it on from the last point
            s0 = points[-1].arclength
            points += [replace(pt, arclength=pt.arclength + s0) for pt in br.points[1:]]
        else:
            points += br.points
        events += [replace(e, step=e.step + offset) for e in br.events]
        slides += [replace(sl, step=sl.step + offset) for sl in br.slides]
        if br.result is not Result.MAX_STEPS:
            return Branch(points, events, br.result, br.message or br.result.value, slides=slides)
        message = stop(points, events)
        if message:
            return Branch(points, events, Result.STOPPED, message, slides=slides)
        last = points[-1]
        start = (last.u, last.p, last.tangent)
        # the next chunk's first step: the step the path had reached (not ds again)
        opts = replace(opts, ds=math.copysign(min(max(abs(last.ds), opts.ds_min), opts.ds_max), opts.ds))


def restabilisation(events, after=0):
    """The first event past step ``after`` at which the Morse index comes back to 0 from above (a
    fold or branch point where the followed unstable branch regains its stability), or None."""
    return next((e for e in events if e.step > after and e.kind in SHAPE_EVENTS
                 and e.morse_after == 0 < e.morse_before), None)


def until_stable(problem, alg, opts, *, start=None, max_points=400, keep=3, observer=None):
    """Follow an unstable branch until it restabilises: ``continuation_until`` stopped at the first
    fold or branch point where the Morse index returns to 0 (``restabilisation``), ``keep`` points
    past it, or after ``max_points`` points (the alternative to relaxing along the critical mode,
    ``jaxrod.continuation``'s branch switching). Returns (Branch, the restabilising Event or None)."""
    def stop(points, events):
        e = restabilisation(events)
        if e is not None and len(points) - 1 - e.step >= keep - 1:
            return f"restabilised at p = {e.p:.12g} ({e.kind}, Morse {e.morse_before} -> 0)"
        if len(points) >= max_points:
            return f"not restabilised within {len(points)} points (max_points)"
        return ""

    br = continuation_until(problem, alg, opts, stop, start=start, observer=observer)
    e = restabilisation(br.events)
    if e is not None:
        br.points = br.points[:e.step + keep]
    return br, e


def why_not_located(event, tol):
    """Why a detected ``event`` was not located to ``tol`` (event_tol), in words."""
    if event.residual <= tol and abs(event.critical_eigenvalue) <= tol:
        return (f"{event.kind} near p = {event.p:.6g} not located: Newton converged to a sliding mode's singular "
                f"point (residual {event.residual:.3g}), and the shape {event.kind} in the same bracket "
                f"(Morse {event.morse_before} -> {event.morse_after}) was not resolved")
    return (f"{event.kind} near p = {event.p:.6g} not located: residual {event.residual:.3g}, critical eigenvalue "
            f"{event.critical_eigenvalue:.3g} > event_tol = {tol:g}")


def _slide(problem, opts, fold, direction, step):
    """Relax past a soft fold: minimise E(., p1) at p1 = fold.p + direction * slide_dp from the fold
    kicked by slide_kick downhill along its soft mode (``problem.relax``, steps capped at 10
    slide_kick to follow the valley), then correct on p = p1. -> (Slide, Correction), or None."""
    import jax.numpy as jnp

    if problem.energy is None:
        raise ValueError("soft_folds='slide' needs the problem's energy (give energy=, or soft_folds='follow')")
    p1 = jnp.asarray(fold.p + direction * opts.slide_dp, dtype=jnp.float64)
    u0, v = np.asarray(fold.u), np.asarray(fold.v[:, 0])
    args = problem.args
    g = np.asarray(problem.linearise(u0, p1, args)[0])  # the gradient F, compiled already
    y = u0 - opts.slide_kick * (1.0 if float(g @ v) > 0 else -1.0) * v  # downhill: past the fold, E falls along v
    sol, args = problem.relax(y, p1, args, gtol=1e-9, max_step=10.0 * opts.slide_kick)
    if not sol.converged:
        return None
    problem.args = args
    t0 = np.zeros(problem.n + 1)
    t0[-1] = direction
    c = correct(problem.backend, lambda u, p: problem.linearise(u, p, problem.args), np.append(sol.y, float(p1)), t0,
                opts.newton_tol, opts.newton_max_iter)
    if not c.converged:
        return None
    e_fold, e_new = (float(problem.energy_value(x, p1, args)) for x in (u0, c.z[:-1]))
    slide = Slide(fold, float(p1), c.z[:-1].copy(), float(np.linalg.norm(c.z[:-1] - u0)), e_fold - e_new,
                  sol.iterations, step)
    return slide, c


def _start_state(problem, start):
    """(u, p) where a run starts: the predicted point ``start`` gives, else the problem's own."""
    return (problem.u0, problem.p0) if start is None else (start[0], start[1])


def _accepted_start(c, start_tol):
    """The start's Correction c, taken as converged at a residual of at most start_tol (None: never)."""
    if not c.converged and start_tol is not None and c.residual <= start_tol:
        return replace(c, converged=True)
    return c


def _finish(branch, throw):
    if throw and branch.result in (Result.CORRECTOR_FAILED, Result.LOCATION_FAILED):
        raise ContinuationError(f"{branch.result.value}: {branch.message}", branch)
    return branch
