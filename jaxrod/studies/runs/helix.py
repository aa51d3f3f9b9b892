"""Localized helical buckling of a clamped rod against Neukirch, van der Heijden & Thompson 2002
(NvdHT), as ``jaxrod helix`` runs it: each analytic loop asked for solved by Newton from its
shape, one root taken, its end loads extrapolated (Richardson, N and about N/2), optionally
followed along a sweep of end rotations, and the summary record against the analytic values.

    from jaxrod.studies import endloads as el
    from jaxrod.studies.runs import helix_case, run_helix
    case = helix_case(N=240, B=1.0, C=2 / 3, nu=0.5, gamma=2 / 3, D=2e-4, EA=16 / 2e-4 ** 2, sweep=0,
                      refs=[("only", el.localized_helix(20.0, 300.0, 2 / 3))], n_found=1)
    run = run_helix(case)
    run.result["m"], run.result["t"]        # M L/B and T L^2/B, L = 1

Units: the rod's length L = 1; m = M L/B and t = T L^2/B; angles in rad.
"""
from __future__ import annotations

import dataclasses
import time
import warnings

from ...continuation.natural import follow_parameter
from .. import endloads as el


@dataclasses.dataclass
class HelixCase:
    """A helix problem, checked: N nodes; the material (gamma = C/B, D the slenderness D/L);
    sweep, the number of end rotations to follow; refs, the analytic loops to solve as (name,
    LocalizedHelix), of n_found at the imposed ends; checks, each one's ReferenceCheck by name;
    resolved, those N resolves, and refused, (name, LocalizedHelix, why) for the others."""

    N: int
    B: float
    C: float
    nu: float
    gamma: float
    D: float
    EA: float
    sweep: int
    refs: list
    n_found: int
    checks: dict
    resolved: list
    refused: list

    @property
    def ea(self):
        return self.EA / self.B  # EA L^2 / B, L = 1

    @property
    def material(self):
        """The rod's ``Material``."""
        from ...model.material import Material

        return Material(B=self.B, C=self.C, EA=self.EA, D=self.D)


@dataclasses.dataclass
class SolvedHelixRoot:
    """A root as solved at N: its analytic loop ref, the rod, its equilibrium eq and state
    (``endloads.helix_state``), or eq and state None and the ConvergenceError where Newton failed."""

    ref: object
    rod: object
    eq: object
    state: dict
    error: Exception


@dataclasses.dataclass
class HelixRun:
    """A solved case: ``solved`` {name: SolvedHelixRoot}; ``taken``, the root reported (None where
    no root reached an equilibrium: then result and profiles are None too); ``result``, the summary
    record (helix.json); ``profiles``, the taken loop's ``HelixProfiles`` beside its reference."""

    case: HelixCase
    solved: dict
    taken: str | None = None
    result: dict | None = None
    profiles: object = None


def helix_case(N, B, C, nu, gamma, D, EA, sweep, refs, n_found, strict=False):
    """The ``HelixCase`` of these values (N nodes, at least 8; sweep >= 0): each root's
    reference checked; with strict, only the roots whose reference applies (ValueError with the
    reasons if none does); ValueError where N resolves none of them."""
    from ...validation import check_int_at_least

    N = check_int_at_least("N", N, 8)
    sweep = check_int_at_least("sweep", sweep, 0)
    checks = {name: el.reference_check(h, EA / B) for name, h in refs}
    if strict:
        refs = roots_that_apply(refs, checks)
    resolved, refused = roots_resolved(N, refs)
    return HelixCase(N=N, B=B, C=C, nu=nu, gamma=gamma, D=D, EA=EA, sweep=sweep, refs=refs, n_found=n_found,
                     checks=checks, resolved=resolved, refused=refused)


def roots_that_apply(refs, checks):
    """The roots whose analytic reference applies; ValueError with the reasons if none does."""
    invalid = [f"{name} root (m = {h.m:.4g}, t = {h.t:.4g}): {checks[name].reason}" for name, h in refs
               if not checks[name].valid]
    refs = [(name, h) for name, h in refs if checks[name].valid]
    if not refs:
        raise ValueError("strict: the analytic reference (NvdHT 2002) does not apply: " + "; ".join(invalid))
    return refs


def roots_resolved(N, refs):
    """(resolved, refused): the roots N nodes resolve, and those it does not as (name, helix,
    why); every loop solved must be resolved, so ValueError (the first why) where none is."""
    resolved, refused = [], []
    for name, h in refs:
        try:
            el.check_helix_resolution(N, h.m, h.t, h.R)
            resolved.append((name, h))
        except ValueError as exc:
            refused.append((name, h, str(exc)))
    if not resolved:
        raise ValueError(refused[0][2])
    return resolved, refused


