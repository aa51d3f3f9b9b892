"""``jaxrod analyze`` on jaxrod's own output (issue 16, defects 5 and 6).

Defect 5: ``analyze`` refused a study's step files (``steps/*.npz``: "unknown file extension").
It now reads their ``x`` and ``eccentric`` arrays (and the imposed twist ``phi``).

Defect 6: at a non-whole number of turns the line drawn on a closed rod does not close: its ends
were turned by phi before gluing, so it jumps by -phi (mod 2 pi) at the joint. ``analyze`` took
the jump for an ordinary step: on a right-handed trefoil (Lk0 = 3) at 6.5 pi and 7 pi it returned
Lk = 6 (true 6.25, 6.5), a Tw short by that fractional turn, a Gauss "linking number" 6 of a line
that does not close, a tau L spike at the joint, and no warning. It now warns (without
``joint_twist``), or accounts for the jump (with it); ``step_record`` writes Lk_gauss as NaN at
non-whole turns.

The states: jaxrod's trefoil (D, L) = (8, 292), N = 61 (as elsewhere in the tests: compiled code
shared), relaxed at 6 pi, 6.5 pi and 7 pi (one module fixture, 15-30 s, mostly compilation); all
three are on the symmetric branch (phi*_+ ~ 11.6 pi).
"""
import json
import math
import os

import numpy as np
import pytest

import jaxrod
from jaxrod.measure import analysis
from jaxrod.measure.analysis import analyze, load_polyline
from jaxrod.io.atomic import savez
from jaxrod.io.records import step_record
from helpers import analyze_checked

PI = math.pi
TURNS = (6.0, 6.5, 7.0)  # phi / pi


@pytest.fixture(scope="module")
def states():
    """{phi/pi: (row, extra, phi, q)} of the trefoil relaxed at 6 pi, 6.5 pi, 7 pi."""
    scene = jaxrod.trefoil(D=8, L=292, N=61)
    out, q = {}, None
    for k in TURNS:
        eq = jaxrod.relax(scene, k * PI, q, jaxrod.RelaxOptions(with_stability=False))
        q = eq.q
        row, extra = step_record(scene, eq, branch="symmetric")
        out[k] = (row, extra, float(eq.phi), np.asarray(eq.q))
    return out


_analyze = analyze_checked  # the warnings it issues are the ones it returns


def _step_file(folder, states, k, name="plus_0001.npz"):
    """A step file as twist_study writes it (study.py, save_point)."""
    row, extra, phi, q = states[k]
    path = folder / "steps" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    savez(str(path), q=q, phi=phi, branch=row["branch"], **extra)
    return path


# ---------------------------------------------------------------------------- defect 5: step files
def test_load_polyline_reads_the_arrays_of_a_step_file(tmp_path, states):
    path = _step_file(tmp_path, states, 6.5)
    _, extra, phi, _ = states[6.5]
    assert np.array_equal(load_polyline(path), extra["x"])  # array="x" by default
    assert np.array_equal(load_polyline(path, array="eccentric"), extra["eccentric"])
    assert analysis.load_joint_twist(path) == phi
    assert analysis.load_joint_twist(tmp_path / "elsewhere.csv") is None  # not a step file: no twist known
    # An .npz without the array asked for: one line naming the file and the array.
    bare = tmp_path / "centre_only.npz"
    np.savez(bare, x=extra["x"])
    with pytest.raises(ValueError, match=r"centre_only\.npz: no array 'eccentric' in this \.npz \(it holds x\)"):
        load_polyline(bare, array="eccentric")
    assert analysis.load_joint_twist(bare) is None


