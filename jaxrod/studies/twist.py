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

Step files, states and JSON files are written atomically (a temporary name, then a rename);
rows are appended (a row cut short by a kill is dropped on resume). Interrupted at any moment
(even by ``kill -9``) and called again with the same arguments, the study drops whatever was
written after the last saved state, goes on from that state, and ends with files identical to
those of an uninterrupted run: finished directions are skipped, nothing computed before the
last state is lost. ``figures(DIR)`` draws bifurcation diagram, Lk/Tw/Wr, kappa(s)/tau(s)
profiles and 3D snapshots from the files.
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

from ..linalg.sparse_contact import use_sparse
from ..continuation import (CONTACT_NEGATIVE_TOL, ContinuationOptions, Observer, PathState, check_dense_memory,
                           follow_twist)
from ..continuation.options import checked_options, observed
from ..linalg.stability import DEFAULT_NEGATIVE_TOL
from ..solve.equilibrium import relax_to_minimum
from ..validation import check_finite, check_positive
from ..io.records import ROW_KEYS, ROW_UNITS, step_record
from ..continuation.end_check import onset_events
from ..io.locking import holds_output_folder
from ..io.atomic import savez as _savez, write_json as _write_json, write_rows as _write_rows

__all__ = ["twist_study", "StudyResult", "read_table", "figures", "study_summary", "check_study_folder",
           "study_options", "event_marks"]


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
        "terms": list(scene.terms),
    }


