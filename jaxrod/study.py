"""Twist study of a closed rod (a knot): continuation in both directions from phi = 0, every step
recorded as it is made, resumable, with the figures of the seed paper.

``twist_study(scene, phi_min, phi_max, out=DIR)`` writes into DIR, while it runs:

* ``run.json``       the scene and continuation parameters (a resumed run must match them);
* ``branch.csv``     one row per accepted step (``jaxrod.records.ROW_KEYS``, ``direction``,
  ``lambda_0``...), appended and flushed at every step;
* ``steps/<direction>_<NNNN>.npz`` the state (q, phi, branch) and its profiles
  (s/L, kappa L, tau L, centreline, eccentric line) at every step;
* ``critical.json``  the instabilities met so far (rewritten whenever one is found) and which
  directions are finished.

Interrupted, it is called again with the same arguments: finished directions are skipped, an
unfinished one restarts from its last saved state (nothing computed is lost). ``figures(DIR)``
draws bifurcation diagram, Lk/Tw/Wr, kappa(s)/tau(s) profiles and 3D snapshots from the files.
"""
from __future__ import annotations

import csv
import glob
import json
import math
import os
import threading
import time
from dataclasses import dataclass

import numpy as np

from .continuation import CONTACT_NEGATIVE_TOL, follow_twist
from .stability import DEFAULT_NEGATIVE_TOL
from .equilibrium import relax
from .validation import check_finite, check_positive
from .records import ROW_KEYS, step_record

__all__ = ["twist_study", "StudyResult", "read_table", "figures", "study_summary"]


@dataclass(frozen=True)
class StudyResult:
    """table: dict column -> array (all rows, both directions); critical: the critical.json dict;
    out: the folder (or None); seconds: time of this call."""

    table: dict
    critical: dict
    out: str | None
    seconds: float


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
    }
    if out:
        name = f"critical_mode_{direction}_{index}.npz"
        mode_q = np.asarray(scene.from_scaled(inst.mode))
        _savez(os.path.join(out, name), mode_scaled=inst.mode, mode_q=mode_q, q=before.q, phi=before.phi)
        d["mode_file"] = name
    return d


def _savez(path, **arrays):
    """np.savez to ``path`` atomically: written under a hidden temporary name in the same
    folder (outside the ``<direction>_*.npz`` pattern that resume counts), then renamed."""
    folder, name = os.path.split(path)
    tmp = os.path.join(folder, ".tmp-" + name)
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def _write_json(path, obj):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(obj, f, indent=2, sort_keys=True)  # key order independent of which side ends first
    os.replace(tmp, path)  # never a half-written file


