"""A knot's critical twists as curves in its slenderness: phi*+-(D/L) (issue 17, item 5).

For each side, the knot at a start ratio is followed from phi = 0 by the stable-only engine to a
coarse branch end, then, from a stable state ~0.2 pi before it, the first instability is located
on its extended system and followed in D by ``jaxrod.bifurcation.event_curve`` up and down the
ratios asked for. D varies at fixed L, N, E and nu (B, C ~ D^4, EA ~ D^2, contact at D:
``jaxrod.bifurcation.rods.set_diameter``), so N must be at least L/D over the whole range.

Every row says which event it is (a fold or a simple branch point, with the Morse index across
it), its critical eigenvalue and residual, dphi*/d(D/L) from the implicit function theorem, and
which predictor found its start ("ift": that slope at the previous ratio; "secant": the last two
events, where the slope threw the start off the branch, as at a nearly degenerate branch point;
"none").
With ``out`` the rows go to ``critical_curve.csv`` as they are found, then
``critical_curve.json`` (settings, how each leg ended) and ``critical_curve.png``. The run is
resumable: each point is also kept whole (``points/<side>_<leg>_<k>.npz``: its event, slope and
the stable state the next ratio starts from), with each side's start state (``start_<side>.npz``)
and each finished leg (``legs/<side>_<leg>.json``), all written atomically; a run on the same
folder with the same settings goes on from the last point of each leg (``fresh=True`` starts
over; other settings are refused, naming the difference).
"""
from __future__ import annotations

import csv
import glob
import json
import math
import os
import shutil
import time
from dataclasses import asdict, dataclass, fields

import numpy as np

from .atomic import savez, write_json, write_rows
from .validation import check_int_at_least, check_positive

__all__ = ["CriticalCurveOptions", "critical_twist_curve", "CSV_COLUMNS"]

SIDE_SIGNS = {"plus": 1.0, "minus": -1.0}
CSV_COLUMNS = ("side", "D_over_L", "phi_star", "phi_star_over_pi", "kind", "morse_before", "morse_after",
               "critical_eigenvalue", "residual", "dphi_dratio", "predictor", "seconds")


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


SETTINGS_FILE = "critical_curve_settings.json"


def _settings(knot, N, ratios, start, opts):
    return {"knot": knot, "N": int(N), "ratios": [float(v) for v in ratios], "start_ratio": float(start),
            "options": json.loads(json.dumps(asdict(opts)))}


def _check_folder(out, settings, fresh):
    """Make ``out`` ready: with ``fresh`` (or nothing on file) the earlier run's files go; else a
    folder of a run with other settings is refused (ValueError naming what differs)."""
    path = os.path.join(out, SETTINGS_FILE)
    if not fresh and os.path.exists(path):
        with open(path) as f:
            stored = json.load(f)
        if stored != settings:
            differ = sorted(k for k in set(stored) | set(settings) if stored.get(k) != settings.get(k))
            if "options" in differ:
                differ += [f"options.{k}" for k in settings["options"]
                           if stored.get("options", {}).get(k) != settings["options"][k]]
            raise ValueError(f"out: {out} holds a critical curve with other settings ({', '.join(differ)}); "
                             "give another folder, or fresh=True (the CLI's --fresh) to start over")
        return True
    for name in ("points", "legs"):
        shutil.rmtree(os.path.join(out, name), ignore_errors=True)
    for name in glob.glob(os.path.join(out, "start_*.npz")):
        os.remove(name)
    os.makedirs(os.path.join(out, "points"), exist_ok=True)
    os.makedirs(os.path.join(out, "legs"), exist_ok=True)
    write_json(path, settings)
    return False


def _save_point(path, point, recorded):
    from .bifurcation.event_curve import EventCurvePoint

    arrays = {f.name: np.asarray(getattr(point, f.name)) for f in fields(EventCurvePoint)}
    savez(path, recorded=np.asarray(bool(recorded)), **arrays)


def _load_point(path):
    """-> (EventCurvePoint, recorded) as ``_save_point`` stored it."""
    from .bifurcation.event_curve import EventCurvePoint

    with np.load(path) as f:
        values = {}
        for fd in fields(EventCurvePoint):
            if fd.name not in f:  # a field added since the point was stored: its default
                continue
            v = f[fd.name]
            values[fd.name] = v if v.ndim else v.item()
        return EventCurvePoint(**values), bool(f["recorded"])


def _row(side, point):
    return dict(side=side, D_over_L=point.mu, phi_star=point.p, phi_star_over_pi=point.p / math.pi,
                kind=point.kind, morse_before=point.morse_before, morse_after=point.morse_after,
                critical_eigenvalue=point.critical_eigenvalue, residual=point.residual,
                dphi_dratio=point.dp_dmu, predictor=point.predictor, seconds=point.seconds)


