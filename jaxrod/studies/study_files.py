"""The files of a twist study's folder (``jaxrod.studies.twist``), read and kept consistent:
``branch.csv`` and its columns, the rows of unstable branches, an interrupted run's files made to
agree with its saved states (``reconcile``), and what is kept of each branch end."""
from __future__ import annotations

import csv
import glob
import json
import math
import os

import numpy as np

from ..continuation import PathState
from ..io.atomic import write_rows
from ..io.records import ROW_KEYS

__all__ = ["read_table", "read_seconds", "reconcile", "rewrite_sorted", "DIAGRAM_KEYS", "final_header",
           "UNSTABLE_PREFIX", "is_unstable", "add_branch_columns", "critical_mode", "end_states"]


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


def read_seconds(out):
    try:
        with open(os.path.join(out, "time.json")) as f:
            return float(json.load(f)["seconds_total"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0.0


def reconcile(out, critical, header, say):
    """Make the files of an interrupted run agree with its saved continuation states: a direction
    keeps what its state counts and drops what was written after it; one without a state starts
    over. The diagram's rows, events and files are dropped (computed again). Returns {direction:
    PathState} for those with a state."""
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
        diagram_rows = [row for row in rows if is_unstable(row)]
        rows = [row for row in rows if not is_unstable(row)]  # the diagram's: computed again after the study
        for row in rows:
            d = row.get("direction")
            complete = d in seen and row.get(header[-1]) is not None  # a line cut short has fewer fields
            if complete and (keep_rows[d] is None or seen[d] < keep_rows[d]):
                seen[d] += 1
                good.append(row)
        if len(good) != len(rows):
            dropped.append(f"{len(rows) - len(good)} row(s) of branch.csv")
        if len(good) != len(rows) or diagram_rows:
            write_rows(csv_path, header, good)
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
            rows = sum(1 for row in csv.DictReader(f) if row.get("direction") == direction and not is_unstable(row))
    found = sum(1 for c in critical["instabilities"] if c["direction"] == direction)
    return steps and rows >= n_points and found >= n_instabilities


def rewrite_sorted(csv_path, header, order, scene):
    """Rewrite branch.csv with its rows stably sorted by direction, with the diagram's columns
    (``add_branch_columns``, from the step files), atomically."""
    if not os.path.exists(csv_path):
        return
    with open(csv_path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if not is_unstable(r)]
    rows.sort(key=lambda r: order.get(r.get("direction"), 2))
    steps = os.path.join(os.path.dirname(csv_path), "steps")
    states, counter = [], {"plus": 0, "minus": 0}
    for r in rows:
        d = r["direction"]
        with np.load(os.path.join(steps, f"{d}_{counter[d]:04d}.npz")) as f:
            states.append((np.asarray(scene.to_scaled(f["q"])), float(f["phi"])))
        counter[d] += 1
    add_branch_columns(rows, states)
    write_rows(csv_path, header, rows)


# Columns that place a row in the bifurcation diagram, between ``direction`` and the eigenvalues.
DIAGRAM_KEYS = ("branch_id", "arclength", "morse_index")


def final_header(k):
    return list(ROW_KEYS) + ["direction", *DIAGRAM_KEYS] + [f"lambda_{j}" for j in range(k)]


# Rows of branch.csv on an unstable branch (``jaxrod.studies.diagram``) have a branch name starting with this.
UNSTABLE_PREFIX = "unstable "


def is_unstable(row):
    return str(row.get("branch", "")).startswith(UNSTABLE_PREFIX)


def _branch_key(name):
    # 'symmetric+' and 'symmetric-' are the branch through phi = 0 followed both ways: one id
    return name[:-1] if name.startswith("symmetric") and name[-1:] in "+-" else name


def add_branch_columns(rows, states):
    """Give each stable row (canonical order) its ``branch_id`` (by first appearance), ``arclength``
    (sum of sqrt(dphi^2 + |du|^2) along its branch, u the scaled DOFs; negative on the minus side
    of the branch through phi = 0) and ``morse_index`` (n_negative)."""
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


def end_states(critical, memory, out):
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
