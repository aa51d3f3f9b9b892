"""The bifurcation diagram reads without the text: stable pieces solid and unstable ones dashed,
the modes the stability count excludes (|lambda| inside the near-zero band) kept out of the
eigenvalue panel with a note saying so, folds marked, every axis with a unit."""
import json
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jaxrod.io import plotting  # noqa: E402
from jaxrod.studies import twist_figures  # noqa: E402

BAND = 1e-6


def _table():
    """Two branches: 'ring' stable then unstable past 2 pi (a sliding mode at +-1e-7 throughout),
    'upper' unstable then stable."""
    phi = np.concatenate([np.linspace(0.0, 3.0, 13), np.linspace(3.0, 2.0, 9)]) * math.pi
    stable = np.concatenate([phi[:13] < 2.0 * math.pi + 1e-12, phi[13:] < 2.5 * math.pi])
    branch = np.array(["ring"] * 13 + ["upper"] * 9)
    wr = np.concatenate([np.where(phi[:13] < 2 * math.pi, 0.0, 0.2 * (phi[:13] / math.pi - 2)), 0.5 + 0 * phi[13:]])
    lam0 = np.where(stable, 0.3, -0.2) * (1.0 + 0.1 * np.arange(phi.size))
    sliding = 1e-7 * np.where(np.arange(phi.size) % 2 == 0, 1.0, -1.0)  # changes sign step to step
    return {"phi": phi, "Wr": wr, "stable": stable, "branch": branch, "lambda_0": sliding,
            "lambda_1": lam0, "lambda_2": lam0 + 0.5}


def _stable_at(table):
    return {(round(p / math.pi, 12), round(w, 12)): bool(s)
            for p, w, s in zip(table["phi"], table["Wr"], table["stable"])}


def _diagram_lines(ax):
    """The drawn polylines of the diagram: two or more points and a line style other than the
    dotted verticals at the critical twists."""
    return [ln for ln in ax.get_lines() if len(ln.get_xdata()) >= 2 and ln.get_linestyle() not in ("None", "", ":")]


def test_unstable_dashed_stable_solid():
    table = _table()
    fig = plotting.plot_bifurcation(table, [{"phi": 2.5 * math.pi, "label": "fold", "kind": "fold", "Wr": 0.5}],
                                    band=BAND)
    top = fig.axes[0]
    lookup = _stable_at(table)
    lines = _diagram_lines(top)
    assert lines, "no branch lines in the diagram"
    styles = set()
    for ln in lines:
        pts = [lookup[(round(x, 12), round(y, 12))] for x, y in zip(ln.get_xdata(), ln.get_ydata())]
        style = ln.get_linestyle()
        styles.add(style)
        if all(pts):
            assert style == "-", f"a stable piece drawn {style!r}"
        else:
            assert style == "--", f"a piece with unstable states drawn {style!r}"
    assert styles == {"-", "--"}
    legend = [t.get_text() for t in top.get_legend().get_texts()]
    assert {"stable", "unstable", "fold"} <= set(legend)
    assert any(ln.get_marker() == "v" and len(ln.get_xdata()) == 1 for ln in top.get_lines()), "fold not marked"
    plt.close(fig)


def test_excluded_modes_left_out_with_note():
    table = _table()
    fig = plotting.plot_bifurcation(table, band=BAND)
    bottom = fig.axes[1]
    drawn = np.concatenate([np.asarray(ln.get_ydata(), float) for ln in bottom.get_lines()])
    finite = drawn[np.isfinite(drawn)]
    inside = finite[(np.abs(finite) <= BAND) & (finite != 0.0)]  # 0.0: the axis line at lambda = 0
    assert inside.size == 0, f"modes inside the band drawn: {inside[:5]}"
    assert np.any(np.abs(finite) > BAND), "the spectrum that decides stability is missing"
    notes = [t.get_text() for t in bottom.texts]
    assert any("not drawn" in t and "1e-06" in t for t in notes), f"no note on the left-out modes: {notes}"
    plt.close(fig)


def test_every_axis_has_a_unit():
    fig = plotting.plot_bifurcation(_table(), band=BAND)
    top, bottom = fig.axes[:2]
    labels = {"top y": (top.get_ylabel(), "turns"), "bottom y": (bottom.get_ylabel(), "B/l"),
              "x": (bottom.get_xlabel(), "rad")}
    for where, (label, unit) in labels.items():
        assert unit in label and "(" in label, f"{where} axis label {label!r} has no unit"
    plt.close(fig)


def test_study_figure_uses_the_study_band(tmp_path, monkeypatch):
    """branch_figures hands critical.json's negative_tol to the diagram as the band."""
    table = _table()
    cols = list(table)
    with open(tmp_path / "branch.csv", "w") as f:
        f.write(",".join(cols) + "\n")
        for i in range(table["phi"].size):
            f.write(",".join(str(int(table[c][i]) if c == "stable" else table[c][i]) for c in cols) + "\n")
    (tmp_path / "critical.json").write_text(json.dumps({"instabilities": [], "events": [], "negative_tol": BAND}))
    seen = {}
    real = plotting.plot_bifurcation
    monkeypatch.setattr(plotting, "plot_bifurcation", lambda *a, **k: (seen.update(k), real(*a, **k))[1])
    monkeypatch.setattr(plotting, "plot_linking", lambda *a, **k: None)
    twist_figures.branch_figures(str(tmp_path))
    assert seen.get("band") == BAND
