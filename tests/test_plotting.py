"""Figures of jaxrod.io.plotting on small synthetic data: each writes a PNG or returns a Figure."""
import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from jaxrod.io import plotting  # noqa: E402
from jaxrod.model.scenes import trefoil_points  # noqa: E402

CRITICAL = [{"phi": 2.5 * math.pi, "label": "phi+"}, {"phi": -1.5 * math.pi, "label": "phi-"}]


def _table(n=12):
    """Two branches of a fake continuation: a symmetric one over [-3pi, 3pi] (stable inside
    [-1.5pi, 2.5pi]) and a buckled one beyond 2.5pi."""
    phi_s = np.linspace(-3 * math.pi, 3 * math.pi, n)
    phi_b = np.linspace(2.5 * math.pi, 4 * math.pi, n // 2)
    phi = np.concatenate([phi_s, phi_b])
    branch = np.array(["symmetric"] * n + ["buckled+"] * (n // 2))
    stable = np.concatenate([(phi_s > -1.5 * math.pi) & (phi_s < 2.5 * math.pi), np.ones(n // 2, bool)])
    wr = np.concatenate([-3.35 + 0 * phi_s, -3.35 + 0.2 * (phi_b - 2.5 * math.pi)])
    lk = -3 + phi / (2 * math.pi)
    lam0 = np.concatenate([(phi_s + 1.5 * math.pi) * (2.5 * math.pi - phi_s) * 1e-3, 1e-3 * (phi_b - 2.4 * math.pi)])
    return {
        "phi": phi,
        "branch": branch,
        "stable": stable,
        "n_negative": (~stable).astype(int),
        "Wr": wr,
        "Tw": lk - wr,
        "Lk_frames": lk,
        "Lk_gauss": np.round(lk * 4) / 4,
        "energy": phi**2,
        "lambda_0": lam0,
        "lambda_1": lam0 + 1e-2,
        "lambda_10": lam0 + 5e-2,  # columns ordered numerically, not as strings
    }


def _check(path):
    assert path.stat().st_size > 1000
    with open(path, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"


def _returns_figure(fig):
    assert isinstance(fig, Figure)
    plt.close(fig)


def test_plot_bifurcation(tmp_path):
    table = _table()
    path = tmp_path / "bifurcation.png"
    plotting.plot_bifurcation(table, CRITICAL, path=path, title="fake trefoil")
    _check(path)
    fig = plotting.plot_bifurcation(table)
    top, bottom = fig.axes[:2]
    assert bottom.get_yscale() == "symlog"
    assert bottom.get_shared_x_axes().joined(top, bottom)
    _returns_figure(fig)
    # 0/1 stable column, no branch column, string stable flags (as read from a CSV)
    t2 = {k: v for k, v in table.items() if k != "branch"}
    t2["stable"] = table["stable"].astype(int)
    _returns_figure(plotting.plot_bifurcation(t2))
    t2["stable"] = np.where(table["stable"], "True", "False")
    _returns_figure(plotting.plot_bifurcation(t2, CRITICAL))


def test_plot_branch_ends_and_event_marks(tmp_path):
    """A located fold at 2.5 pi with an unstable branch (dashed, no stable row) turning back from it."""
    table = _table()
    phi_u = np.linspace(2.5, 2.3, 5) * math.pi
    t = {k: np.concatenate([np.asarray(v), np.asarray(v)[:5]]) for k, v in table.items()}
    t["phi"][-5:] = phi_u
    t["branch"] = np.concatenate([table["branch"], ["unstable symmetric"] * 5])
    t["stable"] = np.concatenate([table["stable"], [False] * 5])
    t["lambda_0"][-5:] = -1e-3 * (2.5 * math.pi - phi_u)
    events = [{"phi": 2.5 * math.pi, "kind": "fold", "unstable_branch": "unstable symmetric"}]
    path = tmp_path / "branch_ends.png"
    fig = plotting.plot_branch_ends(t, events, path=None)
    ax = fig.axes[0]
    dashed = [line for line in ax.get_lines() if line.get_label() == "unstable symmetric"]
    assert len(dashed) == 1 and dashed[0].get_linestyle() == "--"
    assert ax.get_xlim()[0] < -0.2 < 0.2 < ax.get_xlim()[1]  # the window holds the unstable branch
    plotting.plot_branch_ends(t, events, path=path)
    _check(path)
    with pytest.raises(ValueError, match="no located event"):
        plotting.plot_branch_ends(t, [{"phi": 1.0}])
    # the event marker on the diagram itself: a triangle for a fold, at (phi, Wr)
    fig = plotting.plot_bifurcation(t, [{"phi": 2.5 * math.pi, "label": "fold", "kind": "fold", "Wr": -3.35}])
    marks = [line for line in fig.axes[0].get_lines() if line.get_marker() == "v" and len(line.get_xdata()) == 1
             and line.get_xdata()[0] == 2.5]
    assert len(marks) == 1
    plt.close("all")


def test_plot_bifurcation_rejects_bad_tables():
    table = _table()
    with pytest.raises(ValueError, match="missing column 'Wr'"):
        plotting.plot_bifurcation({k: v for k, v in table.items() if k != "Wr"})
    with pytest.raises(ValueError, match="lambda_0"):
        plotting.plot_bifurcation({k: v for k, v in table.items() if not k.startswith("lambda")})
    with pytest.raises(ValueError, match="'Wr' has 3 entries"):
        plotting.plot_bifurcation({**table, "Wr": np.zeros(3)})
    with pytest.raises(ValueError, match=r"critical\[0\]"):
        plotting.plot_bifurcation(table, [{"phi": 1.0}])
    plt.close("all")


def test_plot_linking(tmp_path):
    table = _table()
    path = tmp_path / "linking.png"
    plotting.plot_linking(table, CRITICAL, path=path)
    _check(path)
    _returns_figure(plotting.plot_linking(table, title="Lk"))
    with pytest.raises(ValueError, match="missing column 'Lk_gauss'"):
        plotting.plot_linking({k: v for k, v in table.items() if k != "Lk_gauss"})


def test_plot_profiles(tmp_path):
    s = np.arange(64) / 64
    profiles = [(20 + 5 * np.cos(6 * np.pi * s), 3 + np.sin(6 * np.pi * s)), (20 + 0 * s, 2 + 0 * s)]
    path = tmp_path / "profiles.png"
    plotting.plot_profiles(s, profiles, ["phi = 2pi", "phi = 0"], path=path, title="trefoil")
    _check(path)
    fig = plotting.plot_profiles(s, profiles[:1], ["a"], ylabel_kappa="kL", ylabel_tau="tL")
    assert fig.axes[0].get_ylabel() == "kL" and fig.axes[1].get_ylabel() == "tL"
    _returns_figure(fig)
    with pytest.raises(ValueError, match="2 profiles but 1 labels"):
        plotting.plot_profiles(s, profiles, ["a"])
    with pytest.raises(ValueError, match=r"profiles\[0\]"):
        plotting.plot_profiles(s, [(s[:10], s[:10])], ["a"])
    plt.close("all")


def _stripe(x, offset=0.2):
    return x + offset * np.array([0.0, 0.0, 1.0])


def test_plot_snapshot(tmp_path):
    x = trefoil_points(60)
    path = tmp_path / "snapshot.png"
    plotting.plot_snapshot(x, _stripe(x), path=path, title="trefoil", unit="mm")
    _check(path)
    fig = plotting.plot_snapshot(x, _stripe(x), unit="mm")
    ax = fig.axes[0]
    assert ax.get_aspect() == 1.0 and ax.get_xlim() == ax.get_ylim()  # equal aspect, square view
    assert ax.get_xlabel() == "e1 (mm)" and ax.get_ylabel() == "e2 (mm)"
    # A tube piece per edge plus the visible stripe pieces, over a silhouette of one per edge.
    silhouette, tube = ax.collections
    assert len(silhouette.get_paths()) == 60 and 60 < len(tube.get_paths()) <= 120
    _returns_figure(fig)
    # The view is along the axis of least spread: for the trefoil, its symmetry axis z.
    frame = plotting.view_frame(x)
    assert abs(abs(frame[2, 2]) - 1.0) < 1e-9 and np.allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    with pytest.raises(ValueError, match="eccentric must have shape"):
        plotting.plot_snapshot(x, x[:, :2])
    with pytest.raises(ValueError, match="node by node"):
        plotting.plot_snapshot(x, x[:10])
    plt.close("all")


def test_plot_snapshots(tmp_path):
    x = trefoil_points(40)
    snaps = [(x * (1 + 0.1 * i), _stripe(x * (1 + 0.1 * i)), f"phi = {i} pi") for i in range(4)]
    path = tmp_path / "snapshots.png"
    plotting.plot_snapshots(snaps, path=path, ncols=3)
    _check(path)
    fig = plotting.plot_snapshots(snaps[:2])
    assert len(fig.axes) == 2 and fig.axes[1].get_title() == "phi = 1 pi"
    fig = plotting.plot_snapshots(snaps, ncols=3)  # 2 x 3 grid, the sixth axis hidden
    assert sum(ax.get_visible() for ax in fig.axes) == 4
    _returns_figure(fig)
    with pytest.raises(ValueError, match="nothing"):
        plotting.plot_snapshots([])
    with pytest.raises(ValueError, match="ncols"):
        plotting.plot_snapshots(snaps, ncols=0)


def test_plot_critical_vs_ratio(tmp_path):
    ratios = np.array([0.05, 0.02, 0.03, 0.04])
    plus = np.array([2.0, 3.1, np.nan, 2.4]) * math.pi
    minus = -np.array([1.1, 1.9, 1.6, 1.3]) * math.pi
    path = tmp_path / "critical.png"
    plotting.plot_critical_vs_ratio(ratios, plus, minus, michell_plus=5.2 * math.pi,
                                    michell_minus=-5.2 * math.pi, path=path)
    _check(path)
    _returns_figure(plotting.plot_critical_vs_ratio(ratios, plus, minus))
    # A ratio without buckling in the searched range is marked at the range's edge, not dropped.
    fig = plotting.plot_critical_vs_ratio(ratios, plus, minus, searched=16 * math.pi)
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert "no buckling within +16 pi" in labels
    _returns_figure(fig)
    with pytest.raises(ValueError, match="equal length"):
        plotting.plot_critical_vs_ratio(ratios, plus[:2], minus)


def test_all_exported():
    for name in ("plot_bifurcation", "plot_linking", "plot_profiles", "plot_snapshot", "plot_snapshots",
                 "plot_critical_vs_ratio"):
        assert name in plotting.__all__ and callable(getattr(plotting, name))


def test_resolution_convergence_draws_a_side_that_found_no_end(tmp_path):
    """A side whose coarsest level found no end gets a panel saying why (it used to raise on the
    empty array of levels, after the study itself had finished)."""
    from jaxrod.studies.accuracy import Level, SideConvergence

    found = SideConvergence("plus", (Level(24, 6.5 * math.pi, 0.01, "fold", 0.0, 0.0),
                                     Level(47, 6.4 * math.pi, 0.01, "fold", 0.0, 0.0)), None, 0.1, False, "N_max")
    none = SideConvergence("minus", (), None, 0.1, False, "at N = 24: no branch end before -14 pi")
    path = tmp_path / "convergence.png"
    plotting.plot_resolution_convergence({"plus": found, "minus": none}, str(path))
    assert path.stat().st_size > 0
    fig = plotting.plot_resolution_convergence({"minus": none})
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert any("no end located" in t and "-14 pi" in t for t in texts)
    assert fig.axes[0].get_title() == "minus (not reached)"
