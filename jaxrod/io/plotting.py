"""Figures (matplotlib). Each function returns its figure, or saves and closes it when given a path.
The backend is left to the caller (inline in notebooks; the CLI selects Agg)."""
from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

from ..continuation.kinds import EventKind
from ..linalg.tolerances import DEFAULT_NEGATIVE_TOL
from .figures import finish
from .plot_snapshots import plot_snapshot, plot_snapshots, view_frame

__all__ = [
    "plot_eigenvalue_scan",
    "plot_mode",
    "plot_convergence",
    "plot_bifurcation",
    "plot_branch_ends",
    "plot_linking",
    "plot_profiles",
    "plot_snapshot",
    "plot_snapshots",
    "view_frame",
    "plot_critical_vs_ratio",
]


def plot_eigenvalue_scan(scan, critical=None, path=None, n_show=6, title=None, analytic=None):
    """Lowest eigenvalues (zero modes removed) against phi/pi along a scan.

    scan: list of (phi, n_negative, eigenvalues (k,)); critical: optional CriticalPoint;
    analytic: optional (phi in rad, label), e.g. Michell's 2 pi sqrt(3)(1 + nu), marked too.
    """
    phi = np.array([s[0] for s in scan]) / math.pi
    lam = np.array([s[2][:n_show] for s in scan])
    fig, ax = plt.subplots(figsize=(6, 4))
    for j in range(lam.shape[1]):
        ax.plot(phi, lam[:, j], "o-", ms=3, lw=1)
    ax.axhline(0.0, color="k", lw=0.8)
    if critical is not None:
        ax.axvline(critical.phi / math.pi, color="r", ls="--", lw=1,
                   label=f"phi* = {critical.phi / math.pi:.6f} pi (computed)")
    if analytic is not None:
        ax.axvline(float(analytic[0]) / math.pi, color="k", ls=":", lw=1.2,
                   label=f"{analytic[1]} = {float(analytic[0]) / math.pi:.6f} pi")
    if critical is not None or analytic is not None:
        ax.legend(fontsize=8, loc="upper right")
    ax.set_xlabel("imposed twist phi / pi (rad / pi)")
    ax.set_ylabel("lowest Hessian eigenvalues (units of B/l)")
    ax.set_title(title or "Stability along the twist continuation")
    return finish(fig, path)


def plot_mode(x, mode_displacement, path=None, title="Critical mode", amplitude=None):
    """3D view of the centreline x (N,3) and the centreline displaced along the mode (N,3)."""
    x = np.asarray(x)
    d = np.asarray(mode_displacement)
    size = np.ptp(x, axis=0).max()
    amp = 0.06 * size / max(np.abs(d).max(), 1e-300) if amplitude is None else amplitude
    y = x + amp * d
    fig = plt.figure(figsize=(5, 5))
    ax = fig.add_subplot(projection="3d")
    loop = lambda a: np.vstack([a, a[:1]])
    ax.plot(*loop(x).T, "k-", lw=1, label="equilibrium")
    ax.plot(*loop(y).T, "r-", lw=2, label="+ critical mode")
    ax.set_box_aspect((1, 1, 1))
    c = x.mean(axis=0)
    for set_lim, k in ((ax.set_xlim, 0), (ax.set_ylim, 1), (ax.set_zlim, 2)):
        set_lim(c[k] - 0.6 * size, c[k] + 0.6 * size)
    ax.legend(loc="upper left")
    ax.set_title(title)
    return finish(fig, path)


def plot_convergence(rows, path=None, title="Accuracy against time"):
    """Relative error against wall time (log-log). rows: dicts with 'N', 'rel_error', 'seconds'
    and optionally 'label' (one curve per label)."""
    fig, ax = plt.subplots(figsize=(6, 4))
    labels = sorted({r.get("label", "") for r in rows})
    for lab in labels:
        rs = [r for r in rows if r.get("label", "") == lab]
        t = [r["seconds"] for r in rs]
        e = [abs(r["rel_error"]) for r in rs]
        ax.loglog(t, e, "o-", label=lab or None)
        for r in rs:
            ax.annotate(f"N={r['N']}", (r["seconds"], abs(r["rel_error"])), fontsize=8,
                        xytext=(4, 4), textcoords="offset points")
    ax.set_xlabel("wall time per critical twist (s, compile excluded)")
    ax.set_ylabel("relative error of phi*")
    ax.set_title(title)
    if any(labels):
        ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    return finish(fig, path)


