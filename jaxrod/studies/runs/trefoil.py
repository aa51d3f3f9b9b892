"""A knot's whole twist study, as ``jaxrod trefoil`` and ``jaxrod knot`` run it: the knot relaxed
at zero twist and followed to both ends of the twist range (``twist_study``), each branch end
located exactly and its unstable branch followed (``jaxrod.studies.diagram``) while the study goes
on, each side's first end found again at N' = (N+1)/2 for an error estimate
(``coarse.coarse_companion``), then summary.json, the figures and, if asked, VTK files.

    from jaxrod.studies.runs import KnotStudyOptions, run_knot_study, study_scene
    options = KnotStudyOptions(D=8.0, L=292.0, N=121, out="results/trefoil")
    run = run_knot_study(study_scene(options), options, progress=print)
    run.summary["phi_plus"], run.summary["phi_minus"]      # rad

Lengths in any unit shared by D and L (mm in the seed paper), E in MPa (N/mm^2), angles in rad.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import time

from ...model.scenes import DEFAULT_CONTACT_STIFFNESS, PAPER_YOUNG_MODULUS
from .workers import Workers


@dataclasses.dataclass(frozen=True)
class KnotStudyOptions:
    """The knot, its rod and the study.

    The knot: ``chirality`` "right" or "left" (the seed paper's trefoil); with chirality None,
    the named ``knot`` or the closed curve of the file ``curve`` (CSV or NPY), with ``lk0`` the
    untwisted rod's linking number (None: nearest the curve's writhe). The rod: D and L (one
    unit), N nodes, E, nu, contact_stiffness (units of B/D^3). The study: twists phi_min < 0 to
    phi_max > 0, step and tol (rad), ``bracket_tol`` (rad; None: LOCATED_BRACKET, or tol where
    stable_only) the width to which an end is bracketed where an eigenvalue passes zero, before its
    exact location, the folder ``out`` (resumed unless ``fresh``); ``serial``:
    one direction after the other; ``stable_only``: no exact location of the ends;
    ``extrapolation``: the N' = (N+1)/2 error estimate; ``figures``, ``vtk``. The accuracy mode
    (``run_accuracy``): ``accuracy`` (rad) to reach, and N_max, the finest level."""

    D: float = 8.0
    L: float = 292.0
    N: int = 121
    E: float = PAPER_YOUNG_MODULUS
    nu: float = 0.5
    contact_stiffness: float = DEFAULT_CONTACT_STIFFNESS
    chirality: str | None = "right"
    knot: str | None = None
    curve: str | None = None
    lk0: int | None = None
    phi_min: float = -12.0 * math.pi
    phi_max: float = 14.0 * math.pi
    step: float = 0.5 * math.pi
    tol: float = 2e-4 * math.pi
    bracket_tol: float | None = None
    out: str = "results/trefoil"
    fresh: bool = False
    serial: bool = False
    stable_only: bool = False
    extrapolation: bool = True
    figures: bool = True
    vtk: bool = False
    accuracy: float | None = None
    N_max: int = 481


@dataclasses.dataclass
class KnotStudyRun:
    """A finished study: its ``StudyResult`` (with the diagram's unstable branches unless
    stable_only) and ``summary``, the record written to summary.json (``critical_json``)."""

    scene: object
    options: KnotStudyOptions
    result: object
    summary: dict


def study_scene(options):
    """The knot of ``options``: the trefoil (chirality given), a named knot, or the closed curve of
    ``options.curve`` (ValueError naming it where the curve is refused)."""
    from ...model.scenes import closed_curve, knot, trefoil

    o = options
    if o.chirality is not None:
        return trefoil(N=o.N, D=o.D, L=o.L, E=o.E, nu=o.nu, chirality=o.chirality,
                       contact_stiffness=o.contact_stiffness)
    if o.knot is not None:
        return knot(o.knot, N=o.N, D=o.D, L=o.L, E=o.E, nu=o.nu, contact_stiffness=o.contact_stiffness, Lk0=o.lk0)
    from ...measure.analysis import load_polyline
    from ...model.material import Material

    points = load_polyline(o.curve)
    try:
        return closed_curve(points, material=Material.from_engineering(o.E, o.nu, o.D), N=o.N, length=o.L,
                            name=f"closed curve from {os.path.basename(o.curve)}",
                            contact_stiffness=o.contact_stiffness, Lk0=o.lk0)
    except ValueError as exc:
        raise ValueError(f"curve {o.curve}: {exc}") from None


def check_knot_memory(n_nodes):
    """Refuse a knot whose dense Hessian cannot fit in memory now, before the scene is built and
    anything compiled. A closed rod has 4 DOFs per node."""
    from types import SimpleNamespace

    from ...continuation import check_dense_memory

    check_dense_memory(SimpleNamespace(n_dof=4 * n_nodes, n_nodes=n_nodes))


# The study's bracket of an end where an eigenvalue passes zero (rad), when the end is then located
# exactly on the extended system: narrowing it to tol would only repeat that work, less exactly.
LOCATED_BRACKET = 0.02 * math.pi


def continuation_options(options):
    """The study's ``ContinuationOptions`` (its step, tol and bracket_tol)."""
    from ...continuation import ContinuationOptions

    bracket = options.bracket_tol
    if bracket is None:
        bracket = options.tol if options.stable_only else max(options.tol, LOCATED_BRACKET)
    return ContinuationOptions(step=options.step, tol=options.tol, bracket_tol=bracket)


