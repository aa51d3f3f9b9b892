"""Command line: ``jaxrod michell ...``, ``jaxrod trefoil ...``, ``jaxrod analyze CENTRELINE ECCENTRIC ...``.

Progress goes to stderr; results to stdout (``--json``: one JSON object); figures and data
(PNG, CSV, JSON) into ``--out DIR``. Bad input exits with status 2, a computation that fails
(no critical twist in range, no equilibrium) with status 1, Ctrl-C with 130: each with one line
on stderr that says what to change (or, for an interrupted study, that it resumes).
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
import time

__all__ = ["main"]

# A ring of fewer nodes does not buckle within twice Michell's twist (N = 4 to 6 were seen to
# scan the whole range in vain).
MICHELL_MIN_NODES = 8


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
branch and go on. Lengths in mm (any unit, if D and L share it), E in MPa (N/mm^2).
{_ANGLES}

Writes into --out as it goes: branch.csv (a row per step), steps/*.npz, critical.json (phi_plus,
phi_minus in radians), summary.json and figures. An interrupted run (Ctrl-C, kill) resumes
when the same command is given again, and ends with the same files as an uninterrupted run.

examples:
  jaxrod trefoil --D 8 --L 292 --N 121 --phi-min -12pi --phi-max 14pi --out results/trefoil
  jaxrod trefoil --N 61 --phi-min -0.5pi --phi-max 7.5pi --out results/quick
"""

