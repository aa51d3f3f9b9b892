"""Command line: ``jaxrod michell ...``, ``jaxrod trefoil ...``, ``jaxrod knot ...``, ``jaxrod atlas ...``,
``jaxrod analyze CENTRELINE ECCENTRIC ...``, ``jaxrod helix ...``, ``jaxrod critical-curve ...``.

Progress goes to stderr; results to stdout (``--json``: one JSON object); figures and data
(PNG, CSV, JSON) into ``--out DIR``. Bad input exits with status 2, a computation that fails
(no critical twist in range, no equilibrium) with status 1, Ctrl-C with 130: each with one line
on stderr that says what to change (or, for an interrupted study, that it resumes).
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import json
import math
import os
import sys
import time

__all__ = ["main"]

# The knot factories' default E (jaxrod.model.scenes.PAPER_YOUNG_MODULUS; a test checks that they agree),
# written here so that `jaxrod --help` does not import JAX.
PAPER_YOUNG_MODULUS = 0.474

# A ring of fewer nodes does not buckle within twice Michell's twist (N = 4 to 6 were seen to
# scan the whole range in vain).
MICHELL_MIN_NODES = 8

# trefoil / knot: --N when not given (the twist study; with --accuracy the coarsest level is the
# larger of ACCURACY_NODES and L/D).
STUDY_NODES = 121
ACCURACY_NODES = 61


def _angle(text):
    """Parse an angle in radians; accepts '12pi', '-8*pi', '3.5pi', 'pi', or a plain number."""
    s = text.strip().lower().replace(" ", "")
    try:
        if s.endswith("pi"):
            head = s[:-2].rstrip("*")
            factor = 1.0 if head in ("", "+") else -1.0 if head == "-" else float(head)
            return factor * math.pi
        return float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an angle: {text!r} (use e.g. 12pi or 3.7)") from None


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, status 2
        self.exit(2, f"jaxrod: error: {message} (see {self.prog} --help)\n")


_ANGLES = "Angles are in radians, or in units of pi with a pi suffix: 12pi, -8.5pi, 0.25*pi."

_MICHELL_HELP = f"""\
Critical twist of Michell's ring (a closed, initially circular rod, B/C = 1 + nu): the twist at
which the planar ring buckles, found where the lowest eigenvalue of the equilibrium's Hessian
crosses zero (Newton on that eigenvalue), compared with the analytic 2 pi sqrt(3)(1 + nu).
{_ANGLES}

examples:
  jaxrod michell --N 128 --nu 0.5 --out results/michell
  jaxrod michell --N 512 --tol 1e-8pi --json
"""

_TREFOIL_HELP = f"""\
The twisted trefoil knot of the seed paper: relax a trefoil of rod diameter D and length L at
zero twist, then follow its stable equilibria as the joint is twisted up to --phi-max and down
to --phi-min; where a branch ends (buckling), locate the critical twist, switch to the buckled
branch and go on. Then the whole diagram: each branch end located exactly on the extended system
(a fold or a branch point) and the unstable branch beyond it (--stable-only skips this). Lengths in
mm (any unit, if D and L share it), E in MPa (N/mm^2).
{_ANGLES}

Writes into --out as it goes: branch.csv (a row per step, then the unstable branches' rows),
steps/*.npz, critical.json (phi_plus, phi_minus in radians; events: each located end), summary.json
and figures (bifurcation.png, branch_ends.png, ...). An interrupted run (Ctrl-C, kill) resumes
when the same command is given again, and ends with the same files as an uninterrupted run.

examples:
  jaxrod trefoil --D 8 --L 292 --N 121 --phi-min -12pi --phi-max 14pi --out results/trefoil
  jaxrod trefoil --N 61 --phi-min -0.5pi --phi-max 7.5pi --out results/quick
"""

_KNOT_HELP = f"""\
The twist study of the trefoil command for another knot: the figure-eight knot 4_1, the
cinquefoil 5_1 (torus knot T(2,5)), the three-twist knot 5_2 (or the trefoil 3_1), each from a
published parametrisation and refused below its ideal ropelength L/D; or any closed curve read
from a file (--curve: CSV with an x,y,z header or three columns, or .npy of shape (M, 3); it is
resampled to N nodes and scaled to length L; its linking number at zero twist, Lk0, is the
integer nearest its writhe unless --lk0 gives it: that is the untwisted rod only if the curve is
close to its relaxed shape, and a warning says when the rod relaxed at zero twist still stores
more than a quarter turn). Lengths in mm, E in MPa. {_ANGLES}

Writes the same files as the trefoil command, and resumes the same way.

examples:
  jaxrod knot 4_1 --D 8 --L 292 --N 121 --phi-min -12pi --phi-max 12pi --out results/figure_eight
  jaxrod knot --curve my_knot.csv --D 8 --L 400 --N 161 --out results/my_knot
"""

_ATLAS_HELP = f"""\
The twisted-knot atlas: for each knot (--knots) and slenderness D/L (--ratios), the critical
twists phi*+ (phi > 0) and phi*- (phi < 0) at which the stable branch of the knot relaxed at zero
twist ends (a bifurcation or a fold), each side followed up to +-span. Cases are independent:
they run one after the other, over a local Dask cluster (--workers K, K processes) or on a
running Dask scheduler (--scheduler tcp://HOST:PORT), with the same numbers either way.
Several --N values give a convergence study. {_ANGLES}

Writes into --out as it goes: atlas.csv (a row per finished case; an interrupted run skips the
cases already there when given again), atlas.json (settings), atlas.md (table, convergence in
N) and atlas.png (phi*/pi against D/L per knot, with the Michell lines).

examples:
  jaxrod atlas --knots 3_1,4_1,5_1,5_2 --ratios 0.01,0.015,0.02,0.0274,0.03,0.035 --N 101 --out results/atlas
  jaxrod atlas --knots 4_1 --ratios 0.02 --N 101,151,201 --workers 2 --out results/atlas_convergence