# ---------------------------------------------------------------------------- continuation tables
def _column(table, name, n=None):
    """1-D column ``name`` of ``table`` (ValueError if missing or of another length than n)."""
    if name not in table:
        raise ValueError(f"table: missing column {name!r} (columns: {', '.join(map(str, table))})")
    a = np.asarray(table[name])
    if a.ndim != 1:
        raise ValueError(f"table: column {name!r} must be 1-D, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"table: column {name!r} has {a.shape[0]} entries, column 'phi' has {n}")
    return a


def _table_basics(table):
    """(phi/pi, branch labels as str, ordered unique labels, n)."""
    if not hasattr(table, "keys"):
        raise ValueError(f"table must be a dict of columns, got {type(table).__name__}")
    phi = _column(table, "phi").astype(float)
    n = phi.shape[0]
    if n == 0:
        raise ValueError("table: no rows")
    branch = _column(table, "branch", n).astype(str) if "branch" in table else np.full(n, "")
    labels = list(dict.fromkeys(branch.tolist()))  # order of first appearance
    return phi / math.pi, branch, labels, n


def _as_bool(a):
    a = np.asarray(a)
    if a.dtype.kind in "US":
        return np.isin(np.char.lower(np.char.strip(a.astype(str))), ("true", "1", "yes", "1.0"))
    return a.astype(float) != 0.0


def _lambda_columns(table):
    """Names of the columns lambda_0, lambda_1, ... present, in numeric order."""
    cols = []
    for name in table:
        name = str(name)
        if name.startswith("lambda_") and name[7:].isdigit():
            cols.append((int(name[7:]), name))
    return [name for _, name in sorted(cols)]


def _draw_critical(axes, critical, colour_start):
    """Vertical dashed lines at critical['phi']/pi on every axis, labelled on the first."""
    if not critical:
        return
    for i, c in enumerate(critical):
        try:
            phi, label = float(c["phi"]), str(c["label"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"critical[{i}] must be a dict with a numeric 'phi' and a 'label', got {c!r}") from None
        colour = f"C{(colour_start + i) % 10}"
        for j, ax in enumerate(axes):
            ax.axvline(phi / math.pi, color=colour, ls=":", lw=1,
                       label=f"{label} ({phi / math.pi:.4f} pi)" if j == 0 else None)
        kind, wr = c.get("kind"), c.get("Wr")
        if kind is not None and wr is not None and math.isfinite(float(wr)):
            # a located event: marked where it sits on the diagram (fold: triangle, branch point: star)
            axes[0].plot([phi / math.pi], [float(wr)], "v" if kind == EventKind.FOLD else "*", color=colour, ms=11,
                         mec="k", mew=0.8, ls="none", zorder=5)


def _runs_by_stability(stable):
    """Consecutive pieces of one branch's polyline: (start, stop, stable) with rows start..stop
    inclusive; a piece is stable where every row in it is, so the step between a stable and an
    unstable row belongs to the dashed piece."""
    step_stable = stable[:-1] & stable[1:]
    runs, i = [], 0
    while i < step_stable.shape[0]:
        j = i
        while j + 1 < step_stable.shape[0] and step_stable[j + 1] == step_stable[i]:
            j += 1
        runs.append((i, j + 1, bool(step_stable[i])))
        i = j + 1
    return runs


def _draw_branch_lines(ax, x, wr, stable, colour, name):
    """One branch in the diagram: stable pieces solid, unstable pieces dashed, row markers filled
    where stable and open where unstable; in the legend by its colour alone (a square), so that
    the line styles keep one meaning."""
    ax.plot([], [], "s", color=colour, ls="none", label=name)
    for a, b, st in _runs_by_stability(stable):
        ax.plot(x[a:b + 1], wr[a:b + 1], "-" if st else "--", color=colour, lw=1.2 if st else 1.0,
                gid="stable" if st else "unstable")
    ax.plot(x[stable], wr[stable], "o", color=colour, ms=4, ls="none")
    ax.plot(x[~stable], wr[~stable], "o", color=colour, ms=4, ls="none", mfc="none")


def plot_bifurcation(table, critical=None, path=None, title=None, band=None):
    """Bifurcation diagram of a continuation: writhe against imposed twist (top; stable pieces
    solid, unstable ones dashed, folds and branch points marked) and the lowest Hessian
    eigenvalues (bottom, symlog scale, linthresh 1e-7) sharing the x axis.

    Parameters
    ----------
    table : dict of str to array_like
        One entry per continuation step (1-D, all of one length), with at least 'phi' (rad), 'Wr'
        (turns), 'stable' (bool, 0/1 or 'True'/'False'), the eigenvalue columns 'lambda_0',
        'lambda_1', ... (units of B/l, zero modes removed) and optionally 'branch' (str labels;
        without it all rows are one branch). Rows of a branch are drawn in table order.
    critical : list of dict, optional
        ``{'phi': rad, 'label': str}``: vertical dotted lines, in the legend; with 'kind' ('fold'
        or 'branch_point') and 'Wr', also a marker at (phi, Wr): a triangle for a fold, a star
        for a branch point.
    path : str or path-like, optional
        Save the figure there and close it.
    title : str, optional
        Figure title (default "Bifurcation diagram").
    band : float, optional
        Half-width of the near-zero band, in units of B/l: the stability count's ``negative_tol``
        (default ``DEFAULT_NEGATIVE_TOL``). Eigenvalues with ``|lambda| <= band`` (zero and
        sliding modes, which the count excludes) are left out of the eigenvalue panel, and a
        note in the panel says so.

    Returns
    -------
    matplotlib.figure.Figure
        The figure (closed when saved to ``path``).

    Raises
    ------
    ValueError
        If ``table`` is not a dict of columns, has no rows, lacks a column named above or no
        eigenvalue column, or has columns of different lengths.
    """
    x, branch, labels, n = _table_basics(table)
    wr = _column(table, "Wr", n).astype(float)
    stable = _as_bool(_column(table, "stable", n))
    lam_cols = _lambda_columns(table)
    if not lam_cols:
        raise ValueError("table: no eigenvalue columns 'lambda_0', 'lambda_1', ...")
    lam = np.stack([_column(table, c, n).astype(float) for c in lam_cols], axis=1)
    band = DEFAULT_NEGATIVE_TOL if band is None else float(band)
    lam = np.where(np.abs(lam) <= band, np.nan, lam)  # the modes the stability count excludes
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(9.5, 6.5),
                                      gridspec_kw={"height_ratios": [1, 1]})
    for b, lab in enumerate(labels):
        sel = branch == lab
        colour = f"C{b % 10}"
        name = lab or "equilibria"
        _draw_branch_lines(top, x[sel], wr[sel], stable[sel], colour, name)
        for j in range(lam.shape[1]):
            bottom.plot(x[sel], lam[sel, j], ".-", color=colour, ms=3, lw=0.8,
                        alpha=1.0 if j == 0 else 0.6, label=name if j == 0 else None)
    # Legend proxies for the line and marker convention.
    top.plot([], [], "o-", color="0.3", ms=4, label="stable")
    top.plot([], [], "o--", color="0.3", ms=4, mfc="none", label="unstable")
    if critical and any(c.get("kind") for c in critical):
        top.plot([], [], "v", color="0.3", ms=8, mec="k", label="fold")
        top.plot([], [], "*", color="0.3", ms=9, mec="k", label="branch point")
    bottom.axhline(0.0, color="k", lw=0.8)
    bottom.set_yscale("symlog", linthresh=1e-7)
    # beside the axes, under the legend: a note inside them would cover eigenvalues
    bottom.text(1.01, 0.0, f"not drawn:\n|lambda| <= {band:.0e} B/l\n(zero and sliding\nmodes, not counted)",
                transform=bottom.transAxes, fontsize=7, va="bottom", ha="left", color="0.3", gid="band_note")
    _draw_critical((top, bottom), critical, len(labels))
    top.set_ylabel("writhe Wr (turns)")
    bottom.set_ylabel("lowest Hessian eigenvalues\n(units of B/l; symlog)")
    bottom.set_xlabel("imposed twist phi / pi (rad / pi)")
    top.legend(**_OUTSIDE)  # legends beside the axes, never over the data
    if len(labels) > 1:
        bottom.legend(**_OUTSIDE)
    top.grid(True, alpha=0.3)
    bottom.grid(True, alpha=0.3)
    top.set_title(title or "Bifurcation diagram")
    return finish(fig, path)


def plot_branch_ends(table, events, path=None, title=None):
    """Each located branch end up close: the lowest eigenvalue (column 'lambda_0', the study's
    scaled units) against phi/pi near the event, for every branch with rows there: stable rows
    solid, unstable branches dashed, the event marked (fold: triangle, branch point: star).

    table: branch.csv's columns (at least 'phi', 'branch', 'lambda_0', 'stable'); events: dicts
    with 'phi' (rad), 'kind' and 'unstable_branch' (critical.json's located ``events``). The window
    spans the unstable branch's rows and the nearest stable rows, at least 1e-3 pi wide.
    """
    x, branch, labels, n = _table_basics(table)
    lam = _column(table, "lambda_0", n).astype(float)
    stable = _as_bool(_column(table, "stable", n))
    events = [e for e in events if e.get("kind")]
    if not events:
        raise ValueError("events: no located event to draw")
    ncols = min(2, len(events))
    nrows = -(-len(events) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.5 * ncols, 3.8 * nrows), squeeze=False)
    for ax in axes.ravel()[len(events):]:
        ax.set_visible(False)
    for ax, ev in zip(axes.ravel(), events):
        x0 = float(ev["phi"]) / math.pi
        own = branch == ev.get("unstable_branch")
        half = max(1e-3, 1.5 * float(np.max(np.abs(x[own] - x0))) if own.any() else 1e-3)
        window = np.abs(x - x0) <= half
        for b, lab in enumerate(labels):
            sel = (branch == lab) & window
            if not sel.any():
                continue
            ls = "-" if (stable & sel).any() else "--"
            ax.plot(x[sel] - x0, lam[sel], ls, marker="o", ms=3, color=f"C{b % 10}", lw=1, label=lab or "equilibria",
                    mfc="none" if ls == "--" else None)
        ax.plot([0.0], [0.0], "v" if ev["kind"] == EventKind.FOLD else "*", color="k", ms=10, ls="none",
                label=f"{ev['kind'].replace('_', ' ')} at {x0:+.8f} pi")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_xlim(-half, half)
        ax.set_xlabel("(phi - phi*) / pi")
        ax.set_ylabel("lowest eigenvalue (B/l)")
        ax.legend(fontsize=7)
        ax.grid(True, alpha=0.3)
    fig.suptitle(title or "Branch ends, located on the extended system")
    return finish(fig, path)


