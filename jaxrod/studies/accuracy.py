"""Accuracy asked for, not N: critical twists converged in the resolution, with an error estimate.

The discrete rod's critical twists converge as phi*(N) = phi*_inf + c h^p + ..., h = L/N, p = 2,
and at practical N are far from their limits compared with a single study's bracket. So a
converged answer needs a sequence of N and an extrapolation:

    richardson(Ns, values)                  -> Extrapolation (value, error, order, ...)
    converged_critical_twists(scene, 0.01 * pi)   -> {side: SideConvergence}

``richardson`` measures the order from the three finest levels (the exact fit of
v = v_inf + c h^p), extrapolates with it, and estimates the error a posteriori from how far the
estimate moved when the finest level was added: ``1.25 |R_K - R_{K-1}| / (r^p - 1)``, r the last
refinement ratio and 1.25 Roache's factor of safety. Two levels only give an extrapolation with
the order assumed, flagged as such, with Roache's factor 3. Where the levels do not converge
monotonically or the measured order is outside (0.5, 4), ``asymptotic`` is False and the error is
the last difference itself. With ``errors`` (each level's bracket), their propagation through the
extrapolation is added (``Extrapolation.level_error``).

``converged_critical_twists`` runs N_0, 2 N_0 - 1, 4 N_0 - 3, ... (every node of a level is a node
of the next), each level started from the previous one's state a little before its branch end,
resampled and relaxed, and followed to its own end (bracket tol = accuracy / 20). It stops when
the error estimate is below the accuracy asked for, or at N_max (then ``reached`` is False).
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..validation import check_finite, check_int_at_least, check_positive

__all__ = ["Extrapolation", "richardson", "Level", "SideConvergence", "converged_critical_twists", "refine_scene",
           "THEORETICAL_ORDER", "unconverged_reason", "level_of_side"]

# The discrete elastic rod's energies are second-order accurate in the edge length.
THEORETICAL_ORDER = 2.0
# Roache's factors of safety on the grid convergence index: 3 with two grids (the order assumed),
# 1.25 with three or more (the order measured).
TWO_LEVEL_SAFETY = 3.0
THREE_LEVEL_SAFETY = 1.25
ORDER_RANGE = (0.5, 4.0)


@dataclass(frozen=True)
class Extrapolation:
    """value: the extrapolated limit N -> infinity; error: its estimated error (module docstring);
    order: the order p used; order_measured: whether p was measured (else THEORETICAL_ORDER);
    asymptotic: the levels converge monotonically with a plausible order; N, values: the levels
    used; level_error: the part of ``error`` from the levels' own errors (brackets)."""

    value: float
    error: float
    order: float
    order_measured: bool
    asymptotic: bool
    N: tuple
    values: tuple
    level_error: float = 0.0

    def as_json(self):
        return {"value": self.value, "error": self.error, "order": self.order, "order_measured": self.order_measured,
                "asymptotic": self.asymptotic, "N": list(self.N), "values": list(self.values),
                "level_error": self.level_error}


def _extrapolate(h_coarse, h_fine, v_coarse, v_fine, p):
    """Two-level Richardson: v_fine + (v_fine - v_coarse) / ((h_coarse / h_fine)^p - 1)."""
    return v_fine + (v_fine - v_coarse) / ((h_coarse / h_fine) ** p - 1.0)


