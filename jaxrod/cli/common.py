"""What every command shares: angles as arguments, the --out folder, the compile cache, the
progress bar on stderr and warnings in one line. Nothing here imports JAX at module level, so
that ``jaxrod --help`` stays fast."""
from __future__ import annotations

import argparse
import math
import os
import sys

ANGLES = "Angles are in radians, or in units of pi with a pi suffix: 12pi, -8.5pi, 0.25*pi."

# Options whose value is an angle such as -12pi: argparse would read a leading '-' as an option.
ANGLE_OPTIONS = ("--phi-min", "--phi-max", "--step", "--tol", "--span", "--accuracy", "--joint-twist", "--R")


def parse_angle(text):
    """Parse an angle in radians; accepts '12pi', '-8*pi', '3.5pi', 'pi', or a plain number."""
    from ..validation import parse_angle_text

    try:
        return parse_angle_text(text, "angle")
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an angle: {text!r} (use e.g. 12pi or 3.7)") from None


def join_angle_values(argv):
    """argv with each angle option and its value joined (``--phi-min=-12pi``), so that a negative
    angle is read as the option's value."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in ANGLE_OPTIONS and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


# --no-cache's help: the long form where a first run is the common case (michell, helix).
NO_CACHE_HELP = "do not keep compiled code in ~/.cache/jaxrod"
NO_CACHE_HELP_LONG = NO_CACHE_HELP + " (later runs then compile again)"


def add_quiet_and_cache(parser, cache_help=None):
    """The last options of a command: --quiet and, where it compiles (cache_help given), --no-cache."""
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    if cache_help is not None:
        parser.add_argument("--no-cache", action="store_true", help=cache_help)


def output_folder(path):
    """Create the --out folder now (not after the computation) or raise ValueError naming --out."""
    if os.path.exists(path) and not os.path.isdir(path):
        raise ValueError(f"--out {path} is a file, not a folder")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--out {path}: cannot create the folder ({exc.strerror or exc})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise ValueError(f"--out {path}: the folder is not writable")
    return path


def number_list(flag, text, kind):
    """The comma-separated numbers of ``text`` as ``kind``; ValueError naming ``flag``."""
    try:
        values = [kind(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"{flag} must be a comma-separated list of numbers, got {text!r}") from None
    if not values:
        raise ValueError(f"{flag}: give at least one value")
    return values


def enable_compilation_cache(args):
    """Keep XLA's compiled code between runs (first run ~30 s, later runs a few s), unless the
    user chose a cache already (JAX_COMPILATION_CACHE_DIR) or passed --no-cache. Sets
    ``args.programs``, the folder of the exported programs (``jaxrod.aot``); returns the cache
    folder this function chose, or None."""
    if getattr(args, "no_cache", False):
        return
    import jax

    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        # The user's cache: JAX keeps only compilations over 1 s there by default, which left
        # 51 of command 1's ~95 programs to be compiled again by every later run.
        if not os.environ.get("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"):
            jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        args.programs = os.path.join(os.environ["JAX_COMPILATION_CACHE_DIR"], "jaxrod-programs")
        return

    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.path.join(base, "jaxrod", "xla")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return  # read-only home: run without a cache
    jax.config.update("jax_compilation_cache_dir", path)
    # Every compilation, also the many small ones under the default 1 s threshold.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    # The heaviest functions' exported programs (``jaxrod.aot``): a later run loads them instead
    # of tracing and lowering them again (kept for the command's duration, see ``main``)
    args.programs = os.path.join(base, "jaxrod", "programs")
    return path


def compile_notice(args, cache):
    """A line before the silent first compilation, so that a first run does not look stuck."""
    if getattr(args, "no_cache", False):
        return "compiling (~15-30 s; --no-cache: not kept for later runs)"
    if cache is None:
        cache = os.environ.get("JAX_COMPILATION_CACHE_DIR")
    if cache and os.path.isdir(cache) and len(os.listdir(cache)) > 0:
        return f"using compiled code cached in {cache} (compiling only what is new)"
    where = f"; cached in {cache} for later runs" if cache else ""
    return f"compiling (first run, ~15-30 s{where})"


def use_files_only_backend():
    """Matplotlib draws into files only: no display needed (loaded by the commands that draw)."""
    import matplotlib

    matplotlib.use("Agg")


def warn_in_one_line(message, category, filename, lineno, file=None, line=None):
    """``warnings.showwarning`` for the command line: one line, not a source quote."""
    print(f"jaxrod: warning: {message}", file=sys.stderr, flush=True)


class Progress:
    """Progress on stderr: a tqdm bar (on a terminal only) of the twist reached, with the elapsed
    time and an ETA, and the progress lines written above it; nothing with --quiet."""

    def __init__(self, args, total, desc, counting=None):
        """total: the twist to cover (units of pi), or with ``counting`` (e.g. "cases") a count."""
        import threading

        self.quiet = bool(args.quiet)
        self.lock = threading.Lock()
        self.bar = None
        if not self.quiet and total > 0:
            from tqdm import tqdm

            self.bar = tqdm(total=round(total, 2), file=sys.stderr, disable=None, desc=desc, leave=False,
                            dynamic_ncols=True,
                            bar_format=("{desc}: {percentage:3.0f}%|{bar}| phi {n:.2f}/{total:.2f} pi "
                                        "[{elapsed}<{remaining}{postfix}]") if counting is None else
                            ("{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} " + counting +
                             " [{elapsed}<{remaining}{postfix}]"))
            if self.bar.disable:
                self.bar = None

    def say(self, line):
        """Writes one progress line (above the bar, if any)."""
        if self.quiet:
            return
        with self.lock:
            if self.bar is not None:
                self.bar.write(line, file=sys.stderr)
            else:
                print(line, file=sys.stderr, flush=True)

    def update(self, reached, **postfix):
        """reached: the twist covered so far, in units of pi (or the count)."""
        if self.bar is None:
            return
        with self.lock:
            self.bar.n = min(round(reached, 2), self.bar.total)
            self.bar.set_postfix(postfix, refresh=False)
            self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.bar.close()