def check_resumable(scene, options):
    """Unless ``options.fresh``: ValueError where ``options.out`` holds a study of other
    parameters (checked before anything is compiled)."""
    from ..twist import check_study_folder

    if not options.fresh:
        check_study_folder(options.out, scene, options.phi_min, options.phi_max, continuation_options(options))


def run_knot_study(scene, options, progress=None, on_point=None, on_followed=None):
    """The whole study of ``scene`` (``study_scene(options)``) into ``options.out``; returns a
    ``KnotStudyRun``. progress(str) gets the progress lines; on_point(PathPoint) is called after
    every step of the stable branches (from two threads unless serial); on_followed() once their
    continuation has ended, successfully or not."""
    run = _KnotStudy(scene, options, progress or (lambda line: None), on_point)
    try:
        result = run.follow()
    finally:
        if on_followed is not None:
            on_followed()
    result, summary = run.collect(result)
    return KnotStudyRun(scene, options, result, summary)


class _KnotStudy:
    """One run of ``run_knot_study``. Each branch end's exact location and each side's error
    estimate are queued as soon as the study finds that end, and run by worker threads: one
    started when a study direction finishes (on the core it leaves), the second once the study is
    done. The results are those of the serial order (each job is independent)."""

    def __init__(self, scene, options, say, on_point):
        from ..twist import study_options

        self.scene, self.options, self.say, self._on_point = scene, options, say, on_point
        self.continuation = continuation_options(options)
        self.k = study_options(self.continuation).k  # the eigenvalue columns of branch.csv
        self.span = max(-options.phi_min, options.phi_max)
        self.title = f"{scene.name}, D/L = {options.D / options.L:.4f}, N = {options.N}"
        self.workers = None if options.serial else Workers(start=False)
        self.announced = []  # the estimate's first line is said once

    def _point(self, point):
        if self._on_point is not None:
            self._on_point(point)
        o = self.options
        if self.workers is not None and point.equilibrium.phi == (o.phi_max if point.direction == "plus" else
                                                                   o.phi_min):
            self.workers.add_worker()  # this direction is done: its core takes the queued ends

    def _estimate_job(self, side, entry):
        """The N' = (N+1)/2 error estimate of one side's first end (``coarse_companion``)."""
        from ..coarse import CoarseLevelTooSmall, coarse_companion

        def job(cancel):
            t_side = time.perf_counter()
            if not self.announced:
                self.announced.append(side)
                self.say(f"estimating the discretisation error of phi*: each end again at N = "
                         f"{(self.options.N + 1) // 2}")
            try:
                found = coarse_companion(self.scene, self.options.out, {"instabilities": [entry]}, span=self.span,
                                         step=self.options.step, tol=self.options.tol, progress=self.say,
                                         cancel=cancel, sides=(side,))
            except CoarseLevelTooSmall:  # no estimate at this N (the summary says so)
                return None, time.perf_counter() - t_side
            return found.get(side), time.perf_counter() - t_side
        return job

    def _end_job(self, entry, state):
        """The exact location of one branch end and its unstable branch (``diagram.locate_end``)."""
        def job(cancel):
            from ..diagram import end_capacity, end_rows, locate_end
            from ..threads import Cancelled
            from ..twist import critical_mode

            def stop(point):
                if cancel.is_set():
                    raise Cancelled()
            # this end's own contact-list size (the same for every end of a loose knot)
            o = self.options
            end = locate_end(self.scene, entry, state, p_min=o.phi_min, p_max=o.phi_max,
                             capacity=end_capacity(self.scene, [state]), progress=self.say, observer=stop,
                             mode=critical_mode(o.out, entry))
            if end.event is not None and end.event.converged:  # its rows too, while the study goes on
                end_rows(self.scene, end, self.k, entry["negative_tol"])
            return end
        return job

    def _on_end(self, direction, index, entry, state):
        if not self.options.stable_only:
            self.workers.submit(("end", direction, index), self._end_job(entry, state))
        if self.options.extrapolation and index == 0:
            self.workers.submit(("estimate", direction), self._estimate_job(direction, entry))

    def follow(self):
        """The stable branches (``twist_study``), the ends queued as they are found."""
        from .. import twist
        from ...continuation import Observer

        o = self.options
        try:
            return twist.twist_study(self.scene, o.phi_min, o.phi_max, self.continuation, out=o.out,
                                     resume=not o.fresh, parallel=not o.serial,
                                     observer=Observer(progress=self.say, on_point=self._point,
                                                       on_instability=None if self.workers is None else self._on_end))
        except BaseException:
            if self.workers is not None:
                self.workers.stop()
            raise

    def collect(self, result):
        """(result, summary): the located ends and estimates collected, the diagram, summary.json
        written, the figures drawn."""
        from ..twist import state_figures, study_summary

        o = self.options
        summary, drawn = study_summary(result), None
        if o.figures and not o.serial:
            # the states' figures need only the step files: drawn while the diagram runs
            drawn = Workers()  # one job, in its own thread
            drawn.submit("states", lambda cancel: state_figures(o.out, title=self.title, length_unit="mm"))
        firsts = {}  # each side's first end (critical.json's entry)
        for c in result.critical["instabilities"]:
            firsts.setdefault(c["direction"], c)
        sides_with_end = [side for side in ("plus", "minus") if side in firsts]
        try:
            located, found, seconds_extrapolation = self._jobs_done(firsts, sides_with_end)
            if not o.stable_only and result.end_states:
                result, summary = self._diagram(result, located)
        except BaseException:
            for job in (self.workers, drawn):
                if job is not None:
                    job.stop()
            raise
        summary = self._summary(result, summary, found if sides_with_end else None, seconds_extrapolation)
        self._figures_and_files(drawn)
        return result, summary

    def _jobs_done(self, firsts, sides_with_end):
        """(located ends by (direction, index), estimates by side, the estimates' seconds)."""
        located, found, seconds_extrapolation = {}, {}, 0.0
        estimate = self.options.extrapolation
        if self.workers is not None:
            for side in sides_with_end:  # a resumed run: ends found before the interruption
                if estimate and ("estimate", side) not in self.workers.keys:
                    self.workers.submit(("estimate", side), self._estimate_job(side, firsts[side]))
            while self.workers.n_workers < 2:
                self.workers.add_worker()
            for key, value in self.workers.results().items():
                if key[0] == "end":
                    located[key[1:]] = value
                elif value[0] is not None:
                    found[key[1]] = value[0]
                    seconds_extrapolation += value[1]
        elif estimate and sides_with_end:
            for side in sides_with_end:
                level, seconds = self._estimate_job(side, firsts[side])(None)
                if level is not None:
                    found[side] = level
                seconds_extrapolation += seconds
        return located, found, seconds_extrapolation

    def _diagram(self, result, located):
        """(result, summary) with the unstable branches beyond the located ends."""
        from ..diagram import unstable_branches
        from ..twist import study_summary

        t_diagram = time.perf_counter()
        diagram = unstable_branches(self.scene, result, progress=self.say, parallel=not self.options.serial,
                                    located=located)
        result = diagram.study
        summary = study_summary(result)
        # the ends' own wall time (most of it spent while the study ran) and the rest
        summary["seconds_diagram"] = time.perf_counter() - t_diagram + sum(end.seconds for end in located.values())
        return result, summary

    def _summary(self, result, summary, found, seconds_extrapolation):
        """summary.json's record, written: the study's summary, the rod, the estimates (found None:
        no side has an end, or none was asked for) and the knot."""
        o = self.options
        summary.update({"D": o.D, "L": o.L, "N": o.N, "nu": o.nu, "contact_stiffness": o.contact_stiffness,
                        "out": o.out})
        if o.chirality is not None:
            summary["chirality"] = o.chirality
        else:
            summary.update({"knot": o.knot, "curve": o.curve})
        summary = critical_json(summary, critical=result.critical)
        if o.extrapolation and found is not None:
            summary.update(extrapolated_fields(found, summary, o.N))
            summary["seconds_extrapolation"] = seconds_extrapolation
        with open(os.path.join(o.out, "summary.json"), "w") as f:
            json.dump(summary, f, indent=2)
        return summary

    def _figures_and_files(self, drawn):
        """The figures (unless figures is off) and the VTK files (with vtk), each file said."""
        o = self.options
        if o.figures:
            from ..twist import branch_figures, state_figures

            # pyplot's figure registry is shared: the states' figures are finished before these start
            states = drawn.results()["states"] if drawn is not None else state_figures(o.out, title=self.title,
                                                                                        length_unit="mm")
            for path in branch_figures(o.out, title=self.title) + states:
                self.say(f"wrote {path}")
        if o.vtk:
            from ...io.export import export_study_vtk

            self.say(f"wrote {len(export_study_vtk(o.out))} VTK files into {o.out}/vtk/")


