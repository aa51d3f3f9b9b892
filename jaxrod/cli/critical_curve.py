"""``jaxrod critical-curve``: a knot's critical twists as curves phi*+-(D/L)
(``jaxrod.studies.critical_curve``)."""
from __future__ import annotations

import math

from .common import NO_CACHE_HELP, Progress, add_quiet_and_cache, parse_angle

NAME = "critical-curve"

HELP = """\
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


def add_parser(sub, formatter_class):
    """Adds the critical-curve command's parser to the subparsers ``sub``."""
    cc = sub.add_parser(NAME, help="a knot's critical twists as curves phi*+-(D/L): each side's first "
                        "instability at each D/L, as the point study finds it (CSV, JSON, figure)",
                        description=HELP, formatter_class=formatter_class)
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
    cc.add_argument("--span", type=parse_angle, default=16.0 * math.pi,
                    help="search each side's first end up to +-span (default 16pi)")
    cc.add_argument("--out", default="results/critical_curve", help="output folder (default results/critical_curve)")
    cc.add_argument("--fresh", action="store_true", help="start over even if --out holds an interrupted curve")
    cc.add_argument("--json", action="store_true", help="print the result as one JSON object")
    add_quiet_and_cache(cc, NO_CACHE_HELP)


def run(args):
    """Runs ``jaxrod critical-curve`` with the parsed ``args``; returns the exit status."""
    import json

    from .common import use_files_only_backend

    use_files_only_backend()
    from ..io.locking import folder_lock
    from ..studies.critical_curve import CriticalCurveOptions, check_ratio_range, critical_twist_curve, json_ready
    from ..validation import check_poisson_ratio

    ratios = check_ratio_range(args.ratios)
    sides = tuple(x.strip() for x in args.sides.split(",") if x.strip())
    opts = CriticalCurveOptions(sides=sides, start_ratio=args.start, span=args.span,
                                nu=check_poisson_ratio("nu", args.nu), contact_stiffness=args.contact_stiffness)
    args.hold(folder_lock(args.out))
    bar = Progress(args, len(ratios) * len(opts.sides), "critical curve", counting="points")
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
