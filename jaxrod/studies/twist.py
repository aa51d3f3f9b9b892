"""Twist study of a closed rod (a knot): continuation in both directions from phi = 0, every step
recorded as it is made, resumable, with the figures of the seed paper.

``twist_study(scene, phi_min, phi_max, out=DIR)`` writes into DIR, while it runs:

* ``run.json``       the scene and continuation parameters (a resumed run must match them);
* ``branch.csv``     one row per accepted step (``jaxrod.io.records.ROW_KEYS``, ``direction``,
  ``lambda_0``...), appended and flushed at every step; ``branch_units.json`` the unit of each
  column (``jaxrod.io.records.ROW_UNITS``);
* ``steps/<direction>_<NNNN>.npz`` the state (q, phi, branch) and its profiles
  (s/L, kappa L, tau L, centreline, eccentric line) at every step;
* ``critical.json``  the instabilities met so far (rewritten whenever one is found) and which
  directions are finished;
* ``state_<direction>.npz`` the continuation's state (``PathState``) after every step tried,
  written after the rows, step files and instabilities it counts;
* ``time.json``      the computing time over this run and the interrupted runs before it.

Files are written atomically and rows appended. Interrupted at any moment (even by ``kill -9``)
and called again with the same arguments, the study goes on from the last saved state and ends
with files identical to those of an uninterrupted run. ``figures(DIR)`` draws the bifurcation
diagram, Lk/Tw/Wr, kappa(s)/tau(s) profiles and 3D snapshots from the files.
"""
from __future__ import annotations

import copy
import csv
import glob
import json
import math
import os
import threading
import time
from dataclasses import dataclass, field, replace

import jax.numpy as jnp
import numpy as np

from ..continuation import (CONTACT_NEGATIVE_TOL, ContinuationOptions, Observer, check_dense_memory,
                            follow_twist, follows_sparse)
from ..continuation.options import checked_options, observed
from ..io.atomic import savez, write_json
from ..io.locking import holds_output_folder
from ..io.records import ROW_KEYS, ROW_UNITS, step_record
from ..linalg.stability import DEFAULT_NEGATIVE_TOL
from ..solve.equilibrium import relax_to_minimum
from ..validation import check_finite, check_positive
from .critical_summary import study_summary, summarise_critical, tightening_side  # noqa: F401 (callers find them here)
from .study_files import (UNSTABLE_PREFIX, add_branch_columns, critical_mode, end_states,  # noqa: F401
                          final_header, read_seconds, read_table, reconcile, rewrite_sorted)
from .threads import Cancelled, run_all
from .twist_figures import branch_figures, event_marks, figures, state_figures  # noqa: F401

__all__ = ["twist_study", "StudyResult", "read_table", "figures", "study_summary", "check_study_folder",
           "study_options", "event_marks", "compile_ahead"]


@dataclass(frozen=True)
class StudyResult:
    """table: dict column -> array (all rows, both directions); critical: the critical.json dict;
    out: the folder (or None); seconds: time of this call; seconds_total: of all calls on this
    folder (an interrupted run and its resumptions)."""

    table: dict
    critical: dict
    out: str | None
    seconds: float
    seconds_total: float = math.nan
    end_states: list = field(default_factory=list, repr=False)  # (q, phi) of the last stable state before
    # each instability (critical["instabilities"] order), or None where it is not known


def _scene_parameters(scene):
    m = scene.material
    return {
        "name": scene.name,
        "N": int(scene.n_nodes),
        "L": float(scene.length),
        "D": None if m.D is None else float(m.D),
        "B": float(m.B),
        "C": float(m.C),
        "EA": float(m.EA),
        "Lk0": float(getattr(scene, "Lk0", 0.0)),
        "contact_stiffness": float(getattr(scene, "contact_stiffness", 0.0) or 0.0),
        "terms": list(scene.term_names),
    }


def _instability_dict(inst, scene, out, direction, index):
    before, after = inst.equilibrium, inst.jumped_to
    d = {
        "direction": direction,
        "phi": inst.phi,
        "phi_over_pi": inst.phi / math.pi,
        "negative_tol": inst.negative_tol,
        "phi_error": inst.phi_error,
        "bracket": list(inst.bracket),
        "kind": inst.kind,
        "multiplicity": inst.multiplicity,
        "eigenvalue": inst.eigenvalue,
        "dlambda_dphi": inst.dlambda_dphi,
        "dlambda_dphi_secant": None if not math.isfinite(inst.dlambda_dphi_secant) else inst.dlambda_dphi_secant,
        "from_branch": inst.from_branch,
        "to_branch": inst.to_branch,
        "Wr_before": before.Wr, "Tw_before": before.Tw, "energy_before": before.energy,
        "Wr_after": None if after is None else after.Wr,
        "Tw_after": None if after is None else after.Tw,
        "energy_after": None if after is None else after.energy,
        "switch": inst.switch,
    }
    if out:
        name = f"critical_mode_{direction}_{index}.npz"
        mode_q = np.asarray(scene.from_scaled(inst.mode))
        savez(os.path.join(out, name), mode_scaled=inst.mode, mode_q=mode_q, q=before.q, phi=before.phi)
        d["mode_file"] = name
    return d


