"""A knot's critical twists as curves in its slenderness: phi*+-(D/L).

Every row is the point study's first instability (``twist_study`` from a minimum at phi = 0,
then ``jaxrod.studies.diagram.unstable_branches``) at its ratio, so it does not depend on the other
ratios. Continuation in D from one event would follow that event, not the first instability, and
a loose knot's near-null slides make it drift; it is used only for the exact slope dphi*/d(D/L)
from the implicit function theorem (D varied at fixed L, N, E and nu: ``set_diameter``).

Along a side, a change of the first instability's kind between neighbouring ratios is marked
(``switched``, ``previous_kind``, ``previous_ratio``) and warned about. Each slope is checked
against the secant of its located neighbours of the same kind, never across a switch, and a
disagreement above SLOPE_DOUBT is warned about. A row whose point study keeps its bracket's
estimate is kind "bracketed" (no slope), with a warning.

With ``out`` the rows go to ``critical_curve.csv`` as they are found, then ``critical_curve.json``
and ``critical_curve.png``. A run on the same folder with the same settings resumes from the
per-ratio files ``points/ratio_<k>.json`` (``fresh=True`` starts over; other settings are refused).
"""
from __future__ import annotations

import csv
import glob
import json
import math
import os
import shutil
import time
import warnings
from dataclasses import asdict, dataclass

import numpy as np

from ..io.atomic import write_json, write_rows
from ..validation import check_int_at_least, check_positive

__all__ = ["CriticalCurveOptions", "critical_twist_curve", "first_instabilities", "json_ready", "CSV_COLUMNS"]

SIDE_SIGNS = {"plus": 1.0, "minus": -1.0}
CSV_COLUMNS = ("side", "D_over_L", "phi_star", "phi_star_over_pi", "kind", "located", "morse_before",
               "morse_after", "critical_eigenvalue", "residual", "dphi_dratio", "switched", "previous_kind",
               "previous_ratio", "phi_bracketed", "phi_located", "seconds")
# the twist an unasked side is followed to (the study runs both sides; this one costs a step)
UNASKED_SPAN = 0.01 * math.pi
# The rod's length (mm) at every ratio: the point study's default, so a row matches it to roundoff.
LENGTH = 292.0


@dataclass(frozen=True)
class CriticalCurveOptions:
    """Settings of ``critical_twist_curve``.

    sides: "plus" (phi > 0) and/or "minus"; start_ratio: the D/L done first, then those above it
    going up, then those below going down (default: the ratio in the middle of those asked for; the
    rows do not depend on it); span: each side's first end is searched up to +-span (rad); slopes:
    dphi*/d(D/L) at each located event (False: nan, and no slope check); nu, contact_stiffness:
    the rod's Poisson ratio and contact penalty (units of B/D^3).
    """

    sides: tuple = ("plus", "minus")
    start_ratio: float | None = None
    span: float = 16.0 * math.pi
    slopes: bool = True
    nu: float = 0.5
    contact_stiffness: float = 100.0

    def __post_init__(self):
        sides = (self.sides,) if isinstance(self.sides, str) else tuple(self.sides)
        if not sides or any(s not in SIDE_SIGNS for s in sides):
            raise ValueError(f"sides must be 'plus' and/or 'minus', got {self.sides!r}")
        object.__setattr__(self, "sides", tuple(s for s in SIDE_SIGNS if s in sides))
        check_positive("span", self.span)
        if not isinstance(self.slopes, (bool, np.bool_)):
            raise ValueError(f"slopes must be True or False, got {self.slopes!r}")


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
                differ += [f"options.{k}" for k in sorted(set(settings["options"]) | set(stored.get("options", {})))
                           if stored.get("options", {}).get(k) != settings["options"].get(k)]
            raise ValueError(f"out: {out} holds a critical curve with other settings ({', '.join(differ)}); "
                             "give another folder, or fresh=True (the CLI's --fresh) to start over")
        return True
    for name in ("points", "legs"):
        shutil.rmtree(os.path.join(out, name), ignore_errors=True)
    for name in glob.glob(os.path.join(out, "start_*.npz")):
        os.remove(name)
    os.makedirs(os.path.join(out, "points"), exist_ok=True)
    write_json(path, settings)
    return False


