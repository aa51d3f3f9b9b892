"""``jaxrod michell``: the critical twist of Michell's ring against 2 pi sqrt(3)(1 + nu)."""
from __future__ import annotations

import json
import math

from .common import ANGLES, NO_CACHE_HELP_LONG, Progress, add_quiet_and_cache, output_folder, parse_angle

NAME = "michell"

HELP = f"""\
Critical twist of Michell's ring (a closed, initially circular rod, B/C = 1 + nu): the twist at
which the planar ring buckles, found where the lowest eigenvalue of the equilibrium's Hessian
crosses zero (Newton on that eigenvalue), compared with the analytic 2 pi sqrt(3)(1 + nu).
{ANGLES}

examples:
  jaxrod michell --N 128 --nu 0.5 --out results/michell
  jaxrod michell --N 512 --tol 1e-8pi --json
"""


def add_parser(sub, formatter_class):
    """Adds the michell command's parser to the subparsers ``sub``."""
    m = sub.add_parser(NAME, help="critical twist of Michell's ring, against 2 pi sqrt(3)(1+nu)",
                       description=HELP, formatter_class=formatter_class)
    m.add_argument("--N", type=int, default=128, help="number of nodes, at least 8 (default 128)")
    m.add_argument("--nu", type=float, default=0.5, help="Poisson ratio in (-1, 0.5], B/C = 1 + nu (default 0.5)")
    m.add_argument("--slenderness", type=float, default=0.01, help="rod diameter over ring radius, D/R (default 0.01)")
    m.add_argument("--tol", type=parse_angle, default=1e-6 * math.pi, help="accuracy of phi* (default 1e-6pi)")
    m.add_argument("--json", action="store_true",
                   help="print one JSON object (its keys: python -m jaxrod.io.schema, and the README)")
    m.add_argument("--out", default=None, help="folder for michell.json, scan.csv and figures (default: none)")
    add_quiet_and_cache(m, NO_CACHE_HELP_LONG)


def run(args):
    """Runs ``jaxrod michell`` with the parsed ``args``; returns the exit status."""
    from .common import use_files_only_backend

    use_files_only_backend()
    from ..continuation import Observer
    from ..model.scenes import michell_critical_twist
    from ..studies.runs.michell import MichellOptions, run_michell, write_michell_files

    options = MichellOptions(N=args.N, nu=args.nu, slenderness=args.slenderness, tol=args.tol).checked()
    if args.out:
        output_folder(args.out)
    analytic = michell_critical_twist(options.nu)
    bar = Progress(args, analytic / math.pi, NAME)
    bar.say(f"Michell ring: N = {args.N}, nu = {options.nu}, analytic phi* = {analytic / math.pi:.6f} pi")
    bar.say(args.compile_notice)
    steps = [0]

    def on_step(phi, n_negative):
        steps[0] += 1
        bar.update(phi / math.pi, steps=steps[0], negative=n_negative)

    try:
        ring = run_michell(options, observer=Observer(progress=bar.say, on_step=on_step))
    finally:
        bar.close()
    if args.out:
        names = write_michell_files(ring, args.out)
        bar.say(f"wrote {args.out}/{', '.join(names)}")
    if args.json:
        print(json.dumps(ring.result))
    else:
        _print_result(ring)
    return 0


def _print_result(ring):
    cp, analytic = ring.critical, ring.analytic
    print(f"phi*          = {cp.phi:.12f} rad = {cp.phi / math.pi:.10f} pi  (+- {cp.phi_error:.1e})")
    print(f"analytic      = {analytic:.12f} rad = {analytic / math.pi:.10f} pi  (2 pi sqrt(3) (1+nu))")
    print(f"rel. error    = {(cp.phi - analytic) / analytic:.3e}")
    print(f"time          = {ring.seconds:.2f} s ({cp.hessian_evaluations} Hessian evaluations in the refinement)")
