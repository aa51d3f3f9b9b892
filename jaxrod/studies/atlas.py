"""Twisted-knot atlas: the critical twists phi*+ and phi*- of several knots over a range of
slenderness D/L, the seed paper's "future work".

One *case* is a knot, a slenderness D/L, a node count N and a side; ``knot_critical_twist``
answers it: the stable branch followed from phi = 0 until it ends, and that end located on its
extended system (a fold or a branch point, the kind ``critical_twists`` reports). Cases are
independent, so a sweep runs them serially or over a Dask cluster (``client=``) with the same numbers.

``run_atlas(..., out=DIR)`` writes, as it goes:

* ``atlas.json``  the settings (a resumed run must match them);
* ``atlas.csv``   one row per finished case (``FIELDS``), appended as each case ends and sorted
  by case when the sweep ends; a rerun skips the cases already there (resume);
* ``atlas.png``   phi*/pi against D/L, a panel per knot, with the Michell lines (``figures``);
* ``atlas.md``    the table, and the change of phi* with N where a case ran at several N;
* ``states/``     for each end that is a snap, the states on both sides of it (.npz: q_before,
  phi_before, q_after, phi_after).
"""
from __future__ import annotations

import csv
import json
import math
import os
import time
import warnings
from dataclasses import asdict, dataclass

import numpy as np

from ..io.atomic import savez, write_json, write_rows
from ..measure.chirality import ACHIRAL_TOL, mirror_distance
from ..measure.profiles import mode_pattern
from ..model.geometry import radius_of_gyration
from ..io.locking import holds_output_folder
from ..validation import check_finite, check_int_at_least, check_positive

__all__ = ["AtlasCase", "AtlasSettings", "FIELDS", "ACCURACY_LEVELS", "accuracy_levels", "atlas_cases", "knot_critical_twist", "run_atlas", "read_atlas",
           "figures", "report", "tightening_sides", "convergence_series"]

SIDES = ("plus", "minus")
FIELDS = ["knot", "D_over_L", "N", "side", "phi_star", "phi_star_over_pi", "phi_error", "kind", "located", "phi_study",
          "reason", "critical_eigenvalue", "dlambda_dphi", "mode_pattern", "lowest_eigenvalue_start", "Lk0",
          "mirror_distance_start", "Wr_start", "Wr_before", "Tw_before", "contact_count_change",
          "radius_of_gyration_change", "snap_moved", "snap_energy_change", "Wr_after", "contact_count_after",
          "phi_extrapolated", "extrapolation_error", "accuracy_reached", "accuracy_levels", "n_points", "seconds"]
# Columns a snap fills (NaN elsewhere) and those of the accuracy mode (NaN / empty without it); an
# atlas written before they existed reads with NaN / empty in them.
SNAP_FIELDS = ("snap_moved", "snap_energy_change", "Wr_after", "contact_count_after")
ACCURACY_FIELDS = ("phi_extrapolated", "extrapolation_error", "accuracy_reached", "accuracy_levels")
_OPTIONAL = (*SNAP_FIELDS, *ACCURACY_FIELDS)
_FLOATS = ("D_over_L", "phi_star", "phi_star_over_pi", "phi_error", "phi_study", "critical_eigenvalue",
           "dlambda_dphi", "lowest_eigenvalue_start", "mirror_distance_start", "Wr_start", "Wr_before", "Tw_before",
           "radius_of_gyration_change", *SNAP_FIELDS, "phi_extrapolated", "extrapolation_error", "seconds")
# The accuracy mode's levels, as multiples of the case's N (three: the order is measured).
ACCURACY_LEVELS = (1.0, 4.0 / 3.0, 5.0 / 3.0)
KNOTS = ("3_1", "4_1", "5_1", "5_2")