"""

_ANALYZE_HELP = """\
Analyse a rod from its centreline and an eccentric line drawn on its surface, as the seed
paper does with measured knots: frames, curvature kappa(s) and twist tau(s) profiles, writhe,
twist and linking number (Lk from Wr + Tw and from the Gauss integral). Files: CSV with an
x,y,z header (or three bare columns), .npy arrays of shape (N, 3), or a study's step file
steps/*.npz alone (its x and eccentric arrays). Closed curves unless --open.

A line drawn on a rod whose ends were turned by phi before gluing does not close unless phi
is a whole number of turns: it jumps at the joint, the Gauss linking number is then undefined
(null) and Wr + Tw misses the fractional turn. analyze warns, or, given --joint-twist phi (read
from a step file's phi), adds that turn to Tw and Lk and removes the joint's spike from tau.

examples:
  jaxrod analyze results/trefoil/steps/plus_0013.npz
  jaxrod analyze centreline.csv stripe.csv --smoothing-modes 12 --out results/analysis
  jaxrod analyze centreline.npy stripe.npy --open --json
"""


def _version():
    try:
        from importlib.metadata import version

        return version("jaxrod")
    except Exception:  # noqa: BLE001 -- running from a source tree that is not installed
        return "unknown"


def _build_parser():
    p = _Parser(prog="jaxrod", description="Equilibria and buckling of twisted elastic rods: Michell's ring, "
                "the twisted trefoil and other knots, the twisted-knot atlas, a knot's critical twists as curves "
                "in D/L, the localized helix of a clamped rod, and the analysis of measured rods. "
                "Give a command and --help for its options.",
                formatter_class=argparse.RawDescriptionHelpFormatter,
                epilog="examples:\n  jaxrod trefoil --N 121 --out results/trefoil\n"
                       "  jaxrod atlas --knots 3_1,4_1 --ratios 0.01,0.02,0.03 --N 101 --out results/atlas\n"
                       "  jaxrod michell --N 128 --out results/michell\n  jaxrod trefoil --help")
    p.add_argument("--version", action="version", version=f"jaxrod {_version()}")
    sub = p.add_subparsers(dest="command", parser_class=_Parser)
    raw = argparse.RawDescriptionHelpFormatter
    m = sub.add_parser("michell", help="critical twist of Michell's ring, against 2 pi sqrt(3)(1+nu)",
                       description=_MICHELL_HELP, formatter_class=raw)
    m.add_argument("--N", type=int, default=128, help="number of nodes, at least 8 (default 128)")
    m.add_argument("--nu", type=float, default=0.5, help="Poisson ratio in (-1, 0.5], B/C = 1 + nu (default 0.5)")
    m.add_argument("--slenderness", type=float, default=0.01, help="rod diameter over ring radius, D/R (default 0.01)")
    m.add_argument("--tol", type=_angle, default=1e-6 * math.pi, help="accuracy of phi* (default 1e-6pi)")
    m.add_argument("--json", action="store_true",
                   help="print one JSON object (its keys: python -m jaxrod.io.schema, and the README)")
    m.add_argument("--out", default=None, help="folder for michell.json, scan.csv and figures (default: none)")
    m.add_argument("--quiet", action="store_true", help="no progress on stderr")
    m.add_argument("--no-cache", action="store_true",
                   help="do not keep compiled code in ~/.cache/jaxrod (later runs then compile again)")
    a = sub.add_parser(
        "analyze",
        help="frames, curvature/twist profiles and Wr, Tw, Lk of a rod from two polylines (CSV, NPY) or a step file",
        description=_ANALYZE_HELP, formatter_class=raw,
    )
    a.add_argument("centreline", help="centreline points (.csv, .npy, or a step file steps/*.npz: its x)")
    a.add_argument("eccentric", nargs="?", default=None,
                   help="eccentric-line points (.csv, .npy or .npz: its eccentric array); "
                        "default: the centreline's step file")
    a.add_argument("--joint-twist", type=_angle, default=None, metavar="PHI",
                   help="twist phi imposed at the joint before gluing, e.g. 6.5pi (default: a step file's phi; "
                        "for other files none)")
    a.add_argument("--open", action="store_true", help="open curves (default: closed loops)")
    a.add_argument("--n-samples", type=int, default=None,
                   help="number of nodes, at least 4, equally spaced in arc length (default: as many as "
                        "centreline points)")
    a.add_argument("--smoothing-modes", type=int, default=None, metavar="K",
                   help="least-squares smoothing with K modes (Fourier, closed) or K spline intervals (open), "
                        "at least 1 (default: none)")
    a.add_argument("--out", default=None, help="folder for profiles.csv, summary.json, profiles.png")
    a.add_argument("--json", action="store_true", help="print one JSON object")
    a.add_argument("--quiet", action="store_true", help="no progress on stderr")
    t = sub.add_parser("trefoil", help="twisted trefoil knot: both critical twists, branches beyond, figures",
                       description=_TREFOIL_HELP, formatter_class=raw)
    t.add_argument("--chirality", choices=("right", "left"), default="right", help="knot handedness (default right)")
    _study_arguments(t, "results/trefoil", "at least 16.372 D")
    k = sub.add_parser("knot", help="the same twist study for 4_1, 5_1, 5_2 or any closed curve from a file",
                       description=_KNOT_HELP, formatter_class=raw)
    k.add_argument("name", nargs="?", choices=("3_1", "4_1", "5_1", "5_2"), help="the knot (or give --curve)")
    k.add_argument("--curve", default=None, help="closed curve to tie the rod along (.csv or .npy), instead of a name")
    k.add_argument("--lk0", type=int, default=None,
                   help="linking number of the untwisted rod (default: the integer nearest the curve's writhe)")
    _study_arguments(k, "results/knot", "above the knot's ideal ropelength times D")
    at = sub.add_parser("atlas", help="critical twists of several knots over a range of D/L (CSV, figure)",
                        description=_ATLAS_HELP, formatter_class=raw)
    at.add_argument("--knots", default="3_1,4_1,5_1,5_2", help="comma-separated knots (default 3_1,4_1,5_1,5_2)")
    at.add_argument("--ratios", default="0.01,0.015,0.02,0.0274,0.03,0.035",
                    help="comma-separated slenderness values D/L, one or more "
                         "(default 0.01,0.015,0.02,0.0274,0.03,0.035)")
    at.add_argument("--N", default="101", help="number of nodes, or a comma-separated list (default 101; "
                                               "each at least 24 and L/D)")
    at.add_argument("--sides", default="plus,minus",
                    help="plus (phi > 0), minus (phi < 0) or both (default plus,minus)")
    at.add_argument("--nu", type=float, default=0.5, help="Poisson ratio in (-1, 0.5] (default 0.5)")
    at.add_argument("--contact-stiffness", type=float, default=100.0,
                    help="contact penalty kappa_c in units of B/D^3 (default 100)")
    at.add_argument("--span", type=_angle, default=16.0 * math.pi, help="follow each side up to +-span (default 16pi)")
    at.add_argument("--step", type=_angle, default=0.5 * math.pi, help="largest continuation step (default 0.5pi)")
    at.add_argument("--tol", type=_angle, default=1e-3 * math.pi, help="accuracy of the critical twists (default 1e-3pi)")
    at.add_argument("--workers", type=int, default=1,
                    help="cases at once on a local Dask cluster of this many processes (default 1: in this process)")
    at.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://HOST:PORT)")
    at.add_argument("--out", default="results/atlas", help="output folder (default results/atlas)")
    at.add_argument("--fresh", action="store_true", help="start over even if --out holds an interrupted atlas")
    at.add_argument("--no-figures", action="store_true", help="data only")
    at.add_argument("--json", action="store_true", help="print the rows as one JSON object (the critical twists' "
                                                        "keys: python -m jaxrod.io.schema, and the README)")
    at.add_argument("--quiet", action="store_true", help="no progress on stderr")
    hx = sub.add_parser("helix", help="localized helical buckling of a clamped rod with end shortening and "
                        "rotation, against NvdHT 2002 (M, T, stability, figures)", description=_HELIX_HELP,
                        formatter_class=raw)
    hx.add_argument("--m", type=float, default=None, help="end moment M L/B (with --t)")
    hx.add_argument("--t", type=float, default=None, help="tension T L^2/B (with --m)")
    hx.add_argument("--d", type=float, default=None, help="end shortening / L, in (0, 1) (with --R)")
    hx.add_argument("--R", type=_angle, default=None, metavar="R", help="end rotation in rad, e.g. 10pi (with --d)")
    hx.add_argument("--nu", type=float, default=None,
                    help="Poisson ratio in (-1, 0.5]: C/B = 1/(1 + nu); nu = 0.5 where none of --nu, --gamma, --C is given")
    hx.add_argument("--gamma", type=float, default=None, help="twist over bending stiffness C/B, any positive value")
    hx.add_argument("--B", type=float, default=None,
                    help="bending stiffness B (1 where not given); m = M L/B and t = T L^2/B, L = 1")
    hx.add_argument("--C", type=float, default=None, help="twist stiffness C (C/B any positive value)")
    hx.add_argument("--EA", type=float, default=None, help="stretching stiffness EA (16 B / slenderness^2 where not given)")
    hx.add_argument("--root", choices=("stable", "small", "large", "both"), default="stable",
                    help="with --d/--R, which of the (up to two) analytic loops: stable (each solved, the one of Morse "
                         "index 0 taken), small or large t, or both (each reported in full) (default stable)")
    hx.add_argument("--strict", action="store_true",
                    help="refuse a case outside the analytic formulas' range (lambda < 13, or a stretch that shifts "
                         "t by more than 1e-4) instead of reporting it without the comparison")
    hx.add_argument("--no-extrapolate", action="store_true",
                    help="skip the coarse solve (N/2 + 1 nodes) for Richardson's extrapolation of m and t")
    hx.add_argument("--N", type=int, default=240, help="number of nodes (default 240; at least 6 per loop core "
                                                      "width L/lambda and 2 per radian of R)")
    hx.add_argument("--slenderness", type=float, default=2e-4,
                    help="rod diameter over length D/L: EA = 16 B / (D/L)^2 unless --EA (default 2e-4: inextensible)")
    hx.add_argument("--sweep", type=int, default=0, metavar="K",
                    help="also solve K end rotations from 0.8 R to 1.1 R at the same shortening (default 0)")
    hx.add_argument("--out", default=None, help="folder for helix.json, CSV files and figures (default: none)")
    hx.add_argument("--json", action="store_true", help="print one JSON object")
    hx.add_argument("--quiet", action="store_true", help="no progress on stderr")
    hx.add_argument("--no-cache", action="store_true",
                    help="do not keep compiled code in ~/.cache/jaxrod (later runs then compile again)")
    at.add_argument("--no-cache", action="store_true", help="do not keep compiled code in ~/.cache/jaxrod")
    cc = sub.add_parser("critical-curve", help="a knot's critical twists as curves phi*+-(D/L): each side's first "
                        "instability at each D/L, as the point study finds it (CSV, JSON, figure)",
                        description=_CURVE_HELP,
                        formatter_class=raw)
    cc.add_argument("--knot", choices=("3_1", "4_1", "5_1", "5_2"), default="3_1", help="the knot (default 3_1)")
    cc.add_argument("--N", type=int, default=128,
                    help="number of nodes, at least 24 and L/D over the range (default 128)")
    cc.add_argument("--ratios", default="0.008:0.045:0.001",
                    help="D/L values: first:last:step or a comma-separated list (default 0.008:0.045:0.001)")
    cc.add_argument("--start", type=float, default=None,
                    help="the D/L done first, then those above it, then those below (default: mid-range; "
                         "the rows do not depend on it)")
    cc.add_argument("--sides", default="plus,minus",
                    help="plus (phi > 0), minus (phi < 0) or both (default plus,minus)")
    cc.add_argument("--nu", type=float, default=0.5, help="Poisson ratio in (-1, 0.5] (default 0.5)")
    cc.add_argument("--contact-stiffness", type=float, default=100.0,
                    help="contact penalty kappa_c in units of B/D^3 (default 100)")
    cc.add_argument("--span", type=_angle, default=16.0 * math.pi,
                    help="search each side's first end up to +-span (default 16pi)")
    cc.add_argument("--out", default="results/critical_curve", help="output folder (default results/critical_curve)")
    cc.add_argument("--fresh", action="store_true", help="start over even if --out holds an interrupted curve")
    cc.add_argument("--json", action="store_true", help="print the result as one JSON object")
    cc.add_argument("--quiet", action="store_true", help="no progress on stderr")
    cc.add_argument("--no-cache", action="store_true", help="do not keep compiled code in ~/.cache/jaxrod")
    sub.metavar = "{" + ",".join(sub.choices) + "}"  # every command, in the order of the list below it
    return p


def _study_arguments(t, default_out, length_rule):
    """The options that the trefoil and knot twist studies share."""
    t.add_argument("--D", type=float, default=8.0, help="rod diameter (default 8, mm)")
    t.add_argument("--L", type=float, default=292.0, help=f"rod length, {length_rule} (default 292, mm)")
    t.add_argument("--N", type=int, default=None,
                   help=f"number of nodes, at least 24 and L/D (default {STUDY_NODES}; with --accuracy the coarsest "
                        f"level, default: the larger of {ACCURACY_NODES} and L/D)")
    t.add_argument("--E", type=float, default=PAPER_YOUNG_MODULUS,
                   help=f"Young's modulus (default {PAPER_YOUNG_MODULUS:g}, the seed paper's elastomer, as in the API; "
                        "MPa = N/mm^2)")
    t.add_argument("--nu", type=float, default=0.5, help="Poisson ratio in (-1, 0.5], B/C = 1 + nu (default 0.5)")
    t.add_argument("--contact-stiffness", type=float, default=None,
                   help="contact penalty kappa_c in units of B/D^3 (default: the scene's, 100)")
    t.add_argument("--phi-min", type=_angle, default=-12.0 * math.pi, help="lowest twist, < 0 (default -12pi)")
    t.add_argument("--phi-max", type=_angle, default=14.0 * math.pi, help="highest twist, > 0 (default 14pi)")
    t.add_argument("--step", type=_angle, default=0.5 * math.pi, help="largest continuation step (default 0.5pi)")
    t.add_argument("--tol", type=_angle, default=2e-4 * math.pi, help="accuracy of the critical twists (default 2e-4pi)")
    t.add_argument("--accuracy", type=_angle, default=None,
                   help="instead of the twist study: both critical twists converged in N to this accuracy "
                        "(e.g. 0.01pi): N, 2N-1, 4N-3, ... each started from the previous one, extrapolated "
                        "(Richardson, order measured) until the error estimate is below it")
    t.add_argument("--no-extrapolation", action="store_true",
                   help="skip the rough error estimate of the study's critical twists (each end found again at "
                        "N' = (N+1)/2 from the study's state, then Richardson; a few seconds)")
    t.add_argument("--N-max", type=int, default=481,
                   help="with --accuracy: the finest level allowed (default 481; dense linear algebra, "
                        "minutes a side there)")
    t.add_argument("--out", default=default_out, help=f"output folder (default {default_out})")
    t.add_argument("--fresh", action="store_true", help="start over even if --out holds an interrupted run")
    t.add_argument("--serial", action="store_true",
                   help="follow the two directions one after the other (default: both at once, two threads)")
    t.add_argument("--no-figures", action="store_true", help="data only")
    t.add_argument("--stable-only", action="store_true",
                   help="stable branches only: no exact location of the branch ends (extended system), no unstable "
                        "branches beyond them")
    t.add_argument("--vtk", action="store_true",
                   help="also write every step as a VTK polyline file (vtk/*.vtk, for ParaView)")
    t.add_argument("--json", action="store_true", help="print one JSON summary object (the critical twists' keys: "
                                                       "python -m jaxrod.io.schema, and the README)")
    t.add_argument("--quiet", action="store_true", help="no progress on stderr")
    t.add_argument("--no-cache", action="store_true", help="do not keep compiled code in ~/.cache/jaxrod")


def _flag_names(parser, command):
    """{python name: flag} for the options of ``command`` (e.g. phi_min -> --phi-min)."""
    for action in parser._actions:  # the subparsers action holds each command's parser
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            return {a.dest: a.option_strings[-1] for a in action.choices[command]._actions
                    if a.option_strings and a.dest not in ("help",)}
    return {}


def _in_flags(message, names):
    """The library's message with its parameter names written as the CLI's flags: a name at the
    start of the message ("N must be ..."), and names with an underscore anywhere ("phi_min must
    be < 0 < phi_max"). Other words are left alone (L/D stays L/D, run.json stays run.json)."""
    import re

    for name, flag in names.items():
        if message.startswith(name + " ") or message.startswith(name + ":"):
            message = flag + message[len(name):]
        if "_" in name:  # phi_min, n_samples: never an ordinary word (json, nu, tol may be)
            message = re.sub(rf"(?<![\w-]){re.escape(name)}(?![\w-])", flag, message)
    return message


def _output_folder(path):
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


def _enable_compilation_cache(args):
    """Keep XLA's compiled code between runs (first run ~30 s, later runs a few s), unless the
    user chose a cache already (JAX_COMPILATION_CACHE_DIR) or passed --no-cache."""
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
    # of tracing and lowering them again (kept for the command's duration, see ``_main``)
    args.programs = os.path.join(base, "jaxrod", "programs")
    return path


def _compile_notice(args, cache):
    """A line before the silent first compilation, so that a first run does not look stuck."""
    if getattr(args, "no_cache", False):
        return "compiling (~15-30 s; --no-cache: not kept for later runs)"
    if cache is None:
        cache = os.environ.get("JAX_COMPILATION_CACHE_DIR")
    if cache and os.path.isdir(cache) and len(os.listdir(cache)) > 0:
        return f"using compiled code cached in {cache} (compiling only what is new)"
    where = f"; cached in {cache} for later runs" if cache else ""
    return f"compiling (first run, ~15-30 s{where})"


class _Progress:
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
        if self.quiet:
            return
        with self.lock:
            if self.bar is not None:
                self.bar.write(line, file=sys.stderr)
            else:
                print(line, file=sys.stderr, flush=True)

    def update(self, reached, **postfix):
        """reached: the twist covered so far, in units of pi."""
        if self.bar is None:
            return
        with self.lock:
            self.bar.n = min(round(reached, 2), self.bar.total)
            self.bar.set_postfix(postfix, refresh=False)
            self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _michell(args):
    import matplotlib

    matplotlib.use("Agg")  # files only, no display needed
    from ..io import plotting
    from ..continuation import ContinuationOptions, Observer, critical_twist
    from ..validation import check_int_at_least, check_poisson_ratio, check_positive
    from ..model.scenes import michell_critical_twist, michell_ring

    check_int_at_least("N", args.N, MICHELL_MIN_NODES)
    nu = check_poisson_ratio("nu", args.nu)
    check_positive("slenderness", args.slenderness)
    check_positive("tol", args.tol)
    if args.out:
        _output_folder(args.out)
    t0 = time.perf_counter()
    scene = michell_ring(args.N, nu=nu, slenderness=args.slenderness)
    analytic = michell_critical_twist(nu)
    bar = _Progress(args, analytic / math.pi, "michell")
    say = bar.say
    say(f"Michell ring: N = {args.N}, nu = {nu}, analytic phi* = {analytic / math.pi:.6f} pi")
    say(args.compile_notice)
    steps = [0]

    def on_step(phi, n_negative):
        steps[0] += 1
        bar.update(phi / math.pi, steps=steps[0], negative=n_negative)

    try:
        cp = critical_twist(scene, 0.0, 2.0 * analytic, ContinuationOptions(step=analytic / 10.0, tol=args.tol),
                            observer=Observer(progress=say, on_step=on_step))
    finally:
        bar.close()
    seconds = time.perf_counter() - t0
    rel = (cp.phi - analytic) / analytic
    result = _michell_json(cp, analytic, args.N, nu, seconds)
    if args.out:
        with open(os.path.join(args.out, "michell.json"), "w") as f:
            json.dump(result, f, indent=2)
        with open(os.path.join(args.out, "scan.csv"), "w", newline="") as f:
            w = csv.writer(f)
            k = len(cp.scan[0][2])
            w.writerow(["phi", "phi_over_pi", "n_negative"] + [f"lambda_{j}" for j in range(k)])
            for phi, n_neg, lam in cp.scan:
                w.writerow([phi, phi / math.pi, n_neg] + [float(v) for v in lam])
        plotting.plot_eigenvalue_scan(
            cp.scan, cp, os.path.join(args.out, "eigenvalues.png"),
            title=f"Michell ring, N = {args.N}, nu = {nu}", analytic=(analytic, "analytic 2 pi sqrt(3)(1 + nu)"),
        )
        mode_q = scene.from_scaled(cp.mode)
        x_mode, _ = scene.unpack(mode_q, 0.0)
        plotting.plot_mode(
            cp.equilibrium.x, x_mode, os.path.join(args.out, "critical_mode.png"),
            title=f"Critical mode at phi* = {cp.phi / math.pi:.5f} pi",
        )
        say(f"wrote {args.out}/michell.json, scan.csv, eigenvalues.png, critical_mode.png")
    if args.json:
        print(json.dumps(result))
    else:
        print(f"phi*          = {cp.phi:.12f} rad = {cp.phi / math.pi:.10f} pi  (+- {cp.phi_error:.1e})")
        print(f"analytic      = {analytic:.12f} rad = {analytic / math.pi:.10f} pi  (2 pi sqrt(3) (1+nu))")
        print(f"rel. error    = {rel:.3e}")
        print(f"time          = {seconds:.2f} s ({cp.hessian_evaluations} Hessian evaluations in the refinement)")
    return 0


def _michell_json(cp, analytic, N, nu, seconds):
    """michell's JSON (printed by --json, written to michell.json): the critical twist under
    jaxrod.io.schema's one-side keys, and the comparison with Michell's value."""
    from ..io import schema

    result = schema.side_record("plus", cp.phi, cp.phi_error, "unstable")  # an eigenvalue pair crosses zero
    result.update({
        "phi_star_analytic": analytic,
        "rel_error": (cp.phi - analytic) / analytic,
        "N": N,
        "nu": nu,
        "seconds": seconds,
        "phi_error_bound": cp.phi_error,  # the former name of phi_error
        "multiplicity": cp.multiplicity,
        "dlambda_dphi": cp.dlambda_dphi,
        "hessian_evaluations": cp.hessian_evaluations,
    })
    return schema.json_safe(result)


def _json_number(v):
    """float for JSON, None for NaN (strict JSON has no NaN)."""
    v = float(v)
    return v if math.isfinite(v) else None


def _analyze(args):
    import matplotlib

    matplotlib.use("Agg")  # files only, no display needed
    from ..io import plotting
    from ..measure.analysis import analyze, count_peaks, load_joint_twist, load_polyline, symmetry_order, write_profiles_csv
    from ..validation import check_int_at_least

    say = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    if args.n_samples is not None:
        check_int_at_least("n_samples", args.n_samples, 4)
    if args.smoothing_modes is not None:
        check_int_at_least("smoothing_modes", args.smoothing_modes, 1)
    if args.out:
        _output_folder(args.out)
    eccentric = args.eccentric
    if eccentric is None:
        if os.path.splitext(args.centreline)[1].lower() != ".npz":
            raise ValueError(f"{args.centreline}: give the eccentric line too (a second file); only a study's step "
                             "file (steps/*.npz) holds both the centreline and the eccentric line")
        eccentric = args.centreline
    centre = load_polyline(args.centreline, array="x")
    ecc = load_polyline(eccentric, array="eccentric")
    closed = not args.open
    joint = args.joint_twist
    if joint is None and closed:  # the twist imposed on the simulated rod whose line this is
        joint = load_joint_twist(eccentric)
    res = analyze(centre, ecc, closed=closed, n_samples=args.n_samples, smoothing_modes=args.smoothing_modes,
                  joint_twist=joint)
    L = res.length
    n = int(res.s.shape[0])
    order = symmetry_order(res.kappa) if closed and n >= 8 else None
    peaks = count_peaks(res.kappa) if closed and n >= 8 else None
    result = {
        "Wr": res.Wr,
        "Tw": res.Tw,
        "Lk_frames": res.Lk_frames,
        "Lk_gauss": _json_number(res.Lk_exact),
        "Lk_quadrature": _json_number(res.Lk_quadrature),
        "Tw_integral": res.Tw_integral,
        "joint_twist": res.joint_twist,
        "joint_jump": _json_number(res.joint_jump),
        "length": L,
        "symmetry_order": order,
        "n_peaks": peaks,
        "n_samples": n,
        "closed": closed,
        "smoothing_modes": args.smoothing_modes,
        "n_unpaired": int(n - int(res.paired.sum())),
        "warnings": list(res.warnings),
        "centreline": os.path.abspath(args.centreline),
        "eccentric": os.path.abspath(eccentric),
    }
    if args.out:
        write_profiles_csv(res, os.path.join(args.out, "profiles.csv"))
        with open(os.path.join(args.out, "summary.json"), "w") as f:
            json.dump(result, f, indent=2)
        lk = "" if not closed else f", Lk = {res.Lk_exact:.0f}" if math.isfinite(res.Lk_exact) else \
            f", Lk = {res.Lk_frames:.4f}"
        plotting.plot_profiles(
            res.s / L, [(res.kappa * L, res.tau * L)], [os.path.basename(args.centreline)],
            path=os.path.join(args.out, "profiles.png"),
            title=f"Wr = {res.Wr:.4f}, Tw = {res.Tw:.4f}{lk}",
        )
        say(f"wrote {args.out}/profiles.csv, summary.json, profiles.png")
    if args.json:
        print(json.dumps(result))
    else:
        undefined = "n/a (open curve)" if not closed else "n/a (the line does not close at the joint)"
        fmt = lambda v: undefined if v is None or not math.isfinite(v) else f"{v:.10f}"  # noqa: E731
        print(f"Wr            = {res.Wr:.10f}")
        print(f"Tw            = {res.Tw:.10f}   (integral of tau: {res.Tw_integral:.10f})")
        print(f"Lk (frames)   = {res.Lk_frames:.10f}   (Wr + Tw)")
        print(f"Lk (Gauss)    = {fmt(res.Lk_exact)}   (exact polygon linking number)")
        print(f"Lk (quadr.)   = {fmt(res.Lk_quadrature)}   (midpoint Gauss quadrature)")
        if res.joint_twist is not None:
            print(f"joint twist   = {res.joint_twist:.10g}   ({res.joint_twist / math.pi:.6g} pi, "
                  f"line's jump at the joint {res.joint_jump:+.4f} turns)")
        print(f"length        = {L:.10g}   ({n} nodes)")
        if closed:
            print(f"kappa profile : symmetry order {order}, {peaks} peak(s)")
    return 0


def _trefoil(args):
    import matplotlib

    matplotlib.use("Agg")
    from ..validation import check_finite, check_int_at_least, check_poisson_ratio, check_positive
    from ..model.scenes import DEFAULT_CONTACT_STIFFNESS, IDEAL_ROPELENGTH, MIN_TREFOIL_NODES
    from ..io.locking import folder_lock
    from ..continuation import ContinuationOptions, Observer
    from ..studies.twist import check_study_folder, state_figures, study_options, study_summary, twist_study

    D, L = check_positive("D", args.D), check_positive("L", args.L)
    knot_name = "3_1" if args.command == "trefoil" else args.name
    if args.command == "knot" and (knot_name is None) == (args.curve is None):
        raise ValueError("give a knot (3_1, 4_1, 5_1 or 5_2) or --curve FILE" +
                         (", not both" if knot_name is not None else ""))
    if knot_name is not None and L / D < IDEAL_ROPELENGTH[knot_name]:
        raise ValueError(f"--L {args.L:g} / --D {args.D:g} = {L / D:.3f} is below the ideal {knot_name} knot's ropelength "
                         f"{IDEAL_ROPELENGTH[knot_name]}: no such knot exists (raise --L or lower --D)")
    need = math.ceil(L / D - 1e-9)
    if args.N is None:
        args.N = STUDY_NODES if args.accuracy is None else max(ACCURACY_NODES, need)
    check_int_at_least("N", args.N, MIN_TREFOIL_NODES)
    if args.N < need:
        raise ValueError(f"--N {args.N} gives edges of {L / args.N / D:.2f} D: self-contact needs edges no longer "
                         f"than the diameter: raise --N to at least L/D = {need}")
    check_positive("E", args.E)
    check_poisson_ratio("nu", args.nu)
    if args.contact_stiffness is not None:
        check_positive("contact_stiffness", args.contact_stiffness)
    for name in ("phi_min", "phi_max"):
        check_finite(name, getattr(args, name))
    if not args.phi_min < 0.0 < args.phi_max:
        raise ValueError(f"--phi-min must be < 0 < --phi-max, got --phi-min {args.phi_min / math.pi:g}pi, "
                         f"--phi-max {args.phi_max / math.pi:g}pi")
    check_positive("step", args.step)
    check_positive("tol", args.tol)
    _output_folder(args.out)
    args.hold(folder_lock(args.out))  # one run per folder, taken before any compilation
    stiffness = DEFAULT_CONTACT_STIFFNESS if args.contact_stiffness is None else args.contact_stiffness
    if args.accuracy is not None:
        check_positive("accuracy", args.accuracy)
        if args.N_max < 4 * args.N - 3:
            raise ValueError(f"--N-max {args.N_max} leaves fewer than three levels from --N {args.N} "
                             f"(N, 2N-1, 4N-3): give --N-max at least {4 * args.N - 3}")
        _check_knot_memory(args.N_max)
        return _accuracy(args, _study_scene(args, knot_name, stiffness), stiffness)
    _check_knot_memory(args.N)
    scene = _study_scene(args, knot_name, stiffness)
    options = ContinuationOptions(step=args.step, tol=args.tol)
    if not args.fresh:  # a folder of another run: refused now, not after the compilation
        check_study_folder(args.out, scene, args.phi_min, args.phi_max, options)
    bar = _Progress(args, (args.phi_max - args.phi_min) / math.pi, args.command)
    say = bar.say
    lk0 = "given" if getattr(args, "lk0", None) is not None else "the integer nearest the writhe as drawn"
    say(f"{scene.name}: D = {args.D}, L = {args.L}, N = {args.N}, nu = {args.nu}, kappa_c = {stiffness}, "
        f"Lk0 = {scene.Lk0:g} ({lk0}); "
        f"phi from {args.phi_min / math.pi:+.3f} pi to {args.phi_max / math.pi:+.3f} pi; writing {args.out}/")
    say(args.compile_notice)
    reached, counts = {"plus": 0.0, "minus": 0.0}, {"steps": 0}

    def on_point(direction, point):
        reached[direction] = max(reached[direction], abs(point.equilibrium.phi) / math.pi)
        counts["steps"] += 1
        bar.update(reached["plus"] + reached["minus"], steps=counts["steps"], branch=point.branch)
        if workers is not None and point.equilibrium.phi == (args.phi_max if direction == "plus" else args.phi_min):
            workers.add_worker()  # this direction is done: its core takes the queued ends

    title = f"{scene.name}, D/L = {args.D / args.L:.4f}, N = {args.N}"
    span = max(-args.phi_min, args.phi_max)
    announced, n_estimates = [], (args.N + 1) // 2  # the estimate's first line is said once

    def estimate_job(side, entry):
        """The N' = (N+1)/2 error estimate of one side's first end (``coarse_companion``)."""
        from ..studies.accuracy import coarse_companion

        def job(cancel):
            t_side = time.perf_counter()
            if not announced:
                announced.append(side)
                say(f"estimating the discretisation error of phi*: each end again at N = {n_estimates}")
            found = coarse_companion(scene, args.out, {"instabilities": [entry]}, span=span, step=args.step,
                                     tol=args.tol, progress=say, cancel=cancel, sides=(side,))
            return found.get(side), time.perf_counter() - t_side
        return job

    def end_job(direction, index, entry, state):
        """The exact location of one branch end and its unstable branch (``diagram.locate_end``)."""
        def job(cancel):
            from ..studies.diagram import end_capacity, end_rows, locate_end
            from ..studies.twist import critical_mode

            def stop(point):
                if cancel.is_set():
                    raise _Cancelled()
            # this end's own contact-list size: the same for every end of a loose knot (the size
            # does not depend on the state until a segment has more than 8 candidates)
            end = locate_end(scene, entry, state, p_min=args.phi_min, p_max=args.phi_max,
                             capacity=end_capacity(scene, [state]), progress=say, observer=stop,
                             mode=critical_mode(args.out, entry))
            if end.event is not None and end.event.converged:  # its rows too, while the study goes on
                end_rows(scene, end, options_k, entry["negative_tol"])
            return end
        return job

    # Each branch end's exact location and each side's error estimate are queued as soon as the
    # study has found that end, and run by worker threads, one started when a study direction
    # reaches its end of the range (``on_point``: on the core that direction leaves; started beside
    # the study's two threads they gained nothing), the second once the study is done. Before, a
    # core idled from the tightening side's end until the whole study was over (~4 s on command 1).
    # The results are those of the serial order (each job is independent).
    workers = None if args.serial else _Workers(start=False)
    options_k = study_options(options).k  # the eigenvalue columns of branch.csv
    wanted = {"ends": not args.stable_only, "estimate": not args.no_extrapolation}

    def on_end(direction, index, entry, state):
        if wanted["ends"]:
            workers.submit(("end", direction, index), end_job(direction, index, entry, state))
        if wanted["estimate"] and index == 0:
            workers.submit(("estimate", direction), estimate_job(direction, entry))

    from ..studies.twist import _Cancelled

    try:
        result = twist_study(scene, args.phi_min, args.phi_max, options, out=args.out, resume=not args.fresh,
                             parallel=not args.serial,
                             observer=Observer(progress=say, on_point=on_point,
                                               on_instability=None if workers is None else on_end))
    except BaseException:
        if workers is not None:
            workers.stop()
        raise
    finally:
        bar.close()
    summary = study_summary(result)
    drawn = None
    if not args.no_figures and not args.serial:
        # the states' figures need only the step files: drawn while the diagram runs
        drawn = _Workers()  # one job, in its own thread
        drawn.submit("states", lambda cancel: state_figures(args.out, title=title, length_unit="mm"))
    firsts = {}  # each side's first end (critical.json's entry)
    for c in result.critical["instabilities"]:
        firsts.setdefault(c["direction"], c)
    sides_with_end = [side for side in ("plus", "minus") if side in firsts]
    found, seconds_extrapolation = {}, 0.0
    try:
        located = {}
        if workers is not None:
            for side in sides_with_end:  # a resumed run: ends found before the interruption
                if wanted["estimate"] and ("estimate", side) not in workers.keys:
                    workers.submit(("estimate", side), estimate_job(side, firsts[side]))
            while workers.n_workers < 2:
                workers.add_worker()
            for key, value in workers.results().items():
                if key[0] == "end":
                    located[key[1:]] = value
                elif value[0] is not None:
                    found[key[1]] = value[0]
                    seconds_extrapolation += value[1]
        elif wanted["estimate"] and sides_with_end:
            for side in sides_with_end:
                level, seconds = estimate_job(side, firsts[side])(None)
                if level is not None:
                    found[side] = level
                seconds_extrapolation += seconds
        if not args.stable_only and result.end_states:
            from ..studies.diagram import unstable_branches

            t_diagram = time.perf_counter()
            diagram = unstable_branches(scene, result, progress=say, parallel=not args.serial, located=located)
            result = diagram.study
            summary = study_summary(result)
            # the ends' own wall time (most of it spent while the study ran) and the rest
            summary["seconds_diagram"] = time.perf_counter() - t_diagram + sum(
                end.seconds for end in located.values())
    except BaseException:
        for job in (workers, drawn):
            if job is not None:
                job.stop()
        raise
    summary.update({"D": args.D, "L": args.L, "N": args.N, "nu": args.nu, "contact_stiffness": stiffness,
                    "out": args.out})
    if wanted["estimate"] and sides_with_end:
        for side, (level, ext) in found.items():
            summary[f"phi_{side}_extrapolated"] = {"value": ext.value, "value_over_pi": ext.value / math.pi,
                                                   "error": ext.error, "error_over_pi": ext.error / math.pi,
                                                   "N": list(ext.N), "values": list(ext.values),
                                                   "order": ext.order, "order_measured": ext.order_measured}
        summary["seconds_extrapolation"] = seconds_extrapolation
    if args.command == "trefoil":
        summary["chirality"] = args.chirality
    else:
        summary.update({"knot": knot_name, "curve": args.curve})
    summary = _critical_json(summary, critical=result.critical)
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    if not args.no_figures:
        from ..studies.twist import branch_figures

        # pyplot's figure registry is shared: the states' figures are finished before these start
        states = drawn.results()["states"] if drawn is not None else state_figures(args.out, title=title,
                                                                                    length_unit="mm")
        paths = branch_figures(args.out, title=title) + states
        for path in paths:
            say(f"wrote {path}")
    if args.vtk:
        from ..io.export import export_study_vtk

        say(f"wrote {len(export_study_vtk(args.out))} VTK files into {args.out}/vtk/")
    if args.json:
        print(json.dumps(summary))
    else:
        for key in ("phi_plus", "phi_minus"):
            v = summary[key]
            print(f"{key:10s} = " + ("none in range" if v is None else f"{v:+.6f} rad = {v / math.pi:+.5f} pi"))
            ext = summary.get(key + "_extrapolated")
            if ext is not None:
                print(f"{'':10s}   at N = {args.N}, not converged in N: extrapolated {ext['value_over_pi']:+.3f} pi "
                      f"+- {ext['error_over_pi']:.2f} pi (from N = {ext['N'][0]} and {ext['N'][1]}, order 2 assumed; "
                      f"--accuracy 0.01pi for a converged value)")
        total = summary.get("seconds_total")
        resumed = f" ({total:.1f} s with the interrupted runs)" if total and total > summary["seconds"] + 0.05 else ""
        side = summary.get("tightening_side")
        if side == "equal":
            side = "neither (the two sides are mirror images within round-off)"
        print(f"tightening side: {side}; time {summary['seconds']:.1f} s{resumed}; data in {args.out}/")
    return 0


def _critical_json(summary, critical=None, convergence=None):
    """The JSON object of a trefoil or knot run, whichever the mode (printed by --json; the twist
    study writes it to summary.json too): the critical twists first, under jaxrod.io.schema's
    both-sides keys (phi_plus, phi_plus_over_pi, phi_plus_error, phi_plus_kind, phi_minus, ...),
    then the mode's other keys from ``summary``. The one place where these commands name them.

    The twist study (with or without --stable-only): ``summary`` is its study_summary (phi_plus,
    phi_plus_error, phi_plus_located, ...) and ``critical`` its critical.json; each side's kind is
    that of its located end, else that of its first instability. --accuracy: ``convergence``
    {side: SideConvergence}; each side's details (levels, extrapolation, reached, ...) under
    "plus" / "minus", with the one-side keys (phi_star, phi_error, kind, ...) among them."""
    from ..io import schema

    records, details = {}, {}
    if convergence is not None:
        for side, r in convergence.items():
            records[side] = schema.side_record(side, r.phi_star, r.error, r.levels[-1].kind if r.levels else None)
            details[side] = {**r.as_json(), **records[side]}  # "error": the former name of phi_error
    else:
        for side in schema.SIDES:
            located = summary.get(f"phi_{side}_located")
            firsts = [c for c in (critical or {}).get("instabilities", []) if c.get("direction") == side]
            kind = located.get("kind") if isinstance(located, dict) else firsts[0].get("kind") if firsts else None
            records[side] = schema.side_record(side, summary.get(f"phi_{side}"), summary.get(f"phi_{side}_error"),
                                               kind)
    out = schema.both_sides(records)
    out.update(details)
    out.update((key, value) for key, value in summary.items() if key not in out)
    return schema.json_safe(out)


class _Workers:
    """Jobs run by worker threads in the order they were submitted: ``submit(key, fn)`` queues
    fn(cancel); ``add_worker()`` starts one more thread (one is started at once, unless
    start=False); ``results()``
    waits until every job has run (in short waits, so that Ctrl-C still reaches the main thread)
    and returns {key: value}, or raises the first job's exception; ``stop()`` sets ``cancel`` (a
    job stops at its next point), drops the jobs not started and waits until every thread has left
    XLA. Used from several threads: the study's threads submit, the main thread collects."""

    def __init__(self, start=True):
        import collections
        import threading

        self._threading = threading
        self._jobs = collections.deque()
        self._wake = threading.Condition()
        self._cancel = threading.Event()
        self._closed = False
        self._values, self._errors, self._done = {}, [], []
        self.keys = set()
        if start:
            self.add_worker()

    @property
    def n_workers(self):
        return len(self._done)

    def submit(self, key, fn):
        with self._wake:
            self.keys.add(key)
            self._jobs.append((key, fn))
            self._wake.notify()

    def add_worker(self):
        done = self._threading.Event()
        self._done.append(done)

        def loop():
            try:
                while True:
                    with self._wake:
                        while not self._jobs and not self._closed:
                            self._wake.wait(0.2)
                        if not self._jobs:
                            return
                        key, fn = self._jobs.popleft()
                    if self._cancel.is_set():
                        continue
                    try:
                        self._values[key] = fn(self._cancel)
                    except BaseException as exc:  # noqa: BLE001 -- handed to the main thread
                        if not self._cancel.is_set():
                            self._errors.append(exc)
                        self._cancel.set()  # the first failure ends the others' work too
            finally:
                done.set()

        self._threading.Thread(target=loop, daemon=True).start()

    def _close(self):
        with self._wake:
            self._closed = True
            self._wake.notify_all()

    def _wait(self):
        for done in list(self._done):
            while not done.wait(0.2):
                pass

    def results(self):
        self._close()
        try:
            self._wait()
        except BaseException:  # Ctrl-C while waiting: stop the threads first
            self.stop()
            raise
        if self._errors:
            raise self._errors[0]
        return dict(self._values)

    def stop(self):
        self._cancel.set()
        with self._wake:
            self._jobs.clear()
        self._close()
        self._wait()


def _accuracy(args, scene, stiffness):
    """--accuracy: both sides' first branch ends converged in N (jaxrod.studies.accuracy), written to
    --out (levels/ as they are found, convergence.json, convergence.csv, convergence.png)."""
    import csv

    from ..studies.accuracy import converged_critical_twists, resolution_levels

    if args.fresh:
        import shutil

        shutil.rmtree(os.path.join(args.out, "levels"), ignore_errors=True)
    levels = resolution_levels(args.N, args.N_max)
    bar = _Progress(args, 0, args.command)
    say = bar.say
    say(f"{scene.name}: D = {args.D}, L = {args.L}, nu = {args.nu}, kappa_c = {stiffness}; critical twists to "
        f"{args.accuracy / math.pi:g} pi, N = {', '.join(map(str, levels))} at most; writing {args.out}/")
    say(args.compile_notice)
    t0 = time.perf_counter()
    try:
        result = converged_critical_twists(scene, args.accuracy, N_max=args.N_max, span=max(-args.phi_min, args.phi_max),
                                           step=args.step, progress=say, parallel=not args.serial, out=args.out)
    finally:
        bar.close()
    seconds = time.perf_counter() - t0
    with open(os.path.join(args.out, "convergence.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["side", "N", "phi_star", "phi_star_over_pi", "phi_error", "kind", "seconds"])
        for side, r in result.items():
            for lv in r.levels:
                w.writerow([side, lv.N, repr(lv.phi_star), repr(lv.phi_star / math.pi), repr(lv.phi_error), lv.kind,
                            f"{lv.seconds:.3f}"])
    if not args.no_figures:
        from ..io.plotting import plot_resolution_convergence

        path = os.path.join(args.out, "convergence.png")
        plot_resolution_convergence(result, path, title=f"{scene.name}, D/L = {args.D / args.L:.4f}: "
                                                        f"critical twists converged in N")
        say(f"wrote {path}")
    summary = _critical_json({"D": args.D, "L": args.L, "nu": args.nu, "contact_stiffness": stiffness,
                              "accuracy": args.accuracy, "seconds": seconds, "out": args.out}, convergence=result)
    if args.json:
        print(json.dumps(summary))
    else:
        for side, key in (("plus", "phi_plus"), ("minus", "phi_minus")):
            r = result[side]
            ns = "/".join(str(lv.N) for lv in r.levels)
            print(f"{key:10s} = {r.phi_star / math.pi:+.5f} pi +- {r.error / math.pi:.1e} pi "
                  f"(N = {ns}, order {r.extrapolation.order:.2f}) " + ("" if r.reached else f"NOT CONVERGED: {r.reason}"))
        print(f"time {seconds:.1f} s; data in {args.out}/")
    return 0 if all(r.reached for r in result.values()) else 1


def _check_knot_memory(n_nodes):
    """Refuse a knot whose dense Hessian cannot fit in memory now: before the scene is built (its
    O(N^2) checks take 30 s at N = 10000) and before anything is compiled (issue 16: N = 10000
    died in XLA after 46 s). A closed rod has 4 DOFs per node (3 coordinates, 1 twist angle)."""
    from types import SimpleNamespace

    from ..continuation import check_dense_memory

    try:
        check_dense_memory(SimpleNamespace(n_dof=4 * n_nodes, n_nodes=n_nodes))
    except ValueError as exc:
        raise ValueError(str(exc).replace("use N at most", "use --N at most")) from None


def _study_scene(args, name, stiffness):
    """The knot of a trefoil / knot study: a named knot, or the closed curve of --curve."""
    from ..model.scenes import closed_curve, knot, trefoil

    if args.command == "trefoil":
        return trefoil(args.D, args.L, args.N, E=args.E, nu=args.nu, chirality=args.chirality,
                       contact_stiffness=stiffness)
    if name is not None:
        return knot(name, args.D, args.L, args.N, E=args.E, nu=args.nu, contact_stiffness=stiffness, Lk0=args.lk0)
    from ..measure.analysis import load_polyline
    from ..model.material import Material

    points = load_polyline(args.curve)
    try:
        return closed_curve(points, Material.from_engineering(args.E, args.nu, args.D), N=args.N, length=args.L,
                            name=f"closed curve from {os.path.basename(args.curve)}", contact_stiffness=stiffness,
                            Lk0=args.lk0)
    except ValueError as exc:
        raise ValueError(f"--curve {args.curve}: {exc}") from None


def _atlas(args):
    import matplotlib

    matplotlib.use("Agg")
    from ..studies import atlas
    from ..io.locking import folder_lock
    from ..validation import check_int_at_least

    knots = [k.strip() for k in args.knots.split(",") if k.strip()]
    unknown = [k for k in knots if k not in atlas.KNOTS]
    if unknown or not knots:
        raise ValueError(f"--knots: unknown knot(s) {', '.join(unknown) or '(none given)'}; "
                         f"choose from {','.join(atlas.KNOTS)}")
    ratios = _number_list("--ratios", args.ratios, float)
    ns = _number_list("--N", args.N, int)
    settings = atlas.AtlasSettings(span=args.span, step=args.step, tol=args.tol, nu=args.nu,
                                   contact_stiffness=args.contact_stiffness)
    check_int_at_least("workers", args.workers, 1)
    _output_folder(args.out)
    args.hold(folder_lock(args.out))
    sides = [v.strip() for v in args.sides.split(",") if v.strip()]
    cases = atlas.atlas_cases(knots, ratios, ns, settings, sides)  # every case checked before any work
    bar = _Progress(args, len(cases), "atlas", counting="cases")
    say = bar.say
    say(f"atlas: {len(knots)} knot(s) x {len(set(ratios))} D/L x {len(set(ns))} N x {len(sides)} side(s) = "
        f"{len(cases)} cases; "
        f"writing {args.out}/")
    say(args.compile_notice)
    t0 = time.perf_counter()

    def on_row(row, done, total):
        phi = f"{row['phi_star'] / math.pi:+.4f} pi ({row['kind']})" if math.isfinite(row["phi_star"]) else \
            f"none within {'+' if row['side'] == 'plus' else '-'}{args.span / math.pi:g} pi"
        say(f"[{done}/{total}] {row['knot']} D/L = {row['D_over_L']:g} N = {row['N']} {row['side']}: phi* = {phi}, "
            f"{row['seconds']:.1f} s")
        bar.update(done)

    client = cluster = None
    try:
        if args.scheduler is not None or args.workers > 1:
            try:
                from distributed import Client, LocalCluster
            except ImportError:
                raise ValueError("--workers / --scheduler need Dask: pip install 'dask[distributed]'") from None
            if args.scheduler is not None:
                say(f"connecting to the Dask scheduler at {args.scheduler}")
                try:
                    client = Client(args.scheduler, timeout="20s")
                except OSError as exc:
                    raise ValueError(f"--scheduler {args.scheduler}: cannot connect ({exc})") from None
            else:
                say(f"starting a local Dask cluster of {args.workers} worker processes")
                cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, dashboard_address=None)
                client = Client(cluster)
        rows = atlas.run_atlas(knots, ratios, ns, settings=settings, out=args.out, client=client, fresh=args.fresh,
                               on_row=on_row, sides=sides)
    finally:
        bar.close()
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    say(f"wrote {atlas.report(args.out)}")
    if not args.no_figures:
        say(f"wrote {atlas.figures(args.out)}")
    if args.json:
        print(json.dumps(_atlas_json(rows)))
    else:
        for r in rows:
            phi = f"{r['phi_star'] / math.pi:+.4f} pi" if math.isfinite(r["phi_star"]) else "none"
            print(f"{r['knot']:4s} D/L = {r['D_over_L']:<7g} N = {r['N']:<4d} {r['side']:5s} phi* = {phi}")
        print(f"time {time.perf_counter() - t0:.1f} s; data in {args.out}/")
    return 0


def _atlas_json(rows):
    """atlas's JSON: {"rows": [...]}, a row per case with atlas.csv's columns, its critical twist
    under jaxrod.io.schema's one-side keys (side, phi_star, phi_star_over_pi, phi_error, kind: null,
    not NaN or 'none', where the side has no end within the span)."""
    from ..io import schema

    return schema.json_safe({"rows": [{**r, **schema.side_record(r["side"], r["phi_star"], r["phi_error"], r["kind"])}
                                      for r in rows]})


def _number_list(flag, text, kind):
    try:
        values = [kind(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"{flag} must be a comma-separated list of numbers, got {text!r}") from None
    if not values:
        raise ValueError(f"{flag}: give at least one value")
    return values


# Options whose value is an angle such as -12pi: argparse would read a leading '-' as an option.
_ANGLE_OPTIONS = ("--phi-min", "--phi-max", "--step", "--tol", "--span", "--accuracy", "--joint-twist", "--R")


def _join_angle_values(argv):
    out, i = [], 0
    while i < len(argv):
        if argv[i] in _ANGLE_OPTIONS and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def _warn_in_one_line(message, category, filename, lineno, file=None, line=None):
    print(f"jaxrod: warning: {message}", file=sys.stderr, flush=True)


_CURVE_HELP = """\
A knot's critical twists as curves in its slenderness, phi*+-(D/L): D varied at fixed L, N, E and
nu (B, C ~ D^4, contact at D). Each row is the first instability of the branch from phi = 0 at its
ratio, found as the point study (jaxrod trefoil / jaxrod knot) finds it: the knot relaxed to a
minimum at phi = 0, followed by the stable-only engine to each side's first end, and that end
located on its extended system (a fold or a branch point); so a row equals the point study's
phi_plus / phi_minus at the same N. Each located row also gives its Morse index across the event,
critical eigenvalue, residual and dphi*/d(D/L) from the implicit function theorem on its extended
system, checked at the end against the secant of its neighbours of the same kind (secant_slope,
slope_disagreement; a warning names the rows where they differ by more than 50 %). Where the kind
of the first instability changes from one ratio to the next, the row is marked (switched,
previous_kind) and a warning names it; no slope is compared across it. Where the point study does
not take its located end as the onset (outside its bracket, or not its critical mode) the row keeps
the study's bracket estimate, as the point study does (kind "bracketed", a warning).

