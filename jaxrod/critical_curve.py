"""A knot's critical twists as curves in its slenderness: phi*+-(D/L) (issue 17, item 5).

For each side, the knot at a start ratio is followed from phi = 0 by the stable-only engine to a
coarse branch end, then, from a stable state ~0.2 pi before it, the first instability is located
on its extended system and followed in D by ``jaxrod.bifurcation.event_curve`` up and down the
ratios asked for. D varies at fixed L, N, E and nu (B, C ~ D^4, EA ~ D^2, contact at D:
``jaxrod.bifurcation.rods.set_diameter``), so N must be at least L/D over the whole range.

Every row says which event it is (a fold or a simple branch point, with the Morse index across
it), its critical eigenvalue and residual, and dphi*/d(D/L) from the implicit function theorem.
With ``out`` the rows go to ``critical_curve.csv`` as they are found (an interrupted run keeps
them; it is not resumed: a new run starts over), then ``critical_curve.json`` (settings, how
each leg ended) and ``critical_curve.png``.
"""
from __future__ import annotations

import csv
import json
import math
import os
import time
from dataclasses import asdict, dataclass

import numpy as np

from .validation import check_int_at_least, check_positive

__all__ = ["CriticalCurveOptions", "critical_twist_curve", "CSV_COLUMNS"]

SIDE_SIGNS = {"plus": 1.0, "minus": -1.0}
CSV_COLUMNS = ("side", "D_over_L", "phi_star", "phi_star_over_pi", "kind", "morse_before", "morse_after",
               "critical_eigenvalue", "residual", "dphi_dratio", "seconds")


@dataclass(frozen=True)
class CriticalCurveOptions:
    """Settings of ``critical_twist_curve``.

    sides: "plus" (phi > 0) and/or "minus"; start_ratio: the D/L where each side's event is first
    located (default: the ratio in the middle of those asked for); span: each side's first end is
    searched up to +-span (rad); delta: the gap in phi kept between each run's start and the event
    (rad); max_jump: a start that relaxes further (scaled units, edge lengths) has left the branch;
    max_points: continuation points per try; ds_max: their largest step; nu, contact_stiffness:
    the rod's Poisson ratio and contact penalty (units of B/D^3).
    """

    sides: tuple = ("plus", "minus")
    start_ratio: float | None = None
    span: float = 16.0 * math.pi
    delta: float = 0.03 * math.pi
    max_jump: float = 2.0
    max_points: int = 150
    ds_max: float = 0.5
    nu: float = 0.5
    contact_stiffness: float = 100.0

    def __post_init__(self):
        sides = (self.sides,) if isinstance(self.sides, str) else tuple(self.sides)
        if not sides or any(s not in SIDE_SIGNS for s in sides):
            raise ValueError(f"sides must be 'plus' and/or 'minus', got {self.sides!r}")
        object.__setattr__(self, "sides", sides)
        for name in ("span", "delta", "max_jump", "ds_max"):
            check_positive(name, getattr(self, name))
        check_int_at_least("max_points", self.max_points, 8)


def _ratios(ratios):
    r = np.atleast_1d(np.asarray(ratios, dtype=float))
    if r.size < 1:
        raise ValueError("ratios: give at least one D/L")
    for v in r:
        check_positive("ratios", float(v))
    return np.unique(r)