@dataclass(frozen=True)
class AtlasSettings:
    """What every case of a sweep shares: span (radians: each side is followed to +-span),
    step (largest continuation step, radians), tol (accuracy of the study's bracket, radians), nu
    (Poisson ratio), contact_stiffness (``jaxrod.knot``'s; None: no contact term); locate: each
    end bracketed by the study located on its extended system (a fold or branch point, as
    ``critical_twists`` does), else the study's bracket kept; accuracy (radians, None: off): each
    case's end also converged in N by ``accuracy.converged_critical_twists`` over the levels
    ``ACCURACY_LEVELS`` times N, its extrapolated value and error bar in the row."""

    span: float = 16.0 * math.pi
    step: float = 0.5 * math.pi
    tol: float = 1e-3 * math.pi
    nu: float = 0.5
    contact_stiffness: float | None = 100.0
    locate: bool = True
    accuracy: float | None = None

    def __post_init__(self):
        check_positive("span", self.span)
        check_positive("step", self.step)
        check_positive("tol", self.tol)
        nu = check_finite("nu", self.nu)
        if not -1.0 < nu < 0.5 + 1e-12:
            raise ValueError(f"nu must lie in (-1, 0.5], got {nu}")
        if self.contact_stiffness is not None:
            check_positive("contact_stiffness", self.contact_stiffness)
        if not isinstance(self.locate, (bool, np.bool_)):
            raise ValueError(f"locate must be True or False, got {self.locate!r}")
        if self.accuracy is not None:
            check_positive("accuracy", self.accuracy)

    def as_json(self):
        return json.loads(json.dumps(asdict(self)))


@dataclass(frozen=True)
class AtlasCase:
    """One study of the atlas: knot ('3_1', '4_1', '5_1', '5_2'), D_over_L, N, side ('plus':
    phi > 0, 'minus': phi < 0)."""

    knot: str
    D_over_L: float
    N: int
    side: str

    @property
    def key(self):
        return (self.knot, float(self.D_over_L), int(self.N), self.side)


def _scene(knot, D_over_L, N, settings):
    from ..model.scenes import knot as make_knot

    return make_knot(knot, D=D_over_L, L=1.0, N=N, nu=settings.nu, contact_stiffness=settings.contact_stiffness)


def atlas_cases(knots, ratios, N, settings=None, sides=SIDES):
    """The cases of a sweep, knot by knot, D/L ascending, N ascending, plus before minus; each
    (knot, D/L, N) is built now, so that a bad sweep is refused before any work. ``N``: an int or
    a list; sides: 'plus' (phi > 0) and/or 'minus'. Warnings are given once each."""
    settings = settings or AtlasSettings()
    sides = [sides] if isinstance(sides, str) else list(sides)
    if not sides or any(side not in SIDES for side in sides):
        raise ValueError(f"sides must be 'plus' and/or 'minus', got {sides!r}")
    sides = [side for side in SIDES if side in sides]
    knots = [knots] if isinstance(knots, str) else list(knots)
    if not knots:
        raise ValueError("knots: give at least one knot")
    ratios = [check_positive("ratios", r) for r in (np.atleast_1d(np.asarray(ratios, dtype=float)).tolist())]
    if not ratios:
        raise ValueError("ratios: give at least one D/L")
    ns = sorted({check_int_at_least("N", n, 4) for n in np.atleast_1d(N).tolist()})
    cases = []
    for knot in dict.fromkeys(knots):
        for ratio in sorted(set(ratios)):
            for n in ns:
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    try:
                        _scene(knot, ratio, n, settings)
                    except ValueError as exc:
                        # Name the sweep's parameter: a ratio too large for the knot, or too small for N.
                        what = "N" if str(exc).startswith("N") else "ratios"
                        raise ValueError(f"{what}: {knot} at D/L = {ratio:g}, N = {n}: {exc}") from None
                for w in caught:
                    if n == ns[0]:
                        warnings.warn(f"{knot} at D/L = {ratio:g}: {w.message}", stacklevel=2)
                cases.extend(AtlasCase(knot, float(ratio), int(n), side) for side in sides)
    return cases


