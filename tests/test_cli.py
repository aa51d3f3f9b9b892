"""Acceptance 5 and 6: the CLI as a user runs it (installed console script)."""
import json
import math
import os
import shutil
import subprocess
import sys

import pytest

EXE = shutil.which("jaxrod") or os.path.join(os.path.dirname(sys.executable), "jaxrod")


def run(*args, timeout=600):
    return subprocess.run([EXE, *args], capture_output=True, text=True, timeout=timeout)


def test_michell_json_N128(tmp_path):
    r = run("michell", "--N", "128", "--nu", "0.5", "--json", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    for key in ("phi_star", "phi_star_analytic", "rel_error", "N", "nu", "seconds"):
        assert key in out
    assert out["N"] == 128 and out["nu"] == 0.5
    assert out["phi_star_analytic"] == pytest.approx(2 * math.pi * math.sqrt(3) * 1.5, rel=1e-15)
    assert 0 < out["rel_error"] < 2e-3
    assert out["rel_error"] == pytest.approx((out["phi_star"] - out["phi_star_analytic"]) / out["phi_star_analytic"])
    assert "phi =" in r.stderr  # progress
    for name in ("michell.json", "scan.csv", "eigenvalues.png", "critical_mode.png"):
        assert (tmp_path / name).stat().st_size > 0
    import matplotlib.image

    for name in ("eigenvalues.png", "critical_mode.png"):
        image = matplotlib.image.imread(tmp_path / name)
        assert image.ndim == 3 and min(image.shape[:2]) > 300 and image[..., :3].std() > 0.05, name
    assert "compiling" in r.stderr or "compiled code cached" in r.stderr  # the line before the compile


# ---------------------------------------------------------------------------- jaxrod analyze
def _trefoil_files(tmp_path, n=160, offset=0.1):
    """A trefoil centreline (CSV with header) and an eccentric line (NPY) offset along the Frenet
    normal, at other points than the centreline (a shifted parameter, another count)."""
    import numpy as np

    from jaxrod.model.scenes import trefoil_points

    def curve(t):
        return np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), np.sin(3 * t)], axis=1)

    def d1(t):
        return np.stack([np.cos(t) + 4 * np.cos(2 * t), -np.sin(t) + 4 * np.sin(2 * t), 3 * np.cos(3 * t)], axis=1)

    def d2(t):
        return np.stack([-np.sin(t) - 8 * np.sin(2 * t), -np.cos(t) + 8 * np.cos(2 * t), -9 * np.sin(3 * t)], axis=1)

    x = trefoil_points(n)
    assert np.allclose(x, curve(2 * np.pi * np.arange(n) / n))  # the same (right-handed) trefoil
    m = 131
    t = 2 * np.pi * (np.arange(m) + 0.3) / m
    tan = d1(t) / np.linalg.norm(d1(t), axis=1, keepdims=True)
    nrm = d2(t) - np.sum(d2(t) * tan, axis=1, keepdims=True) * tan
    ecc = curve(t) + offset * nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    centre_path = tmp_path / "centreline.csv"
    with open(centre_path, "w") as fh:
        fh.write("x,y,z\n" + "".join(f"{a:.17g},{b:.17g},{c:.17g}\n" for a, b, c in x))
    ecc_path = tmp_path / "stripe.npy"
    np.save(ecc_path, ecc)
    return centre_path, ecc_path


ANALYZE_KEYS = ("Wr", "Tw", "Lk_frames", "Lk_gauss", "Lk_quadrature", "length", "symmetry_order", "n_peaks",
                "n_samples")