def twist_study(scene, phi_min, phi_max, step=0.5 * math.pi, out=None, tol=2e-4 * math.pi, k=8,
                progress=None, resume=True, max_switches=3, parallel=True):
    """Follow the knot's stable states from phi = 0 up to phi_max and down to phi_min (relaxed at
    phi = 0 first), switching branches at each instability (see ``follow_twist``). Records every
    step (``step_record``); with ``out`` writes the files described in the module docstring as it
    goes and resumes an interrupted run. Returns a ``StudyResult``.

    parallel: follow the two directions at once, in two threads (JAX releases the GIL while it
    computes, so on two cores the study takes about as long as its longer side: README's trefoil
    12.3 -> 9.5 s). The numbers are the same as in a serial run; rows reach branch.csv in the order
    they are found, and the file is rewritten in canonical order (plus, then minus) at the end."""
    t0 = time.perf_counter()
    phi_min = check_finite("phi_min", phi_min)
    phi_max = check_finite("phi_max", phi_max)
    if not phi_min < 0.0 < phi_max:
        raise ValueError(f"phi_min must be < 0 < phi_max, got phi_min = {phi_min!r}, phi_max = {phi_max!r}")
    step = check_positive("step", step)
    tol = check_positive("tol", tol)
    say = progress or (lambda s: None)
    params = {"scene": _scene_parameters(scene), "phi_min": phi_min, "phi_max": phi_max, "step": step,
              "tol": tol, "k": k, "max_switches": max_switches}
    csv_path = crit_path = None
    critical = {"instabilities": [], "finished": []}
    if out:
        os.makedirs(os.path.join(out, "steps"), exist_ok=True)
        run_path, csv_path, crit_path = (os.path.join(out, n) for n in ("run.json", "branch.csv", "critical.json"))
        if os.path.exists(run_path) and resume:
            with open(run_path) as f:
                old = json.load(f)
            if old != json.loads(json.dumps(params)):
                raise ValueError(f"{out} holds a run with other parameters (see run.json): use another --out folder")
            if os.path.exists(crit_path):
                with open(crit_path) as f:
                    critical = json.load(f)
        else:
            for stale in [csv_path, crit_path] + glob.glob(os.path.join(out, "steps", "*.npz")):
                if os.path.exists(stale):
                    os.remove(stale)
            _write_json(run_path, params)
    header = list(ROW_KEYS) + ["direction"] + [f"lambda_{j}" for j in range(k)]

    lock = threading.Lock()  # one writer at a time (files, rows, critical)

    def save_point(direction, counter, point):
        e = point.equilibrium
        row, extra = step_record(point.scene, e, branch=point.branch)
        row["direction"] = direction
        with lock:
            if not out:
                rows.append(row)
                return
            new = not os.path.exists(csv_path) or os.path.getsize(csv_path) == 0
            with open(csv_path, "a", newline="") as f:
                w = csv.DictWriter(f, fieldnames=header, extrasaction="ignore")
                if new:
                    w.writeheader()
                w.writerow(row)
            _savez(os.path.join(out, "steps", f"{direction}_{counter:04d}.npz"), q=e.q, phi=e.phi,
                   branch=point.branch, **extra)

    rows = []
    if critical.get("negative_tol") is None:
        critical["negative_tol"] = CONTACT_NEGATIVE_TOL if "contact" in scene.terms else DEFAULT_NEGATIVE_TOL
    todo = []
    for direction, target in (("plus", phi_max), ("minus", phi_min)):
        if direction in critical["finished"]:
            say(f"{direction}: already finished (resumed run)")
            continue
        files = sorted(glob.glob(os.path.join(out, "steps", f"{direction}_*.npz"))) if out else []
        todo.append((direction, target, files))
    if any(not files for _, _, files in todo):
        say("relaxing the knot at phi = 0")
        start = relax(scene, 0.0, None, gtol=1e-9, with_stability=False)

    def run_direction(direction, target, files):
        counter = len(files)
        if files:  # resume from the last saved state of this direction
            last = np.load(files[-1])
            branch = str(last["branch"])[:-1]
            say(f"{direction}: resuming from phi = {float(last['phi']) / math.pi:+.5f} pi on {branch}")
            begin = relax(scene, float(last["phi"]), last["q"], gtol=1e-9, with_stability=False)
            skip_first = True
        else:
            begin, branch, skip_first = start, "symmetric", False

        def on_point(point):
            nonlocal counter, skip_first
            if skip_first:  # the resumed state itself is already on file
                skip_first = False
                return
            save_point(direction, counter, point)
            counter += 1

        def on_instability(inst):
            # On file at once (critical.json and the mode file), before the new branch's first
            # row: a run interrupted after it resumes with the instability already known.
            with lock:
                index = sum(1 for c in critical["instabilities"] if c["direction"] == direction)
                critical["instabilities"].append(_instability_dict(inst, scene, out, direction, index))
                _summarise(critical)
                if out:
                    _write_json(crit_path, critical)

        path = follow_twist(scene, begin.phi, target, step=step, start=begin, tol=tol, branch=branch, k=k,
                            negative_tol=critical["negative_tol"], max_switches=max_switches,
                            on_point=on_point, progress=say, on_instability=on_instability)
        with lock:
            critical["finished"].append(direction)
            critical["stopped_" + direction] = path.reason
            _summarise(critical)
            if out:
                _write_json(crit_path, critical)

    _run_all(run_direction, todo, parallel)
    # Canonical order (plus before minus, each in the order of its steps; instabilities likewise),
    # whichever direction finished first: a parallel run writes the same files as a serial one.
    order = {"plus": 0, "minus": 1}
    critical["instabilities"].sort(key=lambda c: order[c["direction"]])
    critical["finished"].sort(key=order.get)
    if out:
        _rewrite_sorted(csv_path, header, order)
    else:
        rows.sort(key=lambda r: order[r["direction"]])
    table = read_table(csv_path) if out else {key: np.array([r.get(key, math.nan) for r in rows]) for key in header}
    _summarise(critical, table)
    if out:
        _write_json(crit_path, critical)
    return StudyResult(table=table, critical=critical, out=out, seconds=time.perf_counter() - t0)