def run_helix(case, root="stable", extrapolate=True, progress=None, on_state=None):
    """Solves ``case`` and returns a ``HelixRun``. root: the root taken where several are solved
    ("stable", "small", "large" or "both": ``endloads.choose_helix_root``); extrapolate: also
    solve the coarse rod for Richardson's extrapolation of m and t. progress(str) gets the progress
    lines; on_state(count) after each state solved (the roots, the coarse rod, the sweep's). Warns
    where the reference does not apply to the root taken or T carries a large roundoff."""
    say = progress or (lambda line: None)
    on_state = on_state or (lambda count: None)
    t0 = time.perf_counter()
    solved = solve_helix_roots(case, say, on_state)
    if all(r.eq is None for r in solved.values()):
        return HelixRun(case, solved)
    taken, why = take_helix_root(case, solved, root)
    taken_root = solved[taken]
    say(f"taken: the {taken} root (t = {taken_root.ref.t:.6g}): {why}")
    t_roundoff = warn_about_helix_reference(case, taken, taken_root.state["T"])
    extra = no_helix_extrapolation()
    if extrapolate:
        extra = helix_extrapolation(case, taken_root, case.checks[taken].valid, say)
        on_state(len(solved) + 1)
    path, stopped = [], []
    if case.sweep:
        path, stopped = helix_sweep(case, taken_root, say, on_state, len(solved) + int(extrapolate))
    seconds = time.perf_counter() - t0
    profiles = el.helix_profiles(taken_root.eq.x, taken_root.ref)
    result = helix_result(case, solved, taken, why, t_roundoff, extra)
    result.update(helix_shape_errors(taken_root, profiles, result["reference_valid"]),
                  newton_steps=taken_root.eq.solution.iterations, seconds=seconds, path=path,
                  sweep_stopped_at=stopped)
    return HelixRun(case, solved, taken, result, profiles)


def solve_helix_roots(case, say, on_state):
    """{name: SolvedHelixRoot} of each resolved root, solved from its analytic loop, in order."""
    from ...solve.solvers import ConvergenceError

    solved, material = {}, case.material
    for name, h in case.resolved:
        rod = el.shortened_rod(case.N, 1.0, material, shortening=h.d)
        try:
            e = el.solve_from_helix(rod, h.m, h.t, h.R, el.EndLoadOptions(k=4))
        except ConvergenceError as exc:
            sol = exc.solution
            say(f"{name} root: no equilibrium reached from the analytic loop" + ("" if sol is None else
                f" ({sol.reason} after {sol.iterations} Newton steps, |gradient| {sol.grad_norm:.2e})"))
            solved[name] = SolvedHelixRoot(h, rod, None, None, exc)
            continue
        st = el.helix_state(rod, e, h.R, h, case.B, case.ea)
        solved[name] = SolvedHelixRoot(h, rod, e, st, None)
        on_state(len(solved))
        say(f"{name} root solved: m = {st['m']:.6g} (analytic {h.m:.6g}), t = {st['t']:.6g} (analytic "
            f"{h.t:.6g}), Morse index {st['morse']} ({e.solution.iterations} Newton steps in the last stage)")
    return solved


def take_helix_root(case, solved, root):
    """(name, reason) of the root taken among those solved (``endloads.choose_helix_root``)."""
    candidates = [(name, r.ref.t, r.state["stable"]) for name, r in solved.items() if r.eq is not None]
    return el.choose_helix_root(candidates, case.n_found, root)


def warn_about_helix_reference(case, taken, T):
    """Warns where the analytic reference does not apply to the root taken, or where its tension
    T carries a roundoff above 1e-4 relative; returns that roundoff."""
    check = case.checks[taken]
    if not check.valid:
        warnings.warn(f"the analytic reference (NvdHT 2002) does not apply to the {taken} root: {check.reason}; "
                      "no error against it is computed", stacklevel=1)
    t_roundoff = el.tension_roundoff(case.N, case.EA, T)
    if t_roundoff > 1e-4:
        warnings.warn(f"EA L^2/B = {case.ea:.3g} is so stiff that T carries a roundoff of ~{t_roundoff:.1e} "
                      "relative (EA times the roundoff of a strain)", stacklevel=1)
    return t_roundoff


def no_helix_extrapolation():
    """The extrapolation's result keys, empty."""
    return {"N_coarse": None, "m_extrapolated": None, "t_extrapolated": None,
            "m_extrapolated_rel_error": None, "t_extrapolated_rel_error": None, "extrapolation_note": None}