def test_analyze_json_and_files(tmp_path, capsys):
    from jaxrod.cli import main

    centre, ecc = _trefoil_files(tmp_path)
    out = tmp_path / "out"
    code = main(["analyze", str(centre), str(ecc), "--n-samples", "200", "--out", str(out), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    res = json.loads(captured.out)
    for key in ANALYZE_KEYS:
        assert key in res, key
    assert res["n_samples"] == 200
    assert res["Lk_gauss"] == round(res["Lk_gauss"])  # exact linking number: an integer
    assert abs(res["Lk_gauss"]) >= 1
    assert res["Lk_frames"] == pytest.approx(res["Lk_gauss"], abs=1e-6)
    assert res["Lk_quadrature"] == pytest.approx(res["Lk_gauss"], abs=0.05)
    assert res["Wr"] == pytest.approx(3.35, abs=0.02)  # right-handed trefoil
    assert res["symmetry_order"] == 3
    assert res["n_peaks"] == 6  # two curvature maxima per lobe in this parametrisation
    assert res["length"] > 0
    for name in ("profiles.csv", "summary.json", "profiles.png"):
        assert (out / name).stat().st_size > 0
    import matplotlib.image

    image = matplotlib.image.imread(out / "profiles.png")
    assert image.ndim == 3 and min(image.shape[:2]) > 300 and image[..., :3].std() > 0.05
    assert res["warnings"] == []  # clean synthetic data: nothing to warn about
    assert json.loads((out / "summary.json").read_text())["Lk_gauss"] == res["Lk_gauss"]
    lines = (out / "profiles.csv").read_text().splitlines()
    assert lines[0] == "s,kappa1,kappa2,tau,kappa" and len(lines) == 201
    assert "wrote" in captured.err


def test_analyze_text_summary_and_open_curves(tmp_path, capsys):
    from jaxrod.cli import main

    centre, ecc = _trefoil_files(tmp_path, n=120)
    assert main(["analyze", str(centre), str(ecc), "--smoothing-modes", "12"]) == 0
    text = capsys.readouterr().out
    for word in ("Wr", "Tw", "Lk (frames)", "Lk (Gauss)", "length", "symmetry order 3"):
        assert word in text, text
    # Open curves: no linking number (null in JSON), no symmetry order.
    assert main(["analyze", str(centre), str(ecc), "--open", "--json", "--quiet"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["Lk_gauss"] is None and res["symmetry_order"] is None and res["closed"] is False


def _one_line_error(capsys):
    err = capsys.readouterr().err
    lines = [line for line in err.strip().splitlines() if line]
    assert len(lines) == 1, err
    assert lines[0].startswith("jaxrod: error:")
    return lines[0]


def test_analyze_bad_input_exits_2_with_one_line(tmp_path, capsys):
    from jaxrod.cli import main

    centre, ecc = _trefoil_files(tmp_path, n=40)
    missing = tmp_path / "nowhere.csv"
    assert main(["analyze", str(missing), str(ecc)]) == 2
    line = _one_line_error(capsys)
    assert "nowhere.csv" in line and "No such file" in line
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,w\n" + "1,2,3\n" * 5)
    assert main(["analyze", str(centre), str(bad)]) == 2
    assert "missing column(s) z" in _one_line_error(capsys)
    text = tmp_path / "text.csv"
    text.write_text("x,y,z\n0,0,0\n1,0,0\n1,one,0\n0,1,0\n")
    assert main(["analyze", str(text), str(ecc)]) == 2
    assert "'one' is not a number" in _one_line_error(capsys)
    assert main(["analyze", str(centre), str(ecc), "--smoothing-modes", "500"]) == 2
    assert "--smoothing-modes" in _one_line_error(capsys)
    assert main(["analyze", str(centre), str(ecc), "--n-samples", "many"]) == 2  # argparse: not an integer
    assert "--n-samples" in _one_line_error(capsys)


# ------------------------------------------------------------------ jaxrod trefoil
from jaxrod.cli import main  # noqa: E402
def test_trefoil_study_json_files_and_resume(tmp_path, capsys):
    out = tmp_path / "tref"
    args = ["trefoil", "--N", "61", "--phi-min", "-1pi", "--phi-max", "1pi", "--step", "0.5pi",
            "--out", str(out), "--vtk", "--json", "--quiet"]
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out)
    for key in ("phi_plus", "phi_minus", "seconds", "tightening_side", "steps", "N", "D", "L"):
        assert key in summary
    # Nothing buckles within one half-turn either way; both sides were covered.
    assert summary["phi_plus"] is None and summary["phi_minus"] is None
    assert summary["steps"] == 6
    # the corrector's iterations per accepted point, per direction, are those of branch.csv
    import csv

    with open(out / "branch.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for direction, count in summary["corrector_iterations"].items():
        mine = [int(float(r["iterations"])) for r in rows if r["direction"] == direction]
        assert count["points"] == len(mine) and count["iterations"] == sum(mine)
        assert count["per_point"] == pytest.approx(sum(mine) / len(mine), abs=0.005)
    assert set(summary["corrector_iterations"]) == {"plus", "minus"}
    for name in ("branch.csv", "critical.json", "run.json", "summary.json"):
        assert (out / name).stat().st_size > 0, name
    # Every figure opens as an image with something drawn on it.
    import matplotlib.image

    for name in ("bifurcation.png", "linking.png", "profiles.png", "snapshots.png"):
        image = matplotlib.image.imread(out / name)
        assert image.ndim == 3 and min(image.shape[:2]) > 300 and image[..., :3].std() > 0.05, name
    # One VTK file per step (ParaView), each with the centreline and the stripe.
    vtk = sorted(os.listdir(out / "vtk"))
    assert len(vtk) == 6 and "LINES 2 " in (out / "vtk" / vtk[0]).read_text()
    header = (out / "branch.csv").read_text().splitlines()[0].split(",")
    for column in ("phi", "E_bend", "E_twist", "E_contact", "Wr", "Tw", "Lk_frames", "Lk_gauss", "n_negative",
                   "stable", "contact_count", "symmetry_order", "lambda_0"):
        assert column in header
    # Issue 16, defect 6: the Gauss linking number of the drawn line exists only at whole turns
    # (the line jumps at the joint otherwise): an empty cell there, not a rounded integer.
    import csv

    with open(out / "branch.csv", newline="") as f:
        cells = {float(r["phi"]): r["Lk_gauss"] for r in csv.DictReader(f)}
    assert abs(float(cells[0.0]) - 3.0) < 1e-9 and all(cells[p] == "" for p in cells if p != 0.0), cells
    crit = json.loads((out / "critical.json").read_text())
    assert crit["phi_plus"] is None and sorted(crit["finished"]) == ["minus", "plus"]
    # Run again: everything is on file, nothing is recomputed, same answer.
    assert main(args[:-1]) == 0
    text = capsys.readouterr()
    assert "phi_plus" in text.out and "already finished" in text.err


@pytest.mark.parametrize(
    "exc, code, words",
    [
        ("no_crossing", 1, "widen it (--phi-min / --phi-max)"),
        ("convergence", 1, "raise --N"),
        ("interrupt", 130, "resumes"),
    ],
)
def test_failed_computation_is_one_line_with_advice(monkeypatch, capsys, tmp_path, exc, code, words):
    # Issue 8, defect 3: a computation that fails (no crossing in range, no equilibrium) or is
    # interrupted ends in one line that says what to do, not a traceback.
    import jaxrod.cli.trefoil as trefoil_command
    from jaxrod import NoCrossingError
    from jaxrod.solve.solvers import ConvergenceError

    errors = {"no_crossing": NoCrossingError("negative count stayed 0 from phi = +0.000000 pi to +6.366198 pi"),
              "convergence": ConvergenceError("relaxation did not converge: Solution(...)\nmore"),
              "interrupt": KeyboardInterrupt()}

    def fail(args):
        raise errors[exc]

    monkeypatch.setattr(trefoil_command, "run", fail)
    assert main(["trefoil", "--out", str(tmp_path / "t")]) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jaxrod: ") and words in err[0], err


def test_progress_bar_on_a_terminal_shows_twist_steps_and_eta(monkeypatch):
    # On a terminal the CLI shows a tqdm bar (twist reached, elapsed < remaining, steps) with the
    # progress lines written above it; off a terminal (CI, logs, pipes) only the lines.
    import io
    import types

    import jaxrod.cli as cli

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    screen = Terminal()
    monkeypatch.setattr(sys, "stderr", screen)
    bar = cli.Progress(types.SimpleNamespace(quiet=False), 4.0, "trefoil")
    bar.say("relaxing the knot at phi = 0")
    bar.update(1.5, steps=3, branch="symmetric+")
    bar.close()
    text = screen.getvalue()
    assert "relaxing the knot at phi = 0" in text
    assert "phi 1.50/4.00 pi" in text and "<" in text and "steps=3" in text
    piped = io.StringIO()
    monkeypatch.setattr(sys, "stderr", piped)
    bar = cli.Progress(types.SimpleNamespace(quiet=False), 4.0, "trefoil")
    bar.say("a line")
    bar.update(1.0, steps=1)
    bar.close()
    assert piped.getvalue() == "a line\n"


def test_version_and_help(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("jaxrod ")
    for command in ("michell", "trefoil", "analyze"):
        assert main([command, "--help"]) == 0
        text = capsys.readouterr().out
        assert "examples:" in text and f"jaxrod {command}" in text
        if command != "analyze":  # the angle units, stated where angles are given
            assert "radians" in text and "pi suffix" in text


def test_cli_xla_flags_are_added_unless_the_user_set_them():
    """The CLI compiles with XLA:CPU's classic emitters (cold command 1: 33 s against 43.5 s). The
    flag is appended to the user's XLA_FLAGS, never overrides one the user set, and takes effect
    because importing jaxrod starts no XLA backend (XLA reads its flags when the first starts)."""
    import subprocess
    import sys

    from jaxrod.cli import add_cli_xla_flags

    env = {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    add_cli_xla_flags(env)
    assert env["XLA_FLAGS"].split() == ["--xla_force_host_platform_device_count=2",
                                        "--xla_cpu_use_fusion_emitters=false", "--xla_backend_optimization_level=1"]
    mine = {"XLA_FLAGS": "--xla_cpu_use_fusion_emitters=true --xla_backend_optimization_level=3"}
    add_cli_xla_flags(mine)
    assert mine["XLA_FLAGS"] == "--xla_cpu_use_fusion_emitters=true --xla_backend_optimization_level=3"
    one = {"XLA_FLAGS": "--xla_backend_optimization_level=2"}  # the user's value of one flag stays
    add_cli_xla_flags(one)
    assert one["XLA_FLAGS"].split() == ["--xla_backend_optimization_level=2", "--xla_cpu_use_fusion_emitters=false"]
    empty = {}
    add_cli_xla_flags(empty)
    assert empty["XLA_FLAGS"] == "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=1"
    code = "import jaxrod.cli; from jax._src import xla_bridge; print(len(xla_bridge._backends))"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "0"


def test_a_users_compile_cache_keeps_every_program(monkeypatch, tmp_path):
    """With the user's own JAX_COMPILATION_CACHE_DIR, JAX by default keeps only compilations over
    1 s: command 1's second run then compiled 51 of its ~90 programs again. The CLI lowers that
    threshold to 0 unless the user set one; its own cache (~/.cache/jaxrod) likewise."""
    import argparse

    import jax

    from jaxrod.cli import enable_compilation_cache

    before = jax.config.jax_persistent_cache_min_compile_time_secs
    try:
        monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "user"))
        monkeypatch.delenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", raising=False)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
        assert enable_compilation_cache(argparse.Namespace()) is None  # the user's folder, kept
        assert jax.config.jax_persistent_cache_min_compile_time_secs == 0.0
        monkeypatch.setenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "2")  # the user's choice stays
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 2.0)
        enable_compilation_cache(argparse.Namespace())
        assert jax.config.jax_persistent_cache_min_compile_time_secs == 2.0
    finally:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", before)


def test_workers_run_jobs_in_order_hand_back_values_and_errors():
    # The CLI's worker threads (issue 18): each branch end's location and error estimate runs as a
    # job as soon as the study has found that end; the main thread collects them.
    import threading

    from jaxrod.studies.runs import Workers

    workers = Workers(start=False)
    ran = []
    for i in range(4):
        workers.submit(("job", i), lambda cancel, i=i: ran.append(i) or i * i)
    assert workers.n_workers == 0 and not ran  # nothing runs before a worker is added
    workers.add_worker()
    assert workers.results() == {("job", i): i * i for i in range(4)} and ran == [0, 1, 2, 3]
    assert workers.keys == {("job", i) for i in range(4)}

    failing = Workers()
    failing.submit("bad", lambda cancel: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        failing.results()

    # stop(): a running job sees cancel, the queued ones never start
    started, later = threading.Event(), []
    stopping = Workers()

    def long_job(cancel):
        started.set()
        while not cancel.wait(0.01):
            pass
        return "stopped"

    stopping.submit("long", long_job)
    stopping.submit("later", lambda cancel: later.append(1))
    assert started.wait(5.0)
    stopping.stop()
    assert later == []


def test_accuracy_mode_with_no_end_in_range_says_so(tmp_path, capsys):
    # a tight trefoil (L/D = 17.5) at N = 24 reaches neither side's end within +-14 pi: the run
    # says so per side and exits 1, and convergence.json holds no phi_star (never a made-up value)
    out = tmp_path / "acc"
    code = main(["trefoil", "--D", "8", "--L", "140", "--N", "24", "--accuracy", "1pi", "--N-max", "93",
                 "--no-figures", "--quiet", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 1
    assert "phi_plus   = no end (N = 24): NOT CONVERGED" in printed and "before the twist range's end" in printed
    sides = json.loads((out / "convergence.json").read_text())
    assert sides["plus"]["phi_star"] is None and sides["plus"]["reached"] is False


def test_a_valueerror_raised_inside_numpy_is_not_reported_as_a_wrong_flag(monkeypatch, capsys):
    """A ValueError from jaxrod's checks names a wrong input (exit 2); one raised inside numpy (here
    an empty array reduced, as a figure once did) is said to come from there, exit 1."""
    import numpy as np

    from jaxrod.cli.parser import COMMANDS

    def broken(args):
        return np.min(np.array([]))

    monkeypatch.setattr(COMMANDS["michell"], "run", broken)
    assert main(["michell", "--N", "32"]) == 1
    err = capsys.readouterr().err
    assert "zero-size array" in err and "raised inside numpy" in err and "--" not in err.split("(")[0]
    monkeypatch.undo()
    assert main(["michell", "--N", "2"]) == 2  # jaxrod's own check of --N
    assert "--N" in capsys.readouterr().err
