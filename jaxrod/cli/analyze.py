"""``jaxrod analyze``: frames, curvature and twist profiles and Wr, Tw, Lk of a rod from two
polylines or a study's step file."""
from __future__ import annotations

import json
import math
import sys

from .common import add_quiet_and_cache, output_folder, parse_angle

NAME = "analyze"

HELP = """\
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


def add_parser(sub, formatter_class):
    """Adds the analyze command's parser to the subparsers ``sub``."""
    a = sub.add_parser(
        NAME,
        help="frames, curvature/twist profiles and Wr, Tw, Lk of a rod from two polylines (CSV, NPY) or a step file",
        description=HELP, formatter_class=formatter_class,
    )
    a.add_argument("centreline", help="centreline points (.csv, .npy, or a step file steps/*.npz: its x)")
    a.add_argument("eccentric", nargs="?", default=None,
                   help="eccentric-line points (.csv, .npy or .npz: its eccentric array); "
                        "default: the centreline's step file")
    a.add_argument("--joint-twist", type=parse_angle, default=None, metavar="PHI",
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
    add_quiet_and_cache(a)


def run(args):
    """Runs ``jaxrod analyze`` with the parsed ``args``; returns the exit status."""
    from .common import use_files_only_backend

    use_files_only_backend()
    from ..studies.runs.analyze import AnalyzeOptions, analyze_files, write_analysis_files

    say = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    options = AnalyzeOptions(args.centreline, args.eccentric, closed=not args.open, joint_twist=args.joint_twist,
                             n_samples=args.n_samples, smoothing_modes=args.smoothing_modes).checked()
    if args.out:
        output_folder(args.out)
    rod = analyze_files(options)
    if args.out:
        names = write_analysis_files(rod, args.out)
        say(f"wrote {args.out}/{', '.join(names)}")
    if args.json:
        print(json.dumps(rod.result))
    else:
        _print_summary(rod)
    return 0


def _print_summary(rod):
    res, result, closed = rod.analysis, rod.result, rod.options.closed
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
    print(f"length        = {res.length:.10g}   ({result['n_samples']} nodes)")
    if closed:
        print(f"kappa profile : symmetry order {result['symmetry_order']}, {result['n_peaks']} peak(s)")
