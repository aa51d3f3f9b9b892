"""``main``: the command line run in this process (exit status returned), and ``console_main``,
the installed ``jaxrod`` command (the process exits)."""
from __future__ import annotations

import contextlib
import os
import sys

from .common import compile_notice, enable_compilation_cache, join_angle_values, warn_in_one_line
from .parser import COMMANDS, build_parser, flag_names, in_flags

# ``main``: how long a thread may keep the GIL when another waits (seconds). The study's and the
# workers' threads each hand the GIL back while XLA or LAPACK computes, and wait for it again when
# the call returns: up to the switch interval (5 ms) whenever another thread runs Python then,
# thousands of times in a run. 0.5 ms: command 1 warm 17.75 s against 18.98 s (means of 6
# alternating runs, 2026-12-04); 0.1 ms was slower (18.6 s).
SWITCH_INTERVAL = 5e-4

# XLA:CPU's classic elemental emitters instead of its MLIR fusion emitters: the same arithmetic
# (fast-math stays off), compiled faster. Command 1 (N = 121, -12 pi ... 14 pi) as two CLI
# processes on an empty cache (benchmarks/cli_start.py, medians of 2 rounds): 35.8 s against
# 41.1 s cold, 24.3 s against 25.5 s warm, phi* equal to 2e-10 rad. And LLVM's optimisation
# level 1 instead of XLA's default 3: 32.5 / 32.7 / 33.4 s cold against 33.9 / 34.7 / 35.6 s,
# warm 15.2 / 15.4 / 15.6 s against 15.1 / 15.5 / 15.6 s (alternating runs, 2026-12-04; level 0
# compiled 40 % faster but ran the Newton loop 1.5x slower); the located ends equal to 2e-11 pi.
# Only for the command's own process, and only if the user set no such flag.
CLI_XLA_FLAGS = ("--xla_cpu_use_fusion_emitters=false", "--xla_backend_optimization_level=1")

# A failed computation's advice, by command (the twist studies' where none is given).
_NO_CROSSING_ADVICE = {
    "michell": "no critical twist up to twice Michell's value: raise --N",
    "critical-curve": "no instability within --span at a ratio of --ratios: widen --span or raise --N",
}
_NO_CROSSING_DEFAULT = "no critical twist in the range: widen it (--phi-min / --phi-max) or raise --N"
_NO_EQUILIBRIUM_ADVICE = ("no equilibrium found: raise --N (for a knot, edges no longer than the diameter: "
                          "N >= L/D), or loosen the knot (larger --L/--D)")


def _interrupt(signum, frame):
    """SIGTERM (a scheduler's or a `kill`'s stop) is handled like Ctrl-C: the study stops at its
    next saved state, says that the same command resumes, and exits with status 130."""
    raise KeyboardInterrupt