def _run_all(run_direction, todo, parallel):
    """run_direction(*task) for each task, in daemon threads when ``parallel`` and there are two
    (so that Ctrl-C still stops the process); the first exception raised in a thread is raised here."""
    if not parallel or len(todo) < 2:
        for task in todo:
            run_direction(*task)
        return
    errors = []

    def target(task):
        try:
            run_direction(*task)
        except BaseException as exc:  # noqa: BLE001 -- handed to the main thread
            errors.append(exc)

    threads = [threading.Thread(target=target, args=(task,), daemon=True) for task in todo]
    for t in threads:
        t.start()
    for t in threads:
        while t.is_alive():
            t.join(0.2)
    if errors:
        raise errors[0]


def _rewrite_sorted(csv_path, header, order):
    """Rewrite branch.csv with its rows stably sorted by direction (atomically)."""
    if not os.path.exists(csv_path):
        return
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    rows.sort(key=lambda r: order.get(r.get("direction"), 2))
    tmp = csv_path + ".tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=header, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, csv_path)


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
        # Tightening packs the strands together: more segment pairs in contact (and a radius of
        # gyration that shrinks, or grows less); opening pulls them apart.
        key = lambda d: (trend[d]["contact_count"], trend[d]["radius_of_gyration"])  # noqa: E731
        tight = max(trend, key=key)
        critical["tightening_side"] = "phi>0" if tight == "plus" else "phi<0"
        critical["symmetric_branch_change"] = trend
        critical["phi_tightening"] = critical["phi_plus" if tight == "plus" else "phi_minus"]
        critical["phi_opening"] = critical["phi_minus" if tight == "plus" else "phi_plus"]


def study_summary(result):
    """A small JSON-able summary of a study: critical twists (rad and /pi), sides, time."""
    c = result.critical
    s = {key: c.get(key) for key in ("phi_plus", "phi_minus", "phi_plus_error", "phi_minus_error",
                                       "tightening_side", "phi_tightening", "phi_opening")}
    for key in ("phi_plus", "phi_minus", "phi_tightening", "phi_opening"):
        s[key + "_over_pi"] = None if c.get(key) is None else c[key] / math.pi
    s["seconds"] = result.seconds
    s["steps"] = int(len(result.table.get("phi", [])))
    return s


def figures(out, title=""):
    """Draw the study's figures from the files in ``out``: bifurcation.png, linking.png,
    profiles.png, snapshots.png. Returns the list of files written."""
    from . import plotting

    table = read_table(os.path.join(out, "branch.csv"))
    with open(os.path.join(out, "critical.json")) as f:
        critical = json.load(f)
    marks = [{"phi": c["phi"], "label": f"phi* = {c['phi'] / math.pi:+.3f} pi ({c['from_branch']})"}
             for c in critical["instabilities"]]
    written = []
    p = os.path.join(out, "bifurcation.png")
    plotting.plot_bifurcation(table, marks, p, title=title or None)
    written.append(p)
    p = os.path.join(out, "linking.png")
    plotting.plot_linking(table, marks, p, title=title or None)
    written.append(p)
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
        plotting.plot_snapshots(snaps, p, ncols=3)
        written.append(p)
    return written