_LINESTYLES = ("-", "--", ":", "-.")
_OUTSIDE = {"fontsize": 8, "loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0}
_MARKERS = ("o", "s", "^", "D", "v", "P", "X")


def plot_linking(table, critical=None, path=None, title=None):
    """Lk from the frames (Wr + Tw, lines), Lk from the Gauss integral (markers), Wr and Tw
    against phi/pi. One colour per quantity; branches differ by line style and marker.

    table: dict of 1-D columns with at least 'phi' (rad), 'Lk_frames', 'Lk_gauss', 'Wr', 'Tw'
    (and 'branch'); critical: optional list of {'phi', 'label'} as in :func:`plot_bifurcation`.
    """
    x, branch, labels, n = _table_basics(table)
    cols = {c: _column(table, c, n).astype(float) for c in ("Lk_frames", "Lk_gauss", "Wr", "Tw")}
    colours = {"Lk_frames": "C0", "Lk_gauss": "C0", "Wr": "C1", "Tw": "C2"}
    fig, ax = plt.subplots(figsize=(9.5, 4.5))
    # The line drawn on a twisted rod closes only at whole turns (its ends were turned by phi
    # before gluing): its Gauss linking number is an integer, and means Lk, only there.
    whole = np.abs(x / 2.0 - np.round(x / 2.0)) < 1e-9
    for b, lab in enumerate(labels):
        sel = branch == lab
        ls, mk = _LINESTYLES[b % len(_LINESTYLES)], _MARKERS[b % len(_MARKERS)]
        ax.plot(x[sel], cols["Lk_frames"][sel], ls, color=colours["Lk_frames"], lw=1.5)
        at = sel & whole
        ax.plot(x[at], cols["Lk_gauss"][at], mk, color=colours["Lk_gauss"], ms=6, mfc="none", ls="none")
        ax.plot(x[sel], cols["Wr"][sel], ls, color=colours["Wr"], lw=1.2)
        ax.plot(x[sel], cols["Tw"][sel], ls, color=colours["Tw"], lw=1.2)
    # Legend: quantities by colour, branches by style.
    ax.plot([], [], "-", color="C0", label="Lk (frames, Wr + Tw)")
    ax.plot([], [], "o", color="C0", mfc="none", label="Lk (Gauss integral,\nat whole turns)")
    ax.plot([], [], "-", color="C1", label="Wr")
    ax.plot([], [], "-", color="C2", label="Tw")
    if len(labels) > 1 or labels[0]:
        for b, lab in enumerate(labels):
            ax.plot([], [], _LINESTYLES[b % len(_LINESTYLES)] + _MARKERS[b % len(_MARKERS)],
                    color="0.4", mfc="none", label=f"branch {lab}")
    _draw_critical((ax,), critical, 3)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("imposed twist phi / pi (rad / pi)")
    ax.set_ylabel("Lk, Wr, Tw (turns)")
    ax.legend(**_OUTSIDE)
    ax.grid(True, alpha=0.3)
    ax.set_title(title or "Linking number, writhe and twist")
    return finish(fig, path)


# ---------------------------------------------------------------------------- profiles
def plot_profiles(s_over_L, profiles, labels, path=None, title=None, ylabel_kappa="curvature kappa L (-)",
                  ylabel_tau="twist density tau L (rad)"):
    """Curvature (top) and twist (bottom) profiles against s/L, one curve per label.

    s_over_L: (n,) common grid; profiles: list of (kappa_L, tau_L) pairs of (n,) arrays (already
    made dimensionless by the caller, e.g. kappa * L); labels: one str per pair.
    """
    s = np.asarray(s_over_L, dtype=float)
    if s.ndim != 1:
        raise ValueError(f"s_over_L must be 1-D, got shape {s.shape}")
    profiles, labels = list(profiles), list(labels)
    if len(profiles) != len(labels):
        raise ValueError(f"{len(profiles)} profiles but {len(labels)} labels")
    if not profiles:
        raise ValueError("profiles: nothing to plot")
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(9.5, 5.5))
    for i, (pair, lab) in enumerate(zip(profiles, labels)):
        try:
            kappa, tau = (np.asarray(a, dtype=float) for a in pair)
        except (TypeError, ValueError):
            raise ValueError(f"profiles[{i}] must be a pair (kappa_L, tau_L) of arrays") from None
        if kappa.shape != s.shape or tau.shape != s.shape:
            raise ValueError(
                f"profiles[{i}]: arrays of shapes {kappa.shape}, {tau.shape} do not match s_over_L {s.shape}"
            )
        top.plot(s, kappa, lw=1.2, label=str(lab))
        bottom.plot(s, tau, lw=1.2, label=str(lab))
    bottom.axhline(0.0, color="k", lw=0.5)
    top.set_ylabel(ylabel_kappa)
    bottom.set_ylabel(ylabel_tau)
    bottom.set_xlabel("arc length s / L (-)")
    top.legend(**_OUTSIDE)
    top.grid(True, alpha=0.3)
    bottom.grid(True, alpha=0.3)
    top.set_title(title or "Curvature and twist profiles")
    return finish(fig, path)


