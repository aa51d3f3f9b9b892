"""The files of a solved helix (``run_helix``): helix.json, centreline.csv, envelope.csv,
centreline.png, envelope.png and, with a sweep, path.csv and loads.png. Lengths in units of the
rod's length L = 1, angles in rad."""
from __future__ import annotations

import csv
import json
import os


def write_helix_files(run, out):
    """Writes helix.json, centreline.csv, envelope.csv, centreline.png, envelope.png and, with a
    sweep, path.csv and loads.png of the ``HelixRun`` ``run`` into the folder out; returns their
    names."""
    from ...io import plotting  # noqa: F401  (matplotlib's style)

    case, result, profiles = run.case, run.result, run.profiles
    with open(os.path.join(out, "helix.json"), "w") as f:
        json.dump(result, f, indent=2)
    p = profiles
    _write_helix_csv(os.path.join(out, "centreline.csv"), ["s_over_L", "x", "y", "z", "x_analytic", "y_analytic",
                                                          "z_analytic"],
                     ([p.s_node[k], *p.x[k], *p.r[k]] for k in range(case.N)))
    _write_helix_csv(os.path.join(out, "envelope.csv"), ["s_over_L", "theta", "theta_analytic"],
                     ([p.s_edge[k], p.theta[k], p.theta_analytic[k]] for k in range(p.theta.size)))
    title = f"m = {result['m_analytic']:.4g}, t = {result['t_analytic']:.4g}, gamma = {case.gamma:.3g}, N = {case.N}"
    _plot_helix_centreline(os.path.join(out, "centreline.png"), profiles, title, result["reference_valid"])
    _plot_helix_envelope(os.path.join(out, "envelope.png"), profiles, title, result["envelope_L1"])
    written = ["helix.json", "centreline.csv", "envelope.csv", "centreline.png", "envelope.png"]
    path = result["path"]
    if path:
        keys = list(path[0])
        _write_helix_csv(os.path.join(out, "path.csv"), keys,
                         (["" if row[k] is None else row[k] for k in keys] for row in path))
        _plot_helix_loads(os.path.join(out, "loads.png"), path, result["d"], case)
        written += ["path.csv", "loads.png"]
    return written


def _write_helix_csv(file, header, rows):
    """A CSV file of a header and rows."""
    with open(file, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for row in rows:
            w.writerow(row)


def _plot_helix_centreline(file, profiles, title, valid):
    """The computed centreline beside the analytic one, in 3-D."""
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="3d")
    ax.plot(*profiles.r.T, "k--", lw=1, label="analytic (NvdHT 2002)" if valid else "analytic (not applicable)")
    ax.plot(*profiles.x.T, "C0", lw=2, label="jaxrod")
    ax.set_title(title)
    ax.legend()
    fig.savefig(file, dpi=120)
    plt.close(fig)


def _plot_helix_envelope(file, profiles, title, envelope_L1):
    """The edges' tangent angle beside the analytic one (envelope_L1 None: the reference does not apply)."""
    import matplotlib.pyplot as plt

    valid = envelope_L1 is not None
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(profiles.s_edge, profiles.theta_analytic, "k--", lw=1,
            label="analytic" if valid else "analytic (not applicable)")
    ax.plot(profiles.s_edge, profiles.theta, "C0.", ms=3, label="jaxrod (edges)")
    ax.set_xlabel("s / L (from the middle)")
    ax.set_ylabel("tangent angle to the axis theta (rad)")
    ax.set_title(f"{title}: L1 error {envelope_L1:.2e}" if valid else
                 f"{title}: the analytic reference does not apply")
    ax.legend()
    fig.tight_layout()
    fig.savefig(file, dpi=120)
    plt.close(fig)


def _plot_helix_loads(file, path, d, case):
    """M and T along the sweep's path, stable and unstable states apart, beside the analytic ones."""
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    R_ = np.array([p["R"] for p in path])
    st = np.array([p["stable"] for p in path])
    for ax, key, label in ((axes[0], "m", "M L / B"), (axes[1], "t", "T L^2 / B")):
        v = np.array([p[key] for p in path])
        va = np.array([np.nan if p[key + "_analytic"] is None else p[key + "_analytic"] for p in path])
        ax.plot(R_, va, "k--", lw=1, label="analytic")
        ax.plot(R_[st], v[st], "C0o", label="jaxrod, stable")
        ax.plot(R_[~st], v[~st], "C3o", mfc="none", label="jaxrod, unstable")
        ax.set_ylabel(label)
    axes[0].legend()
    axes[1].set_xlabel(f"end rotation R (rad), d = {d:.4g}")
    axes[0].set_title(f"gamma = {case.gamma:.3g}, N = {case.N} (stability under fixed ends)")
    fig.tight_layout()
    fig.savefig(file, dpi=120)
    plt.close(fig)
