"""Reading polylines and a step file's imposed twist: CSV (an x,y,z header or three bare columns),
.npy (N, 3), an array of an .npz (e.g. ``x`` and ``eccentric`` of a study's step file
``steps/*.npz``)."""
from __future__ import annotations

import csv
import os

import numpy as np

from .inputs import checked_points

__all__ = ["load_joint_twist", "load_polyline"]


def _parse_float(text):
    try:
        return float(text)
    except ValueError:
        return None


def _read_csv(path):
    with open(path, newline="") as fh:
        rows = [
            (lineno, [cell.strip() for cell in row])
            for lineno, row in enumerate(csv.reader(fh), start=1)
            if row and any(cell.strip() for cell in row) and not row[0].lstrip().startswith("#")
        ]
    if not rows:
        raise ValueError(f"{path}: empty file, no points")
    first_line, first = rows[0]
    has_header = any(_parse_float(cell) is None for cell in first)
    if has_header:
        names = [cell.lower() for cell in first]
        missing = [c for c in ("x", "y", "z") if c not in names]
        if missing:
            raise ValueError(
                f"{path}: missing column(s) {', '.join(missing)} in the header {first!r} "
                "(need columns named x, y, z)"
            )
        dup = [c for c in ("x", "y", "z") if names.count(c) > 1]
        if dup:
            raise ValueError(f"{path}: duplicate column(s) {', '.join(dup)} in the header {first!r}")
        cols = [names.index(c) for c in ("x", "y", "z")]
        body = rows[1:]
        width = len(names)
    else:
        cols = [0, 1, 2]
        body = rows
        width = 3
        if len(first) != 3:
            raise ValueError(
                f"{path}: a file without header must have exactly 3 numeric columns (x, y, z), "
                f"line {first_line} has {len(first)}"
            )
    pts = np.empty((len(body), 3))
    for i, (lineno, row) in enumerate(body):
        if len(row) != width:
            raise ValueError(f"{path}: line {lineno} has {len(row)} columns, expected {width}")
        for k, c in enumerate(cols):
            v = _parse_float(row[c])
            if v is None:
                raise ValueError(f"{path}: line {lineno}: value {row[c]!r} is not a number")
            pts[i, k] = v
    return pts


def _read_npz(path):
    """The arrays of a .npz file (no pickles), as a dict; ValueError naming the file if unreadable."""
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: data[name] for name in data.files}
    except (ValueError, zipfile.BadZipFile, EOFError) as err:  # OSError (a missing file): the caller's
        raise ValueError(f"{path}: not a readable .npz archive of numeric arrays ({err})") from None


def load_polyline(path, array="x"):
    """Read a polyline (N, 3) from a file.

    * ``.csv``: comma-separated. Either a header row naming columns ``x``, ``y``, ``z`` (any order,
      case-insensitive; other columns are ignored) followed by numeric rows, or exactly three
      numeric columns without header. Blank lines and lines starting with ``#`` are skipped.
    * ``.npy``: a numeric array of shape (N, 3) (no pickles).
    * ``.npz``: the array named ``array`` (default ``"x"``) of the archive, e.g. a study's step
      file ``steps/<direction>_<NNNN>.npz``, which holds the centreline ``x`` and the eccentric
      line ``eccentric`` (and the imposed twist ``phi``, see :func:`load_joint_twist`).
      ``array`` is ignored for the other formats.

    Returns a float array (N, 3). Raises ValueError naming the file and the problem: unknown
    extension, missing x/y/z columns, an .npz without the named array, a non-numeric value, wrong
    shape, fewer than 4 points, non-finite values.
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext == ".csv":
        pts = _read_csv(path)
    elif ext == ".npy":
        try:
            pts = np.load(path, allow_pickle=False)
        except ValueError as err:
            raise ValueError(f"{path}: not a numeric .npy array ({err})") from None
        if pts.dtype.kind not in "biuf":
            raise ValueError(f"{path}: array of dtype {pts.dtype} is not numeric")
    elif ext == ".npz":
        arrays = _read_npz(path)
        if array not in arrays:
            held = ", ".join(sorted(arrays)) or "nothing"
            raise ValueError(f"{path}: no array {array!r} in this .npz (it holds {held}); a study's step file "
                             "(steps/*.npz) holds the centreline 'x' and the eccentric line 'eccentric'")
        pts = arrays[array]
        if pts.dtype.kind not in "biuf":
            raise ValueError(f"{path}: array {array!r} of dtype {pts.dtype} is not numeric")
        return checked_points("polyline", pts, source=f"{path} (array {array!r})")
    else:
        raise ValueError(f"{path}: unknown file extension {ext!r} (expected .csv, .npy or .npz)")
    return checked_points("polyline", pts, source=path)


def load_joint_twist(path):
    """The imposed twist ``phi`` (radians) stored in a study's step file (``steps/*.npz``), for
    :func:`analyze`'s ``joint_twist``; None if ``path`` is not an .npz or holds no ``phi``.
    Raises ValueError (naming the file) for a ``phi`` that is not one finite number."""
    path = os.fspath(path)
    if os.path.splitext(path)[1].lower() != ".npz":
        return None
    arrays = _read_npz(path)
    if "phi" not in arrays:
        return None
    phi = arrays["phi"]
    if phi.dtype.kind not in "biuf" or phi.size != 1 or not np.isfinite(phi).all():
        raise ValueError(f"{path}: array 'phi' must be one finite number (the imposed twist, radians)")
    return float(phi.reshape(()))
