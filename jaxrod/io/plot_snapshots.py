"""Rods seen as tubes (matplotlib): a closed rod's centreline thickened to its diameter, shaded by
depth and drawn far to near, with the stripe drawn on its surface; a grid of such views seen the
same way."""
from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

from ..validation import check_points
from .figures import finish

__all__ = ["plot_snapshot", "plot_snapshots", "view_frame"]


def view_frame(x):
    """(3, 3) rows e1, e2, e3: a view of the closed curve x (N, 3) along its axis of least spread
    (e3; for a trefoil, its three-fold symmetry axis), oriented towards +z, with e1 the global x
    axis projected onto the view plane (so that successive states are seen the same way)."""
    x = check_points("x", x)
    centred = x - x.mean(axis=0)
    _, vectors = np.linalg.eigh(centred.T @ centred)
    e3 = vectors[:, 0]
    if e3[2] < 0.0:
        e3 = -e3
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        e1 = axis - (axis @ e3) * e3
        if np.linalg.norm(e1) > 0.3:
            break
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(e3, e1), e3])


def _capsules(p, q, half_width, n_arc=8):
    """(K, 2 n_arc + 2, 2) outlines of 2D capsules (segments p -> q, each (K, 2), thickened by
    half_width, with round ends): a tube segment seen from the side."""
    d = q - p
    angle = np.arctan2(d[:, 1], d[:, 0])[:, None]
    arc = np.linspace(0.5 * np.pi, 1.5 * np.pi, n_arc + 1)[None, :]
    start = p[:, None, :] + half_width * np.stack([np.cos(angle + arc), np.sin(angle + arc)], axis=-1)
    end = q[:, None, :] + half_width * np.stack([np.cos(angle + arc + np.pi), np.sin(angle + arc + np.pi)], axis=-1)
    return np.concatenate([start, end], axis=1)


def plot_snapshot(x, eccentric, path=None, title=None, ax=None, diameter=None, frame=None, unit=None):
    """A closed rod seen as a tube along its symmetry axis (``view_frame``): the centreline x
    (N, 3) thickened to the rod's ``diameter`` (default: 2x the stripe's mean distance from the
    centreline), shaded by depth (lighter = nearer the viewer) and drawn far to near, so that at
    each crossing the strand on top covers the one below; the stripe (the eccentric line, (N, 3),
    paired node by node with x) is drawn where it faces the viewer. Equal aspect; axes in
    ``unit`` (e.g. 'mm') along the view's in-plane axes e1, e2.

    ax: a 2D axis to draw into (e.g. from :func:`plot_snapshots`); frame: a (3, 3) view frame
    (default ``view_frame(x)``). Returns the figure; with ``path`` it is saved and closed.
    """
    from matplotlib.collections import PolyCollection

    x = check_points("x", x)
    e = check_points("eccentric", eccentric)
    if e.shape != x.shape:
        raise ValueError(f"eccentric must pair with x node by node: shapes {e.shape} and {x.shape}")
    if diameter is None:
        diameter = 2.0 * float(np.mean(np.linalg.norm(e - x, axis=1)))
    frame = view_frame(x) if frame is None else np.asarray(frame, dtype=float)
    if ax is None:
        fig, ax = plt.subplots(figsize=(5, 5))
    else:
        fig = ax.figure
    centre = x.mean(axis=0)
    xv, ev = (x - centre) @ frame.T, (e - centre) @ frame.T  # (N, 3): in-plane, in-plane, depth
    xn, en = np.roll(xv, -1, axis=0), np.roll(ev, -1, axis=0)
    r = 0.5 * diameter
    depth = 0.5 * (xv[:, 2] + xn[:, 2])
    stripe_depth = 0.5 * (ev[:, 2] + en[:, 2])
    tubes = _capsules(xv[:, :2], xn[:, :2], r)
    stripes = _capsules(ev[:, :2], en[:, :2], 0.12 * r, n_arc=4)
    lo, hi = depth.min(), depth.max()
    shade = plt.get_cmap("Blues")(0.85 - 0.45 * (depth - lo) / max(hi - lo, 1e-300))  # near: lighter
    # Painter's order: every tube piece and every visible stripe piece by its own depth. A
    # stripe on the near side of its strand is up to r nearer than the strand's centre, so it
    # shows over its own tube but not through a strand crossing above it (>= D nearer).
    visible = stripe_depth > depth
    keys = np.concatenate([depth, stripe_depth[visible]])
    shapes = list(tubes) + list(stripes[visible])
    colours = list(shade) + [(1.0, 0.62, 0.11, 1.0)] * int(visible.sum())
    order = np.argsort(keys, kind="stable")
    outline = PolyCollection(list(_capsules(xv[:, :2], xn[:, :2], 1.12 * r)), facecolors="#0b1e3f",
                             edgecolors="none")
    ax.add_collection(outline)  # the silhouette, under everything
    ax.add_collection(PolyCollection([shapes[i] for i in order], facecolors=[colours[i] for i in order],
                                     edgecolors="none"))
    span = float(np.max(np.abs(xv[:, :2]))) + 1.3 * r
    ax.set_xlim(-span, span)
    ax.set_ylim(-span, span)
    ax.set_aspect("equal")
    suffix = f" ({unit})" if unit else ""
    ax.set_xlabel("e1" + suffix)
    ax.set_ylabel("e2" + suffix)
    ax.tick_params(labelsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    if path is not None:
        fig.tight_layout()
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


def plot_snapshots(snapshots, path=None, ncols=3, diameter=None, unit=None):
    """Grid of tube views (:func:`plot_snapshot`): snapshots is a list of (x, eccentric, title),
    ``ncols`` columns. All are seen along the first one's symmetry axis, so that shapes compare."""
    snapshots = list(snapshots)
    if not snapshots:
        raise ValueError("snapshots: nothing to plot")
    try:
        integral = not isinstance(ncols, bool) and int(ncols) == ncols
    except (TypeError, ValueError):
        integral = False
    if not integral or int(ncols) < 1:
        raise ValueError(f"ncols must be an integer >= 1, got {ncols!r}")
    ncols = min(int(ncols), len(snapshots))
    nrows = math.ceil(len(snapshots) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.6 * ncols, 3.7 * nrows), squeeze=False)
    frame = None
    for i, snap in enumerate(snapshots):
        try:
            x, e, t = snap
        except (TypeError, ValueError):
            plt.close(fig)
            raise ValueError(f"snapshots[{i}] must be (x, eccentric, title)") from None
        if frame is None:
            frame = view_frame(x)
        plot_snapshot(x, e, title=t, ax=axes.flat[i], diameter=diameter, frame=frame, unit=unit)
    for ax in list(axes.flat)[len(snapshots):]:
        ax.set_visible(False)
    return finish(fig, path)