def helix_extrapolation(case, root, valid, say):
    """The extrapolation's result keys (``no_helix_extrapolation``) for the root taken: Richardson's
    (O(h^2)) from N and the coarse rod (edges twice as long), relative errors where the reference
    applies (valid), or the note why it is not extrapolated."""
    from ...solve.solvers import ConvergenceError

    N, ref, coarse_N = case.N, root.ref, el.coarse_nodes(case.N)
    extra = no_helix_extrapolation()
    try:
        el.check_helix_resolution(coarse_N, ref.m, ref.t, ref.R)
        rod_c = el.shortened_rod(coarse_N, 1.0, case.material, shortening=ref.d)
        e_c = el.solve_from_helix(rod_c, ref.m, ref.t, ref.R, el.EndLoadOptions(with_stability=False))
        loads_c = el.end_loads(rod_c, e_c.q, ref.R, e_c.neighbourhood)
        m_x = el.richardson_extrapolation(root.state["m"], loads_c.M / case.B, N, coarse_N)
        t_x = el.richardson_extrapolation(root.state["t"], loads_c.T / case.B, N, coarse_N)
        extra.update(N_coarse=coarse_N, m_extrapolated=m_x, t_extrapolated=t_x,
                     m_extrapolated_rel_error=el.relative_error(m_x, ref.m, valid),
                     t_extrapolated_rel_error=el.relative_error(t_x, ref.t, valid))
        say(f"Richardson (N = {coarse_N}, {N}): m = {m_x:.6g}, t = {t_x:.6g}")
    except ValueError as exc:
        extra["extrapolation_note"] = f"not extrapolated: the coarse rod (N = {coarse_N}) is refused: {exc}"
        say(extra["extrapolation_note"])
    except ConvergenceError:
        extra["extrapolation_note"] = f"not extrapolated: no equilibrium reached at N = {coarse_N}"
        say(extra["extrapolation_note"])
    return extra


def helix_sweep(case, root, say, on_state, done):
    """(path, stopped): the root taken followed along case.sweep end rotations from 0.8 R to 1.1 R
    at the same shortening, each solved from its neighbour outwards from R; path, the states
    ascending in R, and stopped, the rotations where a side found no equilibrium (past a fold).
    done: the states counted before the sweep."""
    import numpy as np

    R = root.ref.R
    Rs = np.linspace(0.8 * R, 1.1 * R, case.sweep)
    path, stopped = [root.state], []
    for side in (np.sort(Rs[Rs >= R]), np.sort(Rs[Rs < R])[::-1]):
        stop = _helix_sweep_side(case, root, side, path, say, lambda n: on_state(done + n))
        if stop is not None:
            stopped.append(stop)
    path.sort(key=lambda r: r["R"])
    return path, stopped


def _helix_sweep_side(case, root, side, path, say, on_state):
    """Follows the root taken along the end rotations ``side`` (outwards from its own), appending
    each state to path; returns the rotation where Newton found no equilibrium, or None."""
    from ...solve.solvers import ConvergenceError

    rod, prev = root.rod, root.eq
    for R in side:
        try:
            el.check_rotation_resolution(case.N, R)
            # sub-steps of at most 0.25 rad (Newton alone does not follow larger ones)
            prev = follow_parameter(lambda r, s: el.solve(rod, r, s.q, el.EndLoadOptions(with_stability=False)),
                                    prev, float(prev.phi), float(R), 0.25,
                                    solve_last=lambda r, s: el.solve(rod, r, s.q, el.EndLoadOptions(k=4)))
            loads = el.end_loads(rod, prev.q, float(R), prev.neighbourhood)
            h = el.nearest_localized_helix(root.ref.d, float(R), case.gamma, loads.M / case.B, loads.T / case.B)
            path.append(el.helix_state(rod, prev, float(R), h, case.B, case.ea))
            on_state(len(path))
            say(f"R = {R:.5g}: m = {path[-1]['m']:.6g}, t = {path[-1]['t']:.6g}, Morse {path[-1]['morse']}")
        except ConvergenceError:
            say(f"R = {R:.5g}: no equilibrium reached from R = {float(prev.phi):.5g} (past a fold?): "
                "this side of the sweep stops")
            return float(R)
    return None


def helix_result(case, solved, taken, why, t_roundoff, extra):
    """The helix summary (helix.json, --json) up to the envelope's comparison: the input, the
    taken root's state beside its reference, every root's comparison, the extrapolation."""
    root, check = solved[taken], case.checks[taken]
    ref, main, valid = root.ref, root.state, check.valid
    roots = []
    for name, h in case.refs:
        r = solved.get(name)
        note = None if r is not None else next((w for n_, _, w in case.refused if n_ == name), None)
        roots.append(el.helix_root_row(name, h, case.checks[name], None if r is None else r.state,
                                       attempted=r is not None, note=note))
    return {"N": case.N, "B": case.B, "C": case.C, "EA": case.EA, "nu": case.nu, "gamma": case.gamma,
            "slenderness": case.D, "d": ref.d, "lambda": ref.lam, **main, "reference_valid": valid,
            "reference_reason": check.reason, "stretch": check.stretch, "t_roundoff": t_roundoff, "root": taken,
            "root_reason": why, "roots": roots, "m_rel_error": el.relative_error(main["m"], ref.m, valid),
            "t_rel_error": el.relative_error(main["t"], ref.t, valid), **extra}


def helix_shape_errors(root, profiles, valid):
    """The loop's shape against the reference where it applies (valid; else None): envelope_L1,
    the L1 error of the tangent angle, and centreline_max_distance (units of L)."""
    return {"envelope_L1": el.envelope_error(root.eq.x, root.ref.m, root.ref.t, 1.0) if valid else None,
            "centreline_max_distance": profiles.max_distance() if valid else None}
