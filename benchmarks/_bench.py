"""What every benchmark script shares: its small mode, its output folder and its provenance.

Small mode (``JAXROD_SMOKE=1`` in the environment, or ``--smoke`` on a script's command line): the
script runs the same code path at the smallest sizes that exercise it (small N, a few steps, one
level instead of a sweep), so that a test can run every script in seconds. Its numbers mean
nothing; only that the script still runs and writes its files.

Output folder (``results_dir()``): ``JAXROD_BENCH_OUT`` if set, else ``benchmarks/results`` at full
size and a fresh temporary folder in the small mode, which never writes over
``benchmarks/results``.

Provenance (``provenance()``): the commit (``git rev-parse --short HEAD``, "+ uncommitted changes"
when the tracked files outside benchmarks/results differ from it) and the command that produced a
results file.
"""
import functools
import os
import platform
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
COMMITTED_RESULTS = os.path.join(HERE, "results")


def _small_mode():
    # --smoke is taken off the command line, so that a script's own argument parsing never sees it
    if "--smoke" in sys.argv[1:]:
        sys.argv.remove("--smoke")
        os.environ["JAXROD_SMOKE"] = "1"
    return os.environ.get("JAXROD_SMOKE", "") not in ("", "0")


SMOKE = _small_mode()


def pick(full, small):
    """``full`` at full size, ``small`` in the small mode."""
    return small if SMOKE else full


@functools.cache
def results_dir():
    """The folder a script writes its results to (created; one per process)."""
    out = os.environ.get("JAXROD_BENCH_OUT") or (tempfile.mkdtemp(prefix="jaxrod-bench-") if SMOKE
                                                 else COMMITTED_RESULTS)
    if SMOKE and os.path.realpath(out) == os.path.realpath(COMMITTED_RESULTS):
        raise SystemExit("the small mode must not write over benchmarks/results: set JAXROD_BENCH_OUT elsewhere")
    os.makedirs(out, exist_ok=True)
    os.environ["JAXROD_BENCH_OUT"] = out  # a script's worker processes write to the same folder
    return out


def _git(*args):
    run = subprocess.run(["git", "-C", REPO, *args], capture_output=True, text=True)
    return run.stdout.strip() if run.returncode == 0 else ""


def provenance():
    """{"commit": ..., "command": ...} of this run, for a results file's header."""
    commit = _git("rev-parse", "--short", "HEAD") or "unknown"
    # results files the run itself (re)writes are not changes to the code that produced them
    if _git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)benchmarks/results"):
        commit += " + uncommitted changes"
    script = os.path.relpath(os.path.abspath(sys.argv[0]), REPO)
    command = " ".join(["python", script, *sys.argv[1:]] + (["--smoke"] if SMOKE else []))
    return {"commit": commit, "command": command}


def provenance_json():
    """The provenance with the machine, as a JSON results file's ``"provenance"`` field."""
    return {**provenance(), "machine": platform.processor() or platform.machine()}


def with_provenance(data):
    """``data`` (a dict, or a list stored under ``"rows"``) with its ``"provenance"`` field first."""
    body = data if isinstance(data, dict) else {"rows": data}
    return {"provenance": provenance_json(), **{k: v for k, v in body.items() if k != "provenance"}}


def provenance_line():
    """The provenance as one line of text (a Markdown results file's header)."""
    p = provenance()
    return f"Produced by `{p['command']}` at commit {p['commit']}."


def fmt(value, spec, missing="none"):
    """``value`` formatted with ``spec``, or ``missing`` where it is None (a small run's tiny twist
    range finds no critical twist, so its tables have none to show)."""
    return missing if value is None else format(value, spec)


# The smallest trefoil study a CLI process can run: the knot at 17.5 D (the fewest nodes its contact
# allows), stable branches only, a quarter turn each way: the same CLI code path in a few seconds.
TINY_CLI_ARGS = ["trefoil", "--D", "8", "--L", "140", "--N", "24", "--phi-min", "-0.5pi", "--phi-max", "0.5pi",
                 "--stable-only", "--no-extrapolation"]


def markdown(lines):
    """``lines`` (a title first) as the text of a Markdown results file, the provenance under the title."""
    return "\n".join([lines[0], "", provenance_line(), *lines[1:]]) + "\n"


def run_cli(argv, in_process=False):
    """The command line ``jaxrod argv``: a process of its own (the ``jaxrod`` next to this Python),
    or ``jaxrod.cli.main`` in this process, where a script compares answers rather than timing a
    process (the small mode: the programs compiled for one command then serve the next).
    -> CompletedProcess (returncode, stdout, stderr)."""
    if not in_process:
        exe = os.path.join(os.path.dirname(sys.executable), "jaxrod")
        return subprocess.run([exe, *argv], capture_output=True, text=True)
    import contextlib
    import io

    from jaxrod.cli import main as cli_main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli_main(argv)
    return subprocess.CompletedProcess(["jaxrod", *argv], code, out.getvalue(), err.getvalue())