_ANALYZE_HELP = """\
Analyse a rod from its centreline and an eccentric line drawn on its surface, as the seed
paper does with measured knots: frames, curvature kappa(s) and twist tau(s) profiles, writhe,
twist and linking number (Lk from Wr + Tw and from the Gauss integral). Files: CSV with an
x,y,z header (or three bare columns), or .npy arrays of shape (N, 3). Closed curves unless
--open.

examples:
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
                "the twisted trefoil knot, and the analysis of measured rods. "
                "Give a command and --help for its options.",
                formatter_class=argparse.RawDescriptionHelpFormatter,
                epilog="examples:\n  jaxrod trefoil --N 121 --out results/trefoil\n"
                       "  jaxrod michell --N 128 --out results/michell\n  jaxrod trefoil --help")
    p.add_argument("--version", action="version", version=f"jaxrod {_version()}")
    sub = p.add_subparsers(dest="command", parser_class=_Parser, metavar="{michell,trefoil,analyze}")
    raw = argparse.RawDescriptionHelpFormatter
    m = sub.add_parser("michell", help="critical twist of Michell's ring, against 2 pi sqrt(3)(1+nu)",
                       description=_MICHELL_HELP, formatter_class=raw)
    m.add_argument("--N", type=int, default=128, help="number of nodes, at least 8 (default 128)")
    m.add_argument("--nu", type=float, default=0.5, help="Poisson ratio in (-1, 0.5], B/C = 1 + nu (default 0.5)")
    m.add_argument("--slenderness", type=float, default=0.01, help="rod diameter over ring radius, D/R (default 0.01)")
    m.add_argument("--tol", type=_angle, default=1e-6 * math.pi, help="accuracy of phi* (default 1e-6pi)")
    m.add_argument("--json", action="store_true", help="print one JSON object")
    m.add_argument("--out", default=None, help="folder for michell.json, scan.csv and figures (default: none)")
    m.add_argument("--quiet", action="store_true", help="no progress on stderr")
    m.add_argument("--no-cache", action="store_true",
                   help="do not keep compiled code in ~/.cache/jaxrod (later runs then compile again)")
    a = sub.add_parser(
        "analyze",
        help="frames, curvature/twist profiles and Wr, Tw, Lk of a rod from two polylines (CSV or NPY)",
        description=_ANALYZE_HELP, formatter_class=raw,
    )
    a.add_argument("centreline", help="centreline points (.csv or .npy)")
    a.add_argument("eccentric", help="eccentric-line points (.csv or .npy)")
    a.add_argument("--open", action="store_true", help="open curves (default: closed loops)")
    a.add_argument("--n-samples", type=int, default=None,
                   help="number of nodes, equally spaced in arc length (default: as many as centreline points)")
    a.add_argument("--smoothing-modes", type=int, default=None,
                   help="least-squares smoothing with K modes (Fourier, closed) or K spline intervals (open)")
    a.add_argument("--out", default=None, help="folder for profiles.csv, summary.json, profiles.png")
    a.add_argument("--json", action="store_true", help="print one JSON object")
    a.add_argument("--quiet", action="store_true", help="no progress on stderr")
    t = sub.add_parser("trefoil", help="twisted trefoil knot: both critical twists, branches beyond, figures",
                       description=_TREFOIL_HELP, formatter_class=raw)
    t.add_argument("--D", type=float, default=8.0, help="rod diameter (default 8, mm)")
    t.add_argument("--L", type=float, default=292.0, help="rod length, at least 16.372 D (default 292, mm)")
    t.add_argument("--N", type=int, default=121, help="number of nodes, at least 24 and L/D (default 121)")
    t.add_argument("--E", type=float, default=0.474, help="Young's modulus (default 0.474, MPa = N/mm^2)")
    t.add_argument("--nu", type=float, default=0.5, help="Poisson ratio in (-1, 0.5], B/C = 1 + nu (default 0.5)")
    t.add_argument("--chirality", choices=("right", "left"), default="right", help="knot handedness (default right)")
    t.add_argument("--contact-stiffness", type=float, default=None,
                   help="contact penalty kappa_c in units of B/D^3 (default: the scene's, 100)")
    t.add_argument("--phi-min", type=_angle, default=-12.0 * math.pi, help="lowest twist, < 0 (default -12pi)")
    t.add_argument("--phi-max", type=_angle, default=14.0 * math.pi, help="highest twist, > 0 (default 14pi)")
    t.add_argument("--step", type=_angle, default=0.5 * math.pi, help="largest continuation step (default 0.5pi)")
    t.add_argument("--tol", type=_angle, default=2e-4 * math.pi, help="accuracy of the critical twists (default 2e-4pi)")
    t.add_argument("--out", default="results/trefoil", help="output folder (default results/trefoil)")
    t.add_argument("--fresh", action="store_true", help="start over even if --out holds an interrupted run")
    t.add_argument("--serial", action="store_true",
                   help="follow the two directions one after the other (default: both at once, two threads)")
    t.add_argument("--no-figures", action="store_true", help="data only")
    t.add_argument("--vtk", action="store_true",
                   help="also write every step as a VTK polyline file (vtk/*.vtk, for ParaView)")
    t.add_argument("--json", action="store_true", help="print one JSON summary object")
    t.add_argument("--quiet", action="store_true", help="no progress on stderr")
    t.add_argument("--no-cache", action="store_true", help="do not keep compiled code in ~/.cache/jaxrod")
    return p


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
    if getattr(args, "no_cache", False) or os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return
    import jax

    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.path.join(base, "jaxrod", "xla")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return  # read-only home: run without a cache
    jax.config.update("jax_compilation_cache_dir", path)
    # Every compilation, also the many small ones under the default 1 s threshold.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
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

    def __init__(self, args, total, desc):
        import threading

        self.quiet = bool(args.quiet)
        self.lock = threading.Lock()
        self.bar = None
        if not self.quiet and total > 0:
            from tqdm import tqdm

            self.bar = tqdm(total=round(total, 2), file=sys.stderr, disable=None, desc=desc, leave=False,
                            dynamic_ncols=True,
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| phi {n:.2f}/{total:.2f} pi "
                                       "[{elapsed}<{remaining}{postfix}]")
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
    from . import plotting
    from .continuation import critical_twist
    from .validation import check_int_at_least, check_poisson_ratio, check_positive
    from .scenes import michell_critical_twist, michell_ring

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
        cp = critical_twist(scene, 0.0, 2.0 * analytic, step=analytic / 10.0, tol=args.tol, progress=say,
                            on_step=on_step)
    finally:
        bar.close()
    seconds = time.perf_counter() - t0
    rel = (cp.phi - analytic) / analytic
    result = {
        "phi_star": cp.phi,
        "phi_star_analytic": analytic,
        "rel_error": rel,
        "N": args.N,
        "nu": nu,
        "seconds": seconds,
        "phi_error_bound": cp.phi_error,
        "multiplicity": cp.multiplicity,
        "dlambda_dphi": cp.dlambda_dphi,
        "hessian_evaluations": cp.hessian_evaluations,
    }
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


def _json_number(v):
    """float for JSON, None for NaN (strict JSON has no NaN)."""
    v = float(v)
    return v if math.isfinite(v) else None


def _analyze(args):
    import matplotlib

    matplotlib.use("Agg")  # files only, no display needed
    from . import plotting
    from .analysis import analyze, count_peaks, load_polyline, symmetry_order, write_profiles_csv
    from .validation import check_int_at_least

    say = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    if args.n_samples is not None:
        check_int_at_least("n_samples", args.n_samples, 4)
    if args.smoothing_modes is not None:
        check_int_at_least("smoothing_modes", args.smoothing_modes, 1)
    if args.out:
        _output_folder(args.out)
    centre = load_polyline(args.centreline)
    ecc = load_polyline(args.eccentric)
    closed = not args.open
    res = analyze(centre, ecc, closed=closed, n_samples=args.n_samples, smoothing_modes=args.smoothing_modes)
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
        "length": L,
        "symmetry_order": order,
        "n_peaks": peaks,
        "n_samples": n,
        "closed": closed,
        "smoothing_modes": args.smoothing_modes,
        "n_unpaired": int(n - int(res.paired.sum())),
        "warnings": list(res.warnings),
        "centreline": os.path.abspath(args.centreline),
        "eccentric": os.path.abspath(args.eccentric),
    }
    if args.out:
        write_profiles_csv(res, os.path.join(args.out, "profiles.csv"))
        with open(os.path.join(args.out, "summary.json"), "w") as f:
            json.dump(result, f, indent=2)
        lk = "" if not closed else f", Lk = {res.Lk_exact:.0f}"
        plotting.plot_profiles(
            res.s / L, [(res.kappa * L, res.tau * L)], [os.path.basename(args.centreline)],
            path=os.path.join(args.out, "profiles.png"),
            title=f"Wr = {res.Wr:.4f}, Tw = {res.Tw:.4f}{lk}",
        )
        say(f"wrote {args.out}/profiles.csv, summary.json, profiles.png")
    if args.json:
        print(json.dumps(result))
    else:
        fmt = lambda v: "n/a (open curve)" if v is None or not math.isfinite(v) else f"{v:.10f}"  # noqa: E731
        print(f"Wr            = {res.Wr:.10f}")
        print(f"Tw            = {res.Tw:.10f}   (integral of tau: {res.Tw_integral:.10f})")
        print(f"Lk (frames)   = {res.Lk_frames:.10f}   (Wr + Tw)")
        print(f"Lk (Gauss)    = {fmt(res.Lk_exact)}   (exact polygon linking number)")
        print(f"Lk (quadr.)   = {fmt(res.Lk_quadrature)}   (midpoint Gauss quadrature)")
        print(f"length        = {L:.10g}   ({n} nodes)")
        if closed:
            print(f"kappa profile : symmetry order {order}, {peaks} peak(s)")
    return 0


def _trefoil(args):
    import matplotlib

    matplotlib.use("Agg")
    from .validation import check_finite, check_int_at_least, check_poisson_ratio, check_positive
    from .scenes import DEFAULT_CONTACT_STIFFNESS, IDEAL_TREFOIL_ROPELENGTH, MIN_TREFOIL_NODES, trefoil
    from .study import check_study_folder, figures, study_summary, twist_study

    D, L = check_positive("D", args.D), check_positive("L", args.L)
    if L / D < IDEAL_TREFOIL_ROPELENGTH:
        raise ValueError(f"--L {args.L:g} / --D {args.D:g} = {L / D:.3f} is below the ideal trefoil's ropelength "
                         f"{IDEAL_TREFOIL_ROPELENGTH}: no such knot exists (raise --L or lower --D)")
    check_int_at_least("N", args.N, MIN_TREFOIL_NODES)
    need = math.ceil(L / D - 1e-9)
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
    stiffness = DEFAULT_CONTACT_STIFFNESS if args.contact_stiffness is None else args.contact_stiffness
    scene = trefoil(args.D, args.L, args.N, E=args.E, nu=args.nu, chirality=args.chirality,
                    contact_stiffness=stiffness)
    if not args.fresh:  # a folder of another run: refused now, not after the compilation
        check_study_folder(args.out, scene, args.phi_min, args.phi_max, args.step, args.tol)
    bar = _Progress(args, (args.phi_max - args.phi_min) / math.pi, "trefoil")
    say = bar.say
    say(f"{scene.name}: D = {args.D}, L = {args.L}, N = {args.N}, nu = {args.nu}, kappa_c = {stiffness}; "
        f"phi from {args.phi_min / math.pi:+.3f} pi to {args.phi_max / math.pi:+.3f} pi; writing {args.out}/")
    say(args.compile_notice)
    reached, counts = {"plus": 0.0, "minus": 0.0}, {"steps": 0}

    def on_point(direction, point):
        reached[direction] = max(reached[direction], abs(point.equilibrium.phi) / math.pi)
        counts["steps"] += 1
        bar.update(reached["plus"] + reached["minus"], steps=counts["steps"], branch=point.branch)

    try:
        result = twist_study(scene, args.phi_min, args.phi_max, step=args.step, out=args.out, tol=args.tol,
                             progress=say, resume=not args.fresh, parallel=not args.serial, on_point=on_point)
    finally:
        bar.close()
    summary = study_summary(result)
    summary.update({"D": args.D, "L": args.L, "N": args.N, "nu": args.nu, "chirality": args.chirality,
                    "contact_stiffness": stiffness, "out": args.out})
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    if not args.no_figures:
        for path in figures(args.out, title=f"{scene.name}, D/L = {args.D / args.L:.4f}, N = {args.N}",
                            length_unit="mm"):
            say(f"wrote {path}")
    if args.vtk:
        from .export import export_study_vtk

        say(f"wrote {len(export_study_vtk(args.out))} VTK files into {args.out}/vtk/")
    if args.json:
        print(json.dumps(summary))
    else:
        for key in ("phi_plus", "phi_minus"):
            v = summary[key]
            print(f"{key:10s} = " + ("none in range" if v is None else f"{v:+.6f} rad = {v / math.pi:+.5f} pi"))
        total = summary.get("seconds_total")
        resumed = f" ({total:.1f} s with the interrupted runs)" if total and total > summary["seconds"] + 0.05 else ""
        print(f"tightening side: {summary.get('tightening_side')}; time {summary['seconds']:.1f} s{resumed}; "
              f"data in {args.out}/")
    return 0


# Options whose value is an angle such as -12pi: argparse would read a leading '-' as an option.
_ANGLE_OPTIONS = ("--phi-min", "--phi-max", "--step", "--tol")


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


def main(argv=None):
    """Run the command line with ``argv`` (default sys.argv[1:]); returns the exit status."""
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
        with warnings.catch_warnings():
            warnings.showwarning = _warn_in_one_line  # a warning is one line, not a source quote
            if args.command == "michell":
                return _michell(args)
            if args.command == "analyze":
                return _analyze(args)
            if args.command == "trefoil":
                return _trefoil(args)
    except ValueError as exc:
        print(f"jaxrod: error: {_in_flags(str(exc), flags)}", file=sys.stderr)
        return 2
    except OSError as exc:  # missing or unreadable file, unwritable --out
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"jaxrod: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        hint = f"; the same command resumes from what is in {args.out}/" if args.command == "trefoil" else ""
        print(f"jaxrod: interrupted{hint}", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 -- a failed computation: one line, what to change
        from .continuation import NoCrossingError
        from .solvers import ConvergenceError

        if isinstance(exc, NoCrossingError):
            advice = ("no critical twist up to twice Michell's value: raise --N" if args.command == "michell" else
                      "no critical twist in the range: widen it (--phi-min / --phi-max) or raise --N")
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


if __name__ == "__main__":
    sys.exit(main())
