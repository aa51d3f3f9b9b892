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


@pytest.mark.parametrize(
    "args, name",
    [
        (["--N", "3"], "N"),
        (["--nu", "nan"], "nu"),
        (["--nu", "0.7"], "nu"),
        (["--nu", "-1"], "nu"),
        (["--slenderness", "-0.1"], "slenderness"),
        (["--N", "abc"], "--N"),
    ],
)
def test_bad_input_exits_nonzero_with_one_line(args, name):
    r = run("michell", *args, timeout=120)
    assert r.returncode != 0
    lines = [l for l in r.stderr.strip().splitlines() if l]
    assert len(lines) == 1, r.stderr
    assert name in lines[0] and lines[0].startswith("jaxrod: error:")