Writes into --out: critical_curve.csv (a row per point, as they come), critical_curve.json and
critical_curve.png (with Michell's ring line and its double). Each ratio's result is also kept
(points/): an interrupted run given the same command does only the ratios not on file; --fresh
starts over.

examples:
  jaxrod critical-curve --ratios 0.018:0.032:0.002 --N 61 --out results/critical_curve
  jaxrod critical-curve --ratios 0.026,0.0274,0.029 --N 121 --sides plus --out results/curve_plus
"""


def _critical_curve(args):
    import json

    import matplotlib

    matplotlib.use("Agg")
    from ..studies.critical_curve import CriticalCurveOptions, check_ratio_range, critical_twist_curve, json_ready
    from ..io.locking import folder_lock
    from ..validation import check_poisson_ratio

    ratios = check_ratio_range(args.ratios)
    sides = tuple(x.strip() for x in args.sides.split(",") if x.strip())
    opts = CriticalCurveOptions(sides=sides, start_ratio=args.start, span=args.span,
                                nu=check_poisson_ratio("nu", args.nu), contact_stiffness=args.contact_stiffness)
    args.hold(folder_lock(args.out))
    bar = _Progress(args, len(ratios) * len(opts.sides), "critical curve", counting="points")
    done = [0]

    def say(line):
        bar.say(line)
        if line.startswith("[") and "D/L = " in line and ("Morse" in line or ": no row:" in line):
            done[0] += 1
            bar.update(done[0])

    say(args.compile_notice)
    try:
        result = critical_twist_curve(args.knot, args.N, ratios, opts, out=args.out, progress=say, fresh=args.fresh)
    finally:
        bar.close()
    switched = f", {len(result['switches'])} switch(es) of kind" if result["switches"] else ""
    missing = f", {len(result['failures'])} without an instability" if result["failures"] else ""
    say(f"{len(result['rows'])} points{switched}{missing} in {result['seconds']:.0f} s; results in {args.out}/")
    if args.json:
        print(json.dumps(json_ready(result), allow_nan=False))
    return 0


_HELIX_HELP = """\
Localized helical buckling of a clamped rod (Neukirch, van der Heijden & Thompson 2002, J. Mech.
Phys. Solids 50, eqs. 14-15): a rod of length L clamped at both ends along one axis, the far clamp
moved closer by the end shortening d L and turned by the end rotation R, solved from the analytic
loop by Newton. Give the loads (--m M L/B, --t T L^2/B) or the imposed ends (--d, --R; either
sign: the mirror image has (-m, t)); the material by --nu (C/B = 1/(1 + nu)), --gamma (C/B) or
--B and --C, and EA by --slenderness or --EA. Reports the end moment M and tension T (exact
derivatives of the energy), theta_max, Lk = Wr + Tw (= R / 2 pi), the Morse index, and the
analytic values beside them, with Richardson's extrapolation from N and about N/2 where both
resolve the loop. The formulas are those of an infinite inextensible rod: where the loop is not
localized (lambda = sqrt(t - m^2/4) < 13) or the stretch shifts t by more than 1e-4, the
analytic values are reported as not applicable (reference_valid: false, with the reason) and
no error is computed; --strict refuses such a case instead.
At given (d, R) the formulas have up to two loops (small and large t): --root stable (default)
solves each and takes the stable one (Morse index 0 under fixed ends; if none or both are, the
larger t), --root small / large takes that one, --root both reports both in full.
--sweep K also follows the loop along K end rotations from 0.8 R to 1.1 R at the same shortening
(M, T and stability along the path).

Writes into --out: helix.json (summary), centreline.csv, envelope.csv (s/L, theta numeric and
analytic), centreline.png, envelope.png and, with --sweep, path.csv and loads.png.

examples:
  jaxrod helix --m 20 --t 300 --N 240 --out results/helix
  jaxrod helix --d 0.13 --R 13pi --nu 0.3 --root large --sweep 9 --out results/helix_sweep
  jaxrod helix --d 0.1886 --R=-43.82 --B 2 --C 1 --root both
"""


@dataclasses.dataclass
class _HelixCase:
    """The helix command's input, checked: N nodes; the material (B, C, nu, gamma = C/B, D the
    slenderness, EA, ea = EA L^2/B with L = 1); sweep, the number of end rotations to follow;
    refs, the analytic loops to solve as (name, LocalizedHelix), of n_found at the imposed ends;
    checks, each one's ReferenceCheck by name; resolved, those N resolves, and refused, those it
    does not, as (name, LocalizedHelix, why)."""

    N: int
    B: float
    C: float
    nu: float
    gamma: float
    D: float
    EA: float
    sweep: int
    refs: list
    n_found: int
    checks: dict
    resolved: list
    refused: list

    @property
    def ea(self):
        return self.EA / self.B  # EA L^2 / B, L = 1


@dataclasses.dataclass
class _SolvedHelixRoot:
    """A root as solved at N: its analytic loop ref, the rod, its equilibrium eq and state
    (``endloads.helix_state``), or eq and state None and the ConvergenceError where Newton failed."""

    ref: object
    rod: object
    eq: object
    state: dict
    error: Exception


def _helix(args):
    import matplotlib

    matplotlib.use("Agg")
    from ..studies import endloads as el
    from ..io.locking import folder_lock
    from ..model.material import Material

    case = _helix_case(args)
    if args.out:
        _output_folder(args.out)
        args.hold(folder_lock(args.out))
    extrapolate = not args.no_extrapolate
    bar = _Progress(args, len(case.resolved) + case.sweep + int(extrapolate), "helix", counting="states")
    _announce_helix_roots(bar.say, case)
    bar.say(args.compile_notice)
    t0 = time.perf_counter()
    material = Material(B=case.B, C=case.C, EA=case.EA, D=case.D)
    try:
        solved = _solve_helix_roots(case, material, bar)
        if all(root.eq is None for root in solved.values()):
            return _no_helix_equilibrium(solved)
        taken, why = _take_helix_root(args, case, solved)
        root = solved[taken]
        bar.say(f"taken: the {taken} root (t = {root.ref.t:.6g}): {why}")
        t_roundoff = _warn_about_helix_reference(case, taken, root.state["T"])
        extra = _no_helix_extrapolation()
        if extrapolate:
            extra = _helix_extrapolation(case, material, root, case.checks[taken].valid, bar.say)
            bar.update(len(solved) + 1)
        path, stopped = [], []
        if case.sweep:
            path, stopped = _helix_sweep(case, root, bar, len(solved) + int(extrapolate))
    finally:
        bar.close()
    seconds = time.perf_counter() - t0
    profiles = el.helix_profiles(root.eq.x, root.ref)
    result = _helix_result(case, solved, taken, why, t_roundoff, extra)
    result.update(_helix_shape_errors(root, profiles, result["reference_valid"]),
                  newton_steps=root.eq.solution.iterations, seconds=seconds, path=path, sweep_stopped_at=stopped)
    if args.out:
        _write_helix_files(args.out, case, result, profiles, bar.say)
    if args.json:
        print(json.dumps(result))
    else:
        _print_helix(args, case, solved, result)
    return 0


def _helix_case(args):
    """The helix command's ``_HelixCase`` from its arguments; ValueError (bad input) naming the flag."""
    from ..studies import endloads as el
    from ..validation import check_int_at_least

    N = check_int_at_least("N", args.N, 8)
    B, C, nu, gamma, D, EA = _helix_material(args)
    sweep = check_int_at_least("sweep", args.sweep, 0)
    refs, n_found = _helix_roots_asked(args, gamma)
    checks = {name: el.reference_check(h, EA / B) for name, h in refs}
    if args.strict:
        refs = _helix_roots_that_apply(refs, checks)
    resolved, refused = _helix_roots_resolved(N, refs)
    return _HelixCase(N=N, B=B, C=C, nu=nu, gamma=gamma, D=D, EA=EA, sweep=sweep, refs=refs, n_found=n_found,
                      checks=checks, resolved=resolved, refused=refused)


