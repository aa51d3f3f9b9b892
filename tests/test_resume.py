"""A study killed (SIGKILL) at any moment resumes to exactly the files of an uninterrupted run
(issue 8, acceptance 1): mid-row (between a row of branch.csv and its step file, with a
half-written temporary file left behind), mid-bisection (while a branch end is being
located) and just after a branch switch. Each kill is a real ``kill -9`` of a subprocess; the
resumed runs are chained on one folder, and the result is compared with a run that was never
interrupted: branch.csv and critical.json byte for byte, every array of every step file and
critical-mode file exactly (so phi* is identical, not merely to 1e-12)."""
import json
import math
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import jaxrod as jr
from jaxrod.studies.twist import twist_study

PI = math.pi
RANGE = (-0.5 * PI, 7.5 * PI)  # the opening side's fold at 6.83 pi (N = 41), a switch, the buckled branch
STEP = 1.0 * PI  # 7 steps to the fold: the sixth step file is written before the bisection starts

# The subprocess: imports jaxrod once (which starts no XLA backend and no thread, so forking is
# safe), then for each moment read from stdin forks a child that runs the study with a hook that
# kills it (SIGKILL: no cleanup, no finally), and prints the child's wait status. The children
# skip Python's start and JaxRod's import (~3 s each); each still starts its own XLA backend.
SCRIPT = textwrap.dedent("""
    import math, os, signal, sys
    import jaxrod as jr
    import jaxrod.studies.twist as study

    out = sys.argv[1]

    def killed_study(moment):
        kill = lambda: os.kill(os.getpid(), signal.SIGKILL)
        saves = [0]
        real_savez = study.savez

        def savez(path, **arrays):
            # mid-row: the 6th step file, after its row of branch.csv; a partial temporary file is
            # left where the atomic write would have renamed it.
            if moment == "mid-row" and os.sep + "steps" + os.sep in path:
                saves[0] += 1
                if saves[0] == 6:
                    folder, name = os.path.split(path)
                    with open(os.path.join(folder, ".tmp-" + name), "wb") as f:
                        f.write(b"PK\\x03\\x04 half a zip")
                    kill()
            real_savez(path, **arrays)

        study.savez = savez

        def progress(message):
            if moment == "mid-bisection" and " refused (" in message:
                kill()
            if moment == "after-switch" and message.startswith("[buckled+] phi"):
                kill()

        scene = jr.trefoil(D=8.0, L=292.0, N=41)
        study.twist_study(scene, %r, %r, jr.ContinuationOptions(step=%r, tol=1e-3 * math.pi), out=out,
                          observer=jr.Observer(progress=progress))

    for line in sys.stdin:
        moment = line.strip()
        pid = os.fork()
        if pid == 0:
            try:
                killed_study(moment)
            finally:
                os._exit(3)  # not killed: the test fails on the status
        _, status = os.waitpid(pid, 0)
        print(moment, status, flush=True)
""" % (RANGE + (STEP,)))


def _killer(script, out):
    return subprocess.Popen([sys.executable, str(script), str(out)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _kill_at(killer, moment):
    """Run the study in a forked child until ``moment``; its wait status."""
    killer.stdin.write(moment + "\n")
    killer.stdin.flush()
    line = killer.stdout.readline()
    assert line.split()[:1] == [moment], (moment, line, killer.poll())
    return int(line.split()[1])


def _arrays(path):
    with np.load(path) as f:
        return {key: f[key] for key in f.files}


@pytest.mark.validation  # the validation tier (-m validation): four studies, three of them killed
def test_sigkill_at_three_moments_resumes_to_the_uninterrupted_files(tmp_path):
    scene = jr.trefoil(D=8.0, L=292.0, N=41)
    whole = tmp_path / "whole"
    ref = twist_study(scene, *RANGE, jr.ContinuationOptions(step=STEP, tol=1e-3 * PI), out=str(whole))
    assert ref.critical["phi_plus"] is not None and len(ref.critical["instabilities"]) >= 1

    script = tmp_path / "killed_study.py"
    script.write_text(SCRIPT)
    cut = tmp_path / "cut"
    killer = _killer(script, cut)
    for moment in ("mid-row", "mid-bisection", "after-switch"):
        status = _kill_at(killer, moment)
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, (moment, status)
        if moment == "mid-row":
            assert any(name.startswith(".tmp-") for name in os.listdir(cut / "steps"))
        if moment == "after-switch":
            # Killed right after the buckled branch's first row: the instability is on file.
            crit = json.loads((cut / "critical.json").read_text())
            assert crit["phi_plus"] == ref.critical["phi_plus"]
    killer.stdin.close()
    assert killer.wait(timeout=60) == 0, killer.stderr.read()[-2000:]
    # The last resumption runs here, in this process (its code is compiled already).
    said = []
    twist_study(scene, *RANGE, jr.ContinuationOptions(step=STEP, tol=1e-3 * PI), out=str(cut),
                observer=jr.Observer(progress=said.append))
    assert any(m.startswith("plus: resuming on ") for m in said), said

    for name in ("branch.csv", "critical.json"):
        assert (cut / name).read_bytes() == (whole / name).read_bytes(), name
    steps = sorted(os.listdir(whole / "steps"))
    assert sorted(n for n in os.listdir(cut / "steps") if not n.startswith(".tmp-")) == steps
    modes = sorted(n for n in os.listdir(whole) if n.startswith("critical_mode_"))
    assert sorted(n for n in os.listdir(cut) if n.startswith("critical_mode_")) == modes
    for path in [os.path.join("steps", n) for n in steps] + modes:
        a, b = _arrays(whole / path), _arrays(cut / path)
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a), path
    # The total time covers all five runs.
    assert json.loads((cut / "time.json").read_text())["seconds_total"] > ref.seconds_total
