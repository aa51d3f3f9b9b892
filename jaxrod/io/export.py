"""Export of rod states for ParaView and other VTK readers.

``write_vtk(path, x, eccentric, ...)`` writes a legacy-format VTK PolyData file (ASCII): the
centreline and the stripe (the line drawn on the rod surface) as two polylines, with optional
per-node scalars (e.g. curvature and twist density). A small writer rather than meshio or
pyvista: the legacy format is a few lines of text that every VTK reader opens, and polylines
with point data are all a rod needs; meshio would add a dependency for one file type, pyvista a
VTK build of hundreds of MB.
"""
from __future__ import annotations

import glob
import math
import os

import numpy as np

from ..validation import check_points

__all__ = ["write_vtk", "export_study_vtk"]


def write_vtk(path, x, eccentric=None, closed=True, point_data=None, title="jaxrod rod state"):
    """Write a VTK legacy PolyData file: polyline 0 the centreline x (N, 3), polyline 1 the
    stripe ``eccentric`` (M, 3) if given; closed polylines repeat their first point's index.

    point_data: {name: (N,) array} scalars on the centreline nodes (the stripe's points get
    NaN), e.g. {'kappa_L': ..., 'tau_L': ...}. A scalar ``line`` (0 centreline, 1 stripe) is
    always written, to colour the two apart. Returns ``path``.
    """
    x = check_points("x", x, finite=True)
    lines = [x]
    if eccentric is not None:
        lines.append(check_points("eccentric", eccentric, finite=True))
    n_total = sum(len(p) for p in lines)
    data = {"line": np.concatenate([np.full(len(p), float(i)) for i, p in enumerate(lines)])}
    for name, values in (point_data or {}).items():
        values = np.asarray(values, dtype=float)
        if values.shape != (len(x),):
            raise ValueError(f"point_data[{name!r}] must have shape ({len(x)},), got {values.shape}")
        if not name.replace("_", "").isalnum():
            raise ValueError(f"point_data name {name!r}: letters, digits and '_' only")
        data[name] = np.concatenate([values, np.full(n_total - len(x), np.nan)])
    out = ["# vtk DataFile Version 3.0", title.replace("\n", " ")[:255], "ASCII", "DATASET POLYDATA",
           f"POINTS {n_total} double"]
    out += [" ".join(repr(float(v)) for v in p) for p in np.vstack(lines)]
    cells, size, start = [], 0, 0
    for p in lines:
        ids = list(range(start, start + len(p))) + ([start] if closed else [])
        cells.append(f"{len(ids)} " + " ".join(map(str, ids)))
        size += len(ids) + 1
        start += len(p)
    out += [f"LINES {len(lines)} {size}"] + cells
    out.append(f"POINT_DATA {n_total}")
    for name, values in data.items():
        out += [f"SCALARS {name} double 1", "LOOKUP_TABLE default"]
        out += ["nan" if math.isnan(v) else repr(float(v)) for v in values]
    tmp = os.fspath(path) + ".tmp"
    with open(tmp, "w") as f:
        f.write("\n".join(out) + "\n")
    os.replace(tmp, path)
    return path


def export_study_vtk(out, folder="vtk"):
    """One VTK file per recorded step of a twist study in ``out`` (steps/<direction>_NNNN.npz ->
    <folder>/<direction>_NNNN.vtk): centreline, stripe, kappa L and tau L. Returns the paths."""
    target = os.path.join(out, folder)
    os.makedirs(target, exist_ok=True)
    written = []
    for fn in sorted(glob.glob(os.path.join(out, "steps", "*.npz"))):
        with np.load(fn) as d:
            name = os.path.splitext(os.path.basename(fn))[0]
            title = f"jaxrod {name}: branch {d['branch']}, phi = {float(d['phi']) / math.pi:+.6f} pi"
            written.append(write_vtk(os.path.join(target, name + ".vtk"), d["x"], d["eccentric"], closed=True,
                                     point_data={"kappa_L": d["kappa_L"], "tau_L": d["tau_L"]}, title=title))
    return written