def first_instabilities(knot, N, ratio, options=None, *, progress=None):
    """The point study's first instability on each side of ``options.sides`` at one D/L.

    ``twist_study`` (no branch switching) to each side's first end within +-options.span, then
    ``unstable_branches``; phi* is the study's ``phi_plus`` / ``phi_minus`` (kind "bracketed" where
    the study keeps its bracket's estimate), with dphi*/d(D/L) at a located event.

    Returns {side: row dict (``CSV_COLUMNS`` less switched / previous_kind / previous_ratio) or a
    str saying why there is none (no end within the span)}.
    """
    from ..continuation.arclength.event_curve import branch_point_sensitivity
    from ..continuation.arclength.rods import set_diameter
    from ..continuation.arclength.two_parameter import fold_sensitivity
    from ..continuation import ContinuationOptions
    from ..continuation.kinds import EventKind
    from .diagram import unstable_branches
    from ..model.scenes import knot as make_knot
    from .twist import twist_study

    opts = options or CriticalCurveOptions()
    say = progress or (lambda line: None)
    t0 = time.perf_counter()
    scene = make_knot(knot, D=ratio * LENGTH, L=LENGTH, N=N, nu=opts.nu, contact_stiffness=opts.contact_stiffness)
    phi_max = opts.span if "plus" in opts.sides else UNASKED_SPAN
    phi_min = -opts.span if "minus" in opts.sides else -UNASKED_SPAN
    study = twist_study(scene, phi_min, phi_max, ContinuationOptions(max_switches=0))
    with warnings.catch_warnings():  # a located end outside the study's bracket: warned about per row
        warnings.simplefilter("ignore")
        diagram = unstable_branches(scene, study, progress=lambda line: say(f"  {line}"))
    critical = diagram.study.critical
    seconds = (time.perf_counter() - t0) / len(opts.sides)
    found = {}
    for side in opts.sides:
        phi = critical.get(f"phi_{side}")
        if phi is None:
            found[side] = (f"no instability within {SIDE_SIGNS[side] * opts.span / math.pi:+g} pi "
                           f"({critical.get('stopped_' + side, 'not followed')})")
            continue
        inst = next(c for c in critical["instabilities"] if c["direction"] == side)
        end = diagram.ends[critical["instabilities"].index(inst)]
        ev = end.event
        row = dict(side=side, D_over_L=float(ratio), phi_star=float(phi), phi_star_over_pi=float(phi) / math.pi,
                   kind="bracketed", located=False, morse_before=None, morse_after=None,
                   critical_eigenvalue=math.nan, residual=math.nan, dphi_dratio=math.nan,
                   phi_bracketed=float(inst["phi"]), phi_located=math.nan if ev is None or not ev.converged
                   else float(ev.p), seconds=seconds)
        if critical.get(f"phi_{side}_located") is not None and ev is not None and float(ev.p) == float(phi):
            t = time.perf_counter()
            slope = math.nan
            if opts.slopes:
                sensitivity = fold_sensitivity if ev.kind == EventKind.FOLD else branch_point_sensitivity
                # dphi*/d(D/L) = L dphi*/dD, D in the scene's units
                slope = LENGTH * float(sensitivity(end.rod.problem, ev, set_diameter, float(ratio) * LENGTH))
            row.update(kind=ev.kind, located=True, morse_before=int(ev.morse_before),
                       morse_after=int(ev.morse_after), critical_eigenvalue=float(ev.critical_eigenvalue),
                       residual=float(ev.residual), dphi_dratio=slope, seconds=seconds + time.perf_counter() - t)
        found[side] = row
    return found