def _measured_order(h, v):
    """The p of v = v_inf + c h^p through three points (h decreasing), or None when the
    differences change sign. Bisection on p in (0.05, 12); None when no root there."""
    d1, d2 = v[0] - v[1], v[1] - v[2]
    if d1 == 0.0 or d2 == 0.0 or (d1 > 0) != (d2 > 0):
        return None
    target = d1 / d2

    def g(p):
        return (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - target

    lo, hi = 0.05, 12.0
    if g(lo) * g(hi) > 0:
        return None
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(lo) * g(mid) <= 0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def _three_level(h, v):
    """(R, p) from the three levels h (3,), v (3,): the order measured and the finest pair
    extrapolated with it; (None, None) without monotone convergence."""
    p = _measured_order(h, v)
    if p is None:
        return None, None
    return _extrapolate(h[1], h[2], v[1], v[2], p), p


def _propagated(h_coarse, h_fine, e_coarse, e_fine, p):
    """The error of ``_extrapolate``'s value from errors of its two inputs (at fixed p)."""
    c = 1.0 / ((h_coarse / h_fine) ** p - 1.0)
    return (1.0 + c) * e_fine + c * e_coarse


def richardson(N, values, errors=None):
    """Extrapolate ``values`` (one per resolution) to N -> infinity. N: increasing node counts
    (h = 1/N, the rod's length fixed), at least 2. errors: optional, each value's own error (a
    branch end's bracket), propagated into the result's error (``level_error``). Returns an
    ``Extrapolation``."""
    N = [check_int_at_least("N", n, 2) for n in N]
    values = [check_finite("values", float(v)) for v in values]
    if len(N) != len(values) or len(N) < 2:
        raise ValueError(f"richardson needs at least 2 levels, one value each (got N={N}, values={values})")
    if any(b <= a for a, b in zip(N, N[1:])):
        raise ValueError(f"N must increase, got {N}")
    if errors is None:
        errors = [0.0] * len(N)
    errors = [abs(check_finite("errors", float(e))) for e in errors]
    if len(errors) != len(N):
        raise ValueError(f"errors: one per level, got {len(errors)} for {len(N)} levels")
    h = [1.0 / n for n in N]
    if len(N) == 2:
        value = _extrapolate(h[0], h[1], values[0], values[1], THEORETICAL_ORDER)
        level = _propagated(h[0], h[1], errors[0], errors[1], THEORETICAL_ORDER)
        return Extrapolation(value, TWO_LEVEL_SAFETY * abs(value - values[1]) + level, THEORETICAL_ORDER, False, True,
                             tuple(N), tuple(values), level)
    value, p = _three_level(h[-3:], values[-3:])
    if value is None or not ORDER_RANGE[0] < p < ORDER_RANGE[1]:
        # not in the asymptotic range: the finest value is the answer, its last change the error
        return Extrapolation(values[-1], abs(values[-1] - values[-2]) + errors[-1], math.nan if p is None else p,
                             p is not None, False, tuple(N), tuple(values), errors[-1])
    if len(N) == 3:
        previous = _extrapolate(h[0], h[1], values[0], values[1], THEORETICAL_ORDER)
    else:
        previous, _ = _three_level(h[-4:-1], values[-4:-1])
        if previous is None:
            previous = values[-2]
    ratio = h[-2] / h[-1]
    error = THREE_LEVEL_SAFETY * abs(value - previous) / (ratio ** p - 1.0)
    # each of the three finest levels moved by its error both ways, the order measured again each time
    level = 0.0
    for i in range(1, 4):
        if errors[-i] > 0.0:
            spread = []
            for sign in (1.0, -1.0):
                moved = list(values[-3:])
                moved[-i] += sign * errors[-i]
                v, _ = _three_level(h[-3:], moved)
                spread.append(math.inf if v is None else abs(v - value))
            level += max(spread)
    return Extrapolation(value, error + level, p, True, True, tuple(N), tuple(values), level)


# ---------------------------------------------------------------------- the refinement study
@dataclass(frozen=True)
class Level:
    """One resolution of a side: N, phi_star (rad) and its bracket error phi_error, kind
    ('jump' or 'unstable', from ``follow_twist``), phi_start (where this level's continuation
    began), seconds, and the states on its branch (phi, q) kept to start the next level."""

    N: int
    phi_star: float
    phi_error: float
    kind: str
    phi_start: float
    seconds: float
    states: tuple = field(default=(), repr=False)

    def as_json(self):
        return {"N": self.N, "phi_star": self.phi_star, "phi_star_over_pi": self.phi_star / math.pi,
                "phi_error": self.phi_error, "kind": self.kind, "phi_start": self.phi_start, "seconds": self.seconds}


@dataclass(frozen=True)
class SideConvergence:
    """One side ('plus': phi > 0, 'minus'): its levels, the extrapolation over them (None with a
    single level), reached (error <= accuracy), and a reason in words."""

    side: str
    levels: tuple
    extrapolation: Extrapolation | None
    accuracy: float
    reached: bool
    reason: str

    @property
    def phi_star(self):
        """The best estimate: the extrapolated value (the finest level's with one level); None
        where no level found an end (``reason`` says why)."""
        if self.extrapolation is not None:
            return self.extrapolation.value
        return self.levels[-1].phi_star if self.levels else None

    @property
    def error(self):
        return self.extrapolation.error if self.extrapolation is not None else math.inf

    def as_json(self):
        phi = self.phi_star
        return {"side": self.side, "phi_star": phi, "phi_star_over_pi": None if phi is None else phi / math.pi,
                "error": self.error, "error_over_pi": self.error / math.pi, "accuracy": self.accuracy,
                "reached": self.reached, "reason": self.reason,
                "extrapolation": None if self.extrapolation is None else self.extrapolation.as_json(),
                "levels": [lv.as_json() for lv in self.levels]}


def refine_scene(scene, x, N):
    """The closed rod ``scene`` at another resolution N, along the centreline x (M, 3) resampled:
    same material, length, Lk0, name and contact. x: a state of ``scene`` (so the new rod starts
    at that shape). Closed rods only."""
    from ..model.scenes import closed_curve

    if not getattr(scene, "closed", False):
        raise ValueError(f"refine_scene: closed rods only (got a {type(scene).__name__})")
    contact = scene.contact_stiffness if scene.has_term("contact") else None
    return closed_curve(np.asarray(x), material=scene.material, N=N, length=float(scene.length),
                        Lk0=int(round(scene.Lk0)), name=scene.name, contact_stiffness=contact)


def level_of_side(scene, side, phi_start, start, span, step, tol, say, cancel):
    """Follow ``scene``'s stable branch from ``start`` (an Equilibrium at phi_start) towards
    side * span; its first end as a Level. ``cancel`` (an Event) set: stop at the next point."""
    from ..continuation import ContinuationOptions, Observer, follow_twist
    from .threads import Cancelled as _Cancelled

    def on_point(point):
        if cancel is not None and cancel.is_set():
            raise _Cancelled

    t0 = time.perf_counter()
    sign = 1.0 if side == "plus" else -1.0
    path = follow_twist(scene, phi_start, sign * span, ContinuationOptions(step=step, tol=tol, switch=False),
                        start=start, observer=Observer(on_point=on_point))
    states = tuple((p.equilibrium.phi, np.asarray(p.equilibrium.q)) for p in path.points)
    if not path.instabilities:
        reason = "no branch end before the twist range's end" if path.reason == "phi_stop" else path.reason
        return None, f"{reason} ({sign * span / math.pi:+g} pi)", states
    inst = path.instabilities[0]
    if scene.has_term("contact"):
        # a shape mode negative inside the near-zero band kept for sliding modes means the branch
        # ended earlier, unseen by the stable-only engine: locate it by events instead
        from ..linalg.stability import CONTACT_NEGATIVE_TOL
        from ..linalg.stability import shape_modes_in_band

        if shape_modes_in_band(scene, inst.equilibrium, CONTACT_NEGATIVE_TOL):
            level, why = _level_by_events(scene, side, path, phi_start, tol, say)
            if level is None:
                return None, why, states
            return replace(level, seconds=time.perf_counter() - t0, states=states), "", states
    level = Level(int(scene.n_nodes), float(inst.phi), float(inst.phi_error), str(inst.kind.value),
                  float(phi_start), time.perf_counter() - t0, states)
    say(f"{side}: N = {level.N}: phi* = {level.phi_star / math.pi:+.6f} pi +- {level.phi_error / math.pi:.1e} pi "
        f"({level.kind}), {level.seconds:.1f} s")
    return level, path.reason, states


def _level_by_events(scene, side, path, phi_start, tol, say):
    """The level's end as the first fold or branch point of pseudo-arclength continuation from the
    last state of ``path`` with no shape mode negative inside the near-zero band (where that band
    hid the end from the stable-only engine). Returns (Level or None, reason)."""
    from ..continuation import ContinuationOptions
    from ..continuation.arclength import PseudoArclength, continuation
    from ..continuation.arclength.rods import knot_problem
    from ..continuation.kinds import SHAPE_EVENTS
    from ..linalg.stability import CONTACT_NEGATIVE_TOL
    from ..linalg.stability import shape_modes_in_band

    clean = [p.equilibrium for p in path.points if not shape_modes_in_band(scene, p.equilibrium, CONTACT_NEGATIVE_TOL)]
    if not clean:
        return None, "every state of the branch has a shape mode negative inside the near-zero band"
    e = clean[-1]
    hidden_at = path.instabilities[0].equilibrium.phi
    say(f"{side}: N = {scene.n_nodes}: the stable-only continuation's band hid the end (a shape mode negative "
        f"at {hidden_at / math.pi:+.5f} pi); locating it by pseudo-arclength from {e.phi / math.pi:+.5f} pi")
    sign = 1.0 if side == "plus" else -1.0
    lo, hi = sorted((e.phi, hidden_at + sign * 0.5 * math.pi))
    opts = ContinuationOptions(ds=sign * 0.05, ds_min=1e-6, ds_max=0.25, p_min=lo, p_max=hi, max_steps=120,
                               newton_tol=1e-10, eig_rtol=1e-13, k=6, resolve_crossings=1e-4)
    rod = knot_problem(scene, np.asarray(e.q), e.phi)
    branch = continuation(rod.problem, PseudoArclength(), opts, throw=False)
    events = [ev for ev in branch.events if ev.kind in SHAPE_EVENTS and ev.morse_before == 0]
    if not events:
        return None, (f"the end hidden in the near-zero band was not located by the pseudo-arclength continuation "
                      f"({branch.result}: {branch.message})")
    ev = events[0]
    if not ev.converged:
        return None, f"the {ev.kind} at {ev.p / math.pi:+.6f} pi was not located to event_tol (residual {ev.residual:.1e})"
    level = Level(int(scene.n_nodes), float(ev.p), 0.0, ev.kind, float(phi_start), 0.0)
    say(f"{side}: N = {level.N}: phi* = {level.phi_star / math.pi:+.8f} pi ({ev.kind}, multiplicity "
        f"{ev.multiplicity}, critical eigenvalue {ev.critical_eigenvalue:.1e}, located by Newton on its extended system)")
    return level, ""


def _side(scene, side, accuracy, N_levels, span, step, tol, say, cancel, store):
    from ..solve.equilibrium import relax_to_minimum
    from .threads import Cancelled as _Cancelled

    levels = []
    current, phi_start, start = scene, 0.0, None
    ext = None
    for k, N in enumerate(N_levels):
        if cancel is not None and cancel.is_set():
            raise _Cancelled
        kept = None if store is None else store.load(side, N)
        if kept is not None:  # a level finished by an interrupted run: its states start the next one
            say(f"{side}: N = {N}: phi* = {kept.phi_star / math.pi:+.6f} pi (kept from the interrupted run)")
            levels.append(kept)
            current = None  # rebuilt from the kept states at the next level
        elif k == 0:
            start = relax_to_minimum(scene, 0.0)
        else:
            prev = levels[-1]
            margin = max(0.25 * math.pi, abs(prev.phi_star - levels[-2].phi_star) if k > 1 else math.pi)
            target = prev.phi_star - math.copysign(margin, prev.phi_star)
            # the previous level's stable state nearest below the target (in |phi|), resampled
            below = [(phi, q) for phi, q in prev.states if abs(phi) <= abs(target)]
            if below:
                phi_start, q = below[-1]
                x = np.asarray(q)[: 3 * prev.N].reshape(prev.N, 3)  # a closed rod's q starts with its nodes
            else:  # the previous level began past the target: from the drawing, relaxed at 0
                phi_start, x = 0.0, scene.positions(np.asarray(scene.q_init))
            current = refine_scene(scene, x, N)
            # spread the twist evenly: a jump of turns at the joint would drive strands through each other
            q0 = np.array(current.q_init)
            q0[3 * N:] += phi_start * np.arange(N) / N
            try:
                start = relax_to_minimum(current, phi_start, q0=q0)
            except Exception as exc:  # noqa: BLE001 -- a resampled start that does not relax: from 0
                say(f"{side}: N = {N}: resampled start at {phi_start / math.pi:+.3f} pi failed ({exc}); from 0")
                phi_start, start = 0.0, relax_to_minimum(current, 0.0)
        if kept is None:
            level, reason, _ = level_of_side(current, side, phi_start, start, span, step, tol, say, cancel)
            if level is None:
                return SideConvergence(side, tuple(levels), ext, accuracy, False, f"at N = {N}: {reason}")
            levels.append(level)
            if store is not None:
                store.save(side, level)
        if len(levels) >= 2:
            ext = richardson([lv.N for lv in levels], [lv.phi_star for lv in levels], [lv.phi_error for lv in levels])
            say(f"{side}: extrapolated phi* = {ext.value / math.pi:+.6f} pi +- {ext.error / math.pi:.1e} pi "
                f"(order {ext.order:.2f}{'' if ext.order_measured else ' assumed'}"
                f"{'' if ext.asymptotic else ', not in the asymptotic range'})")
            if len(levels) >= 3 and ext.asymptotic and ext.order_measured and ext.error <= accuracy:
                return SideConvergence(side, tuple(levels), ext, accuracy, True,
                                       f"error estimate {ext.error / math.pi:.1e} pi <= {accuracy / math.pi:.1e} pi "
                                       f"at N = {levels[-1].N}")
    return SideConvergence(side, tuple(levels), ext, accuracy, False,
                           unconverged_reason(N_levels[-1], ext, accuracy, levels))


def unconverged_reason(N_max, ext, accuracy, levels=()):
    """Why a side stopped at N_max without converging (a small last change is not an error
    estimate outside the asymptotic range, e.g. where the end changed kind between levels)."""
    why = f"N_max = {N_max} reached before the accuracy asked for"
    if ext is None:
        return f"{why} (no estimate)"
    kinds = [lv.kind for lv in levels]
    changed = f"; the branch end changed kind between levels ({', '.join(f'{lv.N}: {lv.kind}' for lv in levels)})" \
        if len(set(kinds)) > 1 else ""
    if not ext.asymptotic:
        order = "no order" if math.isnan(ext.order) else f"measured order {ext.order:.2f}"
        return (f"{why}: the levels are not in their asymptotic range ({order}, outside {ORDER_RANGE}){changed}; "
                f"the finest value's last change is {ext.error / math.pi:.1e} pi, not an error estimate")
    if not ext.order_measured:
        return f"{why}: two levels only (order assumed), error estimate {ext.error / math.pi:.1e} pi{changed}"
    return f"{why} (error estimate {ext.error / math.pi:.1e} pi > {accuracy / math.pi:.1e} pi){changed}"


def resolution_levels(N_start, N_max):
    """N_start, 2 N_start - 1, 4 N_start - 3, ... up to N_max (every node kept at the next level)."""
    out = [N_start]
    while 2 * out[-1] - 1 <= N_max:
        out.append(2 * out[-1] - 1)
    return out


def converged_critical_twists(scene, accuracy, sides=("plus", "minus"), N_max=481, span=16 * math.pi,
                              step=0.5 * math.pi, progress=None, parallel=True, levels=None, out=None):
    """The first branch end on each side of the closed rod ``scene`` (the coarsest level, e.g.
    ``trefoil(N=61, D=D, L=L)``), refined in N until its extrapolated value's error estimate is below
    ``accuracy`` (radians). Each level is followed from a state resampled from the previous one,
    its end bracketed to accuracy / 20. Returns {side: SideConvergence}. parallel: the sides in
    two threads. N_max: the finest level allowed (cost grows as N^3). levels: the node counts to
    use instead (increasing, the first the scene's own, at least three; N_max is then ignored).
    out: a folder where every finished level is kept (``levels/<side>_N<N>.npz``), and
    ``convergence.json`` at the end; a run called again with the same arguments reuses the
    finished levels (Ctrl-C: the sides stop at their next continuation point)."""
    accuracy = check_positive("accuracy", accuracy)
    check_positive("span", span)
    check_positive("step", step)
    for side in sides:
        if side not in ("plus", "minus"):
            raise ValueError(f"sides: 'plus' or 'minus', got {side!r}")
    if not getattr(scene, "closed", False):
        raise ValueError("converged_critical_twists: closed rods (rings, knots) only")
    N0 = int(scene.n_nodes)
    if levels is None:
        N_max = check_int_at_least("N_max", N_max, 4 * N0 - 3)  # three levels at least: the order is measured
        levels = resolution_levels(N0, N_max)
    else:
        levels = [check_int_at_least("levels", n, 4) for n in levels]
        if len(levels) < 3 or levels[0] != N0 or any(b <= a for a, b in zip(levels, levels[1:])):
            raise ValueError(f"levels must increase from the scene's N = {N0}, at least three of them, got {levels}")
    tol = accuracy / 20.0
    say = progress or (lambda s: None)
    say(f"{scene.name}: levels N = {', '.join(map(str, levels))} at most, until the error estimate is "
        f"<= {accuracy / math.pi:g} pi (each end bracketed to {tol / math.pi:.1e} pi)")
    from .threads import run_all as _run_all

    store = None if out is None else _LevelStore(out, scene, accuracy, span, step)
    results = {}
    cancel = threading.Event()

    def run(side):
        results[side] = _side(scene, side, accuracy, levels, span, step, tol, say, cancel, store)

    _run_all(run, [(s,) for s in sides], parallel, cancel)
    results = {s: results[s] for s in sides}
    if store is not None:
        store.finish(results)
    return results


class _LevelStore:
    """Finished levels on file, written atomically as they are found, read back on resume. The
    run's parameters are in levels/run.json; another run's folder is refused."""

    def __init__(self, out, scene, accuracy, span, step):
        import json
        import os

        self.out = out
        self.folder = os.path.join(out, "levels")
        os.makedirs(self.folder, exist_ok=True)
        params = {"name": scene.name, "N0": int(scene.n_nodes), "L": float(scene.length),
                  "D": None if scene.material.D is None else float(scene.material.D), "B": float(scene.material.B),
                  "C": float(scene.material.C), "Lk0": float(scene.Lk0), "terms": list(scene.term_names),
                  "contact_stiffness": float(getattr(scene, "contact_stiffness", 0.0) or 0.0),
                  "accuracy": float(accuracy), "span": float(span), "step": float(step)}
        path = os.path.join(self.folder, "run.json")
        if os.path.exists(path):
            with open(path) as f:
                before = json.load(f)
            if before != params:
                changed = sorted(k for k in params if before.get(k) != params[k])
                raise ValueError(f"out: {out} holds levels of another accuracy study (different {', '.join(changed)}): "
                                 f"use another folder or delete {self.folder}")
        else:
            from ..io.atomic import write_json

            write_json(path, params)

    def _path(self, side, N):
        import os

        return os.path.join(self.folder, f"{side}_N{N:05d}.npz")

    def load(self, side, N):
        import os

        path = self._path(side, N)
        if not os.path.exists(path):
            return None
        with np.load(path) as f:
            states = tuple((float(phi), q) for phi, q in zip(f["state_phi"], f["state_q"]))
            return Level(int(f["N"]), float(f["phi_star"]), float(f["phi_error"]), str(f["kind"]), float(f["phi_start"]),
                         float(f["seconds"]), states)

    def save(self, side, level):
        from ..io.atomic import savez

        states = level.states
        savez(self._path(side, level.N), N=level.N, phi_star=level.phi_star, phi_error=level.phi_error,
              kind=level.kind, phi_start=level.phi_start, seconds=level.seconds,
              state_phi=np.array([phi for phi, _ in states]), state_q=np.stack([q for _, q in states]))

    def finish(self, results):
        import os

        from ..io.atomic import write_json

        write_json(os.path.join(self.out, "convergence.json"), {s: r.as_json() for s, r in results.items()})