def _study_parameters(scene, phi_min, phi_max, o):
    """What a resumed study must share with the interrupted one (run.json), as JSON would read it;
    o: its ``study_options`` (bracket_tol recorded only where it is not tol)."""
    params = {"scene": _scene_parameters(scene), "phi_min": float(phi_min), "phi_max": float(phi_max),
              "step": float(o.step), "tol": float(o.tol), "k": o.k, "max_switches": o.max_switches}
    if o.bracket_tol is not None and o.bracket_tol != o.tol:
        params["bracket_tol"] = float(o.bracket_tol)
    return json.loads(json.dumps(params))


# A study's own defaults (a coarser step than follow_twist's 0.25 pi); run.json records these four,
# and bracket_tol (default: tol) where it is given.
STUDY_DEFAULTS = {"step": 0.5 * math.pi, "tol": 2e-4 * math.pi, "k": 8, "max_switches": 3}


def study_options(options=None):
    """``options`` (a ``ContinuationOptions``, or None) with STUDY_DEFAULTS filled in where None. A
    study sets the other fields itself, so a value given for one of them is refused (ValueError
    naming it): a resumed run could not check it against run.json."""
    options = checked_options(options)
    for name in ("negative_tol", "gtol", "jump_tol", "corrector_max_steps", "max_refine", "linear_algebra", "branch",
                 "switch", "perturbation", "keep_symmetry"):
        if getattr(options, name) is not None:
            raise ValueError(f"options.{name}: twist_study does not take it (it sets step, tol, bracket_tol, k and max_switches, "
                             "which run.json records)")
    return replace(options, **{key: d for key, d in STUDY_DEFAULTS.items() if getattr(options, key) is None})


def check_study_folder(out, scene, phi_min, phi_max, options=None):
    """Raise ValueError naming ``out`` if it holds a study (run.json) with other parameters than
    these, as ``twist_study`` with resume=True would, before any work."""
    o = study_options(options)
    run_path = os.path.join(out, "run.json")
    if not os.path.exists(run_path):
        return
    try:
        with open(run_path) as f:
            old = json.load(f)
    except (OSError, ValueError):
        old = None
    if old != _study_parameters(scene, phi_min, phi_max, o):
        raise ValueError(f"out: {out} holds a run with other parameters (see its run.json): use another "
                         "folder, or start over there (resume=False; the CLI's --fresh)")



@holds_output_folder
def twist_study(scene, phi_min, phi_max, options=None, *, out=None, resume=True, parallel=True, observer=None):
    """Follow the knot's stable states from phi = 0 up to phi_max and down to phi_min (relaxed at
    phi = 0 first), switching branches at each instability (see ``follow_twist``). With ``out``
    writes the files of the module docstring as it goes and resumes an interrupted run
    (resume=False starts over). options: a ``ContinuationOptions`` with step, tol, k, max_switches
    (defaults: ``study_options``). observer: an ``Observer`` whose progress(str) gets progress
    lines, on_point(PathPoint) is called after every step recorded (from two threads when
    ``parallel``), and on_instability(direction, index, entry, (q, phi)) once each branch end is
    on file, with its critical.json entry (a copy) and the last stable state before it.
    Returns a ``StudyResult``.

    parallel: follow the two directions at once, in two threads (JAX releases the GIL). The
    numbers are the same as in a serial run; branch.csv is rewritten in canonical order (plus,
    then minus) at the end."""
    t0 = time.perf_counter()
    phi_min = check_finite("phi_min", phi_min)
    phi_max = check_finite("phi_max", phi_max)
    if not phi_min < 0.0 < phi_max:
        raise ValueError(f"phi_min must be < 0 < phi_max, got phi_min = {phi_min!r}, phi_max = {phi_max!r}")
    options = study_options(options)
    options = replace(options, step=check_positive("step", options.step), tol=check_positive("tol", options.tol))
    observer = observed(observer, "twist_study", ("progress", "on_point", "on_instability"))
    if not follows_sparse(scene, options.linear_algebra or "auto"):
        check_dense_memory(scene)  # the dense Hessian must fit: refused before anything is compiled
    run = _StudyRun(scene, out, options, observer, t0)
    run.open(phi_min, phi_max, resume)
    todo = []
    for direction, target in (("plus", phi_max), ("minus", phi_min)):
        if direction in run.critical["finished"]:
            run.say(f"{direction}: already finished (resumed run)")
            continue
        todo.append((direction, target, run.stored.get(direction)))
    start = None
    if any(state is None for _, _, state in todo):
        run.say("relaxing the knot at phi = 0")
        ahead = compile_ahead(scene) if parallel and len(todo) == 2 else None
        # A minimum, not a saddle: a symmetric drawing (a torus knot) can relax onto a saddle.
        start = relax_to_minimum(scene, 0.0, None, progress=run.say)
        if ahead is not None:
            ahead.join()
    run_all(lambda direction, target, state: run.follow(direction, target, state, start), todo, parallel,
            run.cancel)
    return run.finish()