def critical_twist_curve(knot, N, ratios, options=None, *, out=None, progress=None):
    """phi*+-(D/L) of ``knot`` ("3_1", "4_1", "5_1", "5_2") at N nodes over ``ratios`` (D/L values).

    Returns a dict: rows (one per side and ratio, the CSV's columns), legs (how each run up or
    down ended), seconds. progress(str): a line per point and per failed try. The knot at every
    ratio is checked first (N >= L/D, L/D above the ideal ropelength): ValueError naming ratios or
    N. Raises RuntimeError when a side has no instability within +-span at the start ratio.
    """
    from .bifurcation import ContinuationOptions as PathOptions
    from .bifurcation.event_curve import EventCurveOptions, event_curve
    from .bifurcation.rods import knot_problem, set_diameter
    from .continuation import ContinuationOptions, follow_twist
    from .scenes import knot as make_knot

    t0 = time.perf_counter()
    opts = options or CriticalCurveOptions()
    N = check_int_at_least("N", N, 24)
    r = _ratios(ratios)
    start = float(r[len(r) // 2]) if opts.start_ratio is None else check_positive("start_ratio", opts.start_ratio)
    if not r[0] <= start <= r[-1]:
        raise ValueError(f"start_ratio = {start:g} must lie within the ratios ({r[0]:g} ... {r[-1]:g})")
    for ratio in sorted(set(r.tolist()) | {start}):
        try:
            make_knot(knot, ratio, 1.0, N, nu=opts.nu, contact_stiffness=opts.contact_stiffness)
        except ValueError as exc:
            what = "N" if str(exc).startswith("N") else "ratios"
            raise ValueError(f"{what}: {knot} at D/L = {ratio:g}, N = {N}: {exc}") from None
    say = progress or (lambda s: None)
    rows, legs = [], {}
    csv_path = None
    if out is not None:
        os.makedirs(out, exist_ok=True)
        csv_path = os.path.join(out, "critical_curve.csv")
        with open(csv_path, "w", newline="") as f:
            csv.writer(f).writerow(CSV_COLUMNS)

    def record(side, point):
        row = dict(side=side, D_over_L=point.mu, phi_star=point.p, phi_star_over_pi=point.p / math.pi,
                   kind=point.kind, morse_before=point.morse_before, morse_after=point.morse_after,
                   critical_eigenvalue=point.critical_eigenvalue, residual=point.residual,
                   dphi_dratio=point.dp_dmu, seconds=point.seconds)
        rows.append(row)
        say(f"[{side}] D/L = {point.mu:.5f}: {point.kind} at {point.p / math.pi:+.8f} pi (Morse {point.morse_before} -> "
            f"{point.morse_after}, dphi*/d(D/L) = {point.dp_dmu / math.pi:+.3f} pi, {point.seconds:.1f} s)")
        if csv_path is not None:
            with open(csv_path, "a", newline="") as f:
                csv.writer(f).writerow([row[c] if not isinstance(row[c], float) else repr(row[c]) for c in CSV_COLUMNS])

    for side in opts.sides:
        sign = SIDE_SIGNS[side]
        scene = make_knot(knot, start, 1.0, N, nu=opts.nu, contact_stiffness=opts.contact_stiffness)
        path = follow_twist(scene, 0.0, sign * opts.span,
                            ContinuationOptions(step=0.5 * math.pi, tol=1e-2 * math.pi, max_switches=0))
        if not path.instabilities:
            raise RuntimeError(f"{knot} at D/L = {start:g}: no instability on the {side} side within "
                               f"{sign * opts.span / math.pi:+g} pi ({path.reason})")
        end = path.instabilities[0].phi
        before = [p.equilibrium for p in path.points if p.branch.startswith("symmetric")
                  and sign * (end - p.equilibrium.phi) >= 0.2 * math.pi]
        e = before[-1] if before else path.points[0].equilibrium
        say(f"[{side}] stable-only engine: branch end near {end / math.pi:+.3f} pi; events from {e.phi / math.pi:+.3f} pi")
        path_opts = PathOptions(ds=0.05 * sign, ds_min=1e-6, ds_max=opts.ds_max, newton_tol=1e-10, eig_rtol=1e-13,
                                n_eig=6, p_min=-opts.span - math.pi, p_max=opts.span + math.pi)
        curve_opts = EventCurveOptions(path_opts, opts.delta, max_jump=opts.max_jump, max_points=opts.max_points)
        for leg, values in (("up", [v for v in r if v > start]), ("down", [v for v in r[::-1] if v < start])):
            if leg == "down" and not values:  # the up leg has done the start ratio
                continue
            rod = knot_problem(scene, np.asarray(e.q), e.phi)
            prob = rod.problem
            skip_start = leg == "down" and f"{side}_up" in legs  # the start ratio is the up leg's first point

            def observer(point, side=side, skip_start=skip_start):
                if not (skip_start and point.mu == start):
                    record(side, point)

            curve = event_curve(prob, (prob.u0, prob.p0), set_diameter, start, values, curve_opts,
                                observer=observer, progress=lambda m, side=side: say(f"[{side}]   {m}"))
            legs[f"{side}_{leg}"] = dict(result=curve.result.value, message=curve.message, points=len(curve.points))
    rows.sort(key=lambda q: (list(SIDE_SIGNS).index(q["side"]), q["D_over_L"]))
    seconds = time.perf_counter() - t0
    result = dict(knot=knot, N=N, ratios=r.tolist(), start_ratio=start, options=asdict(opts), legs=legs, rows=rows,
                  seconds=seconds)
    if out is not None:
        with open(os.path.join(out, "critical_curve.json"), "w") as f:
            json.dump(result, f, indent=1)
        _figure(result, os.path.join(out, "critical_curve.png"))
    return result


def _figure(result, path):
    from .plotting import plot_critical_curve

    plot_critical_curve(result["rows"], nu=result["options"]["nu"], title=f"{result['knot']}, N = {result['N']}: "
                        "critical twists against D/L", path=path)


def check_ratio_range(text):
    """'a:b:step' or 'a,b,c' -> the D/L values (a sorted array); ValueError naming --ratios."""
    text = str(text).strip()
    try:
        if ":" in text:
            a, b, h = (float(x) for x in text.split(":"))
            if not (h > 0 and b >= a):
                raise ValueError
            values = np.round(np.arange(a, b + 0.5 * h, h), 10)
        else:
            values = np.array([float(x) for x in text.split(",") if x.strip()])
    except ValueError:
        raise ValueError(f"--ratios: give 'first:last:step' (step > 0) or a comma-separated list, got {text!r}") \
            from None
    if values.size == 0 or not np.all(np.isfinite(values)) or np.any(values <= 0):
        raise ValueError(f"--ratios: D/L values must be finite and > 0, got {text!r}")
    return np.unique(values)