def _cell(v):
    return repr(v) if isinstance(v, float) else v


def _say_row(say, row):
    if row["located"]:
        say(f"[{row['side']}] D/L = {row['D_over_L']:.5f}: {row['kind']} at {row['phi_star_over_pi']:+.10f} pi "
            f"(Morse {row['morse_before']} -> {row['morse_after']}, dphi*/d(D/L) = {row['dphi_dratio'] / math.pi:+.3f} "
            f"pi, {row['seconds']:.1f} s)")
    else:
        say(f"[{row['side']}] D/L = {row['D_over_L']:.5f}: bracketed at {row['phi_star_over_pi']:+.8f} pi (the study's "
            f"estimate, as the point study reports it; Morse index and slope unknown: {_unlocated(row)}; "
            f"{row['seconds']:.1f} s)")


def _unlocated(row):
    if math.isnan(row["phi_located"]):
        return "the end was not located on its extended system"
    return (f"the end located on its extended system, at {row['phi_located'] / math.pi:+.8f} pi, is not the study's "
            "onset (outside its bracket, or not its critical mode)")


def _order(r, start):
    """The ratios in the order they are done: from start up, then below it going down."""
    return [v for v in r if v >= start] + [v for v in r[::-1] if v < start]


def critical_twist_curve(knot, N, ratios, options=None, *, out=None, progress=None, fresh=False):
    """phi*+-(D/L) of ``knot`` ("3_1", "4_1", "5_1", "5_2") at N nodes over ``ratios`` (D/L values).

    Each row is ``first_instabilities`` at its ratio. Returns a dict: rows (one per side and
    ratio where an end was located, sorted by side then D/L, the CSV's columns with CHECK_COLUMNS),
    failures (side, D_over_L, message where none was), switches (the rows where the kind changed),
    seconds (this run), resumed_points (rows taken from ``out``). progress(str): a line per row.
    The knot at every ratio is built first: ValueError naming ratios or N. Raises NoCrossingError
    when a side has no located end at any ratio; warns where a ratio has none, where the kind
    switches, where a row keeps the bracket's estimate and where a slope disagrees with its secant.
    With ``out``: written as it goes and resumed (``fresh``: start over).
    """
    t0 = time.perf_counter()
    opts = options or CriticalCurveOptions()
    N, r, start = _checked_inputs(knot, N, ratios, opts)
    say = progress or (lambda s: None)
    files = _CurveFiles(out, r) if out is not None else None
    if files is not None and _check_folder(out, _settings(knot, N, r, start, opts), fresh):
        say(f"resuming from {out}/")
    rows, failures, todo = _resumed(files, _order(r, start))
    resumed = len(rows)
    if files is not None:
        write_rows(files.csv, CSV_COLUMNS, [{c: _cell(v) for c, v in row.items()} for row in rows])
    for ratio in todo:
        new_rows, new_failures = _ratio_rows(knot, N, ratio, opts, say, files)
        rows += new_rows
        failures += new_failures
    rows, failures = _checked_rows(knot, N, opts, rows, failures)
    switches = [dict(side=q["side"], D_over_L=q["D_over_L"], kind=q["kind"], previous_kind=q["previous_kind"])
                for q in rows if q["switched"]]
    result = dict(knot=knot, N=N, ratios=r.tolist(), start_ratio=start, options=asdict(opts), rows=rows,
                  failures=failures, switches=switches, seconds=time.perf_counter() - t0, resumed_points=resumed)
    if files is not None:
        write_rows(files.csv, CSV_COLUMNS + CHECK_COLUMNS, [{c: _cell(v) for c, v in row.items()} for row in rows])
        write_json(os.path.join(out, "critical_curve.json"), result)
        _figure(result, os.path.join(out, "critical_curve.png"))
    return result


