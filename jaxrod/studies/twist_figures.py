"""The figures of a twist study, drawn from the files in its folder (``jaxrod.studies.twist``):
the bifurcation diagram, Lk/Tw/Wr, the located branch ends, profiles and 3D snapshots."""
from __future__ import annotations

import glob
import json
import math
import os

import numpy as np

from .study_files import read_table

__all__ = ["event_marks", "figures", "branch_figures", "state_figures"]


def event_marks(critical, table):
    """The branch ends to mark on the figures: each located event (kind, phi, writhe) where the
    diagram has it, else the study's bracketed estimate. critical: critical.json's dict; table:
    branch.csv's columns."""
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
    plotting.plot_bifurcation(table, marks, p, title=title or None, band=critical.get("negative_tol"))
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