def _clear_folder(out):
    """Remove what an earlier study left in ``out`` (a fresh start there)."""
    for stale in [os.path.join(out, n) for n in ("branch.csv", "critical.json", "time.json")] + \
            glob.glob(os.path.join(out, "state_*.npz")) + glob.glob(os.path.join(out, "steps", "*.npz")) + \
            glob.glob(os.path.join(out, "event_*.npz")) + glob.glob(os.path.join(out, "diagram.json")):
        if os.path.exists(stale):
            os.remove(stale)


@dataclass
class _StudyRun:
    """One ``twist_study`` call: its folder's files, the rows and instabilities found so far, and
    what each direction's ``follow_twist`` hands over, written by one thread at a time (``lock``).
    ``cancel`` is set when the main thread is interrupted: each direction's thread stops at its
    next saved state rather than being torn down inside XLA, which aborts the process."""

    scene: object
    out: str | None
    options: ContinuationOptions
    observer: Observer
    t0: float
    critical: dict = field(default_factory=lambda: {"instabilities": [], "finished": []})
    stored: dict = field(default_factory=dict)
    seconds_before: float = 0.0
    rows: list = field(default_factory=list)
    row_states: dict = field(default_factory=dict)
    end_states: dict = field(default_factory=dict)
    lock: object = field(default_factory=threading.Lock)
    cancel: object = field(default_factory=threading.Event)

    def say(self, line):
        self.observer.say(line)

    def path(self, name):
        return os.path.join(self.out, name)

    @property
    def header(self):
        return list(ROW_KEYS) + ["direction"] + [f"lambda_{j}" for j in range(self.options.k)]

    def open(self, phi_min, phi_max, resume):
        """Prepare the folder (resume or start over) and the critical dict."""
        o = self.options
        if self.out:
            params = _study_parameters(self.scene, phi_min, phi_max, o)
            if resume:
                check_study_folder(self.out, self.scene, phi_min, phi_max, o)
            os.makedirs(self.path("steps"), exist_ok=True)
            if os.path.exists(self.path("run.json")) and resume:
                if os.path.exists(self.path("critical.json")):
                    with open(self.path("critical.json")) as f:
                        self.critical = json.load(f)
            else:
                _clear_folder(self.out)
                write_json(self.path("run.json"), params)
            write_json(self.path("branch_units.json"), ROW_UNITS)
        if self.critical.get("negative_tol") is None:
            self.critical["negative_tol"] = CONTACT_NEGATIVE_TOL if self.scene.has_term("contact") \
                else DEFAULT_NEGATIVE_TOL
        if self.out:
            self.stored = reconcile(self.out, self.critical, self.header, self.say)
            self.seconds_before = read_seconds(self.out)

    def stop_if_cancelled(self):
        if self.cancel.is_set():
            raise Cancelled()

    def save_point(self, direction, counter, point):
        """A recorded step: its row (branch.csv, appended) and its step file."""
        e = point.equilibrium
        row, extra = step_record(point.scene, e, branch=point.branch)
        row["direction"] = direction
        with self.lock:
            if not self.out:
                self.rows.append(row)
                self.row_states[id(row)] = (np.asarray(point.scene.to_scaled(e.q)), float(e.phi))
                return
            csv_path = self.path("branch.csv")
            new = not os.path.exists(csv_path) or os.path.getsize(csv_path) == 0
            with open(csv_path, "a", newline="") as f:
                w = csv.DictWriter(f, fieldnames=self.header, extrasaction="ignore")
                if new:
                    w.writeheader()
                # An undefined value (Lk_gauss between whole turns) is an empty cell, not "nan".
                w.writerow({key: "" if isinstance(v, float) and math.isnan(v) else v for key, v in row.items()})
            savez(os.path.join(self.out, "steps", f"{direction}_{counter:04d}.npz"), q=e.q, phi=e.phi,
                   branch=point.branch, **extra)

    def record_instability(self, direction, inst):
        """A branch end, on file at once (critical.json and the mode file), before the new branch's
        first row: a run interrupted after it resumes with the instability already known."""
        with self.lock:
            index = sum(1 for c in self.critical["instabilities"] if c["direction"] == direction)
            self.end_states[(direction, index)] = (np.asarray(inst.equilibrium.q), float(inst.equilibrium.phi))
            entry = _instability_dict(inst, self.scene, self.out, direction, index)
            self.critical["instabilities"].append(entry)
            self.write_critical()
        if self.observer.on_instability is not None:  # outside the lock: it may start work on this end at once
            self.observer.on_instability(direction, index, copy.deepcopy(entry), self.end_states[(direction, index)])

    def save_state(self, direction, path_state):
        """After the rows, step files and instabilities that this state counts: a run killed at any
        moment resumes from the last state on file, and drops what came after it."""
        if self.out:
            with self.lock:
                savez(self.path(f"state_{direction}.npz"), **path_state.to_arrays())
                write_json(self.path("time.json"),
                            {"seconds_total": self.seconds_before + time.perf_counter() - self.t0})
        self.stop_if_cancelled()  # after the state is on file: a resumed run goes on from it

    def write_critical(self, table=None):
        summarise_critical(self.critical, table)
        if self.out:
            write_json(self.path("critical.json"), self.critical)

    def follow(self, direction, target, state, start):
        """One direction: ``follow_twist`` from phi = 0 (or from its saved state) to ``target``."""
        counter = 0 if state is None else int(state.arrays["n_points"])
        if state is not None:
            self.say(f"{direction}: resuming on {state.arrays['branch']} at phi = "
                     f"{float(state.arrays['prev_phi']) / math.pi:+.5f} pi ({state.arrays['phase']}, step {counter})")

        def on_point(point):
            nonlocal counter
            self.stop_if_cancelled()
            self.save_point(direction, counter, point)
            counter += 1
            if self.observer.on_point is not None:
                self.observer.on_point(point)

        o = self.options
        opts = ContinuationOptions(step=o.step, tol=o.tol, bracket_tol=o.bracket_tol, k=o.k,
                                   negative_tol=self.critical["negative_tol"], max_switches=o.max_switches)
        path = follow_twist(self.scene, 0.0, target, opts, start=start if state is None else None, resume=state,
                            observer=Observer(progress=self.say, on_point=on_point,
                                              on_instability=lambda inst: self.record_instability(direction, inst),
                                              on_state=lambda s: self.save_state(direction, s)))
        with self.lock:
            self.critical["finished"].append(direction)
            self.critical["stopped_" + direction] = path.reason
            self.write_critical()

    def finish(self):
        """Canonical order (plus before minus, each in the order of its steps; instabilities likewise),
        whichever direction finished first: a parallel run writes the same files as a serial one."""
        order = {"plus": 0, "minus": 1}
        critical = self.critical
        critical["instabilities"].sort(key=lambda c: order[c["direction"]])
        critical["finished"].sort(key=order.get)
        header = final_header(self.options.k)
        if self.out:
            rewrite_sorted(self.path("branch.csv"), header, order, self.scene)
            table = read_table(self.path("branch.csv"))
        else:
            self.rows.sort(key=lambda r: order[r["direction"]])
            add_branch_columns(self.rows, [self.row_states[id(r)] for r in self.rows])
            table = {key: np.array([r.get(key, math.nan) for r in self.rows]) for key in header}
        summarise_critical(critical, table)
        seconds = time.perf_counter() - self.t0
        if self.out:
            write_json(self.path("critical.json"), critical)
            write_json(self.path("time.json"), {"seconds_total": self.seconds_before + seconds})
        return StudyResult(table=table, critical=critical, out=self.out, seconds=seconds,
                           seconds_total=self.seconds_before + seconds,
                           end_states=end_states(critical, self.end_states, self.out))


def compile_ahead(scene):
    """A thread that runs the continuation's per-step analysis once on the drawn shape while the
    relaxation at phi = 0 runs, so its programs compile on the idle core. The results are
    dropped; a failure only loses the head start."""
    from ..io.records import _record_arrays
    from ..linalg.stability import branch_analysis

    def run():
        try:
            q = np.asarray(scene.q_init, dtype=float)
            nbr = scene.neighbourhood(q, 0.0)
            branch_analysis(scene, q, 0.0, 0, nbr=nbr)
            _record_arrays(scene, jnp.asarray(q), jnp.asarray(0.0), nbr)
        except Exception:  # noqa: BLE001 -- only a head start
            pass

    if follows_sparse(scene):
        return None  # the sparse path compiles other programs
    thread = threading.Thread(target=run, name="jaxrod-compile-ahead", daemon=True)
    thread.start()
    return thread