def _checked_inputs(knot, N, ratios, opts):
    """(N, the sorted ratios, the start ratio), each checked; the knot is built at every ratio
    first, so that a ratio it cannot be tied at (N < L/D, L/D below the ropelength) is named."""
    from ..model.scenes import knot as make_knot

    N = check_int_at_least("N", N, 24)
    r = _ratios(ratios)
    start = float(r[len(r) // 2]) if opts.start_ratio is None else check_positive("start_ratio", opts.start_ratio)
    if not r[0] <= start <= r[-1]:
        raise ValueError(f"start_ratio = {start:g} must lie within the ratios ({r[0]:g} ... {r[-1]:g})")
    for ratio in r:
        try:
            make_knot(knot, D=ratio * LENGTH, L=LENGTH, N=N, nu=opts.nu, contact_stiffness=opts.contact_stiffness)
        except ValueError as exc:
            what = "N" if str(exc).startswith("N") else "ratios"
            raise ValueError(f"{what}: {knot} at D/L = {ratio:g}, N = {N}: {exc}") from None
    return N, r, start


@dataclass(frozen=True)
class _CurveFiles:
    """Where a curve run writes: the folder, its CSV and one JSON file per ratio done."""

    out: str
    ratios: np.ndarray

    def __post_init__(self):
        os.makedirs(self.out, exist_ok=True)

    @property
    def csv(self):
        return os.path.join(self.out, "critical_curve.csv")

    def point(self, ratio):
        return os.path.join(self.out, "points", f"ratio_{int(np.searchsorted(self.ratios, ratio)):04d}.json")


def _resumed(files, ordered):
    """(rows, failures) of the ratios already on file, in the order they were done, and the ratios
    still to do."""
    rows, failures, todo = [], [], []
    for ratio in ordered:
        path = None if files is None else files.point(ratio)
        if path is not None and os.path.exists(path):
            with open(path) as f:
                done = json.load(f)
            rows += done["rows"]
            failures += done["failures"]
        else:
            todo.append(ratio)
    return rows, failures, todo


def _ratio_rows(knot, N, ratio, opts, say, files):
    """The point study's rows and failures at one ratio, written (point file, CSV row) and said."""
    found = first_instabilities(knot, N, ratio, opts, progress=say)
    rows = [found[s] for s in opts.sides if isinstance(found[s], dict)]
    failures = [dict(side=s, D_over_L=float(ratio), message=found[s]) for s in opts.sides
                if not isinstance(found[s], dict)]
    if files is not None:
        write_json(files.point(ratio), {"ratio": float(ratio), "rows": rows, "failures": failures})
    for row in rows:
        _say_row(say, row)
        if files is not None:
            with open(files.csv, "a", newline="") as f:
                csv.DictWriter(f, fieldnames=CSV_COLUMNS, extrasaction="ignore").writerow(
                    {c: _cell(v) for c, v in row.items()})
    for failure in failures:
        say(f"[{failure['side']}] D/L = {ratio:.5f}: no row: {failure['message']}")
    return rows, failures


def _checked_rows(knot, N, opts, rows, failures):
    """Rows and failures sorted by side then D/L, the rows marked (kind switches, slope checks);
    NoCrossingError where a side has no row at all, a warning for each failure and each doubt."""
    from ..continuation import NoCrossingError

    for side in opts.sides:
        if not any(q["side"] == side for q in rows):
            first = next(f for f in failures if f["side"] == side)
            raise NoCrossingError(f"{knot} at N = {N}: no located instability on the {side} side at any ratio "
                                  f"(D/L = {first['D_over_L']:g}: {first['message']})")
    failures = sorted(failures, key=lambda q: (list(SIDE_SIGNS).index(q["side"]), q["D_over_L"]))
    for f in failures:
        warnings.warn(f"{f['side']} side, D/L = {f['D_over_L']:.5f}: no row ({f['message']})", stacklevel=3)
    rows = sorted(rows, key=lambda q: (list(SIDE_SIGNS).index(q["side"]), q["D_over_L"]))
    rows = _slope_checks(_mark_switches(rows))
    _warn(rows)
    return rows, failures


def _event_kind(row):
    """What identifies a located event along a side: its kind and how many eigenvalues cross there."""
    return row["kind"] if row["morse_after"] - row["morse_before"] == 1 else \
        f"{row['kind']} (Morse {row['morse_before']} -> {row['morse_after']})"


def _mark_switches(rows):
    """rows (sorted by side, then D/L) with switched (the kind differs from the located row below it
    on the same side), previous_kind and previous_ratio ('' and nan where there is none)."""
    out, before = [], {}
    for q in rows:
        q = dict(q)
        prev = before.get(q["side"])
        q["previous_kind"], q["previous_ratio"], q["switched"] = "", math.nan, False
        if q["located"]:
            if prev is not None:
                q["previous_kind"], q["previous_ratio"] = _event_kind(prev), prev["D_over_L"]
                q["switched"] = _event_kind(prev) != _event_kind(q)
            before[q["side"]] = q
        out.append(q)
    return out


def _warn(rows):
    for q in rows:
        if q["switched"]:
            message = (f"{q['side']} side: the first instability switches from a {q['previous_kind']} at D/L = "
                       f"{q['previous_ratio']:.5f} to a {_event_kind(q)} at {q['D_over_L']:.5f}: the curve goes on "
                       "with the new event (switched in the rows); no slope is compared across it")
            warnings.warn(message, stacklevel=4)
        if not q["located"]:
            message = (f"{q['side']} side, D/L = {q['D_over_L']:.5f}: phi* = {q['phi_star_over_pi']:+.8f} pi is the "
                       f"stable-only study's bracket estimate, as the point study reports it: {_unlocated(q)} (no "
                       "kind or slope for this row)")
            warnings.warn(message, stacklevel=4)
    doubtful = [f"{q['side']} D/L = {q['D_over_L']:.5f}" for q in rows if q["slope_disagreement"] > SLOPE_DOUBT]
    if doubtful:
        message = (f"dphi*/d(D/L) from the implicit function theorem disagrees with the secant of the neighbouring "
                   f"events of the same kind by more than {SLOPE_DOUBT:.0%} at {', '.join(doubtful)}: a nearly "
                   "degenerate event whose slope holds only over a range far below the step in D/L, or a jump to "
                   "another event of the same kind (see slope_disagreement)")
        warnings.warn(message, stacklevel=4)


# The largest relative disagreement of a row's IFT slope with its secant not warned about.
SLOPE_DOUBT = 0.5
CHECK_COLUMNS = ("secant_slope", "slope_disagreement")


def _slope_checks(rows):
    """rows (sorted, switches marked) with secant_slope (through the located neighbours on the same
    side with no switch between; nan without) and slope_disagreement = |ift - secant| /
    max(|ift|, |secant|)."""
    out = []
    for side in SIDE_SIGNS:
        mine = [dict(q) for q in rows if q["side"] == side]
        for i, q in enumerate(mine):
            below = mine[i - 1] if i > 0 else None
            above = mine[i + 1] if i + 1 < len(mine) else None
            a = below if q["located"] and below is not None and below["located"] and not q["switched"] else q
            b = above if q["located"] and above is not None and above["located"] and not above["switched"] else q
            secant = (b["phi_star"] - a["phi_star"]) / (b["D_over_L"] - a["D_over_L"]) if b is not a else math.nan
            ift = float(q["dphi_dratio"])
            scale = max(abs(ift), abs(secant))
            q["secant_slope"] = float(secant)
            q["slope_disagreement"] = float(abs(ift - secant) / scale) if math.isfinite(secant) and scale > 0 else \
                math.nan
            out.append(q)
    return out


def json_ready(value):
    """``value`` (a result of ``critical_twist_curve``) with every float that is not finite (a
    slope not computed, a secant without neighbours) as None: strict JSON, as the CLI prints it."""
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _figure(result, path):
    from ..io.plotting import plot_critical_curve

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