def extrapolated_fields(found, summary, N):
    """summary.json's ``phi_<side>_extrapolated`` records from the coarse levels ``found`` ({side:
    (Level, Extrapolation)}, ``coarse.coarse_companion``) for a study at N nodes. Where ``summary``
    has the side's end located on its extended system (``phi_<side>_located``), the two-level
    Richardson is redone with that value (exact to roundoff) in place of the study's bracket."""
    from ..accuracy import richardson

    fields = {}
    for side, (level, ext) in found.items():
        if summary.get(f"phi_{side}_located") is not None:
            ext = richardson([level.N, N], [level.phi_star, summary[f"phi_{side}"]], [level.phi_error, 0.0])
        fields[f"phi_{side}_extrapolated"] = {"value": ext.value, "value_over_pi": ext.value / math.pi,
                                              "error": ext.error, "error_over_pi": ext.error / math.pi,
                                              "N": list(ext.N), "values": list(ext.values), "order": ext.order,
                                              "order_measured": ext.order_measured}
    return fields


def critical_json(summary, critical=None, convergence=None):
    """The JSON object of a trefoil or knot run, whichever the mode (--json, summary.json): the
    critical twists first, under jaxrod.io.schema's both-sides keys, then the mode's other keys
    from ``summary``.

    The twist study: ``summary`` is its study_summary and ``critical`` its critical.json; each
    side's kind is that of its located end, else of its first instability. The accuracy mode:
    ``convergence`` {side: SideConvergence}, each side's details under "plus" / "minus"."""
    from ...io import schema

    records, details = {}, {}
    if convergence is not None:
        for side, r in convergence.items():
            records[side] = schema.side_record(side, r.phi_star, r.error, r.levels[-1].kind if r.levels else None)
            details[side] = {**r.as_json(), **records[side]}  # "error": the former name of phi_error
    else:
        for side in schema.SIDES:
            located = summary.get(f"phi_{side}_located")
            firsts = [c for c in (critical or {}).get("instabilities", []) if c.get("direction") == side]
            kind = located.get("kind") if isinstance(located, dict) else firsts[0].get("kind") if firsts else None
            records[side] = schema.side_record(side, summary.get(f"phi_{side}"), summary.get(f"phi_{side}_error"),
                                               kind)
    out = schema.both_sides(records)
    out.update(details)
    out.update((key, value) for key, value in summary.items() if key not in out)
    return schema.json_safe(out)