def _contact_count(scene, e):
    from ..model.contact import contact_count

    if not scene.has_term("contact"):
        return 0
    nbr = e.neighbourhood if e.neighbourhood is not None else scene.neighbourhood(e.q, e.phi)
    return int(contact_count(e.x, nbr.pairs, nbr.mask, True, scene.material.D))


def _lowest_above_band(e):
    """The lowest eigenvalue above the near-null band of sliding modes (|lambda| < 1e-6 with
    contact): how deep a minimum is."""
    ev = np.asarray(e.stability.eigenvalues)
    above = ev[ev > e.stability.tol]
    return float(above[0]) if above.size else math.nan


def tightening_sides(rows):
    """{(knot, D/L, N): 'plus', 'minus' or 'equal'}: the side whose branch packs the strands
    together (``tightening_side``); only where both sides ran."""
    from .twist import tightening_side

    sides = {}
    for r in rows:
        sides.setdefault((r["knot"], r["D_over_L"], r["N"]), {})[r["side"]] = (
            r["contact_count_change"], r["radius_of_gyration_change"])
    # judged against the larger change, so mirror-image sides come out 'equal'
    return {k: tightening_side(v, scale=max(abs(v["plus"][1]), abs(v["minus"][1])))
            for k, v in sides.items() if len(v) == 2}


def knot_critical_twist(case, settings=None):
    """The first branch end of ``case`` (an ``AtlasCase`` or its dict) on its side: relax to a
    minimum at phi = 0 with the linking number Lk0 that leaves it untwisted (``relax_twist_free``;
    the drawing's nearest-integer writhe can be off by turns), follow the stable branch towards +-span, and (``settings.locate``) locate
    the end the study bracketed on its extended system. Returns a row (dict, ``FIELDS``): phi_star
    in radians (NaN when the branch reaches +-span), phi_error (the study's bracket, within which
    a located end lies), kind ('fold' or 'branch_point' where located; 'snap' where the study's jump
    is not explained by a located end and the rod jumps to another stable state inside the bracket
    (``continuation.snap``: snap_moved, snap_energy_change, Wr_after, contact_count_after, and both
    states in the row's ``states``, which ``run_atlas`` writes to states/*.npz); else the study's
    'unstable' or 'jump', with the reason), located ('yes' / 'no'), phi_study (the study's
    estimate), the critical eigenvalue at the last stable state and its rate, the start's lowest
    eigenvalue above the sliding band, the critical mode's m-fold pattern (``profiles.mode_pattern``;
    0 without an end), Lk0, the start's distance from its mirror image (``chirality.mirror_distance``),
    writhe and twist, the change in contacts and radius of
    gyration along the branch, n_points, seconds. Pure in its inputs."""
    from ..continuation import ContinuationOptions, follow_twist
    from ..solve.equilibrium import relax_twist_free

    if isinstance(case, dict):
        case = AtlasCase(**case)
    if isinstance(settings, dict):
        settings = AtlasSettings(**settings)
    settings = settings or AtlasSettings()
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # nearly-tight warnings were given by atlas_cases
        scene = _scene(case.knot, case.D_over_L, case.N, settings)
    scene, start = relax_twist_free(scene)  # phi = 0 is the untwisted knot, whatever the drawing's writhe
    sign = 1.0 if case.side == "plus" else -1.0
    options = ContinuationOptions(step=settings.step, tol=settings.tol, switch=False)
    path = follow_twist(scene, 0.0, sign * settings.span, options, start=start)
    last = path.points[-1].equilibrium
    if path.instabilities:
        last = path.instabilities[0].equilibrium
    row = {"knot": case.knot, "D_over_L": case.D_over_L, "N": case.N, "side": case.side,
           "phi_star": math.nan, "phi_star_over_pi": math.nan, "phi_error": math.nan, "kind": "none",
           "located": "no", "phi_study": math.nan, "reason": path.reason, "critical_eigenvalue": math.nan,
           "dlambda_dphi": math.nan,
           "lowest_eigenvalue_start": _lowest_above_band(start), "Lk0": int(round(float(scene.Lk0))),
           "mirror_distance_start": mirror_distance(start.x), "Wr_start": float(start.Wr), "mode_pattern": 0,
           "Wr_before": float(last.Wr), "Tw_before": float(last.Tw),
           "contact_count_change": _contact_count(scene, last) - _contact_count(scene, start),
           "radius_of_gyration_change": radius_of_gyration(last.x) - radius_of_gyration(start.x),
           **{name: math.nan for name in SNAP_FIELDS}, "phi_extrapolated": math.nan,
           "extrapolation_error": math.nan, "accuracy_reached": "", "accuracy_levels": "", "n_points": len(path.points)}
    if path.instabilities:
        inst = path.instabilities[0]
        row.update(phi_star=float(inst.phi), phi_star_over_pi=float(inst.phi) / math.pi,
                   phi_error=float(inst.phi_error), kind=str(inst.kind.value), phi_study=float(inst.phi),
                   critical_eigenvalue=float(inst.eigenvalue), mode_pattern=_mode_pattern(scene, inst),
                   dlambda_dphi=float(inst.dlambda_dphi_secant if math.isfinite(inst.dlambda_dphi_secant)
                                      else inst.dlambda_dphi))
        if settings.locate:
            row.update(_located_end(scene, inst, case.side, settings, row))
        if row["kind"] == "jump":
            row.update(_snap_fields(scene, path, options, row))
    if settings.accuracy is not None:
        row.update(_accuracy_fields(scene, case, settings, row))
    row["seconds"] = time.perf_counter() - t0
    return row