def main(argv=None):
    """Run the command line with ``argv`` (default sys.argv[1:]); returns the exit status."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return _main(argv)
    previous = signal.signal(signal.SIGTERM, _interrupt)
    # Ctrl-C raises KeyboardInterrupt even where the parent left SIGINT ignored (a background job
    # of a non-interactive shell, a pytest-xdist worker): Python installs its handler only if
    # SIGINT was not ignored at start-up, and an ignored Ctrl-C let a study run on to its end.
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    interval = sys.getswitchinterval()
    sys.setswitchinterval(SWITCH_INTERVAL)
    try:
        return _main(argv)
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
        sys.setswitchinterval(interval)


def _main(argv):
    argv = join_angle_values(list(sys.argv[1:] if argv is None else argv))
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version (0) or a usage error (2, its one line printed)
        return exc.code if isinstance(exc.code, int) else 2
    if args.command is None:  # `jaxrod` alone: what it can do
        parser.print_help(sys.stderr)
        return 2
    flags = flag_names(parser, args.command)
    try:
        return _run(args)
    except ValueError as exc:
        where = raised_in(exc)
        if where != "jaxrod":  # numpy's, SciPy's, JAX's own: a defect of the run, or an unreadable input file
            print(f"jaxrod: error: {exc} (raised inside {where}, not by jaxrod's checks of its inputs: if the "
                  f"inputs are right, this is a defect of jaxrod)", file=sys.stderr)
            return 1
        print(f"jaxrod: error: {in_flags(str(exc), flags)}", file=sys.stderr)
        return 2
    except OSError as exc:  # missing or unreadable file, unwritable --out
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"jaxrod: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        hint = (f"; the same command resumes from what is in {args.out}/"
                if args.command in ("trefoil", "knot", "atlas") else "")
        print(f"jaxrod: interrupted{hint}", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 -- a failed computation: one line, what to change
        status = _failed(args.command, exc)
        if status is None:
            raise
        return status


def _run(args):
    """The command of ``args`` run with the compile cache, one-line warnings and, until it ends,
    its exported programs and its --out folder's lock."""
    import warnings

    import jaxrod  # noqa: F401  (float64, BLAS threads)

    args.compile_notice = compile_notice(args, enable_compilation_cache(args))
    with warnings.catch_warnings(), contextlib.ExitStack() as held:
        warnings.showwarning = warn_in_one_line  # a warning is one line, not a source quote
        if getattr(args, "programs", None) and os.environ.get("JAXROD_PROGRAMS", "1") != "0":
            from .. import aot

            held.enter_context(aot.kept_in(args.programs))
        args.hold = held.enter_context  # the --out folder's lock, until the command ends
        return COMMANDS[args.command].run(args)


def raised_in(exc):
    """The top-level package whose code raised ``exc`` (its traceback's innermost frame): "jaxrod"
    for jaxrod's own checks, which name the wrong input; else e.g. "numpy" or "jax" (an empty array
    reduced, a singular matrix, an unreadable file), which the command line does not report as a
    wrong flag."""
    tb, last = exc.__traceback__, None
    while tb is not None:
        last, tb = tb, tb.tb_next
    if last is None:
        return "jaxrod"
    module = last.tb_frame.f_globals.get("__name__", "") or "?"
    return module.split(".")[0]


def _failed(command, exc):
    """Exit status 1 and one line on stderr for a computation that found no critical twist or no
    equilibrium; None for any other exception (raised again by the caller)."""
    from ..continuation import NoCrossingError
    from ..solve.solvers import ConvergenceError

    if isinstance(exc, NoCrossingError):
        advice = _NO_CROSSING_ADVICE.get(command, _NO_CROSSING_DEFAULT)
    elif isinstance(exc, ConvergenceError):
        advice = _NO_EQUILIBRIUM_ADVICE
    else:
        return None
    detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    if len(detail) > 160:
        detail = detail[:157] + "..."
    print(f"jaxrod: error: {advice} ({detail})", file=sys.stderr)
    return 1


def add_cli_xla_flags(environ=os.environ):
    """Append the CLI's XLA flags to XLA_FLAGS unless the user set them (read by XLA when the CPU
    backend starts, at the first computation: after ``import jax``, before any array is built)."""
    flags = environ.get("XLA_FLAGS", "").split()
    for flag in CLI_XLA_FLAGS:
        if not any(f.split("=")[0] == flag.split("=")[0] for f in flags):
            flags.append(flag)
    environ["XLA_FLAGS"] = " ".join(flags)


def console_main():
    """The ``jaxrod`` command: ``main()``, then the process exit. The run leaves at once, once its
    threads have stopped and its files are closed (``main`` returns only then), without the
    interpreter's teardown of XLA and of the modules: that teardown took 1.1 s of command 1's wall
    time, and after an interrupted run (130) it aborted ("terminate called ...", status 134) in
    about one run in four although the study had already stopped cleanly. The persistent compile
    cache is written when each program is compiled, not at exit."""
    add_cli_xla_flags()
    status = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status if isinstance(status, int) else 1)