def _helix_material(args):
    """(B, C, nu, gamma, D, EA): B from --B (default 1) and C = gamma B, gamma from one of --C,
    --gamma and --nu (default nu = 0.5); the slenderness D = D/L (below 0.1) and EA from --EA or
    16 B / D^2 (a solid round rod)."""
    from ..validation import check_poisson_ratio, check_positive

    B = 1.0 if args.B is None else check_positive("B", args.B)
    given = [flag for flag, v in (("--nu", args.nu), ("--gamma", args.gamma), ("--C", args.C)) if v is not None]
    if len(given) > 1:
        raise ValueError(f"give one of --nu, --gamma and --C (the twist stiffness), not {' and '.join(given)}")
    if args.C is not None:
        gamma = check_positive("C", args.C) / B
    elif args.gamma is not None:
        gamma = check_positive("gamma", args.gamma)
    else:
        gamma = 1.0 / (1.0 + check_poisson_ratio("nu", 0.5 if args.nu is None else args.nu))
    C, nu = gamma * B, 1.0 / gamma - 1.0
    D = check_positive("slenderness", args.slenderness)
    if not D < 0.1:
        raise ValueError(f"--slenderness (D/L) must be below 0.1, got {D!r}")
    EA = 16.0 * B / D ** 2 if args.EA is None else check_positive("EA", args.EA)
    return B, C, nu, gamma, D, EA