def read_table(path):
    """branch.csv -> dict column -> numpy array (numbers as float, 'branch'/'direction' as str)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return {}
    table = {}
    for key in rows[0]:
        vals = [r[key] for r in rows]
        if key in ("branch", "direction"):
            table[key] = np.array(vals, dtype=str)
        else:
            table[key] = np.array([float(v) if v not in ("", None) else math.nan for v in vals])
    return table


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
        _savez(os.path.join(out, name), mode_scaled=inst.mode, mode_q=mode_q, q=before.q, phi=before.phi)
        d["mode_file"] = name
    return d


def _study_parameters(scene, phi_min, phi_max, step, tol, k, max_switches):
    """What a resumed study must share with the interrupted one (run.json), as JSON would read it."""
    return json.loads(json.dumps({"scene": _scene_parameters(scene), "phi_min": phi_min, "phi_max": phi_max,
                                  "step": step, "tol": tol, "k": k, "max_switches": max_switches}))


# A study's own defaults (a coarser step than follow_twist's 0.25 pi); run.json records these four.
STUDY_DEFAULTS = {"step": 0.5 * math.pi, "tol": 2e-4 * math.pi, "k": 8, "max_switches": 3}


def study_options(options=None):
    """``options`` (a ``ContinuationOptions``, or None) with the study's defaults filled in where
    None: step 0.5 pi, tol 2e-4 pi, k 8, max_switches 3 (the values run.json records). A study
    sets the other fields itself (negative_tol from critical.json), so a value given for one of
    them is refused (ValueError naming it): a resumed run could not check it against run.json."""
    options = checked_options(options)
    for name in ("negative_tol", "gtol", "jump_tol", "corrector_max_steps", "max_refine", "linear_algebra", "branch",
                 "switch", "perturbation", "keep_symmetry"):
        if getattr(options, name) is not None:
            raise ValueError(f"options.{name}: twist_study does not take it (it sets step, tol, k and max_switches, "
                             "which run.json records)")
    return replace(options, **{key: d for key, d in STUDY_DEFAULTS.items() if getattr(options, key) is None})


def check_study_folder(out, scene, phi_min, phi_max, options=None):
    """Raise ValueError naming ``out`` if it holds a study (run.json) with other parameters than
    these (options: as for ``twist_study``), which a ``twist_study`` with resume=True would
    refuse: checked before any work."""
    o = study_options(options)
    step, tol, k, max_switches = o.step, o.tol, o.k, o.max_switches
    run_path = os.path.join(out, "run.json")
    if not os.path.exists(run_path):
        return
    try:
        with open(run_path) as f:
            old = json.load(f)
    except (OSError, ValueError):
        old = None
    if old != _study_parameters(scene, float(phi_min), float(phi_max), float(step), float(tol), k, max_switches):
        raise ValueError(f"out: {out} holds a run with other parameters (see its run.json): use another "
                         "folder, or start over there (resume=False; the CLI's --fresh)")


@holds_output_folder
def twist_study(scene, phi_min, phi_max, options=None, *, out=None, resume=True, parallel=True, observer=None):
    """Follow the knot's stable states from phi = 0 up to phi_max and down to phi_min (relaxed at
    phi = 0 first), switching branches at each instability (see ``follow_twist``). Records every
    step (``step_record``); with ``out`` writes the files described in the module docstring as it
    goes and resumes an interrupted run (see the module docstring; resume=False starts over).
    options: a ``ContinuationOptions`` with step, tol, k, max_switches (``study_options``: a
    study's defaults are step 0.5 pi, tol 2e-4 pi, k 8, max_switches 3). observer: an
    ``Observer`` whose progress(str) gets progress lines and on_point(direction, BranchPoint) is
    called after every step recorded ('plus' or 'minus'; from two threads when ``parallel``);
    on_instability(direction, index, entry, (q, phi)), once each branch end is on file: its
    critical.json entry (a copy), its index among that direction's ends, and the last stable state
    before it (the CLI starts each end's exact location while the study goes on).
    Returns a ``StudyResult``.

    parallel: follow the two directions at once, in two threads (JAX releases the GIL while it
    computes, so on two cores the study takes about as long as its longer side: README's trefoil
    12.3 -> 9.5 s). The numbers are the same as in a serial run; rows reach branch.csv in the order
    they are found, and the file is rewritten in canonical order (plus, then minus) at the end."""
    t0 = time.perf_counter()
    phi_min = check_finite("phi_min", phi_min)
    phi_max = check_finite("phi_max", phi_max)
    if not phi_min < 0.0 < phi_max:
        raise ValueError(f"phi_min must be < 0 < phi_max, got phi_min = {phi_min!r}, phi_max = {phi_max!r}")
    options = study_options(options)
    step = check_positive("step", options.step)
    tol = check_positive("tol", options.tol)
    k, max_switches = options.k, options.max_switches
    observer = observed(observer, "twist_study", ("progress", "on_point", "on_instability"))
    on_point, on_end = observer.on_point, observer.on_instability
    if not ("contact" in scene.terms and use_sparse(scene, options.linear_algebra or "auto")):
        check_dense_memory(scene)  # the dense Hessian must fit: refused before anything is compiled
    say = observer.say
    params = _study_parameters(scene, phi_min, phi_max, step, tol, k, max_switches)
    csv_path = crit_path = None
    critical = {"instabilities": [], "finished": []}
    if out:
        if resume:
            check_study_folder(out, scene, phi_min, phi_max, options)
        os.makedirs(os.path.join(out, "steps"), exist_ok=True)
        run_path, csv_path, crit_path = (os.path.join(out, n) for n in ("run.json", "branch.csv", "critical.json"))
        if os.path.exists(run_path) and resume:
            if os.path.exists(crit_path):
                with open(crit_path) as f:
                    critical = json.load(f)
        else:
            for stale in [csv_path, crit_path, os.path.join(out, "time.json")] + \
                    glob.glob(os.path.join(out, "state_*.npz")) + glob.glob(os.path.join(out, "steps", "*.npz")) + \
                    glob.glob(os.path.join(out, "event_*.npz")) + glob.glob(os.path.join(out, "diagram.json")):
                if os.path.exists(stale):
                    os.remove(stale)
            _write_json(run_path, params)
    header = list(ROW_KEYS) + ["direction"] + [f"lambda_{j}" for j in range(k)]
    if out:
        _write_json(os.path.join(out, "branch_units.json"), ROW_UNITS)

    lock = threading.Lock()  # one writer at a time (files, rows, critical)
    # Set when the main thread is interrupted (Ctrl-C, SIGTERM): each direction's thread stops at
    # its next saved state instead of being torn down inside XLA when the process exits (which
    # aborted the process: "terminate called ...", status 134).
    cancel = threading.Event()

    def stop_if_cancelled():
        if cancel.is_set():
            raise _Cancelled()

    def save_point(direction, counter, point):
        e = point.equilibrium
        row, extra = step_record(point.scene, e, branch=point.branch)
        row["direction"] = direction
        with lock:
            if not out:
                rows.append(row)
                row_states[id(row)] = (np.asarray(point.scene.to_scaled(e.q)), float(e.phi))
                return
            new = not os.path.exists(csv_path) or os.path.getsize(csv_path) == 0
            with open(csv_path, "a", newline="") as f:
                w = csv.DictWriter(f, fieldnames=header, extrasaction="ignore")
                if new:
                    w.writeheader()
                # An undefined value (Lk_gauss between whole turns) is an empty cell, not "nan".
                w.writerow({key: "" if isinstance(v, float) and math.isnan(v) else v for key, v in row.items()})
            _savez(os.path.join(out, "steps", f"{direction}_{counter:04d}.npz"), q=e.q, phi=e.phi,
                   branch=point.branch, **extra)

    rows, end_states, row_states = [], {}, {}
    if critical.get("negative_tol") is None:
        critical["negative_tol"] = CONTACT_NEGATIVE_TOL if "contact" in scene.terms else DEFAULT_NEGATIVE_TOL
    stored = _reconcile(out, critical, header, say) if out else {}
    seconds_before = _read_seconds(out) if out else 0.0
    todo = []
    for direction, target in (("plus", phi_max), ("minus", phi_min)):
        if direction in critical["finished"]:
            say(f"{direction}: already finished (resumed run)")
            continue
        todo.append((direction, target, stored.get(direction)))
    if any(state is None for _, _, state in todo):
        say("relaxing the knot at phi = 0")
        ahead = _compile_ahead(scene) if parallel and len(todo) == 2 else None
        # A minimum, not a saddle: a symmetric drawing (a torus knot) can relax onto a saddle.
        start = relax_to_minimum(scene, 0.0, None, progress=say)
        if ahead is not None:
            ahead.join()

    def run_direction(direction, target, state):
        counter = 0 if state is None else int(state.arrays["n_points"])
        if state is not None:
            say(f"{direction}: resuming on {state.arrays['branch']} at phi = "
                f"{float(state.arrays['prev_phi']) / math.pi:+.5f} pi ({state.arrays['phase']}, step {counter})")

        def on_point_saved(point):
            nonlocal counter
            stop_if_cancelled()
            save_point(direction, counter, point)
            counter += 1
            if on_point is not None:
                on_point(direction, point)

        def on_instability(inst):
            # On file at once (critical.json and the mode file), before the new branch's first
            # row: a run interrupted after it resumes with the instability already known.
            with lock:
                index = sum(1 for c in critical["instabilities"] if c["direction"] == direction)
                end_states[(direction, index)] = (np.asarray(inst.equilibrium.q), float(inst.equilibrium.phi))
                entry = _instability_dict(inst, scene, out, direction, index)
                critical["instabilities"].append(entry)
                _summarise(critical)
                if out:
                    _write_json(crit_path, critical)
            if on_end is not None:  # outside the lock: it may start work on this end at once
                on_end(direction, index, copy.deepcopy(entry), end_states[(direction, index)])

        def on_state(path_state):
            # After the rows, step files and instabilities that this state counts: a run killed
            # at any moment resumes from the last state on file, and drops what came after it.
            if out:
                with lock:
                    _savez(os.path.join(out, f"state_{direction}.npz"), **path_state.to_arrays())
                    _write_json(os.path.join(out, "time.json"),
                                {"seconds_total": seconds_before + time.perf_counter() - t0})
            stop_if_cancelled()  # after the state is on file: a resumed run goes on from it

        opts = ContinuationOptions(step=step, tol=tol, k=k, negative_tol=critical["negative_tol"],
                                   max_switches=max_switches)
        path = follow_twist(scene, 0.0, target, opts, start=start if state is None else None, resume=state,
                            observer=Observer(progress=say, on_point=on_point_saved, on_instability=on_instability,
                                              on_state=on_state))
        with lock:
            critical["finished"].append(direction)
            critical["stopped_" + direction] = path.reason
            _summarise(critical)
            if out:
                _write_json(crit_path, critical)

    _run_all(run_direction, todo, parallel, cancel)
    # Canonical order (plus before minus, each in the order of its steps; instabilities likewise),
    # whichever direction finished first: a parallel run writes the same files as a serial one.
    order = {"plus": 0, "minus": 1}
    critical["instabilities"].sort(key=lambda c: order[c["direction"]])
    critical["finished"].sort(key=order.get)
    final_header = _final_header(k)
    if out:
        _rewrite_sorted(csv_path, final_header, order, scene)
    else:
        rows.sort(key=lambda r: order[r["direction"]])
        _add_branch_columns(rows, [row_states[id(r)] for r in rows])
    table = read_table(csv_path) if out else {key: np.array([r.get(key, math.nan) for r in rows]) for key in final_header}
    _summarise(critical, table)
    seconds = time.perf_counter() - t0
    if out:
        _write_json(crit_path, critical)
        _write_json(os.path.join(out, "time.json"), {"seconds_total": seconds_before + seconds})
    return StudyResult(table=table, critical=critical, out=out, seconds=seconds,
                       seconds_total=seconds_before + seconds,
                       end_states=_end_states(critical, end_states, out))


def _compile_ahead(scene):
    """A thread that runs the continuation's per-step analysis once on the drawn shape, while the
    relaxation at phi = 0 runs: its programs (projected Hessian, branch tangent, step records) are
    then compiled, or loaded from the compile cache, on the core the relaxation leaves idle (one
    XLA compilation uses one core), not one after the other at the first steps. The results are
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

    if "contact" in scene.terms and use_sparse(scene, "auto"):
        return None  # the sparse path compiles other programs
    thread = threading.Thread(target=run, name="jaxrod-compile-ahead", daemon=True)
    thread.start()
    return thread


def _read_seconds(out):
    try:
        with open(os.path.join(out, "time.json")) as f:
            return float(json.load(f)["seconds_total"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0.0


def _reconcile(out, critical, header, say):
    """Make the files of an interrupted run agree with its saved continuation states: a direction
    keeps the rows, step files and instabilities its state counts (written before it), and
    drops what was written after it (a kill between a row and its state). A direction without a
    state starts over. The bifurcation diagram's rows, events and files (``jaxrod.studies.diagram``) are
    dropped: they are computed again from the finished study. Returns {direction:
    PathState.from_arrays(...)} for those with a state."""
    critical.pop("events", None)
    for stale in glob.glob(os.path.join(out, "event_*.npz")) + glob.glob(os.path.join(out, "diagram.json")):
        os.remove(stale)
    stored, keep_rows, keep_inst = {}, {}, {}
    for direction in ("plus", "minus"):
        path = os.path.join(out, f"state_{direction}.npz")
        if os.path.exists(path):
            with np.load(path) as f:
                stored[direction] = PathState.from_arrays({key: f[key] for key in f.files})
            arrays = stored[direction].arrays
            keep_rows[direction] = int(arrays["n_points"])
            keep_inst[direction] = int(arrays["n_instabilities"])
            if not _files_cover(out, critical, direction, keep_rows[direction], keep_inst[direction]):
                # The state counts rows, step files or instabilities that are not on file (removed
                # by hand): it cannot be continued from; this direction starts over.
                say(f"{direction}: files missing that its saved state counts: starting this direction over")
                del stored[direction]
                keep_rows[direction] = keep_inst[direction] = 0
                if direction in critical["finished"]:
                    critical["finished"].remove(direction)
        else:
            keep_rows[direction] = keep_inst[direction] = 0
            if direction in critical["finished"]:  # finished before states were kept: leave it
                keep_rows[direction] = keep_inst[direction] = None
    dropped = []
    for direction in ("plus", "minus"):
        if keep_rows[direction] is None:
            continue
        for fn in sorted(glob.glob(os.path.join(out, "steps", f"{direction}_*.npz"))):
            if int(os.path.basename(fn)[len(direction) + 1:-4]) >= keep_rows[direction]:
                os.remove(fn)
                dropped.append(os.path.basename(fn))
    kept, seen = [], {"plus": 0, "minus": 0}
    for c in critical["instabilities"]:
        d = c["direction"]
        if keep_inst[d] is not None and seen[d] >= keep_inst[d]:
            dropped.append(f"instability at phi = {c['phi'] / math.pi:+.5f} pi ({d})")
            continue
        seen[d] += 1
        kept.append(c)
    critical["instabilities"] = kept
    csv_path = os.path.join(out, "branch.csv")
    if os.path.exists(csv_path):
        with open(csv_path, newline="") as f:
            rows = list(csv.DictReader(f))
        good, seen = [], {"plus": 0, "minus": 0}
        diagram_rows = [row for row in rows if _is_unstable(row)]
        rows = [row for row in rows if not _is_unstable(row)]  # the diagram's: computed again after the study
        for row in rows:
            d = row.get("direction")
            complete = d in seen and row.get(header[-1]) is not None  # a line cut short has fewer fields
            if complete and (keep_rows[d] is None or seen[d] < keep_rows[d]):
                seen[d] += 1
                good.append(row)
        if len(good) != len(rows):
            dropped.append(f"{len(rows) - len(good)} row(s) of branch.csv")
        if len(good) != len(rows) or diagram_rows:
            _write_rows(csv_path, header, good)
    if dropped:
        say("resuming: dropped what was written after the last saved state: " + ", ".join(dropped))
    return stored


def _files_cover(out, critical, direction, n_points, n_instabilities):
    """Whether ``out`` holds the first n_points step files and rows of ``direction`` and its
    first n_instabilities instabilities."""
    steps = all(os.path.exists(os.path.join(out, "steps", f"{direction}_{i:04d}.npz")) for i in range(n_points))
    rows = 0
    csv_path = os.path.join(out, "branch.csv")
    if os.path.exists(csv_path):
        with open(csv_path, newline="") as f:
            rows = sum(1 for row in csv.DictReader(f) if row.get("direction") == direction and not _is_unstable(row))
    found = sum(1 for c in critical["instabilities"] if c["direction"] == direction)
    return steps and rows >= n_points and found >= n_instabilities


class _Cancelled(Exception):
    """Raised inside a direction's thread at a saved state once the main thread was interrupted."""


def _run_all(run_direction, todo, parallel, cancel):
    """run_direction(*task) for each task, in threads when ``parallel`` and there are two; the
    first exception raised in a thread is raised here. The main thread only waits (in short waits,
    so that Ctrl-C and SIGTERM reach it); when it is interrupted it sets ``cancel``, waits until
    every thread has stopped at its next saved state, and then re-raises the interrupt: no thread
    is left inside XLA while the interpreter shuts down."""
    if not parallel or len(todo) < 2:
        for task in todo:
            run_direction(*task)
        return
    errors = []
    # Each thread says when it has ended through an Event: the main thread waits on those, never
    # in Thread.join, because a join interrupted by Ctrl-C marks the running thread as stopped
    # (CPython 3.11's bpo-45274 handling), after which nothing waits for it any more.
    done = [threading.Event() for _ in todo]

    def target(task, finished):
        try:
            run_direction(*task)
        except _Cancelled:
            pass
        except BaseException as exc:  # noqa: BLE001 -- handed to the main thread
            errors.append(exc)
        finally:
            finished.set()

    threads = [threading.Thread(target=target, args=(task, finished), daemon=True)
               for task, finished in zip(todo, done)]
    for t in threads:
        t.start()
    try:
        for finished in done:
            while not finished.wait(0.2):
                pass
    except BaseException:
        cancel.set()
        for finished in done:
            while not finished.wait(0.2):
                pass
        raise
    if errors:
        raise errors[0]


def _rewrite_sorted(csv_path, header, order, scene):
    """Rewrite branch.csv with its rows stably sorted by direction, with the diagram's columns
    (``_add_branch_columns``, from the step files), atomically."""
    if not os.path.exists(csv_path):
        return
    with open(csv_path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if not _is_unstable(r)]
    rows.sort(key=lambda r: order.get(r.get("direction"), 2))
    steps = os.path.join(os.path.dirname(csv_path), "steps")
    states, counter = [], {"plus": 0, "minus": 0}
    for r in rows:
        d = r["direction"]
        with np.load(os.path.join(steps, f"{d}_{counter[d]:04d}.npz")) as f:
            states.append((np.asarray(scene.to_scaled(f["q"])), float(f["phi"])))
        counter[d] += 1
    _add_branch_columns(rows, states)
    _write_rows(csv_path, header, rows)


# Columns that place a row in the bifurcation diagram, between ``direction`` and the eigenvalues.
DIAGRAM_KEYS = ("branch_id", "arclength", "morse_index")


def _final_header(k):
    return list(ROW_KEYS) + ["direction", *DIAGRAM_KEYS] + [f"lambda_{j}" for j in range(k)]


# Rows of branch.csv on an unstable branch (``jaxrod.studies.diagram``) have a branch name starting with this.
UNSTABLE_PREFIX = "unstable "


def _is_unstable(row):
    return str(row.get("branch", "")).startswith(UNSTABLE_PREFIX)


def _branch_key(name):
    # the branch the study starts on (phi = 0) is one branch, followed both ways ('symmetric+'
    # and 'symmetric-'): one id, its arclength signed (negative on the minus side)
    return name[:-1] if name.startswith("symmetric") and name[-1:] in "+-" else name


def _add_branch_columns(rows, states):
    """Give each stable row (canonical order) its ``branch_id`` (by first appearance, the branch
    through phi = 0 being 0), ``arclength`` (along its branch from its first state: the sum of
    sqrt(dphi^2 + |du|^2) between consecutive states, u the scaled DOFs (node coordinates in mean
    edge lengths, twist angles in rad); negative on the minus side of the branch through phi = 0)
    and ``morse_index`` (the study's count of negative eigenvalues, n_negative)."""
    ids, last = {}, {}
    for row, (u, phi) in zip(rows, states):
        key = _branch_key(str(row["branch"]))
        ids.setdefault(key, len(ids))
        sign = -1.0 if key != row["branch"] and row["branch"].endswith("-") else 1.0
        prev = last.get((key, sign))
        s = 0.0 if prev is None else prev[2] + sign * math.sqrt((phi - prev[1]) ** 2 + float(np.sum((u - prev[0]) ** 2)))
        last[(key, sign)] = (u, phi, s)
        row["branch_id"] = ids[key]
        row["arclength"] = s
        row["morse_index"] = row.get("n_negative")


def critical_mode(out, inst):
    """(n,) the critical eigenvector (scaled DOFs) at the last stable state before the instability
    ``inst`` (a critical.json entry), from its mode file in the folder ``out``; None without one."""
    if not out or not inst.get("mode_file"):
        return None
    try:
        with np.load(os.path.join(out, inst["mode_file"])) as f:
            return np.asarray(f["mode_scaled"])
    except (OSError, KeyError):
        return None


def _end_states(critical, memory, out):
    """(q, phi) of the last stable state before each instability (critical order): from this run,
    or from the instability's mode file; None where neither has it."""
    states, seen = [], {"plus": 0, "minus": 0}
    for c in critical["instabilities"]:
        d = c["direction"]
        state = memory.get((d, seen[d]))
        seen[d] += 1
        if state is None and out and c.get("mode_file"):
            try:
                with np.load(os.path.join(out, c["mode_file"])) as f:
                    state = (np.asarray(f["q"]), float(f["phi"]))
            except OSError:
                state = None
        states.append(state)
    return states


def _summarise(critical, table=None):
    """phi_plus / phi_minus: first instability met at phi > 0 / phi < 0 (jaxrod's sign of phi,
    radians). The tightening side is told by behaviour along the symmetric branch: the number of
    segment pairs in contact grows on the tightening side and falls on the opening side."""
    for direction, key in (("plus", "phi_plus"), ("minus", "phi_minus")):
        first = [c for c in critical["instabilities"] if c["direction"] == direction]
        critical[key] = first[0]["phi"] if first else None
        critical[key + "_error"] = first[0]["phi_error"] if first else None
        critical[key + "_dlambda_dphi"] = first[0]["dlambda_dphi"] if first else None
        critical[key + "_mode_file"] = first[0].get("mode_file") if first else None
        # Located exactly on the extended system (``jaxrod.studies.diagram``): that value replaces the bracket's
        # estimate, which is kept as ``<key>_bracketed``.
        index = critical["instabilities"].index(first[0]) if first else None
        # only where it lies in the study's bracket: elsewhere the two methods disagree (jaxrod.studies.diagram warns)
        ours = [ev for ev in critical.get("events", []) if ev.get("instability") == index]
        # the located end is the onset only where it lies in the bracket and is the study's critical mode
        # (``jaxrod.continuation.end_check``; files written before that check count as verified)
        located = [ev for ev in ours if ev.get("located") and ev.get("within_bracket") is not False
                   and ev.get("confirmed", True)]
        if first:
            critical[key + "_events"] = onset_events(first[0], ours[0] if ours else None)
        if located:
            ev = located[0]
            critical[key + "_bracketed"] = critical[key]
            critical[key + "_bracketed_error"] = critical[key + "_error"]
            critical[key] = ev["phi"]
            critical[key + "_error"] = None
            critical[key + "_located"] = {name: ev.get(name) for name in ("kind", "critical_eigenvalue", "residual",
                                                                       "iterations", "state_file")}
    if table is None or "radius_of_gyration" not in table:
        return
    rg, phi, br, cc = table["radius_of_gyration"], table["phi"], table["branch"], table["contact_count"]
    sym = np.char.startswith(br.astype(str), "symmetric")
    at0 = sym & (phi == 0.0)
    trend = {}
    for direction, sgn in (("plus", 1.0), ("minus", -1.0)):
        sel = sym & (np.sign(phi) == sgn)
        if np.any(sel) and np.any(at0):
            i, i0 = np.argmax(np.abs(phi) * sel), np.argmax(at0)
            trend[direction] = {"contact_count": float(cc[i] - cc[i0]), "radius_of_gyration": float(rg[i] - rg[i0]),
                                "phi_last_symmetric": float(phi[i])}
    if len(trend) == 2:
        tight = tightening_side({d: (t["contact_count"], t["radius_of_gyration"]) for d, t in trend.items()},
                                scale=float(rg[np.argmax(at0)]))
        critical["symmetric_branch_change"] = trend
        if tight == "equal":
            # Mirror-image sides (an achiral knot relaxed to a mirror-symmetric shape): neither
            # side tightens more, and a label decided by round-off would mean nothing.
            critical["tightening_side"] = "equal"
            critical["phi_tightening"] = critical["phi_opening"] = None
            return
        critical["tightening_side"] = "phi>0" if tight == "plus" else "phi<0"
        critical["phi_tightening"] = critical["phi_plus" if tight == "plus" else "phi_minus"]
        critical["phi_opening"] = critical["phi_minus" if tight == "plus" else "phi_plus"]


# Two sides whose radius-of-gyration changes differ by less than this fraction of the radius of
# gyration (with equal contact counts) are the same within the solver's accuracy (gtol 1e-9 in
# scaled units moves it by ~1e-8 relative): seen 2e-8 mm on the mirror-symmetric figure-eight.
SIDES_EQUAL_RTOL = 1e-6


def tightening_side(changes, scale, rtol=SIDES_EQUAL_RTOL):
    """Which side tightens: ``changes`` {'plus': (contact pairs gained, radius of gyration
    change), 'minus': (...)} along each side's symmetric branch; ``scale`` a length to judge the
    radius-of-gyration difference by (the radius of gyration itself). Tightening packs the strands
    together: more segment pairs in contact, then a radius of gyration that shrinks (or grows
    less); opening pulls them apart. Returns 'plus', 'minus', or 'equal' when the contact counts
    agree and the radii differ by at most rtol * scale (mirror images: no side is the tighter)."""
    (cc_plus, rg_plus), (cc_minus, rg_minus) = changes["plus"], changes["minus"]
    if cc_plus == cc_minus and abs(rg_plus - rg_minus) <= rtol * abs(scale):
        return "equal"
    return "plus" if (cc_plus, -rg_plus) > (cc_minus, -rg_minus) else "minus"


def study_summary(result):
    """A small JSON-able summary of a study: critical twists (rad and /pi), sides, time."""
    c = result.critical
    s = {key: c.get(key) for key in ("phi_plus", "phi_minus", "phi_plus_error", "phi_minus_error",
                                       "tightening_side", "phi_tightening", "phi_opening", "phi_plus_located",
                                       "phi_minus_located", "phi_plus_bracketed", "phi_minus_bracketed")}
    for key in ("phi_plus", "phi_minus", "phi_tightening", "phi_opening"):
        s[key + "_over_pi"] = None if c.get(key) is None else c[key] / math.pi
    s["seconds"] = result.seconds
    s["seconds_total"] = result.seconds_total  # this run and the interrupted ones before it
    s["steps"] = int(len(result.table.get("phi", [])))
    return s


def event_marks(critical, table):
    """The branch ends to mark on the figures (``plotting.plot_bifurcation``'s ``critical``): each
    located event (kind, phi, and the writhe of the unstable branch's first row, the located state)
    where the diagram (``jaxrod.studies.diagram``) has it, else the study's bracketed estimate.
    critical: critical.json's dict; table: branch.csv's columns."""
    located = {ev["instability"]: ev for ev in critical.get("events", []) if ev.get("located")}
    marks = []
    for i, c in enumerate(critical["instabilities"]):
        ev = located.get(i)
        if ev is None:
            marks.append({"phi": c["phi"], "label": f"end of {c['from_branch']}"})
            continue
        sel = (np.asarray(table["branch"]) == ev["unstable_branch"]) & (np.asarray(table["arclength"]) == 0.0)
        wr = float(np.asarray(table["Wr"])[sel][0]) if sel.any() else math.nan
        marks.append({"phi": ev["phi"], "label": f"{ev['kind'].replace('_', ' ')}, end of {c['from_branch']}",
                      "kind": ev["kind"], "Wr": wr})
    return marks


def figures(out, title="", length_unit=None):
    """Draw the study's figures from the files in ``out``: bifurcation.png, linking.png,
    branch_ends.png (with the diagram's located events, ``jaxrod.studies.diagram``),
    profiles.png, snapshots.png (the knot as a tube of the rod's diameter, seen along its
    symmetry axis; axes in ``length_unit``, e.g. 'mm'). Returns the list of files written."""
    return branch_figures(out, title) + state_figures(out, title, length_unit)


def branch_figures(out, title=""):
    """bifurcation.png, linking.png and branch_ends.png of the study in ``out`` (``figures``):
    drawn from branch.csv and critical.json, so after the diagram. Returns the files written."""
    from ..io import plotting

    table = read_table(os.path.join(out, "branch.csv"))
    with open(os.path.join(out, "critical.json")) as f:
        critical = json.load(f)
    marks = event_marks(critical, table)
    written = []
    p = os.path.join(out, "bifurcation.png")
    plotting.plot_bifurcation(table, marks, p, title=title or None)
    written.append(p)
    p = os.path.join(out, "linking.png")
    plotting.plot_linking(table, [{"phi": m["phi"], "label": m["label"]} for m in marks], p, title=title or None)
    written.append(p)
    located = [ev for ev in critical.get("events", []) if ev.get("located")]
    if located and "arclength" in table:
        p = os.path.join(out, "branch_ends.png")
        plotting.plot_branch_ends(table, located, p, title=title or None)
        written.append(p)
    return written


def state_figures(out, title="", length_unit=None):
    """profiles.png and snapshots.png of the study in ``out`` (``figures``): drawn from the step
    files alone, so they may be drawn while the diagram runs. Returns the files written."""
    from ..io import plotting

    diameter = None
    try:
        with open(os.path.join(out, "run.json")) as f:
            diameter = json.load(f)["scene"]["D"]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    written = []
    # States shown: phi = 0, the last state before each instability and the first one after it.
    steps = {}
    for direction in ("plus", "minus"):
        steps[direction] = sorted(glob.glob(os.path.join(out, "steps", f"{direction}_*.npz")))
    chosen = []
    if steps["plus"]:
        chosen.append(steps["plus"][0])
    for direction in ("plus", "minus"):
        files = steps[direction]
        branches = [str(np.load(fn)["branch"]) for fn in files]
        for i in range(1, len(files)):
            if branches[i] != branches[i - 1]:
                chosen += [files[i - 1], files[i]]
        if files and files[-1] not in chosen:
            chosen.append(files[-1])
    profiles, labels, snaps = [], [], []
    for fn in chosen:
        d = np.load(fn)
        label = f"{str(d['branch'])}, phi = {float(d['phi']) / math.pi:+.2f} pi"
        profiles.append((d["kappa_L"], d["tau_L"]))
        labels.append(label)
        snaps.append((d["x"], d["eccentric"], label))
    if profiles:
        s_over_L = np.load(chosen[0])["s_over_L"]
        p = os.path.join(out, "profiles.png")
        plotting.plot_profiles(s_over_L, profiles, labels, p, title=title or None)
        written.append(p)
        p = os.path.join(out, "snapshots.png")
        plotting.plot_snapshots(snaps, p, ncols=3, diameter=diameter, unit=length_unit)
        written.append(p)
    return written