# ---------------------------------------------------------------------------- critical angles
def plot_critical_vs_ratio(ratios, phi_plus, phi_minus, michell_plus=None, michell_minus=None,
                           path=None, title=None, searched=None):
    """Critical twist angles / pi against the slenderness D/L: phi_plus (> 0 side) and phi_minus
    (< 0 side) in radians, one per ratio (NaN where none was found); optional Michell estimates
    (radians) as horizontal dashed lines of the same colours. searched: the range searched
    (radians, e.g. 16 pi): a ratio without a critical twist is then marked at +-searched by an
    open triangle, "no buckling within +-searched", instead of being left out."""
    r = np.asarray(ratios, dtype=float)
    pp = np.asarray(phi_plus, dtype=float)
    pm = np.asarray(phi_minus, dtype=float)
    if r.ndim != 1 or pp.shape != r.shape or pm.shape != r.shape:
        raise ValueError(
            f"ratios, phi_plus, phi_minus must be 1-D of equal length, got {r.shape}, {pp.shape}, {pm.shape}"
        )
    order = np.argsort(r)
    fig, ax = plt.subplots(figsize=(8.5, 4.5))
    ax.plot(r[order], pp[order] / math.pi, "o-", color="C0", ms=5, lw=1, label="phi+ (critical, > 0)")
    ax.plot(r[order], pm[order] / math.pi, "s-", color="C3", ms=5, lw=1, label="phi- (critical, < 0)")
    if searched is not None:
        bound = abs(float(searched)) / math.pi
        for values, sign, colour, marker in ((pp, 1.0, "C0", "^"), (pm, -1.0, "C3", "v")):
            none = ~np.isfinite(values)
            if np.any(none):
                ax.plot(r[none], np.full(int(none.sum()), sign * bound), marker, color=colour, ms=8, mfc="none",
                        ls="none", label=f"no buckling within {'+' if sign > 0 else '-'}{bound:g} pi")
    if michell_plus is not None:
        ax.axhline(float(michell_plus) / math.pi, color="C0", ls="--", lw=1,
                   label=f"Michell estimate + ({float(michell_plus) / math.pi:.3f} pi)")
    if michell_minus is not None:
        ax.axhline(float(michell_minus) / math.pi, color="C3", ls="--", lw=1,
                   label=f"Michell estimate - ({float(michell_minus) / math.pi:.3f} pi)")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("slenderness D / L (-)")
    ax.set_ylabel("critical twist phi* / pi (rad / pi)")
    ax.legend(**_OUTSIDE)
    ax.grid(True, alpha=0.3)
    ax.set_title(title or "Critical twist against slenderness")
    return finish(fig, path)