def critical_twist_curve(knot, N, ratios, options=None, *, out=None, progress=None, fresh=False):
    """phi*+-(D/L) of ``knot`` ("3_1", "4_1", "5_1", "5_2") at N nodes over ``ratios`` (D/L values).

    Returns a dict: rows (one per side and ratio, the CSV's columns), legs (how each run up or
    down ended), seconds (this run), resumed_points (rows taken from ``out``). progress(str): a
    line per point and per failed try. The knot at every ratio is checked first (N >= L/D, L/D
    above the ideal ropelength): ValueError naming ratios or N. Raises RuntimeError when a side has
    no instability within +-span at the start ratio. With ``out``: written as it goes and resumed
    from what is there (see the module docstring); ``fresh``: start over.
    """
    from .bifurcation import ContinuationOptions as PathOptions
    from .bifurcation.event_curve import EventCurveOptions, event_curve
    from .bifurcation.rods import knot_problem, set_diameter
    from .continuation import ContinuationOptions, NoCrossingError, follow_twist
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
    rows, legs, resumed = [], {}, 0
    csv_path = None
    if out is not None:
        os.makedirs(out, exist_ok=True)
        if _check_folder(out, _settings(knot, N, r, start, opts), fresh):
            say(f"resuming from {out}/")
        csv_path = os.path.join(out, "critical_curve.csv")

    def stored(side, leg):
        """The points on file of one leg, in order: [(point, recorded)]."""
        if out is None:
            return []
        names = sorted(glob.glob(os.path.join(out, "points", f"{side}_{leg}_*.npz")))
        return [_load_point(name) for name in names]

    def record(side, point):
        row = _row(side, point)
        rows.append(row)
        say(f"[{side}] D/L = {point.mu:.5f}: {point.kind} at {point.p / math.pi:+.8f} pi (Morse {point.morse_before} -> "
            f"{point.morse_after}, dphi*/d(D/L) = {point.dp_dmu / math.pi:+.3f} pi, {point.seconds:.1f} s)")
        if csv_path is not None:
            with open(csv_path, "a", newline="") as f:
                csv.writer(f).writerow([row[c] if not isinstance(row[c], float) else repr(row[c]) for c in CSV_COLUMNS])

    if out is not None:  # the rows on file, in the order they came, and nothing half-written
        for side in opts.sides:
            for leg in ("up", "down"):
                rows += [_row(side, point) for point, recorded in stored(side, leg) if recorded]
        resumed = len(rows)
        write_rows(csv_path, CSV_COLUMNS, [{c: (repr(v) if isinstance(v, float) else v) for c, v in row.items()}
                                           for row in rows])

    for side in opts.sides:
        sign = SIDE_SIGNS[side]
        scene = make_knot(knot, start, 1.0, N, nu=opts.nu, contact_stiffness=opts.contact_stiffness)
        start_file = None if out is None else os.path.join(out, f"start_{side}.npz")
        if start_file is not None and os.path.exists(start_file):
            with np.load(start_file) as f:
                q_start, phi_start = np.array(f["q"]), float(f["phi"])
        else:
            path = follow_twist(scene, 0.0, sign * opts.span,
                                ContinuationOptions(step=0.5 * math.pi, tol=1e-2 * math.pi, max_switches=0))
            if not path.instabilities:
                raise NoCrossingError(f"{knot} at D/L = {start:g}: no instability on the {side} side within "
                                      f"{sign * opts.span / math.pi:+g} pi ({path.reason})")
            end = path.instabilities[0].phi
            before = [p.equilibrium for p in path.points if p.branch.startswith("symmetric")
                      and sign * (end - p.equilibrium.phi) >= 0.2 * math.pi]
            e = before[-1] if before else path.points[0].equilibrium
            q_start, phi_start = np.asarray(e.q), float(e.phi)
            say(f"[{side}] stable-only engine: branch end near {end / math.pi:+.3f} pi; events from "
                f"{phi_start / math.pi:+.3f} pi")
            if start_file is not None:
                savez(start_file, q=q_start, phi=np.asarray(phi_start))
        path_opts = PathOptions(ds=0.05 * sign, ds_min=1e-6, ds_max=opts.ds_max, newton_tol=1e-10, eig_rtol=1e-13,
                                n_eig=6, p_min=-opts.span - math.pi, p_max=opts.span + math.pi)
        curve_opts = EventCurveOptions(path_opts, opts.delta, max_jump=opts.max_jump, max_points=opts.max_points)
        for leg, values in (("up", [v for v in r if v > start]), ("down", [v for v in r[::-1] if v < start])):
            if leg == "down" and not values:  # the up leg has done the start ratio
                continue
            key = f"{side}_{leg}"
            leg_file = None if out is None else os.path.join(out, "legs", key + ".json")
            if leg_file is not None and os.path.exists(leg_file):
                with open(leg_file) as f:
                    legs[key] = json.load(f)
                continue
            done = stored(side, leg)
            last = done[-1][0] if done else None
            if last is not None:  # go on after the last point on file
                values = [v for v in values if _leg_sign(leg) * (v - last.mu) > 0]
                say(f"[{side}] {leg}: {len(done)} points on file, going on from D/L = {last.mu:.5f}")
            rod = knot_problem(scene, q_start, phi_start)
            prob = rod.problem
            skip_start = leg == "down" and f"{side}_up" in legs  # the start ratio is the up leg's first point
            counter = [len(done)]

            def observer(point, side=side, leg=leg, skip_start=skip_start, counter=counter):
                recorded = not (skip_start and point.mu == start)
                if out is not None:
                    _save_point(os.path.join(out, "points", f"{side}_{leg}_{counter[0]:03d}.npz"), point, recorded)
                counter[0] += 1
                if recorded:
                    record(side, point)

            first = (prob.u0, prob.p0) if last is None else [q for q, _ in done]  # a resumed leg: its points
            curve = event_curve(prob, first, set_diameter, start, values, curve_opts, observer=observer,
                                progress=lambda m, side=side: say(f"[{side}]   {m}"))
            legs[key] = dict(result=curve.result.value, message=curve.message, points=counter[0])
            if leg_file is not None:
                write_json(leg_file, legs[key])
    rows.sort(key=lambda q: (list(SIDE_SIGNS).index(q["side"]), q["D_over_L"]))
    rows = _slope_checks(rows)
    doubtful = [f"{q['side']} D/L = {q['D_over_L']:.5f}" for q in rows if q["slope_disagreement"] > SLOPE_DOUBT]
    if doubtful:
        say(f"dphi*/d(D/L) from the implicit function theorem disagrees with the secant of the neighbouring "
            f"points by more than {SLOPE_DOUBT:.0%} at {', '.join(doubtful)}: a nearly degenerate event whose "
            "slope holds only over a range far below the step in D/L (see slope_disagreement)")
    seconds = time.perf_counter() - t0
    result = dict(knot=knot, N=N, ratios=r.tolist(), start_ratio=start, options=asdict(opts), legs=legs, rows=rows,
                  seconds=seconds, resumed_points=resumed)
    if out is not None:
        write_rows(csv_path, CSV_COLUMNS + CHECK_COLUMNS, [{c: (repr(v) if isinstance(v, float) else v)
                                                           for c, v in row.items()} for row in rows])
        write_json(os.path.join(out, "critical_curve.json"), result)
        _figure(result, os.path.join(out, "critical_curve.png"))
    return result