def test_cli_analyzes_a_step_file_alone(tmp_path, states, capsys):
    from jaxrod.cli import main

    path = _step_file(tmp_path, states, 7.0)
    row, extra, phi, _ = states[7.0]
    out = tmp_path / "analysis"
    assert main(["analyze", str(path), "--json", "--quiet", "--out", str(out)]) == 0
    res = json.loads(capsys.readouterr().out)
    # The step's own phi is the joint's twist: Lk = 3 + 7pi/2pi = 6.5, Tw = Lk - Wr as the
    # simulation's frames have it, no Gauss linking number (the line does not close), no warning.
    assert res["joint_twist"] == phi
    assert res["Lk_frames"] == pytest.approx(6.5, abs=1e-6)
    assert res["Tw"] == pytest.approx(row["Tw"], abs=1e-3)
    assert res["Lk_gauss"] is None and res["Lk_quadrature"] is None
    assert res["joint_jump"] == pytest.approx(-0.5, abs=0.01)
    assert res["warnings"] == []
    assert res["centreline"] == res["eccentric"] == os.path.abspath(path)
    assert json.loads((out / "summary.json").read_text())["Lk_frames"] == res["Lk_frames"]
    assert (out / "profiles.png").stat().st_size > 0
    # The same file given twice: the same answer; the text summary says why Lk (Gauss) is missing.
    assert main(["analyze", str(path), str(path)]) == 0
    text = capsys.readouterr().out
    assert "Lk (frames)   = 6.5000000000" in text and "does not close at the joint" in text