def plot_critical_curve(rows, nu=0.5, path=None, title=None, points=None):
    """Critical twists against D/L as curves (``jaxrod.studies.critical_curve``): rows with side,
    D_over_L, phi_star (rad) and kind ("fold" or "branch_point"); each side a line, folds as
    dots and branch points as diamonds; Michell's ring (2 sqrt(3)(1 + nu) pi) and its double as
    dashed lines. points: optional [(D/L, phi* (rad), label)] drawn as open squares (point studies)."""
    fig, ax = plt.subplots(figsize=(8.5, 4.8))
    names = {"plus": "phi > 0 side", "minus": "phi < 0 side"}
    for side, colour in (("plus", "C0"), ("minus", "C3")):
        rr = sorted((r for r in rows if r["side"] == side), key=lambda r: r["D_over_L"])
        if not rr:
            continue
        x = np.array([r["D_over_L"] for r in rr])
        y = np.array([r["phi_star"] for r in rr]) / math.pi
        ax.plot(x, y, "-", color=colour, lw=1.2, label=f"{names[side]}: first instability")
        for kind, marker in ((EventKind.FOLD, "o"), (EventKind.BRANCH_POINT, "D")):
            m = np.array([r["kind"] == kind for r in rr])
            if m.any():
                ax.plot(x[m], y[m], marker, color=colour, ms=3.5, ls="none", label=f"  {kind.replace('_', ' ')}s")
    for k, (r, phi, label) in enumerate(points or ()):
        ax.plot(r, phi / math.pi, "ks", mfc="none", ms=8, label=label if k == 0 else None)
    m = 2.0 * math.sqrt(3.0) * (1.0 + float(nu))
    ax.axhline(m, color="C0", ls="--", lw=1, label=f"Michell's ring, +{m:.3f} pi")
    ax.axhline(-2.0 * m, color="C3", ls="--", lw=1, label=f"2 x Michell, -{2 * m:.3f} pi")
    ax.set_xlabel("slenderness D / L (-)")
    ax.set_ylabel("critical twist phi* / pi (rad / pi)")
    ax.grid(True, alpha=0.3)
    ax.legend(**_OUTSIDE)
    ax.set_title(title or "Critical twists against slenderness")
    return finish(fig, path)