def accuracy_levels(N):
    """The node counts of a case's accuracy mode: ``ACCURACY_LEVELS`` times N, rounded."""
    return tuple(int(round(f * N)) for f in ACCURACY_LEVELS)


def _accuracy_fields(scene, case, settings, row):
    """The row's fields from the accuracy mode on the case's side (each level started from the
    previous one's state, resampled): the extrapolated phi* and its error, whether the accuracy
    asked for was reached, and every level's phi*; the mode's reason appended to the row's."""
    from .accuracy import converged_critical_twists

    result = converged_critical_twists(scene, settings.accuracy, sides=(case.side,), levels=accuracy_levels(case.N),
                                       span=settings.span, step=settings.step, parallel=False)[case.side]
    phi = result.phi_star
    return {"phi_extrapolated": math.nan if phi is None else float(phi),
            "extrapolation_error": float(result.error) if phi is not None else math.nan,
            "accuracy_reached": "yes" if result.reached else "no",
            "accuracy_levels": ";".join(f"{lv.N}:{lv.phi_star / math.pi:+.6f}" for lv in result.levels),
            "reason": f"{row['reason']}; accuracy mode: {result.reason}"}


def _snap_fields(scene, path, options, row):
    """The row's fields for a jump that no located end explains: kind 'snap', with the state it
    snaps to (``snap_of``; ``states``: both states as arrays, written by ``run_atlas``), or the jump
    kept with the reason where no stable state is found beyond it."""
    from ..continuation.snap import snap_of

    snap = snap_of(scene, path, options)
    if snap is None:
        return {"reason": f"{row['reason']}; no stable state found beyond the jump"}
    return {"kind": "snap", "reason": f"{row['reason']}; {snap.summary()}", "snap_moved": snap.moved,
            "snap_energy_change": snap.energy_change, "Wr_after": float(snap.after.Wr),
            "contact_count_after": _contact_count(scene, snap.after), "states": snap.arrays()}


