"""``jaxrod atlas``: the critical twists of several knots over a range of D/L (CSV, report, figure)."""
from __future__ import annotations

import contextlib
import json
import math
import time

from .common import (ANGLES, NO_CACHE_HELP, Progress, add_quiet_and_cache, number_list, output_folder,
                     parse_angle)

NAME = "atlas"

HELP = f"""\
The twisted-knot atlas: for each knot (--knots) and slenderness D/L (--ratios), the critical
twists phi*+ (phi > 0) and phi*- (phi < 0) at which the stable branch of the knot relaxed at zero
twist ends (a bifurcation or a fold), each side followed up to +-span. Cases are independent:
they run one after the other, over a local Dask cluster (--workers K, K processes) or on a
running Dask scheduler (--scheduler tcp://HOST:PORT), with the same numbers either way.
Several --N values give a convergence study. {ANGLES}

Writes into --out as it goes: atlas.csv (a row per finished case; an interrupted run skips the
cases already there when given again), atlas.json (settings), atlas.md (table, convergence in
N) and atlas.png (phi*/pi against D/L per knot, with the Michell lines).

examples:
  jaxrod atlas --knots 3_1,4_1,5_1,5_2 --ratios 0.01,0.015,0.02,0.0274,0.03,0.035 --N 101 --out results/atlas
  jaxrod atlas --knots 4_1 --ratios 0.02 --N 101,151,201 --workers 2 --out results/atlas_convergence
"""


def add_parser(sub, formatter_class):
    """Adds the atlas command's parser to the subparsers ``sub``."""
    at = sub.add_parser(NAME, help="critical twists of several knots over a range of D/L (CSV, figure)",
                        description=HELP, formatter_class=formatter_class)
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
    at.add_argument("--span", type=parse_angle, default=16.0 * math.pi,
                    help="follow each side up to +-span (default 16pi)")
    at.add_argument("--step", type=parse_angle, default=0.5 * math.pi, help="largest continuation step (default 0.5pi)")
    at.add_argument("--tol", type=parse_angle, default=1e-3 * math.pi,
                    help="accuracy of the critical twists (default 1e-3pi)")
    at.add_argument("--accuracy", type=parse_angle, default=None,
                    help="also converge each end in N to this accuracy (levels N, 4N/3, 5N/3, Richardson with the "
                         "order measured): the extrapolated value and its error bar in each row (default: off)")
    at.add_argument("--workers", type=int, default=1,
                    help="cases at once on a local Dask cluster of this many processes (default 1: in this process)")
    at.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://HOST:PORT)")
    at.add_argument("--out", default="results/atlas", help="output folder (default results/atlas)")
    at.add_argument("--fresh", action="store_true", help="start over even if --out holds an interrupted atlas")
    at.add_argument("--no-figures", action="store_true", help="data only")
    at.add_argument("--json", action="store_true", help="print the rows as one JSON object (the critical twists' "
                                                        "keys: python -m jaxrod.io.schema, and the README)")
    add_quiet_and_cache(at, NO_CACHE_HELP)


def _options(args):
    """The ``AtlasOptions`` of ``args``; ValueError naming the flag."""
    from ..studies import atlas
    from ..studies.runs.atlas import AtlasOptions

    knots = [k.strip() for k in args.knots.split(",") if k.strip()]
    unknown = [k for k in knots if k not in atlas.KNOTS]
    if unknown or not knots:
        raise ValueError(f"--knots: unknown knot(s) {', '.join(unknown) or '(none given)'}; "
                         f"choose from {','.join(atlas.KNOTS)}")
    ratios = number_list("--ratios", args.ratios, float)
    ns = number_list("--N", args.N, int)
    settings = atlas.AtlasSettings(span=args.span, step=args.step, tol=args.tol, nu=args.nu,
                                   contact_stiffness=args.contact_stiffness, accuracy=args.accuracy)
    sides = [v.strip() for v in args.sides.split(",") if v.strip()]
    return AtlasOptions(knots=tuple(knots), ratios=tuple(ratios), N=tuple(ns), sides=tuple(sides), settings=settings,
                        out=args.out, fresh=args.fresh, figures=not args.no_figures)


@contextlib.contextmanager
def _dask_client(args, say):
    """The Dask client of --scheduler or of a local cluster of --workers processes (None: neither)."""
    if args.scheduler is None and args.workers <= 1:
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError("--workers / --scheduler need Dask: pip install 'dask[distributed]'") from None
    cluster = None
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
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run(args):
    """Runs ``jaxrod atlas`` with the parsed ``args``; returns the exit status."""
    from .common import use_files_only_backend

    use_files_only_backend()
    from ..io.locking import folder_lock
    from ..studies.runs.atlas import atlas_cases_of, atlas_json, run_atlas_study, write_atlas_summary
    from ..validation import check_int_at_least

    options = _options(args)
    check_int_at_least("workers", args.workers, 1)
    output_folder(args.out)
    args.hold(folder_lock(args.out))
    cases = atlas_cases_of(options)  # every case checked before any work
    bar = Progress(args, len(cases), NAME, counting="cases")
    bar.say(f"atlas: {len(options.knots)} knot(s) x {len(set(options.ratios))} D/L x {len(set(options.N))} N x "
            f"{len(options.sides)} side(s) = {len(cases)} cases; writing {args.out}/")
    bar.say(args.compile_notice)
    t0 = time.perf_counter()

    def on_row(row, done, total):
        phi = f"{row['phi_star'] / math.pi:+.4f} pi ({row['kind']})" if math.isfinite(row["phi_star"]) else \
            f"none within {'+' if row['side'] == 'plus' else '-'}{args.span / math.pi:g} pi"
        bar.say(f"[{done}/{total}] {row['knot']} D/L = {row['D_over_L']:g} N = {row['N']} {row['side']}: "
                f"phi* = {phi}, {row['seconds']:.1f} s")
        bar.update(done)

    try:
        with _dask_client(args, bar.say) as client:
            rows = run_atlas_study(options, client=client, on_row=on_row)
    finally:
        bar.close()
    for path in write_atlas_summary(options):
        bar.say(f"wrote {path}")
    if args.json:
        print(json.dumps(atlas_json(rows)))
    else:
        for r in rows:
            phi = f"{r['phi_star'] / math.pi:+.4f} pi" if math.isfinite(r["phi_star"]) else "none"
            print(f"{r['knot']:4s} D/L = {r['D_over_L']:<7g} N = {r['N']:<4d} {r['side']:5s} phi* = {phi}")
        print(f"time {time.perf_counter() - t0:.1f} s; data in {args.out}/")
    return 0
