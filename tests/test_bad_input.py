"""Bad input, refused cleanly (issue 8, acceptance 2): every case below, CLI or API, ends in one
clear error naming the flag or parameter to change, never in a traceback or a long computation.

The CLI is run in-process (``jaxrod.cli.main``): exit status 2, one line on stderr that names
the flag (or the file), nothing on stdout. API calls raise ValueError (TypeError for a wrong
type) whose message names the parameter. README links a short version of this table."""
import math

import numpy as np
import pytest

import jaxrod as jr
from jaxrod.measure.analysis import analyze, load_polyline
from jaxrod.cli import main
from jaxrod.studies.twist import twist_study

NAN, INF, PI = math.nan, math.inf, math.pi


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Polylines for the analyze cases: a good pair, and files with each kind of defect."""
    d = tmp_path_factory.mktemp("polylines")
    t = 2 * PI * np.arange(40) / 40
    c = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    e = c * 1.05
    paths = {}
    for name, pts in (("centre.csv", c), ("stripe.csv", e)):
        np.savetxt(d / name, pts, delimiter=",", header="x,y,z", comments="")
        paths[name] = str(d / name)
    (d / "two_columns.csv").write_text("x,y\n" + "\n".join(f"{a},{b}" for a, b, _ in c))
    (d / "not_a_number.csv").write_text("x,y,z\n" + "\n".join(f"{a},{b},{z}" for a, b, z in c) + "\n1,2,abc\n")
    (d / "nan.csv").write_text("x,y,z\n" + "\n".join(f"{a},{b},{z}" for a, b, z in c) + "\nnan,0,0\n")
    (d / "empty.csv").write_text("")
    (d / "points.txt").write_text("1 2 3\n")
    (d / "a_file").write_text("not a folder")
    (d / "other_run").mkdir()
    (d / "other_run" / "run.json").write_text('{"scene": {"name": "another run"}}')
    for name in ("two_columns.csv", "not_a_number.csv", "nan.csv", "empty.csv", "points.txt", "a_file", "other_run"):
        paths[name] = str(d / name)
    paths["missing.csv"] = str(d / "missing.csv")
    return paths


# (argv, the text that must appear in the one-line error). Exit status 2 for all.
CLI_CASES = [
    (["frobnicate"], "invalid choice"),
    (["michell", "--N", "abc"], "--N"),
    (["michell", "--N", "12.5"], "--N"),
    (["michell", "--N", "3"], "--N must be at least 8"),
    (["michell", "--nu", "0.7"], "--nu"),
    (["michell", "--nu", "nan"], "--nu"),
    (["michell", "--slenderness", "0"], "--slenderness"),
    (["michell", "--tol", "-1e-6pi"], "--tol"),
    (["michell", "--tol", "abc"], "--tol"),
    (["michell", "--out", "{a_file}"], "--out"),
    (["michell", "--bogus"], "--bogus"),
    (["trefoil", "--N", "10"], "--N must be at least 24"),
    (["trefoil", "--N", "many"], "--N"),
    (["trefoil", "--N", "61", "--D", "1"], "raise --N to at least L/D = 292"),
    (["trefoil", "--D", "0"], "--D"),
    (["trefoil", "--D", "-8"], "--D"),
    (["trefoil", "--L", "inf"], "--L"),
    (["trefoil", "--D", "20"], "raise --L or lower --D"),
    (["trefoil", "--E", "0"], "--E"),
    (["trefoil", "--nu", "1"], "--nu"),
    (["trefoil", "--contact-stiffness", "-1"], "--contact-stiffness"),
    (["trefoil", "--phi-min", "1pi"], "--phi-min"),
    (["trefoil", "--phi-max", "-2pi"], "--phi-max"),
    (["trefoil", "--phi-max", "nan"], "--phi-max"),
    (["trefoil", "--step", "0"], "--step"),
    (["trefoil", "--tol", "0pi"], "--tol"),
    (["trefoil", "--chirality", "up"], "--chirality"),
    (["trefoil", "--out", "{a_file}"], "--out"),
    (["trefoil", "--N", "61", "--out", "{other_run}"], "--out"),
    (["knot"], "--curve"),
    (["knot", "4_1", "--curve", "{centre.csv}"], "not both"),
    (["knot", "6_1"], "invalid choice"),
    (["knot", "5_2", "--D", "12"], "raise --L or lower --D"),
    (["knot", "--curve", "{missing.csv}"], "missing.csv"),
    (["knot", "--curve", "{two_columns.csv}"], "two_columns.csv"),
    (["knot", "4_1", "--N", "30"], "raise --N to at least L/D = 37"),
    (["atlas", "--knots", "3_1,6_1"], "--knots"),
    (["atlas", "--ratios", "0.5"], "--ratios"),
    (["atlas", "--ratios", "0.01,abc"], "--ratios"),
    (["atlas", "--ratios", "-0.02"], "--ratios"),
    (["atlas", "--N", "61"], "--N"),
    (["atlas", "--N", "twelve"], "--N"),
    (["atlas", "--span", "0"], "--span"),
    (["atlas", "--nu", "0.9"], "--nu"),
    (["atlas", "--workers", "0"], "--workers"),
    (["atlas", "--sides", "up"], "--sides"),
    (["atlas", "--out", "{a_file}"], "--out"),
    (["analyze", "{missing.csv}", "{stripe.csv}"], "missing.csv"),
    (["analyze", "{two_columns.csv}", "{stripe.csv}"], "two_columns.csv"),
    (["analyze", "{not_a_number.csv}", "{stripe.csv}"], "not_a_number.csv"),
    (["analyze", "{nan.csv}", "{stripe.csv}"], "nan.csv"),
    (["analyze", "{empty.csv}", "{stripe.csv}"], "empty.csv"),
    (["analyze", "{points.txt}", "{stripe.csv}"], "points.txt"),
    (["analyze", "{centre.csv}", "{stripe.csv}", "--n-samples", "2"], "--n-samples"),
    (["analyze", "{centre.csv}", "{stripe.csv}", "--smoothing-modes", "0"], "--smoothing-modes"),
    (["analyze", "{centre.csv}", "{stripe.csv}", "--out", "{a_file}"], "--out"),
]


@pytest.mark.parametrize("argv, names", CLI_CASES, ids=[" ".join(a) for a, _ in CLI_CASES])
def test_cli_refuses_bad_input_in_one_line(argv, names, files, capsys):
    def filled(arg):
        for name, path in files.items():
            arg = arg.replace("{" + name + "}", path)
        return arg

    status = main([filled(a) for a in argv])
    out, err = capsys.readouterr()
    assert status == 2, err
    assert "Traceback" not in err + out and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxrod"), err
    assert names in lines[0], lines[0]


def test_cli_without_a_command_prints_usage(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: jaxrod") and "michell" in err and "trefoil" in err and "analyze" in err


MAT = jr.Material.from_engineering(E=1.0, nu=0.5, D=0.1)
CIRCLE = np.stack([np.cos(np.linspace(0, 2 * PI, 30, endpoint=False)),
                   np.sin(np.linspace(0, 2 * PI, 30, endpoint=False)), np.zeros(30)], axis=1)
_S = np.linspace(0, 2 * PI, 60, endpoint=False)
FIGURE_EIGHT_IN_A_PLANE = np.stack([np.sin(_S), np.sin(_S) * np.cos(_S), 0 * _S], axis=1)  # crosses itself


def _knot():
    # the trefoil of issue 17's report: critical_twist returned a sliding mode at 2.5411 pi there
    return jr.trefoil(D=8.0, L=292.0, N=61)


def _ring():
    return jr.ring(N=16, material=MAT)


# (call, exception, the parameter named in the message)
API_CASES = [
    ("ring N='abc'", lambda: jr.ring(N="abc", material=MAT), ValueError, "N must be an integer"),
    ("ring N=None", lambda: jr.ring(N=None, material=MAT), ValueError, "N must be an integer"),
    ("ring N=nan", lambda: jr.ring(N=NAN, material=MAT), ValueError, "N must be an integer"),
    ("ring N=2", lambda: jr.ring(N=2, material=MAT), ValueError, "N must be at least"),
    ("ring radius=0", lambda: jr.ring(N=16, material=MAT, radius=0.0), ValueError, "radius"),
    ("ring material", lambda: jr.ring(N=16, material="steel"), TypeError, "material"),
    ("E<0", lambda: jr.Material.from_engineering(E=-1.0, nu=0.5, D=8.0), ValueError, "E"),
    ("nu>0.5", lambda: jr.Material.from_engineering(E=1.0, nu=0.6, D=8.0), ValueError, "nu"),
    ("B=0", lambda: jr.Material(B=0.0, C=1.0, EA=1.0), ValueError, "B"),
    ("trefoil N=10", lambda: jr.trefoil(D=8.0, L=292.0, N=10), ValueError, "N must be at least 24"),
    ("trefoil too tight", lambda: jr.trefoil(D=8.0, L=100.0, N=61), ValueError, "L/D"),
    ("trefoil N<L/D", lambda: jr.trefoil(D=1.0, L=292.0, N=61), ValueError, "N >= L/D = 292"),
    ("trefoil D=nan", lambda: jr.trefoil(D=NAN, L=292.0, N=61), ValueError, "D must be finite"),
    ("trefoil chirality", lambda: jr.trefoil(D=8.0, L=292.0, N=61, chirality="up"), ValueError, "chirality"),
    ("torus knot not coprime", lambda: jr.torus_knot(2, 4, D=1.0, L=100.0, N=120), ValueError, "coprime"),
    ("clamped length=0", lambda: jr.clamped_rod(N=41, length=0.0, material=MAT), ValueError, "length"),
    ("clamped length=inf", lambda: jr.clamped_rod(N=41, length=INF, material=MAT), ValueError, "length"),
    ("clamped N=3", lambda: jr.clamped_rod(N=3, length=10.0, material=MAT), ValueError, "N"),
    ("curve with nan", lambda: jr.closed_curve(np.where(CIRCLE == CIRCLE[3, 0], NAN, CIRCLE), material=MAT), ValueError,
     "points"),
    ("curve of one point", lambda: jr.closed_curve(np.ones((30, 3)), material=MAT), ValueError, "points"),
    ("curve through itself", lambda: jr.closed_curve(FIGURE_EIGHT_IN_A_PLANE, material=MAT), ValueError,
     "passes through itself"),
    ("curve in 2D", lambda: jr.closed_curve(CIRCLE[:, :2], material=MAT), ValueError, "points"),
    ("phi=nan", lambda: jr.solve_equilibrium(_ring(), phi=NAN), ValueError, "phi"),
    ("q0 shape", lambda: jr.solve_equilibrium(_ring(), q0=np.zeros(3)), ValueError, "q0"),
    ("method", lambda: jr.EquilibriumOptions(method="bfgs"), ValueError, "method"),
    ("phi_stop = phi_start", lambda: jr.critical_twist(_ring(), 1.0, 1.0), ValueError, "phi_stop"),
    ("critical tol<0", lambda: jr.critical_twist(_ring(), 0.0, 10.0, jr.ContinuationOptions(tol=-1.0)), ValueError, "tol"),
    ("critical_twist on a knot", lambda: jr.critical_twist(_knot(), 0.0, 7.5 * math.pi), ValueError,
     "critical_twist does not handle knots"),
    ("critical_twist_derivative on a knot", lambda: jr.critical_twist_derivative(_knot(), None, "C"), ValueError,
     "critical_twist_derivative does not handle knots"),
    ("follow step=0", lambda: jr.follow_twist(_ring(), 0.0, 1.0, jr.ContinuationOptions(step=0.0)), ValueError, "step"),
    ("options k=0", lambda: jr.ContinuationOptions(k=0).resolved(_ring(), "follow_twist", 1.0), ValueError, "k"),
    ("study phi_min>0", lambda: twist_study(_ring(), 1.0, 2.0), ValueError, "phi_min"),
    ("analyze n_samples", lambda: analyze(CIRCLE, CIRCLE * 1.1, n_samples=2), ValueError, "n_samples"),
]


@pytest.mark.parametrize("call, error, names", [c[1:] for c in API_CASES], ids=[c[0] for c in API_CASES])
def test_api_refuses_bad_input_naming_the_parameter(call, error, names):
    with pytest.raises(error) as info:
        call()
    assert names in str(info.value), str(info.value)


@pytest.mark.parametrize("name, piece", [("two_columns.csv", "z"), ("empty.csv", "empty.csv"),
                                         ("not_a_number.csv", "abc"), ("points.txt", "extension")])
def test_load_polyline_names_the_file_and_the_problem(files, name, piece):
    with pytest.raises(ValueError) as info:
        load_polyline(files[name])
    assert name in str(info.value) and piece in str(info.value), str(info.value)


def test_a_nearly_tight_knot_warns():
    with pytest.warns(UserWarning, match="nearly tight"):
        jr.trefoil(D=8.0, L=140.0, N=61)