def _mode_pattern(scene, inst):
    """The m-fold pattern (``profiles.mode_pattern``) of the study's critical mode at its last
    stable state."""
    q = np.asarray(inst.equilibrium.q)
    dq = scene.from_scaled(np.asarray(inst.mode))
    x = np.asarray(scene.positions(q))
    return mode_pattern(x, np.asarray(scene.positions(q + dq)) - x)


def _located_end(scene, inst, side, settings, row):
    """The row's fields for the end the study bracketed (``inst``), located on its extended system
    from the study's last stable state (``diagram.locate_end``): phi_star and kind of the located
    fold or branch point where it lies in the study's bracket, else the study's with the reason."""
    from .diagram import DiagramOptions, locate_end

    entry = {"direction": side, "from_branch": inst.from_branch or "symmetric", "kind": str(inst.kind.value),
             "bracket": list(inst.bracket),
             "phi": float(inst.phi), "phi_error": float(inst.phi_error), "eigenvalue": row["critical_eigenvalue"],
             "dlambda_dphi": row["dlambda_dphi"], "negative_tol": float(inst.negative_tol)}
    state = (np.asarray(inst.equilibrium.q), float(inst.equilibrium.phi))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # said in the row: located, or the reason it was not
        end = locate_end(scene, entry, state, DiagramOptions(unstable_points=1), p_min=-settings.span,
                         p_max=settings.span, mode=np.asarray(inst.mode))
    ev = end.event
    if ev is None or not ev.converged:
        return {"reason": f"{row['reason']}; not located: {end.message}"}
    if not end.within_bracket:
        return {"reason": f"{row['reason']}; the {getattr(ev.kind, 'value', ev.kind)} located at "
                          f"{ev.p / math.pi:+.8f} pi lies outside the study's bracket: the study's value kept"}
    return {"phi_star": float(ev.p), "phi_star_over_pi": float(ev.p) / math.pi,
            "kind": str(getattr(ev.kind, "value", ev.kind)), "located": "yes",
            "reason": f"{row['reason']}; {end.message}"}


def _case_of(row):
    return AtlasCase(row["knot"], float(row["D_over_L"]), int(row["N"]), row["side"])


def read_atlas(path):
    """Rows of an atlas CSV (a folder or the file) with numbers as floats / ints; raises
    ValueError naming the file if a column of ``FIELDS`` is missing."""
    if os.path.isdir(path):
        path = os.path.join(path, "atlas.csv")
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in FIELDS if c not in (reader.fieldnames or []) and c not in _OPTIONAL]
        if missing:
            raise ValueError(f"{path}: missing column(s) {', '.join(missing)} (an atlas CSV has {', '.join(FIELDS)})")
        rows = []
        for r in reader:
            if None in r.values() or len(r) != len(reader.fieldnames):
                continue  # a row cut short by an interruption
            for c in _FLOATS:
                r[c] = float(r.get(c, math.nan))
            for c in ("accuracy_reached", "accuracy_levels"):
                r[c] = r.get(c, "")
            r["N"], r["n_points"], r["contact_count_change"] = int(r["N"]), int(r["n_points"]), int(r["contact_count_change"])
            r["Lk0"], r["mode_pattern"] = int(r["Lk0"]), int(r["mode_pattern"])
            rows.append(r)
    return rows


def _check_folder(out, settings, fresh):
    """Create ``out``; refuse one holding an atlas of other settings (unless fresh: start over)."""
    os.makedirs(out, exist_ok=True)
    settings_path, csv_path = os.path.join(out, "atlas.json"), os.path.join(out, "atlas.csv")
    if fresh:
        for p in (settings_path, csv_path):
            if os.path.exists(p):
                os.remove(p)
    if os.path.exists(settings_path):
        with open(settings_path) as f:
            old = {**asdict(AtlasSettings()), **json.load(f)}  # a setting added since: its default
        if old != settings.as_json():
            raise ValueError(f"out: {out} holds an atlas with other settings (see its atlas.json): use another "
                             "folder, or start over there (fresh=True; the CLI's --fresh)")
    write_json(settings_path, settings.as_json())