# A row's dphi*/d(D/L) from the implicit function theorem is checked against the secant of its
# neighbours on the curve (central where it has two): on a smooth curve sampled at 0.001 in D/L the
# two agree to a few per cent; at a nearly degenerate branch point the theorem's slope holds only
# over a sliver of D/L (the trefoil's tightening side at N = 128, D/L = 0.039: -7570 pi).
SLOPE_DOUBT = 0.5
CHECK_COLUMNS = ("secant_slope", "slope_disagreement")


def _slope_checks(rows):
    """rows (sorted by side, then D/L) with secant_slope (the neighbours' secant of phi*, nan for
    a lone point) and slope_disagreement = |ift - secant| / max(|ift|, |secant|) (0 where equal, up
    to 2 for opposite signs; nan without a secant)."""
    out = []
    for side in SIDE_SIGNS:
        mine = [dict(q) for q in rows if q["side"] == side]
        for i, q in enumerate(mine):
            a, b = mine[max(i - 1, 0)], mine[min(i + 1, len(mine) - 1)]
            secant = (b["phi_star"] - a["phi_star"]) / (b["D_over_L"] - a["D_over_L"]) if b is not a else math.nan
            ift = float(q["dphi_dratio"])
            scale = max(abs(ift), abs(secant))
            q["secant_slope"] = float(secant)
            q["slope_disagreement"] = float(abs(ift - secant) / scale) if math.isfinite(secant) and scale > 0 else \
                math.nan
            out.append(q)
    return out


def _leg_sign(leg):
    """+1 for the leg going up in D/L, -1 for the one going down."""
    return 1.0 if leg == "up" else -1.0


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
