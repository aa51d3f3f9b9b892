"""Figures (matplotlib). Each function returns its figure, or saves and closes it when given a path.
The backend is left to the caller (inline in notebooks; the CLI selects Agg)."""
from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

__all__ = ["plot_eigenvalue_scan", "plot_mode", "plot_convergence"]


def plot_eigenvalue_scan(scan, critical=None, path=None, n_show=6, title=None):
    """Lowest eigenvalues (zero modes removed) against phi/pi along a scan.

    scan: list of (phi, n_negative, eigenvalues (k,)); critical: optional CriticalPoint.
    """
    phi = np.array([s[0] for s in scan]) / math.pi
    lam = np.array([s[2][:n_show] for s in scan])
    fig, ax = plt.subplots(figsize=(6, 4))
    for j in range(lam.shape[1]):
        ax.plot(phi, lam[:, j], "o-", ms=3, lw=1)
    ax.axhline(0.0, color="k", lw=0.8)
    if critical is not None:
        ax.axvline(critical.phi / math.pi, color="r", ls="--", lw=1,
                   label=f"phi* = {critical.phi / math.pi:.6f} pi")
        ax.legend()
    ax.set_xlabel("imposed twist phi / pi")
    ax.set_ylabel("lowest Hessian eigenvalues (B/l units)")
    ax.set_title(title or "Stability along the twist continuation")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


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
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig


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
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