def _helix_given_by_loads(args):
    """True for --m and --t (the loads), False for --d and --R (the ends); ValueError unless one
    pair is given, in full."""
    by_loads, by_ends = args.m is not None or args.t is not None, args.d is not None or args.R is not None
    if by_loads == by_ends or (by_loads and (args.m is None or args.t is None)) or \
            (by_ends and (args.d is None or args.R is None)):
        raise ValueError("give either --m and --t (loads) or --d and --R (end shortening and rotation)")
    return by_loads


def _helix_roots_asked(args, gamma):
    """(refs, n_found): the analytic loops to solve, as (name, LocalizedHelix), for the loads or
    the ends given and --root, and how many loops the ends have (1 for given loads)."""
    from ..studies import endloads as el
    from ..validation import check_finite, check_positive

    if _helix_given_by_loads(args):
        if args.root not in ("stable", "both"):
            raise ValueError(f"--root {args.root} chooses between the loops at given --d and --R; --m and --t give one")
        return [("only", el.localized_helix(check_finite("m", args.m), args.t, gamma))], 1
    d = check_positive("d", args.d)
    if not d < 1.0:
        raise ValueError(f"--d (end shortening / L) must be below 1, got {d!r}")
    found = el.localized_helix_from_shortening(d, check_finite("R", args.R), gamma)  # ascending in t
    if not found:
        raise ValueError(f"--d {d:g} --R {args.R:g}: no localized helix (NvdHT 2002 eqs. 14-15) has this end "
                         f"shortening and rotation at gamma = C/B = {gamma:.4g}: change --R or --d")
    return el.select_helix_roots(el.named_helix_roots(found), args.root), len(found)