def _keep_whole_rows(csv_path):
    """The finished rows of an interrupted sweep (a last row cut short is dropped)."""
    if not os.path.exists(csv_path):
        return []
    try:
        rows = read_atlas(csv_path)
    except ValueError:
        rows = []
    write_rows(csv_path, FIELDS, rows)
    return rows


@holds_output_folder
def run_atlas(knots=KNOTS, ratios=(0.01, 0.015, 0.02, 0.0274, 0.03, 0.035), N=101, settings=None, out=None,
              client=None, fresh=False, on_row=None, sides=SIDES):
    """Critical twists of every (knot, D/L, N, side) case (``atlas_cases``).

    out: folder for atlas.json / atlas.csv (rows appended as cases end; cases already there are
    skipped, so an interrupted sweep resumes); client: a ``dask.distributed.Client`` to spread
    the cases over (None: one after the other in this process); on_row(row, n_done, n_total):
    called as each case ends (progress); sides: both by default, or one ('plus' / 'minus').
    Returns the rows of all the cases, sorted by case.
    A case that fails raises (its message names the case); the cases done before stay on file.
    """
    settings = settings or AtlasSettings()
    cases = atlas_cases(knots, ratios, N, settings, sides)
    order = {c.key: i for i, c in enumerate(cases)}
    csv_path = None
    done = {}
    if out is not None:
        _check_folder(out, settings, fresh)
        csv_path = os.path.join(out, "atlas.csv")
        for r in _keep_whole_rows(csv_path):
            done[_case_of(r).key] = r
    todo = [c for c in cases if c.key not in done]
    n_total, n_done = len(cases), len(cases) - len(todo)

    def finished(row):
        nonlocal n_done
        n_done += 1
        states = row.pop("states", None)
        if states is not None and out is not None:
            _write_snap_states(out, _case_of(row), states)
        done[_case_of(row).key] = row
        if csv_path is not None:
            new = not os.path.exists(csv_path)
            with open(csv_path, "a", newline="") as f:
                w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
                if new:
                    w.writeheader()
                w.writerow(row)
                f.flush()
        if on_row is not None:
            on_row(row, n_done, n_total)

    if client is None:
        for case in todo:
            finished(_checked(knot_critical_twist, case, settings))
    else:
        from distributed import as_completed

        futures = {client.submit(_checked, knot_critical_twist, case, settings, pure=False): case for case in todo}
        try:
            for future in as_completed(futures):
                finished(future.result())
        finally:
            for future in futures:
                future.cancel()
    rows = sorted((r for k, r in done.items() if k in order), key=lambda r: order[_case_of(r).key])
    if csv_path is not None:  # with the cases of earlier sweeps into this folder, in case order
        write_rows(csv_path, FIELDS, sorted(done.values(), key=_case_order))
    return rows


def _write_snap_states(out, case, states):
    """Both states of a snap, as ``states/<knot>_<D/L>_N<N>_<side>.npz`` in ``out``."""
    folder = os.path.join(out, "states")
    os.makedirs(folder, exist_ok=True)
    savez(os.path.join(folder, f"{case.knot}_{case.D_over_L:g}_N{case.N}_{case.side}.npz"), **states)


def _case_order(row):
    """Knot, D/L, N ascending, plus before minus (the order of ``atlas_cases``)."""
    case = _case_of(row)
    return (case.knot, case.D_over_L, case.N, SIDES.index(case.side))


def _checked(fn, case, settings):
    """fn(case, settings), its failure re-raised with the case named."""
    try:
        return fn(case, settings)
    except Exception as exc:  # noqa: BLE001 -- re-raised with the case named
        raise RuntimeError(f"atlas case {case.knot} D/L = {case.D_over_L:g} N = {case.N} {case.side}: "
                           f"{type(exc).__name__}: {exc}") from exc