def test_cli_step_file_errors(tmp_path, states, capsys):
    from jaxrod.cli import main

    _, extra, _, _ = states[6.0]
    bare = tmp_path / "centre_only.npz"
    np.savez(bare, x=extra["x"])
    assert main(["analyze", str(bare)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jaxrod: error: ") and "no array 'eccentric'" in err[0], err
    centre = tmp_path / "centre.npy"
    np.save(centre, extra["x"])
    assert main(["analyze", str(centre)]) == 2  # a CSV/NPY centreline needs its eccentric line
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "give the eccentric line too" in err[0] and "centre.npy" in err[0], err
    path = _step_file(tmp_path, states, 6.0)
    assert main(["analyze", str(path), "--open", "--joint-twist", "pi"]) == 2  # no joint on an open rod
    err = capsys.readouterr().err
    assert "--joint-twist applies to closed rods only" in err


# ---------------------------------------------------------------------------- defect 6: the joint
@pytest.mark.parametrize("k, jump", [(6.5, -0.25), (7.0, -0.5)])
def test_a_line_that_does_not_close_is_flagged(states, k, jump):
    _, extra, _, _ = states[k]
    res = _analyze(extra["x"], extra["eccentric"])
    assert len(res.warnings) == 1
    assert "the line does not close onto itself" in res.warnings[0] and "joint_twist=" in res.warnings[0]
    assert f"{jump:+.2f}" in res.warnings[0]  # e.g. "jumps by -0.2530 turns"
    assert res.joint_jump == pytest.approx(jump, abs=0.01)
    # No linking number of a line that does not close (today's code: the rounded integer 6).
    assert math.isnan(res.Lk_exact) and math.isnan(res.Lk_quadrature)
    # Without the joint's twist the frames still miss the fractional turn: Wr + Tw is an integer.
    assert res.Lk_frames == pytest.approx(6.0, abs=1e-8)


@pytest.mark.parametrize("k", [6.5, 7.0])
def test_joint_twist_gives_lk_tw_and_tau_without_spike(states, k):
    row, extra, phi, _ = states[k]
    lk = 3.0 + phi / (2 * PI)  # 6.25, 6.5
    raw = _analyze(extra["x"], extra["eccentric"], n_samples=200)
    res = _analyze(extra["x"], extra["eccentric"], joint_twist=phi)
    assert res.warnings == ()
    assert res.Lk_frames == pytest.approx(lk, abs=1e-3) and row["Lk_frames"] == pytest.approx(lk, abs=1e-8)
    assert res.Tw == pytest.approx(res.Lk_frames - res.Wr, abs=1e-12)
    assert res.Tw == pytest.approx(row["Tw"], abs=1e-3)  # the simulation's frames (measured: 2e-5)
    assert math.isnan(res.Lk_exact)
    # tau L: the simulation's is uniform on this branch (to ~1.5%); today's analysis spiked to
    # -42 (6.5 pi) and -91 (7 pi) at the joint (n_samples = 200). With the joint's twist the spike
    # is gone: within 3% of the simulation's mean everywhere (measured: 0.9%, 1.7%).
    fine = _analyze(extra["x"], extra["eccentric"], n_samples=200, joint_twist=phi)
    assert fine.warnings == ()
    tau_sim = float(np.mean(extra["tau_L"]))
    assert np.min(raw.tau * raw.length) < 0.0  # the spike, without joint_twist
    assert np.max(np.abs(fine.tau * fine.length - tau_sim)) < 0.03 * tau_sim
    assert fine.Tw_integral == pytest.approx(fine.Tw, abs=0.02)  # measured 0.006 at both
    assert fine.Lk_frames == pytest.approx(lk, abs=1e-3)


def test_whole_turns_unchanged_and_a_wrong_joint_twist_is_flagged(states):
    _, extra, phi, _ = states[6.0]
    plain = _analyze(extra["x"], extra["eccentric"])
    assert plain.warnings == () and plain.joint_jump == 0.0
    assert plain.Lk_exact == pytest.approx(6.0, abs=1e-9) and plain.Lk_frames == pytest.approx(6.0, abs=1e-8)
    # A whole turn at the joint changes nothing: the line closes.
    given = _analyze(extra["x"], extra["eccentric"], joint_twist=phi)
    assert given.warnings == () and given.Tw == plain.Tw and np.array_equal(given.tau, plain.tau)
    assert given.Lk_exact == plain.Lk_exact
    # A joint_twist the line contradicts (a quarter turn it does not show) is said.
    wrong = _analyze(extra["x"], extra["eccentric"], joint_twist=6.5 * PI)
    assert len(wrong.warnings) == 1 and "does not match the line, which closes smoothly" in wrong.warnings[0]
    _, extra7, _, _ = states[7.0]
    wrong = _analyze(extra7["x"], extra7["eccentric"], joint_twist=6.5 * PI)
    assert len(wrong.warnings) == 1 and "does not match the line, which jumps by -0.50" in wrong.warnings[0]
    with pytest.raises(ValueError, match="joint_twist applies to closed rods only"):
        analyze(extra["x"], extra["eccentric"], closed=False, joint_twist=phi)
    with pytest.raises(ValueError, match="joint_twist must be a finite number"):
        analyze(extra["x"], extra["eccentric"], joint_twist=float("nan"))


def test_step_record_lk_gauss_only_at_whole_turns(states, tmp_path):
    whole, quarter, half = (states[k][0] for k in TURNS)
    assert whole["Lk_gauss"] == pytest.approx(6.0, abs=1e-8) == whole["Lk_frames"]
    # Today's code: 6.0 at both (the rounded linking number of a line that does not close).
    assert math.isnan(quarter["Lk_gauss"]) and math.isnan(half["Lk_gauss"])
    assert quarter["Lk_frames"] == pytest.approx(6.25, abs=1e-8) and half["Lk_frames"] == pytest.approx(6.5, abs=1e-8)
    # branch.csv: an empty (or nan) Lk_gauss cell reads back as NaN; the linking figure plots
    # Lk_gauss at whole turns only and copes with the NaN.
    from jaxrod.io import plotting
    from jaxrod.studies.twist import read_table

    csv_path = tmp_path / "branch.csv"
    csv_path.write_text("branch,phi,Lk_frames,Lk_gauss,Wr,Tw\n" + "".join(
        f"{r['branch']},{r['phi']!r},{r['Lk_frames']!r},{'' if math.isnan(r['Lk_gauss']) else repr(r['Lk_gauss'])},"
        f"{r['Wr']!r},{r['Tw']!r}\n" for r in (whole, quarter, half)))
    table = read_table(csv_path)
    assert table["Lk_gauss"][0] == pytest.approx(6.0) and np.isnan(table["Lk_gauss"][1:]).all()
    import matplotlib

    matplotlib.use("Agg")
    plotting.plot_linking(table, path=str(tmp_path / "linking.png"))
    assert (tmp_path / "linking.png").stat().st_size > 0