def _helix_roots_that_apply(refs, checks):
    """--strict: the roots whose analytic reference applies; ValueError with the reasons if none does."""
    invalid = [f"{name} root (m = {h.m:.4g}, t = {h.t:.4g}): {checks[name].reason}" for name, h in refs
               if not checks[name].valid]
    refs = [(name, h) for name, h in refs if checks[name].valid]
    if not refs:
        raise ValueError("--strict: the analytic reference (NvdHT 2002) does not apply: " + "; ".join(invalid))
    return refs


def _helix_roots_resolved(N, refs):
    """(resolved, refused): the roots N nodes resolve, and those it does not as (name, helix,
    why); every loop solved must be resolved, so ValueError (the first why) where none is."""
    from ..studies import endloads as el

    resolved, refused = [], []
    for name, h in refs:
        try:
            el.check_helix_resolution(N, h.m, h.t, h.R)
            resolved.append((name, h))
        except ValueError as exc:
            refused.append((name, h, str(exc)))
    if not resolved:
        raise ValueError(refused[0][2])
    return resolved, refused


def _announce_helix_roots(say, case):
    """The roots to solve, and those left out, on the progress line."""
    for name, h in case.resolved:
        say(f"localized helix ({name} root): m = {h.m:.6g}, t = {h.t:.6g}, gamma = {case.gamma:.4g}: d = {h.d:.6g}, "
            f"R = {h.R:.6g} rad ({h.R / (2 * math.pi):.4g} turns), lambda = {h.lam:.4g}; N = {case.N}")
    for name, h, why in case.refused:
        say(f"{name} root (m = {h.m:.6g}, t = {h.t:.6g}) left out: {why}")