_KNOT_TITLES = {"3_1": "trefoil 3_1", "4_1": "figure-eight 4_1", "5_1": "cinquefoil 5_1", "5_2": "three-twist 5_2"}


def plot_atlas(rows, michell, span=None, path=None, title=None, tightening=None):
    """The twisted-knot atlas: a panel per knot of phi*/pi against D/L, phi > 0 side (filled
    circles) and phi < 0 side (squares), the legend says which side tightens the knot; dashed
    lines at +-michell and dotted at +-2 michell (Michell's ring estimate and its double, radians);
    cases that reached +-span without a branch end as open triangles at +-span; snaps (kind
    'snap': the rod jumps to another stable state) crossed; where a row has phi_extrapolated and
    extrapolation_error (the atlas's accuracy mode), that value with its error bar.
    rows: dicts with knot, D_over_L, N, side, phi_star (radians, NaN: none), kind; tightening:
    {(knot, D/L, N): side} (``jaxrod.studies.atlas.tightening_sides``), named in the legend."""
    tightening = tightening or {}
    knots = list(dict.fromkeys(r["knot"] for r in rows))
    if not knots:
        raise ValueError("rows: no atlas rows to plot")
    ncols = min(len(knots), 2)
    nrows = math.ceil(len(knots) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.2 * ncols + 2.2, 3.6 * nrows), squeeze=False, sharex=True)
    m = float(michell) / math.pi
    for ax, knot in zip(axes.flat, knots):
        seen_snap = False
        for side, marker, colour in (("plus", "o", "C0"), ("minus", "s", "C3")):
            sel = sorted((r for r in rows if r["knot"] == knot and r["side"] == side), key=lambda r: r["D_over_L"])
            if not sel:
                continue
            ratio = np.array([r["D_over_L"] for r in sel])
            phi = np.array([r["phi_star"] for r in sel]) / math.pi
            ok = np.isfinite(phi)
            said = {tightening.get((r["knot"], r["D_over_L"], r["N"])) for r in sel} - {None}
            where = ("tightening" if said == {side} else "mirror images" if said == {"equal"} else
                     "opening" if said and side not in said and "equal" not in said else "mixed")
            ax.plot(ratio, phi, marker + "-", color=colour, ms=5, lw=1,  # NaN (no end) breaks the line
                    label=f"phi{'+' if side == 'plus' else '-'}* ({'> 0' if side == 'plus' else '< 0'}; {where})")
            err = np.array([r.get("extrapolation_error", math.nan) for r in sel], dtype=float) / math.pi
            ext = np.array([r.get("phi_extrapolated", math.nan) for r in sel], dtype=float) / math.pi
            bar = np.isfinite(err) & np.isfinite(ext) & (err > 0)
            if np.any(bar):
                ax.errorbar(ratio[bar], ext[bar], yerr=err[bar], fmt="_", color=colour, ms=10, capsize=3, lw=1,
                            label=f"phi{'+' if side == 'plus' else '-'}* converged in N, with its error bar")
            snap = np.array([r.get("kind") == "snap" for r in sel])
            if np.any(snap):
                ax.plot(ratio[snap], phi[snap], "x", color="k", ms=9, ls="none",
                        label=None if seen_snap else "snap (jumps to another stable state)")
                seen_snap = True
            if span is not None and np.any(~ok):
                sign = 1.0 if side == "plus" else -1.0
                ax.plot(ratio[~ok], np.full(int((~ok).sum()), sign * span / math.pi), "^" if sign > 0 else "v",
                        color=colour, mfc="none", ms=8, ls="none",
                        label=f"no branch end within {'+' if sign > 0 else '-'}{span / math.pi:g} pi")
        for level, ls, label in ((m, "--", f"Michell +-{m:.2f} pi"), (2 * m, ":", f"2 x Michell +-{2 * m:.2f} pi")):
            ax.axhline(level, color="0.4", ls=ls, lw=0.9, label=label)
            ax.axhline(-level, color="0.4", ls=ls, lw=0.9)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(_KNOT_TITLES.get(knot, knot), fontsize=10)
        ax.set_ylabel("phi* / pi (rad / pi)")
        ax.grid(True, alpha=0.3)
        ax.legend(**_OUTSIDE)
    for ax in list(axes.flat)[len(knots):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("slenderness D / L (-)")
    if title:
        fig.suptitle(title, fontsize=11)
    return finish(fig, path)


def plot_atlas_convergence(series, path=None, title="Atlas: convergence in N"):
    """phi*/pi against 10^4/N^2 (second-order convergence is a straight line), one panel per
    (knot, D/L, side) series: {(knot, D/L, side): [(N, phi* in radians), ...]}."""
    keys = sorted(series)
    if not keys:
        raise ValueError("series: no case ran at several N")
    fig, axes = plt.subplots(1, len(keys), figsize=(3.2 * len(keys), 3.3), squeeze=False)
    for ax, key in zip(axes[0], keys):
        n = np.array([p[0] for p in series[key]], dtype=float)
        phi = np.array([p[1] for p in series[key]]) / math.pi
        ax.plot(1e4 / n ** 2, phi, "o-", color="C0" if key[2] == "plus" else "C3")
        for ni, pi_ in zip(n, phi):
            ax.annotate(f"N = {ni:.0f}", (1e4 / ni ** 2, pi_), textcoords="offset points", xytext=(4, 4), fontsize=7)
        ax.set_xlim(left=0.0)
        ax.set_title(f"{key[0]}, D/L = {key[1]:g}, {key[2]}", fontsize=9)
        ax.set_xlabel("10^4 / N^2")
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("phi* / pi (rad / pi)")
    fig.suptitle(title, fontsize=10)
    return finish(fig, path)


def plot_resolution_convergence(result, path=None, title="Critical twists converged in N"):
    """phi*/pi against 10^4/N^2 for each side of a ``jaxrod.studies.accuracy.converged_critical_twists``
    result ({side: SideConvergence}), with the extrapolated value (at 1/N^2 = 0) and its error bar."""
    sides = list(result)
    if not sides:
        raise ValueError("result: no side")
    fig, axes = plt.subplots(1, len(sides), figsize=(3.8 * len(sides), 3.4), squeeze=False)
    for ax, side in zip(axes[0], sides):
        r = result[side]
        if not r.levels:  # no level found an end: the panel says why
            ax.text(0.5, 0.5, f"no end located:\n{r.reason}", ha="center", va="center", wrap=True, fontsize=7,
                    transform=ax.transAxes)
            ax.set_title(f"{side} (not reached)", fontsize=9)
            continue
        n = np.array([lv.N for lv in r.levels], dtype=float)
        phi = np.array([lv.phi_star for lv in r.levels]) / math.pi
        colour = "C0" if side == "plus" else "C3"
        ax.plot(1e4 / n ** 2, phi, "o-", color=colour, label="levels")
        for ni, v in zip(n, phi):
            ax.annotate(f"N = {ni:.0f}", (1e4 / ni ** 2, v), textcoords="offset points", xytext=(4, 4), fontsize=7)
        if r.extrapolation is not None:
            e = r.extrapolation
            ax.errorbar([0.0], [e.value / math.pi], yerr=[e.error / math.pi], fmt="s", color="k", capsize=3,
                        label=f"extrapolated {e.value / math.pi:+.4f} pi\n+- {e.error / math.pi:.1e} pi "
                              f"(order {e.order:.2f})")
        ax.set_xlim(left=-0.05 * max(1e4 / n.min() ** 2, 1e-9))
        ax.set_title(f"{side} ({'reached' if r.reached else 'not reached'})", fontsize=9)
        ax.set_xlabel("10^4 / N^2")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("phi* / pi (rad / pi)")
    fig.suptitle(title, fontsize=10)
    return finish(fig, path)