# ------------------------------------------------------------------------------------ outputs
def _yes_no(tight_side, side):
    return "?" if tight_side is None else "equal" if tight_side == "equal" else "yes" if tight_side == side else "no"


def _chirality(distance):
    """'achiral' where a start's mirror distance is within ``ACHIRAL_TOL``, else 'chiral'."""
    return "achiral" if distance <= ACHIRAL_TOL else "chiral"


def _main_rows(rows):
    """The rows at each (knot, D/L)'s most common N (the sweep's N; other N are convergence)."""
    counts = {}
    for r in rows:
        counts[r["N"]] = counts.get(r["N"], 0) + 1
    main_n = max(counts, key=lambda n: (counts[n], -n)) if counts else None
    return [r for r in rows if r["N"] == main_n], main_n


def figures(out, rows=None, path=None, nu=None):
    """atlas.png in ``out`` (or ``path``): phi*/pi against D/L per knot, both sides, with the
    Michell lines +-phi_M and +-2 phi_M (phi_M = 2 pi sqrt(3) (1 + nu)), cases that reach the
    span without an end marked at +-span; beside it atlas_convergence.png (phi* against 1/N^2)
    where cases ran at several N. Returns the path of atlas.png."""
    from ..io.plotting import plot_atlas
    from ..model.scenes import michell_critical_twist

    if rows is None:
        rows = read_atlas(out)
    if nu is None:
        with open(os.path.join(out, "atlas.json")) as f:
            stored = json.load(f)
        nu, span = stored["nu"], stored["span"]
    else:
        span = None
    main, n = _main_rows(rows)
    path = path or os.path.join(out, "atlas.png")
    plot_atlas(main, michell=michell_critical_twist(nu), span=span, tightening=tightening_sides(main), path=path,
               title=f"Twisted-knot atlas (N = {n})")
    series = convergence_series(rows)
    if series:
        from ..io.plotting import plot_atlas_convergence

        plot_atlas_convergence(series, path=os.path.join(os.path.dirname(path), "atlas_convergence.png"))
    return path


def convergence_series(rows):
    """{(knot, D/L, side): [(N, phi*), ...] ascending in N} for the cases run at several N with an
    end found at each."""
    groups = {}
    for r in rows:
        if math.isfinite(r["phi_star"]):
            groups.setdefault((r["knot"], r["D_over_L"], r["side"]), []).append((r["N"], r["phi_star"]))
    return {k: sorted(v) for k, v in groups.items() if len({n for n, _ in v}) > 1}