def _solve_helix_roots(case, material, bar):
    """{name: _SolvedHelixRoot} of each resolved root, solved from its analytic loop, in order."""
    from ..studies import endloads as el
    from ..solve.solvers import ConvergenceError

    solved = {}
    for name, h in case.resolved:
        rod = el.shortened_rod(case.N, 1.0, material, shortening=h.d)
        try:
            e = el.solve_from_helix(rod, h.m, h.t, h.R, k=4)
        except ConvergenceError as exc:
            sol = exc.solution
            bar.say(f"{name} root: no equilibrium reached from the analytic loop" + ("" if sol is None else
                    f" ({sol.reason} after {sol.iterations} Newton steps, |gradient| {sol.grad_norm:.2e})"))
            solved[name] = _SolvedHelixRoot(h, rod, None, None, exc)
            continue
        st = el.helix_state(rod, e, h.R, h, case.B, case.ea)
        solved[name] = _SolvedHelixRoot(h, rod, e, st, None)
        bar.update(len(solved))
        bar.say(f"{name} root solved: m = {st['m']:.6g} (analytic {h.m:.6g}), t = {st['t']:.6g} (analytic "
                f"{h.t:.6g}), Morse index {st['morse']} ({e.solution.iterations} Newton steps in the last stage)")
    return solved


def _no_helix_equilibrium(solved):
    """Exit status 1, with the first root's failure on stderr and what to change."""
    exc = next(iter(solved.values())).error
    print(f"jaxrod: error: no equilibrium found near the analytic loop: raise --N (at least 6 edges per "
          f"loop core L/lambda), or move the loads away from the straight rod's threshold m^2 = 4 t "
          f"({str(exc).splitlines()[0][:160]})", file=sys.stderr)
    return 1


def _take_helix_root(args, case, solved):
    """(name, reason) of the root taken among those solved (``endloads.choose_helix_root``)."""
    from ..studies import endloads as el

    candidates = [(name, root.ref.t, root.state["stable"]) for name, root in solved.items() if root.eq is not None]
    return el.choose_helix_root(candidates, case.n_found, args.root)


def _warn_about_helix_reference(case, taken, T):
    """Warns where the analytic reference does not apply to the root taken, or where its tension
    T carries a roundoff above 1e-4 relative; returns that roundoff."""
    import warnings

    from ..studies import endloads as el

    check = case.checks[taken]
    if not check.valid:
        warnings.warn(f"the analytic reference (NvdHT 2002) does not apply to the {taken} root: {check.reason}; "
                      "no error against it is computed", stacklevel=1)
    t_roundoff = el.tension_roundoff(case.N, case.EA, T)
    if t_roundoff > 1e-4:
        warnings.warn(f"EA L^2/B = {case.ea:.3g} is so stiff that T carries a roundoff of ~{t_roundoff:.1e} "
                      "relative (EA times the roundoff of a strain)", stacklevel=1)
    return t_roundoff


def _no_helix_extrapolation():
    return {"N_coarse": None, "m_extrapolated": None, "t_extrapolated": None,
            "m_extrapolated_rel_error": None, "t_extrapolated_rel_error": None, "extrapolation_note": None}


def _helix_extrapolation(case, material, root, valid, say):
    """The extrapolation's result keys (``_no_helix_extrapolation``) for the root taken: Richardson's
    (O(h^2)) from N and the coarse rod (edges twice as long), relative errors where the reference
    applies (valid), or the note why it is not extrapolated."""
    from ..studies import endloads as el
    from ..solve.solvers import ConvergenceError

    N, ref, coarse_N = case.N, root.ref, el.coarse_nodes(case.N)
    extra = _no_helix_extrapolation()
    try:
        el.check_helix_resolution(coarse_N, ref.m, ref.t, ref.R)
        rod_c = el.shortened_rod(coarse_N, 1.0, material, shortening=ref.d)
        e_c = el.solve_from_helix(rod_c, ref.m, ref.t, ref.R, with_stability=False)
        loads_c = el.end_loads(rod_c, e_c.q, ref.R, e_c.neighbourhood)
        m_x = el.richardson_extrapolation(root.state["m"], loads_c.M / case.B, N, coarse_N)
        t_x = el.richardson_extrapolation(root.state["t"], loads_c.T / case.B, N, coarse_N)
        extra.update(N_coarse=coarse_N, m_extrapolated=m_x, t_extrapolated=t_x,
                     m_extrapolated_rel_error=el.relative_error(m_x, ref.m, valid),
                     t_extrapolated_rel_error=el.relative_error(t_x, ref.t, valid))
        say(f"Richardson (N = {coarse_N}, {N}): m = {m_x:.6g}, t = {t_x:.6g}")
    except ValueError as exc:
        extra["extrapolation_note"] = f"not extrapolated: the coarse rod (N = {coarse_N}) is refused: {exc}"
        say(extra["extrapolation_note"])
    except ConvergenceError:
        extra["extrapolation_note"] = f"not extrapolated: no equilibrium reached at N = {coarse_N}"
        say(extra["extrapolation_note"])
    return extra


def _helix_sweep(case, root, bar, done):
    """(path, stopped): the root taken followed along case.sweep end rotations from 0.8 R to 1.1 R
    at the same shortening, each solved from its neighbour outwards from R (at fixed d the
    analytic loop exists up to a fold in R: a side stops where Newton finds none); path, the
    states (``endloads.helix_state``) ascending in R, and stopped, the rotations where a side
    stopped. done: the states counted on the bar before the sweep."""
    import numpy as np

    R = root.ref.R
    Rs = np.linspace(0.8 * R, 1.1 * R, case.sweep)
    path, stopped = [root.state], []
    for side in (np.sort(Rs[Rs >= R]), np.sort(Rs[Rs < R])[::-1]):
        stop = _helix_sweep_side(case, root, side, path, bar, done)
        if stop is not None:
            stopped.append(stop)
    path.sort(key=lambda r: r["R"])
    return path, stopped


def _helix_sweep_side(case, root, side, path, bar, done):
    """Follows the root taken along the end rotations ``side`` (outwards from its own), appending
    each state to path; returns the rotation where Newton found no equilibrium, or None."""
    from ..studies import endloads as el
    from ..solve.solvers import ConvergenceError

    rod, prev = root.rod, root.eq
    for R in side:
        try:
            el.check_rotation_resolution(case.N, R)
            # continuation in sub-steps of at most 0.25 rad (Newton alone does not follow larger ones)
            R0 = float(prev.phi)
            n_sub = max(1, math.ceil(abs(float(R) - R0) / 0.25))
            for j in range(1, n_sub):
                prev = el.solve(rod, R0 + (float(R) - R0) * j / n_sub, prev.q, with_stability=False)
            prev = el.solve(rod, float(R), prev.q, k=4)
            loads = el.end_loads(rod, prev.q, float(R), prev.neighbourhood)
            h = el.nearest_localized_helix(root.ref.d, float(R), case.gamma, loads.M / case.B, loads.T / case.B)
            path.append(el.helix_state(rod, prev, float(R), h, case.B, case.ea))
            bar.update(done + len(path))
            bar.say(f"R = {R:.5g}: m = {path[-1]['m']:.6g}, t = {path[-1]['t']:.6g}, Morse {path[-1]['morse']}")
        except ConvergenceError:
            bar.say(f"R = {R:.5g}: no equilibrium reached from R = {float(prev.phi):.5g} (past a fold?): "
                    "this side of the sweep stops")
            return float(R)
    return None


def _helix_result(case, solved, taken, why, t_roundoff, extra):
    """The helix summary (helix.json, --json) up to the envelope's comparison: the input, the
    taken root's state beside its reference, every root's comparison, the extrapolation."""
    from ..studies import endloads as el

    root, check = solved[taken], case.checks[taken]
    ref, main, valid = root.ref, root.state, check.valid
    roots = []
    for name, h in case.refs:
        r = solved.get(name)
        note = None if r is not None else next((w for n_, _, w in case.refused if n_ == name), None)
        roots.append(el.helix_root_row(name, h, case.checks[name], None if r is None else r.state,
                                       attempted=r is not None, note=note))
    return {"N": case.N, "B": case.B, "C": case.C, "EA": case.EA, "nu": case.nu, "gamma": case.gamma,
            "slenderness": case.D, "d": ref.d, "lambda": ref.lam, **main, "reference_valid": valid,
            "reference_reason": check.reason, "stretch": check.stretch, "t_roundoff": t_roundoff, "root": taken,
            "root_reason": why, "roots": roots, "m_rel_error": el.relative_error(main["m"], ref.m, valid),
            "t_rel_error": el.relative_error(main["t"], ref.t, valid), **extra}


def _helix_shape_errors(root, profiles, valid):
    """The loop's shape against the reference where it applies (valid; else None): envelope_L1,
    the L1 error of the tangent angle, and centreline_max_distance (units of L)."""
    from ..studies import endloads as el

    return {"envelope_L1": el.envelope_error(root.eq.x, root.ref.m, root.ref.t, 1.0) if valid else None,
            "centreline_max_distance": profiles.max_distance() if valid else None}


