"""Issue 16, defects 1 and 2: a study stopped by Ctrl-C or SIGTERM exits with 130 and one line
(it aborted with 134 and "terminate called ..." while its two threads were inside XLA), and a
second run into a folder in use is refused in one line (it used to interleave its rows with the
first run's: 53 duplicate rows), the lock going with the process that held it, even on kill -9."""
import shlex
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from jaxrod.io.locking import LOCK_NAME, FolderInUseError, folder_lock

from test_cli import EXE

# The validation tier (-m validation): real studies in subprocesses, signalled and killed.
pytestmark = pytest.mark.validation

# Long enough that the run is still going when it is signalled, however fast the machine: small
# steps (~2400 of them; the test stops the run within seconds of its start, so they cost nothing);
# N = 61 shares its compiled code with the other CLI tests (one cache per test session).
STUDY = ["trefoil", "--N", "61", "--phi-min", "-12pi", "--phi-max", "12pi", "--step", "0.01pi", "--no-figures",
         "--quiet"]


def _start(out):
    return subprocess.Popen([EXE, *STUDY, "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _wait_until_both_directions_run(proc, out, timeout=240.0):
    """Both threads have saved a state: the study is in its parallel part."""
    t0 = time.monotonic()
    while not all((out / f"state_{d}.npz").exists() for d in ("plus", "minus")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout, "the study did not start in time"
        time.sleep(0.05)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signalled_study_exits_130_with_one_line_and_the_folder_is_locked_meanwhile(tmp_path, signum):
    out = tmp_path / "study"
    first = _start(out)
    _wait_until_both_directions_run(first, out)
    if signum == signal.SIGINT:
        # Defect 2: the same command into the same folder, while the first one runs.
        second = subprocess.run([EXE, *STUDY, "--out", str(out)], capture_output=True, text=True, timeout=120)
        lines = second.stderr.strip().splitlines()
        assert second.returncode == 2 and len(lines) == 1, second.stderr
        assert "in use by another jaxrod run" in lines[0] and f"pid {first.pid}" in lines[0], lines
        assert lines[0].startswith(f"jaxrod: error: --out {out}"), lines
        assert first.poll() is None  # the first run was not disturbed
    first.send_signal(signum)
    stdout, stderr = first.communicate(timeout=120)
    assert first.returncode == 130, (first.returncode, stderr[-2000:])
    assert stderr.strip().splitlines() == [f"jaxrod: interrupted; the same command resumes from what is in {out}/"]
    # The lock went with the process: the folder can be taken again at once.
    with folder_lock(out):
        pass


def test_the_lock_is_released_when_its_holder_is_killed_and_refuses_the_api_meanwhile(tmp_path):
    import math

    import jaxrod as jr
    from jaxrod.studies.twist import twist_study

    out = tmp_path / "held"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys, time
        from jaxrod.io.locking import folder_lock
        with folder_lock({str(out)!r}):
            print("held", flush=True)
            time.sleep(120)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        scene = jr.trefoil(D=8.0, L=292.0, N=61)
        with pytest.raises(FolderInUseError, match=f"out {out} is in use by another jaxrod run .pid {holder.pid}"):
            twist_study(scene, -math.pi, math.pi, out=str(out))
        assert not (out / "run.json").exists()  # refused before anything was written
    finally:
        holder.kill()  # SIGKILL: no cleanup in the holder
        holder.wait()
    assert (out / LOCK_NAME).exists()  # the file stays; the lock does not
    with folder_lock(out):
        with folder_lock(out):  # re-entrant within a process (the CLI, then twist_study)
            pass
    with folder_lock(out):
        pass


def test_ctrl_c_stops_a_study_whose_parent_ignored_it(tmp_path):
    # a background job of a non-interactive shell (or a pytest-xdist worker's child) starts with
    # SIGINT ignored; the command line takes Ctrl-C back, so the study still stops and says so
    out = tmp_path / "study"
    command = " ".join(shlex.quote(a) for a in [EXE, *STUDY, "--out", str(out)])
    first = subprocess.Popen(["sh", "-c", f"trap '' INT; exec {command}"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)  # exec: the same pid, SIGINT ignored
    _wait_until_both_directions_run(first, out)
    first.send_signal(signal.SIGINT)
    try:
        _, stderr = first.communicate(timeout=120)
    finally:
        first.kill()
    assert first.returncode == 130, stderr[-2000:]
    assert stderr.strip().splitlines() == [f"jaxrod: interrupted; the same command resumes from what is in {out}/"]