def report(out, rows=None):
    """atlas.md in ``out``: the table of phi* per knot, D/L and side, and where a (knot, D/L)
    ran at several N, phi* at each N with the change between successive N."""
    if rows is None:
        rows = read_atlas(out)
    lines = ["# Twisted-knot atlas: critical twists", "",
             "jaxrod sign convention (phi > 0 adds right-handed twist; Lk = Lk0 + phi / 2 pi). Each side followed "
             "from the knot relaxed to a minimum at phi = 0, with the Lk0 that leaves it untwisted, until its stable branch ends, and that end located on its "
             "extended system: kind 'fold' or 'branch_point'. Where it was not located, the study's bracket is kept "
             "('unstable': an eigenvalue crosses zero; 'snap': the rod jumps to another stable state inside the "
             "bracket, both states in states/*.npz, how far it moved and its energy change in atlas.csv; 'jump': "
             "the same with no stable state found beyond; the reason is in atlas.csv). The "
             "critical eigenvalue at the last stable state, with its rate along the branch, says how clearly it was "
             "going to zero; mode: the m-fold pattern of its critical mode (how it bends the knot). mirror distance: "
             "the relaxed start's distance from its mirror image, over its radius of gyration (0: achiral; called "
             f"achiral up to {ACHIRAL_TOL:g}, where the two sides of an amphichiral knot are mirror images). The "
             "tightening side gains segment pairs in contact along its branch (then: loses radius of gyration); the "
             "other side opens the knot.", "",
             "| knot | D/L | N | side | phi*/pi | +- (rad) | kind | mode | critical eigenvalue (d/dphi) | "
             "lowest at phi = 0 | Lk0 | mirror distance | Wr start | Wr before | Tw before | contacts gained | tightens | "
             "time (s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    tight = tightening_sides(rows)
    for r in rows:
        phi = f"{r['phi_star_over_pi']:+.4f}" if math.isfinite(r["phi_star"]) else "none"
        err = f"{r['phi_error']:.1e}" if math.isfinite(r["phi_error"]) else ""
        lam = f"{r['critical_eigenvalue']:.2e} ({r['dlambda_dphi']:+.1e})" if math.isfinite(r["critical_eigenvalue"]) else ""
        mode = f"{r['mode_pattern']}-fold" if r["mode_pattern"] else ""
        lines.append(f"| {r['knot']} | {r['D_over_L']:g} | {r['N']} | {r['side']} | {phi} | {err} | {r['kind']} | {mode} | "
                     f"{lam} | {r['lowest_eigenvalue_start']:.2e} | {r['Lk0']:+d} | "
                     f"{r['mirror_distance_start']:.1e} ({_chirality(r['mirror_distance_start'])}) | "
                     f"{r['Wr_start']:.4f} | {r['Wr_before']:.4f} | {r['Tw_before']:.4f} | {r['contact_count_change']:+d} | "
                     f"{_yes_no(tight.get((r['knot'], r['D_over_L'], r['N'])), r['side'])} | "
                     f"{r['seconds']:.1f} |")
    groups = {}
    for r in rows:
        groups.setdefault((r["knot"], r["D_over_L"], r["side"]), []).append(r)
    conv = [(k, sorted(g, key=lambda r: r["N"])) for k, g in groups.items() if len({r["N"] for r in g}) > 1]
    if conv:
        lines += ["", "## Convergence in N", ""]
        for (knot, ratio, side), g in conv:
            parts = [f"N = {r['N']}: {r['phi_star_over_pi']:+.4f} pi" for r in g]
            changes = [f"{b['phi_star_over_pi'] - a['phi_star_over_pi']:+.4f} pi" for a, b in zip(g, g[1:])]
            lines.append(f"- {knot}, D/L = {ratio:g}, {side}: " + ", ".join(parts) + " (changes " + ", ".join(changes) + ")")
    lines += _accuracy_section(rows)
    path = os.path.join(out, "atlas.md")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return path


def _accuracy_section(rows):
    """The report's lines for the cases run in the accuracy mode (none without it)."""
    converged = [r for r in rows if r.get("accuracy_levels")]
    if not converged:
        return []
    lines = ["", "## Converged in N (accuracy mode)", "",
             "Each case's end followed at the levels N x " + ", ".join(f"{f:.3g}" for f in ACCURACY_LEVELS) +
             ", each from the previous level's state resampled, and extrapolated (Richardson, order measured); "
             "the error bar is the extrapolation's error estimate.", "",
             "| knot | D/L | side | phi*/pi extrapolated | +- /pi | accuracy reached | levels N: phi*/pi |",
             "|---|---|---|---|---|---|---|"]
    for r in converged:
        value = f"{r['phi_extrapolated'] / math.pi:+.4f}" if math.isfinite(r["phi_extrapolated"]) else "none"
        error = f"{r['extrapolation_error'] / math.pi:.3f}" if math.isfinite(r["extrapolation_error"]) else ""
        lines.append(f"| {r['knot']} | {r['D_over_L']:g} | {r['side']} | {value} | {error} | {r['accuracy_reached']} | "
                     f"{r['accuracy_levels'].replace(';', ', ')} |")
    return lines