def _write_helix_files(out, case, result, profiles, say):
    """Writes helix.json, centreline.csv, envelope.csv, centreline.png, envelope.png and, with a
    sweep, path.csv and loads.png into out."""
    from ..io import plotting  # noqa: F401  (matplotlib's style)

    with open(os.path.join(out, "helix.json"), "w") as f:
        json.dump(result, f, indent=2)
    p = profiles
    _write_helix_csv(os.path.join(out, "centreline.csv"), ["s_over_L", "x", "y", "z", "x_analytic", "y_analytic",
                                                          "z_analytic"],
                     ([p.s_node[k], *p.x[k], *p.r[k]] for k in range(case.N)))
    _write_helix_csv(os.path.join(out, "envelope.csv"), ["s_over_L", "theta", "theta_analytic"],
                     ([p.s_edge[k], p.theta[k], p.theta_analytic[k]] for k in range(p.theta.size)))
    title = f"m = {result['m_analytic']:.4g}, t = {result['t_analytic']:.4g}, gamma = {case.gamma:.3g}, N = {case.N}"
    _plot_helix_centreline(os.path.join(out, "centreline.png"), profiles, title, result["reference_valid"])
    _plot_helix_envelope(os.path.join(out, "envelope.png"), profiles, title, result["envelope_L1"])
    written = "helix.json, centreline.csv, envelope.csv, centreline.png, envelope.png"
    path = result["path"]
    if path:
        keys = list(path[0])
        _write_helix_csv(os.path.join(out, "path.csv"), keys,
                         (["" if row[k] is None else row[k] for k in keys] for row in path))
        _plot_helix_loads(os.path.join(out, "loads.png"), path, result["d"], case)
        written += ", path.csv, loads.png"
    say(f"wrote {out}/{written}")


def _write_helix_csv(file, header, rows):
    with open(file, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for row in rows:
            w.writerow(row)


def _plot_helix_centreline(file, profiles, title, valid):
    """The computed centreline beside the analytic one, in 3-D."""
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="3d")
    ax.plot(*profiles.r.T, "k--", lw=1, label="analytic (NvdHT 2002)" if valid else "analytic (not applicable)")
    ax.plot(*profiles.x.T, "C0", lw=2, label="jaxrod")
    ax.set_title(title)
    ax.legend()
    fig.savefig(file, dpi=120)
    plt.close(fig)


def _plot_helix_envelope(file, profiles, title, envelope_L1):
    """The edges' tangent angle beside the analytic one (envelope_L1 None: the reference does not apply)."""
    import matplotlib.pyplot as plt

    valid = envelope_L1 is not None
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(profiles.s_edge, profiles.theta_analytic, "k--", lw=1,
            label="analytic" if valid else "analytic (not applicable)")
    ax.plot(profiles.s_edge, profiles.theta, "C0.", ms=3, label="jaxrod (edges)")
    ax.set_xlabel("s / L (from the middle)")
    ax.set_ylabel("tangent angle to the axis theta (rad)")
    ax.set_title(f"{title}: L1 error {envelope_L1:.2e}" if valid else
                 f"{title}: the analytic reference does not apply")
    ax.legend()
    fig.tight_layout()
    fig.savefig(file, dpi=120)
    plt.close(fig)


def _plot_helix_loads(file, path, d, case):
    """M and T along the sweep's path, stable and unstable states apart, beside the analytic ones."""
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    R_ = np.array([p["R"] for p in path])
    st = np.array([p["stable"] for p in path])
    for ax, key, label in ((axes[0], "m", "M L / B"), (axes[1], "t", "T L^2 / B")):
        v = np.array([p[key] for p in path])
        va = np.array([np.nan if p[key + "_analytic"] is None else p[key + "_analytic"] for p in path])
        ax.plot(R_, va, "k--", lw=1, label="analytic")
        ax.plot(R_[st], v[st], "C0o", label="jaxrod, stable")
        ax.plot(R_[~st], v[~st], "C3o", mfc="none", label="jaxrod, unstable")
        ax.set_ylabel(label)
    axes[0].legend()
    axes[1].set_xlabel(f"end rotation R (rad), d = {d:.4g}")
    axes[0].set_title(f"gamma = {case.gamma:.3g}, N = {case.N} (stability under fixed ends)")
    fig.tight_layout()
    fig.savefig(file, dpi=120)
    plt.close(fig)


def _helix_number(v):
    return "-" if v is None else f"{v:.6g}"


def _print_helix(args, case, solved, result):
    """The helix summary as text on stdout: the roots (where several), the table of each root
    shown (the taken one; all solved with --root both), the extrapolation, envelope and time."""
    taken = result["root"]
    if len(result["roots"]) > 1 or case.refused:
        _print_helix_roots(result["roots"])
    if case.n_found > 1:
        print(f"taken: the {taken} root ({result['root_reason']})")
    shown = [name for name, _ in case.refs if name in solved and solved[name].eq is not None] \
        if args.root == "both" else [taken]
    for name in shown:
        if len(shown) > 1:
            print(f"-- {name} root" + (" (taken)" if name == taken else ""))
        _print_helix_table(solved[name], case.checks[name])
    if result["m_extrapolated"] is not None:
        err = "" if not result["reference_valid"] else (f"; errors {result['m_extrapolated_rel_error']:+.1e}, "
                                                        f"{result['t_extrapolated_rel_error']:+.1e}")
        print(f"Richardson    m = {result['m_extrapolated']:.6g}, t = {result['t_extrapolated']:.6g}  "
              f"(N = {result['N_coarse']} and {case.N}{err}" + (f"; the {taken} root)" if len(shown) > 1 else ")"))
    if result["reference_valid"]:
        print(f"envelope L1   {result['envelope_L1']:>14.3e}")
    print(f"time          {result['seconds']:>14.2f} s")


def _print_helix_roots(roots):
    for row in roots:
        err = "" if row["m_rel_error"] is None else \
            f", errors m {row['m_rel_error']:+.2e}, t {row['t_rel_error']:+.2e}"
        got = ("not solved" + (f": {row['note']}" if row.get("note") else "")) if row["m"] is None else \
            f"m = {row['m']:.6g}, t = {row['t']:.6g}, Morse index {row['morse']}{err}"
        print(f"{row['root']} root (analytic m = {row['m_analytic']:.6g}, t = {row['t_analytic']:.6g}): {got}"
              + ("" if row["reference_valid"] else " [reference not applicable]"))


def _print_helix_table(root, check):
    """One solved root's values beside the analytic ones (only its own where they do not apply)."""
    h, st, fmt = root.ref, root.state, _helix_number
    rows = [("m = M L/B", st["m"], h.m), ("t = T L^2/B", st["t"], h.t),
            ("theta_max", st["theta_max"], h.theta_max), ("Lk", st["Lk"], st["Lk_expected"]),
            ("Wr", st["Wr"], h.Wr), ("Tw", st["Tw"], h.Tw)]
    if check.valid:
        print(f"{'':14s}{'jaxrod':>14s}{'analytic':>14s}")
        for label, a, b in rows:
            print(f"{label:14s}{fmt(a):>14s}{fmt(b):>14s}")
    else:
        print(f"analytic reference (NvdHT 2002): not applicable: {check.reason}")
        print(f"{'':14s}{'jaxrod':>14s}")
        for label, a, _ in rows[:3]:
            print(f"{label:14s}{fmt(a):>14s}")
        print(f"{'Lk':14s}{fmt(st['Lk']):>14s}  (R / 2 pi = {st['Lk_expected']:.6g})")
        for label, a, _ in rows[4:]:
            print(f"{label:14s}{fmt(a):>14s}")
    print(f"Morse index   {st['morse']:>14d}  ({'stable' if st['stable'] else 'unstable'} under fixed ends)")


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
    interval = sys.getswitchinterval()
    # The study's and the workers' threads each hand the GIL back while XLA or LAPACK computes,
    # and wait for it again when the call returns: up to the switch interval (5 ms) whenever
    # another thread runs Python then, thousands of times in a run. 0.5 ms: command 1 warm
    # 17.75 s against 18.98 s (means of 6 alternating runs, 2026-12-04); 0.1 ms was slower (18.6 s).
    sys.setswitchinterval(_SWITCH_INTERVAL)
    try:
        return _main(argv)
    finally:
        signal.signal(signal.SIGTERM, previous)
        sys.setswitchinterval(interval)


def _main(argv):
    argv = _join_angle_values(list(sys.argv[1:] if argv is None else argv))
    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version (0) or a usage error (2, its one line printed)
        return exc.code if isinstance(exc.code, int) else 2
    if args.command is None:  # `jaxrod` alone: what it can do
        parser.print_help(sys.stderr)
        return 2
    flags = _flag_names(parser, args.command)
    try:
        import warnings

        import jaxrod  # noqa: F401  (float64, BLAS threads)

        args.compile_notice = _compile_notice(args, _enable_compilation_cache(args))
        with warnings.catch_warnings(), contextlib.ExitStack() as held:
            warnings.showwarning = _warn_in_one_line  # a warning is one line, not a source quote
            if getattr(args, "programs", None) and os.environ.get("JAXROD_PROGRAMS", "1") != "0":
                from .. import aot

                held.enter_context(aot.kept_in(args.programs))
            args.hold = held.enter_context  # the --out folder's lock, until the command ends
            if args.command == "michell":
                return _michell(args)
            if args.command == "analyze":
                return _analyze(args)
            if args.command in ("trefoil", "knot"):
                return _trefoil(args)
            if args.command == "atlas":
                return _atlas(args)
            if args.command == "helix":
                return _helix(args)
            if args.command == "critical-curve":
                return _critical_curve(args)
    except ValueError as exc:
        print(f"jaxrod: error: {_in_flags(str(exc), flags)}", file=sys.stderr)
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
        from ..continuation import NoCrossingError
        from ..solve.solvers import ConvergenceError

        if isinstance(exc, NoCrossingError):
            advice = {"michell": "no critical twist up to twice Michell's value: raise --N",
                      "critical-curve": "no instability within --span at a ratio of --ratios: widen --span or "
                                        "raise --N"}.get(
                args.command, "no critical twist in the range: widen it (--phi-min / --phi-max) or raise --N")
        elif isinstance(exc, ConvergenceError):
            advice = ("no equilibrium found: raise --N (for a knot, edges no longer than the diameter: "
                      "N >= L/D), or loosen the knot (larger --L/--D)")
        else:
            raise
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if len(detail) > 160:
            detail = detail[:157] + "..."
        print(f"jaxrod: error: {advice} ({detail})", file=sys.stderr)
        return 1
    return 1


# XLA:CPU's classic elemental emitters instead of its MLIR fusion emitters: the same arithmetic
# (fast-math stays off), compiled faster. Command 1 (N = 121, -12 pi ... 14 pi) as two CLI
# processes on an empty cache (benchmarks/cli_start.py, medians of 2 rounds): 35.8 s against
# 41.1 s cold, 24.3 s against 25.5 s warm, phi* equal to 2e-10 rad. And LLVM's optimisation
# level 1 instead of XLA's default 3: 32.5 / 32.7 / 33.4 s cold against 33.9 / 34.7 / 35.6 s,
# warm 15.2 / 15.4 / 15.6 s against 15.1 / 15.5 / 15.6 s (alternating runs, 2026-12-04; level 0
# compiled 40 % faster but ran the Newton loop 1.5x slower); the located ends equal to 2e-11 pi.
# Only for the command's own process, and only if the user set no such flag.
_SWITCH_INTERVAL = 5e-4  # seconds (``main``: how long a thread may keep the GIL when another waits)
_CLI_XLA_FLAGS = ("--xla_cpu_use_fusion_emitters=false", "--xla_backend_optimization_level=1")


def _add_cli_xla_flags(environ=os.environ):
    """Append the CLI's XLA flags to XLA_FLAGS unless the user set them (read by XLA when the CPU
    backend starts, at the first computation: after ``import jax``, before any array is built)."""
    flags = environ.get("XLA_FLAGS", "").split()
    for flag in _CLI_XLA_FLAGS:
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
    _add_cli_xla_flags()
    status = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status if isinstance(status, int) else 1)


if __name__ == "__main__":
    console_main()
